"""Cosmetics of the project's plots that a user reported: labels and legend entries that said
the wrong thing (checked on the figure objects, not on pixels)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402


def _legend_texts(ax):
    leg = ax.get_legend()
    return [t.get_text() for t in leg.get_texts()] if leg is not None else []


def _history(n_steps, batch=16):
    terms = {"center1": 1.0, "center2": 0.5, "size_cls": 0.3, "size_res": 0.2, "total": 2.0}
    return {"config": {"batch": batch},
            "steps": [{"step": 10 * (i + 1), **terms} for i in range(n_steps)],
            "epochs": [{"epoch": 1, "step": 10 * n_steps, "train": terms,
                        "val": {"loss": 2.1, "AO_3d": 0.4, "AO_bev": 0.45, "ACE_3d": 1.2}}]}


def test_loss_curve_labels_the_runs_batch_and_no_mean_of_one():
    from track3d_train.boxnet.train import history_figure

    fig = history_figure(_history(5, batch=16))
    try:
        ax = fig.axes[0]
        assert ax.get_xlabel() == "step (batch 16)"
        texts = _legend_texts(ax)
        assert "train" in texts and not any("mean of" in t for t in texts)
        assert "train (per logged step)" not in texts      # one line for the steps, not two alike
    finally:
        plt.close(fig)


def test_loss_curve_long_run_keeps_the_running_mean():
    from track3d_train.boxnet.train import history_figure

    fig = history_figure(_history(200, batch=32))
    try:
        ax = fig.axes[0]
        assert ax.get_xlabel() == "step (batch 32)"
        texts = _legend_texts(ax)
        assert "train (per logged step)" in texts and "train (mean of 4)" in texts
    finally:
        plt.close(fig)


def test_loss_curve_without_config_says_step():
    from track3d_train.boxnet.train import history_figure

    h = _history(3)
    del h["config"]
    fig = history_figure(h)
    try:
        assert fig.axes[0].get_xlabel() == "step"
    finally:
        plt.close(fig)


def _stats(n_dn, n_seq=4, n_points_only=0):
    import numpy as np

    return {"object_dn": np.full(n_dn, 40.0), "irradiance": np.full(n_seq, 0.2), "n_seq": n_seq,
            "n_points_only": n_points_only}


def test_stats_panel_d_points_only_is_a_note_not_empty_axes():
    from track3d_sim.stats import illumination_panel

    fig, ax = plt.subplots()
    try:
        illumination_panel(ax, _stats(0, n_seq=4, n_points_only=4))
        assert not ax.axison and ax.get_legend() is None and len(fig.axes) == 1   # no twin axis either
        texts = [t.get_text() for t in ax.texts]
        assert len(texts) == 1 and "no illumination data" in texts[0] and "points-only" in texts[0]
    finally:
        plt.close(fig)


def test_stats_panel_d_with_images_keeps_its_histograms():
    from track3d_sim.stats import illumination_panel

    fig, ax = plt.subplots()
    try:
        illumination_panel(ax, _stats(100))
        assert ax.axison and not ax.texts and len(fig.axes) == 2
        assert _legend_texts(ax) == ["mean object value / frame"]
    finally:
        plt.close(fig)


def test_conditions_label_is_the_tables_share_not_one_runs():
    from track3d.evaluation.plots import condition_label

    # the table prints each run's share with {:.2f}: one value when they agree there
    assert condition_label("cut_by_image", [0.6149, 0.6101]) == "cut by image\nshare 0.61"
    # runs whose scored frames differ (restarts): the range, neither the last nor the largest alone
    assert condition_label("whole", [0.6149, 0.62, 0.66]) == "whole\nshare 0.61..0.66"
    assert condition_label("whole", [None, float("nan")]) == "whole"


def test_conditions_plot_ticks_agree_with_the_condition_table(tmp_path, monkeypatch):
    from track3d.evaluation import plots
    from track3d.evaluation.tables import condition_table

    def cond(share_whole, share_cut):
        return {"whole": {"frames": 60, "share": share_whole, "ao_2d": 0.9, "ao_3d": 0.8, "ace_3d": 0.3,
                          "ao_3d_lost": 0.1},
                "past_range": {"frames": 0, "share": 0.0, "ao_2d": None, "ao_3d": None, "ace_3d": None,
                               "ao_3d_lost": 0.0},
                "cut_by_image": {"frames": 40, "share": share_cut, "ao_2d": 0.9, "ao_3d": 0.7, "ace_3d": 0.4,
                                 "ao_3d_lost": 0.1},
                "cut_and_past_range": {"frames": 0, "share": 0.0, "ao_2d": None, "ao_3d": None, "ace_3d": None,
                                       "ao_3d_lost": 0.0}}

    conditions = {"base": cond(0.39, 0.61), "other": cond(0.39, 0.61)}
    seen = {}
    real_save = plots._save

    def save(fig, path):
        seen["ticks"] = [t.get_text() for t in fig.axes[0].get_xticklabels()]
        return real_save(fig, path)

    monkeypatch.setattr(plots, "_save", save)
    assert plots.condition_plot(conditions, tmp_path).is_file()
    assert seen["ticks"] == ["whole\nshare 0.39", "cut by image\nshare 0.61"]
    table = condition_table({"trackers": {n: {"conditions": c} for n, c in conditions.items()}})
    assert "0.61" in table and "0.39" in table
