"""Result folders written by another tracker than ours (a researcher's own scripts): what `track3d
eval` scores, and what it refuses in one line instead of a silently wrong number."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from track3d.cli import main
from track3d.dataset import Dataset
from track3d.evaluation import Experiment, TrackerSpec
from track3d.evaluation.experiment import labels_digest
from track3d.evaluation.results import SequenceResult, read_result, write_result
from track3d.synthetic import make_synthetic_dataset


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    return make_synthetic_dataset(tmp_path_factory.mktemp("ext") / "ds", {"s0001": 8, "s0002": 6},
                                  absent={"s0001": [3]})


def _seqs(synth):
    return Dataset(synth).sequences("test")


def _exact(synth, res, name="mine", record=None, change=None):
    """Exact ground-truth results, init on the first frame, the rest 'tracking'; change(seq, r)
    damages them; record: the run.json to write (None: none)."""
    for seq in _seqs(synth):
        n = len(seq)
        st = np.array(["init"] + ["tracking"] * (n - 1), dtype=object)
        r = SequenceResult(seq.name, seq.gt2d.copy(), seq.gt2d.copy(), seq.gt3d.copy(), st,
                           np.full(n, 0.001), np.full(n, 0.002), np.tile([0.2, 0.2, 0.4, 0.2, 1.0], (n, 1)))
        if change is not None:
            change(seq, r)
        write_result(Path(res) / "test" / name / seq.name, r)
    if record is not None:
        (Path(res) / "test" / name / "run.json").write_text(json.dumps(record))


def _report(synth, tmp_path, name="mine", **kw):
    return Experiment(synth, "test", tmp_path / "res", tmp_path / "rep", **kw).report([name], plots=False)


def _eval_cli(synth, tmp_path, capsys):
    capsys.readouterr()
    rc = main(["eval", "--data", str(synth), "--results", str(tmp_path / "res"), "--out", str(tmp_path / "rep"),
               "--no-plots"])
    return rc, capsys.readouterr().err


# 1 ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("empty", ["s0001", "s0002"])
def test_a_sequence_without_3d_in_a_3d_run_scores_zero(synth, tmp_path, empty):
    """A sequence whose 3D file is all nan had been scored 2D only and left out of AO_3d (1.000
    instead of 0.5 here), or crashed the mean (KeyError 'success_bev')."""
    def no3d(seq, r):
        if seq.name == empty:
            r.box3d[:] = np.nan
    _exact(synth, tmp_path / "res", change=no3d)
    rep = _report(synth, tmp_path)
    ov = rep["trackers"]["mine"]["overall"]
    assert ov["sequences"] == 2 and ov["ao_3d"] == pytest.approx(0.5)   # hand: (1 + 0) / 2
    assert rep["trackers"]["mine"]["sequences"][empty]["ao_3d"] == 0.0
    cond = rep["trackers"]["mine"]["conditions"]
    frames = {"s0001": 6, "s0002": 5}   # scored: 8 - init - 1 absent; 6 - init
    pooled = sum(c["ao_3d"] * c["frames"] for c in cond.values() if c["frames"])
    assert pooled == pytest.approx(frames["s0001" if empty == "s0002" else "s0002"])
    # ACE_3d had been the other sequence's alone (0 m here: outputting nothing lowered it); it is
    # undefined when a sequence has no centre, and the report says which (a metrics review)
    assert np.isnan(ov["ace_3d"]) and ov["ace_2d"] == pytest.approx(0.0)
    assert any(w.startswith("mine: ACE_3D undefined: 1 sequence(s) without a 3D box") and empty in w
               for w in rep["warnings"])


def test_a_run_without_any_3d_box_is_2d_only(synth, tmp_path):
    def no3d(seq, r):
        r.box3d[:] = np.nan
    _exact(synth, tmp_path / "res", change=no3d)
    ov = _report(synth, tmp_path)["trackers"]["mine"]["overall"]
    assert "ao_3d" not in ov and ov["ao_2d"] == pytest.approx(1.0)


# 2 ---------------------------------------------------------------------------------------------
def test_results_of_a_dataset_of_another_name_are_refused(synth, tmp_path):
    """The labels' digests matched (identical ground truth files), so a run made on another
    dataset was scored as this one's, without a word."""
    labels = {s.name: labels_digest(s) for s in _seqs(synth)}
    _exact(synth, tmp_path / "res", record={"dataset": "engine-ideal", "labels": labels})
    with pytest.raises(ValueError, match=r"'engine-ideal'.*'ds'"):
        _report(synth, tmp_path)
    _exact(synth, tmp_path / "res", record={"dataset": "ds", "labels": labels})
    assert _report(synth, tmp_path)["trackers"]["mine"]["overall"]["ao_3d"] == pytest.approx(1.0)


