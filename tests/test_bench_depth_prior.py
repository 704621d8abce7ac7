"""benchmarks/bench_depth_prior.py: the score and the rules against hand cases, and a small run end to end."""
from __future__ import annotations

import json

import numpy as np
import pytest

import bench_depth_prior as bench
from track3d.range_cut import view_depth


def test_depth_score_is_the_iou_of_boxes_sharing_front_face_and_section():
    # true depths 2 and 4, guesses 1 and 4: IoU 0.5 and 1
    assert bench.depth_score(np.array([2.0, 4.0]), np.array([1.0, 4.0])) == pytest.approx(0.75)
    assert bench.depth_score(np.array([1.0]), np.array([3.0])) == pytest.approx(1 / 3)


def test_rules_hand_case():
    ext = np.array([[4.0, 1.0, 2.0], [2.0, 2.0, 1.0]])
    r = bench.rules(ext, k=2.0, a=0.5)
    assert r["mean"] == pytest.approx([2.5, 2.0])
    assert np.allclose(r["mean"], view_depth(ext[:, 0], ext[:, 1]))   # the loop's own rule
    assert r["min"] == pytest.approx([1.0, 2.0]) and r["max"] == pytest.approx([4.0, 2.0])
    assert r["geo mean"] == pytest.approx([2.0, 2.0]) and r["fitted"] == pytest.approx([4.0, 4.0])


def test_fit_finds_the_rule_that_made_the_depths():
    rng = np.random.default_rng(0)
    lat = rng.uniform(1.0, 5.0, (200, 2))
    depth = 0.8 * np.minimum(*lat.T) ** 0.7 * np.maximum(*lat.T) ** 0.3
    k, a, score = bench.fit_power_rule(np.column_stack([lat, depth]))
    assert (k, a) == pytest.approx((0.8, 0.7)) and score == pytest.approx(1.0)


def test_uniform_rotations_are_rotations():
    R = bench.uniform_rotations(np.random.default_rng(1), 5)
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3)) and np.allclose(np.linalg.det(R), 1.0)


def test_small_run_end_to_end(tmp_path):
    assert bench.main(["--bodies", "1", "--attitudes", "3", "--out", str(tmp_path)]) == 0
    rec = json.loads((tmp_path / "depth_prior.json").read_text())
    for mode in bench.ATTITUDES:
        r = rec["results"][mode]
        assert r["bodies"]["training world"] == 3 * len(bench.training_world())
        assert r["bodies"]["held-out"] == 3 * len(bench.held_out())
        s = r["scores"]["training world"]
        # the fitted rule is the best of its family on the bodies it was fitted on (min, max and the
        # geometric mean are members of the family)
        assert s["fitted"] >= max(s["min"], s["max"], s["geo mean"]) - 1e-12
        assert all(0.0 < v <= 1.0 for v in s.values())
    assert "/tmp" not in (tmp_path / "depth_prior.json").read_text().replace(str(tmp_path), "")
    assert "fitted rule" in (tmp_path / "depth_prior.md").read_text()
