"""The dataset on disk: file-format constants and the reader (docs/dataset.md).

The simulator (track3d_sim) writes this layout; training and evaluation read it here::

    <root>/dataset.json
    <root>/<split>/<sequence>/left/000001.png  right/000001.png  depth/000001.png
                             groundtruth_2d.txt  groundtruth_3d.txt
                             absence.label  cut_by_image.label  meta.json

Point clouds are not stored: they are the depth map back-projected with K on load.
"""
from __future__ import annotations

import json
import struct
import warnings
import zlib
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from .boxes import clip_box2d
from .camera import Camera
from .frames import IMAGE_BITS, as_rgb, to_uint8

__all__ = [
    "FORMAT", "FORMAT_VERSION", "DATASET_JSON", "GENERATE_RUN_FILE", "LEFT_DIR", "RIGHT_DIR", "DEPTH_DIR", "GT2D", "GT3D",
    "ABSENCE", "CUT", "META", "frame_name", "write_meta", "write_depth_png", "read_depth_png", "read_rgb", "write_rgb",
    "write_labels", "write_dataset_json", "COARSE_CATEGORIES",
    "DatasetError", "DatasetWarning", "Dataset", "Sequence", "Frame", "PROJECTION_TOLERANCE", "DEPTH_RATIO_LIMITS",
    "LABEL_SLACK_PX", "LABEL_CLIP_PX", "LABEL_CLIP_SHARE",
]

FORMAT = "track3d-dataset"
FORMAT_VERSION = 1
DATASET_JSON = "dataset.json"
# the simulator's settings of a `generate` run, written before anything else (dataset.json last)
GENERATE_RUN_FILE = ".track3d-sim-run.json"
LEFT_DIR, RIGHT_DIR, DEPTH_DIR = "left", "right", "depth"
GT2D, GT3D = "groundtruth_2d.txt", "groundtruth_3d.txt"
ABSENCE, CUT, META = "absence.label", "cut_by_image.label", "meta.json"
DEPTH_MAX_M = 65.535  # uint16 millimetres
# The paper's coarse categories (shape families), in the order of `family_index` in meta.json
# and of A3BoxNet's one-hot category input; kept for the paper's comparison only.
COARSE_CATEGORIES = ("contact_binary", "spinning_top", "irregular")


class DatasetError(Exception):
    """A dataset, split or sequence on disk is missing or malformed; the message says which."""


class DatasetWarning(UserWarning):
    """A dataset that reads but looks wrong (docs/dataset.md "What the reader checks"): one line
    naming the file or sequence, issued once per message and process."""


# The consistency checks run when a sequence is opened (docs/dataset.md "What the reader checks").
# Projection: on present frames not cut by the image border, each edge of the 2D label must lie
# where the 3D label box can put it (between the nearest and farthest projection of the box face
# that edge touches; 1 px of slack for the pixel grid); the per-frame excess, over the 2D box's
# width (x edges) or height (y edges), has a median over the sequence above this -> one warning.
# Every sequence of data/ (867 with such frames: engine-*, calib-*, long-tof, fa-*, ceil-*,
# big-ideal-2027) and the tests' synthetic spheres measure 0.000 (at most 0.0015 without the
# slack); a hand-made set's mistakes measured 0.11 (principal point 11 px off), 0.22 (half
# extents), 0.44 (y up, a body 0.4 m off the axis).
PROJECTION_TOLERANCE = 0.05
PROJECTION_SLACK_PX = 1.0
# Depth units: the median depth of the returns inside the first present frame's 2D label over the
# 3D label's z span [cz - sz/2, cz + sz/2] (1 inside it). data/ measures 0.991 .. 1.0; depth
# maps in centimetres 0.10, in metres 0.001, 3D labels in millimetres 0.001.
DEPTH_RATIO_LIMITS = (0.5, 2.0)
# 2D labels past the image border (docs/dataset.md "Label and frame files"). Up to LABEL_SLACK_PX:
# the pixel grid's rounding, taken as given. Beyond it, on a frame cut_by_image.label flags cut:
# an annotation tool's box dragged a few pixels past the border (GOT-10k style tools allow it),
# clipped to the image with one warning per sequence, as the evaluation clips predicted boxes
# (boxes.clip_box2d); each side at most LABEL_CLIP_PX or LABEL_CLIP_SHARE of the box's side on
# that axis, whichever is larger. Further is no drag but another box (the whole body's, or
# x1,y1,x2,y2 read as x,y,w,h) and is refused, as is a label past the border on a frame flagged
# uncut (the target then lies inside the image: the synthetic spheres' x1,y1,x2,y2 reach 3-5 px
# past it). data/ has no label past the border (54,292 present frames).
LABEL_SLACK_PX = 1.0
LABEL_CLIP_PX = 5.0
LABEL_CLIP_SHARE = 0.1
_MIN_DEPTH_RETURNS = 10
_EXIF_TAIL = 1 << 16   # bytes of a PNG's end searched for an eXIf after the image data
# EXIF orientation values: how a viewer turns the stored pixels to show them
_ORIENTATIONS = {2: "mirrored", 3: "rotated 180 degrees", 4: "flipped upside down", 5: "transposed",
                 6: "rotated 90 degrees clockwise", 7: "transversed", 8: "rotated 90 degrees counterclockwise"}
_warned: set[str] = set()


def _warn_once(message: str) -> None:
    """One DatasetWarning per message and process (a split is opened by the run and again by the
    evaluation: the same words once)."""
    if message in _warned:
        return
    _warned.add(message)
    warnings.warn(message, DatasetWarning, stacklevel=4)


def frame_name(index: int) -> str:
    """File name of the frame with 0-based index `index` (files are numbered from 1)."""
    return f"{index + 1:06d}.png"