# 3 ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("row", ["inf,0,10,1,1,1", "1e200,0,10,1,1,1", "0,0,-inf,1,1,1"])
def test_inf_or_absurd_values_are_refused_naming_file_and_line(synth, tmp_path, capsys, row):
    _exact(synth, tmp_path / "res")
    f = tmp_path / "res" / "test" / "mine" / "s0002" / "s0002_3d_001.txt"
    lines = f.read_text().splitlines()
    lines[3] = row
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=r"s0002_3d_001.txt line 4"):
        read_result(f.parent)
    rc, err = _eval_cli(synth, tmp_path, capsys)
    assert rc == 2 and "Traceback" not in err and "RuntimeWarning" not in err
    assert err.startswith("track3d eval: error:") and "s0002_3d_001.txt line 4" in err and len(err.splitlines()) == 1


def test_a_2d_box_far_off_the_image_is_a_box_not_a_malformed_file(synth, tmp_path):
    """A review: `track3d track` writes a drifting 2D tracker's box 2e5 px off the image, and the
    1e5 bound (metres, for 3D boxes) had made the whole run unscoreable; it scores IoU 0 there.
    1e200 px is still refused (its squared centre error overflows)."""
    _exact(synth, tmp_path / "res")
    f = tmp_path / "res" / "test" / "mine" / "s0002" / "s0002_001.txt"
    lines = f.read_text().splitlines()
    lines[3] = "200160,10,20,20"
    f.write_text("\n".join(lines) + "\n")
    assert read_result(f.parent).box2d[3, 0] == 200160.0
    lines[3] = "1e200,10,20,20"
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=r"s0002_001.txt line 4"):
        read_result(f.parent)


def test_nan_stays_no_output(synth, tmp_path):
    def half(seq, r):
        if seq.name == "s0002":
            r.box3d[1::2] = np.nan
    _exact(synth, tmp_path / "res", change=half)
    seq2 = _report(synth, tmp_path)["trackers"]["mine"]["sequences"]["s0002"]
    assert seq2["ao_3d"] == pytest.approx(2 / 5)   # scored 1..5; nan on 1, 3, 5


# 4 ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("keep", [0, 3])
def test_results_shorter_than_the_labels_are_refused(synth, tmp_path, capsys, keep):
    """Empty files left the sequence out of the mean; short ones were scored on what they hold."""
    def cut(seq, r):
        if seq.name == "s0002":
            for k in ("box2d", "box2d_raw", "box3d", "status", "seconds", "e2e_seconds", "stage_ms"):
                setattr(r, k, getattr(r, k)[:keep])
    _exact(synth, tmp_path / "res", change=cut)
    with pytest.raises(ValueError, match=rf"mine/s0002: {keep} result rows, the labels have 6 frames"):
        _report(synth, tmp_path)
    rc, err = _eval_cli(synth, tmp_path, capsys)
    assert rc == 2 and len(err.splitlines()) == 1
    # with --frames the first frames are scored
    if keep:
        assert _report(synth, tmp_path, max_frames=keep)["trackers"]["mine"]["overall"]["ao_3d"] == 1.0


# 5 ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("rec", [{"restart": False}, {}, {"restart": True, "restart_skip": 1}])
def test_a_run_record_missing_fields_reads_them_as_unknown(synth, tmp_path, rec):
    _exact(synth, tmp_path / "res", record=rec)
    assert _report(synth, tmp_path)["trackers"]["mine"]["overall"]["ao_3d"] == pytest.approx(1.0)


