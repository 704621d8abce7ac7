"""Result folders say what made them (run.json), `track3d eval` reads it, warns on unlike
comparisons, shows frames; other models get another name; IoU never exceeds 1."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from test_cli_conventions import _one_line
from track3d.boxes import iou_2d, iou_3d, iou_bev
from track3d.cli import main
from track3d.evaluation import TrackerSpec
from track3d.evaluation.metrics import success_curve
from track3d.evaluation.results import read_run_record
from track3d.synthetic import make_synthetic_dataset


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    return make_synthetic_dataset(tmp_path_factory.mktemp("rr") / "ds", {"a": 6, "b": 5})


def _track(synth, res, *extra):
    # the baseline box (fast); an --estimator in `extra` comes later and wins
    return main(["track", "--data", str(synth), "--results", str(res), "--video", "none", "--quiet",
                 "--estimator", "baseline", *extra])


def test_run_record_and_eval_read_it(synth, tmp_path, capsys):
    res, rep = tmp_path / "res", tmp_path / "rep"
    assert _track(synth, res, "--tracker", "oracle", "--restart-skip", "3") == 0
    rec = read_run_record(res, "test", "oracle+baseline")
    assert rec["track3d"]["tracker"] == "oracle" and rec["track3d"]["estimator"] == "baseline"
    assert rec["restart"] is True and rec["restart_skip"] == 3 and rec["frames"] == {"a": 6, "b": 5}
    assert rec["track3d"]["options"]["fusion"] is True and rec["versions"]["numpy"]
    assert _track(synth, res, "--tracker", "kcf", "--restart-skip", "3") == 0
    capsys.readouterr()
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--no-plots"]) == 0
    out, err = capsys.readouterr()
    assert "frames" in out.splitlines()[0] and "WARNING" not in err
    report = json.loads((rep / "report.json").read_text())
    assert report["restart_skip"] == 3 and report["trackers"]["kcf+baseline"]["restart_skip"] == 3
    assert report["trackers"]["oracle+baseline"]["run"]["frames"] == {"a": 6, "b": 5}


def test_eval_warns_on_different_frames_and_restart_settings(synth, tmp_path, capsys):
    res, rep = tmp_path / "res", tmp_path / "rep"
    assert _track(synth, res, "--tracker", "oracle") == 0
    assert _track(synth, res, "--tracker", "kcf", "--frames", "3", "--restart-skip", "2") == 0
    capsys.readouterr()
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--no-plots"]) == 0
    err = capsys.readouterr().err
    assert "different frames" in err and "different restart settings" in err
    report = json.loads((rep / "report.json").read_text())
    assert report["restart_skip"] is None and len(report["warnings"]) == 3
    assert "kcf+baseline: 2 of 2 sequences hold fewer result frames" in report["warnings"][2]
    assert report["trackers"]["kcf+baseline"]["overall"]["result_frames"] == 6


def test_other_models_get_another_name(synth, tmp_path):
    from track3d.onnxmodel import MODELS_DIR

    if not (MODELS_DIR / "a3boxnet.onnx").is_file():
        pytest.skip("no shipped A3BoxNet")
    mine = tmp_path / "a3boxnet.onnx"
    shutil.copy(MODELS_DIR / "a3boxnet.onnx", mine)
    label = TrackerSpec("oracle", "a3boxnet", estimator_options={"model": str(mine)}).label
    assert label.startswith("oracle+a3boxnet@a3boxnet-") and label != TrackerSpec("oracle", "a3boxnet").label
    res = tmp_path / "res"
    assert _track(synth, res, "--tracker", "oracle", "--estimator", "a3boxnet", "--estimator-option",
                  f"model={mine}", "--sequence", "a") == 0
    assert (res / "test" / label / "a").is_dir() and not (res / "test" / "oracle+a3boxnet").exists()


def test_same_name_other_configuration_is_refused(synth, tmp_path, capsys):
    res = tmp_path / "res"
    assert _track(synth, res, "--tracker", "oracle", "--name", "mine") == 0
    capsys.readouterr()
    assert _track(synth, res, "--tracker", "kcf", "--name", "mine") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "another configuration" in err[0]
    assert "tracker: 'oracle' -> 'kcf'" in err[0]              # what differs, named
    assert _track(synth, res, "--tracker", "oracle", "--name", "mine", "--no-restart") == 2
    assert "(restart: True -> False)" in capsys.readouterr().err
    assert _track(synth, res, "--tracker", "kcf", "--name", "mine", "--replace") == 0
    assert read_run_record(res, "test", "mine")["track3d"]["tracker"] == "kcf"
    # the same configuration again (another subset of sequences) just adds to the record
    assert _track(synth, res, "--tracker", "kcf", "--name", "mine", "--sequence", "a") == 0
    assert read_run_record(res, "test", "mine")["frames"] == {"a": 6, "b": 5}


def test_a_run_over_other_frames_never_replaces_a_full_one(synth, tmp_path, capsys):
    """A --frames 2 rerun of the same configuration silently replaced the full results (frame
    counts were not part of the configuration check)."""
    res = tmp_path / "res"
    assert _track(synth, res, "--tracker", "oracle") == 0
    status = res / "test" / "oracle+baseline" / "a" / "a_status.txt"
    before = status.read_text()
    capsys.readouterr()
    assert _track(synth, res, "--tracker", "oracle", "--frames", "2") == 2
    _one_line(capsys, "over 6 frames, this run covers 2", "--replace")
    assert status.read_text() == before and len(before.split()) == 6
    assert read_run_record(res, "test", "oracle+baseline")["frames"] == {"a": 6, "b": 5}
    # under another name it runs; with --replace it replaces, and the record says so
    assert _track(synth, res, "--tracker", "oracle", "--frames", "2", "--name", "short") == 0
    assert _track(synth, res, "--tracker", "oracle", "--frames", "2", "--sequence", "a", "--replace") == 0
    assert len(status.read_text().split()) == 2
    assert read_run_record(res, "test", "oracle+baseline")["frames"] == {"a": 2, "b": 5}
    # a --frames larger than every sequence covers the same frames as a full run
    assert _track(synth, res, "--tracker", "oracle", "--frames", "50", "--sequence", "b") == 0


def test_iou_of_a_box_with_itself_is_exactly_one():
    b2 = np.array([81.32702392002724, 91.27555772777217, 61.663577576717984, 73.94965609839984])
    b3 = np.array([0.28319671145462966, 1.2428327649956394, 6.706244146936303, 6.5718951157425005,
                   6.253851114812538, 3.9367755426188347])
    # before the clamp these gave 1.0000000000000004
    assert iou_2d(b2, b2) == 1.0 and iou_3d(b3, b3) == 1.0 and iou_bev(b3, b3) <= 1.0
    rng = np.random.default_rng(1)
    boxes = rng.random((2000, 4)) * 100 + [0, 0, 1, 1]
    assert np.all(iou_2d(boxes, boxes) <= 1.0)
    assert success_curve(np.array([iou_2d(b2, b2)]))[-1] == 0.0     # IoU > 1.0 never succeeds


@pytest.mark.parametrize("name", ["../escaped", "a/b", "..", ".", "x\\y"])
def test_a_result_name_is_one_folder(synth, tmp_path, capsys, name):
    """--name ../escaped wrote beside the results folder, a/b a folder eval never lists."""
    res = tmp_path / "res"
    with pytest.raises(SystemExit) as e:
        _track(synth, res, "--tracker", "oracle", "--name", name)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "one folder name" in err[0]
    assert not any(tmp_path.iterdir())


def test_a_sequence_named_twice_runs_once(synth, tmp_path, capsys):
    assert _track(synth, tmp_path, "--tracker", "oracle", "--sequence", "a", "a") == 0
    assert "on 1 sequence(s)" in capsys.readouterr().out


def test_every_model_file_of_an_option_is_in_the_tag(tmp_path):
    """EdgeTrack's <name>_template.onnx was not hashed: a run with another template looked like
    the same model (same result name)."""
    tags = []
    for template in (b"template one", b"template two"):
        d = tmp_path / template.decode().replace(" ", "_")
        d.mkdir()
        (d / "edge_template.onnx").write_bytes(template)
        (d / "edge_search.onnx").write_bytes(b"the same search network")
        tags += [TrackerSpec("edgetrack", "none", tracker_options={"model": str(d / "edge")}).label,
                 TrackerSpec("edgetrack", "none", tracker_options={"model": str(d / "edge_search.onnx")}).label,
                 TrackerSpec("edgetrack", "none", tracker_options={
                     "template_model": str(d / "edge_template.onnx"),
                     "search_model": str(d / "edge_search.onnx")}).label]
    assert tags[0] == tags[1] == tags[2] and tags[3] == tags[4] == tags[5]   # the same files, however named
    assert tags[0] != tags[3] and tags[0].startswith("edgetrack@edge-")


def test_eval_refuses_results_made_on_another_dataset(synth, tmp_path, capsys):
    """Results of a dataset with the same sequence names were scored against the wrong labels
    without a word (AO_3d 0.007, exit 0)."""
    other = make_synthetic_dataset(tmp_path / "other", {"a": 6, "b": 5}, radius=2.5)
    res, rep = tmp_path / "res", tmp_path / "rep"
    assert _track(other, res, "--tracker", "oracle") == 0
    capsys.readouterr()
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--no-plots"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "another dataset" in err[0] and "--data" in err[0]
    assert not (rep / "report.json").exists()
    # and `track` on this dataset does not silently replace them (unless --replace)
    assert _track(synth, res, "--tracker", "oracle") == 2
    assert "another dataset" in capsys.readouterr().err
    assert _track(synth, res, "--tracker", "oracle", "--replace") == 0
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--no-plots"]) == 0


def test_eval_frames_scores_only_the_first_frames(synth, tmp_path, capsys):
    """`track3d eval --frames N` scored every frame while report.json said max_frames N."""
    res = tmp_path / "res"
    assert _track(synth, res, "--tracker", "kcf") == 0
    reports = {}
    for frames in ("3", None):
        rep = tmp_path / f"rep{frames}"
        argv = ["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--no-plots"]
        assert main(argv + (["--frames", frames] if frames else [])) == 0
        reports[frames] = json.loads((rep / "report.json").read_text())["trackers"]["kcf+baseline"]
    # 2 sequences x frames 2..3 scored (the first is the initialisation) against 5 + 4
    assert reports["3"]["overall"]["frames"] == 4 and reports[None]["overall"]["frames"] == 9
    assert reports["3"]["overall"]["result_frames"] == 6


def test_a_failed_run_leaves_no_folder_that_stops_eval(synth, tmp_path, capsys):
    """A run that failed on a sequence left an empty result folder, and `track3d eval` of the
    whole result folder then refused every tracker in it."""
    broken = tmp_path / "broken"
    shutil.copytree(synth, broken)
    res, rep = tmp_path / "res", tmp_path / "rep"
    assert _track(broken, res, "--tracker", "oracle") == 0
    for f in (broken / "test" / "a" / "depth").iterdir():
        f.write_bytes(b"not an image")
    # with its overlay on (the overlay writer makes the folder first)
    assert main(["track", "--data", str(broken), "--results", str(res), "--quiet", "--estimator", "baseline",
                 "--tracker", "kcf", "--video", "gif"]) == 2
    assert not (res / "test" / "kcf+baseline" / "a").exists()
    capsys.readouterr()
    assert main(["eval", "--data", str(broken), "--results", str(res), "--out", str(rep), "--no-plots"]) == 0
    out, err = capsys.readouterr()
    assert "oracle+baseline" in out and "kcf+baseline" not in out


def test_restart_skip_zero_is_refused_before_any_folder(synth, tmp_path):
    with pytest.raises(SystemExit) as e:
        _track(synth, tmp_path / "res", "--restart-skip", "0")
    assert e.value.code == 2 and not (tmp_path / "res").exists()


def test_eval_says_which_sequences_it_left_out(synth, tmp_path, capsys):
    res, rep = tmp_path / "res", tmp_path / "rep"
    assert _track(synth, res, "--tracker", "oracle", "--sequence", "a") == 0
    capsys.readouterr()
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--no-plots"]) == 0
    err = capsys.readouterr().err
    assert "scored 1 of the split's 2 sequences" in err and "missing: oracle+baseline/b" in err
    assert any("scored 1 of" in w for w in json.loads((rep / "report.json").read_text())["warnings"])


def test_eval_names_a_sequence_whose_status_file_is_missing(synth, tmp_path, capsys):
    # the status file is written last and marks a finished sequence: without it (a run killed on
    # that sequence, or a damaged folder) eval scores the others and names the folder
    res, rep = tmp_path / "res", tmp_path / "rep"
    assert _track(synth, res, "--tracker", "oracle") == 0
    (res / "test" / "oracle+baseline" / "b" / "b_status.txt").unlink()
    capsys.readouterr()
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--no-plots"]) == 0
    assert "missing: oracle+baseline/b (no b_status.txt: unfinished or damaged)" in capsys.readouterr().err


def test_eval_says_when_a_run_has_no_frame_to_score(synth, tmp_path, capsys):
    # one frame a sequence is its initialisation: nothing is scored, and the table's dashes
    # had come with no word of why
    res, rep = tmp_path / "res", tmp_path / "rep"
    assert _track(synth, res, "--tracker", "oracle", "--frames", "1") == 0
    capsys.readouterr()
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--no-plots"]) == 0
    assert "oracle+baseline: no frame to score" in capsys.readouterr().err
    assert _track(synth, res, "--tracker", "oracle", "--frames", "2", "--name", "two") == 0
    capsys.readouterr()
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--no-plots",
                 "--trackers", "two"]) == 0
    assert "no frame to score" not in capsys.readouterr().err


def test_the_status_file_is_written_last(tmp_path, monkeypatch):
    from track3d.evaluation import results as R

    order = []
    real_save = R._save
    monkeypatch.setattr(R, "_save", lambda path, *a, **k: order.append(Path(path).name) or real_save(path, *a, **k))
    real_write = Path.write_text
    monkeypatch.setattr(Path, "write_text", lambda self, *a, **k: order.append(self.name) or real_write(self, *a, **k))
    n = 3
    R.write_result(tmp_path / "s", R.SequenceResult("s", np.zeros((n, 4)), np.zeros((n, 4)), np.zeros((n, 6)),
                                                     np.array(["init", "tracking", "lost"], dtype=object),
                                                     np.zeros(n), np.zeros(n), np.zeros((n, 5))))
    assert order[-1] == "s_status.txt" and len(order) == 7
    assert len(R.read_result(tmp_path / "s")) == n
    # rewriting a finished sequence: its old status file goes first, so a write killed half way
    # leaves the sequence unfinished, not the old status beside new boxes
    monkeypatch.setattr(R, "_save", lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt()))
    with pytest.raises(KeyboardInterrupt):
        R.write_result(tmp_path / "s", R.SequenceResult("s", np.ones((n, 4)), np.ones((n, 4)), np.ones((n, 6)),
                                                         np.array(["init", "tracking", "lost"], dtype=object),
                                                         np.zeros(n), np.zeros(n), np.zeros((n, 5))))
    assert not (tmp_path / "s" / "s_status.txt").exists()


@pytest.mark.parametrize("what", ["out_is_a_file", "results_is_the_split", "results_is_a_run",
                                  "results_is_a_file", "results_do_not_exist", "unknown_split"])
def test_eval_folder_mistakes_are_one_line(synth, tmp_path, capsys, what):
    res, rep = tmp_path / "res", tmp_path / "rep"
    assert _track(synth, res, "--tracker", "oracle") == 0
    if what == "out_is_a_file":
        rep.write_text("mine")
        argv, expect = ["--results", str(res), "--out", str(rep)], "is a file, not a folder"
    elif what == "results_is_the_split":
        argv, expect = ["--results", str(res / "test"), "--out", str(rep)], "--results is the folder"
    elif what == "results_is_a_run":
        argv, expect = (["--results", str(res / "test" / "oracle+baseline"), "--out", str(rep)],
                        "--trackers oracle+baseline to compare that run alone")
    elif what == "results_is_a_file":
        (tmp_path / "f.txt").write_text("x")
        argv, expect = ["--results", str(tmp_path / "f.txt"), "--out", str(rep)], "is a file, not a folder"
    elif what == "results_do_not_exist":
        argv, expect = ["--results", str(tmp_path / "nope"), "--out", str(rep)], "the folder does not exist"
    else:   # the split is wrong, not the results
        argv, expect = ["--results", str(res), "--split", "bogus", "--out", str(rep)], "split 'bogus' not in"
    capsys.readouterr()
    assert main(["eval", "--data", str(synth), "--no-plots", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expect in err[0], err
    if what == "out_is_a_file":
        assert rep.read_text() == "mine"


def test_a_reused_report_folder_keeps_no_stale_plots(synth, tmp_path):
    """`eval --out` reused for fewer sequences (or --no-plots) left the old plots beside the new
    report.json; files of the user's in that folder stay."""
    pytest.importorskip("matplotlib")
    res, rep = tmp_path / "res", tmp_path / "rep"
    assert _track(synth, res, "--tracker", "oracle") == 0
    base = ["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--quiet"]
    assert main(base) == 0
    assert (rep / "trajectory_b.png").is_file()
    (rep / "mine.png").write_bytes(b"a user's file")
    assert main(base + ["--sequence", "a"]) == 0
    assert (rep / "trajectory_a.png").is_file() and not (rep / "trajectory_b.png").exists()
    assert main(base + ["--no-plots"]) == 0
    assert not list(rep.glob("trajectory_*.png")) and not (rep / "success_3d.png").exists()
    assert (rep / "mine.png").read_bytes() == b"a user's file"


