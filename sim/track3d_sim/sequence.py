"""One sequence: plan (shape, texture, scene, sun, motion) and render + write it.

Every random choice of a sequence comes from numpy generators seeded by
(global seed, split, sequence index) only, so the bytes never depend on the number
of workers or on which sequences were rendered before.
"""
from __future__ import annotations

import json
import math
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from track3d import dataset as ds

from .errors import SimError
from .motion import FPS, make_motion
from .render import BodyRenderer, hot_pixels, sensor
from .scenes import SCENES, make_background
from .shapes import FAMILIES, VOLUME_RANGE, Shape, load_user_mesh, procedural_shape, scale_to_volume
from .textures import TEXTURES, SolidTexture

SPLIT_IDS = {"train": 0, "test": 1}

# Fine-grained categories (family, texture) held out for the test split (GOT-10k protocol:
# train and test share none). Every family appears in test, so the coarse category is known.
TEST_CATEGORIES = ((0, 0), (1, 2), (2, 4), (0, 3), (1, 5))
ALL_CATEGORIES = tuple((f, t) for f in range(len(FAMILIES)) for t in range(len(TEXTURES)))
TRAIN_CATEGORIES = tuple(c for c in ALL_CATEGORIES if c not in TEST_CATEGORIES)


def fine_name(family: int, texture: int) -> str:
    return f"{FAMILIES[family]}/{TEXTURES[texture]}"


def sequence_name(index: int) -> str:
    return f"{index + 1:04d}"


@dataclass(frozen=True)
class SeqSpec:
    split: str
    index: int
    family: int
    texture: int
    scene: int

    @property
    def name(self) -> str:
        return sequence_name(self.index)