@pytest.mark.parametrize("rec", [{"frames": 3}, {"labels": "abc"}, {"restart": "no"}, {"restart_skip": 0},
                                 {"dataset": 5}, {"max_frames": "x"}, {"frames": {"s0001": "a"}}])
def test_a_run_record_of_wrong_types_is_one_line(synth, tmp_path, capsys, rec):
    _exact(synth, tmp_path / "res", record=rec)
    rc, err = _eval_cli(synth, tmp_path, capsys)
    assert rc == 2 and "Traceback" not in err and len(err.splitlines()) == 1 and "run.json" in err


# 6 ---------------------------------------------------------------------------------------------
def test_an_init_after_the_first_frame_of_a_one_pass_run_is_refused(synth, tmp_path):
    def reinit(seq, r):
        if seq.name == "s0002":
            r.status[3] = "init"
            r.box3d[3, 0] += 50.0
    _exact(synth, tmp_path / "res", record={"restart": False}, change=reinit)
    with pytest.raises(ValueError, match=r"mine/s0002.* frame 4"):
        _report(synth, tmp_path)


def test_an_init_not_after_a_failure_or_off_the_ground_truth_is_refused(synth, tmp_path):
    # garbage at frame 4 (index 3) marked init: neither after a failure nor the ground truth
    def garbage(seq, r):
        if seq.name == "s0002":
            r.status[3] = "init"
            r.box3d[3, 0] += 50.0
    _exact(synth, tmp_path / "res", record={"restart": True, "restart_skip": 1}, change=garbage)
    with pytest.raises(ValueError, match=r"mine/s0002.* frame 4"):
        _report(synth, tmp_path)

    # the ground truth marked init with no failure before it: a free restart
    def free(seq, r):
        if seq.name == "s0002":
            r.status[3] = "init"
    _exact(synth, tmp_path / "res", record={"restart": True, "restart_skip": 1}, change=free)
    with pytest.raises(ValueError, match=r"mine/s0002.* frame 4"):
        _report(synth, tmp_path)

    # after a failure at index 2 (box far away), one skipped frame (skip 2), init on the ground truth: fine
    def restart(seq, r):
        if seq.name == "s0002":
            r.box3d[2, 0] += 50.0
            r.box2d[2, 0] += 500.0
            r.status[3] = "skipped"
            r.box2d[3] = r.box3d[3] = np.nan
            r.status[4] = "init"
    _exact(synth, tmp_path / "res", record={"restart": True, "restart_skip": 2}, change=restart)
    s2 = _report(synth, tmp_path)["trackers"]["mine"]["sequences"]["s0002"]
    assert s2["restarts"] == 1 and s2["frames"] == 4 and s2["ao_3d"] == pytest.approx(2 / 4)   # 1, 2 (0), 3 (0), 5
    # the same under skip 1: the init should have come one frame earlier
    _exact(synth, tmp_path / "res", record={"restart": True, "restart_skip": 1}, change=restart)
    with pytest.raises(ValueError, match=r"mine/s0002.* frame 5"):
        _report(synth, tmp_path)


def test_skipped_frames_score_zero_whatever_box_they_hold(synth, tmp_path):
    def skip(seq, r):
        if seq.name == "s0002":
            r.status[2] = "skipped"     # its box stays the ground truth
    _exact(synth, tmp_path / "res", record={"restart": False}, change=skip)
    s2 = _report(synth, tmp_path)["trackers"]["mine"]["sequences"]["s0002"]
    assert s2["frames"] == 5 and s2["ao_3d"] == pytest.approx(4 / 5)


# 7 ---------------------------------------------------------------------------------------------
def test_a_status_file_without_init_is_refused(synth, tmp_path):
    """No init: lost scoring was skipped ('-') and the first frame scored."""
    def noinit(seq, r):
        if seq.name == "s0001":
            r.status[0] = "tracking"
    _exact(synth, tmp_path / "res", change=noinit)
    with pytest.raises(ValueError, match=r"mine/s0001.* frame 1.*init"):
        _report(synth, tmp_path)


