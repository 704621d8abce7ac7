"""`track3d-sim preview`: a contact sheet (PNG) or an animation (GIF) of a sequence with its labels.

Green: the 2D label (tight silhouette box). Red: the 3D label (amodal box) projected with
the camera (its 8 corners, edges drawn). Yellow frame number; 'ABSENT' / 'CUT' flags.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from .errors import SimError
from .outfile import check_out, make_parent

_EDGES = [(0, 1), (1, 3), (3, 2), (2, 0), (4, 5), (5, 7), (7, 6), (6, 4), (0, 4), (1, 5), (2, 6), (3, 7)]


def _open_sequence(path: Path):
    """The sequence at `path` (absolute or relative, "." too) of a dataset two levels up; a dataset
    root, a split folder or a folder outside any dataset is a one-line SimError saying which."""
    from track3d.dataset import DATASET_JSON, Dataset, DatasetError, Sequence
    given = Path(path)
    path = Path(os.path.abspath(given))  # "0001" or "." from inside a dataset: its parents are real
    if not path.is_dir():
        raise SimError(f"sequence folder {given} does not exist")
    if (path / DATASET_JSON).is_file():
        raise SimError(f"{given} is a dataset root, not a sequence: pass a sequence folder, "
                       f"e.g. {given / _first_sequence(path)}")
    if (path.parent / DATASET_JSON).is_file():
        first = next((d.name for d in sorted(path.iterdir()) if d.is_dir()), "0001")
        raise SimError(f"{given} is a split folder, not a sequence: pass one of its sequence folders, "
                       f"e.g. {given / first}")
    root = path.parent.parent
    if not (root / DATASET_JSON).is_file():
        raise SimError(f"{given} is not a sequence of a dataset (no {DATASET_JSON} in {root})")
    try:
        data = Dataset(root)
        # the user's spelling in messages, unless it has no folder name ("."); the Dataset's
        # image_bits, which the Sequence would otherwise look up in dataset.json again
        seq = Sequence(given if given.name == path.name else path, data.camera, path.parent.name,
                       data.points_only or None, data.image_bits)
    except DatasetError as e:
        raise SimError(str(e)) from None
    if seq.points_only:
        raise SimError(f"{given} is points-only data (generated with --points-only): no images to show")
    return seq


def _first_sequence(root: Path) -> str:
    """"test/0001": a sequence of the dataset at `root` to name in a message."""
    try:
        splits = json.loads((root / "dataset.json").read_text()).get("splits", {})
        return next(f"{sp}/{names[0]}" for sp, names in splits.items() if names)
    except Exception:  # an unreadable dataset.json: any example will do
        return "test/0001"


def draw_frame(seq, i: int, gain: float = 1.0, right: bool = False):
    from PIL import Image, ImageDraw
    fr = seq.frame(i, right=right)
    img = np.clip(fr.image.astype(np.float32) * gain, 0, 255).astype(np.uint8)
    im = Image.fromarray(img)
    d = ImageDraw.Draw(im)
    b = fr.box3d
    corners = np.array([[b[0] + sx * b[3] / 2, b[1] + sy * b[4] / 2, b[2] + sz * b[5] / 2]
                        for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    if np.all(corners[:, 2] > 0.05):
        uv = seq.camera.project(corners)
        for a, c in _EDGES:
            d.line([tuple(uv[a]), tuple(uv[c])], fill=(255, 60, 60), width=1)
    if not fr.absent:
        x, y, w, h = fr.box2d
        d.rectangle([x, y, x + w - 1, y + h - 1], outline=(60, 255, 60))
    tag = f"{seq.name}#{i + 1}" + (" ABSENT" if fr.absent else "") + (" CUT" if fr.cut else "")
    d.text((3, 2), tag, fill=(255, 255, 0))
    if right:
        r = Image.fromarray(np.clip(fr.right.astype(np.float32) * gain, 0, 255).astype(np.uint8))
        ImageDraw.Draw(r).text((3, 2), f"{seq.name}#{i + 1} right", fill=(255, 255, 0))   # the right tile said nothing
        both = Image.new("RGB", (im.width * 2 + 4, im.height), (40, 40, 40))
        both.paste(im, (0, 0))
        both.paste(r, (im.width + 4, 0))
        im = both
    return im


def shown_frames(sequence: str | Path, out: str | Path, n: int) -> tuple[int, int]:
    """(frames shown, frames in the sequence) of `preview(sequence, out, n)`: a GIF shows every
    frame, a sheet `n` spread over the sequence (at most all of them)."""
    total = len(_open_sequence(Path(sequence)))
    if Path(out).suffix.lower() == ".gif":
        return total, total
    return len(np.unique(np.linspace(0, total - 1, max(1, min(n, total))).round().astype(int))), total


def preview(sequence: str | Path, out: str | Path, n: int = 12, gain: float = 1.0, right: bool = False) -> Path:
    from PIL import Image, ImageDraw
    out = check_out(out, "preview", (".png", ".jpg", ".jpeg", ".gif"))
    seq = _open_sequence(Path(sequence))
    N = len(seq)
    if N == 0:
        raise SimError(f"{sequence} has no frames")
    if n < 1:  # 0 or -5 used to give a one-frame sheet without a word
        raise SimError(f"--frames must be >= 1, got {n}")
    if not (0 < gain < float("inf")):  # <= 0 gave black images, NaN a numpy warning and black
        raise SimError(f"--gain must be a positive number, got {gain}")
    if out.suffix.lower() == ".gif":
        frames = [draw_frame(seq, i, gain, right) for i in range(N)]
        make_parent(out)
        frames[0].save(out, save_all=True, append_images=frames[1:], duration=100, loop=0)
        return out
    idx = np.unique(np.linspace(0, N - 1, max(1, min(n, N))).round().astype(int))   # as shown_frames counts
    tiles = [draw_frame(seq, int(i), gain, right) for i in idx]
    cols = min(4 if not right else 2, len(tiles))
    rows = (len(tiles) + cols - 1) // cols
    tw, th = tiles[0].size
    sheet = Image.new("RGB", (cols * (tw + 2), rows * (th + 2) + 16), (30, 30, 30))
    for k, t in enumerate(tiles):
        sheet.paste(t, ((k % cols) * (tw + 2), (k // cols) * (th + 2) + 16))
    m = seq.meta
    head = ImageDraw.Draw(sheet)
    text = (f"{seq.split}/{seq.name}: {m.get('fine_category')}  scene={m.get('scene')}  "
            f"sun E={m.get('sun', {}).get('irradiance', 0):.2f} phase={m.get('sun', {}).get('phase_deg', 0):.0f}deg  ")
    head.text((4, 2), text, fill=(255, 255, 255))
    # the boxes' key: nothing had said which colour is which
    x = 4 + head.textlength(text)
    head.text((x, 2), "green: 2D label", fill=(60, 255, 60))
    head.text((x + head.textlength("green: 2D label  "), 2), "red: 3D label", fill=(255, 60, 60))
    make_parent(out)
    sheet.save(out)
    return out


def export_ply(sequence: str | Path, frame: int, out: str | Path) -> Path:
    """Write the back-projected point cloud of a frame (left frame, metres) with the left image's
    colours as a binary little-endian PLY, for viewing in MeshLab / CloudCompare / Open3D."""
    out = check_out(out, "point cloud (.ply)")
    seq = _open_sequence(Path(sequence))
    if not 1 <= frame <= len(seq):
        raise SimError(f"frame {frame} out of range 1..{len(seq)} of {sequence}")
    fr = seq.frame(frame - 1)
    vv, uu = np.nonzero(fr.depth_m > 0)
    pts = fr.points
    rgb = fr.image[vv, uu]
    rec = np.zeros(len(pts), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                    ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    rec["red"], rec["green"], rec["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"comment track3d {seq.split}/{seq.name} frame {frame}, left camera frame, metres\n"
              f"element vertex {len(rec)}\nproperty float x\nproperty float y\nproperty float z\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    make_parent(out)
    with open(out, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(rec.tobytes())
    return out


def ply_vertices(path: str | Path) -> int:
    """The vertex count a PLY file's header declares (export_ply's files; 0 when it names none)."""
    with open(path, "rb") as fh:
        for line in fh:
            if line.startswith(b"element vertex "):
                return int(line.split()[2])
            if line.strip() == b"end_header":
                break
    return 0
