"""The `track3d` command: track, eval, trackers, demo; clear errors for bad input."""
from __future__ import annotations

import json

import pytest

from track3d.cli import main
from track3d.synthetic import make_synthetic_dataset


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    return make_synthetic_dataset(tmp_path_factory.mktemp("cli") / "ds", {"a": 5, "b": 4})


def test_track_then_eval(synth, tmp_path, capsys):
    """Default estimator: A3BoxNet (Track3D's default pair, as the README says)."""
    res, rep = tmp_path / "res", tmp_path / "rep"
    assert main(["track", "--data", str(synth), "--tracker", "oracle", "--results", str(res), "--quiet"]) == 0
    assert main(["track", "--data", str(synth), "--tracker", "mosse", "--sequence", "a", "--no-fusion",
                 "--results", str(res), "--video", "none", "--quiet"]) == 0
    assert (res / "test" / "oracle+a3boxnet" / "a" / "a_overlay.gif").is_file()
    assert (res / "test" / "mosse+a3boxnet-nofusion" / "a" / "a_001.txt").is_file()
    assert not (res / "test" / "mosse+a3boxnet-nofusion" / "b").exists()
    capsys.readouterr()
    # Default: every tracker in the folder, on the sequences all of them have (only "a").
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "oracle+a3boxnet" in out and "mosse+a3boxnet-nofusion" in out and "AO_3d" in out
    report = json.loads((rep / "report.json").read_text())
    assert report["sequences"] == ["a"]
    assert (rep / "success_3d.png").is_file() and (rep / "trajectory_a.png").is_file()
    # how sure the means are: each run's interval, the second against the first (sorted names)
    assert report["paired"]["baseline"] == "mosse+a3boxnet-nofusion"
    pair = report["paired"]["trackers"]["oracle+a3boxnet"]["ao_3d"]
    seqs = {n: report["trackers"][n]["sequences"]["a"]["ao_3d"] for n in report["trackers"]}
    assert pair["sequences"] == 1 and pair["mean"] == pytest.approx(seqs["oracle+a3boxnet"] - seqs["mosse+a3boxnet-nofusion"])
    assert report["trackers"]["oracle+a3boxnet"]["intervals"]["ao_3d"] == [seqs["oracle+a3boxnet"]] * 2
    assert "better" in out and "dAO_3d vs mosse+a3boxnet-nofusion" in out
    # each sequence's scores are written beside the report, printed only when asked
    per_seq = (rep / "sequences.txt").read_text().splitlines()
    assert [r.split()[:2] for r in per_seq[1:]] == [["a", "mosse+a3boxnet-nofusion"], ["a", "oracle+a3boxnet"]]
    assert per_seq[0] not in out and f"per sequence: {rep / 'sequences.txt'}" in out
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--quiet", "--no-plots",
                 "--per-sequence"]) == 0
    out = capsys.readouterr().out
    assert per_seq[0] in out and per_seq[2] in out
    # --baseline chooses the run the others are compared with
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--quiet", "--no-plots",
                 "--baseline", "oracle+a3boxnet"]) == 0
    assert "dAO_3d vs oracle+a3boxnet" in capsys.readouterr().out
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--quiet",
                 "--baseline", "nope"]) == 2
    err = capsys.readouterr().err
    assert "--baseline nope is not one of the compared runs" in err and "Traceback" not in err


def test_eval_without_matplotlib_scores_and_says_no_plots(synth, tmp_path, capsys, monkeypatch):
    """The lean install (no `plot` extra) failed its default `track3d eval` with exit 2 (a wheel
    walkthrough): the scores come first, the plots are skipped with one warning."""
    import sys

    res, rep = tmp_path / "res", tmp_path / "rep"
    assert main(["track", "--data", str(synth), "--tracker", "oracle", "--sequence", "a", "--results", str(res),
                 "--video", "none", "--quiet"]) == 0
    capsys.readouterr()
    monkeypatch.setitem(sys.modules, "matplotlib", None)   # `import matplotlib` now fails
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--quiet"]) == 0
    out = capsys.readouterr()
    assert "AO_3d" in out.out and "plot:" not in out.out
    assert sum("no plots: matplotlib is not installed" in x for x in out.err.splitlines()) == 1
    report = json.loads((rep / "report.json").read_text())
    assert any("no plots" in w for w in report["warnings"]) and not list(rep.glob("*.png"))


