"""Loading ONNX models with their metadata: the ONE model loader (engines, precisions, options).

Every model track3d ships carries its metadata in the ONNX file (``metadata_props``):
one key, ``track3d``, whose value is a JSON object (input sizes, size-class table,
hyper-parameters, version, training-data hash ...). The runtime needs nothing else.

Arithmetic (docs/models.md, "Arithmetic"): a model ``<stem>.onnx`` (fp32) may have an int8
twin ``<stem>_int8.onnx`` (static QDQ, written by ``track3d-train quantize``, shipped only when
it passes the accuracy rule). Engines: ``onnxruntime`` (always there) and ``openvino`` (the
optional extra ``track3d[openvino]``, imported only when asked for). Precisions: ``fp32``,
``int8`` (the int8 file, on onnxruntime) and ``bf16`` (OpenVINO's bf16 inference precision
on a CPU with bf16 arithmetic). ``precision="auto"`` / ``engine="auto"`` pick at load time the
fastest variant this CPU allows (``track3d.variant_choice``), and ``OnnxModel.choice`` says
which and why.
"""
from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort

from .threads import check_threads

__all__ = ["META_KEY", "MODELS_DIR", "OnnxModel", "ModelError", "EngineUnavailable", "shipped_model", "model_path",
           "model_pair", "check_pair", "EXPORT_ID", "is_model", "load_model", "models_of",
           "ENGINES", "PRECISIONS", "PARITY_TOLERANCE", "variant_path", "open_session", "PARENT_SHA256",
           "file_sha256", "made_from"]

META_KEY = "track3d"
MODELS_DIR = Path(__file__).resolve().parent / "models"
# The metadata key of a two-graph tracker's export id: one value written into both files of a pair
# by one export (track3d_train.onnx_meta.export_id). The export renames the two files into place
# one after the other; a kill between the renames left a new first graph beside an old search
# graph, which loaded and tracked with features the search graph was not trained on, silently.
EXPORT_ID = "export_id"
# The metadata key of a variant file's parent hash: the sha256 of the fp32 file it was made from
# (file_sha256), written by `track3d-train quantize`. A re-export or retraining replaced the fp32
# file and left its `_int8` twin beside it; the twin carries the parent's metadata (its export id
# too), so precision="int8" loaded the previous model's weights without a word. OnnxModel refuses
# a variant whose recorded parent is not the fp32 file beside it (made_from).
PARENT_SHA256 = "parent_sha256"


ENGINES = ("onnxruntime", "openvino")
PRECISIONS = ("fp32", "int8", "bf16")
# Parity of a variant with onnxruntime fp32 on fixed realistic inputs (tests/test_precision.py),
# per output: max |diff| / max |fp32| and the cosine of the two flattened outputs. What decides
# shipping is the tracking accuracy rule (docs/models.md, "Arithmetic"); these bounds catch a
# broken or mismatched file (measured: int8 up to 0.47 / down to 0.89 for SiamFC's exemplar
# feature, 0.04 / 0.999 for A3BoxNet; bf16 up to 0.03, and 0.061 on the small centre residual
# `center2` of the A3BoxNet retrained on 1.5x more bodies, whose maximum is smaller, cosine 0.9975).
# A3BoxNet's `center2` (a correction of a few cm) is compared as `center1 + center2`, the centre
# the runtime uses: alone, its int8 difference of 2.5 cm on a 4 cm maximum read as 0.60.
PARITY_TOLERANCE = {"fp32": {"max_rel": 1e-4, "min_cos": 0.9999}, "int8": {"max_rel": 0.6, "min_cos": 0.85},
                    "bf16": {"max_rel": 0.1, "min_cos": 0.995}}


class ModelError(Exception):
    """A model file is missing, unreadable or lacks the metadata the runtime needs."""


class EngineUnavailable(ModelError):
    """The engine or precision asked for cannot run here (e.g. OpenVINO not installed)."""


def variant_path(path: str | Path, precision: str) -> Path:
    """The file of a precision of the model at `path` (the fp32 file): fp32 and bf16 use the fp32
    file (bf16 is an engine setting), int8 the sibling ``<stem>_int8.onnx``."""
    p = Path(path)
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)} or auto, got {precision!r}")
    if precision != "int8" or p.stem.endswith("_int8"):
        return p
    return p.with_name(f"{p.stem}_int8{p.suffix}")