def write_depth_png(path: str | Path, depth_m: np.ndarray) -> None:
    """Write z in metres as 16-bit PNG millimetres; 0 (or non-finite) = no return."""
    d = np.asarray(depth_m, dtype=np.float64)
    if np.any(d[np.isfinite(d)] > DEPTH_MAX_M):
        raise ValueError(f"depth beyond {DEPTH_MAX_M} m cannot be stored in 16-bit millimetres")
    mm = np.where(np.isfinite(d) & (d > 0), np.rint(d * 1000.0), 0).astype(np.uint16)
    if not cv2.imwrite(str(path), mm, [cv2.IMWRITE_PNG_COMPRESSION, 3]):
        raise OSError(f"could not write {path}")


def read_depth_png(path: str | Path) -> np.ndarray:
    """16-bit millimetre PNG -> (H, W) float32 metres, 0 = no return."""
    if not Path(path).is_file():   # before OpenCV, which prints a warning of its own
        raise DatasetError(f"missing depth map {path}")
    mm = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if mm is None:
        raise DatasetError(f"cannot read depth map {path}")
    if mm.dtype != np.uint16 or mm.ndim != 2:
        # what it is and how to make one: a camera pipeline's depth is often float metres (a
        # TIFF under a .png name reads as one) or 8-bit
        raise DatasetError(f"depth map {path} is {_describe(mm)}, not a 16-bit single-channel PNG: millimetres of z, "
                           f"0 = no return (float metres: write them with track3d.dataset.write_depth_png)")
    return mm.astype(np.float32) / 1000.0


def _describe(a: np.ndarray) -> str:
    """'8-bit, 3 channels', '32-bit float, 1 channel': what an image file decoded to."""
    depth = {np.dtype(np.uint8): "8-bit", np.dtype(np.uint16): "16-bit"}.get(a.dtype, f"{8 * a.itemsize}-bit "
                                                                             f"{'float' if a.dtype.kind == 'f' else a.dtype}")
    c = 1 if a.ndim == 2 else a.shape[2]
    return f"{depth}, {c} channel{'s' if c > 1 else ''}"


def _png_bit_depth(path: Path) -> int | None:
    """The bit depth a PNG's header declares (1, 2, 4, 8, 16), from its first 26 bytes, or None
    for a file that is no PNG (reading it says so)."""
    try:
        with open(path, "rb") as f:
            head = f.read(26)
    except OSError:
        return None
    return head[24] if len(head) == 26 and head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR" else None


def _png_orientation(path: Path) -> int | None:
    """The orientation (1..8) in a PNG's eXIf chunk, as OpenCV's IMREAD_COLOR applies it, or
    None: no eXIf chunk (or a malformed one, which libpng ignores), no orientation in it, or no
    PNG (reading it says so). A few small reads of one file, never the image data: the chunk
    headers before the image data, then the file's last _EXIF_TAIL bytes (an eXIf after the
    image data, where some writers put it, found by its CRC)."""
    try:
        with open(path, "rb") as f:
            if f.read(8) != b"\x89PNG\r\n\x1a\n":
                return None
            for _ in range(64):
                head = f.read(8)
                if len(head) < 8:
                    return None
                size, kind = struct.unpack(">I4s", head)
                if kind == b"eXIf":
                    return _exif_orientation(f.read(min(size, _EXIF_TAIL)))
                if kind in (b"IDAT", b"IEND"):
                    break
                f.seek(size + 4, 1)   # its data and CRC
            else:
                return None
            end = f.seek(0, 2)
            f.seek(max(0, end - _EXIF_TAIL))
            tail = f.read()
    except OSError:
        return None
    k = tail.rfind(b"eXIf")
    while k >= 4:
        size = struct.unpack(">I", tail[k - 4:k])[0]
        data = tail[k + 4:k + 4 + size]
        if len(data) == size and tail[k + 4 + size:k + 8 + size] == struct.pack(">I", zlib.crc32(b"eXIf" + data)):
            return _exif_orientation(data)
        k = tail.rfind(b"eXIf", 0, k)
    return None


def _exif_orientation(exif: bytes) -> int | None:
    """The Orientation tag (0x0112) of the first IFD of an EXIF block (TIFF, either byte order),
    or None."""
    order = {b"II*\0": "<", b"MM\0*": ">"}.get(exif[:4])
    if order is None:
        return None
    try:
        ifd = struct.unpack(order + "I", exif[4:8])[0]
        for k in range(struct.unpack(order + "H", exif[ifd:ifd + 2])[0]):
            tag, kind, _, value = struct.unpack(order + "HHIH", exif[ifd + 2 + 12 * k:ifd + 12 + 12 * k])
            if tag == 0x0112 and kind == 3:   # Orientation, SHORT
                return value
    except struct.error:   # cut short
        return None
    return None


def _image_bits(info: dict, where: Path) -> int | None:
    """dataset.json's "image_bits" (the bit depth of the samples of 16-bit frames), None when
    not given; DatasetError when malformed."""
    b = info.get("image_bits")
    if b is None:
        return None
    if not isinstance(b, int) or isinstance(b, bool) or b not in IMAGE_BITS:
        raise DatasetError(f"{where}: 'image_bits' must be an integer in {IMAGE_BITS.start}..{IMAGE_BITS.stop - 1}, "
                           f"the bit depth of the camera's samples in 16-bit frames (12 for values 0..4095), "
                           f"got {b!r:.40}")
    return b


def write_rgb(path: str | Path, rgb: np.ndarray) -> None:
    """Write an (H, W, 3) uint8 RGB image as PNG (deterministic bytes)."""
    if not cv2.imwrite(str(path), cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR),
                       [cv2.IMWRITE_PNG_COMPRESSION, 3]):
        raise OSError(f"could not write {path}")


