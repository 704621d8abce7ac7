"""precision="auto" / engine="auto": the fastest model variant this CPU allows, chosen at load.

Two steps (docs/models.md, "Arithmetic"):

1. The CPU's instructions (``track3d.cpu_features.isa_flags``) decide what is ALLOWED: int8
   needs an int8 dot-product instruction (x86 VNNI / AMX-int8, ARM dotprod / i8mm; on an
   AVX2-only CPU int8 measured slower than fp32 for SiamFC and no faster for A3BoxNet), bf16
   needs bf16 arithmetic (AVX512_BF16 / AMX-bf16, ARM bf16) and OpenVINO; fp32 on onnxruntime
   is always allowed and is the reference.
2. When more than one variant is allowed, a short measurement (each candidate run round-robin
   on fixed random inputs for at most ``BUDGET_S`` seconds in all, each call after ``GAP_S`` of
   other work, as the loop calls it) picks the fastest; a variant must beat the reference by
   ``MIN_GAIN`` to be picked, so auto never picks a loser (``pick_fastest``). The timings are
   cached per machine (CPU model + flags + package and engine versions + model name and hashes)
   in ``variants.json`` in ``$TRACK3D_CACHE_DIR``, else ``$XDG_CACHE_HOME/track3d``, else
   ``~/.cache/track3d``. A cached entry is used only if it is exactly what the writer writes,
   its pick re-derived from its timings by the same rule; otherwise (or when the file is not a
   JSON object) one warning line names the file and the model is measured again and the entry
   rewritten. To measure again on purpose, delete that file (or point ``TRACK3D_CACHE_DIR`` at
   an empty folder); ``choose(..., use_cache=False)`` skips reading it.

Given a choice, the outputs are deterministic: the choice only selects the session.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import sys
import tempfile
import time
from importlib.util import find_spec
from pathlib import Path

import numpy as np

from .cpu_features import BF16_DOT, INT8_DOT, cpu_model, isa_flags
from .onnxmodel import (ENGINES, PRECISIONS, EngineUnavailable, ModelError, _OrtSession, open_session,
                        openvino_version, variant_path)

__all__ = ["choose", "candidates", "cache_dir", "pick_fastest", "BUDGET_S", "MIN_GAIN", "GAP_S", "example_feeds"]

BUDGET_S = 0.5          # seconds of measurement per model (all candidates together)
MIN_GAIN = 1.05         # a variant must be 5% faster than fp32 onnxruntime to replace it
# Other work before each timed call: the loop runs a network once a frame, between the rest of the
# frame's work (the other networks, the frustum, the box: 3-5 ms on one core). Called back to
# back, OpenVINO's bf16 A3BoxNet ran 0.80 ms against onnxruntime fp32's 0.94 and auto picked it,
# but the loop ran slower (interleaved, one pinned core: 7.00 vs 5.50 ms); timed after 3 ms of
# other work (a busy wait alone does it too, no memory traffic) the same calls took 1.42 vs 1.13
# ms (runs of track3d.variant_choice.measure, AMD EPYC with AVX-512 BF16; docs/models.md,
# "Arithmetic"). What the loop pays is the call after other work.
GAP_S = 0.003
CACHE_FILE = "variants.json"
VERDICTS_FILE = "accuracy.json"  # beside the models: which variants passed the accuracy rule
# 3: entries record the variants that failed to load, so a cached reason names them as a fresh
# one does, and the key holds the model's name; 2: measured with GAP_S before each call (1: back
# to back)
CACHE_VERSION = 3
_ENTRY_KEYS = frozenset({"pick", "ms", "failed", "cpu", "flags", "model", "measured"})
_STAMP = "%Y-%m-%dT%H:%M:%SZ"


def cache_dir() -> Path:
    """Where the per-machine choices are kept (never inside the repository)."""
    if os.environ.get("TRACK3D_CACHE_DIR"):
        return Path(os.environ["TRACK3D_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "track3d"


def _openvino_installed() -> bool:
    if "openvino" in sys.modules:
        return sys.modules["openvino"] is not None  # None: import blocked (as in the tests)
    try:
        return find_spec("openvino") is not None
    except (ImportError, ValueError):
        return False


def verdict_files(path: Path, variant: str) -> dict[str, str]:
    """{"sha256": of the model file, ["variant_sha256": of its int8 twin]}: what a verdict of
    `variant` ("engine/precision") was measured on. Written with the verdict and checked on reading,
    so a retrained or re-quantised file never inherits the verdict of the file it replaced."""
    out = {"sha256": _file_digest(path)}
    if variant.endswith("/int8"):
        out["variant_sha256"] = _file_digest(variant_path(path, "int8"))
    return out


def verdicts(path: Path) -> dict:
    """{"engine/precision": {"passes": bool, ...}} of the model `path` from the accuracy.json
    beside it (written by benchmarks/bench_precision.py --write-verdicts); {} without one. A
    verdict recorded for other file contents (see ``verdict_files``), or without them, is left
    out: it was measured on another model."""
    try:
        data = json.loads((path.parent / VERDICTS_FILE).read_text())
        found = dict(data.get("models", {}).get(path.name, {}))
    except (OSError, ValueError, AttributeError):
        return {}
    both = verdict_files(path, "any/int8")       # each file hashed once, not once per verdict
    return {k: v for k, v in found.items()
            if isinstance(v, dict) and v.get("sha256") == both["sha256"]
            and (not k.endswith("/int8") or v.get("variant_sha256") == both["variant_sha256"])}


def candidates(path: Path, precision: str, engine: str, flags: frozenset[str]) -> tuple[list, list[str]]:
    """([(engine, precision)...] allowed, reference first when it is allowed; [why others are not]).
    With precision="auto", a variant other than fp32 must also have passed the accuracy rule
    (``verdicts``); an explicit precision is the caller's choice."""
    if engine != "auto" and engine not in ENGINES:
        raise ValueError(f"engine must be one of {', '.join(ENGINES)} or auto, got {engine!r}")
    if precision != "auto" and precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)} or auto, got {precision!r}")
    notes: list[str] = []
    engines = [engine] if engine != "auto" else ["onnxruntime"]
    if engine == "auto":
        if _openvino_installed():
            engines.append("openvino")
        else:
            notes.append("OpenVINO not installed")
    if engine == "openvino" and not _openvino_installed():
        raise EngineUnavailable("engine 'openvino' needs OpenVINO: pip install 'track3d[openvino]'")
    precs = [precision] if precision != "auto" else list(PRECISIONS)
    if precision == "auto":
        if not variant_path(path, "int8").is_file():
            precs.remove("int8")
            notes.append("no int8 file")
        elif not flags & INT8_DOT:
            precs.remove("int8")
            notes.append("int8 not allowed: CPU has no int8 dot-product instruction (VNNI/AMX/dotprod/i8mm)")
        if not flags & BF16_DOT:
            precs.remove("bf16")
            notes.append("bf16 not allowed: CPU has no bf16 arithmetic")
    unsupported = {("onnxruntime", "bf16"), ("openvino", "int8")}  # see onnxmodel's sessions
    out = [(e, p) for e in engines for p in precs if (e, p) not in unsupported]
    if precision == "auto":
        v = verdicts(path)
        keep = []
        for c in out:
            ok = c[1] == "fp32" or v.get(f"{c[0]}/{c[1]}", {}).get("passes", False)
            if ok:
                keep.append(c)
            else:
                notes.append(f"{c[0]}/{c[1]} " + ("failed the accuracy rule" if f"{c[0]}/{c[1]}" in v
                                                   else "has no accuracy verdict"))
        out = keep
    if precision == "bf16" and not any(p == "bf16" for _, p in out):
        raise EngineUnavailable("bf16 needs engine 'openvino': pip install 'track3d[openvino]'")
    if precision == "int8" and not out:
        raise EngineUnavailable("int8 runs on engine 'onnxruntime' only")
    return out, notes