# 8 ---------------------------------------------------------------------------------------------
def test_only_boxes_and_status_are_needed(synth, tmp_path, capsys):
    _exact(synth, tmp_path / "res")
    for seq in _seqs(synth):
        for k in ("raw_001", "time", "e2e_time", "stages"):
            (tmp_path / "res" / "test" / "mine" / seq.name / f"{seq.name}_{k}.txt").unlink()
    rep = _report(synth, tmp_path)
    ov = rep["trackers"]["mine"]["overall"]
    assert ov["ao_3d"] == pytest.approx(1.0) and np.isnan(ov["fps"]) and np.isnan(ov["ms_p99"])
    exp = Experiment(synth, "test", tmp_path / "res", tmp_path / "rep")
    with pytest.raises(ValueError, match="raw_001"):
        exp.score("mine", raw=True)
    rc, err = _eval_cli(synth, tmp_path, capsys)
    assert rc == 0
    # a 2D-only run: no 3D file at all
    for seq in _seqs(synth):
        (tmp_path / "res" / "test" / "mine" / seq.name / f"{seq.name}_3d_001.txt").unlink()
    ov = _report(synth, tmp_path)["trackers"]["mine"]["overall"]
    assert "ao_3d" not in ov and ov["ao_2d"] == pytest.approx(1.0)


def test_the_shipped_loop_still_scores(synth, tmp_path):
    """Our own results (restarts and one pass) pass every check above."""
    for restart in (True, False):
        exp = Experiment(synth, "test", tmp_path / f"res{restart}", tmp_path / "rep", restart=restart)
        exp.run(TrackerSpec("kcf", "baseline"), quiet=True)
        rep = exp.report(["kcf+baseline"], plots=False)
        assert rep["trackers"]["kcf+baseline"]["overall"]["frames"] == 11


@pytest.mark.parametrize("text,needle", [("init\ntracking lost\ntracking\n", "line 2 holds 2 words"),
                                         ("init\n\ntracking\n", "line 2 holds no status")])
def test_a_status_file_is_one_status_a_line(tmp_path, text, needle):
    """The statuses were read with split() over the whole file: "tracking lost" on one line was
    two frames and every later status one frame late; a blank line in the middle gave a
    misleading "differ in length"."""
    from track3d.evaluation.results import read_result

    d = tmp_path / "0001"
    d.mkdir()
    (d / "0001_001.txt").write_text("1,1,2,2\n" * 3)
    (d / "0001_status.txt").write_text(text)
    with pytest.raises(ValueError, match=needle):
        read_result(d)
    (d / "0001_status.txt").write_text("init\r\ntracking\r\nlost\r\n\n")   # CRLF, a blank line at the end: fine
    assert list(read_result(d).status) == ["init", "tracking", "lost"]


def test_a_2d_box_past_the_border_is_scored_on_its_part_in_the_image(synth, tmp_path):
    """The labels are clipped to the image; a box reaching past it lost IoU for the part no label
    can hold (the GOT-10k toolkit clips to the image; a metrics review). Hand case: a box grown
    1000 px to the left scores w / (x + w), the part of it in the image, not w / (w + 1000)."""
    def grow_left(seq, r):
        r.box2d[1:, 0] -= 1000.0      # every frame but the init, which is the ground truth's
        r.box2d[1:, 2] += 1000.0
    _exact(synth, tmp_path / "res", change=grow_left)
    rep = _report(synth, tmp_path)
    for seq in _seqs(synth):
        scored = ~seq.absent & (np.arange(len(seq)) > 0)
        g = seq.gt2d[scored]
        assert g[:, 0].min() > 0          # the case: the true box off the left border
        want = float(np.mean(g[:, 2] / (g[:, 0] + g[:, 2])))
        assert rep["trackers"]["mine"]["sequences"][seq.name]["ao_2d"] == pytest.approx(want)


