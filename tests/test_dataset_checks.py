"""The reader's checks of a dataset written by hand (docs/dataset.md "What the reader refuses" /
"What the reader checks"): the mistakes a user made following the docs loaded silently and only
showed as wrong scores. Each test writes the tiny synthetic sphere dataset and damages it."""
from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from track3d import dataset as D
from track3d.camera import DICT_KEYS, Camera
from track3d.synthetic import CAM, make_synthetic_dataset, render_sphere

DOCS = Path(__file__).resolve().parents[1] / "docs" / "dataset.md"


def _synth(root, sensor="ideal", **kw) -> Path:
    """make_synthetic_dataset with the depth sensor named in each meta.json (None: as written)."""
    root = make_synthetic_dataset(root, **kw)
    if sensor is not None:
        for m in root.glob("*/*/meta.json"):
            D.write_meta(m.parent, {**json.loads(m.read_text()), "depth_sensor": {"name": sensor}})
    return root


def _open(root, split="test") -> tuple[list, list[str]]:
    """(sequences, DatasetWarning messages) of opening every sequence of the split."""
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        seqs = D.Dataset(root).sequences(split)
    return seqs, [str(x.message) for x in w if issubclass(x.category, D.DatasetWarning)]


def _rewrite(path: Path, fn, fmt="%.6f") -> None:
    a = np.loadtxt(path, delimiter=",", ndmin=2)
    np.savetxt(path, fn(a.copy()), fmt=fmt, delimiter=",")


# --- 1. the keys ---------------------------------------------------------------------------------

def test_docs_name_every_key_the_reader_reads():
    """docs/dataset.md had the camera's `baseline`, meta.json's `sensor` and a bare `sun`, keys the
    reader does not read: the user who followed it got no stereo pair and no sun, silently."""
    text = DOCS.read_text()
    for key in (*DICT_KEYS, "format", "version", "splits", "points_only", "depth_sensor", "family_index",
                "depth_sensor.max_range_m"):
        assert f"| `{key}` |" in text or f"`{key}`, `" in text or f", `{key}` |" in text, key
    assert '"direction": [x, y, z]' in text
    assert not re.search(r"`sensor` names the depth sensor", text)


def test_camera_refuses_a_key_it_does_not_know(tmp_path):
    """{"baseline": 0.4} was ignored: a K camera then had no stereo pair."""
    d = {"width": 160, "height": 120, "K": [[140, 0, 80], [0, 140, 60], [0, 0, 1]], "baseline": 0.4}
    with pytest.raises(ValueError, match=r"unknown key 'baseline' \(did you mean 'baseline_m'\?\).*known keys: "
                                         r"width, height"):
        Camera.from_dict(d)
    root = _synth(tmp_path / "ds")
    info = json.loads((root / D.DATASET_JSON).read_text())
    info["camera"]["baseline"] = 0.4
    D.write_dataset_json(root, info)
    with pytest.raises(D.DatasetError, match=r"dataset.json: bad camera: .*unknown key 'baseline'") as e:
        D.Dataset(root)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("change, message", [
    ({"version": None}, r"has no 'version'"),
    ({"version": "1"}, r"'version' must be an integer >= 1 .*got '1'"),
    ({"version": 1.0}, r"'version' must be an integer"),
    ({"version": True}, r"'version' must be an integer"),
    ({"version": 0}, r"'version' must be an integer >= 1"),
])
def test_version_missing_or_of_the_wrong_type_is_one_line(tmp_path, change, message):
    """A missing version was reported as 'format version -1', 1.0 and True were accepted."""
    root = _synth(tmp_path / "ds", sequences={"a": 2})
    info = {**json.loads((root / D.DATASET_JSON).read_text()), **change}
    if change["version"] is None:
        del info["version"]
    D.write_dataset_json(root, info)
    with pytest.raises(D.DatasetError, match=message) as e:
        D.Dataset(root)
    assert "\n" not in str(e.value)


