"""Contact sheet of shape generators (`track3d-sim shapes`): N bodies of each generator, rendered
by the dataset's own renderer (BodyRenderer + SolidTexture, lunar-Lambert, cast shadows), lit by
a sun from the upper left at a ~50 degree phase angle, each body filling its cell.
One row per generator, labelled with its name."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .errors import SimError
from .outfile import check_out, make_parent

__all__ = ["render_body", "contact_sheet"]


def render_body(shape, rng: np.random.Generator, size: int = 192, texture: int | None = None) -> np.ndarray:
    """(size, size, 3) uint8 image of `shape` in a random orientation, lit by the sun, no sensor noise."""
    from track3d.camera import Camera

    from .motion import rotvec_to_matrix
    from .render import BodyRenderer
    from .textures import TEXTURES, SolidTexture
    cam = Camera.from_fov(size, size, 40.0)
    tex = SolidTexture(int(rng.integers(len(TEXTURES))) if texture is None else texture, rng, shape.vertices)
    rend = BodyRenderer(shape, tex, cam)
    axis = rng.standard_normal(3)
    R = rotvec_to_matrix(axis / np.linalg.norm(axis) * rng.uniform(0, math.pi))
    z = shape.radius / math.tan(math.radians(40.0) / 2) * 1.08
    T = np.array([0.0, 0.0, z])
    sun = np.array([-0.55, -0.45, -0.45])  # toward the sun in the camera frame: upper left, ~50 deg phase
    sun /= np.linalg.norm(sun)
    c = rend.cast(R, T)
    dn, _ = rend.shade(c, R, sun, irradiance=1.0, ambient=2.0)
    img = np.zeros((size, size, 3), np.float32)
    img[c["mask"]] = dn
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def contact_sheet(out: str | Path, generators: list[str] | None = None, count: int = 6, seed: int = 0,
                  detail: int = 5, cell: int = 192, progress: bool = True) -> Path:
    """Write a PNG with `count` bodies of each generator (rows) and return its path.
    Raises SimError for an unknown generator name or a bad count / detail."""
    from PIL import Image, ImageDraw

    from .generators import GENERATORS, make_body
    out = check_out(out, "contact sheet", (".png", ".jpg", ".jpeg"))
    names = list(generators) if generators else list(GENERATORS)
    for n in names:
        if n not in GENERATORS:
            raise SimError(f"unknown shape generator {n!r} (choose from {', '.join(GENERATORS)})")
    if count < 1:
        raise SimError(f"--count must be >= 1, got {count}")
    if not 1 <= detail <= 8:
        raise SimError(f"--detail must be 1..8, got {detail}")
    if cell < 16:  # smaller cells leave no room for a body under its label
        raise SimError(f"--cell must be >= 16 pixels, got {cell}")
    label_h = 18
    sheet = Image.new("RGB", (count * cell, len(names) * (cell + label_h)), (0, 0, 0))
    draw = ImageDraw.Draw(sheet)
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(names) * count, desc="bodies", unit="body")
    for row, name in enumerate(names):
        y0 = row * (cell + label_h)
        g = GENERATORS[name]
        draw.text((4, y0 + 3), f"{name}  (coarse: {g.coarse}, {'star' if g.star_shaped else 'non-star'}-shaped)",
                  fill=(230, 230, 230))
        for k in range(count):
            rng = np.random.default_rng([int(seed), row, k])
            shape = make_body(name, rng, volume_m3=300.0, detail=detail)
            sheet.paste(Image.fromarray(render_body(shape, rng, cell)), (k * cell, y0 + label_h))
            if bar is not None:
                bar.update(1)
    if bar is not None:
        bar.close()
    make_parent(out)
    sheet.save(out, optimize=True)
    return out