def file_sha256(path: str | Path) -> str:
    """The sha256 (hex) of a file's bytes: what a variant records of its parent (PARENT_SHA256) and
    what the loader compares it with (made_from)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def made_from(parent: str | Path, meta: dict) -> bool | None:
    """Whether the variant whose metadata is `meta` was made from the file `parent` as it is now:
    its recorded PARENT_SHA256 against the file's sha256; None when it records none (a variant
    made before the key, or by hand). The whole file is hashed, metadata included: a variant
    carries its parent's metadata (tracking thresholds, export id ...), so a parent whose metadata
    was rewritten since (e.g. `track3d-train edgetrack fit-threshold --write`) has a stale twin too."""
    recorded = meta.get(PARENT_SHA256)
    if recorded is None:
        return None
    return recorded == file_sha256(parent)


def shipped_model(name: str) -> Path:
    """Path of a model shipped inside the package (runtime/track3d/models/<name>)."""
    p = MODELS_DIR / name
    if not p.is_file():
        have = sorted(x.name for x in MODELS_DIR.glob("*.onnx")) if MODELS_DIR.is_dir() else []
        raise ModelError(f"no shipped model {name!r} (shipped: {', '.join(have) or 'none'})")
    return p


def model_path(model: str | Path) -> Path:
    """The file a model argument names: `model` itself when it is a file here or has a folder
    part, else the shipped model of that bare name (e.g. "a3boxnet_narrow.onnx") when there is
    one, else `model` as given (the caller says it does not exist)."""
    p = Path(model)
    if not p.is_file() and p.name == str(model) and (MODELS_DIR / p.name).is_file():
        return MODELS_DIR / p.name
    return p


def model_pair(model, first, search, parts: tuple[str, str], shipped) -> tuple[Path, Path]:
    """The two files of a two-graph tracker: `model` a prefix `<dir>/<name>` (or either file of
    the pair) -> `<name>_<parts[0]>.onnx`, `<name>_<parts[1]>.onnx`; else `first` and `search`
    explicit paths, both or neither (an explicit path wins over the prefix's); neither: the
    pair `shipped()` returns."""
    if model is not None:
        p = Path(model)
        stem = p.name
        for suffix in (f"_{parts[0]}.onnx", f"_{parts[1]}.onnx", ".onnx"):
            if stem.endswith(suffix):
                stem = stem[: -len(suffix)]
                break
        first = first or p.parent / f"{stem}_{parts[0]}.onnx"
        search = search or p.parent / f"{stem}_{parts[1]}.onnx"
    if (first is None) != (search is None):
        raise ValueError(f"give both {parts[0]}_model and {parts[1]}_model, or neither")
    if first is None:
        return shipped()
    return first, search


def check_pair(first, search, command: str) -> None:
    """ModelError unless the two loaded graphs of a two-graph tracker come from one export: their
    metadata's EXPORT_ID are equal, or neither has one (models exported before it, the shipped
    ones among them). One file with an id and one without are two exports too: every export that
    writes the id writes it into both. `command`: the export that writes the pair, for the message."""
    a, b = first.meta.get(EXPORT_ID), search.meta.get(EXPORT_ID)
    if a == b:
        return

    def name(m):
        return getattr(m, "file", None) or getattr(m, "path", None) or f"the {m.meta.get('kind')} model given"

    def shown(v):
        return "none" if v is None else str(v)[:12]

    def int8(m):
        return getattr(m, "precision", None) == "int8" or m.meta.get("precision") == "int8"

    if int8(first) or int8(search):
        # int8 files are written by `track3d-train quantize`, not by the export: exporting the pair
        # again does not rewrite them (the message had said so)
        raise ModelError(f"{name(first)} and {name(search)} are not made from one export's pair (export ids "
                         f"{shown(a)} and {shown(b)}): `track3d-train quantize` writes the int8 files from the "
                         f"pair beside them; run it again (after `{command}` if the normal files mix too)")
    raise ModelError(f"{name(first)} and {name(search)} are not one export's pair (export ids {shown(a)} and "
                     f"{shown(b)}): `{command}` writes both; an export killed between its two renames, or files "
                     f"copied from two exports, mix them: export the pair again")


def session_options(threads: int = 1) -> ort.SessionOptions:
    """ORT options tuned for a small CPU: full graph optimisation, fixed intra-op threads,
    no spinning (two sessions with spinning pools fight over 2 cores, measured up to 2x)."""
    threads = check_threads(threads)
    so = ort.SessionOptions()
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.intra_op_num_threads = int(threads)
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    so.log_severity_level = 3
    return so


class _OrtSession:
    """onnxruntime on the CPU (fp32 or the int8 file)."""

    engine = "onnxruntime"

    def __init__(self, path: Path, threads: int, precision: str):
        if precision == "bf16":
            raise EngineUnavailable("onnxruntime has no bf16 arithmetic on x86 CPUs: use engine='openvino' "
                                    "for bf16")
        try:
            self.session = ort.InferenceSession(str(path), session_options(threads),
                                                providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own exception types
            raise ModelError(f"onnxruntime cannot load {path}: {e}") from None
        self.input_names = [i.name for i in self.session.get_inputs()]
        self.output_names = [o.name for o in self.session.get_outputs()]
        self.inputs = [(i.name, i.shape, i.type) for i in self.session.get_inputs()]

    def metadata(self) -> str | None:
        return self.session.get_modelmeta().custom_metadata_map.get(META_KEY)

    def run(self, feeds, outputs=None):
        return self.session.run(outputs, feeds)


def _import_openvino():
    try:
        import openvino  # noqa: F401  (the optional extra)
    except ImportError:
        raise EngineUnavailable("engine 'openvino' needs OpenVINO: pip install 'track3d[openvino]'") from None
    return openvino


def openvino_version() -> str | None:
    """OpenVINO's version if installed (without importing it when it is not)."""
    from importlib import metadata

    try:
        return metadata.version("openvino")
    except metadata.PackageNotFoundError:
        return None


