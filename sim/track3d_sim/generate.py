"""Dataset generation: presets, settings validation, the plan, workers / Ray, progress and resume.

Layout and resume protocol:
  <out>/.track3d-sim-run.json   the settings of the run (written first; a later run into the
                                same folder must use the same settings, or it is refused)
  <out>/<split>/.partial-NNNN/  a sequence being written (deleted and redone on resume)
  <out>/<split>/NNNN/           a complete sequence (renamed atomically from .partial-NNNN)
  <out>/dataset.json            written last, atomically: its presence means "complete"

Backends: one process (`workers=1`), a local process pool (`workers=N`) or a Ray cluster
(`ray="local"` or an address): one task per sequence, each written with the same protocol, so
the bytes are the same whatever the backend and a killed run of any backend resumes.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import re
import shutil
import sys
import time
from collections import Counter
from pathlib import Path

from track3d.dataset import GENERATE_RUN_FILE

from . import __version__
from .errors import SimError
from .generators import GENERATORS
from .motion import DEPTH_RADIUS_MAX, radius_range
from .scenes import SCENES
from .sequence import (SAMPLED_VOLUME_RANGE, SPLITS, USER, body_sources, fine_name, plan, resolve_pool,
                       resolve_unseen, split_categories, write_sequence)
from .sensors import DEPTH_SENSORS, FALSE_ALARM_SENSORS, SENSORS_NEEDING_IMAGES
from .shapes import FAMILIES, USER_MESH_LOADER, load_user_mesh, mean_box_volume, user_mesh_warnings
from .textures import TEXTURES

RUN_FILE = GENERATE_RUN_FILE   # stated once, beside the layout it belongs to (track3d.dataset)

PRESETS = {
    "tiny": {"width": 160, "height": 120, "fov_x_deg": 45.0, "train": 4, "test": 2, "test_unseen": 0, "frames": 8,
             "subdivisions": 4},
    "small": {"width": 640, "height": 480, "fov_x_deg": 45.0, "train": 18, "test": 9, "test_unseen": 0,
              "frames": 100, "subdivisions": 6},
    "paper": {"width": 640, "height": 480, "fov_x_deg": 45.0, "train": 360, "test": 135, "test_unseen": 0,
              "frames": 300, "subdivisions": 6},
}

# Depth sensors whose depth is computed from the rendered images: they cannot run --points-only.


def _listed(names: list[str], most: int = 6) -> str:
    return ", ".join(names[:most]) + (f" and {len(names) - most} more" if len(names) > most else "")


def _mesh_files(folder: Path) -> tuple[list[Path], list[str]]:
    """The files of `folder` whose extension trimesh reads, sorted by name, and the names of the
    other files (skipped for their extension). Hidden files are neither: a name starting with '.'
    is the system's (macOS writes `._rock.obj` beside `rock.obj` on foreign disks: AppleDouble
    metadata under a mesh extension, which had failed the run as "not a mesh")."""
    import trimesh
    if not folder.is_dir():
        raise SimError(f"mesh folder {folder} does not exist or is not a folder")
    formats = {f.lower() for f in trimesh.available_formats()}
    visible = sorted((p for p in folder.iterdir() if p.is_file() and not p.name.startswith(".")),
                     key=lambda p: p.name)
    files = [p for p in visible if p.suffix.lower().lstrip(".") in formats]
    skipped = [p.name for p in visible if p.suffix.lower().lstrip(".") not in formats]
    if not files:
        raise SimError(f"mesh folder {folder} holds no mesh file trimesh reads "
                       f"({', '.join(sorted(formats)[:8])}, ...)"
                       + (f"; skipped for their extension: {_listed(skipped)}" if skipped else ""))
    return files, skipped


def _round(x: float, up: bool) -> float:
    """x to 3 significant digits, rounded inward so a bound the user copies is inside the range."""
    e = 10.0 ** (math.floor(math.log10(x)) - 2)
    return (math.ceil(x / e - 1e-9) if up else math.floor(x / e + 1e-9)) * e


# A bounding radius this small or more is held at any camera (the smallest procedural bodies are
# 1.5 m); below it, and below the view's lower bound (motion.radius_range), a body is refused
SMALL_RADIUS_OK = 1.0


def _user_mesh(path, size_m, camera) -> dict:
    """A validated user mesh: path (in memory only, for loading), file name, sha256, size, and the
    warnings its run logs (`shapes.user_mesh_warnings`; never written). Refused when the body's
    bounding radius (at its size, or at every sampled volume without one) is outside what the
    scenes hold at this camera (`motion.radius_range`)."""
    path = Path(path)  # as the user gave it: the messages name it so
    size = float(size_m) if size_m else None
    shape = load_user_mesh(path, size or 1.0)  # validates: raises SimError naming the file
    r_lo, r_hi = radius_range(camera.tan_half)
    if size:
        radii = (shape.radius, shape.radius)
        how = f"at {size:g} m (its length along its longest axis) has a bounding radius of {shape.radius:.3g} m"
    else:
        # scaled like sequence.make_shape: vertices * (volume / mean box volume) ** (1/3)
        k = [(v / mean_box_volume(shape.vertices)) ** (1.0 / 3.0) for v in SAMPLED_VOLUME_RANGE]
        radii = (shape.radius * k[0], shape.radius * k[1])
        how = (f"scaled to the sampled box volumes ({SAMPLED_VOLUME_RANGE[0]:g}-{SAMPLED_VOLUME_RANGE[1]:g} m^3, "
               f"no :SIZE) gets bounding radii of {radii[0]:.3g}-{radii[1]:.3g} m")
    # bounding radius per metre of SIZE: load_user_mesh scales the body's longest own axis (not the
    # longest side of its box in the file's axes) to SIZE, so the radius at SIZE is per_m * SIZE
    per_m = shape.radius / (size or 1.0)
    fov = [math.degrees(2 * math.atan(t)) for t in camera.tan_half]
    # below the view's lower bound a body is small in the image; refused only below it AND below
    # SMALL_RADIUS_OK: the lower bound grows without limit as the field of view nears 180 degrees
    # (7 m at 170), where procedural bodies from 1.5 m are made (a review)
    r_min = min(r_lo, SMALL_RADIUS_OK)
    if radii[0] < r_min or radii[1] > DEPTH_RADIUS_MAX:
        r_lo = r_min
        raise SimError(f"user mesh {path} {how}, outside the {_round(r_lo, True):g}-{_round(DEPTH_RADIUS_MAX, False):g} m "
                       f"the scenes hold at this camera ({camera.width}x{camera.height}, {fov[0]:.3g} x {fov[1]:.3g} "
                       f"deg: the body in view, its far side within 45 m): give it a size, --mesh {path}:SIZE "
                       f"with SIZE in {_round(r_lo / per_m, True):g}-{_round(DEPTH_RADIUS_MAX / per_m, False):g} m "
                       f"for this shape")
    warnings = user_mesh_warnings(shape, str(path))
    if radii[0] < r_lo:
        warnings.append(f"{path}: a bounding radius of {radii[0]:.3g} m is small in this camera's view (below "
                        f"{r_lo:.3g} m at {fov[0]:.3g} x {fov[1]:.3g} deg): a few pixels when far; --mesh "
                        f"{path}:SIZE with SIZE above {_round(r_lo / per_m, True):g} m shows it larger")
    if radii[1] > r_hi:
        # as large as the largest procedural bodies at a narrow camera: held, but no longer whole in view
        warnings.append(f"{path}: a bounding radius of up to {radii[1]:.3g} m fills this camera's view "
                        f"(above {r_hi:.3g} m at {fov[0]:.3g} x {fov[1]:.3g} deg): the body is cut by the image "
                        f"border in most frames; --mesh {path}:SIZE with SIZE below "
                        f"{_round(r_hi / per_m, False):g} m keeps it whole")
    return {"path": str(path.resolve()), "name": path.name, "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
            "size_m": size, "loader": USER_MESH_LOADER, "warnings": warnings}


def _names(value) -> list[str]:
    if value is None:
        return []
    if isinstance(value, str):
        value = value.split(",")
    return [str(v).strip() for v in value if str(v).strip()]


def make_settings(preset: str = "small", seed: int = 0, **overrides) -> dict:
    """Settings of a run: a preset with overrides (None = keep the preset's value), validated.

    Overrides besides the preset keys: meshes (list of paths or {"path", "size_m"}), mesh_dir
    (folder: every mesh file in it, cycled over the sequences), sensors (names or "a,b"),
    points_only (bool), unseen_generators (names or "a,b"), shape_generators (names or "a,b": the
    generators of train and test; None = the default ones), sun_phase ([lo, hi] degrees: the phase
    angle drawn uniformly in it; None = the default mix), false_alarms (per-pixel rate of false
    returns of the range sensors, sensors.add_false_alarms; 0 = none). Raises SimError (one line)."""
    if preset not in PRESETS:
        raise SimError(f"unknown preset {preset!r} (choose from {', '.join(PRESETS)})")
    s = dict(PRESETS[preset])
    s["preset"] = preset
    s["seed"] = seed
    for k, v in overrides.items():
        if v is not None:
            s[k] = v
    for k in ("width", "height", "frames", "subdivisions", "train", "test", "test_unseen", "seed"):
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
    if min(s["train"], s["test"], s["test_unseen"]) < 0 or s["train"] + s["test"] + s["test_unseen"] == 0:
        raise SimError(f"need a non-negative number of train/test/test_unseen sequences, not all zero "
                       f"(got train={s['train']}, test={s['test']}, test_unseen={s['test_unseen']})")
    if not 1 <= s["subdivisions"] <= 8:
        raise SimError(f"icosphere subdivisions must be in 1..8, got {s['subdivisions']}")
    if s["seed"] < 0:
        raise SimError(f"seed must be >= 0, got {s['seed']}")

    sensors = list(dict.fromkeys(_names(s.get("sensors")) or ["ideal"]))
    bad = [n for n in sensors if n not in DEPTH_SENSORS]
    if bad:
        raise SimError(f"unknown depth sensor {bad[0]!r} (choose from {', '.join(DEPTH_SENSORS)})")
    s["sensors"] = sensors
    s["points_only"] = bool(s.get("points_only", False))
    s["auto_exposure"] = bool(s.get("auto_exposure", False))
    s["motion_blur"] = bool(s.get("motion_blur", False))
    s["sun_phase"] = _sun_phase(s.get("sun_phase"))
    try:
        s["false_alarms"] = float(s.get("false_alarms") or 0.0)
    except (TypeError, ValueError):
        raise SimError(f"false alarm rate must be a number, got {s.get('false_alarms')!r}") from None
    if not 0.0 <= s["false_alarms"] <= 0.01:
        raise SimError(f"false alarm rate must be in 0..0.01 per pixel and frame, got {s['false_alarms']:g}")
    if s["false_alarms"] > 0.0 and not FALSE_ALARM_SENSORS & set(sensors):
        raise SimError(f"--false-alarms needs a range sensor ({', '.join(sorted(FALSE_ALARM_SENSORS))}); "
                       f"stereo's errors are its matcher's")
    if s["points_only"] and SENSORS_NEEDING_IMAGES & set(sensors):
        raise SimError(f"--points-only renders no images, but the depth sensor(s) "
                       f"{', '.join(sorted(SENSORS_NEEDING_IMAGES & set(sensors)))} measure depth from them")

    meshes = []
    # warnings about the meshes as a set (each mesh's own are in its "warnings"): logged by the run
    mesh_notes = []
    mesh_dir = s.pop("mesh_dir", None)
    if s.get("meshes") or mesh_dir is not None:
        cam = camera_of(s)
        for m in s.get("meshes") or []:
            m = dict(m) if isinstance(m, dict) else {"path": str(m)}
            meshes.append(_user_mesh(m["path"], m.get("size_m"), cam))
        if mesh_dir is not None:
            files, skipped = _mesh_files(Path(mesh_dir))
            if skipped:
                mesh_notes.append(f"mesh folder {mesh_dir}: skipped {len(skipped)} file(s) whose extension is "
                                  f"not a mesh format trimesh reads: {_listed(skipped)}")
            meshes += [_user_mesh(p, None, cam) for p in files]
        # sequence i of each split gets mesh i % n (sequence.plan): past the largest split's count
        # a mesh is the body of no sequence
        n_seq = max(s["train"], s["test"])
        if len(meshes) > n_seq:
            unused = [m["name"] for m in meshes[n_seq:]]
            mesh_notes.append(f"{len(meshes)} user meshes but the largest split has {n_seq} sequence"
                              f"{'s' if n_seq != 1 else ''} (sequence i of each split gets mesh i): the last "
                              f"{len(unused)} are not used ({_listed(unused)}); raise --train / --test to use them")
    s["meshes"] = meshes
    s["mesh_warnings"] = mesh_notes
    pool = resolve_pool(_names(s.get("shape_generators")))
    if pool is not None and meshes:
        raise SimError("--generators chooses procedural generators; --mesh / --mesh-dir replace them")
    s["shape_generators"] = list(pool) if pool is not None else None
    unseen, note = resolve_unseen(_names(s.pop("unseen_generators", None)) or None, s["test_unseen"], bool(meshes),
                                  pool)
    s["unseen_generators"] = list(unseen)
    s["unseen_note"] = note
    return s


def _sun_phase(value) -> list[float] | None:
    """The phase-angle range [lo, hi] in degrees (0 <= lo <= hi <= 170), or None (the default mix).
    Beyond 170 deg the camera would see almost nothing of a lit body."""
    if value is None:
        return None
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise SimError(f"sun phase must be two numbers LO:HI in degrees, got {value!r}") from None
    if not (0.0 <= lo <= hi <= 170.0):
        raise SimError(f"sun phase range {lo:g}:{hi:g} deg must satisfy 0 <= LO <= HI <= 170")
    return [lo, hi]


def camera_of(settings: dict):
    from track3d.camera import Camera
    return Camera.from_fov(settings["width"], settings["height"], settings["fov_x_deg"])


def _public_meshes(settings: dict) -> list[dict]:
    """The user meshes as they may be written: file name, content hash, size and the loader's
    version (shapes.USER_MESH_LOADER: a run an older loader started renders differently and is
    not resumed), never a path."""
    return [{**{k: m[k] for k in ("name", "sha256", "size_m")}, "loader": m.get("loader", USER_MESH_LOADER)}
            for m in settings.get("meshes") or []]


def _identity(settings: dict) -> dict:
    keys = ("preset", "seed", "width", "height", "fov_x_deg", "train", "test", "test_unseen", "frames",
            "subdivisions", "sensors", "points_only", "unseen_generators", "auto_exposure", "motion_blur")
    # the registry is part of the plan: a run resumed after a generator was added is refused
    # (an opt-in generator is part of it only in the runs that name it)
    pool = settings.get("shape_generators")
    # a user-mesh run draws no generator: its bodies are the meshes (listed by name and hash), and
    # a generator added later leaves its plan as it was
    generators = {} if settings.get("meshes") else \
        {"generators": body_sources(False, pool, settings.get("unseen_generators") or ())}
    return {"generator_version": __version__, **generators,
            "meshes": _public_meshes(settings), **{k: settings[k] for k in keys},
            **({"shape_generators": list(pool)} if pool is not None else {}),
            **({"sun_phase": list(settings["sun_phase"])} if settings.get("sun_phase") is not None else {}),
            **({"false_alarms": settings["false_alarms"]} if settings.get("false_alarms") else {})}


def train_coverage_note(specs) -> str | None:
    """A warning when the train split holds sequences but not every generator the test split
    holds (its fine categories cycle generator by generator, so a small train split covers the
    first few generators only: 18 train sequences, the small preset's, cover 5 of 7), else None."""
    train = [s for s in specs if s.split == "train"]
    if not train:
        return None
    have = {s.generator for s in train}
    missing = sorted({s.generator for s in specs if s.split == "test"} - have)
    if not missing:
        return None
    return (f"warning: the train split's {len(train)} sequences hold no {', '.join(missing)}, which the test "
            f"split holds (train categories cycle generator by generator; docs/simulator.md 'Splits')")


def plan_of(settings: dict):
    """The SeqSpecs of a run."""
    return plan(settings["train"], settings["test"], settings["test_unseen"], settings["unseen_generators"],
                settings["sensors"], len(settings["meshes"]), settings.get("shape_generators"))


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def dataset_info(settings: dict, specs) -> dict:
    from track3d import boxes
    from track3d import dataset as ds
    cam = camera_of(settings)
    user = bool(settings["meshes"])
    pool = settings.get("shape_generators")
    cats = split_categories(tuple(settings["unseen_generators"]), user, pool)
    sources = body_sources(user, pool, settings["unseen_generators"])
    splits = {split: [s.name for s in specs if s.split == split] for split in SPLITS}
    sensors = {split: dict(sorted(Counter(s.sensor for s in specs if s.split == split).items())) for split in SPLITS}
    return {
        "format": ds.FORMAT,
        "version": ds.FORMAT_VERSION,
        "camera": cam.to_dict(),
        "size_classes": boxes.SIZE_TEMPLATES.tolist(),
        "categories": {
            "shape_families": list(FAMILIES),
            "generators": sources,
            "generator_family": {g: (FAMILIES[GENERATORS[g].coarse] if g in GENERATORS else USER)
                                 for g in sources},
            **({"shape_generators": list(pool)} if pool is not None else {}),
            "textures": list(TEXTURES),
            "fine": [fine_name(g, t) for g in sources for t in range(len(TEXTURES))],
            **{f"{split}_fine": [fine_name(g, t) for g, t in cats[split]] for split in SPLITS},
            "unseen_generators": list(settings["unseen_generators"]),
            "unseen_note": settings["unseen_note"],
            "scenes": list(SCENES),
        },
        "splits": splits,
        "sensors": {"names": list(settings["sensors"]), "per_split": sensors},
        "points_only": bool(settings["points_only"]),
        "meshes": _public_meshes(settings),
        "generator": {"name": "track3d-sim", "version": __version__, "preset": settings["preset"],
                      "seed": settings["seed"], "settings": _identity(settings)},
    }


def prepare_output(out: Path, settings: dict, overwrite: bool = False) -> str:
    """Check / create the output folder. Returns 'new', 'resume' or 'complete'."""
    from track3d import dataset as ds
    ident = _identity(settings)
    if out.exists() and not out.is_dir():
        raise SimError(f"output path {out} exists and is not a folder")
    if out.is_dir():
        # a run killed while it wrote its run file or dataset.json leaves `.<name>.tmp-<pid>`: not
        # part of any dataset (a resume had kept it, and a folder holding only the run file's was
        # taken for a foreign one)
        for tmp in out.glob(".*.tmp-*"):
            if tmp.is_file() and re.fullmatch(r"\..+\.tmp-\d+", tmp.name):
                tmp.unlink()
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
        if isinstance(old, dict) and settings.get("meshes") and "generators" not in ident:
            # a user-mesh run written before its identity left out the procedural registry
            # (it draws no generator): the same run, resumable
            old = {k: v for k, v in old.items() if k != "generators"}
        if old != ident:
            diff = sorted(k for k in set(old) | set(ident) if old.get(k) != ident.get(k))
            raise SimError(f"output folder {out} holds a run with different settings ({', '.join(diff)}); "
                           f"use the same settings to resume, a new --out, or --overwrite")
        return "complete" if (out / ds.DATASET_JSON).exists() else "resume"
    out.mkdir(parents=True, exist_ok=True)
    _atomic_write(out / RUN_FILE, json.dumps(ident, indent=1, sort_keys=True))
    return "new"


# ---- backends ------------------------------------------------------------------------------------
_W = {}


def _die_with_parent(parent: int) -> None:
    """Linux: SIGKILL to this worker when the run that started it dies, however it dies (prctl
    PR_SET_PDEATHSIG). A `kill -9` of `generate --workers N` had left its workers rendering on
    into --out (PPID 1) until their sequences were complete, renamed into place with nobody to
    collect them and racing a resume, then dying on BrokenPipeError tracebacks. SIGKILL, not
    SIGTERM: a worker has nothing to save (its .partial folder is redone on resume), and nothing in
    it can catch or delay the signal. Elsewhere, or without prctl, nothing: SIGTERM and Ctrl-C
    still end the workers through _run_pool.

    The idea of track3d_train.recipes._dies_with_recipe, not that code: it is a preexec_fn of the
    training package (the simulator does not depend on it), and a spawned worker sets the signal
    itself, after its interpreter started."""
    import signal
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return
    # The kernel sends the signal when the *thread* that started the worker ends: the pool's
    # creator (it waits in _run_pool until the pool is gone) or, for a replaced worker, the
    # pool's own handler thread (it ends with the pool)
    if prctl(1, int(signal.SIGKILL)) != 0:    # 1 = PR_SET_PDEATHSIG
        return
    if os.getppid() != parent:                # the run died before the call: as if the signal had come
        os._exit(128 + int(signal.SIGKILL))


def _init_worker(settings, root, queue, parent: int):
    import signal
    _die_with_parent(parent)
    # Ctrl-C reaches the whole process group: the parent ends the pool, the workers do not each
    # print a traceback
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _W.update(settings=settings, root=Path(root), queue=queue, camera=camera_of(settings))


def _work(spec):
    q = _W["queue"]
    write_sequence(spec, _W["settings"], _W["camera"], _W["root"], progress=lambda n: q.put(n))
    return spec.split, spec.name


def _interrupted(signum, frame):
    raise KeyboardInterrupt


def _run_pool(todo, settings, out: Path, workers: int, update) -> None:
    import multiprocessing as mp
    import signal
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    # SIGTERM ends the run as Ctrl-C does, through the pool's exit, which terminates the workers: by
    # default it killed this process alone, and its orphaned workers went on writing into --out while
    # the run was resumed
    before = signal.signal(signal.SIGTERM, _interrupted)
    try:
        with ctx.Pool(min(workers, len(todo)), initializer=_init_worker,
                      initargs=(settings, str(out), queue, os.getpid())) as pool:
            res = pool.map_async(_work, todo, chunksize=1)
            while True:
                try:
                    update(queue.get(timeout=0.2))
                except Exception:
                    if res.ready():
                        break
            res.get()
            while not queue.empty():
                update(queue.get())
    finally:
        signal.signal(signal.SIGTERM, before)


def _ray_sequence(spec, settings: dict, root: str) -> str:
    """One Ray task: render and write one sequence (same .partial / rename protocol)."""
    write_sequence(spec, settings, camera_of(settings), Path(root))
    return f"{spec.split}/{spec.name}"


def _check_reachable(address: str, timeout_s: float = 5.0) -> None:
    """A HOST:PORT (or ray://HOST:PORT) address that does not answer is a one-line error at once
    (Ray itself retries for minutes). "auto" and other forms are left to Ray."""
    import socket
    hostport = address.split("://", 1)[-1]
    host, sep, port = hostport.rpartition(":")
    if not sep or not port.isdigit():
        return
    try:
        socket.create_connection((host, int(port)), timeout=timeout_s).close()
    except OSError as e:
        raise SimError(f"no Ray cluster answers at {address} ({e.strerror or e}); start one with "
                       f"`ray start --head` or check the address") from None


@contextlib.contextmanager
def _ray_session(address: str, num_cpus: int | None = None):
    """Ray started locally (address "local") or connected to a cluster; shut down on exit if this
    call started it. Connecting comes before anything is written, so a bad address leaves no folder."""
    try:
        import ray
    except ImportError:
        raise SimError("--ray needs the cluster extra: pip install 'track3d[sim,cluster]'") from None
    started = False
    if not ray.is_initialized():
        kw = {"include_dashboard": False, "log_to_driver": False}
        if address == "local":
            kw["num_cpus"] = num_cpus
        else:
            _check_reachable(address)
            kw["address"] = address
        try:
            ray.init(**kw)
        except Exception as e:  # ConnectionError, RuntimeError ... from a bad address
            raise SimError(f"could not start / reach Ray at {address!r}: {type(e).__name__}: {e}") from None
        started = True
    try:
        yield ray
    finally:
        if started:
            ray.shutdown()


def _run_ray(ray, todo, settings, out: Path, update) -> None:
    """One Ray task per sequence. The workers write straight into `out`, so on a cluster it must
    be a filesystem every node mounts at the same path (and so must user meshes)."""
    task = ray.remote(num_cpus=1, max_retries=2)(_ray_sequence)
    frames = int(settings["frames"])
    shared = ray.put(settings)
    pending = [task.remote(spec, shared, str(out.resolve())) for spec in todo]
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        for ref in done:
            try:
                ray.get(ref)
            except ray.exceptions.RayTaskError as e:  # a task's SimError stays a one-line error
                if isinstance(e.cause, SimError):
                    raise SimError(str(e.cause)) from None
                raise
            update(frames)


def generate(settings: dict, out: str | Path, workers: int = 1, overwrite: bool = False,
             progress: bool = True, log=None, ray: str | None = None, ray_num_cpus: int | None = None) -> Path:
    """Generate (or resume) a dataset. Deterministic for a seed whatever `workers` / `ray` is.

    ray: None (processes), "local" (start a local Ray instance, `ray_num_cpus` CPUs, default all)
    or the address of a running Ray cluster ("auto", "HOST:6379", "ray://HOST:10001")."""
    log = log or (lambda msg: print(msg, file=sys.stderr))
    from track3d.threads import max_threads, threads_rule

    if int(workers) < 1 or (ray is None and int(workers) > max_threads()):
        # 1,000 had started a process per sequence on 2 cores (495 for --preset paper)
        raise SimError(f"--workers must be {threads_rule()}, got {workers}")
    out = Path(out)
    plan_of(settings)  # plan errors before Ray starts
    with contextlib.ExitStack() as stack:
        ray_mod = stack.enter_context(_ray_session(ray, ray_num_cpus)) if ray is not None else None
        return _generate(settings, out, int(workers), overwrite, progress, log, ray, ray_mod)


def _generate(settings, out: Path, workers, overwrite, progress, log, ray, ray_mod) -> Path:
    from track3d import dataset as ds
    specs = plan_of(settings)
    info = dataset_info(settings, specs)
    state = prepare_output(out, settings, overwrite)
    if settings["unseen_generators"]:
        log(f"test_unseen: {', '.join(settings['unseen_generators'])} ({settings['unseen_note']})")
    for w in settings.get("mesh_warnings") or ():
        log(f"warning: {w}")
    for mesh in settings.get("meshes") or []:
        for w in mesh.get("warnings") or ():
            log(f"warning: {w}")
    if state == "complete":
        missing = [f"{s.split}/{s.name}" for s in specs if not (out / s.split / s.name).is_dir()]
        if not missing:
            log(f"{out}: dataset already complete ({len(specs)} sequences)")
            return out
        (out / ds.DATASET_JSON).unlink()
    for split in sorted({s.split for s in specs}):
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
        from tqdm import tqdm   # a missing extra is the one line, before any warning
    note = train_coverage_note(specs) if todo else None
    if note:
        log(note)
    if progress:
        bar = tqdm(total=total, unit="frame", desc="track3d-sim", file=sys.stderr, dynamic_ncols=True)
    update = bar.update if bar else (lambda n: None)
    t0 = time.time()
    try:
        if ray_mod is not None:
            _run_ray(ray_mod, todo, settings, out, update)
        elif workers == 1 or len(todo) <= 1:
            cam = camera_of(settings)
            for spec in todo:
                write_sequence(spec, settings, cam, out, progress=update)
        else:
            _run_pool(todo, settings, out, workers, update)
    finally:
        if bar:
            bar.close()
    ds.write_dataset_json(out, info)
    dt = time.time() - t0
    if todo:
        how = f"Ray at {ray}" if ray is not None else f"{workers} worker(s)"
        log(f"{out}: wrote {len(todo)} sequences, {total} {'depth-only' if settings['points_only'] else 'stereo'} "
            f"frames in {dt:.1f} s ({dt / max(total, 1):.3f} s per frame, {how})")
    return out
