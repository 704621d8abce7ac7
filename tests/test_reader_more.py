"""The dataset reader on what recorded data holds (docs/dataset.md "Label and frame files"):
frame files whose extension is in upper case, and 2D labels that reach a few pixels past the
image. Each test writes the tiny synthetic sphere dataset and changes it."""
from __future__ import annotations

import re
import shutil
import warnings

import numpy as np
import pytest

from track3d import dataset as D
from track3d.evaluation.metrics import score_sequence
from track3d.synthetic import make_synthetic_dataset


def _open(root, split="test") -> tuple[list, list[str]]:
    """(sequences, DatasetWarning messages) of opening every sequence of the split."""
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        seqs = D.Dataset(root).sequences(split)
    return seqs, [str(x.message) for x in w if issubclass(x.category, D.DatasetWarning)]


def _set_lines(seq_dir, gt2d_rows: dict[int, list[float]], cut: dict[int, int]) -> None:
    """Replace 0-based lines of groundtruth_2d.txt and cut_by_image.label."""
    p = seq_dir / D.GT2D
    a = np.loadtxt(p, delimiter=",", ndmin=2)
    for i, row in gt2d_rows.items():
        a[i] = row
    np.savetxt(p, a, fmt="%g", delimiter=",")
    c = np.loadtxt(seq_dir / D.CUT, ndmin=1)
    for i, v in cut.items():
        c[i] = v
    np.savetxt(seq_dir / D.CUT, c, fmt="%d")


# --- 1. frame files whose extension is in upper case -------------------------------------------------

def test_frames_with_an_upper_case_extension_are_read_in_their_order(tmp_path):
    """000003.PNG among .png files, and whole folders of .PNG (as some cameras write): they had
    been refused as '5 images in left/ but 5 label rows (lacks 000003.png and also holds
    000003.PNG)'. Each frame reads as the frame of its number."""
    root = make_synthetic_dataset(tmp_path / "ds", {"a": 5})
    seq = root / "test" / "a"
    before = D.Dataset(root).sequence("test", "a")
    images = [before.image(i) for i in range(5)]
    rights = [before.right_image(i) for i in range(5)]
    depths = [before.depth(i) for i in range(5)]
    assert not all(np.array_equal(images[0], im) for im in images[1:])   # the frames differ: an order to keep
    (seq / D.LEFT_DIR / "000003.png").rename(seq / D.LEFT_DIR / "000003.PNG")
    for sub in (D.RIGHT_DIR, D.DEPTH_DIR):
        for f in (seq / sub).glob("*.png"):
            f.rename(f.with_suffix(".PNG"))
    (s,), w = _open(root)
    assert w == [] and len(s) == 5
    assert s.image_path(2).name == "000003.PNG" and s.image_path(1).name == "000002.png"
    assert s.depth_path(0).name == "000001.PNG"
    for i in range(5):
        f = s[i]
        np.testing.assert_array_equal(f.image, images[i])
        np.testing.assert_array_equal(f.right, rights[i])
        np.testing.assert_array_equal(f.depth_m, depths[i])


def test_a_frame_in_two_files_whose_names_differ_in_case_is_refused(tmp_path):
    root = make_synthetic_dataset(tmp_path / "ds", {"a": 5})
    left = root / "test" / "a" / D.LEFT_DIR
    shutil.copy(left / "000003.png", left / "000003.PNG")
    with pytest.raises(D.DatasetError, match=rf"{re.escape(str(left))} holds both 000003.PNG and 000003.png") as e:
        D.Dataset(root).sequences("test")
    assert "\n" not in str(e.value)


def test_a_folder_of_upper_case_jpegs_is_still_refused_in_one_line(tmp_path):
    """Only the case of the extension is forgiven: frames are PNG files."""
    root = make_synthetic_dataset(tmp_path / "ds", {"a": 5})
    for f in (root / "test" / "a" / D.LEFT_DIR).glob("*.png"):
        f.rename(f.with_suffix(".JPG"))
    with pytest.raises(D.DatasetError, match=r"left holds 5 JPG image\(s\) and no PNG: frames are PNG files") as e:
        D.Dataset(root).sequences("test")
    assert "\n" not in str(e.value)