@pytest.mark.parametrize("argv, message", [
    (["track", "--data", "{missing}"], "no dataset"),
    (["track", "--data", "{synth}", "--sequence", "zzz"], "zzz"),
    (["track", "--data", "{synth}", "--tracker", "nope"], "unknown 2D tracker 'nope'"),
    (["track", "--data", "{synth}", "--estimator", "nope"], "unknown 3D box estimator"),
    (["track", "--data", "{synth}", "--split", "train"], "split 'train'"),
    (["track", "--data", "{synth}", "--tracker-option", "oops"], "key=value"),
    (["track", "--data", "{synth}", "--body-views-option", "nope=1"], "unknown --body-views-option nope"),
    (["track", "--data", "{synth}", "--body-views-option", "every=0"], "BodyViewsParams.every"),
    (["track", "--data", "{synth}", "--body-views-option", "cut_extent=1.5"], "BodyViewsParams.cut_extent"),
    (["track", "--data", "{synth}", "--no-body-views", "--body-views-option", "every=5"], "drop --no-body-views"),
    (["eval", "--data", "{synth}", "--results", "{missing}"], "the folder does not exist"),
])
def test_clear_errors(synth, tmp_path, capsys, argv, message):
    argv = [a.format(synth=synth, missing=tmp_path / "missing") for a in argv]
    assert main(argv + ["--quiet"]) == 2
    err = capsys.readouterr().err
    assert "error:" in err and message in err and "Traceback" not in err


def test_trackers_lists_names(capsys):
    assert main(["trackers"]) == 0
    out = capsys.readouterr().out
    assert "kcf" in out and "oracle" in out and "baseline" in out
    assert "nano needs the peer NanoTrack v2 models" in out and "TRACK3D_NANOTRACK_DIR" in out


def test_demo_on_a_tiny_simulation(tmp_path, capsys):
    pytest.importorskip("track3d_sim")
    from track3d_sim.cli import main as sim_main

    out = tmp_path / "demo"
    rc = sim_main(["demo", "--out", str(out), "--preset", "tiny", "--sequences", "1", "--frames", "4",
               "--tracker", "kcf", "--estimator", "baseline", "--quiet"])
    assert rc == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["tracker"] == "kcf" and summary["frames"] >= 1
    text = capsys.readouterr().out
    assert "AO_2d" in text and "overlay:" in text and "bias cz" in text   # where the 3D error lies
    assert list((out / "results").rglob("*_overlay.gif"))
    assert (out / "report" / "success_3d.png").is_file() and (out / "report" / "errors_3d.png").is_file()


def test_the_demo_runs_again_in_its_folder_after_a_change(tmp_path, capsys):
    """./run.sh a second time after an update refused: its results folder held a run of another
    configuration. The demo owns that folder and replaces its results."""
    pytest.importorskip("track3d_sim")
    from track3d_sim.cli import main as sim_main

    out = tmp_path / "demo"
    base = ["demo", "--out", str(out), "--preset", "tiny", "--sequences", "1", "--tracker", "kcf",
            "--estimator", "baseline", "--quiet"]
    assert sim_main(base + ["--frames", "4"]) == 0
    assert sim_main(base + ["--frames", "3"]) == 0            # another configuration of the same run
    assert json.loads((out / "summary.json").read_text())["frames_per_sequence"] == 3


