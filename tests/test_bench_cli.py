"""`track3d bench` and track3d.machine: runs from the package alone (no dataset, no simulator,
no tqdm), reports per-stage percentiles, FPS per thread count, the machine and its load."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from track3d import bench, machine
from track3d.boxnet import SENSOR_MODELS
from track3d.cli import main


def test_percentiles_against_a_hand_computed_case():
    p = bench.percentiles(np.arange(1, 1002, dtype=float))     # 1..1001
    assert p["median_ms"] == 501.0
    assert p["p99_ms"] == pytest.approx(991.0)                  # numpy linear: 1 + 0.99 * 1000
    assert p["p99_9_ms"] == pytest.approx(1000.0)
    assert p["max_ms"] == 1001.0


def test_bench_cli_without_sim_and_tqdm(tmp_path):
    out = tmp_path / "b.json"
    code = ("import sys; sys.modules['track3d_sim'] = None; sys.modules['tqdm'] = None; sys.modules['torch'] = None;"
            "from track3d.cli import main;"
            f"sys.exit(main(['bench', '--tracker', 'kcf', '--estimator', 'baseline', '--frames', '8', "
            f"'--threads', '1', '2', '--quiet', '--out', {str(out)!r}]))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "FPS over 8 frames" in r.stdout and "end_to_end" in r.stdout
    rep = json.loads(out.read_text())
    assert [x["threads"] for x in rep["results"]] == [1, 2]
    one = rep["results"][0]
    assert one["cpus"] == machine.allowed_cpus()[:1]
    for k in ("median_ms", "p99_ms", "p99_9_ms", "max_ms"):
        assert one["stages"]["end_to_end"][k] > 0
    assert one["fps"] == pytest.approx(1e3 / one["stages"]["end_to_end"]["median_ms"])
    assert rep["machine"]["cpu"] and rep["machine"]["versions"]["onnxruntime"]
    assert set(rep["load"]) == {"busy_before", "busy_after", "loadavg_before", "loadavg_after"}


def test_bench_shipped_models_and_models_only(capsys):
    """The default bench times the default tracker's networks (EdgeTrack) and A3BoxNet; the
    paper's SiamFC is one flag away."""
    assert main(["bench", "--frames", "5", "--threads", "1", "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    kinds = {m["kind"] for m in rep["track3d"]["models"]}
    assert kinds == {"edgetrack-template", "edgetrack-search", "a3boxnet"}
    assert rep["results"][0]["stages"]["net2d"]["median_ms"] > 0
    assert main(["bench", "--frames", "5", "--threads", "1", "--models-only", "--json", "--quiet",
                 "--tracker", "siamfc-edge"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert set(rep["results"][0]["models"]) == {"siamfc-exemplar", "siamfc-search", "a3boxnet"}
    assert rep["results"][0]["models"]["siamfc-search"]["inputs"]["search"][0] >= 1


def test_busy_machine_is_warned(monkeypatch):
    monkeypatch.setattr(machine, "cpu_busy", lambda seconds=0.5: 0.9)
    rep = bench.run_bench(bench.BenchConfig("kcf", "baseline", frames=3, threads=(1,), synthetic_frames=4))
    assert any("busy" in w for w in rep["warnings"])
    monkeypatch.setattr(machine, "cpu_busy", lambda seconds=0.5: 0.0)
    rep = bench.run_bench(bench.BenchConfig("kcf", "baseline", frames=3, threads=(1,), synthetic_frames=4))
    assert not any("busy" in w for w in rep["warnings"])


def test_bench_bad_model_path_is_one_line(capsys):
    assert main(["bench", "--boxnet-model", "/nonexistent/x.onnx", "--frames", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "error" in err[0]


def test_machine_on_aarch64(monkeypatch):
    arm = ["processor\t: 0", "BogoMIPS\t: 50.00", "Features\t: fp asimd evtstrm aes pmull sha1 asimddp sve i8mm",
           "CPU implementer\t: 0x41", "CPU part\t: 0xd0c"]
    monkeypatch.setattr(machine, "_cpuinfo", lambda: arm)
    assert machine.isa_flags() == ["asimd", "asimddp", "sve", "i8mm"]
    assert "0xd0c" in machine.cpu_name()
    monkeypatch.setattr(machine, "_cpuinfo", lambda: [])
    assert machine.isa_flags() == [] and machine.cpu_name()


def test_synthetic_frames_have_the_target():
    from track3d.camera import Camera

    cam = Camera.from_fov(160, 120, 45.0)
    fr = bench.synthetic_frames(cam, 3)
    img, pts, box = fr[0]
    assert img.shape == (120, 160, 3) and img.dtype == np.uint8 and len(pts) > 100
    assert box[2] > 5 and box[3] > 5


def test_bench_times_a_stereo_camera_s_loop_from_the_package_alone(capsys):
    """--depth stereo: the synthetic sphere is also seen from the right camera (the same surface
    texture, so the pair matches: its stereo cloud lies on the sphere), and the loop matches the
    pair inside each update with the stereo loop options and model."""
    from track3d.camera import Camera
    from track3d.stereo import StereoCloud

    cam = Camera.from_fov(640, 480, 45.0)
    img, right, box = bench.synthetic_frames(cam, 2, stereo=True)[0]
    assert right.shape == img.shape and right.dtype == np.uint8 and not np.array_equal(right, img)
    pts = StereoCloud(cam).bind(img, right)(box)
    r = np.linalg.norm(pts - np.array([-1.5, 0.8, 22.0]), axis=1)   # the first frame's sphere, radius 2 m
    assert len(pts) > 1000 and np.median(np.abs(r - 2.0)) < 0.15
    assert main(["bench", "--depth", "stereo", "--frames", "4", "--threads", "1", "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["source"]["depth"].startswith("stereo from the pair")
    assert SENSOR_MODELS["stereo"] in [m["file"] for m in rep["track3d"]["models"]]
    assert rep["track3d"]["options"]["outline_contain"] is True          # stereo's loop options
    assert rep["results"][0]["statuses"] == {"tracking": 4}
    assert rep["source"]["stereo"]["max_match_px"] == 0                 # the matcher's settings, recorded
    m = rep["results"][0]["matching"]          # the matching inside the frustum stage, and its price here
    assert set(m["ms"]) == set(rep["results"][0]["stages"]["frustum"])       # timed like a stage
    assert m["cost_median"] > 0 and m["dropped"] == 0 and m["price"]["updates"] == 4
    assert m["price"]["ns_per_unit"] > 0 and set(m["price"]["budget_for_ms"]) == {"5", "10", "20"}
    assert main(["bench", "--depth", "stereo", "--frames", "4", "--threads", "1", "--quiet"]) == 0
    out = capsys.readouterr().out
    # the budgets depend on this machine's timings: on a loaded one (CI beside other jobs) the p99
    # above the price passes every deadline and each reads "none fits"
    assert "stereo matching" in out and "ns per unit of cost" in out
    assert "max_match_cost=" in out or out.count("none fits") == 3


def test_the_price_of_a_unit_of_matching_cost_by_hand():
    """bench.matching_price: ms = price x cost by least squares; the budget for a deadline leaves
    room for the p99 of the times above that price."""
    p = bench.matching_price([1e6, 2e6, 3e6, 4e6], [2.0, 4.0, 6.0, 8.0])    # 2 ns a unit, exactly
    assert p["updates"] == 4 and p["ns_per_unit"] == pytest.approx(2.0) and p["above_p99_ms"] == pytest.approx(0.0)
    assert p["budget_for_ms"] == {"5": 2_500_000, "10": 5_000_000, "20": 10_000_000}
    p = bench.matching_price([1e6, 2e6, 3e6, 4e6], [2.0, 4.0, 6.0, 9.0])
    b = 64e6 / 30e12                                          # sum(c t) / sum(c c), ms a unit
    assert p["ns_per_unit"] == pytest.approx(b * 1e6)
    r = np.array([2.0, 4.0, 6.0, 9.0]) - b * np.array([1e6, 2e6, 3e6, 4e6])
    assert p["above_p99_ms"] == pytest.approx(np.percentile(r, 99)) and 0.4 < p["above_p99_ms"] < 0.47
    assert p["budget_for_ms"]["10"] == int((10 - p["above_p99_ms"]) / b)
    for costs, ms in (([], []), ([5e6], [6.0]), ([0, 0, 0], [0.1, 0.1, 0.2])):   # nothing to price
        q = bench.matching_price(costs, ms)
        assert q["ns_per_unit"] is None and q["budget_for_ms"] == {"5": None, "10": None, "20": None}
    q = bench.matching_price([1e6, 2e6], [30.0, 30.0])   # 1.8e-5 ms a unit, 12 ms above it once
    assert q["ns_per_unit"] == pytest.approx(18.0) and q["above_p99_ms"] == pytest.approx(12 - 0.01 * 18)
    assert q["budget_for_ms"]["5"] is None and q["budget_for_ms"]["10"] is None    # the margin alone is more
    assert q["budget_for_ms"]["20"] == int((20 - q["above_p99_ms"]) / 1.8e-5)


def test_bench_takes_the_stereo_matcher_s_settings(capsys):
    """--stereo-option KEY=VALUE sets the matcher of --depth stereo (e.g. binned rows), recorded in
    the report; a key that is no setting, or the option without --depth stereo: one line, status 2."""
    assert main(["bench", "--depth", "stereo", "--stereo-option", "max_match_px=1024", "--frames", "3",
                 "--threads", "1", "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["source"]["stereo"]["max_match_px"] == 1024 and rep["results"][0]["frames"] == 3
    for bad, why in ((["--depth", "stereo", "--stereo-option", "rows=2"], "unknown --stereo-option rows"),
                     (["--stereo-option", "max_match_px=1024"], "add --depth stereo"),
                     (["--depth", "stereo", "--stereo-option", "max_match_px=-1"], "max_match_px must be")):
        assert main(["bench", *bad, "--frames", "2", "--threads", "1", "--quiet"]) == 2
        err = capsys.readouterr().err.strip()
        assert why in err and len(err.splitlines()) == 1


def test_bench_on_a_dataset(tmp_path, capsys):
    from track3d.synthetic import make_synthetic_dataset

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 5})
    assert main(["bench", "--tracker", "kcf", "--estimator", "baseline", "--data", str(root), "--frames", "6",
                 "--threads", "1", "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["source"]["kind"] == "dataset" and rep["results"][0]["frames"] == 6
    assert main(["bench", "--data", str(tmp_path / "none"), "--frames", "2"]) == 2
    assert "no dataset" in capsys.readouterr().err
    # a sequence folder as --data names `--sequence`, which bench now takes too
    assert main(["bench", "--data", str(root / "test" / "a"), "--frames", "2"]) == 2
    assert "--sequence a" in capsys.readouterr().err
    assert main(["bench", "--tracker", "kcf", "--estimator", "baseline", "--data", str(root), "--sequence", "a",
                 "--frames", "3", "--threads", "1", "--json", "--quiet"]) == 0
    assert json.loads(capsys.readouterr().out)["source"]["sequences"] == ["a"]


def test_edgetrack_gets_the_rows_thread_count():
    """`track3d bench --tracker edgetrack --threads 1 2` timed EdgeTrack's networks at 1 thread
    in both rows (only SiamFC got the row's threads)."""
    pytest.importorskip("track3d.edgetrack")
    from track3d.camera import Camera
    from track3d.trackers2d import TrackerUnavailable

    try:
        t3d = bench._build(bench.BenchConfig("edgetrack", "baseline"), Camera.from_fov(160, 120, 45.0), 2)
    except TrackerUnavailable:
        pytest.skip("no shipped EdgeTrack")
    assert [m.threads for m in bench._onnx_models(t3d.tracker2d)] == [2, 2]


def test_bench_mistakes_fail_before_timing(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(bench, "_time_loop", lambda *a: pytest.fail("timed before refusing"))
    # a folder as --out used to fail only after the whole run
    assert main(["bench", "--tracker", "kcf", "--estimator", "baseline", "--out", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is a folder" in err[0]
    # --models-only of a pair without networks printed an empty table, exit 0
    assert main(["bench", "--tracker", "kcf", "--estimator", "baseline", "--models-only", "--threads", "1",
                 "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "run no ONNX network" in err[0]


def test_bench_reads_the_models_counters_and_wraps_nothing(monkeypatch):
    """--models-only used to replace each model's run() by a timing wrapper (left on the models
    the bench built); the run_ms counters and OnnxModel.keep_feeds give the same without it."""
    pytest.importorskip("track3d.siamfc")
    built = []
    build = bench._build
    monkeypatch.setattr(bench, "_build", lambda *a: built.append(build(*a)) or built[-1])
    rep = bench.run_bench(bench.BenchConfig(frames=3, threads=(1,), synthetic_frames=4, models_only=True))
    models = [m for t in built for part in (t.tracker2d, t.estimator) for m in bench._onnx_models(part)]
    assert models and not [m for m in models if "run" in vars(m)]
    assert all(m.run_ms > 0 and m.first_feeds for m in models)
    row = rep["results"][0]["models"]
    assert row["a3boxnet"]["inputs"] == {k: list(v.shape) for k, v in built[0].estimator.model.first_feeds.items()}


def test_an_unknown_name_is_refused_before_any_frame_is_made(capsys, monkeypatch):
    # it had been refused only after "synthesising 60 frames"
    made = []
    monkeypatch.setattr(bench, "synthetic_frames", lambda *a, **k: made.append(1) or [])
    for flag in ("--tracker", "--estimator"):
        assert main(["bench", flag, "nosuch", "--frames", "2", "--threads", "1"]) == 2
        err = capsys.readouterr().err
        assert "unknown" in err and "'nosuch'" in err
    assert not made


def test_the_table_says_what_it_measured(tmp_path, capsys):
    from track3d.synthetic import make_synthetic_dataset

    # the frames are taken from the first sequences until there are 100: the table names those
    root = make_synthetic_dataset(tmp_path / "ds", {"a": 60, "b": 60, "c": 60})
    assert main(["bench", "--tracker", "kcf", "--estimator", "baseline", "--data", str(root), "--frames", "4",
                 "--threads", "1", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "split test, sequences a b\n" in out and "FPS = 1000 / the median end-to-end ms" in out
    assert main(["bench", "--tracker", "kcf", "--estimator", "baseline", "--data", str(root), "--frames", "4",
                 "--threads", "1", "--quiet", "--sequence", "c", "b", "a"]) == 0
    assert "sequences c b\n" in capsys.readouterr().out
    rep = {"mode": "loop", "machine": {"cpu": "c", "arch": "x", "logical_cpus": 2, "isa": [], "versions": {}},
           "source": {"kind": "synthetic"}, "track3d": {}, "warnings": [],
           "load": {"busy_before": 0, "busy_after": 0, "loadavg_before": [0], "loadavg_after": [0]},
           "results": [{"threads": 1, "cpus": [0], "fps": 1.0, "frames": 1,
                        "stages": {k: {"median_ms": 1.0, "p99_ms": 1.0, "p99_9_ms": 1.0, "max_ms": 1.0}
                                   for k in ("track2d", "net2d", "box3d", "net3d", "end_to_end")}}]}
    text = bench.format_table(rep)
    assert "  net2d (in track2d)" in text and "  net3d (in box3d)" in text   # parts, not addends
