"""Determinism (1 vs 2 workers), resume after a kill, clear errors without a dataset that looks complete."""
from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("embreex")
trimesh = pytest.importorskip("trimesh")

from track3d.dataset import DATASET_JSON, Dataset  # noqa: E402

from track3d_sim import SimError  # noqa: E402
from track3d_sim.cli import main  # noqa: E402
from track3d_sim.generate import RUN_FILE, generate, make_settings  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "runtime"), str(ROOT / "sim"),
                                                    os.environ.get("PYTHONPATH", "")])}


def _hashes(root: Path) -> dict:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _quiet(msg):
    pass


def test_same_seed_same_bytes_for_1_and_2_workers(tmp_path):
    s = make_settings("tiny", seed=11, train=3, test=1, frames=4)
    a = generate(s, tmp_path / "a", workers=1, progress=False, log=_quiet)
    b = generate(s, tmp_path / "b", workers=2, progress=False, log=_quiet)
    ha, hb = _hashes(a), _hashes(b)
    assert len(ha) == 4 * (3 * 4 + 5) + 2
    assert ha == hb
    c = generate(make_settings("tiny", seed=12, train=3, test=1, frames=4), tmp_path / "c", progress=False, log=_quiet)
    assert _hashes(c)["train/0001/left/000001.png"] != ha["train/0001/left/000001.png"]


def test_killed_run_resumes_to_the_same_result(tmp_path):
    args = ["generate", "--preset", "tiny", "--seed", "5", "--train", "4", "--test", "2", "--test-unseen", "1",
            "--frames", "12", "--no-progress"]
    ref = tmp_path / "ref"
    assert main(args + ["--out", str(ref)]) == 0
    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "track3d_sim", *args, "--out", str(out)], env=ENV,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    try:
        while time.time() < deadline:  # kill while a sequence is half written, after one is complete
            if (out / "train" / "0001").is_dir() and list((out / "train").glob(".partial-*/left/*.png")):
                break
            if proc.poll() is not None:
                break
            time.sleep(0.01)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert not (out / DATASET_JSON).exists(), "a killed run must not look complete"
    with pytest.raises(Exception):
        Dataset(out)
    assert main(args + ["--out", str(out)]) == 0
    assert _hashes(out) == _hashes(ref)
    assert not list(out.rglob(".partial-*"))
    # a complete run started again is a no-op
    assert main(args + ["--out", str(out)]) == 0
    assert _hashes(out) == _hashes(ref)


def test_a_kill_while_a_file_was_renamed_into_place_leaves_nothing_behind(tmp_path):
    """A run killed while it wrote dataset.json left `.dataset.json.tmp-PID` (kept by the resume:
    not the uninterrupted bytes); killed while it wrote its run file, a folder holding only
    `..track3d-sim-run.json.tmp-PID` was refused as foreign, --overwrite too (a simulator walkthrough)."""
    s = make_settings("tiny", seed=5, train=1, test=0, frames=2)
    ref = generate(s, tmp_path / "ref", progress=False, log=_quiet)
    early = tmp_path / "early"
    early.mkdir()
    (early / f".{RUN_FILE}.tmp-4242").write_text("{")
    assert _hashes(generate(s, early, progress=False, log=_quiet)) == _hashes(ref)
    late = tmp_path / "late"
    generate(s, late, progress=False, log=_quiet)
    (late / DATASET_JSON).unlink()
    (late / f".{DATASET_JSON}.tmp-4243").write_text("{")
    assert _hashes(generate(s, late, progress=False, log=_quiet)) == _hashes(ref)


def test_resume_refuses_other_settings(tmp_path):
    out = tmp_path / "d"
    assert main(["generate", "--preset", "tiny", "--train", "1", "--test", "0", "--frames", "2", "--out", str(out),
                 "--no-progress"]) == 0
    with pytest.raises(SimError, match="different settings.*seed"):
        generate(make_settings("tiny", seed=1, train=1, test=0, frames=2), out, progress=False, log=_quiet)