# --- 2. 2D labels a few pixels past the image --------------------------------------------------------

def test_labels_a_few_pixels_past_the_image_are_clipped_with_one_warning(tmp_path):
    """GOT-10k style annotation tools let a box reach a few pixels past the border; such labels
    had been refused (more than 1 px past). On frames flagged cut they are clipped to the image,
    as the evaluation clips a predicted box: the raw label as a prediction scores AO 1."""
    root = make_synthetic_dataset(tmp_path / "ds", {"a": 5, "b": 4})
    seq = root / "test" / "a"
    # 3 px past the left; 2 px past the right and 5 px past the bottom (h 25: at most 5 px)
    rows = {2: [-3, 40, 30, 30], 3: [132, 100, 30, 25]}
    _set_lines(seq, rows, {2: 1, 3: 1})
    _set_lines(root / "test" / "b", {0: [-2, 10, 30, 30]}, {0: 1})
    (a, b), w = _open(root)
    assert len(w) == 2, w                                          # one per sequence
    assert w[0] == (f"{seq / D.GT2D}: 2 line(s) reach past the 160x120 image, by up to 5 px (line 4): clipped to "
                    f"the image (2D labels are the visible part's box; docs/dataset.md)")
    assert w[1].startswith(f"{root / 'test' / 'b' / D.GT2D}: 1 line(s)")
    np.testing.assert_allclose(a.gt2d[2], [0, 40, 27, 30])
    np.testing.assert_allclose(a.gt2d[3], [132, 100, 28, 20])
    raw = np.loadtxt(seq / D.GT2D, delimiter=",", ndmin=2)
    np.testing.assert_array_equal(a.gt2d[[0, 1, 4]], raw[[0, 1, 4]])   # the others as given
    # the metrics: a prediction equal to the raw label is clipped for its IoU as the label was
    scored = ~a.absent
    s = score_sequence("a", raw, None, a.gt2d, None, scored, image_size=(160, 120))
    assert s.ao_2d == pytest.approx(1.0)
    # once per sequence and process: opened again (the run, then the evaluation) it is not repeated
    assert _open(root)[1] == []


@pytest.mark.parametrize("row, cut, message", [
    # more than 5 px and 10% of its side past the left
    ([-12, 40, 30, 30], 1, r"line 3: -12,40,30,30 reaches 12 px past the 160x120 image: a few px past it are clipped"),
    # far larger than the image: not the visible part's box
    ([-50, -50, 300, 300], 1, r"line 3: -50,-50,300,300 reaches 130 px past the 160x120 image: a few px"),
    # a few px past, but on a frame flagged not cut: the target lies inside the image
    ([-3, 40, 30, 30], 0, r"line 3: -3,40,30,30 reaches 3 px past the 160x120 image on a frame cut_by_image.label "
                          r"marks uncut \(its line 3 is 0\)"),
    ([200, 40, 30, 30], 1, r"line 3: 200,40,30,30 lies wholly outside the 160x120 image"),
    ([np.nan, 40, 30, 30], 1, r"non-finite values on line 3"),
])
def test_labels_far_past_the_image_or_on_an_uncut_frame_are_still_refused(tmp_path, row, cut, message):
    root = make_synthetic_dataset(tmp_path / "ds", {"a": 5})
    seq = root / "test" / "a"
    _set_lines(seq, {2: row}, {2: cut})
    with pytest.raises(D.DatasetError, match=rf"{re.escape(str(seq / D.GT2D))} .*{message}") as e:
        D.Dataset(root).sequences("test")
    assert "\n" not in str(e.value)


