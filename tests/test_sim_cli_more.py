"""`track3d-sim stats` says what it wrote and fails in one line; `generate --workers N` leaves no
orphaned worker when its process is killed with SIGKILL, and such a run still resumes to the
bytes of an uninterrupted one."""
from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest

pytest.importorskip("embreex")
pytest.importorskip("trimesh")
pytest.importorskip("matplotlib")

from track3d_sim.cli import main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "runtime"), str(ROOT / "sim"),
                                                    os.environ.get("PYTHONPATH", "")])}
LINUX = sys.platform.startswith("linux")


def _one_line(capsys, *needles) -> str:
    cap = capsys.readouterr()
    err = cap.err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("track3d-sim"), err
    assert "Traceback" not in cap.err
    assert cap.out == "", cap.out      # a failure does not also claim a written file
    for n in needles:
        assert n in err[0], err
    return err[0]


def _hashes(root: Path) -> dict:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


# ---- stats ---------------------------------------------------------------------------------------

def test_stats_says_what_it_wrote(tiny_dataset, tmp_path, capsys):
    # it printed nothing on success: the user had to look for the file
    out = tmp_path / "plots" / "fig4.svg"
    assert main(["stats", str(tiny_dataset), "--out", str(out), "--split", "train"]) == 0
    assert out.stat().st_size > 1000
    cap = capsys.readouterr()
    lines = cap.out.strip().splitlines()
    assert len(lines) == 1, cap.out
    assert lines[0].startswith("track3d-sim stats: "), lines
    assert lines[0].endswith(f"-> {out}"), lines
    assert "4 sequences" in lines[0] and "32 frames" in lines[0] and "train" in lines[0], lines
    assert cap.err == ""


@pytest.mark.parametrize("what, needles", [
    ("missing", ["no dataset at", "does not exist"]),
    ("empty folder", ["no dataset at", "empty"]),
    ("empty split", ["no sequences", "test_unseen", "train 4", "test 2"]),
])
def test_stats_bad_input_is_one_line(tiny_dataset, tmp_path, capsys, what, needles):
    root, split = {"missing": (tmp_path / "nowhere", "all"), "empty folder": (tmp_path / "empty", "all"),
                   "empty split": (tiny_dataset, "test_unseen")}[what]
    (tmp_path / "empty").mkdir()
    out = tmp_path / "s.png"
    assert main(["stats", str(root), "--out", str(out), "--split", split]) == 2
    _one_line(capsys, *needles)
    assert not out.exists()


def test_stats_unknown_split_is_one_line(tiny_dataset, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["stats", str(tiny_dataset), "--out", str(tmp_path / "s.png"), "--split", "validation"])
    assert e.value.code == 2
    _one_line(capsys, "--split", "validation", "test_unseen")


def test_stats_without_matplotlib_names_the_extra(tiny_dataset, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)   # `import matplotlib` now fails
    assert main(["stats", str(tiny_dataset), "--out", str(tmp_path / "s.png")]) == 2
    _one_line(capsys, "pip install 'track3d[sim]'", "matplotlib")


def test_stats_of_one_frame_sequences_warns_nothing(tmp_path, capsys):
    # sequences of one frame have no frame pair: "Mean of empty slice" and "invalid value"
    # RuntimeWarnings on stderr, and "mean speed nan m/s" in panel (c)
    data = tmp_path / "one"
    assert main(["generate", "--preset", "tiny", "--train", "2", "--test", "0", "--frames", "1", "--points-only",
                 "--quiet", "--out", str(data)]) == 0
    capsys.readouterr()
    from track3d_sim.stats import plot_stats
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        st = plot_stats(data, tmp_path / "s.png")
        assert main(["stats", str(data), "--out", str(tmp_path / "s2.png")]) == 0
    assert st["n_frames"] == 2 and len(st["speed"]) == 0
    cap = capsys.readouterr()
    assert cap.err == "" and "2 sequences, 2 frames" in cap.out


# ---- generate --workers: no orphans ----------------------------------------------------------------

