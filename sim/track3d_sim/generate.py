"""Dataset generation: presets, settings validation, workers, progress and resume.

Layout and resume protocol:
  <out>/.track3d-sim-run.json   the settings of the run (written first; a later run into the
                                same folder must use the same settings, or it is refused)
  <out>/<split>/.partial-NNNN/  a sequence being written (deleted and redone on resume)
  <out>/<split>/NNNN/           a complete sequence (renamed atomically from .partial-NNNN)
  <out>/dataset.json            written last, atomically: its presence means "complete"
"""
from __future__ import annotations

import json
import math
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from . import __version__
from .errors import SimError
from .scenes import SCENES
from .sequence import ALL_CATEGORIES, TEST_CATEGORIES, TRAIN_CATEGORIES, fine_name, plan, write_sequence
from .shapes import FAMILIES, load_user_mesh
from .textures import TEXTURES

RUN_FILE = ".track3d-sim-run.json"

PRESETS = {
    "tiny": {"width": 160, "height": 120, "fov_x_deg": 45.0, "train": 4, "test": 2, "frames": 8, "subdivisions": 4},
    "small": {"width": 640, "height": 480, "fov_x_deg": 45.0, "train": 18, "test": 9, "frames": 100, "subdivisions": 6},
    "paper": {"width": 640, "height": 480, "fov_x_deg": 45.0, "train": 360, "test": 135, "frames": 300, "subdivisions": 6},
}


def make_settings(preset: str = "small", seed: int = 0, **overrides) -> dict:
    """Settings of a run: a preset with overrides (None = keep the preset's value), validated."""
    if preset not in PRESETS:
        raise SimError(f"unknown preset {preset!r} (choose from {', '.join(PRESETS)})")
    s = dict(PRESETS[preset])
    s["preset"] = preset
    s["seed"] = seed
    for k, v in overrides.items():
        if v is not None:
            s[k] = v
    s.setdefault("meshes", [])
    for k in ("width", "height", "frames", "subdivisions", "train", "test", "seed"):
        try:
            s[k] = int(s[k])
        except (TypeError, ValueError):
            raise SimError(f"{k} must be an integer, got {s[k]!r}") from None
    if not (16 <= s["width"] <= 8192 and 16 <= s["height"] <= 8192):
        raise SimError(f"resolution {s['width']}x{s['height']} out of range (16..8192 pixels per side)")
    if not (1.0 <= float(s["fov_x_deg"]) <= 170.0):
        raise SimError(f"horizontal field of view {s['fov_x_deg']} deg out of range (1..170)")
    s["fov_x_deg"] = float(s["fov_x_deg"])
    if s["frames"] < 1:
        raise SimError(f"frames per sequence must be >= 1, got {s['frames']}")
    if s["train"] < 0 or s["test"] < 0 or s["train"] + s["test"] == 0:
        raise SimError(f"need a non-negative number of train/test sequences, not both zero "
                       f"(got train={s['train']}, test={s['test']})")
    if not 1 <= s["subdivisions"] <= 8:
        raise SimError(f"icosphere subdivisions must be in 1..8, got {s['subdivisions']}")
    if s["seed"] < 0:
        raise SimError(f"seed must be >= 0, got {s['seed']}")
    meshes = []
    for m in s["meshes"]:
        m = dict(m) if isinstance(m, dict) else {"path": str(m)}
        m["path"] = str(Path(m["path"]).resolve())
        size = m.get("size_m")
        load_user_mesh(m["path"], float(size) if size else 1.0)  # validates: raises SimError
        meshes.append(m)
    s["meshes"] = meshes
    return s


def camera_of(settings: dict):
    from track3d.camera import Camera
    return Camera.from_fov(settings["width"], settings["height"], settings["fov_x_deg"])


def _identity(settings: dict) -> dict:
    keys = ("preset", "seed", "width", "height", "fov_x_deg", "train", "test", "frames", "subdivisions", "meshes")
    return {"generator_version": __version__, **{k: settings[k] for k in keys}}


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def dataset_info(settings: dict, specs) -> dict:
    from track3d import boxes
    from track3d import dataset as ds
    cam = camera_of(settings)
    splits = {"train": [s.name for s in specs if s.split == "train"],
              "test": [s.name for s in specs if s.split == "test"]}
    return {
        "format": ds.FORMAT,
        "version": ds.FORMAT_VERSION,
        "camera": cam.to_dict(),
        "size_classes": boxes.SIZE_TEMPLATES.tolist(),
        "categories": {
            "shape_families": list(FAMILIES),
            "textures": list(TEXTURES),
            "fine": [fine_name(f, t) for f, t in ALL_CATEGORIES],
            "train_fine": [fine_name(f, t) for f, t in TRAIN_CATEGORIES],
            "test_fine": [fine_name(f, t) for f, t in TEST_CATEGORIES],
            "scenes": list(SCENES),
        },
        "splits": splits,
        "generator": {"name": "track3d-sim", "version": __version__, "preset": settings["preset"],
                      "seed": settings["seed"], "settings": _identity(settings)},
    }