def test_a_copied_report_folder_and_a_killed_eval_leave_no_stale_report(synth, tmp_path, monkeypatch):
    """A report folder copied elsewhere listed its plots by the old folder's paths, so a new
    report there kept them; an eval killed while it drew left the old report.json (and
    sequences.txt) beside its new plots, a report that did not describe them (a kill walkthrough)."""
    import shutil

    pytest.importorskip("matplotlib")
    from track3d.evaluation import plots

    res, rep = tmp_path / "res", tmp_path / "rep"
    assert _track(synth, res, "--tracker", "oracle") == 0
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--quiet"]) == 0
    copy = tmp_path / "copy"
    shutil.copytree(rep, copy)
    base = ["eval", "--data", str(synth), "--results", str(res), "--out", str(copy), "--quiet"]
    assert main(base + ["--sequence", "a"]) == 0
    assert (copy / "trajectory_a.png").is_file() and not (copy / "trajectory_b.png").exists()

    def killed(*a, **k):
        raise KeyboardInterrupt
    monkeypatch.setattr(plots, "trajectory_plots", killed)
    with pytest.raises(KeyboardInterrupt):
        from track3d.evaluation import Experiment
        (run,) = [p.name for p in (res / "test").iterdir() if p.is_dir()]
        Experiment(synth, "test", res, rep).report([run])
    assert not (rep / "report.json").exists() and not (rep / "sequences.txt").exists()