def test_a_2d_box_wholly_off_the_image_keeps_its_centre_error(synth, tmp_path):
    """Clipped for the IoU only (as GOT-10k): a box 2000 px off the image had been clipped to a
    sliver on the border and charged its distance from there (a review of the clipping)."""
    from track3d.boxes import center_error_2d

    def far_off(seq, r):
        r.box2d[1:, 0] -= 2000.0
    _exact(synth, tmp_path / "res", change=far_off)
    rep = _report(synth, tmp_path)
    for seq in _seqs(synth):
        scored = ~seq.absent & (np.arange(len(seq)) > 0)
        want = float(np.mean(center_error_2d(seq.gt2d[scored] - [2000.0, 0, 0, 0], seq.gt2d[scored])))
        got = rep["trackers"]["mine"]["sequences"][seq.name]
        assert got["ace_2d"] == pytest.approx(want) and want == pytest.approx(2000.0)
        assert got["ao_2d"] == 0.0


# a walkthrough with a researcher's own result files ------------------------------------------
def test_a_2d_tracker_copying_the_3d_label_on_its_init_row_is_2d_only(synth, tmp_path):
    """A 2D tracker that follows "an init row holds the ground truth" in its 3D file too, nan on
    every other frame, had been taken for a 3D run and scored AO_3d 0; a run whose record names
    a 3D estimator stays 3D whatever its rows hold (a loop whose estimator never answered)."""
    def init_only(seq, r):
        r.box3d[1:] = np.nan
    _exact(synth, tmp_path / "res", change=init_only)
    ov = _report(synth, tmp_path)["trackers"]["mine"]["overall"]
    assert "ao_3d" not in ov and ov["ao_2d"] == pytest.approx(1.0)
    _exact(synth, tmp_path / "res", change=init_only, record={"two_d": False})
    ov = _report(synth, tmp_path)["trackers"]["mine"]["overall"]
    assert ov["ao_3d"] == 0.0


def test_a_2d_tracker_through_the_loop_with_no_estimator_is_2d_only(synth, tmp_path):
    """Track3D(camera, tracker, NoEstimator()) built by hand records the estimator's class name;
    taken for a 3D estimator, its run had been scored AO_3d 0 (a review)."""
    from track3d.estimators import NoEstimator
    from track3d.tracker import Track3D
    from track3d.trackers2d import create_tracker

    exp = Experiment(synth, "test", tmp_path / "res", tmp_path / "rep")
    exp.run(lambda seq: Track3D(seq.camera, create_tracker("oracle", gt=seq.gt2d), NoEstimator()), name="kcf2d",
            quiet=True)
    rep = exp.report(["kcf2d"], plots=False)
    assert "ao_3d" not in rep["trackers"]["kcf2d"]["overall"] and not rep["warnings"][1:], rep["warnings"]


def test_an_eval_refused_on_a_bad_file_keeps_the_previous_report(synth, tmp_path, capsys):
    _exact(synth, tmp_path / "res")
    rc, _ = _eval_cli(synth, tmp_path, capsys)
    assert rc == 0
    before = (tmp_path / "rep" / "report.json").read_bytes()
    f = tmp_path / "res" / "test" / "mine" / "s0001" / "s0001_001.txt"
    f.write_text(f.read_text() + "x,y,w,h\n")
    rc, err = _eval_cli(synth, tmp_path, capsys)
    assert rc == 2 and "s0001_001.txt" in err
    assert (tmp_path / "rep" / "report.json").read_bytes() == before


def test_a_3d_run_missing_a_sequences_3d_file_says_so(synth, tmp_path):
    """A misnamed `_3D_001.txt` scored the sequence 0 in 3D (AO_3d 0.5 here) with nothing but
    "ACE_3D undefined" to say why; a folder where the file belongs had been read as no file."""
    _exact(synth, tmp_path / "res")
    folder = tmp_path / "res" / "test" / "mine" / "s0002"
    (folder / "s0002_3d_001.txt").rename(folder / "s0002_3D_001.txt")
    rep = _report(synth, tmp_path)
    assert rep["trackers"]["mine"]["overall"]["ao_3d"] == pytest.approx(0.5)
    assert any(w.startswith("mine: a 3D run, but 1 sequence(s) have no <seq>_3d_001.txt (s0002)")
               for w in rep["warnings"]), rep["warnings"]
    (folder / "s0002_3d_001.txt").mkdir()
    with pytest.raises(ValueError, match=r"s0002_3d_001.txt is not a file"):
        _report(synth, tmp_path)