class _OvSession:
    """OpenVINO's own runtime on the CPU: fp32 or bf16 (inference precision hint). One synchronous
    infer request, `threads` inference threads, one stream, latency mode. Not the int8 files:
    OpenVINO rewrites their QDQ pairs its own way and its outputs left the parity bound
    (A3BoxNet centre offsets off by their full range, measured)."""

    engine = "openvino"

    def __init__(self, path: Path, threads: int, precision: str):
        if precision == "int8":
            raise EngineUnavailable("int8 runs on onnxruntime only (OpenVINO's int8 of these QDQ files "
                                    "fails the parity check)")
        ov = _import_openvino()
        core = ov.Core()
        config = {"INFERENCE_NUM_THREADS": int(threads), "NUM_STREAMS": 1, "PERFORMANCE_HINT": "LATENCY",
                  "INFERENCE_PRECISION_HINT": "bf16" if precision == "bf16" else "f32",
                  "ENABLE_CPU_PINNING": False}
        try:
            self.compiled = core.compile_model(core.read_model(str(path)), "CPU", config)
        except Exception as e:  # OpenVINO raises RuntimeError with a long text
            first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            raise ModelError(f"OpenVINO cannot load {path} ({precision}): {first}") from None
        self.request = self.compiled.create_infer_request()
        self.input_names = [i.get_any_name() for i in self.compiled.inputs]
        self.output_names = [o.get_any_name() for o in self.compiled.outputs]
        self.inputs = None
        self._path = path

    def metadata(self) -> str | None:
        return None  # read by the caller with onnxruntime (OpenVINO drops metadata_props)

    def run(self, feeds, outputs=None):
        res = self.request.infer({k: np.ascontiguousarray(v) for k, v in feeds.items()})
        by_name = {o.get_any_name(): res[o] for o in self.compiled.outputs}
        # copies: the request's buffers are reused by its next call
        return [np.array(by_name[n]) for n in (outputs or self.output_names)]


def open_session(path: str | Path, threads: int = 1, engine: str = "onnxruntime", precision: str = "fp32"):
    """A session of one engine at one precision on the file `path` (already the variant's file)."""
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {', '.join(ENGINES)} or auto, got {engine!r}")
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)} or auto, got {precision!r}")
    return (_OrtSession if engine == "onnxruntime" else _OvSession)(Path(path), check_threads(threads), precision)


