"""`track3d-sim` mistakes and damaged data end in one `track3d-sim: error: ...` line and exit 2,
never a traceback: --out folders and formats, damaged frames, relative sequence paths, a
dataset root where a sequence is expected, preset flags (a user audit of stats / preview / ply)."""
from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import pytest

from track3d_sim.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]


def _one_line(capsys, *needles):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("track3d-sim"), err
    for n in needles:
        assert n in err[0], err
    return err[0]


@pytest.fixture
def damaged(tiny_dataset, tmp_path):
    """A copy of one test sequence of the tiny dataset (with its dataset.json) in which left
    image 3 is truncated and depth map 5 is empty."""
    root = tmp_path / "dmg"
    root.mkdir()
    shutil.copy(tiny_dataset / "dataset.json", root)
    seq = root / "test" / "0001"
    shutil.copytree(tiny_dataset / "test" / "0001", seq)
    left = seq / "left" / "000003.png"
    left.write_bytes(left.read_bytes()[:100])
    (seq / "depth" / "000005.png").write_bytes(b"")
    return seq


def test_preview_says_what_it_drew(tiny_dataset, tmp_path, capsys):
    # it printed nothing, and --frames past the sequence's length drew fewer without a word
    seq = tiny_dataset / "test" / "0001"
    total = len(list((seq / "left").glob("*.png")))
    assert main(["preview", str(seq), "--out", str(tmp_path / "p.png"), "--frames", str(total + 40)]) == 0
    out = capsys.readouterr().out
    assert f"{total} of {total} frames (--frames {total + 40}, the sequence has {total})" in out
    assert str(tmp_path / "p.png") in out
    assert main(["preview", str(seq), "--out", str(tmp_path / "p2.png"), "--frames", "2"]) == 0
    assert f"2 of {total} frames ->" in capsys.readouterr().out


def test_stats_makes_the_folder_of_out(tiny_dataset, tmp_path):
    out = tmp_path / "new" / "sub" / "s.png"
    assert main(["stats", str(tiny_dataset), "--out", str(out)]) == 0
    assert out.stat().st_size > 1000


@pytest.mark.parametrize("name", ["s.txt", "s"])
def test_stats_refuses_an_image_format_it_cannot_write(tiny_dataset, tmp_path, capsys, name):
    assert main(["stats", str(tiny_dataset), "--out", str(tmp_path / name)]) == 2
    _one_line(capsys, name, ".png", ".pdf", ".svg")
    assert not (tmp_path / name).exists()


def test_stats_of_a_sequence_folder_names_the_root_without_a_flag_it_lacks(tiny_dataset, tmp_path, capsys):
    assert main(["stats", str(tiny_dataset / "test" / "0001"), "--out", str(tmp_path / "s.png")]) == 2
    line = _one_line(capsys, "sequence folder", str(tiny_dataset))
    assert "--sequence" not in line


@pytest.mark.parametrize("argv, needle", [
    (["preview", "{seq}", "--out", "p.png"], "cannot read image"),          # frame 3 of the sheet
    (["preview", "{seq}", "--out", "p.gif"], "cannot read image"),
    (["ply", "{seq}", "--frame", "3", "--out", "f.ply"], "cannot read image"),
    (["ply", "{seq}", "--frame", "5", "--out", "f.ply"], "cannot read depth map"),
])
def test_damaged_frames_are_one_line(damaged, tmp_path, capsys, argv, needle):
    argv = [a.format(seq=damaged) for a in argv]
    argv[-1] = str(tmp_path / argv[-1])
    assert main(argv) == 2
    _one_line(capsys, needle, str(damaged))
    assert not Path(argv[-1]).exists()


@pytest.mark.parametrize("cmd", ["ply", "preview", "stats", "shapes"])
def test_out_that_is_a_folder_is_one_line(tiny_dataset, tmp_path, capsys, cmd):
    seq = str(tiny_dataset / "test" / "0001")
    argv = {"ply": ["ply", seq], "preview": ["preview", seq], "stats": ["stats", str(tiny_dataset)],
            "shapes": ["shapes", "--count", "1", "--generator", "fragment", "--quiet"]}[cmd]
    assert main(argv + ["--out", str(tmp_path)]) == 2
    _one_line(capsys, "is a folder")