@pytest.mark.parametrize("text, needle", [
    ("1 2 3 4\n", r"at line 1, column 1 \(fields are separated by commas"),
    ("1\t2\t3\t4\n", r"at line 1, column 1 \(fields are separated by commas"),
    ("1;2;3;4\n", r"'1;2;3;4' .* \(fields are separated by commas"),
    ("x,y,w,h\n1,2,3,4\n", r"'x' .*at line 1, column 1 \(a header line starts with #\)"),
    ("1,a,3,4\n", r"'a' to float64 at line 1, column 2$"),                    # a typo, not a header
    ("# a\n# b\n1,2,3,4\n1,2,3,4\n1.2.3,2,3,4\n", r"'1.2.3' to float64 at line 5, column 1$"),   # numpy: "row 2"
    ("1,2,3,4\n\n1,2,3\n", r"columns changed from 4 to 3 at line 3$"),                           # numpy: "row 2"
    ("1,2,-3,4\n", r"line 1: -3 is negative: a box's size is >= 0"),
])
def test_a_malformed_row_names_the_files_line_and_what_to_change(tmp_path, text, needle):
    """numpy's "at row R" counts from 0 past comment and blank lines (or from 1 when the column
    count changes): the file's own line instead; space-, tab- or ;-separated fields and a header
    line are named as such; a negative width (scored IoU 0 but charged a centre error) is refused."""
    from track3d.evaluation.results import _load

    f = tmp_path / "s_001.txt"
    f.write_text(text)
    with pytest.raises(ValueError, match=needle):
        _load(f, 4, 1e15, (2, 3))


def test_a_byte_order_mark_is_not_part_of_the_first_number(synth, tmp_path):
    _exact(synth, tmp_path / "res")
    for seq in _seqs(synth):
        for k in ("001", "status"):
            f = tmp_path / "res" / "test" / "mine" / seq.name / f"{seq.name}_{k}.txt"
            f.write_bytes(b"\xef\xbb\xbf" + f.read_bytes())
    assert _report(synth, tmp_path)["trackers"]["mine"]["overall"]["ao_2d"] == pytest.approx(1.0)


def test_boxes_without_a_status_file_name_the_missing_file(synth, tmp_path, capsys):
    """GOT-10k's layout (boxes only): the run had been left out with "no finished sequence", and
    a misspelt --trackers name listed nothing."""
    _exact(synth, tmp_path / "res")
    _exact(synth, tmp_path / "res", name="theirs")
    for seq in _seqs(synth):
        (tmp_path / "res" / "test" / "theirs" / seq.name / f"{seq.name}_status.txt").unlink()
    rc, err = _eval_cli(synth, tmp_path, capsys)
    assert rc == 0 and "left out theirs" in err and "has s0001_001.txt but no s0001_status.txt" in err, err
    capsys.readouterr()
    rc = main(["eval", "--data", str(synth), "--results", str(tmp_path / "res"), "--out", str(tmp_path / "rep"),
               "--no-plots", "--trackers", "mnie"])
    err = capsys.readouterr().err
    assert rc == 2 and "no folder" in err and "runs there: mine, theirs" in err and "Traceback" not in err, err


@pytest.mark.parametrize("name", ["_mine", "run$^$x", "my$run$"])
def test_a_run_named_with_dollars_or_an_underscore_is_drawn_as_written(synth, tmp_path, name):
    """matplotlib read `$...$` in a run's name as mathtext (an unbalanced one aborted the whole
    report in pyparsing's words) and left a name starting with `_` out of every legend."""
    pytest.importorskip("matplotlib")
    from track3d.evaluation import plots

    _exact(synth, tmp_path / "res", name=name)
    rep = Experiment(synth, "test", tmp_path / "res", tmp_path / "rep").report([name], plots=True)
    assert rep["plots"]
    plt = plots.pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1], label=plots._label(name))
    texts = [t.get_text() for t in ax.legend().get_texts()]
    fig.canvas.draw()
    plt.close(fig)
    assert len(texts) == 1 and texts[0].strip().replace("\\$", "$") == name