def test_worst_sequences_hand_case():
    from types import SimpleNamespace as S

    from track3d.evaluation.plots import worst_sequences

    def run(*ao):
        return [S(name=f"s{i}", frames=0 if a is None else 5, ao_3d=a, ao_2d=0.5, two_d_only=False)
                for i, a in enumerate(ao)]
    # means over the runs: s0 0.75, s1 0.25, s2 0.5 (one run without scored frames), s3 0.25
    scores = {"x": run(0.75, 0.25, None, 0.5), "y": run(0.75, 0.25, 0.5, 0.0)}
    assert worst_sequences(scores, 3) == ["s1", "s3", "s2"]          # a tie keeps the split's order
    assert worst_sequences(scores, 0) == [] and worst_sequences({}, 2) == []
    two_d = {"x": [S(name="a", frames=3, ao_3d=float("nan"), ao_2d=0.9, two_d_only=True),
                   S(name="b", frames=3, ao_3d=float("nan"), ao_2d=0.1, two_d_only=True)]}
    assert worst_sequences(two_d, 1) == ["b"]                          # 2D-only runs: by AO_2d


def test_eval_plots_the_worst_sequences_and_ao_per_sequence(synth, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    res, rep = tmp_path / "res", tmp_path / "rep"
    assert _track(synth, res, "--tracker", "oracle") == 0
    # make b the worst: its 3D boxes far off
    f = res / "test" / "oracle+baseline" / "b" / "b_3d_001.txt"
    boxes = np.loadtxt(f, delimiter=",")
    boxes[1:, :3] += 5.0
    np.savetxt(f, boxes, delimiter=",", fmt="%.6f")
    base = ["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--quiet", "--trajectories", "1"]
    assert main(base) == 0
    assert (rep / "sequences.png").is_file() and (rep / "trajectory_b.png").is_file()
    assert not (rep / "trajectory_a.png").exists()
    assert main(base + ["--trajectories-of", "first"]) == 0
    assert (rep / "trajectory_a.png").is_file() and not (rep / "trajectory_b.png").exists()


def test_track_stopped_by_sigterm_says_so_keeps_finished_sequences_and_resumes(synth, tmp_path, capsys, monkeypatch):
    """SIGTERM (a session's end, a job scheduler) had ended `track3d track` at once, exit 143 with
    no word and the sequence being tracked half-written; it now unwinds as Ctrl-C does: the
    finished sequences stay, the half-done one leaves no folder, one line says the same command
    goes on, and it does."""
    import signal

    from track3d.evaluation import experiment

    res = tmp_path / "res"
    real = experiment.run_sequence
    calls = []

    def second_sequence_terminated(factory, seq, *a, **k):
        calls.append(seq.name)
        if len(calls) == 2:
            # the handler the console script installed, called as the signal would call it: a real
            # SIGTERM sent to the test process had killed it (exit 139) after the whole suite's
            # libraries were loaded; a real one to `track3d track` is checked by hand (exit 143)
            handler = signal.getsignal(signal.SIGTERM)
            assert callable(handler)
            handler(signal.SIGTERM, None)
        return real(factory, seq, *a, **k)

    monkeypatch.setattr(experiment, "run_sequence", second_sequence_terminated)
    before = signal.getsignal(signal.SIGTERM)
    capsys.readouterr()
    assert _track(synth, res, "--tracker", "oracle") == 143
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["track3d track: terminated (SIGTERM): the finished sequences are kept; the same command goes "
                   "on from the first unfinished one"], err
    assert signal.getsignal(signal.SIGTERM) is before   # the handler is the console script's only
    (run,) = (res / "test").iterdir()
    assert sorted(p.name for p in run.iterdir() if p.is_dir()) == ["a"]
    monkeypatch.setattr(experiment, "run_sequence", real)
    assert _track(synth, res, "--tracker", "oracle") == 0
    assert sorted(p.name for p in run.iterdir() if p.is_dir()) == ["a", "b"]


def test_a_console_script_started_with_sigterm_ignored_keeps_it_ignored():
    """terminate_as_interrupt had put its handler over an ignored SIGTERM (a job started to ignore
    it): the signal then stopped the command (a review)."""
    import signal

    from track3d.argparsing import terminate_as_interrupt

    before = signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        with terminate_as_interrupt():
            assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
        with terminate_as_interrupt():
            pass
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        with terminate_as_interrupt():
            assert signal.getsignal(signal.SIGTERM) not in (signal.SIG_DFL, signal.SIG_IGN)
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    finally:
        signal.signal(signal.SIGTERM, before)