def _proc_stat(pid: int) -> tuple[str, int, str] | None:
    """(state, parent pid, start time) of a process from /proc, None when it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return None
    fields = text[text.rindex(")") + 2:].split()
    return fields[0], int(fields[1]), fields[19]


def _children(pid: int) -> dict[int, str]:
    """The live children of `pid`: pid -> start time (a pid reused later is not taken for them)."""
    kids = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            st = _proc_stat(int(d.name))
            if st is not None and st[1] == pid and st[0] != "Z":
                kids[int(d.name)] = st[2]
    return kids


def _alive(pid: int, start: str) -> bool:
    st = _proc_stat(pid)
    return st is not None and st[2] == start and st[0] != "Z"   # a zombie is dead, awaiting its reaper


def _start_pool_run(out: Path, frames: int) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "track3d_sim", "generate", "--preset", "tiny", "--train", "2", "--test", "1",
           "--frames", str(frames), "--seed", "3", "--workers", "2", "--quiet", "--out", str(out)]
    return subprocess.Popen(cmd, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _wait_for_rendering(proc: subprocess.Popen, out: Path) -> None:
    t0 = time.time()
    while time.time() - t0 < 120 and proc.poll() is None and not list(out.glob("*/.partial-*/left/*.png")):
        time.sleep(0.02)
    assert proc.poll() is None, "the run ended before a sequence was half written"


@pytest.mark.skipif(not LINUX, reason="PR_SET_PDEATHSIG is Linux's")
def test_a_pool_runs_workers_die_with_it_on_sigkill(tmp_path):
    """kill -9 of `generate --workers 2` left its workers running (PPID 1): they rendered on into
    --out until their sequence was complete, renamed it into place with nobody to collect, then
    died on a BrokenPipeError traceback; a resume started meanwhile raced them."""
    out = tmp_path / "gk"
    proc = _start_pool_run(out, frames=600)   # a sequence takes far longer than the wait below
    kids = {}
    try:
        _wait_for_rendering(proc, out)
        kids = _children(proc.pid)
        assert len(kids) >= 2, kids           # the two workers (and multiprocessing's resource tracker)
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
        t0 = time.time()
        while time.time() - t0 < 5 and any(_alive(p, s) for p, s in kids.items()):
            time.sleep(0.05)
        survivors = [p for p, s in kids.items() if _alive(p, s)]
        assert not survivors, f"workers {survivors} outlived the killed run"
        files = _hashes(out)
        time.sleep(1.0)
        assert _hashes(out) == files          # nothing writes into --out after the kill
        assert not (out / "train" / "0001").exists()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for p, s in kids.items():             # never leave an orphan behind when the test fails
            if _alive(p, s):
                os.kill(p, signal.SIGKILL)


@pytest.mark.skipif(not LINUX, reason="kills with SIGKILL and reads /proc")
def test_a_pool_run_killed_with_sigkill_resumes_to_the_same_bytes(tmp_path):
    """Resumed at once, as a user would: the killed run's orphaned workers had raced the resume
    (it deletes the .partial folders they wrote into; they renamed theirs into place)."""
    ref = tmp_path / "ref"
    args = ["generate", "--preset", "tiny", "--train", "2", "--test", "1", "--frames", "12", "--seed", "3", "--quiet"]
    assert main(args + ["--workers", "1", "--out", str(ref)]) == 0
    out = tmp_path / "killed"
    proc = _start_pool_run(out, frames=12)
    kids = {}
    try:
        _wait_for_rendering(proc, out)
        kids = _children(proc.pid)
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
        assert main(args + ["--workers", "2", "--out", str(out)]) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for p, s in kids.items():
            if _alive(p, s):
                os.kill(p, signal.SIGKILL)
    assert _hashes(out) == _hashes(ref)
    assert not list(out.rglob(".partial-*"))


def test_shapes_says_what_it_wrote(tmp_path, capsys):
    """`track3d-sim shapes` had printed nothing on success (as `stats` and `ply` had)."""
    from track3d_sim.cli import main

    out = tmp_path / "s.png"
    assert main(["shapes", "--out", str(out), "--count", "1", "--generator", "fragment", "--no-progress"]) == 0
    assert out.is_file() and capsys.readouterr().out.strip().endswith(f"-> {out}")


# ---- preview / ply -----------------------------------------------------------------------------------

def test_preview_and_ply_of_a_12_bit_sequence_named_from_its_split_folder(tmp_path, capsys, monkeypatch):
    """`cd ds/test && track3d-sim preview a`: the 12-bit frames had been refused as undeclared
    ("image_bits" was looked for two folders up of "a", which is ".")."""
    import json

    import cv2
    import numpy as np
    from track3d.synthetic import make_synthetic_dataset

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 3})
    for side in ("left", "right"):
        for f in sorted((root / "test" / "a" / side).glob("*.png")):
            a = cv2.imread(str(f), cv2.IMREAD_UNCHANGED).astype(np.uint32)
            assert cv2.imwrite(str(f), ((a * 4095 + 127) // 255).astype(np.uint16))   # 0..4095
    info = json.loads((root / "dataset.json").read_text())
    (root / "dataset.json").write_text(json.dumps({**info, "image_bits": 12}))
    monkeypatch.chdir(root / "test")
    assert main(["preview", "a", "--out", str(tmp_path / "p.png")]) == 0
    assert main(["ply", "a", "--out", str(tmp_path / "a.ply")]) == 0
    cap = capsys.readouterr()
    assert cap.err == "" and len(cap.out.splitlines()) == 2, cap
    assert (tmp_path / "p.png").is_file() and (tmp_path / "a.ply").is_file()


def test_stats_of_zero_frame_sequences_is_one_line(tmp_path, capsys):
    """Sequences whose label files and frame folders are empty open (0 frames); `stats` had failed
    with a traceback (the volume panel's range of no frames)."""
    from track3d.synthetic import make_synthetic_dataset

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 3})
    seq = root / "test" / "a"
    for f in ("groundtruth_2d.txt", "groundtruth_3d.txt", "absence.label", "cut_by_image.label"):
        (seq / f).write_text("")
    for sub in ("left", "right", "depth"):
        for p in (seq / sub).glob("*.png"):
            p.unlink()
    out = tmp_path / "s.png"
    assert main(["stats", str(root), "--out", str(out)]) == 2
    _one_line(capsys, "no frames in any split", "1 sequence holds none")
    assert not out.exists()