def example_feeds(path: Path, meta: dict, seed: int = 0) -> dict[str, np.ndarray]:
    """Fixed random inputs of the model's shapes (dynamic axes from the metadata: one scale or
    batch item, instance_size, num_points), for the measurement and for parity tests."""
    sess = _OrtSession(path, 1, "fp32")
    rng = np.random.default_rng(seed)
    dims = {"batch": 1, "scales": 1, "height": meta.get("instance_size", 1), "width": meta.get("instance_size", 1),
            "num_points": meta.get("num_points", 1)}
    feeds = {}
    for name, shape, typ in sess.inputs:
        shp = [d if isinstance(d, int) and d > 0 else int(dims.get(str(d), 1)) for d in shape]
        if typ == "tensor(uint8)":
            feeds[name] = rng.integers(0, 256, size=shp, dtype=np.uint8)
        elif name == "category":  # a one-hot
            a = np.zeros(shp, np.float32)
            a[..., 0] = 1.0
            feeds[name] = a
        else:
            feeds[name] = rng.normal(size=shp).astype(np.float32)
    return feeds


def _file_digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()[:16] if p.is_file() else "-"


def _key(path: Path, threads: int, cands: list, flags: frozenset[str]) -> str:
    import onnxruntime

    from . import __version__

    # the name too: a copy of a model under another name would share the entry and, its "model"
    # field then not matching, be measured again each time the other one loads
    k = {"v": CACHE_VERSION, "cpu": cpu_model(), "flags": sorted(flags), "track3d": __version__,
         "onnxruntime": onnxruntime.__version__, "openvino": openvino_version(), "threads": threads,
         "candidates": [list(c) for c in cands], "name": path.name, "model": _file_digest(path),
         "int8": _file_digest(variant_path(path, "int8"))}
    return hashlib.sha256(json.dumps(k, sort_keys=True).encode()).hexdigest()