def test_a_wide_box_may_reach_a_tenth_of_its_side_past_the_image(tmp_path):
    """The limit grows with the box: 10% of a 100 px wide box is 10 px (5 px is the floor)."""
    root = make_synthetic_dataset(tmp_path / "ds", {"a": 5})
    seq = root / "test" / "a"
    _set_lines(seq, {1: [70, 30, 100, 40], 2: [71, 30, 100, 40]}, {1: 1, 2: 1})   # 10 px, then 11 px past
    with pytest.raises(D.DatasetError, match=r"line 3: 71,30,100,40 reaches 11 px past"):
        D.Dataset(root).sequences("test")
    _set_lines(seq, {2: [70, 30, 100, 40]}, {})
    (s,), w = _open(root)
    assert len(w) == 1 and "2 line(s)" in w[0] and "by up to 10 px (line 2)" in w[0]
    np.testing.assert_allclose(s.gt2d[1:3], [[70, 30, 90, 40]] * 2)


def test_an_external_trackers_init_row_may_be_the_raw_label_the_reader_clips(tmp_path, capsys):
    """A tracker started from groundtruth_2d.txt reports the label as the file has it; on a frame
    the reader clips (a few px past the image, flagged cut) `track3d eval` had refused that init
    row as 'not the ground truth's'. The raw row and the clipped one are both the ground truth;
    another box still is not."""
    from track3d.cli import main

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 5})
    _set_lines(root / "test" / "a", {0: [-3, 40, 30, 30]}, {0: 1})
    res = tmp_path / "res"
    assert main(["track", "--data", str(root), "--tracker", "oracle", "--estimator", "baseline",
                 "--results", str(res), "--quiet", "--video", "none"]) == 0
    (run,) = res.rglob("a_001.txt")
    rows = run.read_text().splitlines()
    assert np.allclose(np.array(rows[0].split(","), float), [0, 40, 27, 30])   # track3d's own: clipped
    evaluate = ["eval", "--data", str(root), "--results", str(res), "--out", str(tmp_path / "rep")]
    for first, rc in (("-3,40,30,30", 0), ("-2,40,30,30", 2)):   # the raw label; 1 px off it
        run.write_text("\n".join([first] + rows[1:]) + "\n")
        capsys.readouterr()
        assert main(evaluate) == rc, first
        err = capsys.readouterr().err
        assert "Traceback" not in err
        assert ("is 'init' but its 2D box" in err) == (rc == 2), err


def test_the_console_scripts_print_their_own_warnings_as_one_line(tmp_path):
    """A console script's warning from track3d's own code is one line, `<prog>: warning: ...`, as
    its errors are: Python's form had been two lines, the installed module's path and line and the
    warnings.warn call's source (argparsing.one_line_warnings). Run as a user runs it, in a process
    of its own (pytest's recorder leaves the handler alone)."""
    import subprocess
    import sys

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 5})
    _set_lines(root / "test" / "a", {2: [-3, 40, 30, 30]}, {2: 1})
    code = "import sys; from track3d.cli import main; sys.exit(main(sys.argv[1:]))"
    run = subprocess.run([sys.executable, "-c", code, "track", "--data", str(root), "--split", "test",
                          "--tracker", "oracle", "--estimator", "baseline", "--results", str(tmp_path / "r"),
                          "--quiet"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    said = [line for line in run.stderr.splitlines() if "clipped to the image" in line]
    assert len(said) == 1 and said[0].startswith("track3d: warning: ") and f"{D.GT2D}: 1 line(s)" in said[0]
    assert "DatasetWarning" not in run.stderr and "warnings.warn" not in run.stderr
    # other code's warnings keep Python's form; the formatter before is back after main()
    import warnings

    from track3d.argparsing import one_line_warnings

    before = warnings.formatwarning
    with one_line_warnings("x"):
        assert warnings.formatwarning("m", UserWarning, "/a/track3d/dataset.py", 3) == "x: warning: m\n"
        assert warnings.formatwarning("m", UserWarning, "/a/numpy/core.py", 3).startswith("/a/numpy/core.py:3: ")
    assert warnings.formatwarning is before
