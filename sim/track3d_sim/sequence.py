"""One sequence: plan (generator, texture, scene, sensor, sun, motion) and render + write it.

Every random choice of a sequence comes from numpy generators seeded by
(global seed, split, sequence index) only, so the bytes never depend on the number
of workers, the backend (processes or Ray) or on which sequences were rendered before.

The plan is written against the generator registry (`generators.GENERATORS`): a generator
registered later appears in the plan, the fine categories and the splits without a change here
(an opt-in one, `Generator.default` False, only in runs that name it: `pool`).
"""
from __future__ import annotations

import math
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from track3d import dataset as ds

from .errors import SimError
from .generators import GENERATORS, coarse_index, default_generators, make_body
from .motion import FPS, make_motion
from .render import (BASE_EXPOSURE_MS, BLUR_STEP_PX, MAX_BLUR_SUBSTEPS, BodyRenderer, auto_exposure, blur_substeps,
                     exposure_poses, hot_pixels, sensor)
from .scenes import SCENES, make_background
from .sensors import (FALSE_ALARM_SENSORS, RenderedFrame, add_false_alarms, false_alarm_gate, measure_depth,
                      sensor_info)
from .shapes import FAMILIES, VOLUME_RANGE, Shape, body_extents, load_user_mesh, scale_to_volume
from .textures import TEXTURES, SolidTexture

SPLITS = ("train", "test", "test_unseen")
SPLIT_IDS = {"train": 0, "test": 1, "test_unseen": 2}

# The body source of sequences drawn from user meshes (--mesh / --mesh-dir): not a registered
# generator, coarse category -1.
USER = "user"

# The first release's generators (one per coarse category of the paper).
LEGACY_GENERATORS = tuple(FAMILIES)

# "Unseen shapes" split (test_unseen): whole generators held out of train and test, so the
# project measures generalisation to shapes it never trained on. The registered names listed
# here are held out; empty (or none registered) = the last UNSEEN_DEFAULT_COUNT non-legacy
# generators in registry order. With fewer than that many non-legacy generators, the one legacy
# family FALLBACK_UNSEEN is held out instead (and the run says so). `--unseen-generators a,b`
# overrides all of this. Nothing is held out when no test_unseen sequence is asked for.
# Held out: Mathilde-like bodies with giant concavities and angular fragments, two kinds of
# surface no other generator makes; the realistic families of the missions (bilobate,
# elongated, top-shaped, rubble piles) stay in training.
UNSEEN_GENERATORS: tuple[str, ...] = ("giant_craters", "fragment")
UNSEEN_DEFAULT_COUNT = 2
FALLBACK_UNSEEN = ("irregular",)


def test_textures(k: int) -> tuple[int, ...]:
    """Texture indices of the k-th body source (registry order) held out for the test split
    (GOT-10k protocol: train and test share no fine category). Two of six textures, one for
    every third source: 5 of each 18 fine categories, the first release's choice for the three
    legacy generators (contact_binary: regolith, mottled; spinning_top: layered, rusty_spotted;
    irregular: veined)."""
    n = len(TEXTURES)
    first, second = (2 * k) % n, (2 * k + 3) % n
    return (first,) if k % 3 == 2 else (first, second)


def source_index(generator: str) -> int:
    """Registry position of a generator (user meshes count as position 0 for the texture rule)."""
    names = list(GENERATORS)
    return names.index(generator) if generator in names else 0


