"""benchmarks/bench_range_loss.py: the bins and the summary against hand cases, and one run end to end."""
from __future__ import annotations

import json

import numpy as np
import pytest

import bench_range_loss as bench
from track3d.camera import Camera
from track3d.dataset import Dataset
from track3d.evaluation.results import SequenceResult, result_folder, write_result
from track3d.tracker import STAGES

CAM100 = Camera.from_intrinsics(100, 100, 100.0, 100.0, 50.0, 50.0)
BOX = np.array([40.0, 40.0, 20.0, 20.0])   # centred: its centre ray is the axis, 30 m range -> z 30


def test_frame_kind_hand_cases():
    # at the front face z 28 the 2D box spans 20 px x 28 / 100 = 5.6 m
    whole_near = np.array([[-2.8, -2.8, 20.0], [2.8, 2.8, 25.0]])
    whole_at_range = np.array([[-2.8, -2.8, 28.0], [2.8, 2.8, 29.8]])   # 29.8 >= 30 x 0.98
    cap = np.array([[-1.0, -1.0, 28.0], [1.0, 1.0, 29.8]])               # covers 2 / 5.6 of the box
    assert bench.frame_kind(0, np.zeros((2, 3)), BOX, CAM100, 30.0) == "none"
    assert bench.frame_kind(50, whole_near, BOX, CAM100, 30.0) == "within"
    assert bench.frame_kind(50, whole_at_range, BOX, CAM100, 30.0) == "reaches"
    assert bench.frame_kind(50, cap, BOX, CAM100, 30.0) == "cut"
    assert bench.frame_kind(50, cap, BOX, CAM100, None) == "within"      # an unlimited sensor


def test_face_errors_and_summary_hand_cases():
    # est spans z 9 .. 11, truth 9 .. 12: front 0, back -1, centre -0.5
    assert bench.face_errors(np.array([0, 0, 10.0, 1, 1, 2]), np.array([0, 0, 10.5, 1, 1, 3])) == \
        pytest.approx((0.0, -1.0, -0.5))
    rows = [("within", 1.0, (0.0, 0.0, 0.0)), ("within", 0.5, (1.0, 2.0, 3.0)), ("cut", 0.5, None)]
    s = bench.summarize(rows)
    assert s["within"] == pytest.approx({"frames": 2, "share": 2 / 3, "mean_iou_3d": 0.75, "front_z_error_m": 0.5,
                                         "back_z_error_m": 1.0, "centre_z_error_m": 1.5, "loss_share": 0.5})
    assert s["cut"]["frames"] == 1 and s["cut"]["mean_iou_3d"] == 0.5 and s["cut"]["back_z_error_m"] is None
    assert s["cut"]["loss_share"] == pytest.approx(0.5)
    assert s["none"]["frames"] == 0 and s["none"]["mean_iou_3d"] is None and s["none"]["loss_share"] == 0.0
    assert "-" in bench.table(s)
    assert bench.summarize([])["within"]["share"] == 0.0


def test_sequence_summary_and_table_hand_case():
    rows = [("within", 1.0, (0.0, 0.0, 0.0)), ("cut", 0.25, None), ("cut", 0.75, (1.0, 1.0, 1.0))]
    s = bench.sequence_summary(rows)
    assert s == {"frames": 3, "mean_iou_3d": pytest.approx(2 / 3), "loss": pytest.approx(1.0),
                 "bins": {"none": 0, "cut": 2, "reaches": 0, "within": 1}}
    assert bench.sequence_summary([])["mean_iou_3d"] is None
    text = bench.sequence_table({"0001": bench.sequence_summary(rows[:1]), "0002": s})
    lines = text.splitlines()
    assert lines[1].startswith("0002") and lines[2].startswith("0001")   # the largest loss first
    assert lines[1].split() == ["0002", "3", "0.667", "1.0", "0", "2", "0", "1"]


def test_a_run_of_the_true_boxes_has_no_loss(tiny_dataset, tmp_path, capsys):
    ds = Dataset(tiny_dataset)
    seqs = ds.sequences("test")
    for seq in seqs:
        n = len(seq)
        write_result(result_folder(tmp_path / "R", "test", "truth", seq.name),
                     SequenceResult(seq.name, seq.gt2d, seq.gt2d, seq.gt3d, np.array(["tracking"] * n, dtype=object),
                                    np.zeros(n), np.zeros(n), np.zeros((n, len(STAGES)))))
    out = tmp_path / "out"
    assert bench.main(["--data", str(tiny_dataset), "--split", "test", "--results", str(tmp_path / "R"),
                       "--tracker", "truth", "--out", str(out), "--per-sequence"]) == 0
    rec = json.loads((out / "range_loss_test_truth.json").read_text())
    bins = rec["bins"]
    labelled = sum(int((~seq.absent).sum()) for seq in seqs)
    assert sum(b["frames"] for b in bins.values()) == labelled
    assert list(rec["sequences"]) == [seq.name for seq in seqs]
    for seq in seqs:
        per = rec["sequences"][seq.name]
        assert per["frames"] == int((~seq.absent).sum()) == sum(per["bins"].values())
        assert per["loss"] == pytest.approx(0.0, abs=1e-9)
    printed = capsys.readouterr().out
    assert all(seq.name in printed for seq in seqs)
    for b in bins.values():
        if b["frames"]:
            assert b["mean_iou_3d"] == pytest.approx(1.0) and b["back_z_error_m"] == pytest.approx(0.0, abs=1e-9)
    assert not str(tmp_path) in (out / "range_loss_test_truth.json").read_text()
