"""Training / evaluation data of A3BoxNet: frustum proposals cached once, sampled per epoch.

`prepare_split` walks a split of a track3d dataset, and for every frame where the target is
present cuts the frustum proposal out of the frame's point cloud with the RUNTIME frustum
code (`track3d.frustum.extract_frustum`), from the ground-truth 2D box (``oracle``) and from
``jitters`` copies of it perturbed the way a real 2D tracker errs (`jitter_box`). Each
proposal is stored subsampled to at most ``max_points`` points (random, without
replacement: sampling N <= max_points points from it later has the distribution of sampling
from the whole proposal), with the minimum enclosing box of the WHOLE proposal (the paper's
baseline) and the labels. The cache is one .npz named by the split's hash.

`BoxNetSamples` is the torch Dataset over a cache: each item samples N points with the
runtime sampler (`track3d.frustum.sample_points`), normalises them with the runtime
(the model's `track3d.size_coding` object) and codes the size label with the same object,
so train and run time share every formula.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from track3d.boxes import box3d_from_points, clip_box2d
from track3d.boxnet import PAST_VIEWS, one_hot, with_past_views
from track3d.size_coding import size_coding
from track3d.dataset import GT2D, GT3D, META, RIGHT_DIR, Dataset

from ..caches import load_npz, not_a_cache
from ..onnx_meta import hash_files

__all__ = ["JitterSpec", "jitter_box", "split_hash", "prepare_split", "PointCache", "BoxNetSamples"]

CACHE_VERSION = 1


@dataclass(frozen=True)
class JitterSpec:
    """How a 2D tracker errs, as a random perturbation of the ground-truth box [x, y, w, h]:

    - centre shift: N(0, center_sigma * w) in u and N(0, center_sigma * h) in v (drift);
    - scale: w and h multiplied by exp(N(0, scale_sigma)) with a shared component
      (the tracker's scale estimate) and an independent one of aspect_sigma (aspect error);
    - with probability ``fail_prob`` a larger error (x3 sigmas), as when a tracker slips.
    The box is then clipped to the image (trackers report boxes inside the image).
    """

    center_sigma: float = 0.1
    scale_sigma: float = 0.1
    aspect_sigma: float = 0.05
    fail_prob: float = 0.1


def jitter_box(box: np.ndarray, rng: np.random.Generator, spec: JitterSpec, width: int, height: int) -> np.ndarray:
    b = np.asarray(box, dtype=np.float64)
    k = 3.0 if rng.random() < spec.fail_prob else 1.0
    cx, cy = b[0] + b[2] / 2, b[1] + b[3] / 2
    cx += rng.normal(0.0, k * spec.center_sigma * b[2])
    cy += rng.normal(0.0, k * spec.center_sigma * b[3])
    s = rng.normal(0.0, k * spec.scale_sigma)
    a = rng.normal(0.0, k * spec.aspect_sigma)
    w, h = b[2] * math.exp(s + a), b[3] * math.exp(s - a)
    return clip_box2d(np.array([cx - w / 2, cy - h / 2, w, h]), width, height)


def split_files(ds: Dataset, split: str) -> list[Path]:
    files = [ds.root / "dataset.json"]
    for seq in ds.sequences(split):
        files += [p for p in (seq.path / GT2D, seq.path / GT3D, seq.path / META) if p.is_file()]
    return files


def split_hash(ds: Dataset, split: str) -> str:
    """sha256 over dataset.json and the split's label files (the generator is deterministic,
    so its settings + labels identify the data)."""
    return hash_files(split_files(ds, split))


def prepare_split(root: str | Path, split: str, out: str | Path, jitters: int = 3, oracle: bool = True,
                  max_points: int = 4096, min_points: int = 16, spec: JitterSpec = JitterSpec(),
                  seed: int = 0, max_sequences: int | None = None, frame_step: int = 1,
                  progress: bool = True, stereo_match: int | None = None, past_views: bool = False,
                  sensors: tuple[str, ...] | None = None) -> Path:
    """Build the frustum cache of one split; returns the .npz path (``out`` is a file or a folder).

    stereo_match: None, the frames' clouds (their depth maps); else each box's cloud is matched
    from the stereo pair around it as the loop's `track3d.stereo.StereoCloud` does, with
    ``max_match_px=stereo_match`` (0: every row), searching the disparities the loop's followed
    search would (down to the ground-truth box's near face / follow_depth).

    past_views: each proposal also holds the body's past views in that frame, as the loop gives
    them to a model trained with them (`track3d.body_views.BodyViews` fed each frame's
    ground-truth frustum in order, as the loop does with its own; `track3d.boxnet.with_past_views`
    joins them to the proposal); needs every frame (frame_step 1).

    sensors: only the sequences whose depth sensor (meta.json) is one of these (None: every
    one): a sensor's own model trained on its sequences of a mixed set. The kept sequences are
    cut as a set of only them would be (the same jitter draws, in the same order)."""
    from track3d.frustum import extract_frustum
    from track3d.stereo import StereoMatcher

    ds = Dataset(root)
    seqs = ds.sequences(split)
    if not seqs:   # before the output folder is made, and not as "no frustum with >= 16 points"
        raise ValueError(f"split {split!r} of {root} has no sequences")
    wanted = None if sensors is None else {str(x).strip().lower() for x in sensors}
    if wanted is not None:
        seqs = [q for q in seqs if str(q.depth_sensor or "").lower() in wanted]
        if not seqs:
            raise ValueError(f"no sequence of split {split!r} of {root} has depth sensor {', '.join(sorted(wanted))}")
    seqs = seqs[:max_sequences]
    h = split_hash(ds, split)
    out = Path(out)
    if out.suffix != ".npz":
        out = out / f"boxnet_{split}_{h[:12]}_j{jitters}{'o' if oracle else ''}_p{max_points}_s{seed}.npz"
    out.parent.mkdir(parents=True, exist_ok=True)
    cam = ds.camera
    M = cam.M
    rng = np.random.default_rng(seed)
    matcher = None if stereo_match is None else StereoMatcher(cam, max_match_px=int(stereo_match))
    pts, offs = [], [0]
    rec = {k: [] for k in ("gt3d", "baseline", "box2d", "category", "seq", "frame", "n_full", "jittered")}
    frames = [(si, s, i) for si, s in enumerate(seqs) for i in range(0, len(s), frame_step) if not s.absent[i]]
    it = frames
    if progress:
        from tqdm import tqdm
        it = tqdm(frames, desc=f"frustums {split}", unit="frame")
    if past_views and frame_step != 1:
        raise ValueError("past_views needs every frame (frame_step 1): the views are registered frame by frame")
    views = _PastViews(cam) if past_views else None
    for si, seq, i in it:
        cloud = seq.points(i) if matcher is None else _StereoFrame(matcher, seq, i)
        past = None if views is None else views(seq, si, i, cloud)
        boxes = ([(seq.gt2d[i], 0)] if oracle else []) + \
                [(jitter_box(seq.gt2d[i], rng, spec, cam.width, cam.height), 1) for _ in range(jitters)]
        for box, jit in boxes:
            if box[2] < 1 or box[3] < 1:
                continue
            fr = extract_frustum(cloud(box) if matcher is not None else cloud, box.astype(np.float32), M)
            if len(fr) < min_points:
                continue
            keep = fr if len(fr) <= max_points else fr[rng.choice(len(fr), max_points, replace=False)]
            if past is not None:
                keep = with_past_views(fr, past, int(rng.integers(2 ** 31)))
            pts.append(np.ascontiguousarray(keep, dtype=np.float32))
            offs.append(offs[-1] + len(keep))
            rec["gt3d"].append(seq.gt3d[i])
            rec["baseline"].append(box3d_from_points(fr))
            rec["box2d"].append(box)
            rec["category"].append(seq.category)
            rec["seq"].append(si)
            rec["frame"].append(i)
            rec["n_full"].append(len(fr))
            rec["jittered"].append(jit)
    if not pts:
        raise ValueError(f"no frustum with >= {min_points} points in split {split!r} of {root}")
    info = {"version": CACHE_VERSION, "root": str(ds.root), "split": split, "data_hash": h, "jitters": jitters,
            "oracle": oracle, "stereo_match": stereo_match, "max_points": max_points, "min_points": min_points,
            "past_views": dict(PAST_VIEWS) if past_views else None,
            "seed": seed, "sensors": None if wanted is None else sorted(wanted),
            "jitter": spec.__dict__, "sequences": [s.name for s in seqs], "frame_step": frame_step,
            "categories": list(ds.categories.get("shape_families", [])),
            "num_categories": len(ds.categories.get("shape_families", [])) or 3}
    # Written under another name and renamed when complete: a recipe skips a cache that exists,
    # so a job killed while writing (hundreds of MB) must not leave a truncated file at `out`.
    part = out.with_name(out.name + ".part")
    with open(part, "wb") as f:
        np.savez(f, points=np.concatenate(pts), offsets=np.asarray(offs, np.int64),
                 gt3d=np.asarray(rec["gt3d"], np.float64), baseline=np.asarray(rec["baseline"], np.float64),
                 box2d=np.asarray(rec["box2d"], np.float64), category=np.asarray(rec["category"], np.int64),
                 seq=np.asarray(rec["seq"], np.int64), frame=np.asarray(rec["frame"], np.int64),
                 n_full=np.asarray(rec["n_full"], np.int64), jittered=np.asarray(rec["jittered"], np.int8),
                 info=np.frombuffer(json.dumps(info).encode(), dtype=np.uint8))
    part.replace(out)
    return out


class _PastViews:
    """(seq, index, i, cloud) -> the past views (m, 3) in frame i, or None: one BodyViews per
    sequence, fed the ground-truth frustum of every present frame in order (prepare_split)."""

    def __init__(self, camera):
        self.camera, self.seq, self.views = camera, None, None

    def __call__(self, seq, si: int, i: int, cloud) -> np.ndarray | None:
        from track3d.body_views import BodyViews
        from track3d.frustum import extract_frustum_bounds
        from track3d.range_cut import reaches_range
        from track3d.tracker import cut_box, measured_bounds
        from track3d.sensor_options import frustum_margin_for, front_quantile_for

        if self.seq != si:
            self.seq, self.views = si, BodyViews(self.camera)
        if seq.absent[i]:
            return None
        box = np.asarray(seq.gt2d[i], np.float64)
        cut = cut_box(box, frustum_margin_for(seq.depth_sensor))      # cut and measured as the loop does
        pts, bounds = extract_frustum_bounds(cloud, cut.astype(np.float32), self.camera.M)
        if len(pts) == 0:
            return None
        front = float(measured_bounds(pts, bounds, front_quantile_for(seq.depth_sensor))[0][2])
        by_range = reaches_range(bounds, box, self.camera, seq.depth_range_m)
        W, H = self.camera.width, self.camera.height
        border = box[0] <= 0.5 or box[1] <= 0.5 or box[0] + box[2] >= W - 0.5 or box[1] + box[3] >= H - 0.5
        self.views.update(pts, cut, front, carve=not by_range, whole=not by_range and not border)
        return self.views.past_points(pts)


class _StereoFrame:
    """box -> the frame's cloud matched from its stereo pair around the box (prepare_split)."""

    def __init__(self, matcher, seq, i: int):
        if not (seq.path / RIGHT_DIR).is_dir():
            raise ValueError(f"{seq.path} has no right images: --stereo-match needs a stereo dataset")
        self.matcher, self.left, self.right = matcher, seq.image(i), seq.right_image(i)
        g = seq.gt3d[i]
        follow = matcher.params.follow_depth
        self.n = matcher.disparities_to((g[2] - g[5] / 2.0) / follow) if follow > 0 else None

    def __call__(self, box: np.ndarray) -> np.ndarray:
        return self.matcher.points_window(self.left, self.right, box, self.n)


ITEM_FIELDS = ("gt3d", "baseline", "box2d", "category", "seq", "frame", "n_full", "jittered")


def _read_cache(path: Path) -> dict:
    """The arrays of a frustum cache, "info" decoded, checked against each other: a file that is
    not a cache `prepare_split` wrote (missing, a folder, empty, truncated, another .npz or file)
    is a CacheError (a ValueError: one line on the command line), whatever numpy would raise."""
    kind, maker = "a frustum cache", "track3d-train boxnet prepare"
    z = load_npz(path, kind, maker, ("info", "points", "offsets") + ITEM_FIELDS)
    try:
        info = json.loads(z["info"].tobytes().decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise not_a_cache(path, kind, maker, "its info is not JSON") from None
    if not isinstance(info, dict) or info.get("version") != CACHE_VERSION:
        got = info.get("version") if isinstance(info, dict) else None
        raise not_a_cache(path, kind, maker, f"cache version {got}, this track3d-train reads {CACHE_VERSION}")
    z["info"] = info
    n, pts, offs = len(z["gt3d"]), z["points"], z["offsets"]
    if pts.ndim != 2 or pts.shape[1] != 3 or offs.shape != (n + 1,) or (n and int(offs[-1]) != len(pts)) \
            or any(len(z[k]) != n for k in ITEM_FIELDS):
        raise not_a_cache(path, kind, maker, "its arrays do not fit together: a damaged cache")
    return z


def data_name(info: dict) -> str | None:
    """The training data's name for a model's metadata: the dataset folder of a cache, or the
    folders of every part of concatenated caches joined by "+" (a model trained on three
    datasets must not name only the first)."""
    parts = info.get("parts") or [info]
    names = [Path(str(p["root"])).name for p in parts if p.get("root")]
    return "+".join(names) if names else None


class PointCache:
    """A frustum cache (.npz) in memory: ``cache.points(i)`` -> (n_i, 3) float32."""

    def __init__(self, path: str | Path, indices: np.ndarray | None = None):
        self.path = Path(path)
        z = _read_cache(self.path)
        self.info: dict = z.pop("info")
        self._points = z.pop("points")
        self._offsets = z.pop("offsets")
        for k, v in z.items():
            setattr(self, k, v)
        self.index = np.arange(len(self.gt3d)) if indices is None else np.asarray(indices, np.int64)

    @classmethod
    def concat(cls, paths) -> "PointCache":
        """Several caches as one (e.g. two datasets' train splits); sequence ids are made unique."""
        paths = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
        caches = [cls(p) for p in paths]
        if len(caches) == 1:
            return caches[0]
        c = object.__new__(cls)
        c.path = paths[0]
        c.info = dict(caches[0].info)
        c.info["parts"] = [x.info for x in caches]
        c.info["data_hash"] = hashlib.sha256("".join(x.info["data_hash"] for x in caches).encode()).hexdigest()
        c._points = np.concatenate([x._points for x in caches])
        offs, base = [np.zeros(1, np.int64)], 0
        for x in caches:
            offs.append(x._offsets[1:] + base)
            base += x._offsets[-1]
        c._offsets = np.concatenate(offs)
        seq_base = 0
        seqs = []
        for x in caches:
            seqs.append(x.seq + seq_base)
            seq_base += int(x.seq.max()) + 1
        c.seq = np.concatenate(seqs)
        for k in ("gt3d", "baseline", "box2d", "category", "frame", "n_full", "jittered"):
            setattr(c, k, np.concatenate([getattr(x, k) for x in caches]))
        c.index = np.arange(len(c.gt3d))
        return c

    def subset(self, mask_or_indices) -> "PointCache":
        c = object.__new__(PointCache)
        c.__dict__.update(self.__dict__)
        sel = np.asarray(mask_or_indices)
        c.index = self.index[sel] if sel.dtype != bool else self.index[sel]
        return c

    def __len__(self) -> int:
        return len(self.index)

    def points(self, i: int) -> np.ndarray:
        j = self.index[i]
        return self._points[self._offsets[j]:self._offsets[j + 1]]

    def field(self, name: str) -> np.ndarray:
        return getattr(self, name)[self.index]


class BoxNetSamples:
    """torch-style Dataset over a PointCache: item -> (centred points (N,3) f32, one-hot (C,) f32,
    centre label relative to the coding's reference (3,) f32, size class (), normalised residual (3,) f32,
    residual scale () f32). ``epoch`` (set by the loop) changes the sampling seed;
    ``flip`` mirrors x at random (a valid augmentation: the mirrored frustum of the mirrored box);
    ``cat_dropout``: probability of an all-zero category vector, the runtime's "unknown category"
    (-1, the loop's default), so the net also works without it;
    ``flip_y`` mirrors y at random (valid for the same reason: the principal point is the image
    centre, so the mirrored box cuts the mirrored frustum);
    ``scale_sigma``: points and box scaled about the camera centre by exp(N(0, scale_sigma)),
    clipped to [0.7, 1.4] (projection is scale invariant, so the same 2D box still cuts the scaled
    scene: a bigger body farther away, or a smaller one nearer);
    ``stretch_sigma``: points and box stretched about the box centre, each axis by its own
    exp(N(0, stretch_sigma)) (one sigma, or x / y / z sigmas) clipped to [0.4, 2.5]: another
    body (flatter, deeper, longer) whose
    visible surface is the stretched one (the view is near-orthographic at these ranges), so the
    hidden depth cannot be read off the visible width and height alone, as it could be for the
    generators' proportions."""

    def __init__(self, cache: PointCache, num_points: int, num_categories: int = 3, size_norm: str = "points",
                 seed: int = 0, flip: bool = False, cat_dropout: float = 0.0, flip_y: bool = False,
                 scale_sigma: float = 0.0, stretch_sigma: float = 0.0):
        self.cache, self.num_points, self.num_categories = cache, int(num_points), int(num_categories)
        self.size_norm, self.seed, self.flip, self.epoch = size_norm, int(seed), bool(flip), 0
        self.cat_dropout = float(cat_dropout)
        self.flip_y, self.scale_sigma = bool(flip_y), float(scale_sigma)
        # one sigma for every axis, or (x, y, z); the same random stream either way
        self.stretch_sigma = np.broadcast_to(np.asarray(stretch_sigma, np.float64), (3,)).copy()

    def __len__(self) -> int:
        return len(self.cache)

    def item_seed(self, i: int) -> int:
        return (self.seed * 1_000_003 + self.epoch * 7_919 + int(i) * 104_729) % (2 ** 31 - 1)

    def sample(self, i: int) -> np.ndarray:
        from track3d.frustum import sample_points

        return sample_points(self.cache.points(i), self.num_points, self.item_seed(i))

    def bounds(self, i: int) -> np.ndarray:
        """(2, 3) [min; max] of the item's WHOLE frustum (the cache's enclosing box of it)."""
        b = self.cache.baseline[self.cache.index[i]]
        return np.stack([b[:3] - b[3:] / 2, b[:3] + b[3:] / 2])

    def __getitem__(self, i: int):
        pts = self.sample(i)
        gt = self.cache.gt3d[self.cache.index[i]].copy()
        corners = self.bounds(i)    # transformed with the points, re-sorted per axis at the end
        if self.flip and (self.item_seed(i) % 2):
            pts = pts * np.array([-1.0, 1.0, 1.0], np.float32)
            corners = corners * [-1.0, 1.0, 1.0]
            gt[0] = -gt[0]
        if self.flip_y or self.scale_sigma > 0 or np.any(self.stretch_sigma > 0):
            rng = np.random.default_rng([self.item_seed(i), 17])
            if self.flip_y and rng.random() < 0.5:
                pts = pts * np.array([1.0, -1.0, 1.0], np.float32)
                corners = corners * [1.0, -1.0, 1.0]
                gt[1] = -gt[1]
            if self.scale_sigma > 0:
                k = float(np.clip(np.exp(rng.normal(0.0, self.scale_sigma)), 0.7, 1.4))
                pts = pts * np.float32(k)
                corners = corners * k
                gt = gt * k
            if np.any(self.stretch_sigma > 0):
                k3 = np.clip(np.exp(rng.normal(0.0, self.stretch_sigma, 3)), 0.4, 2.5)
                pts = ((pts - gt[:3]) * k3 + gt[:3]).astype(np.float32)
                corners = (corners - gt[:3]) * k3 + gt[:3]
                gt[3:] = gt[3:] * k3
        bounds = np.stack([corners.min(axis=0), corners.max(axis=0)])
        coding = size_coding(self.size_norm)
        centred, ref, scale = coding.normalise(pts, bounds)
        cls, res, loss_scale = coding.labels(gt[3:], scale)
        cat = one_hot(self.cache.category[self.cache.index[i]], self.num_categories)
        if self.cat_dropout > 0 and (self.item_seed(i) // 2 % 1000) < 1000 * self.cat_dropout:
            cat[:] = 0.0
        return (centred, cat, (gt[:3] - ref).astype(np.float32), np.int64(cls),
                np.asarray(res, np.float32), np.asarray(loss_scale, np.float32))


def cache_past_views(cache_info: dict) -> dict | None:
    """The past-views counts (track3d.boxnet.PAST_VIEWS) of a run's cache, or None; for caches
    joined (PointCache.concat) those of any part that had them: their counts must agree."""
    parts = cache_info.get("parts") or [cache_info]
    found = [p["past_views"] for p in parts if p.get("past_views")]
    if any(f != found[0] for f in found):
        raise ValueError(f"the caches' past_views differ: {found}")
    return dict(found[0]) if found else None