@pytest.mark.parametrize("argv, needle", [
    (["--workers", "0"], "--workers"),
    (["--workers", "1000"], "--workers must be an integer from 1 to"),   # had started a process a sequence
    (["--frames", "0"], "frames"),
    (["--resolution", "8x8"], "resolution"),
    (["--fov", "200"], "field of view"),
    (["--train", "0", "--test", "0"], "train/test"),
    (["--seed", "-3"], "seed"),
    (["--sun-phase", "120:100"], "sun phase"),
    (["--sun-phase", "10:175"], "sun phase"),
    (["--sun-phase", "-5:20"], "sun phase"),
])
def test_bad_arguments_give_clear_errors(tmp_path, capsys, argv, needle):
    out = tmp_path / "bad"
    rc = main(["generate", "--preset", "tiny", "--out", str(out), "--no-progress", *argv])
    assert rc == 2
    assert needle in capsys.readouterr().err
    assert not (out / DATASET_JSON).exists()


def test_argparse_errors(capsys):
    for argv in (["generate", "--preset", "huge", "--out", "x"], ["generate", "--resolution", "abc", "--out", "x"],
                 ["generate"], ["generate", "--sun-phase", "90", "--out", "x"]):
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 2
    err = capsys.readouterr().err
    assert "huge" in err and "resolution" in err and "--out" in err and "100:150" in err


def test_sun_phase_range_relights_a_sequence_and_keeps_its_other_draws():
    import math

    from track3d_sim.generate import _identity
    from track3d_sim.sequence import _sun

    for seed in range(20):
        base = _sun(np.random.default_rng(seed))
        lit = _sun(np.random.default_rng(seed), (100.0, 150.0))
        assert 100.0 <= lit["phase_deg"] <= 150.0
        assert lit["irradiance"] == base["irradiance"]
        # the same azimuth: the in-plane parts of the two directions point the same way
        (bx, by, bz), (lx, ly, lz) = base["direction"], lit["direction"]
        assert math.atan2(ly, lx) == pytest.approx(math.atan2(by, bx), abs=1e-9)
        assert math.degrees(math.acos(-lz)) == pytest.approx(lit["phase_deg"])
        # the default draw itself, by hand: |N(0, 55)| capped at 150 deg, then the azimuth
        rng = np.random.default_rng(seed)
        phase = min(abs(rng.normal(0.0, 55.0)), 150.0)
        assert base["phase_deg"] == phase
        assert math.degrees(math.acos(-bz)) == pytest.approx(phase)
    assert _sun(np.random.default_rng(0), (120.0, 120.0))["phase_deg"] == 120.0
    # the settings reach the renderer: a tiny points-only sequence records a phase in the range
    from track3d_sim.generate import camera_of
    from track3d_sim.sequence import plan, render_sequence

    st = make_settings("tiny", seed=5, frames=1, points_only=True, sun_phase=(120, 130))
    spec = plan(1, 0)[0]
    lit = render_sequence(spec, st, camera_of(st), None)["meta"]["sun"]
    base = render_sequence(spec, make_settings("tiny", seed=5, frames=1, points_only=True), camera_of(st),
                           None)["meta"]["sun"]
    assert 120.0 <= lit["phase_deg"] <= 130.0 and lit["irradiance"] == base["irradiance"]
    # recorded in the run's identity (and dataset.json) only when set: older datasets still resume
    assert "sun_phase" not in _identity(make_settings("tiny", seed=0))
    assert _identity(make_settings("tiny", seed=0, sun_phase=(100, 150)))["sun_phase"] == [100.0, 150.0]


def test_foreign_output_folder_is_refused(tmp_path, capsys):
    (tmp_path / "keep.txt").write_text("precious")
    assert main(["generate", "--preset", "tiny", "--out", str(tmp_path), "--no-progress"]) == 2
    assert "not empty" in capsys.readouterr().err
    assert (tmp_path / "keep.txt").read_text() == "precious"