class OnnxModel:
    """A model session on the CPU plus the model's track3d metadata (``.meta``).

    path: the fp32 file (its variants are found beside it, ``variant_path``); engine:
    "onnxruntime" (default), "openvino" or "auto"; precision: "fp32" (default), "int8", "bf16"
    or "auto". ``choice`` holds the engine, precision, file and the reason of the choice.
    """

    def __init__(self, path: str | Path, threads: int = 1, kind: str | None = None,
                 precision: str = "fp32", engine: str = "onnxruntime", flags: frozenset[str] | None = None):
        self.path = Path(path)
        if not self.path.is_file():
            raise ModelError(f"model file {self.path} does not exist")
        self.threads = check_threads(threads)
        if precision == "auto" or engine == "auto":
            from .variant_choice import choose

            choice, session = choose(self.path, self.threads, precision, engine, flags=flags)
        else:
            file = variant_path(self.path, precision)
            if not file.is_file():
                raise ModelError(f"no {precision} variant of {self.path.name} ({file.name} does not exist; "
                                 f"precision 'auto' runs each network in the fastest variant it has)")
            session = open_session(file, self.threads, engine, precision)
            choice = {"engine": engine, "precision": precision, "file": file.name, "reason": "asked for"}
        self.choice: dict = choice
        self.engine, self.precision = choice["engine"], choice["precision"]
        self.file = variant_path(self.path, self.precision)
        self._session = session
        raw = session.metadata()
        if raw is None and session.engine != "onnxruntime":
            raw = _OrtSession(self.file, 1, "fp32").metadata()
        if raw is None:
            raise ModelError(f"{self.file} has no '{META_KEY}' metadata: not a track3d model")
        try:
            self.meta: dict = json.loads(raw)
        except json.JSONDecodeError as e:
            raise ModelError(f"{self.file}: metadata is not JSON ({e})") from None
        if kind is not None and self.meta.get("kind") != kind:
            raise ModelError(f"{self.file} is a {self.meta.get('kind')!r} model, expected {kind!r}")
        if self.file != self.path and made_from(self.path, self.meta) is False:
            # the variant found beside the fp32 file the caller named was made from another
            # version of it (re-exported or retrained since): its weights are the old model's
            raise ModelError(f"{self.file} was made from another {self.path.name} (its recorded parent sha256 "
                             f"{str(self.meta[PARENT_SHA256])[:12]} is not the file's {file_sha256(self.path)[:12]}: "
                             f"re-exported, retrained or its metadata rewritten since): remake it with "
                             f"`track3d-train quantize`, or load precision 'fp32'")
        self.input_names = list(session.input_names)
        self.output_names = list(session.output_names)
        self.run_ms = 0.0   # summed time of run(): benchmarks read it, nothing wraps run
        # keep_feeds: run() keeps a copy of its first inputs in first_feeds (track3d bench
        # --models-only times each network alone on the inputs it got in the loop)
        self.keep_feeds = False
        self.first_feeds: dict[str, np.ndarray] | None = None

    @property
    def session(self):
        """The engine's own session object (onnxruntime.InferenceSession with onnxruntime)."""
        s = self._session
        return s.session if isinstance(s, _OrtSession) else s.compiled

    def describe(self) -> dict:
        """Engine, precision, file and why (for Track3D.describe())."""
        return {"model": self.path.name, "kind": self.meta.get("kind"), "threads": self.threads, **self.choice}

    def run(self, feeds: dict[str, np.ndarray], outputs: list[str] | None = None) -> list[np.ndarray]:
        if self.keep_feeds and self.first_feeds is None:
            self.first_feeds = {k: np.array(v) for k, v in feeds.items()}
        t = time.perf_counter()
        try:
            return self._session.run(feeds, outputs)
        finally:
            self.run_ms += (time.perf_counter() - t) * 1e3


def is_model(obj) -> bool:
    """An OnnxModel, or a stand-in with its interface (run(feeds, outputs), meta, input_names,
    output_names, run_ms), e.g. a benchmark's torch module of the same graph."""
    return callable(getattr(obj, "run", None)) and isinstance(getattr(obj, "meta", None), dict) \
        and hasattr(obj, "input_names")


def load_model(model, threads: int = 1, kind: str | None = None, precision: str = "fp32",
               engine: str = "onnxruntime"):
    """A path -> OnnxModel(path, ...); a bare file name that is not a file here but a shipped
    model's (e.g. "a3boxnet_narrow.onnx") -> the shipped one; a model object (is_model) ->
    itself, its kind checked: trackers and estimators take either, so a caller can pass the
    models it built."""
    if not is_model(model):
        return OnnxModel(model_path(model), threads, kind, precision=precision, engine=engine)
    if kind is not None and model.meta.get("kind") != kind:
        raise ModelError(f"a {model.meta.get('kind')!r} model was given where a {kind!r} model is expected")
    return model


def models_of(part) -> dict:
    """{attribute: model} of the models (is_model) a tracker or estimator holds."""
    return {k: v for k, v in sorted(vars(part).items()) if is_model(v)} if hasattr(part, "__dict__") else {}


def run_ms_of(part) -> float:
    """The summed run_ms counters of the models a tracker or estimator holds (their network time)."""
    return sum(m.run_ms for m in models_of(part).values())