def _one_line(text) -> str:
    return " ".join(str(text).split())


def _cache_load() -> tuple[dict, str | None]:
    """(the cache's entries, why the file is unusable or None). No file is an empty cache."""
    try:
        data = json.loads((cache_dir() / CACHE_FILE).read_text())
    except FileNotFoundError:
        return {}, None
    except (OSError, ValueError, RecursionError) as e:  # ValueError: not JSON, not UTF-8
        return {}, f"cannot be read ({_one_line(e)[:120] or type(e).__name__})"
    if not isinstance(data, dict):
        return {}, f"is a JSON {type(data).__name__}, not an object"
    return data, None


def _warn(what: str) -> None:
    print(f"track3d: warning: {cache_dir() / CACHE_FILE} {what}; measuring again", file=sys.stderr)


def pick_fastest(ms: dict[str, float], cands: list) -> tuple[str, str]:
    """The variant auto runs, given the median ms per "engine/precision" label: the fastest
    timed candidate (the first in `cands` order among equal times), unless it beats the reference
    (``cands[0]``) by less than ``MIN_GAIN``. The one rule for a fresh and a cached measurement."""
    timed = [c for c in cands if _label(c) in ms]
    best = min(timed, key=lambda c: ms[_label(c)])
    ref = cands[0]
    if _label(ref) in ms and best != ref and ms[_label(best)] * MIN_GAIN > ms[_label(ref)]:
        return ref
    return best


