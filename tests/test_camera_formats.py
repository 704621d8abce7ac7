"""A real navigation camera's frames in the dataset and through the API: monochrome, grey + alpha,
RGBA and palette PNGs, 16-bit PNGs of a 10- to 16-bit camera, float or 8-bit depth maps.

The reader converts each by one rule (track3d.frames.as_rgb, docs/dataset.md "Camera formats"),
or refuses in one line that says what to do; never a frame read wrong without a word (a 12-bit
camera's frames had been read as value >> 8, nearly black, and tracked worse)."""
from __future__ import annotations

import json
import warnings

import cv2
import numpy as np
import pytest

import track3d.dataset as D
from track3d.frames import as_rgb, check_image, to_uint8
from track3d.synthetic import make_synthetic_dataset


@pytest.fixture(scope="module")
def rgb_root(tmp_path_factory):
    """A tiny 8-bit RGB dataset (one sequence of 4 frames) that the tests copy and convert."""
    return make_synthetic_dataset(tmp_path_factory.mktemp("camfmt") / "rgb", {"s": 4})


def _copy(root, dst, convert=None, image_bits=None, sides=("left", "right")):
    """A copy of `root` at `dst`, each image file rewritten by convert(bgr uint8) -> array to write."""
    import shutil

    shutil.copytree(root, dst)
    for side in sides if convert else ():
        for p in sorted((dst / "test" / "s" / side).glob("*.png")):
            assert cv2.imwrite(str(p), convert(cv2.imread(str(p), cv2.IMREAD_COLOR)))
    if image_bits is not None:
        info = json.loads((dst / "dataset.json").read_text())
        info["image_bits"] = image_bits
        (dst / "dataset.json").write_text(json.dumps(info))
    return dst


def _seq(root):
    return D.Dataset(root).sequences("test")[0]


def _originals(root):
    s = _seq(root)
    return [s.image(i) for i in range(len(s))]


def _grey(bgr):
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)


def _bits(bgr, bits):
    """An 8-bit frame as a `bits`-bit camera writes it in a 16-bit PNG (samples in the low bits)."""
    return np.rint(bgr.astype(np.float64) * ((1 << bits) - 1) / 255).astype(np.uint16)


# --- 16-bit frames ------------------------------------------------------------------------------

def test_a_12_bit_camera_without_image_bits_is_refused_in_one_line(rgb_root, tmp_path):
    """A 12-bit camera's 0..4095 in 16-bit PNGs: refused when the sequence is opened (it had been
    read as value >> 8, at most 15 of 255, and tracked without a word)."""
    root = _copy(rgb_root, tmp_path / "u12", lambda bgr: _bits(bgr, 12))
    with pytest.raises(D.DatasetError, match=r'largest sample is 4\d{3} of 65535.*set "image_bits" in dataset\.json') as e:
        _seq(root)
    assert "\n" not in str(e.value) and "left/000001.png" in str(e.value)


@pytest.mark.parametrize("bits", [10, 12, 14])
def test_frames_of_a_declared_bit_depth_read_as_the_8_bit_frames(rgb_root, tmp_path, bits):
    """image_bits scales the samples to 0..255 (v * 255 / (2**bits - 1), rounded): the 16-bit copy
    of an 8-bit frame reads as that frame, to the value (monochrome too)."""
    want = _originals(rgb_root)
    root = _copy(rgb_root, tmp_path / "rgb", lambda bgr: _bits(bgr, bits), image_bits=bits)
    s = _seq(root)
    got = [s.image(i) for i in range(len(s))]
    assert all(g.dtype == np.uint8 and np.array_equal(g, w) for g, w in zip(got, want))
    assert np.array_equal(s.right_image(0), want[0])
    mono = _copy(rgb_root, tmp_path / "mono", lambda bgr: _bits(_grey(bgr), bits), image_bits=bits)
    grey = [cv2.cvtColor(w, cv2.COLOR_RGB2GRAY) for w in want]
    assert all(np.array_equal(_seq(mono).image(i), np.dstack([g] * 3)) for i, g in enumerate(grey))


