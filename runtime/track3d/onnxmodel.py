"""Loading ONNX models with their metadata: one place for session options.

Every model track3d ships carries its metadata in the ONNX file (``metadata_props``):
one key, ``track3d``, whose value is a JSON object (input sizes, size-class table,
hyper-parameters, version, training-data hash ...). The runtime needs nothing else.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnxruntime as ort

__all__ = ["META_KEY", "MODELS_DIR", "OnnxModel", "ModelError", "shipped_model"]

META_KEY = "track3d"
MODELS_DIR = Path(__file__).resolve().parent / "models"


class ModelError(Exception):
    """A model file is missing, unreadable or lacks the metadata the runtime needs."""


def shipped_model(name: str) -> Path:
    """Path of a model shipped inside the package (runtime/track3d/models/<name>)."""
    p = MODELS_DIR / name
    if not p.is_file():
        have = sorted(x.name for x in MODELS_DIR.glob("*.onnx")) if MODELS_DIR.is_dir() else []
        raise ModelError(f"no shipped model {name!r} (shipped: {', '.join(have) or 'none'})")
    return p


def session_options(threads: int = 1) -> ort.SessionOptions:
    """ORT options tuned for a small CPU: full graph optimisation, fixed intra-op threads,
    no spinning (two sessions with spinning pools fight over 2 cores, measured up to 2x)."""
    if int(threads) < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    so = ort.SessionOptions()
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.intra_op_num_threads = int(threads)
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    so.log_severity_level = 3
    return so


class OnnxModel:
    """An onnxruntime session on the CPU plus the model's track3d metadata (``.meta``)."""

    def __init__(self, path: str | Path, threads: int = 1, kind: str | None = None):
        self.path = Path(path)
        if not self.path.is_file():
            raise ModelError(f"model file {self.path} does not exist")
        try:
            self.session = ort.InferenceSession(str(self.path), session_options(threads),
                                                providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own exception types
            raise ModelError(f"onnxruntime cannot load {self.path}: {e}") from None
        raw = self.session.get_modelmeta().custom_metadata_map.get(META_KEY)
        if raw is None:
            raise ModelError(f"{self.path} has no '{META_KEY}' metadata: not a track3d model")
        try:
            self.meta: dict = json.loads(raw)
        except json.JSONDecodeError as e:
            raise ModelError(f"{self.path}: metadata is not JSON ({e})") from None
        if kind is not None and self.meta.get("kind") != kind:
            raise ModelError(f"{self.path} is a {self.meta.get('kind')!r} model, expected {kind!r}")
        self.input_names = [i.name for i in self.session.get_inputs()]
        self.output_names = [o.name for o in self.session.get_outputs()]

    def run(self, feeds: dict[str, np.ndarray], outputs: list[str] | None = None) -> list[np.ndarray]:
        return self.session.run(outputs, feeds)