def resolve_unseen(requested=None, n_unseen: int = 0, user_meshes: bool = False,
                   pool=None) -> tuple[tuple[str, ...], str]:
    """The generators held out for test_unseen and a note saying how they were chosen.

    requested: names from --unseen-generators (None = the default rule of UNSEEN_GENERATORS);
    pool: the generators train and test draw from (None = the default ones).
    Raises SimError for unknown names, for holding out every generator of the pool, and for an
    unseen split of user meshes."""
    if not requested and n_unseen <= 0:
        return (), "no test_unseen split"
    if user_meshes:
        raise SimError("an unseen-shapes split (--test-unseen / --unseen-generators) needs procedural generators, "
                       "not --mesh / --mesh-dir")
    if requested:
        names = tuple(dict.fromkeys(str(n).strip() for n in requested if str(n).strip()))
        bad = [n for n in names if n not in GENERATORS]
        if bad:
            raise SimError(f"unknown shape generator {bad[0]!r} in --unseen-generators "
                           f"(choose from {', '.join(GENERATORS)})")
        if n_unseen <= 0:
            raise SimError("--unseen-generators needs --test-unseen N > 0 (the number of unseen-shape sequences)")
        note = "held out by --unseen-generators"
    else:
        named = tuple(n for n in UNSEEN_GENERATORS if n in GENERATORS)
        new = [n for n in default_generators() if n not in LEGACY_GENERATORS]
        if named:
            names, note = named, "held out by UNSEEN_GENERATORS"
        elif len(new) >= UNSEEN_DEFAULT_COUNT:
            names = tuple(new[-UNSEEN_DEFAULT_COUNT:])
            note = f"held out: the last {UNSEEN_DEFAULT_COUNT} non-legacy generators in registry order"
        else:
            names = tuple(n for n in FALLBACK_UNSEEN if n in GENERATORS)
            note = (f"fewer than {UNSEEN_DEFAULT_COUNT} non-legacy generators registered: held out the legacy "
                    f"family {', '.join(names)} instead (its coarse category is then unseen in training)")
    if not names:
        raise SimError("no generator to hold out for test_unseen")
    if not [g for g in (pool or default_generators()) if g not in names]:
        raise SimError(f"--unseen-generators would hold out every generator ({', '.join(names)}): "
                       f"training needs at least one")
    return names, note


def resolve_pool(requested=None) -> tuple[str, ...] | None:
    """The generators train and test draw from, in registry order: the names of --generators
    (SimError for an unknown one), None when none are named (the default generators)."""
    names = [str(n).strip() for n in (requested or ()) if str(n).strip()]
    if not names:
        return None
    bad = [n for n in names if n not in GENERATORS]
    if bad:
        raise SimError(f"unknown shape generator {bad[0]!r} in --generators (choose from {', '.join(GENERATORS)})")
    return tuple(g for g in GENERATORS if g in names)


def split_categories(unseen=(), user_meshes: bool = False, pool=None) -> dict[str, list[tuple[str, int]]]:
    """Fine categories (body source, texture index) of each split, in the order sequences cycle
    through them. train and test share no fine category and use the same sources (`pool`, None =
    the default generators); test_unseen holds every texture of the held-out generators."""
    pool = [USER] if user_meshes else [g for g in (pool or default_generators()) if g not in unseen]
    held = {g: test_textures(source_index(g)) for g in pool}
    train = [(g, t) for g in pool for t in range(len(TEXTURES)) if t not in held[g]]
    test = [(g, held[g][j]) for j in range(2) for g in pool if j < len(held[g])]
    test_unseen = [(g, t) for t in range(len(TEXTURES)) for g in unseen]
    return {"train": train, "test": test, "test_unseen": test_unseen}


def body_sources(user_meshes: bool = False, pool=None, unseen=()) -> list[str]:
    """Every body source of a run, in the order of the fine-category list: the default
    generators and the opt-in ones of `pool` or held out in `unseen` (registry order)."""
    named = set(pool or ()) | set(unseen or ())
    return [USER] if user_meshes else [g for g, v in GENERATORS.items() if v.default or g in named]


def fine_name(generator: str, texture: int) -> str:
    return f"{generator}/{TEXTURES[texture]}"


def sequence_name(index: int) -> str:
    return f"{index + 1:04d}"


@dataclass(frozen=True)
class SeqSpec:
    """split: one of SPLITS; index: 0-based in the split; generator: a name in
    generators.GENERATORS or USER; texture / scene: indices into TEXTURES / SCENES;
    mesh: index into settings["meshes"] for USER bodies (-1 otherwise);
    sensor: a name in sensors.DEPTH_SENSORS."""

    split: str
    index: int
    generator: str
    texture: int
    scene: int
    mesh: int = -1
    sensor: str = "ideal"

    @property
    def name(self) -> str:
        return sequence_name(self.index)

    @property
    def fine_category(self) -> str:
        return fine_name(self.generator, self.texture)


