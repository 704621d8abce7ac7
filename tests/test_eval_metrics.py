"""Every metric against a hand-computed case, edge cases included."""
from __future__ import annotations

import numpy as np
import pytest

from track3d.evaluation.metrics import (CE2D_THRESHOLDS, CONDITIONS, IOU_THRESHOLDS, ConditionScore, LostScore,
                                        average_scores, axis_errors_3d, bootstrap_interval, compare_paired,
                                        frame_conditions, latency_ms, past_range, precision_curve,
                                        score_conditions, score_lost, score_sequence, success_curve)


def test_success_curve_hand_case():
    got = success_curve([0.0, 0.5, 1.0], np.array([0.0, 0.5, 0.99]))
    np.testing.assert_allclose(got, [2 / 3, 1 / 3, 1 / 3])   # strictly greater than the threshold
    assert success_curve([], IOU_THRESHOLDS).shape == IOU_THRESHOLDS.shape
    assert np.all(success_curve([], IOU_THRESHOLDS) == 0)
    # The area under the success curve approximates AO (GOT-10k's identity).
    ious = np.random.default_rng(0).uniform(size=500)
    assert abs(success_curve(ious).mean() - ious.mean()) < 0.01


def test_precision_curve_hand_case():
    got = precision_curve([1.0, 5.0, np.nan], np.array([0.0, 1.0, 5.0, 10.0]))
    np.testing.assert_allclose(got, [0, 1 / 3, 2 / 3, 2 / 3])  # <= threshold; nan never counts


def test_latency_hand_case():
    # 1..100 ms: median 50.5, p99 by linear interpolation 99 + 0.01 x (100 - 99), the slowest 100
    got = latency_ms(np.arange(1.0, 101.0).reshape(10, 10))
    assert got == pytest.approx({"ms_median": 50.5, "ms_p99": 99.01, "ms_max": 100.0})
    assert latency_ms([3.0, np.nan, 5.0]) == {"ms_median": 4.0, "ms_p99": pytest.approx(4.98), "ms_max": 5.0}
    assert all(np.isnan(v) for v in latency_ms([]).values())

def _seq():
    # frame 0: init (not scored); 1: partial overlap; 2: identical 2D / disjoint 3D; 3: absent.
    pred2d = np.array([[0, 0, 10, 10], [0, 0, 10, 10], [20, 20, 4, 4], [0, 0, 1, 1]], float)
    gt2d = np.array([[0, 0, 10, 10], [5, 0, 10, 10], [20, 20, 4, 4], [50, 50, 3, 3]], float)
    pred3d = np.array([[0, 0, 10, 2, 2, 2], [0, 0, 10, 2, 2, 2], [10, 0, 10, 2, 2, 2], [0, 0, 10, 2, 2, 2]], float)
    gt3d = np.array([[0, 0, 10, 2, 2, 2], [1, 0, 10, 2, 2, 2], [0, 0, 10, 2, 2, 2], [9, 9, 9, 1, 1, 1]], float)
    scored = np.array([False, True, True, False])
    return pred2d, pred3d, gt2d, gt3d, scored


