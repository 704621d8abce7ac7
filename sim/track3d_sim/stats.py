"""`track3d-sim stats`: the paper's Fig. 4 — size classes, box volumes, motion speeds, illumination."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .errors import SimError
from .shapes import VOLUME_RANGE
from .outfile import check_out, make_parent


def image_suffixes() -> tuple[str, ...]:
    """The file extensions matplotlib writes (".png", ".pdf", ".svg", ...): --out of `stats`."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    return tuple(f".{e}" for e in sorted(FigureCanvasAgg.get_supported_filetypes()))


def collect(root: str | Path, split: str = "all") -> dict:
    from track3d import boxes
    from track3d.dataset import DATASET_JSON, GT2D, LEFT_DIR, Dataset, DatasetError
    r = Path(os.path.abspath(root))
    if (r / GT2D).is_file() or (r / LEFT_DIR).is_dir():  # the runtime's message offers --sequence: stats has none
        up = r.parent.parent
        raise SimError(f"{root} is a sequence folder, not a dataset root: pass the folder holding {DATASET_JSON}"
                       + (f" ({up})" if (up / DATASET_JSON).is_file() else ""))
    try:
        data = Dataset(root)
        splits = list(data.splits) if split == "all" else [split]
        seqs = [s for sp in splits if sp in data.splits for s in data.sequences(sp)]
    except DatasetError as e:
        raise SimError(str(e)) from None
    if not seqs:
        # which splits do hold sequences: the user picks another --split without a second look
        have = ", ".join(f"{k} {len(v)}" for k, v in data.splits.items())
        where = "any split" if split == "all" else f"split {split}"
        raise SimError(f"no sequences in {where} of {root} (sequences per split: {have or 'none'})")
    sizes, speeds, vel, irr, dn = [], [], [], [], []
    n_points_only = sum(bool(s.points_only) for s in seqs)
    for s in seqs:
        b = s.gt3d
        sizes.append(b[:, 3:])
        fps = float(s.meta.get("fps", 10.0))
        if len(b) > 1:
            v = np.diff(b[:, :3], axis=0) * fps
            speeds.append(np.linalg.norm(v, axis=1))
            vel.append(v)
        irr.append(float(s.meta.get("sun", {}).get("irradiance", np.nan)))
        m = s.meta.get("frame_data", {}).get("mean_object_dn", [])
        dn.extend(x for x in m if x is not None)
    sizes = np.concatenate(sizes)
    if not len(sizes):
        # sequences of zero frames only: every panel would be empty (the volume panel's range had
        # failed with a traceback), so there is nothing to plot
        where = "any split" if split == "all" else f"split {split}"
        raise SimError(f"no frames in {where} of {root}: its {len(seqs)} sequence{'s' if len(seqs) > 1 else ''} "
                       f"hold{'' if len(seqs) > 1 else 's'} none, nothing to plot")
    cls, _ = boxes.size_class_of(sizes)
    return {"size_class": cls, "volume": np.prod(sizes, axis=1),
            "speed": np.concatenate(speeds) if speeds else np.zeros(0),
            "velocity": np.concatenate(vel) if vel else np.zeros((0, 3)),
            "irradiance": np.array(irr), "object_dn": np.array(dn), "n_seq": len(seqs),
            "n_frames": len(sizes), "n_points_only": n_points_only}


