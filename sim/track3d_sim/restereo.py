"""Recompute a stereo dataset's depth maps from its own left/right images with this release's
matcher (`track3d.stereo`, the simulator's stereo sensor), without rendering again.

A stereo sequence's depth is a function of its images and the matcher's settings only, so a
matcher change (e.g. `StereoParams.edge_erode_px`) reaches an existing dataset through this,
byte for byte what `track3d-sim generate` would now write. Resumable and idempotent: a sequence
whose meta.json already records the current settings is skipped, and meta.json is rewritten
only after all of the sequence's depth maps."""
from __future__ import annotations

import sys
from pathlib import Path

from track3d.dataset import Dataset, write_depth_png, write_meta
from track3d.stereo import StereoMatcher

from .errors import SimError
from .sensors import sensor_info

__all__ = ["restereo"]


def restereo(root: str | Path, progress: bool = True) -> dict[str, int]:
    """Recompute the depth maps of every stereo sequence under `root` (a dataset root).

    Returns counts: {"recomputed": sequences, "current": already up to date, "other": not
    stereo (left alone), "frames": depth maps written}."""
    ds = Dataset(root)
    if ds.points_only:
        raise SimError(f"{root} is points-only data: no images to match")
    info = sensor_info("stereo")
    matcher = StereoMatcher(ds.camera)
    seqs = [s for split in ds.splits for s in ds.sequences(split)]
    todo = [s for s in seqs if s.depth_sensor == "stereo" and s.meta.get("depth_sensor") != info]
    counts = {"recomputed": 0, "current": sum(s.depth_sensor == "stereo" for s in seqs) - len(todo),
              "other": sum(s.depth_sensor != "stereo" for s in seqs), "frames": 0}
    bar = None
    if progress and todo:
        from tqdm import tqdm
        bar = tqdm(total=sum(len(s) for s in todo), unit="frame", desc="track3d-sim restereo",
                   file=sys.stderr, dynamic_ncols=True)
    try:
        for s in todo:
            for i in range(len(s)):
                z = matcher.depth(s.image(i), s.right_image(i))
                write_depth_png(s.depth_path(i), z)
                counts["frames"] += 1
                if bar is not None:
                    bar.update(1)
            write_meta(s.path, {**s.meta, "depth_sensor": info})
            counts["recomputed"] += 1
    finally:
        if bar is not None:
            bar.close()
    return counts
