"""A known first 3D box (3D single-object tracking's start): its weight and depth blend by hand,
its checks, the loop holding its depth, its state, the experiment's protocol and the CLI."""
from __future__ import annotations

import json

import numpy as np
import pytest

from track3d.cli import main
from track3d.estimators import BaselineEstimator
from track3d.evaluation import Experiment, TrackerSpec
from track3d.evaluation.results import read_result
from track3d.first_box import FIRST_BOX_FADE, check_fade, first_box_weight, with_first_depth
from track3d.frames import check_init_box3d
from track3d.synthetic import CAM, make_synthetic_dataset, render_sphere, sphere_path
from track3d.tracker import Track3D
from track3d.trackers2d import OracleTracker

FIRST = np.array([1.0, -0.5, 20.0, 4.0, 2.0, 5.0])


@pytest.mark.parametrize("sx, sy, weight", [
    (4.0, 2.0, 1.0),              # the first box's lateral extents: all of its depth
    (4.4, 2.0, 0.5),              # x 10 % wider: 1 - 0.1 / 0.2
    (4.0, 1.9, 0.75),             # y 5 % narrower: 1 - 0.05 / 0.2
    (3.6, 2.1, 0.5),              # the larger of the two changes counts (10 % in x)
    (4.0, 2.4, 0.0),              # 20 % in y: the fade's end
    (8.0, 2.0, 0.0),              # far past it: clipped at 0
    (np.nan, 2.0, 0.0),           # no box: nothing to blend
])
def test_weight_by_hand(sx, sy, weight):
    box = np.array([0.0, 0.0, 18.0, sx, sy, 3.0])
    assert first_box_weight(box, FIRST, 0.2) == pytest.approx(weight)


def test_depth_blend_by_hand_keeps_the_front_face():
    box = np.array([0.5, 0.2, 20.0, 4.4, 2.0, 3.0])           # front face at 18.5; weight 0.5
    out = with_first_depth(box, FIRST, 0.2)
    assert out[5] == pytest.approx(0.5 * 5.0 + 0.5 * 3.0)     # 4.0
    assert out[2] - out[5] / 2.0 == pytest.approx(18.5)        # the front face where it was
    assert out[2] == pytest.approx(20.5)
    assert np.array_equal(out[[0, 1, 3, 4]], box[[0, 1, 3, 4]])
    assert box[5] == 3.0                                       # a new array, the input untouched
    far = with_first_depth(np.array([0.5, 0.2, 20.0, 8.0, 2.0, 3.0]), FIRST, 0.2)
    assert far[5] == 3.0 and far[2] == 20.0                   # turned past the fade: its own depth


@pytest.mark.parametrize("box, message", [
    ([1, 2, 3, 4, 5], "6 finite numbers"),
    ([0, 0, 20, 1, np.nan, 1], "6 finite numbers"),
    ([0, 0, 20, 1, 0, 1], "sizes above 0"),
    ([0, 0, -5, 1, 1, 1], "in front of the camera"),
    ([0, 0, 1e9, 1, 1, 1], "within"),
    ("box", "6 numbers"),
    (None, "got None"),
])
def test_bad_first_boxes_are_one_line_errors(box, message):
    with pytest.raises(ValueError, match=message):
        check_init_box3d(box)


@pytest.mark.parametrize("fade", [0, -0.1, float("nan"), 11, "x", None])
def test_bad_fade(fade):
    with pytest.raises(ValueError, match="first_box_fade"):
        check_fade(fade)
    with pytest.raises(ValueError, match="first_box_fade"):
        Track3D(CAM, OracleTracker(np.zeros((1, 4))), BaselineEstimator(), first_box_fade=fade)


PATH = sphere_path(8)


def _frames():
    for c in PATH:
        img, depth, box2d, box3d = render_sphere(CAM, c, 1.5)
        yield img, CAM.backproject_depth(depth), box2d, box3d


def _tracker():
    frames = list(_frames())
    gt = np.array([f[2] for f in frames])
    return Track3D(CAM, OracleTracker(gt, np.zeros(len(gt), dtype=bool)), BaselineEstimator()), frames


def test_the_loop_holds_the_first_depth():
    """The baseline boxes the visible cap of the sphere: its depth extent is far short of the
    diameter. Given the first 3D box, the sphere's lateral extents do not change, so its depth
    holds."""
    plain, frames = _tracker()
    given, _ = _tracker()
    img, pts, b2, b3 = frames[0]
    plain.init(img, b2, points=pts)
    given.init(img, b2, points=pts, box3d=b3)
    assert np.array_equal(given.box3d, b3)
    for img, pts, _, b3 in frames[1:]:
        a, b = plain.update(img, pts).box3d, given.update(img, pts).box3d
        assert a[5] < 0.7 * b3[5]                               # the cap alone
        w = first_box_weight(b, frames[0][3])
        assert w > 0.5
        assert abs(b[5] - b3[5]) < abs(a[5] - b3[5]) / 2.0      # the first depth held
        assert b[2] - b[5] / 2.0 == pytest.approx(a[2] - a[5] / 2.0)   # the same front face