def test_meta_without_a_known_depth_sensor_warns_once(tmp_path):
    root = _synth(tmp_path / "ds", sensor=None, sequences={"a": 3, "b": 3})
    assert _open(root)[1] == []              # the synthetic sets say "depth_sensor": null: unknown on purpose
    for m in root.glob("*/*/meta.json"):     # meta.json that names none
        D.write_meta(m.parent, {k: v for k, v in json.loads(m.read_text()).items() if k != "depth_sensor"})
    seqs, w = _open(root)
    assert len(w) == 2 and all("meta.json" in m and "unknown sensor's defaults" in m for m in w), w
    assert [s.depth_sensor for s in seqs] == [None, None]
    assert _open(root)[1] == []                                               # once per process
    m = root / "test" / "a" / D.META
    D.write_meta(m.parent, {"family_index": 0, "depth_sensor": {"name": "realsense"}, "sun": [0, 0, -1]})
    D.write_meta(root / "test" / "b", {"family_index": 0, "sensor": "Stereo"})   # the alias, any case
    seqs, w = _open(root)
    assert len(w) == 1 and str(m) in w[0] and "'realsense'" in w[0] and "sun is not" in w[0], w
    assert [s.depth_sensor for s in seqs] == ["realsense", "Stereo"] and seqs[0].sun_direction is None


# --- 2. labels that cannot be right ----------------------------------------------------------------

@pytest.mark.parametrize("file, line, fn, message", [
    (D.GT3D, 3, lambda a: a * [1, 1, -1, 1, 1, 1], r"cz = -1\d.* in front of the camera"),
    (D.GT3D, 2, lambda a: a * [1, 1, 1, 1, 0, 1], r"sy = 0 .*full extents"),
    (D.GT2D, 4, lambda a: a * 0, r"0,0,0,0 on a frame that absence.label marks present"),
    (D.GT2D, 2, lambda a: a + [500, 0, 0, 0], r"553,45,34,34 lies wholly outside the 160x120 image"),
    (D.GT2D, 1, lambda a: np.c_[a[:, :2], a[:, :2] + a[:, 2:]], r"51,45,86,80 reaches 5 px past the 160x120 image"),
])
def test_impossible_labels_are_refused_naming_file_and_line(tmp_path, file, line, fn, message):
    root = _synth(tmp_path / "ds", sequences={"a": 5})
    path = root / "test" / "a" / file

    def damage(a):
        a[line - 1:] = fn(a[line - 1:])
        return a

    _rewrite(path, damage)
    with pytest.raises(D.DatasetError, match=rf"{re.escape(str(path))} line {line}: {message}") as e:
        D.Dataset(root).sequences("test")
    assert "\n" not in str(e.value)


def test_a_label_one_pixel_past_the_image_and_absent_frames_are_accepted(tmp_path):
    root = _synth(tmp_path / "ds", sequences={"a": 5}, absent={"a": [1]})
    p = root / "test" / "a" / D.GT2D
    _rewrite(p, lambda a: np.r_[a[:2], [[-1, 0, 50, 50]], a[3:]])        # 1 px past the left border
    _rewrite(root / "test" / "a" / D.GT3D, lambda a: np.r_[a[:1], [[0, 0, -3, 0, 0, 0]], a[2:]])  # absent
    (seq,) = _open(root)[0]
    assert seq.gt2d[2, 0] == -1


# --- 3. conventions: projection and depth units ------------------------------------------------------

def test_real_conventions_do_not_warn(tmp_path, tiny_dataset):
    """The synthetic spheres (and the simulator's tiny set) read without a warning: the threshold
    sits far above what correct labels measure (0.000 on every dataset of data/)."""
    _, w = _open(_synth(tmp_path / "ds", sequences={"a": 8, "b": 6}, absent={"a": [0, 1]}))
    assert w == []
    for split in D.Dataset(tiny_dataset).splits:
        assert _open(tiny_dataset, split)[1] == []