def test_a_full_range_16_bit_copy_reads_as_the_8_bit_frames_without_image_bits(rgb_root, tmp_path):
    want = _originals(rgb_root)
    root = _copy(rgb_root, tmp_path / "u16", lambda bgr: bgr.astype(np.uint16) * 257)
    s = _seq(root)
    assert all(np.array_equal(s.image(i), w) for i, w in enumerate(want))
    # samples in the high bits (a 12-bit camera's v << 4) are a 16-bit frame: image_bits 16 or none
    msb = _copy(rgb_root, tmp_path / "msb", lambda bgr: _bits(bgr, 12) << 4)
    assert np.abs(_seq(msb).image(1).astype(int) - want[1]).max() <= 1


def test_image_bits_below_the_samples_is_refused(rgb_root, tmp_path):
    """A 12-bit camera that writes its samples in the high bits, declared 12: refused when the
    sequence is opened (the declaration had been ignored)."""
    root = _copy(rgb_root, tmp_path / "msb", lambda bgr: _bits(bgr, 12) << 4, image_bits=12)
    with pytest.raises(D.DatasetError, match=r"above the 12-bit camera's 4095 that \"image_bits\""):
        _seq(root)


def test_a_later_frame_above_the_declared_bits_is_refused_when_read(rgb_root, tmp_path):
    root = _copy(rgb_root, tmp_path / "u12", lambda bgr: _bits(bgr, 12), image_bits=12)
    p = root / "test" / "s" / "left" / D.frame_name(2)
    cv2.imwrite(str(p), np.full((120, 160, 3), 5000, np.uint16))
    s = _seq(root)
    s.image(1)
    with pytest.raises(D.DatasetError, match=r"000003\.png: the image holds 5000, above a 12-bit camera's 4095"):
        s.image(2)


@pytest.mark.parametrize("bits", ["12", 7, 17, True, 12.5])
def test_a_malformed_image_bits_is_refused(rgb_root, tmp_path, bits):
    root = _copy(rgb_root, tmp_path / "ds", image_bits=bits)
    with pytest.raises(D.DatasetError, match=r"'image_bits' must be an integer in 8\.\.16"):
        D.Dataset(root)


def test_a_sequence_opened_alone_takes_image_bits_from_its_dataset(rgb_root, tmp_path):
    """track3d-sim preview opens a Sequence without its Dataset: the declaration still holds."""
    root = _copy(rgb_root, tmp_path / "u12", lambda bgr: _bits(bgr, 12), image_bits=12)
    data = D.Dataset(root)
    s = D.Sequence(root / "test" / "s", data.camera, "test")
    assert s.image_bits == 12 and np.array_equal(s.image(0), _originals(rgb_root)[0])


def test_a_sequence_opened_alone_by_a_relative_path_takes_image_bits_from_its_dataset(rgb_root, tmp_path,
                                                                                     monkeypatch):
    """"s" from inside the split folder: dataset.json had been looked for two folders up of "s",
    which is ".", and the 12-bit frames were refused as undeclared."""
    root = _copy(rgb_root, tmp_path / "u12", lambda bgr: _bits(bgr, 12), image_bits=12)
    camera = D.Dataset(root).camera
    monkeypatch.chdir(root / "test")
    s = D.Sequence("s", camera, "test")
    assert s.image_bits == 12 and np.array_equal(s.image(0), _originals(rgb_root)[0])


# --- 8-bit camera formats -----------------------------------------------------------------------

def _grey_alpha_png(path, grey):
    from PIL import Image
    Image.fromarray(np.dstack([grey, np.full_like(grey, 255)]), "LA").save(path)


def _palette_png(path, grey):
    from PIL import Image
    Image.fromarray(grey).convert("P").save(path)


@pytest.mark.parametrize("kind", ["grey", "grey3", "grey_alpha", "palette", "grey_rgba"])
def test_monochrome_pngs_read_as_rgb_of_equal_channels(rgb_root, tmp_path, kind):
    root = _copy(rgb_root, tmp_path / kind)
    want = []
    for p in sorted((root / "test" / "s" / "left").glob("*.png")):
        g = _grey(cv2.imread(str(p), cv2.IMREAD_COLOR))
        want.append(np.dstack([g] * 3))
        if kind == "grey":
            cv2.imwrite(str(p), g)
        elif kind == "grey3":
            cv2.imwrite(str(p), np.dstack([g] * 3))
        elif kind == "grey_alpha":
            _grey_alpha_png(p, g)
        elif kind == "palette":
            _palette_png(p, g)
        else:
            cv2.imwrite(str(p), np.dstack([g] * 3 + [np.full_like(g, 128)]))   # alpha is no part of the scene
    s = _seq(root)
    assert all(np.array_equal(s.image(i), w) for i, w in enumerate(want))


