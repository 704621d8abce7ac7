"""Plots of an evaluation: success / precision curves and 3D trajectories (the paper's Fig. 10-12),
and the near and far faces along the line of sight over time (where a hidden depth guessed wrong shows).

matplotlib is optional (the `plot` extra): it is imported here, inside the functions, and a
clear error says how to get it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .metrics import AXES_3D, CE2D_THRESHOLDS, CE3D_THRESHOLDS, CONDITIONS, IOU_THRESHOLDS, OverallScore
from .results import INIT

__all__ = ["pyplot", "curve_plots", "trajectory_plot", "trajectory_plots", "line_of_sight_plot", "sequence_plot",
           "worst_sequences", "axis_error_plot", "condition_plot"]


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend, or a clear error."""
    try:
        import matplotlib
    except ImportError:
        raise RuntimeError("plots need matplotlib: pip install 'track3d[plot]' (or pass --no-plots)") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: str | Path) -> Path:
    """Lay out, write and close `fig` at `path` (its folder made); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    # a legend beside the axes (_legend) is left out of tight_layout, so the axes keep their size,
    # and named here, so the saved picture grows to hold it
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    fig.savefig(path, bbox_inches="tight", bbox_extra_artists=legends)
    pyplot().close(fig)
    return path


def _label(text: str) -> str:
    """A run's (or a sequence's) name as matplotlib shows it as written: a `$` would start
    mathtext (an unbalanced one had aborted the whole report), and a legend leaves out a label
    starting with `_`."""
    text = str(text).replace("$", r"\$")
    return " " + text if text.startswith("_") else text


# line styles by run, beside the colours: two runs of the same boxes draw one line over the other,
# and a reader took the hidden one for missing
_STYLES = ("-", "--", "-.", ":")


def _styles(names) -> dict[str, str]:
    return {n: _STYLES[k % len(_STYLES)] for k, n in enumerate(sorted(names))}


def _legend(ax, entries: int, fontsize: int = 8) -> None:
    """The legend inside the axes' corner for up to 3 entries, beside the axes for more: inside,
    8 runs' curves ran under it."""
    if entries <= 3:
        ax.legend(fontsize=fontsize, loc="best")
    else:
        leg = ax.legend(fontsize=fontsize - 1, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
        leg.set_in_layout(False)   # the axes keep their size; the saved picture grows to hold it (_save)


def _colours(names) -> dict[str, tuple]:
    """One colour per tracker name, the same in every plot of a report (sorted names; tab10, or
    tab20 past 10 runs: tab10 had given the 11th run the 1st one's colour)."""
    plt = pyplot()
    names = sorted(names)
    cmap = plt.get_cmap("tab10" if len(names) <= 10 else "tab20")
    return {n: cmap(k % cmap.N) for k, n in enumerate(names)}


_SUCCESS = {"2d": ("success_2d", "ao_2d", "2D"), "bev": ("success_bev", "ao_bev", "BEV"),
            "3d": ("success_3d", "ao_3d", "3D")}
_PRECISION = {"2d": ("precision_2d", "ace_2d", CE2D_THRESHOLDS, "centre error (px)", "px"),
              "3d": ("precision_3d", "ace_3d", CE3D_THRESHOLDS, "centre error (m)", "m")}


def curve_plots(overall: dict[str, OverallScore], out_dir: str | Path, own_2d: bool = False) -> list[Path]:
    """success_{2d,bev,3d}.png (legend: AO) and precision_{2d,3d}.png (legend: ACE); the 3D ones
    only when some run has 3D curves. own_2d: the 2D trackers' own boxes were scored (the titles
    say so: the same file names had shown other numbers than the loop's)."""
    plt = pyplot()
    out_dir = Path(out_dir)
    files = []
    colour, style = _colours(overall), _styles(overall)
    what = ", trackers' own boxes" if own_2d else ""
    def drawn(curve: str) -> bool:   # 2D-only runs have no 3D curves: no empty 3D plots
        return any(curve in ov.curves for ov in overall.values())

    for kind, (curve, key, title) in _SUCCESS.items():
        if not drawn(curve):
            continue
        fig, ax = plt.subplots(figsize=(5, 4), dpi=100)
        order = sorted(overall, key=lambda n: -np.nan_to_num(overall[n].values[key], nan=-1))
        drawn_runs = [n for n in order if curve in overall[n].curves]
        for name in drawn_runs:
            ov = overall[name]
            ax.plot(IOU_THRESHOLDS, ov.curves[curve], color=colour[name], ls=style[name],
                    label=f"{_label(name)} [AO {ov.values[key]:.3f}]")
        ax.set(xlabel="overlap threshold", ylabel="success rate", title=f"Success plot ({title}{what})",
               xlim=(0, 1), ylim=(0, 1.02))
        ax.grid(alpha=0.3)
        _legend(ax, len(drawn_runs))
        files.append(_save(fig, out_dir / f"success_{kind}.png"))
    for kind, (curve, key, thr, xlabel, unit) in _PRECISION.items():
        if not drawn(curve):
            continue
        fig, ax = plt.subplots(figsize=(5, 4), dpi=100)
        # the success plots' order (by AO), so that a run is in the same place in both legends
        order = sorted(overall, key=lambda n: -np.nan_to_num(overall[n].values[_SUCCESS[kind][1]], nan=-1))
        drawn_runs = [n for n in order if curve in overall[n].curves]
        for name in drawn_runs:
            ov = overall[name]
            ax.plot(thr, ov.curves[curve], color=colour[name], ls=style[name],
                    label=f"{_label(name)} [ACE {ov.values[key]:.3f} {unit}]")
        ax.set(xlabel=xlabel, ylabel="precision", title=f"Precision plot ({kind.upper()}{what})",
               xlim=(thr[0], thr[-1]), ylim=(0, 1.02))
        ax.grid(alpha=0.3)
        _legend(ax, len(drawn_runs))
        files.append(_save(fig, out_dir / f"precision_{kind}.png"))
    return files


def trajectory_plot(gt3d: np.ndarray, tracks: dict[str, np.ndarray], path: str | Path, title: str = "",
                    absent: np.ndarray | None = None, restarts: dict[str, np.ndarray] | None = None) -> Path:
    """3D trajectory of box centres (Fig. 12): ground truth vs each tracker's (T, 6) boxes.

    Axes are the camera frame (x right, z forward, -y up for a natural view); frames with
    no output are gaps; restart frames are marked with x.
    """
    plt = pyplot()
    fig = plt.figure(figsize=(5.5, 4.5), dpi=100)
    ax = fig.add_subplot(projection="3d")
    g = np.asarray(gt3d, np.float64).copy()
    if absent is not None:
        g[np.asarray(absent, bool)] = np.nan
    # drawn over the runs (zorder): under eight runs' lines it had been buried
    ax.plot(g[:, 0], g[:, 2], -g[:, 1], color="black", lw=2, label="ground truth", zorder=5)
    colour, style = _colours(tracks), _styles(tracks)
    for name, boxes in tracks.items():
        b = np.asarray(boxes, np.float64)
        line, = ax.plot(b[:, 0], b[:, 2], -b[:, 1], lw=1, color=colour[name], ls=style[name], label=_label(name))
        if restarts is not None and name in restarts and np.any(restarts[name]):
            r = b[restarts[name]]
            ax.scatter(r[:, 0], r[:, 2], -r[:, 1], marker="x", color=line.get_color(), s=25)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_zlabel("-y (m)")
    ax.set_title(_label(title), fontsize=10)
    _legend(ax, len(tracks) + 1, fontsize=8)
    return _save(fig, path)


def line_of_sight_plot(gt3d: np.ndarray, tracks: dict[str, np.ndarray], path: str | Path, title: str = "",
                       absent: np.ndarray | None = None) -> Path:
    """The boxes' near and far faces along the line of sight (z = cz -/+ sz / 2, camera frame)
    per frame: ground truth (black) vs each tracker's (T, 6) boxes. A depth sensor measures the
    near face; the far face is the estimator's guess of the hidden side, so this is where its
    error shows (a gap that stays between the far faces, a far face that follows the near one).
    Frames with no box are gaps."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 3.6), dpi=100)
    g = np.asarray(gt3d, np.float64).copy()
    if absent is not None:
        g[np.asarray(absent, bool)] = np.nan
    t = np.arange(len(g))
    ax.plot(t, g[:, 2] - g[:, 5] / 2, color="black", lw=2, label="ground truth", zorder=5)
    ax.plot(t, g[:, 2] + g[:, 5] / 2, color="black", lw=2, ls="--", zorder=5)
    colour = _colours(tracks)
    for name, boxes in tracks.items():
        b = np.asarray(boxes, np.float64)
        tb = np.arange(len(b))
        ax.plot(tb, b[:, 2] - b[:, 5] / 2, lw=1, color=colour[name], label=_label(name))
        ax.plot(tb, b[:, 2] + b[:, 5] / 2, lw=1, ls="--", color=colour[name])
    # one entry a run (two had made 18 entries for 8 runs, over the curves), the faces' key once
    ax.plot([], [], color="grey", lw=1, label="solid: near face")
    ax.plot([], [], color="grey", lw=1, ls="--", label="dashed: far face")
    ax.set(xlabel="frame", ylabel="z, along the line of sight (m)")
    ax.set_title(_label(title), fontsize=10)
    ax.grid(alpha=0.3)
    _legend(ax, len(tracks) + 3, fontsize=8)
    return _save(fig, path)


def trajectory_plots(exp, names: list[str], seq_names: list[str], out_dir: str | Path) -> list[Path]:
    """Per sequence of the experiment `exp`, all trackers in `names`: its 3D trajectory plot
    (trajectory_<seq>.png) and, when some tracker has 3D boxes, its line-of-sight plot
    (depth_<seq>.png)."""
    files = []
    by_name = {s.name: s for s in exp.sequences}
    # 2D-only runs have no 3D track: in the legend with no line they read as a run that failed
    runs_3d = [name for name in names if exp._run_3d(name)]
    if not runs_3d:
        return files
    for sn in seq_names:
        seq = by_name[sn]
        tracks, restarts, n = {}, {}, exp._frames(seq)
        for name in runs_3d:
            # the rows as scored (--frames cut, skipped frames without a box): the whole files had
            # drawn 300 frames beside a table of 60
            res = exp._read(name, seq)
            n = min(n, len(res))
            tracks[name] = res.box3d
            st = res.status
            first = np.argmax(st == INIT)
            restarts[name] = (st == INIT) & (np.arange(len(st)) > first)
        tracks = {k: v[:n] for k, v in tracks.items()}
        restarts = {k: v[:n] for k, v in restarts.items()}
        files.append(trajectory_plot(seq.gt3d[:n], tracks, Path(out_dir) / f"trajectory_{sn}.png",
                                     f"3D trajectory, sequence {sn}", seq.absent[:n], restarts))
        boxed = {k: v for k, v in tracks.items() if np.any(np.isfinite(v[:, 5]))}
        if boxed:
            files.append(line_of_sight_plot(seq.gt3d[:n], boxed, Path(out_dir) / f"depth_{sn}.png",
                                            f"Near and far faces along the line of sight, sequence {sn}",
                                            seq.absent[:n]))
    return files


def _per_sequence_key(scores: dict[str, list]) -> str:
    """"ao_3d" when some run has 3D scores, else "ao_2d" (2D-only runs)."""
    return "ao_2d" if all(s.two_d_only for ss in scores.values() for s in ss) else "ao_3d"


def worst_sequences(scores: dict[str, list], n: int) -> list[str]:
    """The n sequence names with the lowest AO (3D, or 2D for 2D-only runs) averaged over the
    compared runs (scores: run name -> its SequenceScore list, one per sequence, same order);
    sequences without scored frames last; ties in sequence order."""
    key = _per_sequence_key(scores)
    runs = list(scores.values())
    if not runs:
        return []
    names = [s.name for s in runs[0]]
    mean = []
    for i, name in enumerate(names):
        v = [getattr(r[i], key) for r in runs if r[i].frames > 0]
        v = [x for x in v if np.isfinite(x)]
        mean.append(float(np.mean(v)) if v else np.inf)
    order = sorted(range(len(names)), key=lambda i: (mean[i], i))
    return [names[i] for i in order[:max(int(n), 0)]]


def sequence_plot(scores: dict[str, list], out_dir: str | Path) -> Path:
    """sequences.png: AO per sequence (3D, or 2D for 2D-only runs), one bar per run, the worst
    sequence (lowest mean over the runs) at the top: where a person looks first."""
    plt = pyplot()
    key = _per_sequence_key(scores)
    order = worst_sequences(scores, len(next(iter(scores.values()), [])))
    colour = _colours(scores)
    # a 2D-only run has no AO_3d: its bars had been drawn at 0, as a run that lost every frame
    runs = sorted(n for n in scores if key == "ao_2d" or not all(s.two_d_only for s in scores[n]))
    rows = len(order)
    h = 0.8 / max(len(runs), 1)
    fig, ax = plt.subplots(figsize=(6, 1.0 + 0.28 * rows * max(1, len(runs) / 2)), dpi=100)
    for k, name in enumerate(runs):
        by = {s.name: s for s in scores[name]}
        y = np.arange(rows) + (k - (len(runs) - 1) / 2) * h
        v = [getattr(by[sn], key) if by[sn].frames > 0 else np.nan for sn in order]
        ax.barh(y, np.nan_to_num(v, nan=0.0), height=h, color=colour[name], label=_label(name))
    ax.set_yticks(np.arange(rows), [_label(sn) for sn in order], fontsize=7)
    ax.invert_yaxis()
    ax.set(xlim=(0, 1), xlabel=f"AO_{key[3:]} per sequence",
           title=f"AO_{key[3:]} per sequence, worst (mean over the runs) first")
    ax.grid(axis="x", alpha=0.3)
    # beside the bars, not under them: below the axes it covered the x label on short plots
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    return _save(fig, Path(out_dir) / "sequences.png")


def _grouped(groups: int, runs: list[str]) -> tuple[np.ndarray, float, dict[str, np.ndarray]]:
    """Bars of `runs` side by side in each of `groups` groups: (the groups' centres, a bar's
    width, {run: its bars' x})."""
    x = np.arange(groups)
    w = 0.8 / max(len(runs), 1)
    return x, w, {name: x + (k - (len(runs) - 1) / 2) * w for k, name in enumerate(runs)}


def axis_error_plot(overall: dict[str, OverallScore], out_dir: str | Path) -> Path | None:
    """errors_3d.png: each run's mean |error| per 3D box coordinate (bars) and its bias (prediction -
    truth, black ticks), camera frame: where the 3D error lies (a hidden depth guessed wrong shows in
    cz and sz). None when no run has 3D boxes."""
    runs = sorted(n for n, ov in overall.items() if not ov.two_d_only and "mae_3d" in ov.values)
    if not runs:
        return None
    plt = pyplot()
    colour = _colours(runs)
    x, w, at = _grouped(len(AXES_3D), runs)
    fig, ax = plt.subplots(figsize=(6.5, 3.6), dpi=100)
    for name in runs:
        xs = at[name]
        mae = np.asarray(overall[name].values["mae_3d"], np.float64)
        bias = np.asarray(overall[name].values["bias_3d"], np.float64)
        ax.bar(xs, np.nan_to_num(mae), width=w, color=colour[name], label=_label(name))
        ax.scatter(xs, bias, marker="_", s=200 * w, color="black", zorder=3,
                   label="bias (prediction - truth)" if name == runs[0] else None)
    ax.axhline(0.0, color="grey", lw=0.8)
    labels = {"cx": "centre x", "cy": "centre y", "cz": "centre z\n(line of sight)", "sx": "size x",
              "sy": "size y", "sz": "size z\n(line of sight)"}
    ax.set_xticks(x, [labels[a] for a in AXES_3D], fontsize=8)
    ax.set(ylabel="metres", title="3D error per box coordinate: mean |error| (bars), bias (ticks)")
    ax.title.set_fontsize(10)
    ax.grid(axis="y", alpha=0.3)
    _legend(ax, len(runs) + 1, fontsize=8)
    return _save(fig, Path(out_dir) / "errors_3d.png")


def condition_label(condition: str, shares) -> str:
    """A conditions.png tick label: the condition and its share of the scored frames as the
    condition table prints it ({:.2f}); a run's scored frames depend on its restarts, so runs whose
    shares print differently get their range (lowest..highest), not one run's value."""
    text = sorted({f"{float(v):.2f}" for v in shares if v is not None and np.isfinite(float(v))}, key=float)
    name = condition.replace("_", " ")
    if not text:
        return name
    return f"{name}\nshare {text[0] if len(text) == 1 else text[0] + '..' + text[-1]}"


def condition_plot(conditions: dict[str, dict], out_dir: str | Path) -> Path | None:
    """conditions.png: where the loss is. Per frame condition (metrics.CONDITIONS, those some run
    has frames in) each run's AO_3d lost there (bars: the shares of 1 - IoU_3d over all frames,
    adding up to 1 - the pooled AO_3d) and its AO_3d over those frames (black ticks, right
    axis); the condition's share of the scored frames under its name (condition_label).
    `conditions`: {run: report.json's "conditions"}. None when every frame is whole or no run has
    3D boxes."""
    runs = sorted(n for n, c in conditions.items() if all("ao_3d_lost" in v for v in c.values()))
    used = [k for k in CONDITIONS if any(conditions[n].get(k, {}).get("frames", 0) for n in runs)]
    if not runs or used in ([], ["whole"]):
        return None
    plt = pyplot()
    colour = _colours(runs)
    x, w, at = _grouped(len(used), runs)
    fig, ax = plt.subplots(figsize=(6.5, 4.2), dpi=100)
    ao = ax.twinx()
    for name in runs:
        xs = at[name]
        c = conditions[name]
        lost = np.array([c[u]["ao_3d_lost"] for u in used], np.float64)
        mean = np.array([np.nan if c[u]["ao_3d"] is None else c[u]["ao_3d"] for u in used], np.float64)
        ax.bar(xs, np.nan_to_num(lost), width=w, color=colour[name], label=_label(name))
        ao.scatter(xs, mean, marker="_", s=200, color="black")
    ticks = [condition_label(u, [conditions[n].get(u, {}).get("share") for n in runs]) for u in used]
    ax.set_xticks(x, ticks, fontsize=7)
    ax.set(ylabel="AO_3d lost (share of all frames)", title="Where the loss is: frames by condition")
    ax.set_xlabel("frame condition; share: of the scored frames"
                  + (" (a range: the runs' shares differ)" if any(".." in t for t in ticks) else ""), fontsize=7)
    ao.set(ylim=(0, 1), ylabel="AO_3d over the condition's frames (ticks)")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.24), ncol=2)
    return _save(fig, Path(out_dir) / "conditions.png")