@pytest.mark.parametrize("mistake", ["half_extents", "principal_point", "y_up"])
def test_wrong_conventions_warn_once_per_sequence(tmp_path, mistake):
    root = _synth(tmp_path / "ds", sequences={"a": 6, "b": 6})
    seq_a = root / "test" / "a"
    if mistake == "half_extents":
        _rewrite(seq_a / D.GT3D, lambda a: a * [1, 1, 1, 0.5, 0.5, 0.5])
    elif mistake == "y_up":     # the sphere rendered 1.5 m lower (y down), labelled y-up
        gt3d = np.loadtxt(seq_a / D.GT3D, delimiter=",", ndmin=2)
        gt2d = []
        for i, c in enumerate(gt3d[:, :3] + [0, 1.5, 0]):
            img, depth, b2, b3 = render_sphere(CAM, c, 1.5)
            D.write_rgb(seq_a / D.LEFT_DIR / D.frame_name(i), img)
            D.write_depth_png(seq_a / D.DEPTH_DIR / D.frame_name(i), depth)
            gt2d.append(b2)
            gt3d[i] = b3 * [1, -1, 1, 1, 1, 1]
        np.savetxt(seq_a / D.GT2D, gt2d, fmt="%d", delimiter=",")
        np.savetxt(seq_a / D.GT3D, gt3d, fmt="%.6f", delimiter=",")
    else:                       # the data rendered around (80, 60), dataset.json says (88, 60)
        info = json.loads((root / D.DATASET_JSON).read_text())
        cam = D.Camera.from_dict(info["camera"])
        info["camera"] = Camera.from_intrinsics(160, 120, cam.fx, cam.fy, cam.cx + 8, cam.cy).to_dict()
        D.write_dataset_json(root, info)
    _, w = _open(root)
    hits = [m for m in w if "projected with the dataset's camera" in m]
    assert len(hits) == (2 if mistake == "principal_point" else 1), w
    assert hits[0].startswith(f"{seq_a}:") and "y-up" in hits[0] and "principal point" in hits[0]


@pytest.mark.parametrize("mistake, ratio", [("depth_cm", 0.1), ("depth_m", 0.001), ("labels_mm", 0.001)])
def test_depth_units_warn_naming_the_depth_file(tmp_path, mistake, ratio):
    root = _synth(tmp_path / "ds", sequences={"a": 4}, absent={"a": [0]})
    seq = root / "test" / "a"
    if mistake == "labels_mm":
        _rewrite(seq / D.GT3D, lambda a: a * 1000)
    else:
        for f in sorted((seq / D.DEPTH_DIR).glob("*.png")):
            z = D.read_depth_png(f)
            D.write_depth_png(f, z / 10 if mistake == "depth_cm" else np.round(z) / 1000)
    _, w = _open(root)
    assert len(w) == 1, w
    # the first present frame (frame 1 is absent) names its depth map
    assert w[0].startswith(f"{seq / D.DEPTH_DIR / '000002.png'}: the depth inside the 2D label")
    assert float(re.search(r"is ([\d.e-]+)x", w[0]).group(1)) == pytest.approx(ratio, rel=0.35)


# --- 4. frame files checked when a sequence is opened ----------------------------------------------

@pytest.mark.parametrize("mistake, message", [
    ("from_zero", r"left is numbered from 000000.png: frames are numbered from 1, 000001.png \.\. 000005.png"),
    ("five_digit", r"left has 5-digit frame names \(00001.png\)"),
    ("missing_depth", r"4 images in depth/ but 5 label rows in groundtruth_2d.txt \(depth/ lacks 000003.png"),
    ("extra_left", r"6 images in left/ but 5 label rows .*also holds thumb.png"),
    ("jpeg", r"left holds 5 jpg image\(s\) and no PNG"),
])
def test_frame_files_are_checked_when_the_sequence_is_opened(tmp_path, mistake, message):
    """Misnamed frames had failed mid-run, after the sequences before them were tracked."""
    root = _synth(tmp_path / "ds", sequences={"a": 4, "b": 5})
    left = root / "test" / "b" / D.LEFT_DIR
    names = sorted(left.glob("*.png"))
    if mistake == "from_zero":
        for i, f in enumerate(names):
            f.rename(left / f"{i:06d}.png")
    elif mistake == "five_digit":
        for i, f in enumerate(names):
            f.rename(left / f"{i + 1:05d}.png")
    elif mistake == "missing_depth":
        (root / "test" / "b" / D.DEPTH_DIR / D.frame_name(2)).unlink()
    elif mistake == "extra_left":
        (left / "thumb.png").write_bytes(names[0].read_bytes())
    else:
        for f in names:
            f.rename(f.with_suffix(".jpg"))
    with pytest.raises(D.DatasetError, match=message) as e:
        D.Dataset(root).sequences("test")
    assert "\n" not in str(e.value) and str(root / "test" / "b") in str(e.value)


def test_hidden_files_in_a_frame_folder_are_no_frames(tmp_path):
    """macOS leaves ._000001.png beside each frame on a FAT / exFAT / SMB copy: it had been refused
    as an extra image (a review)."""
    root = _synth(tmp_path / "ds", sequences={"a": 3})
    (root / "test" / "a" / "left" / "._000001.png").write_bytes(b"junk")
    seqs, w = _open(root)
    assert len(seqs) == 1 and w == []