def plan(n_train: int, n_test: int) -> list[SeqSpec]:
    """Categories cycle through the split's fine-grained categories; scenes cycle through all 9."""
    specs = []
    for split, n, cats, off in (("train", n_train, TRAIN_CATEGORIES, 0), ("test", n_test, TEST_CATEGORIES, 4)):
        for i in range(n):
            f, t = cats[i % len(cats)]
            specs.append(SeqSpec(split, i, f, t, (i * 2 + off + i // 9) % len(SCENES)))
    return specs


def _rngs(seed: int, spec: SeqSpec):
    ss = np.random.SeedSequence([int(seed), SPLIT_IDS[spec.split], int(spec.index)])
    names = ("shape", "texture", "scene", "motion", "sun", "sensor")
    return {k: np.random.default_rng(s) for k, s in zip(names, ss.spawn(len(names)))}, ss


def _sun(rng: np.random.Generator) -> dict:
    """Sun direction (unit vector toward the sun, left camera frame) and irradiance.

    The phase angle (sun - body - observer) is mostly below ~90 deg so most of the visible
    surface is lit, sometimes large (thin crescents). Irradiance is mostly LOW (paper Fig. 4d):
    log-normal with median 0.35 of the exposure-saturating irradiance."""
    phase = min(abs(rng.normal(0.0, 55.0)), 150.0)
    az = rng.uniform(0, 2 * np.pi)
    a = math.radians(phase)
    # rotate the "toward camera" direction (0,0,-1) by the phase angle about an in-plane axis
    d = np.array([math.sin(a) * math.cos(az), math.sin(a) * math.sin(az), -math.cos(a)])
    E = float(np.clip(rng.lognormal(math.log(0.35), 0.5), 0.05, 1.6))
    return {"direction": d.tolist(), "phase_deg": phase, "irradiance": E}


def make_shape(spec: SeqSpec, rng: np.random.Generator, subdivisions: int, user_mesh: dict | None) -> Shape:
    lo, hi = VOLUME_RANGE
    volume = math.exp(rng.uniform(math.log(lo * 1.25), math.log(hi / 1.25)))
    if user_mesh is not None:
        shape = load_user_mesh(user_mesh["path"], user_mesh.get("size_m") or 1.0)
        if not user_mesh.get("size_m"):
            shape.vertices = scale_to_volume(shape.vertices, volume)
            shape.params["target_volume_m3"] = volume
        return shape
    return procedural_shape(spec.family, rng, volume, subdivisions)


def render_sequence(spec: SeqSpec, settings: dict, camera, out_dir: Path | None = None, progress=None,
                    keep_right_depth: bool = False):
    """Render a sequence; write it under out_dir (a folder that must not exist yet) if given.

    Returns a dict with the labels and (when keep_right_depth) the right depth maps, used by tests.
    """
    rng, ss = _rngs(settings["seed"], spec)
    meshes = settings.get("meshes") or []
    user_mesh = meshes[spec.index % len(meshes)] if meshes else None
    shape = make_shape(spec, rng["shape"], settings["subdivisions"], user_mesh)
    texture = SolidTexture(spec.texture, rng["texture"], shape.vertices)
    renderer = BodyRenderer(shape, texture, camera)
    H, W, N = camera.height, camera.width, int(settings["frames"])
    tan_half = (math.tan(math.radians(camera.fov_x_deg) / 2), math.tan(math.radians(camera.fov_y_deg) / 2))
    motion = make_motion(rng["motion"], N, shape.radius, tan_half, inertia=shape.inertia())
    sun = _sun(rng["sun"])
    sun_dir = np.asarray(sun["direction"])
    margin = max(4, int(0.06 * W))
    bg = make_background(spec.scene, rng["scene"], H + 2 * margin, W + 2 * margin)
    drift0 = rng["scene"].uniform(0, 2 * margin, 2)
    drift_v = rng["scene"].normal(0, 0.25 * margin / max(N, 1), 2)  # pixels per frame
    ambient = 3.0 if SCENES[spec.scene] == "planet_limb" else 0.8
    hot_l = hot_pixels(rng["sensor"], H, W)
    hot_r = hot_pixels(rng["sensor"], H, W)
    right_eye = camera.right_offset

    if out_dir is not None:
        for sub in (ds.LEFT_DIR, ds.RIGHT_DIR, ds.DEPTH_DIR):
            (out_dir / sub).mkdir(parents=True, exist_ok=False)
    gt2d = np.zeros((N, 4), np.int64)
    gt3d = np.zeros((N, 6))
    absent = np.zeros(N, np.int64)
    cut = np.zeros(N, np.int64)
    frames_meta = {"object_pixels": [], "mean_object_dn": [], "lit_fraction": [], "R": [], "T": []}
    right_depths = []
    for i in range(N):
        R, T = motion["R"][i], motion["T"][i]
        X = shape.vertices @ R.T + T
        lo, hi = X.min(0), X.max(0)
        gt3d[i] = np.concatenate([(lo + hi) / 2, hi - lo])
        frng = np.random.default_rng([int(settings["seed"]), SPLIT_IDS[spec.split], spec.index, i, 1])
        off = np.clip(np.rint(drift0 + drift_v * i), 0, 2 * margin).astype(int)
        bgc = bg[off[1]:off[1] + H, off[0]:off[0] + W]
        images = []
        for side, eye, hot in (("left", np.zeros(3), hot_l), ("right", right_eye, hot_r)):
            c = renderer.cast(R, T, eye)
            dn, lit = renderer.shade(c, R, sun_dir, sun["irradiance"], ambient)
            img = bgc.copy()
            img[c["mask"]] = dn
            images.append(sensor(img, frng, hot))
            if side == "left":
                left = c
                ys, xs = np.nonzero(c["mask"])
                if len(xs):
                    gt2d[i] = [xs.min(), ys.min(), xs.max() + 1 - xs.min(), ys.max() + 1 - ys.min()]
                else:
                    absent[i] = 1
                umin, vmin, umax, vmax = c["bounds"]
                # truncated: the silhouette touches the border, or part of the body projects outside
                touches = len(xs) > 0 and (xs.min() == 0 or ys.min() == 0 or xs.max() == W - 1 or ys.max() == H - 1)
                cut[i] = int(len(xs) > 0 and (touches or umin < 0 or vmin < 0 or umax > W or vmax > H))
                frames_meta["object_pixels"].append(int(len(xs)))
                frames_meta["mean_object_dn"].append(round(float(images[0][c["mask"]].mean()), 3) if len(xs) else None)
                frames_meta["lit_fraction"].append(round(float(lit.mean()), 4) if len(xs) else None)
            elif keep_right_depth:
                right_depths.append(c["z"])
        frames_meta["R"].append(np.round(R.reshape(-1), 7).tolist())
        frames_meta["T"].append(np.round(T, 6).tolist())
        if out_dir is not None:
            name = ds.frame_name(i)
            ds.write_rgb(out_dir / ds.LEFT_DIR / name, images[0])
            ds.write_rgb(out_dir / ds.RIGHT_DIR / name, images[1])
            ds.write_depth_png(out_dir / ds.DEPTH_DIR / name, left["z"])
        if progress is not None:
            progress(1)
    meta = {
        "name": spec.name, "split": spec.split, "index": spec.index,
        "family": FAMILIES[spec.family], "family_index": spec.family,
        "texture": TEXTURES[spec.texture], "texture_index": spec.texture,
        "fine_category": fine_name(spec.family, spec.texture),
        "fine_index": ALL_CATEGORIES.index((spec.family, spec.texture)),
        "scene": SCENES[spec.scene], "scene_index": spec.scene,
        "shape": {"family": shape.family, "radius_m": shape.radius, "extent_m": shape.extent.tolist(),
                  "vertices": int(len(shape.vertices)), "faces": int(len(shape.faces)), **shape.params},
        "sun": sun, "ambient_dn": ambient, "motion": motion["info"],
        "seed": [int(settings["seed"]), SPLIT_IDS[spec.split], spec.index],
        "frames": len(gt2d), "fps": FPS, "frame_data": frames_meta,
    }
    if out_dir is not None:
        np.savetxt(out_dir / ds.GT2D, gt2d, fmt="%d", delimiter=",")
        np.savetxt(out_dir / ds.GT3D, gt3d, fmt="%.4f", delimiter=",")
        np.savetxt(out_dir / ds.ABSENCE, absent, fmt="%d")
        np.savetxt(out_dir / ds.CUT, cut, fmt="%d")
        (out_dir / ds.META).write_text(json.dumps(meta, indent=1, sort_keys=True))
    result = {"gt2d": gt2d, "gt3d": gt3d, "absent": absent, "cut": cut, "meta": meta, "shape": shape}
    if keep_right_depth:
        result["right_depth"] = right_depths
    return result


def write_sequence(spec: SeqSpec, settings: dict, camera, root: Path, progress=None) -> str:
    """Render into <root>/<split>/.partial-<name> and atomically rename to <root>/<split>/<name>."""
    final = root / spec.split / spec.name
    if final.exists():
        return spec.name
    tmp = root / spec.split / f".partial-{spec.name}"
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    render_sequence(spec, settings, camera, tmp, progress)
    os.replace(tmp, final)
    return spec.name