def test_a_bad_first_box_leaves_the_tracker_as_it_was():
    t, frames = _tracker()
    img, pts, b2, b3 = frames[0]
    t.init(img, b2, points=pts, box3d=b3)
    before = t.get_state()
    with pytest.raises(ValueError, match="6 finite numbers"):
        t.init(img, b2, points=pts, box3d=[0, 0, np.inf, 1, 1, 1])
    assert json.dumps(t.get_state()) == json.dumps(before)


def test_state_carries_the_first_box():
    t, frames = _tracker()
    img, pts, b2, b3 = frames[0]
    t.init(img, b2, points=pts, box3d=b3)
    t.update(*frames[1][:2])
    st = json.loads(json.dumps(t.get_state()))
    assert st["first_box"] == pytest.approx(list(b3))
    r, _ = _tracker()
    r.set_state(st)
    for img, pts, _, _ in frames[2:]:
        assert np.array_equal(t.update(img, pts).box3d, r.update(img, pts).box3d)
    st["first_box"] = [0, 0, 0, 1, 1, 1]
    with pytest.raises(ValueError, match="damaged Track3D state"):
        r.set_state(st)


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    return make_synthetic_dataset(tmp_path_factory.mktemp("first") / "ds", {"s0001": 6, "s0002": 5})


def test_experiment_hands_the_ground_truth_box_at_each_start(synth, tmp_path):
    given = []

    class Spy(Track3D):
        def init(self, image, box2d, category=-1, points=None, box3d=None):
            given.append(None if box3d is None else np.array(box3d))
            super().init(image, box2d, category, points=points, box3d=box3d)

    def factory(seq):
        return Spy(seq.camera, OracleTracker(seq.gt2d, seq.absent), BaselineEstimator())

    Experiment(synth, "test", tmp_path / "a", sequences=["s0001"]).run(factory, "plain", quiet=True)
    assert given == [None]
    given.clear()
    exp = Experiment(synth, "test", tmp_path / "b", sequences=["s0001"], init_3d=True)
    exp.run(factory, "given", quiet=True)
    assert len(given) == 1 and np.allclose(given[0], exp.sequences[0].gt3d[0])
    rec = json.loads((tmp_path / "b" / "test" / "given" / "run.json").read_text())
    assert rec["init_3d"] is True
    plain = json.loads((tmp_path / "a" / "test" / "plain" / "run.json").read_text())
    assert "init_3d" not in plain


def test_cli_names_the_protocol_apart_and_warns_when_compared(synth, tmp_path, capsys):
    res = tmp_path / "res"
    base = ["track", "--data", str(synth), "--tracker", "oracle", "--estimator", "baseline", "--results", str(res),
            "--video", "none", "--quiet"]
    assert main(base) == 0
    assert main(base + ["--init-3d"]) == 0
    assert main(base + ["--init-3d", "--first-box-fade", "0.4", "--name", "fade"]) == 0
    plain = read_result(res / "test" / "oracle+baseline" / "s0001")
    given = read_result(res / "test" / "oracle+baseline-init3d" / "s0001")
    gt = np.loadtxt(synth / "test" / "s0001" / "groundtruth_3d.txt", delimiter=",")
    err = lambda r: np.abs(r.box3d[1:, 5] - gt[1:, 5]).mean()   # noqa: E731
    assert err(given) < err(plain) / 2.0
    rec = json.loads((res / "test" / "fade" / "run.json").read_text())
    assert rec["init_3d"] is True and rec["first_box_fade"] == 0.4
    capsys.readouterr()
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(tmp_path / "rep"),
                 "--no-plots", "--quiet"]) == 0
    assert "another protocol" in capsys.readouterr().err


@pytest.mark.parametrize("extra, message", [
    (["--first-box-fade", "0.3"], "needs --init-3d"),
    (["--init-3d", "--first-box-fade", "0"], "--first-box-fade"),
])
def test_cli_errors(synth, tmp_path, capsys, extra, message):
    argv = ["track", "--data", str(synth), "--tracker", "oracle", "--results", str(tmp_path / "r"), "--quiet"]
    try:
        rc = main(argv + extra)
    except SystemExit as e:      # argparse's own check of the flag's value
        rc = e.code
    assert rc == 2
    err = capsys.readouterr().err
    assert "error:" in err and message in err and "Traceback" not in err


def test_the_fades_are_the_measured_ones():
    from track3d.sensor_options import first_box_fade_for, sensor_options

    # chosen on calibration sets (track3d.sensor_options.SENSOR_FIRST_BOX_FADES)
    assert FIRST_BOX_FADE == 0.2 == first_box_fade_for("ideal") == first_box_fade_for(None)
    assert first_box_fade_for("Stereo") == sensor_options("stereo")["first_box_fade"] == first_box_fade_for("tof") == 0.5
    spec = TrackerSpec("oracle", "baseline")
    assert spec.sensor_options("stereo")["first_box_fade"] == 0.5
    assert TrackerSpec("oracle", "baseline", first_box_fade=0.3).sensor_options("stereo")["first_box_fade"] == 0.3