def plan(n_train: int, n_test: int, n_test_unseen: int = 0, unseen=(), sensors=("ideal",),
         n_meshes: int = 0, pool=None) -> list[SeqSpec]:
    """Every sequence of a run. Categories cycle through the split's fine categories, scenes
    through all 9, sensors through `sensors` (offset by split), user meshes by sequence index;
    pool: the generators of train and test (None = the default ones)."""
    cats = split_categories(tuple(unseen), n_meshes > 0, pool)
    specs = []
    for split, n, off in (("train", n_train, 0), ("test", n_test, 4), ("test_unseen", n_test_unseen, 7)):
        if n > 0 and not cats[split]:
            raise SimError(f"split {split} has no fine category to draw from")
        for i in range(n):
            g, t = cats[split][i % len(cats[split])]
            specs.append(SeqSpec(split, i, g, t, (i * 2 + off + i // 9) % len(SCENES),
                                 i % n_meshes if g == USER else -1,
                                 sensors[(i + SPLIT_IDS[split]) % len(sensors)]))
    return specs


def _rngs(seed: int, spec: SeqSpec):
    ss = np.random.SeedSequence([int(seed), SPLIT_IDS[spec.split], int(spec.index)])
    names = ("shape", "texture", "scene", "motion", "sun", "sensor")
    return {k: np.random.default_rng(s) for k, s in zip(names, ss.spawn(len(names)))}, ss


def _sun(rng: np.random.Generator, phase_range: tuple[float, float] | None = None) -> dict:
    """Sun direction (unit vector toward the sun, left camera frame) and irradiance.

    The phase angle (sun - body - observer) is mostly below ~90 deg so most of the visible
    surface is lit, sometimes large (thin crescents). Irradiance is mostly LOW (paper Fig. 4d):
    log-normal with median 0.35 of the exposure-saturating irradiance.

    phase_range (degrees, lo <= hi): the phase is drawn uniformly in it instead. It is drawn
    after the default draws, so a sequence keeps its azimuth and irradiance (and every other
    stream) and only its lighting changes: a stress set is the default set lit from elsewhere."""
    phase = min(abs(rng.normal(0.0, 55.0)), 150.0)
    az = rng.uniform(0, 2 * np.pi)
    E = float(np.clip(rng.lognormal(math.log(0.35), 0.5), 0.05, 1.6))
    if phase_range is not None:
        phase = float(rng.uniform(phase_range[0], phase_range[1]))
    a = math.radians(phase)
    # rotate the "toward camera" direction (0,0,-1) by the phase angle about an in-plane axis
    d = np.array([math.sin(a) * math.cos(az), math.sin(a) * math.sin(az), -math.cos(a)])
    return {"direction": d.tolist(), "phase_deg": phase, "irradiance": E}


# The box volumes (m^3) a sequence's body is drawn from (log-uniform), inside the paper's
# VOLUME_RANGE; user meshes without a size are scaled to them too.
SAMPLED_VOLUME_RANGE = (VOLUME_RANGE[0] * 1.25, VOLUME_RANGE[1] / 1.25)


def make_shape(spec: SeqSpec, rng: np.random.Generator, subdivisions: int, user_mesh: dict | None) -> Shape:
    """The body of a sequence: from its generator, or (generator USER) the user mesh, whose
    params name the file by name and sha256 only (never a path of the machine)."""
    lo, hi = SAMPLED_VOLUME_RANGE
    volume = math.exp(rng.uniform(math.log(lo), math.log(hi)))
    if spec.generator == USER:
        if user_mesh is None:
            raise SimError(f"sequence {spec.split}/{spec.name} needs a user mesh but the settings hold none")
        shape = load_user_mesh(user_mesh["path"], user_mesh.get("size_m") or 1.0)
        shape.params.update(source=user_mesh["name"], sha256=user_mesh["sha256"])
        if not user_mesh.get("size_m"):
            shape.vertices = scale_to_volume(shape.vertices, volume)
            # size_m keeps the meaning of --mesh FILE:SIZE_M, the length along the body's longest
            # own axis (shapes.body_extents): the volume rescale made it what it is, not the 1.0
            # the mesh was loaded at
            shape.params["size_m"] = float(body_extents(shape.vertices)[2])
            shape.params["target_volume_m3"] = volume
        return shape
    return make_body(spec.generator, rng, volume, subdivisions)


def render_sequence(spec: SeqSpec, settings: dict, camera, out_dir: Path | None = None, progress=None,
                    keep_right_depth: bool = False, keep_depth: bool = False):
    """Render a sequence; write it under out_dir (a folder that must not exist yet) if given.

    Returns a dict with the labels and (when keep_right_depth / keep_depth) the right depth maps
    and the stored (sensor-measured) left depth maps, used by tests.
    """
    rng, ss = _rngs(settings["seed"], spec)
    depth_sensor = sensor_info(spec.sensor)  # an unknown name fails here, before any work
    if float(settings.get("false_alarms") or 0.0) > 0.0 and spec.sensor in FALSE_ALARM_SENSORS:
        depth_sensor = {**depth_sensor, "false_alarm_rate": float(settings["false_alarms"]),
                        "false_alarm_gate_m": list(false_alarm_gate(spec.sensor))}
    meshes = settings.get("meshes") or []
    user_mesh = meshes[spec.mesh] if spec.generator == USER and 0 <= spec.mesh < len(meshes) else None
    # points-only (box-network data): depth, labels and meta; no shading, shadow rays or images
    points_only = bool(settings.get("points_only", False))
    shape = make_shape(spec, rng["shape"], settings["subdivisions"], user_mesh)
    texture = SolidTexture(spec.texture, rng["texture"], shape.vertices)
    renderer = BodyRenderer(shape, texture, camera)
    H, W, N = camera.height, camera.width, int(settings["frames"])
    tan_half = camera.tan_half
    motion = make_motion(rng["motion"], N, shape.radius, tan_half, inertia=shape.inertia())
    phase_range = settings.get("sun_phase")
    sun = _sun(rng["sun"], tuple(phase_range) if phase_range is not None else None)
    sun_dir = np.asarray(sun["direction"])
    margin = max(4, int(0.06 * W))
    if not points_only:  # the scene's draws only shape the images
        bg = make_background(spec.scene, rng["scene"], H + 2 * margin, W + 2 * margin)
        drift0 = rng["scene"].uniform(0, 2 * margin, 2)
        drift_v = rng["scene"].normal(0, 0.25 * margin / max(N, 1), 2)  # pixels per frame
    ambient = 3.0 if SCENES[spec.scene] == "planet_limb" else 0.8
    # drawn in points-only runs too, so the sensor stream that follows is that of the full render
    hot_l = hot_pixels(rng["sensor"], H, W)
    hot_r = hot_pixels(rng["sensor"], H, W)
    right_eye = camera.right_offset
    # camera effects (opt-in; render.py): per-sequence auto exposure, motion blur of fast frames
    exposure = auto_exposure(sun["irradiance"]) if settings.get("auto_exposure") else None
    exposure_ms = exposure.exposure_ms if exposure is not None else BASE_EXPOSURE_MS
    blur = bool(settings.get("motion_blur"))
    camera_effects = {"auto_exposure": exposure is not None, "exposure_ms": exposure_ms,
                      "gain": exposure.gain if exposure is not None else 1.0, "motion_blur": blur}
    if blur:
        camera_effects.update(blur_step_px=BLUR_STEP_PX, max_blur_substeps=MAX_BLUR_SUBSTEPS)

    if out_dir is not None:
        for sub in (ds.DEPTH_DIR,) if points_only else (ds.LEFT_DIR, ds.RIGHT_DIR, ds.DEPTH_DIR):
            (out_dir / sub).mkdir(parents=True, exist_ok=False)
    gt2d = np.zeros((N, 4), np.int64)
    gt3d = np.zeros((N, 6))
    absent = np.zeros(N, np.int64)
    cut = np.zeros(N, np.int64)
    frames_meta = {"object_pixels": [], "mean_object_dn": [], "lit_fraction": [], "R": [], "T": []}
    right_depths = []
    depths = []
    for i in range(N):
        R, T = motion["R"][i], motion["T"][i]
        X = shape.vertices @ R.T + T
        lo, hi = X.min(0), X.max(0)
        gt3d[i] = np.concatenate([(lo + hi) / 2, hi - lo])
        frng = np.random.default_rng([int(settings["seed"]), SPLIT_IDS[spec.split], spec.index, i, 1])
        if not points_only:
            off = np.clip(np.rint(drift0 + drift_v * i), 0, 2 * margin).astype(int)
            bgc = bg[off[1]:off[1] + H, off[0]:off[0] + W]
        images = []
        sub_poses = None
        if blur and not points_only:
            n_sub = blur_substeps(camera, shape.vertices,
                                  exposure_poses(motion["R"], motion["T"], i, exposure_ms, FPS, 2, ends=True))
            frames_meta.setdefault("blur_substeps", []).append(n_sub)
            if n_sub > 1:
                sub_poses = exposure_poses(motion["R"], motion["T"], i, exposure_ms, FPS, n_sub)
        sides = (("left", np.zeros(3), hot_l), ("right", right_eye, hot_r))
        for side, eye, hot in sides[:1] if points_only else sides:
            c = renderer.cast(R, T, eye)
            if not points_only:
                dn, lit = renderer.shade(c, R, sun_dir, sun["irradiance"], ambient)
                img = bgc.copy()
                img[c["mask"]] = dn
                if sub_poses is not None:
                    img = renderer.blurred_view(bgc, sub_poses, eye, sun_dir, sun["irradiance"], ambient)
                images.append(sensor(img, frng, hot, exposure))
            if side == "left":
                left = c
                if spec.sensor != "ideal":
                    cos_inc, albedo = renderer.surface(c)
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
                shaded = len(xs) and not points_only
                frames_meta["mean_object_dn"].append(round(float(images[0][c["mask"]].mean()), 3) if shaded else None)
                frames_meta["lit_fraction"].append(round(float(lit.mean()), 4) if shaded else None)
            elif keep_right_depth:
                right_depths.append(c["z"])
        depth = left["z"]
        rate = float(settings.get("false_alarms") or 0.0)
        alarms = None
        if rate > 0.0 and spec.sensor in FALSE_ALARM_SENSORS:
            # stream 3, drawn only in runs with false alarms: the other streams stay as they were
            alarms = (rate, np.random.default_rng([int(settings["seed"]), SPLIT_IDS[spec.split], spec.index, i, 3]))
        if spec.sensor != "ideal":
            # the sensor's own noise stream per frame, like frng (1) but stream 2
            drng = np.random.default_rng([int(settings["seed"]), SPLIT_IDS[spec.split], spec.index, i, 2])
            depth = measure_depth(spec.sensor, RenderedFrame(left["z"], cos_inc, albedo,
                                                                images[0] if images else None,
                                                                images[1] if images else None),
                                  camera, drng, false_alarms=alarms)
        elif alarms is not None:
            depth = add_false_alarms(depth, camera, alarms[0], false_alarm_gate(spec.sensor), alarms[1])
        frames_meta["R"].append(np.round(R.reshape(-1), 7).tolist())
        frames_meta["T"].append(np.round(T, 6).tolist())
        if keep_depth:
            depths.append(depth)
        if out_dir is not None:
            name = ds.frame_name(i)
            if not points_only:
                ds.write_rgb(out_dir / ds.LEFT_DIR / name, images[0])
                ds.write_rgb(out_dir / ds.RIGHT_DIR / name, images[1])
            ds.write_depth_png(out_dir / ds.DEPTH_DIR / name, depth)
        if progress is not None:
            progress(1)
    coarse = -1 if spec.generator == USER else coarse_index(spec.generator)
    family = USER if spec.generator == USER else FAMILIES[coarse]
    sources = body_sources(bool(meshes), settings.get("shape_generators"), settings.get("unseen_generators") or ())
    meta = {
        "name": spec.name, "split": spec.split, "index": spec.index,
        # family / family_index: the paper's coarse category (what Sequence.category reads), "user" / -1
        # for user meshes; fine category = generator/texture
        "generator": spec.generator, "family": family, "family_index": coarse,
        "texture": TEXTURES[spec.texture], "texture_index": spec.texture,
        "fine_category": spec.fine_category,
        "fine_index": sources.index(spec.generator) * len(TEXTURES) + spec.texture,
        "sensor": spec.sensor, "points_only": points_only,
        "scene": SCENES[spec.scene], "scene_index": spec.scene,
        "shape": {"family": shape.family, "radius_m": shape.radius, "extent_m": shape.extent.tolist(),
                  "vertices": int(len(shape.vertices)), "faces": int(len(shape.faces)), **shape.params},
        "sun": sun, "ambient_dn": ambient, "depth_sensor": depth_sensor,
        "camera_effects": camera_effects, "motion": motion["info"],
        "seed": [int(settings["seed"]), SPLIT_IDS[spec.split], spec.index],
        "frames": len(gt2d), "fps": FPS, "frame_data": frames_meta,
    }
    if out_dir is not None:
        ds.write_labels(out_dir, gt2d, gt3d, absent, cut, meta)
    result = {"gt2d": gt2d, "gt3d": gt3d, "absent": absent, "cut": cut, "meta": meta, "shape": shape}
    if keep_depth:
        result["depth"] = depths
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