def prepare_output(out: Path, settings: dict, overwrite: bool = False) -> str:
    """Check / create the output folder. Returns 'new', 'resume' or 'complete'."""
    from track3d import dataset as ds
    ident = _identity(settings)
    if out.exists() and not out.is_dir():
        raise SimError(f"output path {out} exists and is not a folder")
    if out.exists() and overwrite:
        if any(out.iterdir()) and not (out / RUN_FILE).exists() and not (out / ds.DATASET_JSON).exists():
            raise SimError(f"refusing to --overwrite {out}: it is not empty and not a track3d-sim output folder")
        shutil.rmtree(out)
    if out.exists() and any(out.iterdir()):
        run = out / RUN_FILE
        if not run.exists():
            raise SimError(f"output folder {out} is not empty and holds no {RUN_FILE}: "
                           f"choose a new --out (a track3d-sim run never writes into a foreign folder)")
        try:
            old = json.loads(run.read_text())
        except json.JSONDecodeError:
            raise SimError(f"{run} is corrupt; delete {out} or pass --overwrite") from None
        if old != ident:
            diff = sorted(k for k in set(old) | set(ident) if old.get(k) != ident.get(k))
            raise SimError(f"output folder {out} holds a run with different settings ({', '.join(diff)}); "
                           f"use the same settings to resume, a new --out, or --overwrite")
        return "complete" if (out / ds.DATASET_JSON).exists() else "resume"
    out.mkdir(parents=True, exist_ok=True)
    _atomic_write(out / RUN_FILE, json.dumps(ident, indent=1, sort_keys=True))
    return "new"


# ---- workers -------------------------------------------------------------------------------------
_W = {}


def _init_worker(settings, root, queue):
    _W.update(settings=settings, root=Path(root), queue=queue, camera=camera_of(settings))


def _work(spec):
    q = _W["queue"]
    write_sequence(spec, _W["settings"], _W["camera"], _W["root"], progress=lambda n: q.put(n))
    return spec.split, spec.name


def generate(settings: dict, out: str | Path, workers: int = 1, overwrite: bool = False,
             progress: bool = True, log=None) -> Path:
    """Generate (or resume) a dataset. Deterministic for a seed whatever `workers` is."""
    from track3d import dataset as ds
    log = log or (lambda msg: print(msg, file=sys.stderr))
    if int(workers) < 1:
        raise SimError(f"--workers must be >= 1, got {workers}")
    out = Path(out)
    state = prepare_output(out, settings, overwrite)
    specs = plan(settings["train"], settings["test"])
    info = dataset_info(settings, specs)
    if state == "complete":
        missing = [f"{s.split}/{s.name}" for s in specs if not (out / s.split / s.name).is_dir()]
        if not missing:
            log(f"{out}: dataset already complete ({len(specs)} sequences)")
            return out
        (out / ds.DATASET_JSON).unlink()
    for split in ("train", "test"):
        d = out / split
        d.mkdir(exist_ok=True)
        for p in d.glob(".partial-*"):
            shutil.rmtree(p)
    todo = [s for s in specs if not (out / s.split / s.name).is_dir()]
    done = len(specs) - len(todo)
    if done:
        log(f"{out}: resuming, {done} of {len(specs)} sequences already complete")
    total = len(todo) * settings["frames"]
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=total, unit="frame", desc="track3d-sim", file=sys.stderr, dynamic_ncols=True)
    t0 = time.time()
    try:
        if int(workers) == 1 or len(todo) <= 1:
            cam = camera_of(settings)
            for spec in todo:
                write_sequence(spec, settings, cam, out, progress=(bar.update if bar else None))
        else:
            import multiprocessing as mp
            ctx = mp.get_context("spawn")
            queue = ctx.Queue()
            with ctx.Pool(min(int(workers), len(todo)), initializer=_init_worker,
                          initargs=(settings, str(out), queue)) as pool:
                res = pool.map_async(_work, todo, chunksize=1)
                while True:
                    try:
                        n = queue.get(timeout=0.2)
                        if bar:
                            bar.update(n)
                    except Exception:
                        if res.ready():
                            break
                res.get()
                while not queue.empty():
                    n = queue.get()
                    if bar:
                        bar.update(n)
    finally:
        if bar:
            bar.close()
    _atomic_write(out / ds.DATASET_JSON, json.dumps(info, indent=1, sort_keys=True))
    dt = time.time() - t0
    if todo:
        log(f"{out}: wrote {len(todo)} sequences, {total} stereo frames in {dt:.1f} s "
            f"({dt / max(total, 1):.3f} s per frame, {workers} worker(s))")
    return out