def test_ply_says_how_many_points_it_wrote(tiny_dataset, tmp_path, capsys):
    """A frame without a depth return wrote an empty cloud and printed as any other."""
    import numpy as np
    from PIL import Image

    import shutil

    shutil.copytree(tiny_dataset, tmp_path / "ds")   # the session's dataset stays as it is
    seq = tmp_path / "ds" / "test" / "0001"
    assert main(["ply", str(seq), "--frame", "1", "--out", str(tmp_path / "a.ply")]) == 0
    out = capsys.readouterr().out
    n = int(out.split(", ")[1].split()[0])
    assert n > 0 and "no depth return" not in out
    depth = sorted((seq / "depth").iterdir())[0]
    Image.fromarray(np.zeros_like(np.asarray(Image.open(depth)))).save(depth)
    assert main(["ply", str(seq), "--frame", "1", "--out", str(tmp_path / "b.ply")]) == 0
    assert ", 0 points (no depth return on this frame" in capsys.readouterr().out


def test_out_below_a_file_is_one_line(tiny_dataset, tmp_path, capsys):
    (tmp_path / "f").write_text("a file")
    assert main(["ply", str(tiny_dataset / "test" / "0001"), "--out", str(tmp_path / "f" / "x" / "c.ply")]) == 2
    _one_line(capsys, "is a file, not a folder")


@pytest.mark.parametrize("where, argv", [
    ("test", ["preview", "0001", "--out", "{tmp}/p.png"]),
    ("test", ["ply", "0001", "--out", "{tmp}/f.ply"]),
    ("test/0001", ["ply", ".", "--out", "{tmp}/f.ply"]),
    ("test/0001", ["preview", ".", "--frames", "2", "--out", "{tmp}/p.png"]),
])
def test_relative_sequence_paths(tiny_dataset, tmp_path, monkeypatch, where, argv):
    monkeypatch.chdir(tiny_dataset / where)
    argv = [a.format(tmp=tmp_path) for a in argv]
    assert main(argv) == 0
    assert Path(argv[-1]).stat().st_size > 100


def test_a_dataset_root_or_split_is_not_a_sequence(tiny_dataset, tmp_path, capsys, monkeypatch):
    assert main(["preview", str(tiny_dataset), "--out", str(tmp_path / "p.png")]) == 2
    _one_line(capsys, "is a dataset root", "e.g. " + str(tiny_dataset / "test" / "0001"))
    assert main(["ply", str(tiny_dataset / "test"), "--out", str(tmp_path / "f.ply")]) == 2
    _one_line(capsys, "is a split folder", "e.g. " + str(tiny_dataset / "test" / "0001"))
    monkeypatch.chdir(tiny_dataset)
    assert main(["preview", ".", "--out", str(tmp_path / "p.png")]) == 2
    line = _one_line(capsys, "is a dataset root", "e.g. test/0001")
    assert "no dataset.json" not in line


def test_negative_resolution_names_the_value(tmp_path, capsys):
    out = tmp_path / "neg"
    assert main(["generate", "--preset", "tiny", "--resolution", "-320x240", "--out", str(out), "--quiet"]) == 2
    _one_line(capsys, "-320x240", "out of range")
    assert not out.exists()


def test_demo_refuses_an_unknown_preset_before_simulating(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["demo", "--preset", "huge", "--out", str(tmp_path / "demo")])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "huge" in err and "tiny" in err and "[demo]" not in err
    assert not (tmp_path / "demo").exists()


def test_preset_flags_say_their_default_comes_from_the_preset():
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    gen = sub.choices["generate"]
    flags = {o: a for a in gen._actions for o in a.option_strings}
    for flag in ("--frames", "--train", "--test", "--resolution", "--fov", "--subdivisions"):
        assert "default: from the preset" in flags[flag].help, flag


def test_docs_presets_table_has_one_header_row():
    text = (ROOT / "docs" / "simulator.md").read_text()
    headers = [l for l in text.splitlines() if l.startswith("| preset |")]
    assert len(headers) == 1, headers