def test_runtime_demo_points_to_the_simulator(tmp_path, capsys):
    """The runtime never imports the simulator: `track3d demo` says where the demo is, in one line."""
    assert main(["demo", "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err
    assert "track3d-sim demo" in err and err.count("\n") == 1
    assert not (tmp_path / "d").exists()


def test_runtime_demo_help_is_that_line(capsys):
    """`track3d demo --help` gave the error and exit 2 (a wheel walkthrough): help is not an error."""
    assert main(["demo", "--help"]) == 0
    out = capsys.readouterr()
    assert "track3d-sim demo" in out.out and out.err == ""


def test_runtime_never_imports_the_simulator_or_torch():
    import subprocess
    import sys

    code = ("import sys, track3d, track3d.cli, track3d.tracker, track3d.evaluation, track3d.bench, track3d.stereo, track3d.synthetic; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('track3d_sim', 'track3d_train', 'torch')]; "
            "print(bad); sys.exit(1 if bad else 0)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr


@pytest.mark.parametrize("flag,value,recorded,bad", [
    ("--evidence-points", "0", '"evidence_points": 0', "-1"),
    ("--hold-cut-size", "0.5", '"hold_cut_size": 0.5', "2"),
    ("--edge-pad", "0.5", '"edge_pad": 0.5', "-1"),
    ("--front-quantile", "0.01", '"front_quantile": 0.01', "0.5"),
    ("--dark-side", "0.3", '"dark_side": 0.3', "-1"),
    ("--fusion-cover", "0.2", '"fusion_cover": 0.2', "1.5"),
    ("--front-filter", "0.5,0.1", '"front_filter": [0.5, 0.1]', "0,0.1"),
    ("--section-limbs", "3,0.1,0.8", '"section_limbs": [3.0, 0.1, 0.8]', "1,2"),
    ("--silhouette", "0.25", '"silhouette": 0.25', "-1"),
])
def test_track_passes_a_loop_option_to_the_loop_and_records_it(synth, tmp_path, flag, value, recorded, bad):
    from track3d.evaluation.results import read_run_record

    res = tmp_path / "res"
    assert main(["track", "--data", str(synth), "--tracker", "mosse", "--estimator", "baseline", "--sequence", "a",
                 flag, value, "--results", str(res), "--video", "none", "--quiet"]) == 0
    rec = read_run_record(res, "test", "mosse+baseline")
    assert json.dumps(rec).count(recorded) == 1, rec
    with pytest.raises(SystemExit) as e:
        main(["track", "--data", str(synth), flag, bad])
    assert e.value.code == 2


def test_track_passes_body_views_settings_and_names_the_results_by_them(synth, tmp_path):
    """--body-views-option sets BodyViewsParams (the run record keeps them) and, without --name,
    the results go beside the default views' results, not over them."""
    from track3d.evaluation.results import read_run_record

    res = tmp_path / "res"
    assert main(["track", "--data", str(synth), "--tracker", "oracle", "--sequence", "a", "--body-views-option",
                 "cut_extent=0", "--body-views-option", "carve_views=0", "--results", str(res), "--video", "none",
                 "--quiet"]) == 0
    name = "oracle+a3boxnet-views-carve_views=0-cut_extent=0"
    assert (res / "test" / name / "a" / "a_3d_001.txt").is_file()
    views = read_run_record(res, "test", name)
    text = json.dumps(views)
    assert '"cut_extent": 0' in text and '"carve_views": 0' in text and '"every": 3' in text, text


@pytest.mark.parametrize("flag,recorded", [("--outline-contain", '"outline_contain": true'),
                                           ("--no-outline-contain", '"outline_contain": false')])
def test_track_passes_outline_contain_to_the_loop_and_records_it(synth, tmp_path, flag, recorded):
    from track3d.evaluation.results import read_run_record

    res = tmp_path / "res"
    assert main(["track", "--data", str(synth), "--tracker", "mosse", "--estimator", "baseline", "--sequence", "a",
                 flag, "--results", str(res), "--video", "none", "--quiet"]) == 0
    assert json.dumps(read_run_record(res, "test", "mosse+baseline")).count(recorded) == 1


@pytest.mark.parametrize("flags,recorded", [(["--outline-contain", "--texture-trim"], 1),
                                            (["--outline-contain", "--no-texture-trim"], 0),
                                            (["--outline-contain"], 0)])   # the synthetic set's sensor: off
def test_track_passes_texture_trim_to_the_loop_and_records_it_when_on(synth, tmp_path, flags, recorded):
    from track3d.evaluation.results import read_run_record

    res = tmp_path / "res"
    assert main(["track", "--data", str(synth), "--tracker", "mosse", "--estimator", "baseline", "--sequence", "a",
                 *flags, "--results", str(res), "--video", "none", "--quiet"]) == 0
    assert json.dumps(read_run_record(res, "test", "mosse+baseline")).count('"texture_trim": true') == recorded


@pytest.mark.parametrize("flag,recorded", [("--resume-outline", 1), ("--no-resume-outline", 0)])
def test_track_passes_resume_outline_to_the_loop_and_records_it_when_on(synth, tmp_path, flag, recorded):
    from track3d.evaluation.results import read_run_record

    res = tmp_path / "res"
    assert main(["track", "--data", str(synth), "--tracker", "mosse", "--estimator", "baseline", "--sequence", "a",
                 flag, "--results", str(res), "--video", "none", "--quiet"]) == 0
    assert json.dumps(read_run_record(res, "test", "mosse+baseline")).count('"resume_outline": true') == recorded


@pytest.mark.parametrize("flags,recorded", [(["--outline-share-phase", "90"], '"outline_share_phase": 90.0'),
                                            ([], '"outline_share_phase"'),   # the synthetic set's sensor: off
                                            (["--outline-share-phase", "180"], '"outline_share_phase"')])
def test_track_passes_outline_share_phase_to_the_loop_and_records_it_when_on(synth, tmp_path, flags, recorded):
    from track3d.evaluation.results import read_run_record
    from track3d.sensor_options import outline_share_phase_for

    res = tmp_path / "res"
    assert main(["track", "--data", str(synth), "--tracker", "mosse", "--estimator", "baseline", "--sequence", "a",
                 *flags, "--results", str(res), "--video", "none", "--quiet"]) == 0
    on = bool(flags) and flags[-1] != "180"
    assert json.dumps(read_run_record(res, "test", "mosse+baseline")).count(recorded) == int(on)
    assert outline_share_phase_for("stereo") == 90.0 and outline_share_phase_for("ideal") == 180.0
    with pytest.raises(SystemExit) as e:
        main(["track", "--data", str(synth), "--outline-share-phase", "200", "--results", str(res)])
    assert e.value.code == 2


def test_bench_times_the_arithmetic_asked_for(capsys):
    """`track3d bench --precision/--engine` (the wheel-only benchmark could not time auto, int8 or
    bf16: "unrecognized arguments"); the table names each model's engine and precision."""
    from track3d.bench import BenchConfig, _build
    from track3d.camera import Camera

    t3d = _build(BenchConfig(frames=5, threads=(1,), precision="auto"), Camera.from_fov(320, 240, 45.0), 1)
    models = t3d.describe()["models"]
    assert models and all(m["precision"] in ("fp32", "int8", "bf16") and m["reason"] for m in models)
    assert main(["bench", "--threads", "1", "--frames", "3", "--precision", "fp32", "--quiet"]) == 0
    assert "onnxruntime fp32)" in capsys.readouterr().out


@pytest.mark.parametrize("argv,needle", [
    (["--split", "test_unseen"], "needs --data"),
    (["--tracker-model", "/nonexistent-folder/x"], "no folder"),
    (["--boxnet-model", "/nonexistent.onnx"], "no such file"),
])
def test_bench_mistakes_are_named_before_any_timing(argv, needle, capsys):
    """--split without --data had been ignored (synthetic frames timed); a missing model path
    named only its parent folder."""
    assert main(["bench", "--threads", "1", "--frames", "3", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err


def test_eval_scores_the_trackers_own_boxes_on_request(synth, tmp_path, capsys):
    """With ideal depth the loop's boxes follow the depth's outline whatever the 2D tracker did (a
    tracker answering [0, 0, 10, 10] on every frame scored AO_2d 1.000, a plug-in walkthrough):
    --tracker-boxes scores the tracker's own boxes, 2D only."""
    import numpy as np

    from track3d.boxes import iou_2d
    from track3d.dataset import Dataset

    res, rep = tmp_path / "res", tmp_path / "rep"
    assert main(["track", "--data", str(synth), "--tracker", "oracle", "--sequence", "a", "--results", str(res),
                 "--video", "none", "--quiet"]) == 0
    raw = res / "test" / "oracle+a3boxnet" / "a" / "a_raw_001.txt"
    rows = np.loadtxt(raw, delimiter=",")
    rows[1:] = [0.0, 0.0, 10.0, 10.0]            # the tracker's own box: nowhere near the body
    np.savetxt(raw, rows, delimiter=",", fmt="%.4f")
    capsys.readouterr()
    assert main(["eval", "--data", str(synth), "--sequence", "a", "--results", str(res), "--out", str(rep),
                 "--quiet", "--no-plots"]) == 0
    loop = json.loads((rep / "report.json").read_text())["trackers"]["oracle+a3boxnet"]["overall"]
    assert main(["eval", "--data", str(synth), "--sequence", "a", "--results", str(res), "--out", str(rep),
                 "--quiet", "--no-plots", "--tracker-boxes"]) == 0
    out = capsys.readouterr()
    own = json.loads((rep / "report.json").read_text())
    seq = Dataset(synth).sequences("test")[0]
    want = float(np.mean(iou_2d(rows[1:], seq.gt2d[1:])))   # hand: every frame after the init
    assert own["boxes"] == "tracker's own 2D" and "ao_3d" not in own["trackers"]["oracle+a3boxnet"]["overall"]
    assert own["trackers"]["oracle+a3boxnet"]["overall"]["ao_2d"] == pytest.approx(want)
    assert loop["ao_2d"] > 0.9 and want < 0.1
    assert "the 2D trackers' own boxes" in out.err


def test_eval_writes_its_files_before_a_closed_pipe_stops_it(synth, tmp_path):
    """`track3d eval ... | head -2` stopped at the first print into the closed pipe (here a reader
    that left at once: `| true`), before it
    wrote sequences.txt (found writing this session's results); now the files come first."""
    import subprocess
    import sys

    res, rep = tmp_path / "res", tmp_path / "rep"
    assert main(["track", "--data", str(synth), "--tracker", "oracle", "--results", str(res), "--video", "none",
                 "--quiet"]) == 0
    code = ("import sys; from track3d.cli import main; sys.exit(main(['eval', '--data', sys.argv[1], '--results', "
            "sys.argv[2], '--out', sys.argv[3], '--quiet', '--no-plots']))")
    p = subprocess.run(f"{sys.executable} -c \"{code}\" {synth} {res} {rep} | true", shell=True,
                       capture_output=True, text=True, timeout=120)
    assert (rep / "report.json").is_file() and (rep / "sequences.txt").is_file()
    assert "Broken pipe" not in p.stderr and "Traceback" not in p.stderr


def test_stdout_closed_is_told_from_a_real_pipe():
    """_stdout_closed on a pipe whose reader left (POLLERR on Linux, POLLHUP on macOS / BSD) and on
    one still read."""
    import os
    import subprocess
    import sys

    code = "import sys; from track3d.cli import _stdout_closed; sys.stderr.write(str(_stdout_closed()))"
    r, w = os.pipe()
    os.close(r)                                        # the reader has gone
    p = subprocess.run([sys.executable, "-c", code], stdout=w, stderr=subprocess.PIPE, text=True, timeout=60)
    os.close(w)
    assert p.stderr.strip() == "True"
    p = subprocess.run([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                       timeout=60)
    assert p.stderr.strip() == "False"