def _entry_problem(entry, path: Path, cands: list, flags: frozenset[str]) -> str | None:
    """Why `entry` is not what ``choose`` writes for this key (None: it is). Hand edits, a
    truncated write or another tool's output all land here: a cache is never trusted past it."""
    if not isinstance(entry, dict):
        return f"is a JSON {type(entry).__name__}, not an object"
    if set(entry) != _ENTRY_KEYS:
        odd = ([f"lacks {k!r}" for k in sorted(_ENTRY_KEYS - set(entry))]
               + [f"has the unknown key {k!r}" for k in sorted(set(entry) - _ENTRY_KEYS)])
        return _one_line(", ".join(odd))[:160]
    labels = [_label(c) for c in cands]
    ms, failed = entry["ms"], entry["failed"]
    # float only: the writer writes floats, and a bool is an int to Python
    if not (isinstance(ms, dict) and ms and all(
            k in labels and type(v) is float and math.isfinite(v) and v > 0 for k, v in ms.items())):
        return f"has 'ms' {_one_line(json.dumps(ms))[:120]}, not a finite positive time per candidate"
    if not (isinstance(failed, dict) and all(k in labels and k not in ms and isinstance(v, str)
                                             for k, v in failed.items()) and len(ms) + len(failed) == len(labels)):
        return "has 'ms' and 'failed' that do not cover each candidate once"
    for field, want in (("cpu", cpu_model()), ("flags", sorted(flags)), ("model", path.name)):
        if entry[field] != want:   # all three are in the key: only an edit makes them differ
            return f"has '{field}' {_one_line(json.dumps(entry[field]))[:60]}, not {json.dumps(want)}"
    try:
        time.strptime(entry["measured"], _STAMP)
    except (TypeError, ValueError):
        return f"has 'measured' {_one_line(json.dumps(entry['measured']))[:40]}, not a UTC time"
    derived = pick_fastest(ms, cands)
    if entry["pick"] != list(derived):
        return (f"picks {_one_line(json.dumps(entry['pick']))[:60]} against its own timings "
                f"(they give {_label(derived)})")
    return None


def _cache_read(key: str, path: Path, cands: list, flags: frozenset[str]) -> dict | None:
    """The valid entry of `key`, or None (missing, or damaged: then one warning line)."""
    data, problem = _cache_load()
    if problem:
        _warn(problem)
        return None
    if key not in data:
        return None
    problem = _entry_problem(data[key], path, cands, flags)
    if problem:
        _warn(f"holds an entry for {path.name} that {problem}")
        return None
    return data[key]