def read_rgb(path: str | Path, bits: int | None = None) -> np.ndarray:
    """PNG -> (H, W, 3) uint8 RGB. A camera's PNG of 8 or 16 bits, grey, grey + alpha, RGB, RGBA
    or a palette, converted by track3d.frames.as_rgb (grey repeated, alpha dropped); the samples
    of a 16-bit PNG are `bits`-bit (dataset.json "image_bits"; None: 16), scaled to 0..255 by
    frames.to_uint8. OpenCV's IMREAD_COLOR had read them as value >> 8: a 12-bit camera's frames
    came out nearly black and were tracked, worse, without a word."""
    if not Path(path).is_file():
        raise DatasetError(f"missing image {path}")
    a = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)   # as stored (palettes expanded); an 8-bit RGB PNG as fast
    if a is None:
        raise DatasetError(f"cannot read image {path}")
    if a.dtype not in (np.uint8, np.uint16):
        raise DatasetError(f"image {path} is {_describe(a)}: frames are 8- or 16-bit PNG")
    if a.ndim == 3 and a.shape[2] in (3, 4):
        a = cv2.cvtColor(a, cv2.COLOR_BGR2RGB if a.shape[2] == 3 else cv2.COLOR_BGRA2RGB)
    try:
        return as_rgb(a, 16 if bits is None else bits)
    except ValueError as e:
        # the only refusal here: a sample above the declared bits (PNG has no other dtype or channels)
        raise DatasetError(f"image {path}: {e}" + (f" ({DATASET_JSON} \"image_bits\" is {bits})" if bits else "")) from None


def write_labels(seq_dir: str | Path, gt2d: np.ndarray, gt3d: np.ndarray, absent, cut, meta: dict,
                 decimals_3d: int = 4) -> None:
    """Write a sequence's label files and meta.json, the counterpart of `Sequence`'s reader.

    gt2d (N, 4) [x, y, w, h] pixels (integers are written as integers), gt3d (N, 6) metres
    with `decimals_3d` decimals (4: 0.1 mm, finer than the 1 mm depth maps), absent / cut (N,)
    0/1 flags, meta a JSON-able dict (sorted keys: deterministic bytes)."""
    d = Path(seq_dir)
    g2, g3 = np.asarray(gt2d), np.asarray(gt3d, dtype=np.float64)
    a, c = np.asarray(absent).astype(np.int64).reshape(-1), np.asarray(cut).astype(np.int64).reshape(-1)
    n = len(g2)
    if g2.shape != (n, 4) or g3.shape != (n, 6) or a.shape != (n,) or c.shape != (n,):
        raise ValueError(f"labels must be gt2d (N, 4), gt3d (N, 6), absent (N,), cut (N,); got "
                         f"{g2.shape}, {g3.shape}, {a.shape}, {c.shape}")
    np.savetxt(d / GT2D, g2, fmt="%d" if np.issubdtype(g2.dtype, np.integer) else "%.4f", delimiter=",")
    np.savetxt(d / GT3D, g3, fmt=f"%.{int(decimals_3d)}f", delimiter=",")
    np.savetxt(d / ABSENCE, a, fmt="%d")
    np.savetxt(d / CUT, c, fmt="%d")
    write_meta(d, meta)


def write_meta(seq_dir: str | Path, meta: dict) -> None:
    """Write a sequence's meta.json (sorted keys: deterministic bytes), atomically: a temporary
    file renamed, so a killed writer leaves the old file or the new one, never half of one."""
    _write_json(Path(seq_dir) / META, meta)


def write_dataset_json(root: str | Path, info: dict) -> None:
    """Write <root>/dataset.json atomically (a temporary file renamed): its presence means the
    dataset is complete, so it is written last and never half."""
    _write_json(Path(root) / DATASET_JSON, info)


def _write_json(path: Path, obj: dict) -> None:
    """JSON with sorted keys (deterministic bytes) through a temporary file renamed over `path`."""
    import os

    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(obj, indent=1, sort_keys=True))
    os.replace(tmp, path)


def _read_table(path: Path, cols: int) -> np.ndarray:
    if not path.is_file():
        raise DatasetError(f"missing label file {path}")
    try:
        with warnings.catch_warnings():  # an empty file is 0 rows, checked against the images
            warnings.simplefilter("ignore", UserWarning)
            a = np.loadtxt(path, delimiter=",", dtype=np.float64, ndmin=2)
    except ValueError as e:
        raise DatasetError(f"malformed label file {path}: {e}") from None
    if a.size == 0:
        a = a.reshape(0, cols)
    if a.shape[1] != cols:
        raise DatasetError(f"{path} has {a.shape[1]} columns, expected {cols}")
    bad = np.flatnonzero(~np.all(np.isfinite(a), axis=1))
    if len(bad):
        raise DatasetError(f"{path} has non-finite values on line {bad[0] + 1} ({len(bad)} line(s))")
    return a


