"""Training pairs for EdgeTrack: crop caches and an augmenting pair sampler.

`prepare` writes two caches into one folder:
- ``target/``: target-centred crops (SiamFC's cache format and code, `siamfc.data.build_cache`,
  here with a 128 template and a 384 cache = 3x the template's image extent, room for the
  scale and shift jitter of the 256 search crop);
- ``background/``: 256 search crops with no target in them (``bg.npy`` + ``bg.json``): around
  the last seen position on frames where the target is absent (the exits from view) and at
  random places away from the target, so the classifier learns what 'lost' looks like.

The sampler draws (template, search, box) with the field's augmentations: search scale and shift
jitter (the target anywhere in the search region), colour / brightness / gamma / low light,
grayscale, Gaussian or motion blur, sensor noise, horizontal flip, negative pairs (a search
crop from another sequence or from the background cache: no target, all cells negative) and,
optionally, border cuts: the search crop beyond a line through the target is filled with one
colour, as the runtime pads a crop that reaches past the image, so the classifier sees the
slivers of a body leaving or entering the view (positive, the box clipped at the line) and the
frames just after it left (the line before the target: negative).
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

import cv2
import numpy as np

from track3d.edgetrack import pad_colour
from track3d.resample import warp_affine_gray_numpy, warp_axis_aligned
from track3d.siamfc import crop_square

from ..caches import CacheError, load_npy, not_a_cache
from ..siamfc.data import CropCache, build_cache, sequences_from_dataset, synthetic_sequences

__all__ = ["prepare", "PairSampler", "CropCache", "CACHE_SIZE", "PAD", "load_background", "cut_at_border"]

CACHE_SIZE = 384   # 3 x the default template's image extent
# Everything outside the image, in the crops and the border cuts: magenta, a colour neither the
# sky nor a shadowed or lit body takes. With the frame's mean colour (dark on these scenes) a
# cut looked like a terminator, and a model trained on cuts clipped its boxes on half-shadowed
# bodies; with this colour the network learns where the image ends (held-out sequences, seeds
# 3 / 4 / 7: the lost flag's precision 0.76 -> 0.88, 0.47 -> 0.82, 0.77 -> 0.85, AO_3d level).
PAD = (255.0, 0.0, 255.0)
COMPLETE = "bg.json"   # written last by `prepare`: a cache without it is incomplete



def _background(sequences, out_dir: Path, exemplar_size: int, instance_size: int, context_amount: float,
                max_crops: int, seed: int, pad: tuple | None = None) -> int:
    rng = np.random.default_rng(seed)
    crops, origin = [], []
    plans = []
    for name, get, boxes, absent, stride in sequences:
        boxes = np.asarray(boxes, np.float64)
        absent = np.asarray(absent, bool)
        ok = ~absent & np.all(np.isfinite(boxes), 1) & (boxes[:, 2] > 2) & (boxes[:, 3] > 2)
        last = None
        for i in range(len(boxes)):
            if ok[i]:
                last = boxes[i]
                if i % 2 == 0:
                    plans.append((name, get, i, boxes[i], "away"))
            elif last is not None and absent[i]:
                plans.append((name, get, i, last, "absent"))
    if len(plans) > max_crops:
        keep = np.sort(rng.choice(len(plans), max_crops, replace=False))
        plans = [plans[k] for k in keep]
    for name, get, i, b, kind in plans:
        img = get(i)
        h, w = img.shape[:2]
        ctx = context_amount * (b[2] + b[3])
        x_sz = math.sqrt((b[2] + ctx) * (b[3] + ctx)) * instance_size / exemplar_size
        c = b[:2] + b[2:] / 2
        if kind == "away":   # a search window that does not touch the target
            for _ in range(20):
                cand = rng.uniform([0, 0], [w, h])
                if np.all(np.abs(cand - c) > x_sz / 2 + b[2:] / 2 + 2):
                    c = cand
                    break
            else:
                continue
        else:
            c = np.clip(c, 0, [w, h])
        fill = tuple(pad) if pad is not None else tuple(float(v) for v in cv2.mean(img)[:3])
        crops.append(crop_square(img, c, x_sz, instance_size, fill))
        origin.append([name, int(i), kind])
    arr = np.stack(crops) if crops else np.zeros((0, instance_size, instance_size, 3), np.uint8)
    with open(out_dir / "bg.npy.tmp", "wb") as f:   # whole or not at all
        np.save(f, arr)
    os.replace(out_dir / "bg.npy.tmp", out_dir / "bg.npy")
    # bg.json last: the cache's completion marker (`load_background`; the recipes skip a cache that has it)
    (out_dir / "bg.json.tmp").write_text(json.dumps({"origin": origin, "instance_size": instance_size,
                                                     "pad": None if pad is None else [float(v) for v in pad]}))
    os.replace(out_dir / "bg.json.tmp", out_dir / COMPLETE)
    return len(arr)


def prepare(out_dir, data=None, split: str = "train", synthetic: int = 0, synthetic_frames: int = 60,
            max_frames: int = 3000, max_background: int = 1000, exemplar_size: int = 128,
            instance_size: int = 256, context_amount: float = 0.5, seed: int = 0, progress: bool = True,
            pad: tuple | None = PAD) -> dict:
    """Write <out>/target (crops.npy, index.json) and <out>/background (bg.npy, bg.json).
    `data`: one dataset root or a list of them (their `split` sequences, in order). `pad`: the
    RGB colour of everything outside the image, in both caches and in the border cuts (the
    exported model carries it to the runtime's crop); None: each frame's mean colour (the
    shipped model's first training stage)."""
    out = Path(out_dir)
    pad = pad_colour(pad)
    roots = [data] if isinstance(data, (str, Path)) else list(data or [])
    # a re-run over a cache: not complete until this run's marker is written, and the temporaries
    # of a run killed before (crops.npy.tmp can be gigabytes) go
    for name in (COMPLETE, "bg.npy.tmp", "bg.json.tmp"):   # (build_cache cleans the target's)
        (out / "background" / name).unlink(missing_ok=True)

    def seqs():
        if synthetic:
            yield from synthetic_sequences(synthetic, frames=synthetic_frames, seed=seed)
            return
        for root in roots:
            yield from sequences_from_dataset(root, split)

    build_cache(seqs(), out / "target", exemplar_size=exemplar_size, cache_size=3 * exemplar_size,
                context_amount=context_amount, max_frames=max_frames, progress=progress, pad=pad)
    (out / "background").mkdir(parents=True, exist_ok=True)
    nb = _background(seqs(), out / "background", exemplar_size, instance_size, context_amount,
                     max_background, seed, pad)
    nt = len(json.loads((out / "target" / "index.json").read_text())["seq"])
    return {"target_crops": nt, "background_crops": nb}


MAKER = "track3d-train edgetrack prepare"   # the command that writes the caches (named in errors)


def _incomplete(cache_dir, missing: str) -> CacheError:
    return CacheError(f"{cache_dir} is an incomplete EdgeTrack cache (no background/{missing}: its prepare did not "
                      f"finish): run `{MAKER}` again")


def load_background(cache_dir) -> np.ndarray:
    """The background crops (N, S, S, 3) uint8 of a complete cache (`prepare` writes
    background/bg.json last); a cache without them is a CacheError saying it is incomplete (a
    prepare killed before had trained with no background crop, in silence), a bg.npy that is not
    such an array a CacheError naming it."""
    p = Path(cache_dir) / "background" / "bg.npy"
    if not p.exists():
        raise _incomplete(cache_dir, "bg.npy")
    bg = load_npy(p, "a background crop array", MAKER, mmap_mode="r")
    if bg.ndim != 4 or bg.shape[3] != 3 or bg.dtype != np.uint8:
        raise not_a_cache(p, "a background crop array", MAKER, f"a {bg.dtype} array of shape {bg.shape}")
    if not (p.parent / COMPLETE).is_file():
        raise _incomplete(cache_dir, COMPLETE)
    return bg


# Of the border cuts, this share puts the line before the target (it has just left the view:
# negative); the others leave 4-70% of its extent along the cut axis in view.
CUT_GONE = 0.25
CUT_VISIBLE = (0.04, 0.7)


def cut_at_border(crop: np.ndarray, box: np.ndarray, rng,
                  fill: tuple | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """A search crop (S, S, 3) uint8 whose part beyond a line across the target box [x0, y0, x1, y1]
    is filled with `fill` (the cache's pad colour: what the runtime's padding looks like where the
    crop reaches past the image; None: the crop's mean colour). Returns (crop, the box clipped at
    the line, or None when the line lies before the target and nothing of it is left)."""
    out = np.array(crop)
    size = out.shape[0]
    side = int(rng.integers(4))              # the padding lies right / left / below / above
    axis = side // 2                         # 0: a vertical line, 1: a horizontal one
    lo, hi = float(box[axis]), float(box[axis + 2])
    gone = rng.random() < CUT_GONE
    f = rng.uniform(-0.5, 0.0) if gone else rng.uniform(*CUT_VISIBLE)
    if fill is None:
        colour = out.reshape(-1, 3).mean(0).round().astype(np.uint8)
    else:
        colour = np.asarray(fill, np.float64).round().astype(np.uint8)
    new = np.array(box, np.float64)
    if side % 2 == 0:                        # keep [lo, line)
        line = lo + f * (hi - lo)
        k = int(np.clip(math.ceil(line), 0, size))
        sl = (slice(None), slice(k, None)) if axis == 0 else (slice(k, None), slice(None))
        new[axis + 2] = line
    else:                                    # keep [line, hi)
        line = hi - f * (hi - lo)
        k = int(np.clip(math.floor(line), 0, size))
        sl = (slice(None), slice(None, k)) if axis == 0 else (slice(None, k), slice(None))
        new[axis] = line
    out[sl] = colour
    if gone:
        return out, None
    return out, new


def _motion_kernel(rng, length):
    k = np.zeros((length, length), np.float32)
    k[length // 2] = 1.0
    rot = cv2.getRotationMatrix2D(((length - 1) / 2, (length - 1) / 2), float(rng.uniform(0, 180)), 1.0)
    # OpenCV 5.0's warp in fixed arithmetic: the same kernel whatever OpenCV is installed
    k = warp_affine_gray_numpy(k, rot, (length, length))
    return k / max(k.sum(), 1e-6)


class PairSampler:
    """Random (template, search, box) batches: uint8 NHWC crops and boxes (B, 4) [x0, y0, x1, y1]
    in search-crop pixels (NaN for negative pairs). `sequences` restricts to some sequence ids
    (the train / validation split of the cache)."""

    def __init__(self, cache: CropCache, background: np.ndarray, exemplar_size: int = 128,
                 instance_size: int = 256, max_gap: int = 50, scale_jitter: float = 0.25,
                 shift: float | None = None, neg_other: float = 0.1, neg_background: float = 0.1,
                 sequences=None, seed: int = 0, augment: bool = True, border_cut: float = 0.0):
        self.c = cache
        self.border_cut = float(border_cut)
        pad = cache.index.get("pad")
        self.pad = None if pad is None else tuple(float(v) for v in pad)
        self.bg = background
        self.ez, self.xz = exemplar_size, instance_size
        # the target anywhere within a quarter crop of the centre (64 px of a 256 search crop)
        self.max_gap, self.scale_jitter = max_gap, scale_jitter
        self.shift = instance_size / 4.0 if shift is None else shift
        self.neg_other, self.neg_background = neg_other, neg_background
        self.augment = augment
        self.rng = np.random.default_rng(seed)
        self.src = cache.crops.shape[1]
        sizes = np.asarray(cache.index["size_in_crop"], np.float64)
        self.size_in_crop = sizes * 1.0      # the cache scale equals the template's
        groups = [np.nonzero(cache.seq == s)[0] for s in range(len(cache.index["sequences"]))]
        ids = range(len(groups)) if sequences is None else sequences
        self.groups = [groups[s] for s in ids if len(groups[s]) >= 2]
        if not self.groups:
            raise ValueError("the crop cache has no sequence with two usable frames")

    def _warp(self, crop, out, scale, dx, dy):
        cs, co = (self.src - 1) / 2.0, (out - 1) / 2.0
        # the runtime's warp (fixed arithmetic, whatever OpenCV is installed), edge pixels replicated
        return warp_axis_aligned(np.asarray(crop), (scale, scale), (co - scale * cs + dx, co - scale * cs + dy),
                                 (out, out), border="replicate")

    def _photometric(self, im: np.ndarray, search: bool) -> np.ndarray:
        r = self.rng
        f = im.astype(np.float32)
        if r.random() < 0.8:   # brightness / low light, per-channel tint, gamma
            f = f * r.uniform(0.4, 1.5) * r.uniform(0.92, 1.08, 3)
            f = 255.0 * (np.clip(f, 0, 255) / 255.0) ** r.uniform(0.7, 1.4)
        if search and r.random() < 0.25:
            if r.random() < 0.5:
                f = cv2.GaussianBlur(f, (0, 0), r.uniform(0.5, 1.8))
            else:
                f = cv2.filter2D(f, -1, _motion_kernel(r, int(r.integers(3, 10))))
        if search and r.random() < 0.4:
            f = f + r.normal(0, r.uniform(1, 8), f.shape).astype(np.float32)
        return np.clip(f, 0, 255).astype(np.uint8)

    def sample(self, batch: int):
        r = self.rng
        z = np.empty((batch, self.ez, self.ez, 3), np.uint8)
        x = np.empty((batch, self.xz, self.xz, 3), np.uint8)
        boxes = np.full((batch, 4), np.nan, np.float64)
        for k in range(batch):
            g = self.groups[r.integers(len(self.groups))]
            a = r.integers(len(g))
            fr = self.c.frame[g]
            near = np.nonzero(np.abs(fr - fr[a]) <= self.max_gap)[0]
            b = near[r.integers(len(near))]
            jz = 1.0 + (r.uniform(-0.04, 0.04) if self.augment else 0.0)
            zc = self._warp(self.c.crops[g[a]], self.ez, jz, *(r.uniform(-3, 3, 2) if self.augment else (0, 0)))
            u = r.random()
            if u < self.neg_background and len(self.bg):
                xc = np.array(self.bg[r.integers(len(self.bg))])
                if xc.shape[0] != self.xz:
                    xc = cv2.resize(xc, (self.xz, self.xz), interpolation=cv2.INTER_AREA)
                box = None
            else:
                other = u < self.neg_background + self.neg_other and len(self.groups) > 1
                src = g[b]
                if other:
                    while True:
                        h = self.groups[r.integers(len(self.groups))]
                        if h is not g:
                            break
                    src = h[r.integers(len(h))]
                s = math.exp(r.uniform(-self.scale_jitter, self.scale_jitter))
                dx, dy = r.uniform(-self.shift, self.shift, 2)
                xc = self._warp(self.c.crops[src], self.xz, s, dx, dy)
                if other:
                    box = None
                else:
                    cx, cy = self.xz / 2.0 + dx, self.xz / 2.0 + dy
                    w, h2 = self.size_in_crop[src] * s
                    box = np.array([cx - w / 2, cy - h2 / 2, cx + w / 2, cy + h2 / 2])
            if self.augment:
                zc, xc = self._photometric(zc, False), self._photometric(xc, True)
                if r.random() < 0.1:   # grayscale, both crops
                    zc = np.repeat(cv2.cvtColor(zc, cv2.COLOR_RGB2GRAY)[..., None], 3, 2)
                    xc = np.repeat(cv2.cvtColor(xc, cv2.COLOR_RGB2GRAY)[..., None], 3, 2)
                if r.random() < 0.5:
                    zc, xc = zc[:, ::-1], xc[:, ::-1]
                    if box is not None:
                        box = np.array([self.xz - box[2], box[1], self.xz - box[0], box[3]])
            if box is not None and self.border_cut > 0 and r.random() < self.border_cut:
                xc, box = cut_at_border(xc, box, r, self.pad)
            z[k], x[k] = zc, xc
            if box is not None:
                boxes[k] = box
        return z, x, boxes