def _cache_write(key: str, entry: dict) -> None:
    d = cache_dir()
    try:
        d.mkdir(parents=True, exist_ok=True)
        f = d / CACHE_FILE
        data, _ = _cache_load()  # an unusable file was warned of on reading: replaced whole
        data[key] = entry
        # a file of its own per write (threads of one process shared the pid's name, and a torn
        # file was renamed into place), then one atomic rename
        fd, tmp = tempfile.mkstemp(dir=d, prefix=f"{CACHE_FILE}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "w") as out:
                out.write(json.dumps(data, indent=1, sort_keys=True))
            os.replace(tmp, f)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
    except OSError:
        pass  # a read-only home: measure again next time, never fail a load


def _other_work(seconds: float, buf: np.ndarray) -> None:
    """`seconds` of work that is not the candidate's: sums over a buffer the size of a depth
    frame's cloud (the loop's numpy work between two calls of one network)."""
    t_end = time.perf_counter() + seconds
    while time.perf_counter() < t_end:
        buf.sum()


def measure(sessions: dict, feeds: dict, budget_s: float = BUDGET_S, gap_s: float = GAP_S) -> dict:
    """Median ms per session, run round-robin (so that a load change hits all alike), each timed
    call after `gap_s` seconds of other work (GAP_S: what the loop pays is a call after the rest
    of its frame, not a call right after another; 0: back to back). The budget counts the gaps."""
    times: dict = {k: [] for k in sessions}
    buf = np.ones(640 * 480 * 3, np.float32) if gap_s > 0 else None
    for s in sessions.values():  # warm-up: first-call allocations, OpenVINO's shape compile
        s.run(feeds)
        s.run(feeds)
    t_end = time.perf_counter() + budget_s
    rounds = 0
    while rounds < 3 or (time.perf_counter() < t_end and rounds < 200):
        for k, s in sessions.items():
            if buf is not None:
                _other_work(gap_s, buf)
            t = time.perf_counter()
            s.run(feeds)
            times[k].append((time.perf_counter() - t) * 1e3)
        rounds += 1
    return {k: float(np.median(v)) for k, v in times.items()}


def _label(c) -> str:
    return f"{c[0]}/{c[1]}"


def choose(path: Path, threads: int, precision: str = "auto", engine: str = "auto",
           flags: frozenset[str] | None = None, use_cache: bool = True):
    """(choice dict, open session) of the fastest allowed variant of the fp32 model `path`.
    flags: the CPU's ISA names (default: this CPU's; tests inject a smaller set). use_cache=False
    measures again without reading the cache, and writes the new timings to it."""
    flags = isa_flags() if flags is None else frozenset(flags)
    cands, notes = candidates(path, precision, engine, flags)
    if not cands:
        raise ModelError(f"no variant of {path.name} fits precision={precision} engine={engine}")
    shown = ", ".join(sorted(f for f in flags if f not in ("int8_dot", "bf16_dot"))) or "none known"
    if len(cands) == 1:
        (e, p), = cands
        why = "; ".join(notes) if notes else "the only variant asked for"
        return ({"engine": e, "precision": p, "file": variant_path(path, p).name,
                 "reason": f"{why} (CPU flags: {shown})"},
                open_session(variant_path(path, p), threads, e, p))
    key = _key(path, threads, cands, flags)
    hit = _cache_read(key, path, cands, flags) if use_cache else None
    if hit:
        ms, failed = hit["ms"], hit["failed"]
        source = f"timings cached in {CACHE_FILE}, measured {hit['measured']}"
    else:
        sessions, failed = {}, {}
        for c in cands:
            try:
                sessions[c] = open_session(variant_path(path, c[1]), threads, c[0], c[1])
            except ModelError as err:  # e.g. an engine that cannot compile this graph: not a candidate
                failed[_label(c)] = _one_line(err)
        if not sessions:
            raise ModelError(f"no variant of {path.name} loads: "
                             + "; ".join(notes + [f"{k} failed to load ({v})" for k, v in failed.items()]))
        meta = json.loads(_OrtSession(path, 1, "fp32").metadata() or "{}")
        t0 = time.perf_counter()
        timed = measure(sessions, example_feeds(path, meta))
        spent = time.perf_counter() - t0
        # 4 significant digits: the file stays readable and no time rounds to 0 (the reader
        # takes only positive times); the pick is made from the times as written, so a
        # cached entry gives the same pick by the same rule
        ms = {_label(c): float(f"{v:.4g}") for c, v in timed.items()}
        source = f"measured now in {spent:.2f} s"
    pick = pick_fastest(ms, cands)
    if not hit:
        _cache_write(key, {"pick": list(pick), "ms": ms, "failed": failed, "cpu": cpu_model(),
                           "flags": sorted(flags), "model": path.name,
                           "measured": time.strftime(_STAMP, time.gmtime())})
    # cands order, not the file's (sorted) order: the cached reason reads as the fresh one did
    shown_ms = {_label(c): ms[_label(c)] for c in cands if _label(c) in ms}
    notes = notes + [f"{_label(c)} failed to load ({failed[_label(c)]})" for c in cands if _label(c) in failed]
    listing = ", ".join(f"{k} {v:.2f} ms" for k, v in shown_ms.items())
    choice = {"engine": pick[0], "precision": pick[1], "file": variant_path(path, pick[1]).name,
              "reason": f"fastest allowed, {source}: {listing}"
                        + (f"; {'; '.join(notes)}" if notes else "") + f" (CPU flags: {shown})",
              "measured_ms": shown_ms}
    if hit:
        return choice, open_session(variant_path(path, pick[1]), threads, pick[0], pick[1])
    return choice, sessions[pick]