def illumination_panel(ax, st: dict) -> None:
    """Panel (d): the frames' mean object pixel values and the sequences' sun irradiance; without
    images (points-only sequences, no mean object value in any frame) a note in the panel instead
    of empty axes."""
    ax.set_title("(d) illumination: mean object pixel value (0..255)")
    if not len(st["object_dn"]):
        po = st.get("n_points_only", 0)
        why = ("points-only sequences (no images)" if po == st["n_seq"] else
               f"no mean object value in any frame ({po} of {st['n_seq']} sequences points-only)" if po else
               "no mean object value in any frame's meta")
        ax.text(0.5, 0.5, f"no illumination data:\n{why}", ha="center", va="center", transform=ax.transAxes,
                fontsize=10, color="0.3")
        ax.set_axis_off()
        return
    ax.hist(st["object_dn"], bins=np.arange(0, 256, 4), color="tab:gray", label="mean object value / frame")
    ax.set(xlabel="DN", ylabel="frames")
    ax2 = ax.twinx()
    ax2.hist(255 * 0.9 * st["irradiance"] * 0.5, bins=np.arange(0, 256, 8), histtype="step", color="tab:red",
             label="sun irradiance x gain x 0.5 / seq")
    ax2.set_ylabel("sequences", color="tab:red")
    ax.legend(loc="upper right", fontsize=7)
    ax2.legend(loc="center right", fontsize=7)


def plot_stats(root: str | Path, out: str | Path, split: str = "all") -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from track3d import boxes
    out = check_out(out, "plot", image_suffixes())  # before reading the data, not after
    st = collect(root, split)
    fig, ax = plt.subplots(2, 2, figsize=(10, 7.5))
    nc = len(boxes.SIZE_TEMPLATES)
    ax[0, 0].bar(np.arange(nc), np.bincount(st["size_class"], minlength=nc), color="tab:blue")
    ax[0, 0].set(title="(a) size classes (Table 1)", xlabel="size class", ylabel="frames", xticks=np.arange(nc))
    v = st["volume"]
    ax[0, 1].hist(v, bins=np.logspace(np.log10(max(v.min(), 1e-3)), np.log10(v.max() + 1e-9), 40), color="tab:orange")
    ax[0, 1].set_xscale("log")
    # the paper's volume range (VOLUME_RANGE), named: two unexplained dashed lines had been drawn
    ax[0, 1].axvline(VOLUME_RANGE[0], color="k", ls="--", lw=0.8, label=f"paper's range {VOLUME_RANGE[0]:g}-{VOLUME_RANGE[1]:g} m^3")
    ax[0, 1].axvline(VOLUME_RANGE[1], color="k", ls="--", lw=0.8)
    ax[0, 1].legend(fontsize=7)
    ax[0, 1].set(title=f"(b) box volumes, m^3 ({v.min():.0f} .. {v.max():.0f})", xlabel="axis-aligned box volume (m^3)",
                 ylabel="frames")
    vel = st["velocity"]
    if len(vel):
        lim = np.percentile(np.abs(vel), 99.5) + 1e-6
        bins = np.linspace(-lim, lim, 41)
        for k, (name, col) in enumerate(zip("xyz", ("tab:green", "tab:olive", "tab:cyan"))):
            ax[1, 0].hist(vel[:, k], bins=bins, histtype="step", lw=1.5, color=col,
                          label=f"v{name}: sd {vel[:, k].std():.2f} m/s")
        ax[1, 0].legend(fontsize=7)
        ax[1, 0].set(title=f"(c) translation velocity (mean speed {st['speed'].mean():.2f} m/s)",
                     xlabel="velocity component (m/s)", ylabel="frame pairs")
    else:
        # one-frame (or empty) sequences have no frame pair: the mean of no speeds had put two numpy
        # RuntimeWarnings on stderr and "nan m/s" in the title
        ax[1, 0].set_title("(c) translation velocity")
        ax[1, 0].text(0.5, 0.5, "no velocities:\nno sequence has two frames", ha="center", va="center",
                      transform=ax[1, 0].transAxes, fontsize=10, color="0.3")
        ax[1, 0].set_axis_off()
    illumination_panel(ax[1, 1], st)
    def count(n: int, word: str) -> str:
        return f"{n} {word}{'' if n == 1 else 's'}"

    fig.suptitle(f"{Path(os.path.abspath(root)).name}: {count(st['n_seq'], 'sequence')}, "
                 f"{count(st['n_frames'], 'frame')} ({split})")
    fig.tight_layout()
    make_parent(out)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return st
