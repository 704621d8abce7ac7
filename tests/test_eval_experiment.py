"""The evaluation experiment end to end on a synthetic dataset: results, restarts, absent frames, report."""
from __future__ import annotations

import json

import numpy as np
import pytest

from test_loop import make_synthetic_dataset
from track3d.boxes import iou_3d
from track3d.dataset import DatasetError
from track3d.estimators import BaselineEstimator
from track3d.evaluation import Experiment, TrackerSpec
from track3d.evaluation.results import read_result
from track3d.tracker import Track3D
from track3d.trackers2d import OracleTracker


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    return make_synthetic_dataset(tmp_path_factory.mktemp("synth") / "ds", {"s0001": 8, "s0002": 6},
                                  absent={"s0001": [3]})


class _WrongAt(BaselineEstimator):
    """The baseline, except a box far away on chosen calls (to provoke restarts)."""

    def __init__(self, bad_calls):
        self.calls = 0
        self.bad = set(bad_calls)

    def estimate(self, points, category=-1):
        self.calls += 1
        b = super().estimate(points, category)
        if self.calls in self.bad:
            b = b.copy()
            b[0] += 100.0
        return b


def test_oracle_baseline_run_and_report(synth, tmp_path):
    exp = Experiment(synth, "test", tmp_path / "res", tmp_path / "rep")
    folders = exp.run(TrackerSpec("oracle", "baseline"), overlay="gif", quiet=True)
    assert [f.name for f in folders] == ["s0001", "s0002"]
    r = read_result(folders[0])
    assert len(r) == 8 and r.status[0] == "init" and r.restarts == 0
    assert (folders[0] / "s0001_overlay.gif").is_file()
    report = exp.report(["oracle+baseline"])
    data = json.loads((tmp_path / "rep" / "report.json").read_text())
    assert data["trackers"]["oracle+baseline"]["overall"]["restarts"] == 0
    seq1 = report["trackers"]["oracle+baseline"]["sequences"]["s0001"]
    assert seq1["frames"] == 6                       # 8 frames - init - 1 absent
    # The absent frame: the oracle says 'lost' there, and it never counts.
    assert r.status[3] == "lost"
    ov = report["trackers"]["oracle+baseline"]["overall"]
    assert 0.0 < ov["ao_3d"] < 1.0 and ov["ao_2d"] > 0.5 and ov["fps"] > 0
    for name in ("success_2d", "success_bev", "success_3d", "precision_2d", "precision_3d",
                 "trajectory_s0001", "trajectory_s0002"):
        assert (tmp_path / "rep" / f"{name}.png").stat().st_size > 1000


def test_restart_protocol_counts_and_reinitialises(synth, tmp_path):
    def factory(seq):
        return Track3D(seq.camera, OracleTracker(seq.gt2d, seq.absent), _WrongAt({1, 4}))  # call 1 = init

    exp = Experiment(synth, "test", tmp_path / "res", tmp_path / "rep", sequences=["s0002"])
    exp.run(factory, "wrong", quiet=True)
    r = read_result(exp.folder("wrong", "s0002"))
    # init(call 1) -> frame 0 shows the ground truth anyway; frames 1, 2 fine (calls 2, 3);
    # frame 3: call 4 is far away -> IoU 0 -> restart at frame 4 (init, call 5); frame 5 fine.
    assert list(r.status) == ["init", "tracking", "tracking", "tracking", "init", "tracking"]
    assert r.restarts == 1
    seq = exp.sequences[0]
    assert iou_3d(r.box3d[3], seq.gt3d[3]) == 0.0
    np.testing.assert_array_equal(r.box3d[4], seq.gt3d[4])
    s = exp.score("wrong")[0]
    assert s.frames == 4 and s.restarts == 1            # frames 1, 2, 3, 5
    assert s.sr50_3d <= 0.75


def test_restart_skip_leaves_frames_without_output(synth, tmp_path):
    def factory(seq):
        return Track3D(seq.camera, OracleTracker(seq.gt2d, seq.absent), _WrongAt({2}))

    exp = Experiment(synth, "test", tmp_path / "res", tmp_path / "rep", sequences=["s0002"], restart_skip=2)
    exp.run(factory, "skip2", quiet=True)
    r = read_result(exp.folder("skip2", "s0002"))
    assert list(r.status) == ["init", "tracking", "skipped", "init", "tracking", "tracking"]
    assert np.all(np.isnan(r.box3d[2]))
    s = exp.score("skip2")[0]
    assert s.frames == 4                                 # the skipped frame counts, with IoU 0


def test_max_frames_and_clear_errors(synth, tmp_path):
    exp = Experiment(synth, "test", tmp_path / "res", tmp_path / "rep", max_frames=3)
    exp.run(TrackerSpec("kcf", "baseline"), quiet=True)
    assert len(read_result(exp.folder("kcf+baseline", "s0001"))) == 3
    rep = exp.report(["kcf+baseline"], plots=False)
    assert rep["trackers"]["kcf+baseline"]["overall"]["frames"] == 4
    with pytest.raises(DatasetError, match="no dataset"):
        Experiment(tmp_path / "nowhere")
    with pytest.raises(DatasetError, match="nope"):
        Experiment(synth, "test", sequences=["nope"])
    with pytest.raises(DatasetError, match="split"):
        Experiment(synth, "train")
    with pytest.raises(FileNotFoundError, match="no results"):
        exp.report(["never-ran"], plots=False)


def test_oracle_baseline_on_the_tiny_simulated_dataset(tiny_dataset, tmp_path):
    """The whole chain on the simulator's output: finite scores, consistent files, no crash."""
    exp = Experiment(tiny_dataset, "test", tmp_path / "res", tmp_path / "rep")
    exp.run(TrackerSpec("oracle", "baseline"), quiet=True)
    exp.run(TrackerSpec("kcf", "baseline"), quiet=True)
    rep = exp.report(["oracle+baseline", "kcf+baseline"], plots=False)
    for name in ("oracle+baseline", "kcf+baseline"):
        ov = rep["trackers"][name]["overall"]
        assert ov["frames"] > 0
        for k in ("ao_2d", "ao_bev", "ao_3d"):
            assert 0.0 <= ov[k] <= 1.0
        assert ov["ace_3d"] >= 0.0 and ov["restarts"] >= 0
    # The oracle's raw 2D output is the label itself on every tracked frame where the target is present.
    seq = exp.sequences[0]
    r = read_result(exp.folder("oracle+baseline", seq.name))
    present = r.tracked & ~seq.absent[:len(r)]
    np.testing.assert_allclose(r.box2d_raw[present], seq.gt2d[:len(r)][present], atol=1e-4)