def _write_mesh(path: Path, kind: str):
    if kind == "garbage":
        path.write_text("this is not a mesh\n\x00\x01 nonsense\n")
    elif kind == "flat":
        path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\nf 1 3 2\nf 2 3 4\n")
    elif kind == "empty":
        path.write_text("# nothing\n")


@pytest.mark.parametrize("kind, needle", [("missing", "does not exist"), ("garbage", "mesh"),
                                          ("flat", "degenerate"), ("empty", "mesh")])
def test_bad_user_mesh(tmp_path, capsys, kind, needle):
    mesh = tmp_path / f"{kind}.obj"
    if kind != "missing":
        _write_mesh(mesh, kind)
    out = tmp_path / "out"
    rc = main(["generate", "--preset", "tiny", "--mesh", f"{mesh}:5", "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and needle in err and str(mesh.name) in err
    assert not out.exists() or not (out / DATASET_JSON).exists()


def test_user_mesh_is_used_with_its_size(tmp_path):
    mesh = tmp_path / "rock.ply"
    trimesh.creation.box(extents=(2.0, 1.0, 0.5)).export(mesh)
    out = tmp_path / "user"
    assert main(["generate", "--preset", "tiny", "--train", "1", "--test", "0", "--frames", "3",
                 "--mesh", f"{mesh}:6", "--out", str(out), "--no-progress"]) == 0
    data = Dataset(out)
    seq = data.sequences("train")[0]
    assert seq.meta["shape"]["family"] == "user"
    assert np.allclose(sorted(seq.meta["shape"]["extent_m"]), [1.5, 3.0, 6.0])
    size = seq.gt3d[:, 3:]
    assert np.all(np.linalg.norm(size, axis=1) <= np.sqrt(6 ** 2 + 3 ** 2 + 1.5 ** 2) * np.sqrt(3) + 1e-6)
    assert np.all(size.max(1) >= 6.0 * 0.57)


def test_stats_and_preview(tmp_path):
    out = tmp_path / "sp"
    assert main(["generate", "--preset", "tiny", "--train", "2", "--test", "1", "--frames", "4", "--out", str(out),
                 "--no-progress"]) == 0
    assert main(["stats", str(out), "--out", str(tmp_path / "stats.png")]) == 0
    assert main(["preview", str(out / "train" / "0001"), "--out", str(tmp_path / "p.png")]) == 0
    assert main(["preview", str(out / "test" / "0001"), "--out", str(tmp_path / "p.gif"), "--right"]) == 0
    for f in ("stats.png", "p.png", "p.gif"):
        assert (tmp_path / f).stat().st_size > 1000
    assert main(["stats", str(tmp_path / "nothing"), "--out", str(tmp_path / "x.png")]) == 2
    run = json.loads((out / RUN_FILE).read_text())
    assert run["seed"] == 0 and run["preset"] == "tiny"


def test_sigterm_ends_a_pool_run_with_its_workers(tmp_path):
    """`generate --workers 2` killed with SIGTERM had died alone (exit -15, BrokenPipe tracebacks,
    leaked semaphores): its orphaned workers went on writing into --out while the run was resumed.
    Now it stops as Ctrl-C does: one line, exit 130, the workers ended with it."""
    out = tmp_path / "gw"
    cmd = [sys.executable, "-m", "track3d_sim", "generate", "--preset", "tiny", "--train", "4", "--test", "2",
           "--frames", "30", "--seed", "7", "--workers", "2", "--quiet", "--out", str(out)]
    p = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    t0 = time.time()
    while time.time() - t0 < 120 and not any(out.rglob(".partial*")) and p.poll() is None:
        time.sleep(0.05)
    assert p.poll() is None, "the run ended before a sequence was started"
    time.sleep(0.5)
    p.send_signal(signal.SIGTERM)
    rc = p.wait(60)
    err = p.stderr.read()
    assert rc == 130 and "interrupted" in err and "Traceback" not in err, (rc, err[-500:])
    files = sorted(str(x) for x in out.rglob("*"))
    time.sleep(3)
    assert sorted(str(x) for x in out.rglob("*")) == files          # nothing writes after the exit
