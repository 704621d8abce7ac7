"""Training pairs for SiamFC: a cache of target-centred crops and a pair sampler.

`prepare` crops every usable frame of the train split once (target centred, the exemplar
context region scaled to `exemplar_size`, a `cache_size` square around it, mean-colour padding
with the runtime's own crop function) into one uint8 .npy memmap, so training never decodes a
PNG. Pairs are two frames of one sequence at most `max_gap` apart; augmentation: stretch
(scale jitter), crop jitter (translation), brightness jitter, horizontal flip.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np

from track3d.resample import warp_axis_aligned
from track3d.siamfc import crop_square

from ..caches import load_npy, not_a_cache, read_json

__all__ = ["CropCache", "build_cache", "sequences_from_dataset", "synthetic_sequences", "PairSampler"]

CACHE_SIZE = 255
MAKER = "track3d-train siamfc prepare"   # the command that writes the caches (named in errors)


def _usable(box, absent, min_side=4.0):
    return (not absent) and np.all(np.isfinite(box)) and box[2] >= min_side and box[3] >= min_side


def sequences_from_dataset(root, split: str = "train", stride: int = 1):
    """Yield (name, frame_getter, boxes (n,4), absent (n,)) for each sequence of a split."""
    from track3d.dataset import Dataset

    ds = Dataset(root)
    for seq in ds.sequences(split):
        yield seq.name, seq.image, seq.gt2d, seq.absent, stride


def synthetic_sequences(n: int, frames: int = 60, seed: int = 0, h: int = 240, w: int = 320):
    from .synthetic import synthetic_sequence

    rng = np.random.default_rng(seed)
    for k in range(n):
        f, b = synthetic_sequence(frames, h, w, rng, size_range=(16, 80), speed=float(rng.uniform(1, 6)),
                                  noise=float(rng.uniform(0.5, 4)))
        yield f"syn{k:04d}", (lambda i, f=f: f[i]), b, np.zeros(len(b), bool), 1


def build_cache(sequences, out_dir, exemplar_size: int = 127, cache_size: int = CACHE_SIZE,
                context_amount: float = 0.5, max_frames: int = 2000, progress: bool = True,
                data_hash: str | None = None, data_name: str | None = None,
                pad: tuple | None = None) -> Path:
    """Write crops.npy (N, S, S, 3) uint8 + index.json. Sequences: iterable of
    (name, get_image(i), boxes, absent, stride). Frames beyond max_frames are subsampled evenly.
    data_hash / data_name identify the source data (recorded in index.json, then in the
    checkpoints and the exported models' metadata). `pad`: the RGB colour of everything outside
    the image (recorded in index.json); None: each frame's mean colour."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    # a re-run over a cache: not complete until this run's index.json is written (the recipes skip
    # a cache that has one); the temporaries a run killed before left go
    (out / "index.json").unlink(missing_ok=True)
    for name in ("crops.npy.tmp", "index.json.tmp"):
        (out / name).unlink(missing_ok=True)
    seqs = []
    for name, get, boxes, absent, stride in sequences:
        idx = [i for i in range(0, len(boxes), stride) if _usable(boxes[i], absent[i])]
        if len(idx) >= 2:
            seqs.append((name, get, np.asarray(boxes, np.float64), idx))
    total = sum(len(s[3]) for s in seqs)
    keep = 1.0 if total <= max_frames else max_frames / total
    plan = []
    for name, get, boxes, idx in seqs:
        k = max(2, int(round(len(idx) * keep)))
        sel = [idx[int(j)] for j in np.unique(np.linspace(0, len(idx) - 1, k).round().astype(int))]
        plan.append((name, get, boxes, sel))
    n = sum(len(p[3]) for p in plan)
    crops = np.lib.format.open_memmap(out / "crops.npy.tmp", mode="w+", dtype=np.uint8,
                                      shape=(n, cache_size, cache_size, 3))
    seq_of, frame_of, sizes = [], [], []
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=n, desc="crops", unit="frame")
    j = 0
    for s, (name, get, boxes, sel) in enumerate(plan):
        for i in sel:
            img = get(i)
            b = boxes[i]
            c = b[:2] + b[2:] / 2.0
            ctx = context_amount * (b[2] + b[3])
            z_sz = math.sqrt((b[2] + ctx) * (b[3] + ctx))
            x_sz = z_sz * cache_size / exemplar_size
            fill = tuple(pad) if pad is not None else tuple(float(v) for v in cv2.mean(img)[:3])
            crops[j] = crop_square(img, c, x_sz, cache_size, fill)
            seq_of.append(s)
            frame_of.append(int(i))
            sizes.append((b[2:] * exemplar_size / z_sz).tolist())
            j += 1
            if bar:
                bar.update(1)
    if bar:
        bar.close()
    crops.flush()
    del crops
    (out / "crops.npy.tmp").replace(out / "crops.npy")
    (out / "index.json.tmp").write_text(json.dumps({
        "sequences": [p[0] for p in plan], "seq": seq_of, "frame": frame_of, "size_in_crop": sizes,
        "cache_size": cache_size, "exemplar_size": exemplar_size, "context_amount": context_amount,
        "data_hash": data_hash, "data_name": data_name,
        "pad": None if pad is None else [float(v) for v in pad]}))
    (out / "index.json.tmp").replace(out / "index.json")   # last, whole: the cache is complete
    return out


def cache_data_info(cache_dir, maker: str = MAKER) -> dict:
    """{"train_data_hash", "train_data"} of a crop cache: the source data's hash recorded by
    build_cache, else a sha256 of the cache's index.json (older caches)."""
    import hashlib

    p = Path(cache_dir) / "index.json"
    index = read_json(p, "a crop cache index", maker)
    raw = p.read_bytes()
    return {"train_data_hash": index.get("data_hash") or hashlib.sha256(raw).hexdigest(),
            "train_data": index.get("data_name")}


class CropCache:
    """A crop cache folder (crops.npy + index.json from `build_cache`). A path that is not one is a
    CacheError (one line on the command line) naming `maker`, the command that makes it."""

    def __init__(self, path, maker: str = MAKER):
        self.path = Path(path)
        kind = "a crop cache folder"
        if not self.path.exists():
            raise FileNotFoundError(f"{self.path} does not exist: give {kind} made by `{maker}`")
        if not self.path.is_dir():
            raise not_a_cache(self.path, kind, maker, "a file, not a folder")
        for name in ("crops.npy", "index.json"):
            if not (self.path / name).exists():
                raise not_a_cache(self.path, kind, maker, f"no {name} in it")
        self.crops = load_npy(self.path / "crops.npy", "a crop cache's crops.npy", maker, mmap_mode="r")
        self.index = read_json(self.path / "index.json", "a crop cache index", maker,
                               ("sequences", "seq", "frame", "size_in_crop"))
        if self.crops.ndim != 4 or self.crops.shape[3] != 3 or self.crops.dtype != np.uint8 \
                or not (len(self.crops) == len(self.index["seq"]) == len(self.index["frame"])):
            raise not_a_cache(self.path, kind, maker, "crops.npy and index.json do not fit together: a damaged cache")
        self.seq = np.asarray(self.index["seq"], np.int64)
        self.frame = np.asarray(self.index["frame"], np.int64)
        self.by_seq = [np.nonzero(self.seq == s)[0] for s in range(len(self.index["sequences"]))]
        self.by_seq = [x for x in self.by_seq if len(x) >= 2]

    def __len__(self):
        return len(self.crops)


class PairSampler:
    """Random (exemplar, search) pairs from a CropCache as uint8 NHWC batches."""

    def __init__(self, cache: CropCache, exemplar_size: int = 127, instance_size: int = 239,
                 max_gap: int = 50, stretch: float = 0.05, shift: float = 8.0, seed: int = 0):
        self.c = cache
        self.ez, self.xz = exemplar_size, instance_size
        self.max_gap, self.stretch, self.shift = max_gap, stretch, shift
        self.rng = np.random.default_rng(seed)
        self.src = cache.crops.shape[1]
        if not cache.by_seq:
            raise ValueError(f"the crop cache {cache.path} has no sequence with two usable frames")

    def _warp(self, crop, out, shift):
        r = self.rng
        s = 1.0 + r.uniform(-self.stretch, self.stretch)
        sx, sy = s * (1 + r.uniform(-self.stretch, self.stretch) / 2), s
        dx, dy = (r.uniform(-shift, shift, 2) if shift > 0 else (0.0, 0.0))
        cs, co = (self.src - 1) / 2.0, (out - 1) / 2.0
        # the runtime's warp (fixed arithmetic, whatever OpenCV is installed), edge pixels replicated
        return warp_axis_aligned(np.asarray(crop), (sx, sy), (co - sx * cs + dx, co - sy * cs + dy),
                                 (out, out), border="replicate")

    def sample(self, batch: int) -> tuple[np.ndarray, np.ndarray]:
        r = self.rng
        z = np.empty((batch, self.ez, self.ez, 3), np.uint8)
        x = np.empty((batch, self.xz, self.xz, 3), np.uint8)
        for k in range(batch):
            ids = self.c.by_seq[r.integers(len(self.c.by_seq))]
            a = r.integers(len(ids))
            fr = self.c.frame[ids]
            ok = np.nonzero(np.abs(fr - fr[a]) <= self.max_gap)[0]
            b = ok[r.integers(len(ok))]
            zc = self._warp(self.c.crops[ids[a]], self.ez, 0.0)
            xc = self._warp(self.c.crops[ids[b]], self.xz, self.shift)
            for im in (zc, xc):
                if r.random() < 0.8:
                    g = r.uniform(0.6, 1.5)
                    im[:] = np.clip(im.astype(np.float32) * g, 0, 255).astype(np.uint8)
            if r.random() < 0.5:
                zc, xc = zc[:, ::-1], xc[:, ::-1]
            z[k], x[k] = zc, xc
        return z, x