def test_score_sequence_hand_case():
    s = score_sequence("a", *_seq(), restarts=2, tracker_seconds=0.5, e2e_seconds=1.0, timed_frames=3)
    assert s.frames == 2 and s.restarts == 2
    # frame 1: 2D IoU = 50 / 150, centre error 5 px; frame 2: IoU 1, error 0.
    assert s.ao_2d == pytest.approx((1 / 3 + 1) / 2)
    assert s.sr50_2d == pytest.approx(0.5) and s.sr75_2d == pytest.approx(0.5)
    assert s.ace_2d == pytest.approx(2.5)
    # frame 1: 3D IoU = 4 / 12, BEV IoU = 2 / 6, centre error 1 m; frame 2: no overlap, 10 m.
    assert s.ao_3d == pytest.approx(1 / 6) and s.ao_bev == pytest.approx(1 / 6)
    assert s.sr50_3d == 0.0 and s.sr50_bev == 0.0
    assert s.ace_3d == pytest.approx(5.5)
    assert s.fps == pytest.approx(6.0) and s.fps_e2e == pytest.approx(3.0)
    np.testing.assert_allclose(s.curves["success_2d"][[0, 50, 100]], [1.0, 0.5, 0.0])
    np.testing.assert_allclose(s.curves["precision_2d"][[0, 4, 5]], [0.5, 0.5, 1.0])  # 0 px, 4 px, 5 px
    assert s.curves["precision_3d"][-1] == pytest.approx(0.5)  # 10 m is beyond the 4 m axis
    # prediction - truth: frame 1 cx -1, frame 2 cx +10, every other coordinate 0
    np.testing.assert_allclose(s.bias_3d, [4.5, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(s.mae_3d, [5.5, 0, 0, 0, 0, 0])


def test_axis_errors_hand_case():
    pred = np.array([[0, 0, 11, 2, 2, 3], [0, 1, 9, 2, 2, 1], [np.nan] * 6], float)
    gt = np.array([[0, 0, 10, 2, 2, 2], [0, 0, 10, 2, 2, 2], [0, 0, 10, 2, 2, 2]], float)
    bias, mae = axis_errors_3d(pred, gt)   # the frame without a box is left out
    np.testing.assert_allclose(bias, [0, 0.5, 0, 0, 0, 0])
    np.testing.assert_allclose(mae, [0, 0.5, 1.0, 0, 0, 1.0])
    assert np.isnan(axis_errors_3d(pred[2:], gt[2:])[0]).all()
    # over sequences: each sequence weighs the same, a sequence without boxes is left out
    a = score_sequence("a", np.ones((2, 4)), pred[:2], np.ones((2, 4)), gt[:2], np.ones(2, bool))
    b = score_sequence("b", np.ones((1, 4)), np.array([[0, 0, 14, 2, 2, 2.0]]), np.ones((1, 4)), gt[:1],
                       np.ones(1, bool))
    c = score_sequence("c", np.ones((1, 4)), pred[2:], np.ones((1, 4)), gt[2:], np.ones(1, bool))
    ov = average_scores([a, b, c])
    np.testing.assert_allclose(ov.values["bias_3d"], [0, 0.25, 2.0, 0, 0, 0])
    np.testing.assert_allclose(ov.values["mae_3d"], [0, 0.25, 2.5, 0, 0, 0.5])
    assert ov.summary()["mae_3d"] == ov.values["mae_3d"]


def test_identical_boxes_score_perfectly():
    b2 = np.array([[3, 4, 5, 6]] * 3, float)
    b3 = np.array([[1, 2, 10, 1, 2, 3]] * 3, float)
    s = score_sequence("same", b2, b3, b2, b3, np.ones(3, bool))
    assert (s.ao_2d, s.ao_bev, s.ao_3d, s.sr75_3d, s.ace_2d, s.ace_3d) == (1.0, 1.0, 1.0, 1.0, 0.0, 0.0)
    assert np.all(s.curves["success_3d"][:-1] == 1.0) and s.curves["success_3d"][-1] == 0.0


def test_no_output_frames_score_zero_and_skip_the_centre_error():
    b2 = np.array([[0, 0, 10, 10], [np.nan] * 4], float)
    b3 = np.array([[0, 0, 10, 2, 2, 2], [np.nan] * 6], float)
    s = score_sequence("gap", b2, b3, np.array([[0, 0, 10, 10]] * 2, float),
                       np.array([[0, 0, 10, 2, 2, 2]] * 2, float), np.ones(2, bool))
    assert s.ao_2d == pytest.approx(0.5) and s.ao_3d == pytest.approx(0.5)
    assert s.ace_2d == 0.0 and s.ace_3d == 0.0          # over the frame that has an output
    assert s.curves["precision_2d"][0] == pytest.approx(0.5)


def test_all_frames_absent_gives_nan_and_is_left_out_of_the_average():
    p2, p3, g2, g3, _ = _seq()
    empty = score_sequence("absent", p2, p3, g2, g3, np.zeros(4, bool))
    assert empty.frames == 0 and np.isnan(empty.ao_3d) and np.isnan(empty.ace_3d)
    full = score_sequence("a", p2, p3, g2, g3, np.array([False, True, True, False]))
    ov = average_scores([full, empty])
    assert ov.sequences == 1 and ov.values["ao_2d"] == pytest.approx(full.ao_2d)


def test_average_weighs_sequences_equally():
    b2 = np.array([[0, 0, 10, 10]] * 4, float)
    b3 = np.array([[0, 0, 10, 2, 2, 2]] * 4, float)
    off = b3.copy()
    off[:, 0] = 10                                       # disjoint: IoU 0
    one = score_sequence("one", b2, b3, b2, b3, np.array([True, False, False, False]), restarts=1,
                         tracker_seconds=0.1, timed_frames=1)          # AO 1 over 1 frame
    two = score_sequence("two", b2, off, b2, b3, np.ones(4, bool), restarts=2,
                         tracker_seconds=0.3, timed_frames=3)          # AO 0 over 4 frames
    ov = average_scores([one, two])
    assert ov.values["ao_3d"] == pytest.approx(0.5)      # not 1/5: per sequence, then over sequences
    assert ov.values["ace_3d"] == pytest.approx(5.0)     # (0 + 10) / 2
    assert ov.restarts == 3 and ov.frames == 5
    assert ov.fps == pytest.approx(10.0)                 # 4 frames in 0.4 s
    np.testing.assert_allclose(ov.curves["success_3d"][0], 0.5)
    assert len(ov.curves["precision_2d"]) == len(CE2D_THRESHOLDS)


def test_length_mismatch_is_an_error():
    p2, p3, g2, g3, sc = _seq()
    with pytest.raises(ValueError, match="differ in length"):
        score_sequence("bad", p2[:3], p3, g2, g3, sc)


def test_two_d_only_scores_have_no_3d_values_and_the_same_2d_values():
    pred2d, pred3d, gt2d, gt3d, scored = _seq()
    full = score_sequence("a", pred2d, pred3d, gt2d, gt3d, scored)
    s = score_sequence("a", pred2d, None, gt2d, None, scored)
    assert s.two_d_only and not full.two_d_only
    assert (s.ao_2d, s.sr50_2d, s.sr75_2d, s.ace_2d) == (full.ao_2d, full.sr50_2d, full.sr75_2d, full.ace_2d)
    assert np.isnan([s.ao_bev, s.ao_3d, s.sr50_3d, s.ace_3d]).all()
    assert sorted(s.curves) == ["precision_2d", "success_2d"]
    assert "ao_3d" not in s.summary() and s.summary()["ao_2d"] == full.ao_2d
    assert "bias_3d" not in s.summary() and "mae_3d" not in average_scores([s]).summary()
    ov = average_scores([s, s])
    assert ov.two_d_only and "ace_3d" not in ov.summary() and ov.values["ao_2d"] == pytest.approx(s.ao_2d)
    assert not average_scores([full]).two_d_only and "ao_3d" in average_scores([full]).summary()


def test_score_lost_hand_case():
    # frames 0..4: absent at 1, 2; the tracker says lost at 1 (right) and 3 (wrong); the target
    # returns at 3, and frame 4 (within 3 frames, not lost, IoU 1) re-acquires it.
    absent = np.array([0, 1, 1, 0, 0], bool)
    lost = np.array([False, True, False, True, False])
    gt = np.tile([10.0, 10, 10, 10], (5, 1))
    s = score_lost(lost, absent, gt.copy(), gt, reacquire_frames=3)
    assert s == LostScore(lost_true=1, lost_reported=2, absent_frames=2, returns=1, reacquired=1)
    assert (s.precision, s.recall, s.reacquired_share) == (0.5, 0.5, 1.0)
    # Only 1 frame of window: frame 3 is lost, so the return is not re-acquired.
    assert score_lost(lost, absent, gt.copy(), gt, reacquire_frames=1).reacquired == 0
    # A box beside the target: IoU 20 / 180 = 0.11 <= 0.3, not re-acquired; 5 px off, IoU 1/3: it is.
    far = gt.copy()
    far[:, 0] += 8
    near = gt.copy()
    near[:, 0] += 5
    assert score_lost(lost, absent, near, gt, reacquire_frames=3).reacquired == 1
    assert score_lost(lost, absent, far, gt, reacquire_frames=3).reacquired == 0


def test_lost_scores_add_up_and_say_nan_without_a_denominator():
    a = LostScore(lost_true=1, lost_reported=2, absent_frames=4, returns=1, reacquired=0)
    b = LostScore(lost_true=2, lost_reported=2, absent_frames=0, returns=1, reacquired=1)
    t = a + b
    assert t == LostScore(3, 4, 4, 2, 1) and t.precision == 0.75 and t.recall == 0.75 and t.reacquired_share == 0.5
    assert np.isnan(LostScore().precision) and np.isnan(LostScore().recall) and np.isnan(LostScore().reacquired_share)
    assert t.summary()["lost_precision"] == 0.75 and t.summary()["returns"] == 2


def test_bootstrap_interval_hand_cases():
    # The mean of three draws from {1, 2, 3}: 1 with probability 1/27 = 0.037 (> 0.025), so the
    # 95% interval's ends are the extreme means 1 and 3; at 80%, P(mean <= 4/3) = (1 + 3) / 27 =
    # 0.148 > 0.10 > P(mean = 1): the ends are 4/3 and 8/3.
    assert bootstrap_interval([1.0, 2.0, 3.0]) == (1.0, 3.0)
    lo, hi = bootstrap_interval([3.0, 1.0, 2.0], level=0.8)
    assert lo == pytest.approx(4 / 3) and hi == pytest.approx(8 / 3)
    # nan values are left out; one value is its own interval; none gives nan
    assert bootstrap_interval([1.0, np.nan, 2.0, 3.0]) == (1.0, 3.0)
    assert bootstrap_interval([0.7]) == (0.7, 0.7)
    assert all(np.isnan(bootstrap_interval([np.nan])))
    # a fixed seed: the same numbers every time
    v = np.linspace(0.5, 0.9, 12)
    assert bootstrap_interval(v) == bootstrap_interval(v)
    lo, hi = bootstrap_interval(v)
    assert lo < v.mean() < hi
    for bad in ({"level": 1.0}, {"level": 0.0}, {"resamples": 0}):
        with pytest.raises(ValueError):
            bootstrap_interval(v, **bad)


def test_compare_paired_hand_cases():
    base = {"a": 0.5, "b": 0.6, "c": 0.7, "d": 0.8}
    # per-sequence differences +0.01, 0, -0.01 (d has no value in the run: not paired)
    p = compare_paired("ao_3d", base, {"a": 0.51, "b": 0.6, "c": 0.69, "e": 0.1})
    assert (p.sequences, p.better, p.worse) == (3, 1, 1)
    assert p.mean == pytest.approx(0.0, abs=1e-12)
    assert p.lo == pytest.approx(-0.01) and p.hi == pytest.approx(0.01)   # as the {1, 2, 3} case
    # a centre error is better when it falls: -0.1 is better, +0.004 within the margin
    q = compare_paired("ace_3d", {"a": 0.5, "b": 0.6}, {"a": 0.4, "b": 0.604})
    assert (q.better, q.worse) == (1, 0) and q.mean == pytest.approx(-0.048)
    # nothing in common: nan, no sequence moved
    r = compare_paired("ao_3d", {"a": 0.5}, {"b": 0.5})
    assert r.sequences == 0 and np.isnan(r.mean) and np.isnan(r.lo) and (r.better, r.worse) == (0, 0)
    assert set(p.summary()) == {"metric", "sequences", "mean", "lo", "hi", "better", "worse", "level", "margin"}


def test_past_range_hand_cases():
    boxes = np.array([[0, 0, 10, 2, 2, 2],      # far face at 11 m, on the optical axis
                      [3, 4, 10, 2, 2, 2],      # off axis: 11 m of depth, 11 x sqrt(1.25) = 12.30 m away
                      [0, 0, np.nan, 2, 2, 2],  # not finite
                      [0, 0, -5, 2, 2, 2]], float)   # behind the camera
    np.testing.assert_array_equal(past_range(boxes, 10.5), [True, True, False, False])
    np.testing.assert_array_equal(past_range(boxes, 12.0), [False, True, False, False])
    np.testing.assert_array_equal(past_range(boxes, 12.5), [False, False, False, False])
    np.testing.assert_array_equal(past_range(boxes, None), [False] * 4)   # an unlimited sensor


def test_frame_conditions_index_the_conditions():
    boxes = np.array([[0, 0, 10, 2, 2, 2], [0, 0, 20, 2, 2, 2]] * 2, float)
    got = frame_conditions(boxes, np.array([False, False, True, True]), 15.0)
    assert [CONDITIONS[k] for k in got] == ["whole", "past_range", "cut_by_image", "cut_and_past_range"]
    assert list(frame_conditions(boxes, np.ones(4, bool), None)) == [2, 2, 2, 2]
    with pytest.raises(ValueError):
        frame_conditions(boxes, np.ones(3, bool), 15.0)


def test_score_conditions_hand_case():
    pred2d, pred3d, gt2d, gt3d, scored = _seq()
    # frame 0 (init) and frame 3 (absent) are not scored: their conditions count nothing
    cond = np.array([0, 1, 2, 0])
    got = score_conditions(pred2d, pred3d, gt2d, gt3d, scored, cond)
    assert list(got) == list(CONDITIONS)
    assert got["whole"] == ConditionScore() and got["cut_and_past_range"] == ConditionScore()
    # frame 1: 2D IoU 1/3, 3D IoU 1/3, centre error 1 m; frame 2: 2D IoU 1, 3D IoU 0, 10 m
    assert got["past_range"] == ConditionScore(frames=1, iou_2d=pytest.approx(1 / 3), iou_3d=pytest.approx(1 / 3),
                                               ce_3d=pytest.approx(1.0), ce_3d_frames=1)
    cut = got["cut_by_image"].summary(total_frames=2)
    assert cut == {"frames": 1, "share": 0.5, "ao_2d": 1.0, "ao_3d": 0.0, "ace_3d": pytest.approx(10.0),
                   "ao_3d_lost": 0.5}
    past = got["past_range"].summary(total_frames=2)
    # the AO_3d lost by the conditions adds up to 1 - AO_3d pooled over the frames (here 1/6)
    assert past["ao_3d_lost"] + cut["ao_3d_lost"] == pytest.approx(1.0 - 1 / 6)
    none = got["whole"].summary(2)   # no frame: no mean, and nothing lost there
    assert all(np.isnan(none[k]) for k in ("ao_2d", "ao_3d", "ace_3d")) and none["ao_3d_lost"] == 0.0
    # sums add up over sequences
    both = got["past_range"] + got["cut_by_image"]
    assert both.frames == 2 and both.ce_3d == pytest.approx(11.0) and both.ce_3d_frames == 2
    # a frame without a prediction: IoU 0, no centre error; 2D only: no 3D values in the summary
    blank = pred3d.copy()
    blank[1] = np.nan
    got = score_conditions(pred2d, blank, gt2d, gt3d, scored, cond)
    assert got["past_range"].iou_3d == 0.0 and got["past_range"].ce_3d_frames == 0
    two_d = score_conditions(pred2d, None, gt2d, gt3d, scored, cond)["past_range"].summary(2, two_d_only=True)
    assert set(two_d) == {"frames", "share", "ao_2d"} and two_d["ao_2d"] == pytest.approx(1 / 3)
    with pytest.raises(ValueError):
        score_conditions(pred2d, pred3d, gt2d, gt3d, scored, cond[:3])


def test_a_2d_only_and_a_3d_sequence_are_not_averaged_together():
    """Their curves differ (a 2D-only score has no 3D curves): a KeyError ('success_bev') when the
    2D-only one came first. A sequence of a 3D run without a 3D box is scored with nan boxes."""
    b2 = np.array([[3, 4, 5, 6]] * 2, float)
    b3 = np.array([[0, 0, 10, 2, 2, 2]] * 2, float)
    two_d = score_sequence("2d", b2, None, b2, b3, np.ones(2, bool))
    three_d = score_sequence("3d", b2, b3, b2, b3, np.ones(2, bool))
    with pytest.raises(ValueError, match="2D-only and 3D"):
        average_scores([two_d, three_d])
    none = score_sequence("none", b2, np.full((2, 6), np.nan), b2, b3, np.ones(2, bool))
    ov = average_scores([none, three_d])          # a 3D run's sequence without a box: IoU 0 there
    assert ov.values["ao_3d"] == pytest.approx(0.5) and ov.sequences == 2
    assert np.isnan(ov.values["ace_3d"]) and ov.values["ace_2d"] == 0.0   # no centre there: undefined


def test_ace_over_sequences_is_undefined_when_one_has_no_box():
    """The paper's ACE averages every sequence; one without any box had been left out, so a run
    that output nothing on a hard sequence scored a better ACE (0 px here; a metrics review)."""
    gt = np.array([[0, 0, 10, 10]] * 10, float)
    good = score_sequence("B", gt, None, gt, None, np.ones(10, bool))
    off = score_sequence("C", gt + [3, 4, 0, 0], None, gt, None, np.ones(10, bool))
    none = score_sequence("D", np.full((10, 4), np.nan), None, gt, None, np.ones(10, bool))
    assert average_scores([good, off]).values["ace_2d"] == pytest.approx(2.5)    # hand: (0 + 5) / 2
    ov = average_scores([good, none])
    assert np.isnan(ov.values["ace_2d"]) and ov.values["ao_2d"] == pytest.approx(0.5)
