"""bench_table2's record: the paths it names are relative to its output folder (an absolute
--out once put the machine's folders into a committed table2.json)."""
from __future__ import annotations

import json

from benchlib.output import relative_to


def test_relative_to_hand_case(tmp_path):
    assert relative_to(tmp_path / "out" / "report" / "report.json", tmp_path / "out") == "report/report.json"
    assert relative_to(tmp_path / "x.png", tmp_path / "out") == "../x.png"


def test_table2_record_names_no_absolute_path(tiny_dataset, tmp_path):
    import bench_table2

    out = tmp_path / "t2"
    rc = bench_table2.main(["--data", str(tiny_dataset), "--variants", "edge", "--no-ope", "--trackers", "edgetrack",
                            "--sweep-estimators", "a3boxnet", "--max-sequences", "1", "--max-frames", "4",
                            "--out", str(out), "--quiet"])
    assert rc == 0
    rec = json.loads((out / "table2.json").read_text())
    assert rec["reports"] and all(not p.startswith("/") and str(tmp_path) not in p for p in rec["reports"].values())
    assert all(not p.startswith("/") for p in rec["plots"])
    assert (out / rec["reports"]["main"]).is_file()


def _sweep_rows(points):
    """Sweep rows and run scores (only what the Fig. 15 / 16 plots read) of (tracker, ao_2d, ao_3d, ao_bev)."""
    import types

    import numpy as np
    from track3d.evaluation.metrics import CE3D_THRESHOLDS, IOU_THRESHOLDS

    rows, overall = [], {}
    for tracker, ao2, ao3, bev in points:
        run = f"{tracker}+a3boxnet"
        rows.append({"tracker": tracker, "estimator": "a3boxnet", "run": run, "status": "ok",
                     "metrics": {"ao_2d": ao2, "ao_3d": ao3, "ao_bev": bev, "ace_3d": 0.4}})
        t = np.asarray(IOU_THRESHOLDS)
        overall[run] = types.SimpleNamespace(curves={"success_3d": (t <= ao3).astype(float),
                                                     "precision_3d": np.ones(len(CE3D_THRESHOLDS))})
    return rows, overall


def test_fig16_equal_scores_side_by_side_and_nothing_cut_at_one():
    import bench_table2

    # two trackers with the same scores at AO_2d 1.0 (edgetrack and siamfc-edge on easy frames)
    shift = bench_table2._dodge([(1.0, 0.891), (1.0, 0.891), (0.97, 0.83), (float("nan"), 0.5)],
                                (0.9, 1.05), (0.8, 0.95))
    assert shift[0] != shift[1] and shift[0] == -shift[1] and shift[2] == 0 and shift[3] == 0
    lo, hi = bench_table2._ao_limits([0.97, 1.0])
    assert hi > 1.0 and lo < 0.97


def test_fig15_16_layout(tmp_path, monkeypatch):
    """Fig. 15 (a)'s legend lies outside the axes (not on the curves); Fig. 16's x axis reaches past
    1.0 and its two equal markers are drawn apart."""
    import bench_table2
    from matplotlib.figure import Figure

    seen = []
    real = Figure.savefig

    def savefig(fig, path, *a, **k):
        fig.canvas.draw()
        seen.append((str(path), fig))
        return real(fig, path, *a, **k)

    monkeypatch.setattr(Figure, "savefig", savefig)
    rows, overall = _sweep_rows([("edgetrack", 1.0, 0.891, 0.913), ("siamfc-edge", 1.0, 0.891, 0.913),
                                 ("kcf", 0.97, 0.83, 0.84), ("mosse", 0.9, 0.7, 0.75)])
    files = bench_table2.sweep_plots(rows, overall, tmp_path, "test")
    assert [f.name for f in files] == ["fig15_sweep.png", "fig16_3d_vs_2d.png"]
    (_, f15), (_, f16) = seen
    a_s = f15.axes[0]
    assert a_s.get_title() == "(a) 3D success plot"
    leg, box = a_s.get_legend().get_window_extent(), a_s.get_window_extent()
    assert leg.y1 <= box.y0   # under the panel
    ax = f16.axes[0]
    assert ax.get_xlim()[1] > 1.0 and ax.get_ylim()[1] > 0.913
    at = {}
    for c in ax.collections:   # one scatter per marker: its place on the canvas
        x, y = c.get_offset_transform().transform(c.get_offsets())[0]
        at.setdefault(round(float(y), 1), []).append(round(float(x), 1))
    assert all(len(set(xs)) == len(xs) for xs in at.values())   # no marker on top of another