def _with_exif(path, orientation, after_image=False, byte_order="<"):
    """Put an eXIf chunk holding one EXIF orientation into the PNG at `path`, after its header or
    after its image data (both are read by OpenCV's IMREAD_COLOR)."""
    import struct
    import zlib

    magic = b"II*\0" if byte_order == "<" else b"MM\0*"
    exif = (magic + struct.pack(byte_order + "IH", 8, 1)
            + struct.pack(byte_order + "HHIHH", 0x0112, 3, 1, orientation, 0) + struct.pack(byte_order + "I", 0))
    chunk = struct.pack(">I", len(exif)) + b"eXIf" + exif + struct.pack(">I", zlib.crc32(b"eXIf" + exif))
    b = path.read_bytes()
    at = len(b) - 12 if after_image else 33   # before IEND (12 bytes), or after signature + IHDR
    path.write_bytes(b[:at] + chunk + b[at:])


@pytest.mark.parametrize("orientation, after_image, byte_order", [(6, False, "<"), (3, True, ">"), (1, False, "<")])
def test_frames_are_read_as_stored_whatever_their_exif_orientation(rgb_root, tmp_path, orientation, after_image,
                                                                  byte_order):
    """The labels are in stored pixels, so a frame is read as stored (OpenCV's IMREAD_COLOR had
    turned a PNG by its EXIF orientation, IMREAD_UNCHANGED does not); an orientation other than 1
    in the first frame is said once per sequence, naming the file."""
    root = _copy(rgb_root, tmp_path / "exif")
    left = sorted((root / "test" / "s" / "left").glob("*.png"))
    for p in left:
        _with_exif(p, orientation, after_image, byte_order)
    turned = cv2.imread(str(left[0]), cv2.IMREAD_COLOR)
    stored = cv2.imread(str(left[0]), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    assert (turned.shape == stored.shape and np.array_equal(turned, stored)) == (orientation == 1)   # as written
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        s = _seq(root)
        _seq(root)   # opened again (the run, then the evaluation): not repeated
    said = [str(x.message) for x in w if issubclass(x.category, D.DatasetWarning)]
    assert all(np.array_equal(s.image(i), o) for i, o in enumerate(_originals(rgb_root)))
    if orientation == 1:
        assert said == []
    else:
        assert said == [f"{left[0]}: its EXIF orientation ({orientation}: "
                        f"{'rotated 90 degrees clockwise' if orientation == 6 else 'rotated 180 degrees'}) is "
                        f"ignored: frames are read as stored, as the labels are in stored pixels (a viewer may show "
                        f"it turned; docs/dataset.md \"Camera formats\")"], said


# --- depth maps ---------------------------------------------------------------------------------

def test_a_depth_map_of_another_format_is_named_with_what_to_do(rgb_root, tmp_path):
    root = _copy(rgb_root, tmp_path / "d8")
    p = root / "test" / "s" / "depth" / D.frame_name(1)
    cv2.imwrite(str(p), np.zeros((120, 160), np.uint8))
    with pytest.raises(D.DatasetError, match=r"000002\.png is 8-bit, 1 channel, not a 16-bit single-channel PNG: "
                                             r"millimetres of z.*write_depth_png"):
        _seq(root).depth(1)
    # float metres in a TIFF under a .png name (OpenCV reads by content)
    tif = p.with_suffix(".tiff")
    cv2.imwrite(str(tif), np.ones((120, 160), np.float32))
    tif.replace(p)
    with pytest.raises(D.DatasetError, match=r"is 32-bit float, 1 channel, not a 16-bit"):
        _seq(root).depth(1)


def test_a_depth_folder_of_float_files_names_the_conversion(rgb_root, tmp_path):
    root = _copy(rgb_root, tmp_path / "dtiff")
    for p in sorted((root / "test" / "s" / "depth").glob("*.png")):
        cv2.imwrite(str(p.with_suffix(".tiff")), np.ones((120, 160), np.float32))
        p.unlink()
    with pytest.raises(D.DatasetError, match=r"depth holds 4 tiff image\(s\) and no PNG.*write_depth_png"):
        _seq(root)


# --- the Python API -----------------------------------------------------------------------------

def test_check_image_names_the_conversion_for_a_cameras_frame():
    for bad, hint in ((np.zeros((4, 5), np.uint8), r"as_rgb\(image\)"),
                      (np.zeros((4, 5, 4), np.uint8), r"as_rgb\(image\)"),
                      (np.zeros((4, 5), np.uint16), r"as_rgb\(image, bits=B\)"),
                      (np.zeros((4, 5, 3), np.float32), "scale it to 0..255")):
        with pytest.raises(ValueError, match=r"uint8 RGB.*" + hint):
            check_image(bad)


def test_as_rgb_converts_a_cameras_frames_by_one_rule():
    rng = np.random.default_rng(0)
    g = rng.integers(0, 256, (6, 7), dtype=np.uint8)
    rgb = np.dstack([g] * 3)
    for a in (g, g[..., None], np.dstack([g, g]), np.dstack([g, g, g, np.zeros_like(g)])):
        out = as_rgb(a)
        assert out.dtype == np.uint8 and out.flags.c_contiguous and np.array_equal(out, rgb)
    c = rng.integers(0, 256, (6, 7, 3), dtype=np.uint8)
    assert as_rgb(c) is c                                          # the contract's frame: no copy
    f = c.astype(np.float64)
    for bits in (8, 10, 12, 14, 16):
        assert np.array_equal(as_rgb(np.rint(f * ((1 << bits) - 1) / 255).astype(np.uint16), bits), c)
    assert np.array_equal(to_uint8(c.astype(np.uint16) * 257, 16), c)
    assert to_uint8(np.array([0, 4095], np.uint16), 12).tolist() == [0, 255]
    with pytest.raises(ValueError, match="needs bits"):
        as_rgb(c.astype(np.uint16))
    with pytest.raises(ValueError, match=r"holds 4096, above a 12-bit camera's 4095"):
        to_uint8(np.array([4096], np.uint16), 12)
    for bits in (7, 17, True, "12"):
        with pytest.raises(ValueError, match=r"bits must be an integer in 8\.\.16"):
            to_uint8(np.zeros(2, np.uint16), bits)
    for bad in (np.zeros((6, 7, 3), np.float32), np.zeros((6, 7, 5), np.uint8), np.zeros((0, 7), np.uint8)):
        with pytest.raises(ValueError):
            as_rgb(bad)


def test_a_monochrome_12_bit_camera_tracks_as_its_8_bit_frames_through_the_api():
    """Track3D on frames a user converts with as_rgb: the same boxes as on the 8-bit RGB of
    equal channels."""
    from track3d.bench import synthetic_frames
    from track3d.synthetic import CAM
    from track3d.tracker import Track3D

    frames = synthetic_frames(CAM, n=4)
    greys = [cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) for img, _, _ in frames]
    runs = []
    for images in ([np.dstack([g] * 3) for g in greys],
                   [as_rgb(np.rint(g * (4095 / 255)).astype(np.uint16), bits=12) for g in greys]):
        t = Track3D.create(CAM, "kcf", "baseline")
        t.init(images[0], frames[0][2], 0, points=frames[0][1])
        runs.append([t.update(img, pts).box2d for img, (_, pts, _) in zip(images[1:], frames[1:])])
    assert np.array_equal(np.array(runs[0]), np.array(runs[1]))


def test_track_on_a_12_bit_dataset_says_what_to_do_in_one_line(rgb_root, tmp_path, capsys):
    from track3d.cli import main

    root = _copy(rgb_root, tmp_path / "u12", lambda bgr: _bits(bgr, 12))
    assert main(["track", "--data", str(root), "--tracker", "oracle", "--estimator", "baseline",
                 "--results", str(tmp_path / "res"), "--video", "none", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1 and '"image_bits"' in err


def test_as_rgb_drops_a_16_bit_alpha_before_scaling():
    """A 12-bit RGBA frame whose alpha is 16-bit opaque (65535): the alpha is no sample of the
    camera's and must not fail the 12-bit range check."""
    c = np.random.default_rng(1).integers(0, 4096, (5, 6, 3), dtype=np.uint16)
    rgba = np.dstack([c, np.full(c.shape[:2], 65535, np.uint16)])
    assert np.array_equal(as_rgb(rgba, 12), as_rgb(c, 12))
    assert np.array_equal(as_rgb(np.dstack([c[..., 0], c[..., 0] * 0 + 65535]), 12), as_rgb(c[..., 0], 12))
