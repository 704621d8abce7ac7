"""The A3BoxNet benchmark's report: the category ablation pairs each model trained without the
category vector with the one trained with it at the same N (paper Table 3)."""
from __future__ import annotations

import bench_boxnet as bench


def _row(name, n, ao3d, use_category=True):
    return {"name": name, "num_points": n, "AO_3d": ao3d, "AO_bev": ao3d + 0.1, "ACE_3d": 0.5 - ao3d / 10,
            "net_ms_1thread": n / 100, "model_meta": {"use_category": use_category}}


def _res():
    oracle = {"AO_bev": 0.85, "AO_3d": 0.79, "ACE_3d": 0.35, "SR50_3d": 0.98, "sequences": 2, "frames": 10}
    return {"cpu": "test cpu", "data": "d", "oracle": {"a3boxnet": oracle, "baseline": dict(oracle)},
            "ablation_points_trained": [_row("p512", 512, 0.70), _row("p1024", 1024, 0.72)],
            "ablation_other": [_row("nocat512", 512, 0.69, use_category=False), _row("w05", 512, 0.6)],
            "test_time_points": []}


def test_category_table_pairs_models_at_the_same_n():
    rows = bench._category_table(_res())
    assert rows[0] == "| ours N=512, with | p512 | 0.700 | 0.800 | 0.430 |"
    assert rows[1] == "| ours N=512, without | nocat512 | 0.690 | 0.790 | 0.431 |"
    assert "0.721" in rows[2] and "0.715" in rows[3]        # the paper's two rows close the table
    assert len(rows) == 4                                  # w05 keeps its category: not in this table


def test_other_seeds_are_averaged_with_their_spread():
    res = _res()
    res["ablation_points_trained"].append(_row("p512_s1", 512, 0.74))
    res["ablation_other"].append(_row("nocat512_s1", 512, 0.71, use_category=False))
    g = bench._group(res["ablation_points_trained"], lambda r: r["num_points"])
    assert [x[0] for x in g] == [512, 1024] and g[0][-1] == 2
    assert abs(g[0][1] - 0.72) < 1e-12 and g[0][4] == 0.70 and g[0][5] == 0.74   # mean, min, max AO_3d
    rows = bench._category_table(res)
    assert rows[0] == "| ours N=512, with | p512, p512_s1 | 0.720 | 0.820 | 0.428 |"
    assert rows[1] == "| ours N=512, without | nocat512, nocat512_s1 | 0.700 | 0.800 | 0.430 |"


def test_plot_writes_a_png(tmp_path):
    res = _res()
    res["test_time_points"] = [_row("shipped", 256, 0.7), _row("shipped", 512, 0.75)]
    bench.plot(res, tmp_path / "a.png")
    assert (tmp_path / "a.png").stat().st_size > 10_000


def test_category_table_is_absent_without_such_a_model():
    res = _res()
    res["ablation_other"] = res["ablation_other"][1:]
    assert bench._category_table(res) == []
    assert "Table 3" not in bench.markdown(res)


def test_markdown_lists_the_points_ablation_with_its_cost():
    md = bench.markdown(_res())
    assert "| p1024 | 1024 | 0.820 | 0.720 | 0.428 | 10.24 |" in md
    assert "## Category vector (paper Table 3)" in md