def _read_flags(path: Path, n: int) -> np.ndarray:
    # A missing flag file would silently score absent frames as present: refused, not defaulted.
    if not path.is_file():
        raise DatasetError(f"missing label file {path}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            f = np.loadtxt(path, dtype=np.float64, ndmin=1)
    except ValueError as e:
        raise DatasetError(f"malformed label file {path}: {e}") from None
    if f.ndim != 1 or len(f) != n:
        raise DatasetError(f"{path} has {len(f)} flags for {n} frames")
    if not np.all((f == 0) | (f == 1)):
        raise DatasetError(f"{path} has flags other than 0 / 1")
    return f.astype(bool)


def _lines(bad: np.ndarray) -> str:
    """' (and N more lines)' after the first bad line of a label file, or ''."""
    return f" (and {len(bad) - 1} more line(s))" if len(bad) > 1 else ""


def _check_labels(seq: Path, gt2d: np.ndarray, gt3d: np.ndarray, absent: np.ndarray, cut: np.ndarray,
                  width: int, height: int) -> tuple[np.ndarray, str | None]:
    """(2D labels, warning or None): refuse labels that cannot be right on a present frame, in one
    line naming file and line: a 3D box behind the camera or of no size, a 2D box 0,0,0,0 (the
    absence flag forgotten) or of no size, or wholly outside the image; clip those reaching a few
    pixels past it on a frame flagged cut (the warning says how many and how far), refuse those
    reaching further or past it on a frame flagged uncut (LABEL_SLACK_PX, LABEL_CLIP_PX,
    LABEL_CLIP_SHARE)."""
    present = ~absent
    f3, f2 = seq / GT3D, seq / GT2D
    bad = np.flatnonzero(present & (gt3d[:, 2] <= 0))
    if len(bad):
        i = bad[0]
        raise DatasetError(f"{f3} line {i + 1}: cz = {gt3d[i, 2]:g} on a present frame: the 3D label's centre must be "
                           f"in front of the camera (cz > 0; left camera frame, x right, y down, z forward, "
                           f"metres){_lines(bad)}")
    bad = np.flatnonzero(present & np.any(gt3d[:, 3:] <= 0, axis=1))
    if len(bad):
        i = bad[0]
        k = int(np.argmax(gt3d[i, 3:] <= 0))
        raise DatasetError(f"{f3} line {i + 1}: {('sx', 'sy', 'sz')[k]} = {gt3d[i, 3 + k]:g} on a present frame: "
                           f"sx, sy, sz are the box's full extents in metres, > 0{_lines(bad)}")
    bad = np.flatnonzero(present & np.all(gt2d == 0, axis=1))
    if len(bad):
        i = bad[0]
        raise DatasetError(f"{f2} line {i + 1}: 0,0,0,0 on a frame that {ABSENCE} marks present (its line {i + 1} "
                           f"is 0): a frame without the target is flagged 1 in {ABSENCE}{_lines(bad)}")
    x, y, w, h = gt2d.T
    bad = np.flatnonzero(present & ((w <= 0) | (h <= 0)))
    if len(bad):
        i = bad[0]
        raise DatasetError(f"{f2} line {i + 1}: w = {w[i]:g}, h = {h[i]:g} on a present frame: a 2D label is "
                           f"x, y, w, h with w, h > 0{_lines(bad)}")
    bad = np.flatnonzero(present & ((x >= width) | (y >= height) | (x + w <= 0) | (y + h <= 0)))
    if len(bad):
        i = bad[0]
        raise DatasetError(f"{f2} line {i + 1}: {','.join(f'{v:g}' for v in gt2d[i])} lies wholly outside the "
                           f"{width}x{height} image on a present frame{_lines(bad)}")
    sides = np.stack([-x, -y, x + w - width, y + h - height], axis=1)     # px past the left, top, right, bottom
    past = sides.max(axis=1)
    over = present & (past > LABEL_SLACK_PX)
    if not over.any():
        return gt2d, None

    def shown(i):
        return (f"{f2} line {i + 1}: {','.join(f'{v:g}' for v in gt2d[i])} reaches {past[i]:g} px past the "
                f"{width}x{height} image")

    bad = np.flatnonzero(over & ~cut)
    if len(bad):
        i = bad[0]
        raise DatasetError(f"{shown(i)} on a frame {CUT} marks uncut (its line {i + 1} is 0): 2D labels are clipped "
                           f"to the image (and x, y, w, h, not x1, y1, x2, y2); a target cut by the border is "
                           f"flagged 1 there{_lines(bad)}")
    limit = np.maximum(LABEL_CLIP_PX, LABEL_CLIP_SHARE * np.stack([w, h, w, h], axis=1))
    bad = np.flatnonzero(over & np.any(sides > limit, axis=1))
    if len(bad):
        i = bad[0]
        raise DatasetError(f"{shown(i)}: a few px past it are clipped (up to {LABEL_CLIP_PX:g} px or "
                           f"{100 * LABEL_CLIP_SHARE:g}% of the box's side), further is not the visible part's "
                           f"box (the whole body's, or x1, y1, x2, y2?){_lines(bad)}")
    rows = np.flatnonzero(over)
    i = rows[np.argmax(past[rows])]
    gt2d = gt2d.copy()
    # clipped as the evaluation clips a predicted box for its IoU: a perfect prediction scores 1
    gt2d[rows] = clip_box2d(gt2d[rows], width, height)
    return gt2d, (f"{f2}: {len(rows)} line(s) reach past the {width}x{height} image, by up to {past[i]:g} px "
                  f"(line {i + 1}): clipped to the image (2D labels are the visible part's box; docs/dataset.md)")


def _check_frame_files(seq: Path, sub: str, n: int) -> dict[int, str]:
    """The folder `sub` of a sequence holds exactly frame_name(0) .. frame_name(n - 1) (n label
    rows), the extension in any case (000001.PNG: some cameras and Windows tools write it), checked
    when the sequence is opened; what differs is named in one line. Returns {index: file name} of
    the frames whose name is not frame_name(index) (it is opened by that name: on a case-sensitive
    file system 000001.png is not 000001.PNG)."""
    folder = seq / sub
    try:
        names = [f.name for f in folder.iterdir()] if folder.is_dir() else []
    except OSError as e:
        raise DatasetError(f"cannot list {folder}: {e}") from None
    # hidden files are no frames (macOS's ._000001.png on a FAT / exFAT / SMB copy)
    found: dict[str, str] = {}   # the name in lower case -> the file's name
    for f in sorted(f for f in names if f.lower().endswith(".png") and not f.startswith(".")):
        if f.lower() in found:   # two files of one name: which one is the frame is not ours to guess
            raise DatasetError(f"{folder} holds both {found[f.lower()]} and {f} (names that differ only in case): "
                               f"keep one")
        found[f.lower()] = f
    pngs = set(found)
    want = {frame_name(i) for i in range(n)}
    if pngs == want:
        return {i: found[frame_name(i)] for i in range(n) if found[frame_name(i)] != frame_name(i)}
    span = f"{frame_name(0)} .. {frame_name(n - 1)} for the {n} label rows in {GT2D}" if n else \
        f"no frames for the 0 label rows in {GT2D}"
    stems = sorted(f[:-4] for f in pngs if f[:-4].isdigit())
    if pngs and len(stems) == len(pngs):
        digits = {len(t) for t in stems}
        if digits != {6}:
            eg = next(found[f"{t}.png"] for t in stems if len(t) != 6)
            raise DatasetError(f"{folder} has {min(digits) if len(digits) == 1 else 'other than 6'}-digit frame "
                               f"names ({eg}): frames are named {span}")
        if stems[0] == "000000":
            raise DatasetError(f"{folder} is numbered from {found['000000.png']}: frames are numbered from 1, {span}")
    # float depth (metres) often comes as TIFF, EXR, PFM or a numpy file
    others = sorted(f for f in names if f.lower().rsplit(".", 1)[-1] in ("jpg", "jpeg", "bmp", "tif", "tiff", "exr",
                                                                         "pfm", "npy"))
    if not pngs and others:
        raise DatasetError(f"{folder} holds {len(others)} {others[0].rsplit('.', 1)[-1]} image(s) and no PNG: "
                           f"frames are PNG files, {span}"
                           + (" (depth: 16-bit millimetres of z; track3d.dataset.write_depth_png writes float metres "
                              "as such)" if sub == DEPTH_DIR else ""))
    missing, extra = sorted(want - pngs), sorted(found[f] for f in pngs - want)
    what = []
    if missing:
        what.append(f"lacks {missing[0]}" + (f" and {len(missing) - 1} more" if len(missing) > 1 else ""))
    if extra:
        what.append(f"also holds {extra[0]}" + (f" and {len(extra) - 1} more" if len(extra) > 1 else ""))
    raise DatasetError(f"{seq}: {len(pngs)} images in {sub}/ but {n} label rows in {GT2D} ({sub}/ "
                       f"{' and '.join(what)}; frames are {span})")


def _projection_excess(camera: Camera, gt2d: np.ndarray, gt3d: np.ndarray, uncut: np.ndarray) -> np.ndarray:
    """Per usable frame, how far the 2D label's edges lie beyond where the 3D label can put them,
    over the 2D box's width (x edges) or height (y edges), PROJECTION_SLACK_PX forgiven.

    Usable: `uncut` (present, not cut by the image border), a 2D box of size that does not touch
    the border, and the whole 3D box in front of the camera. An edge of the silhouette is the
    image of a point on the 3D box face it touches (its left edge of a point with x = cx - sx/2,
    any y, z in the box), so it lies between that face's nearest and farthest projection, and
    inside the box's projected corners."""
    W, H = camera.width, camera.height
    x, y, w, h = gt2d.T
    lo = gt3d[:, :3] - gt3d[:, 3:] / 2
    hi = gt3d[:, :3] + gt3d[:, 3:] / 2
    use = uncut & (w > 0) & (h > 0) & (x > 1) & (y > 1) & (x + w < W - 1) & (y + h < H - 1) & (lo[:, 2] > 1e-6)
    if not use.any():
        return np.zeros(0)
    lo, hi, b = lo[use], hi[use], gt2d[use]
    zs = np.stack([lo[:, 2], hi[:, 2]], axis=1)
    out = np.zeros(len(b))
    for axis, f, c in ((0, camera.fx, camera.cx), (1, camera.fy, camera.cy)):
        a = f * lo[:, axis:axis + 1] / zs + c       # the low face (x = cx - sx/2) at the near / far z
        z = f * hi[:, axis:axis + 1] / zs + c       # the high face
        first, size = b[:, axis], b[:, 2 + axis]
        last = first + size
        worst = np.maximum.reduce([np.minimum(a.min(1), z.min(1)) - first, first - a.max(1),
                                   z.min(1) - last, last - np.maximum(a.max(1), z.max(1))])
        out = np.maximum(out, np.maximum(worst - PROJECTION_SLACK_PX, 0.0) / size)
    return out


@dataclass
class Frame:
    """One frame of a sequence. Arrays: image/right (H, W, 3) uint8 RGB; depth_m (H, W) float32;
    points (M, 3) float32 in the left frame; box2d (4,) [x, y, w, h]; box3d (6,)."""

    index: int
    image: np.ndarray
    right: np.ndarray | None
    depth_m: np.ndarray
    points: np.ndarray
    box2d: np.ndarray
    box3d: np.ndarray
    absent: bool
    cut: bool


class Sequence:
    """One sequence folder; labels load eagerly (small), images lazily per frame."""

    def __init__(self, path: str | Path, camera: Camera, split: str | None = None, points_only: bool | None = None,
                 image_bits: int | None = None):
        """image_bits: dataset.json's "image_bits" (Dataset passes it); None: looked up in the
        dataset.json two folders up when the frames are 16-bit."""
        self.path = Path(path)
        self.image_bits = image_bits
        if not self.path.is_dir():
            raise DatasetError(f"sequence folder {self.path} does not exist")
        self.name = self.path.name
        self.split = split
        self.camera = camera
        self.gt2d = _read_table(self.path / GT2D, 4)
        self.gt3d = _read_table(self.path / GT3D, 6)
        if len(self.gt2d) != len(self.gt3d):
            raise DatasetError(f"{self.path}: {len(self.gt2d)} 2D labels but {len(self.gt3d)} 3D labels")
        n = len(self.gt2d)
        self.absent = _read_flags(self.path / ABSENCE, n)
        self.cut = _read_flags(self.path / CUT, n)
        meta = self.path / META
        if not meta.is_file():
            raise DatasetError(f"missing sequence metadata {meta}")
        try:
            self.meta: dict = json.loads(meta.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise DatasetError(f"{meta} is not valid JSON: {e}") from None
        if not isinstance(self.meta, dict):
            raise DatasetError(f"{meta} is not a JSON object")
        family = self.meta.get("family_index", -1)
        if not isinstance(family, int) or isinstance(family, bool) or family < -1:
            raise DatasetError(f"{meta}: family_index must be an integer >= -1, got {family!r}")
        # points-only data (track3d-sim --points-only): depth and labels, no images
        self.points_only = bool(self.meta.get("points_only", False) if points_only is None else points_only)
        left = self.path / LEFT_DIR
        if not self.points_only and not left.is_dir():
            raise DatasetError(f"{self.path} has no {LEFT_DIR}/ image folder")
        # labels that cannot be right: refused, naming the file and line; a few px past the image: clipped
        self.gt2d, clipped = _check_labels(self.path, self.gt2d, self.gt3d, self.absent, self.cut, int(camera.width),
                                           int(camera.height))
        # Labels and images must cover the same frames, named 000001.png .. : shorter labels would
        # silently drop frames from tracking and scoring, missing or misnamed images would fail
        # mid-run. Points-only data has no images: its depth maps are the frames.
        self._names: dict[str, dict[int, str]] = {}   # per folder, the frames not named frame_name(i)
        for sub in (DEPTH_DIR,) if self.points_only else (LEFT_DIR, DEPTH_DIR, RIGHT_DIR):
            if sub == LEFT_DIR or self.points_only or (self.path / sub).is_dir():
                self._names[sub] = _check_frame_files(self.path, sub, n)
        # what reads but looks wrong: one warning each, naming the file or the sequence
        if clipped:
            _warn_once(clipped)
        self._check_meta(meta)
        self._check_projection()
        self._check_depth_units()
        if not self.points_only:
            self._check_image_bits()
            self._check_orientation()

    def _check_image_bits(self) -> None:
        """16-bit frames (the first left and right frame's PNG header): refuse, before anything is
        tracked, a first frame whose samples exceed the declared "image_bits", or, with none
        declared, one whose samples stay below 2**14: read as 16-bit it is at most a quarter of
        full scale (63 of 255), as a 10-, 12- or 14-bit camera's frame whose samples sit in the low
        bits is (EdgeTrack on a ToF test set with 12-bit frames read as 16: AO_2d 0.895 -> 0.699;
        14-bit: 0.841), and which bits are right only the camera's owner knows. One header read
        per folder; a 16-bit first frame is decoded (a few ms)."""
        for sub in (LEFT_DIR, RIGHT_DIR):
            if sub not in self._names or not len(self):
                continue
            path = self.image_path(0, sub)
            if _png_bit_depth(path) != 16:
                continue
            if self.image_bits is None:   # a Sequence opened without its Dataset
                # absolute: the parents of a relative path ("a" from inside the split folder) stop at "."
                root_json = self.path.absolute().parent.parent / DATASET_JSON
                try:
                    info = json.loads(root_json.read_text())
                except (OSError, ValueError):
                    info = None
                self.image_bits = _image_bits(info, root_json) if isinstance(info, dict) else None
            a = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if a is None or a.dtype != np.uint16:
                continue   # read_rgb names what is wrong with it when the frame is read
            top = int((a if a.ndim == 2 else a[..., :min(a.shape[2], 3)]).max(initial=0))
            bits = self.image_bits
            if bits is None and top < 1 << 14:
                raise DatasetError(f"{path} is a 16-bit image whose largest sample is {top} of 65535: read as 16-bit it is "
                                   f"nearly black ({to_uint8(np.uint16(top), 16)} of 255 at most); set "
                                   f"\"image_bits\" in {DATASET_JSON} to the camera's bit depth (12 for samples 0..4095), or "
                                   f"to 16 if its frames are this dark (docs/dataset.md)")
            if bits is not None and top >> bits:
                raise DatasetError(f"{path} holds a sample of {top}, above the {bits}-bit camera's {(1 << bits) - 1} "
                                   f"that \"image_bits\" in {DATASET_JSON} declares: its bits are more (16 for samples "
                                   f"in the high bits)")

    def _check_orientation(self) -> None:
        """Warn once when the first left or right frame's PNG has an EXIF orientation other than
        1: frames are read as stored (the labels are in stored pixels), where OpenCV's
        IMREAD_COLOR had turned them by it and a viewer shows them turned. Its chunk list is
        read, not the image."""
        for sub in (LEFT_DIR, RIGHT_DIR):
            if sub not in self._names or not len(self):
                continue
            path = self.image_path(0, sub)
            o = _png_orientation(path)
            if o is not None and o != 1:
                _warn_once(f"{path}: its EXIF orientation ({o}: {_ORIENTATIONS.get(o, 'unknown')}) is ignored: "
                           f"frames are read as stored, as the labels are in stored pixels (a viewer may show it "
                           f"turned; docs/dataset.md \"Camera formats\")")

    def _check_meta(self, meta: Path) -> None:
        from .sensor_options import DEPTH_SENSORS

        issues = []
        name = self.depth_sensor
        known = ", ".join(DEPTH_SENSORS)
        if name is None:
            if self.meta.get("depth_sensor", "") is not None:   # an explicit null: unknown, said on purpose
                issues.append(f"no depth sensor named (\"depth_sensor\": one of {known}, or an object with that "
                              f"\"name\"; null: unknown on purpose)")
        elif name.lower() not in DEPTH_SENSORS:
            issues.append(f"depth sensor {name!r} is none the runtime knows ({known})")
        if issues:
            issues[-1] += ": the loop uses an unknown sensor's defaults"
        if "sun" in self.meta and self.sun_direction is None:
            issues.append("sun is not {\"direction\": [x, y, z]} (toward the sun, left camera frame): ignored")
        if issues:
            _warn_once(f"{meta}: " + "; ".join(issues))

    def _check_projection(self) -> None:
        """Warn once when the 3D labels, projected with the dataset's camera, cannot make the 2D
        labels (a convention mistake: module constant PROJECTION_TOLERANCE)."""
        d = _projection_excess(self.camera, self.gt2d, self.gt3d, ~self.absent & ~self.cut)
        if len(d) == 0:
            return
        m = float(np.median(d))
        if m > PROJECTION_TOLERANCE:
            _warn_once(f"{self.path}: the 3D labels projected with the dataset's camera do not give the 2D labels "
                       f"(edges {m:.2f} of the 2D box size beyond where the 3D box can put them, median of "
                       f"{len(d)} uncut frames): 3D labels y-up, in half extents or not in the left camera "
                       f"frame, 2D labels 1-based or x1,y1,x2,y2, or a principal point (K in {DATASET_JSON}) "
                       f"that is not the data's? (docs/dataset.md)")

    def _check_depth_units(self) -> None:
        """Warn once when the first present frame's depth inside its 2D label is far from the 3D
        label's z (depth maps or 3D labels in other units: module constant DEPTH_RATIO_LIMITS)."""
        present = np.flatnonzero(~self.absent & (self.gt2d[:, 2] > 0) & (self.gt2d[:, 3] > 0))
        if not len(present):
            return
        i = int(present[0])
        path = self.depth_path(i)
        try:
            depth = self._sized(read_depth_png(path), path)
        except DatasetError:   # missing or damaged: the frame says so when read (scoring needs no depth)
            return
        full = float(np.mean(depth >= DEPTH_MAX_M - 5e-4))
        if full > 0.5:
            _warn_once(f"{path}: {100 * full:.0f}% of the pixels hold 65535: no return is 0 in a depth map, "
                       f"not the largest value")
            return
        x, y, w, h = self.gt2d[i]
        x0, y0 = max(int(np.floor(x)), 0), max(int(np.floor(y)), 0)
        x1, y1 = min(int(np.ceil(x + w)), depth.shape[1]), min(int(np.ceil(y + h)), depth.shape[0])
        crop = depth[y0:y1, x0:x1]
        z = crop[crop > 0]
        if len(z) < _MIN_DEPTH_RETURNS:
            return
        med = float(np.median(z))
        cz, sz = float(self.gt3d[i, 2]), float(self.gt3d[i, 5])
        near, far = cz - sz / 2, cz + sz / 2
        ratio = med / far if med > far else (med / near if 0 < near and med < near else 1.0)
        lo, hi = DEPTH_RATIO_LIMITS
        if not lo <= ratio <= hi:
            _warn_once(f"{path}: the depth inside the 2D label (median {med:.4g} m) is {ratio:.3g}x the 3D label's z "
                       f"({near:.4g} .. {far:.4g} m, line {i + 1} of {GT3D}): depth maps are 16-bit millimetres "
                       f"of z and 3D labels metres (a depth map in centimetres or metres, or 3D labels in "
                       f"millimetres?)")

    def __len__(self) -> int:
        return len(self.gt2d)

    def __repr__(self) -> str:
        return f"Sequence({self.split}/{self.name}, {len(self)} frames)"

    @property
    def category(self) -> int:
        """Index of the coarse category (shape family), -1 if unknown."""
        return int(self.meta.get("family_index", -1))

    @property
    def depth_sensor(self) -> str | None:
        """Name of the depth sensor that made the depth maps ("ideal", "tof", "flash-lidar",
        "stereo"): meta.json depth_sensor (a name, or an object with "name"), else its alias
        sensor (a name); None when neither says."""
        sensor = self.meta.get("depth_sensor")
        name = sensor.get("name") if isinstance(sensor, dict) else sensor
        if not (isinstance(name, str) and name):
            name = self.meta.get("sensor")
        return name if isinstance(name, str) and name else None

    @property
    def depth_range_m(self) -> float | None:
        """The depth sensor's maximum range in metres (meta.json depth_sensor.max_range_m), None
        when unlimited (ideal depth, stereo) or not recorded."""
        sensor = self.meta.get("depth_sensor")
        r = sensor.get("max_range_m") if isinstance(sensor, dict) else None
        try:
            r = float(r)
        except (TypeError, ValueError):
            return None
        return r if np.isfinite(r) and r > 0 else None

    @property
    def sun_direction(self) -> np.ndarray | None:
        """Unit (3,) float64 vector toward the sun in the left camera's frame (meta.json
        sun.direction), None when not recorded or not three finite numbers of non-zero length."""
        sun = self.meta.get("sun")
        d = sun.get("direction") if isinstance(sun, dict) else None
        try:
            v = np.asarray(d, dtype=np.float64).reshape(3)
        except (TypeError, ValueError):
            return None
        n = float(np.linalg.norm(v))
        return v / n if np.all(np.isfinite(v)) and n > 1e-12 else None

    def image_path(self, i: int, side: str = LEFT_DIR) -> Path:
        """The file of frame i in the folder `side` (left, right or depth): frame_name(i), or the
        name it has there (000001.PNG)."""
        return self.path / side / self._names.get(side, {}).get(i, frame_name(i))

    def depth_path(self, i: int) -> Path:
        """The depth map of frame i (a writer replacing it writes this file: another case would be
        a second file of the frame, refused when the sequence is next opened)."""
        return self.image_path(i, DEPTH_DIR)

    def image(self, i: int) -> np.ndarray:
        if self.points_only:
            raise DatasetError(f"{self.path} is points-only data (depth and labels, no images): "
                               f"generate without --points-only to track in images")
        return self._sized(read_rgb(self.image_path(i), self.image_bits), self.image_path(i))

    def right_image(self, i: int) -> np.ndarray:
        """(H, W, 3) uint8 RGB of the right camera (stereo pairs)."""
        return self._sized(read_rgb(self.image_path(i, RIGHT_DIR), self.image_bits), self.image_path(i, RIGHT_DIR))

    def depth(self, i: int) -> np.ndarray:
        path = self.depth_path(i)
        return self._sized(read_depth_png(path), path)

    def _sized(self, a: np.ndarray, path: Path) -> np.ndarray:
        # a frame of another size than the dataset's camera: named here, with its file
        w, h = int(self.camera.width), int(self.camera.height)
        if a.shape[:2] != (h, w):
            raise DatasetError(f"{path} is {a.shape[1]}x{a.shape[0]} but the dataset's camera is {w}x{h}")
        return a

    def points(self, i: int) -> np.ndarray:
        """(M, 3) float32 point cloud of frame i, back-projected from its depth map."""
        return self.camera.backproject_depth(self.depth(i))

    def frame(self, i: int, right: bool = False) -> Frame:
        if not 0 <= i < len(self):
            raise IndexError(f"frame {i} out of range for {self!r}")
        depth = self.depth(i)
        image = self.image(i)
        return Frame(i, image, self.right_image(i) if right else None, depth,
                     self.camera.backproject_depth(depth), self.gt2d[i].copy(), self.gt3d[i].copy(),
                     bool(self.absent[i]), bool(self.cut[i]))

    def __getitem__(self, i: int) -> Frame:
        return self.frame(i, right=True)

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self.frame(i)


def _not_a_root(root: Path) -> str:
    """Why `root` is no dataset root, naming what it is when it is something else."""
    if not root.exists():
        return (f"no dataset at {root}: the folder does not exist "
                f"(generate one with `track3d-sim generate --out {root}`)")
    if not root.is_dir():
        return f"no dataset at {root}: it is a file, not a folder (pass the folder holding {DATASET_JSON})"
    if (root / GENERATE_RUN_FILE).is_file():
        # the simulator writes its settings first and dataset.json last
        return (f"no dataset at {root} yet: a `track3d-sim generate` into it did not finish "
                f"(run the same command again: it goes on where it stopped)")
    if (root / GT2D).is_file() or (root / LEFT_DIR).is_dir():
        up = root.parent.parent
        return (f"{root} is a sequence folder, not a dataset root: pass the folder holding {DATASET_JSON}"
                + (f" ({up}; `track3d track` / `eval` take --sequence {root.name})" if (up / DATASET_JSON).is_file()
                   else ""))
    if (root.parent / DATASET_JSON).is_file():
        return f"{root} is a split folder of a dataset: pass its parent {root.parent} and --split {root.name}"
    try:
        subs = [d for d in root.iterdir() if d.is_dir()]
    except OSError:
        subs = []
    if (root / "list.txt").is_file() or any((d / "groundtruth.txt").is_file() for d in subs[:50]) or \
            any((d / "list.txt").is_file() for d in subs[:10]):
        return (f"{root} looks like a GOT-10k style 2D dataset (list.txt / groundtruth.txt): track3d needs "
                f"a track3d dataset with depth and 3D labels ({DATASET_JSON}; see docs/simulator.md)")
    if any((d / GT2D).is_file() for d in subs[:50]):
        return f"{root} holds sequence folders but no {DATASET_JSON}: it is a split folder, pass the dataset root"
    try:
        empty = not any(root.iterdir())
    except OSError:
        empty = False
    if empty:
        return (f"no dataset at {root}: the folder is empty "
                f"(generate one with `track3d-sim generate --out {root}`)")
    return (f"no dataset at {root}: {DATASET_JSON} is missing, and the folder holds other things "
            f"(a dataset root holds {DATASET_JSON} and its split folders: docs/dataset.md)")


class Dataset:
    """A dataset root written by the simulator."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        meta = self.root / DATASET_JSON
        if not meta.is_file():
            raise DatasetError(_not_a_root(self.root))
        try:
            self.info: dict = json.loads(meta.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise DatasetError(f"{meta} is not valid JSON: {e}") from None
        if not isinstance(self.info, dict):
            raise DatasetError(f"{meta} is not a JSON object")
        if self.info.get("format") != FORMAT:
            raise DatasetError(f"{meta} is not a {FORMAT} file")
        if "version" not in self.info:
            raise DatasetError(f"{meta} has no 'version' (the format version, an integer: {FORMAT_VERSION})")
        version = self.info["version"]
        if not isinstance(version, int) or isinstance(version, bool) or version < 1:
            raise DatasetError(f"{meta}: 'version' must be an integer >= 1 (this reader's is {FORMAT_VERSION}), "
                               f"got {version!r:.40}")
        if version > FORMAT_VERSION:
            raise DatasetError(f"{meta} has format version {version!r}, "
                               f"this reader knows up to {FORMAT_VERSION}")
        if not isinstance(self.info.get("camera"), dict):
            raise DatasetError(f"{meta} has no 'camera' object")
        try:
            self.camera = Camera.from_dict(self.info["camera"])
        except (ValueError, TypeError) as e:
            raise DatasetError(f"{meta}: bad camera: {e}") from None
        splits = self.info.get("splits", {})
        if not isinstance(splits, dict) or not all(
                isinstance(v, list) and all(isinstance(n, str) and n and "/" not in n and n not in (".", "..")
                                            for n in v) for v in splits.values()):
            raise DatasetError(f"{meta}: 'splits' must map each split name to a list of sequence names")
        self.points_only = bool(self.info.get("points_only", False))
        self.image_bits = _image_bits(self.info, meta)

    @cached_property
    def splits(self) -> dict[str, list[str]]:
        return {k: list(v) for k, v in self.info.get("splits", {}).items()}

    @property
    def categories(self) -> dict:
        return self.info.get("categories", {})

    def sequences(self, split: str) -> list[Sequence]:
        if split not in self.splits:
            has = ", ".join(f"{k}" if v else f"{k} (empty)" for k, v in self.splits.items())
            raise DatasetError(f"split {split!r} not in {self.root} (has: {has or 'none'})")
        return [Sequence(self.root / split / name, self.camera, split, self.points_only or None, self.image_bits)
                for name in self.splits[split]]

    def sequence(self, split: str, name: str) -> Sequence:
        if name not in self.splits.get(split, []):
            raise DatasetError(f"sequence {name!r} not in split {split!r} of {self.root}")
        return Sequence(self.root / split / name, self.camera, split, self.points_only or None, self.image_bits)
