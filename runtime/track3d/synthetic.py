"""Synthetic scenes and datasets without the simulator: an analytic, textured sphere.

    from track3d.synthetic import CAM, make_synthetic_dataset, render_sphere
    root = make_synthetic_dataset(tmp / "ds", {"a": 6, "b": 5})   # docs/dataset.md layout

The tests and the benchmarks (the fuzz run) share these, so neither edits ``sys.path`` to
borrow the other's code. numpy, OpenCV (through the dataset writer) and track3d only: no
simulator, no torch (the runtime's promise). `track3d.bench.synthetic_frames` is the larger,
640x480 scene for timing.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .camera import Camera
from .dataset import FORMAT, FORMAT_VERSION, frame_name, write_depth_png, write_labels, write_rgb

__all__ = ["CAM", "sphere_hits", "render_sphere", "sphere_path", "ellipsoid_returns", "rotation_y",
           "make_synthetic_dataset"]

CAM = Camera.from_fov(160, 120, 60.0)   # small, so that tests and fuzzing stay fast


def sphere_hits(rays: np.ndarray, centre: np.ndarray, radius: float):
    """Where z = 1 pixel rays (H, W, 3) meet a sphere: hit (H, W) bool, t (H, W) distance along
    the ray (= depth; 0 where missed), unit normals (H, W, 3) at the hit points."""
    a = np.sum(rays * rays, axis=-1)
    b = -2.0 * rays @ centre
    disc = b * b - 4 * a * (centre @ centre - radius ** 2)
    hit = disc >= 0
    t = np.where(hit, (-b - np.sqrt(np.where(hit, disc, 0.0))) / (2 * a), 0.0)
    return hit, t, (rays * t[..., None] - centre) / radius


def render_sphere(cam: Camera, centre, radius: float):
    """Image (H, W, 3) uint8, depth (H, W) float32 metres, tight 2D box, 3D box of a lit sphere."""
    c = np.asarray(centre, np.float64)
    hit, t, n = sphere_hits(cam.pixel_rays(), c, radius)
    depth = np.where(hit, t, 0.0).astype(np.float32)      # t is z because rays have z = 1
    shade = np.clip(n @ np.array([-0.5, -0.5, -0.7]), 0.05, 1.0)
    u = np.arange(cam.width)[None, :]
    v = np.arange(cam.height)[:, None]
    checker = 0.75 + 0.25 * (((u // 6) + (v // 6)) % 2)  # texture for the trackers to hold on to
    img = np.zeros((cam.height, cam.width, 3), np.uint8)
    val = (255 * shade * checker).astype(np.uint8)
    img[hit] = np.stack([val, (val * 0.9).astype(np.uint8), (val * 0.8).astype(np.uint8)], -1)[hit]
    vv, uu = np.nonzero(hit)
    box2d = np.array([uu.min(), vv.min(), uu.max() + 1 - uu.min(), vv.max() + 1 - vv.min()], np.float64) \
        if len(uu) else np.zeros(4)
    box3d = np.concatenate([c, [2 * radius] * 3])
    return img, depth, box2d, box3d


def ellipsoid_returns(cam: Camera, R: np.ndarray, centre, axes) -> tuple[np.ndarray, np.ndarray]:
    """An ideal depth sensor's returns of an ellipsoid with semi-axes `axes` (3,) m at attitude R
    (3, 3) (body -> camera) and `centre` (3,): (n, 3) float32, one per pixel whose ray meets it
    in front of the camera (the nearer root), and their 2D box [x, y, w, h] float64 (zeros when
    none): a turning body with a known back face, for the body's past views."""
    axes = np.asarray(axes, np.float64).reshape(3)
    centre = np.asarray(centre, np.float64).reshape(3)
    rays = cam.pixel_rays().reshape(-1, 3)
    # body coordinates q = R^T (t d - c); sum (q / axes)^2 = 1 is a quadratic in t
    d = (rays @ R) / axes
    c = (centre @ R) / axes
    a, b, k = (d * d).sum(1), -2.0 * (d @ c), c @ c - 1.0
    disc = b * b - 4 * a * k
    hit = disc > 0
    t = np.zeros(len(rays))
    t[hit] = (-b[hit] - np.sqrt(disc[hit])) / (2 * a[hit])
    hit &= t > 0
    if not hit.any():
        return np.zeros((0, 3), np.float32), np.zeros(4)
    v, u = np.divmod(np.flatnonzero(hit), cam.width)
    box = np.array([u.min(), v.min(), u.max() - u.min() + 1, v.max() - v.min() + 1], dtype=np.float64)
    return (rays[hit] * t[hit, None]).astype(np.float32), box


def rotation_y(deg: float) -> np.ndarray:
    """The rotation (3, 3) by `deg` degrees about the camera's vertical (y) axis."""
    a = np.radians(deg)
    return np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])


def sphere_path(n: int, start=(-1.0, 0.2, 12.0), step=(0.12, -0.02, 0.15)):
    return [np.asarray(start) + k * np.asarray(step) for k in range(n)]


def make_synthetic_dataset(root: Path, sequences: dict[str, int] | None = None, radius: float = 1.5,
                           absent: dict[str, list[int]] | None = None, split: str = "test",
                           camera: Camera = CAM) -> Path:
    """Write a tiny dataset in the docs/dataset.md layout: one moving sphere per sequence.

    absent: frames (0-based) of a sequence where the target is flagged absent (its image and
    depth are then empty and the 2D label zero, as the simulator does).
    """
    sequences = sequences or {"s0001": 8, "s0002": 6}
    absent = absent or {}
    root = Path(root)
    for k, (name, n) in enumerate(sequences.items()):
        d = root / split / name
        for sub in ("left", "right", "depth"):
            (d / sub).mkdir(parents=True, exist_ok=True)
        gt2d, gt3d, flags = [], [], []
        for i, c in enumerate(sphere_path(n, start=(-1.0 + 0.5 * k, 0.2, 12.0 + k))):
            img, depth, b2, b3 = render_sphere(camera, c, radius)
            gone = i in absent.get(name, [])
            if gone:
                img[:] = 0
                depth[:] = 0
                b2 = np.zeros(4)
            write_rgb(d / "left" / frame_name(i), img)
            write_rgb(d / "right" / frame_name(i), img)
            write_depth_png(d / "depth" / frame_name(i), depth)
            gt2d.append(b2)
            gt3d.append(b3)
            flags.append(int(gone))
        write_labels(d, np.array(gt2d, dtype=np.float64), np.array(gt3d), np.array(flags), np.zeros(n),
                     # depth_sensor null: no sensor of the simulator's, said on purpose (no warning)
                     {"family_index": 0, "depth_sensor": None}, decimals_3d=6)
    info = {"format": FORMAT, "version": FORMAT_VERSION, "camera": camera.to_dict(),
            "splits": {split: list(sequences)}}
    (root / "dataset.json").write_text(json.dumps(info))
    return root
