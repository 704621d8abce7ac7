"""torch eager stand-ins of the shipped ONNX graphs, for the `--torch` rows of bench_fps.

A TorchModel has an OnnxModel's interface (``run(feeds, outputs)``, ``meta``, ``input_names``,
``output_names``, ``run_ms``; onnxmodel.is_model), so a tracker or estimator takes it as a
parameter in place of the file: same weights (the training checkpoint the ONNX was exported
from), the same wrappers export.py exports, everything else in the loop identical. torch and
the training package are imported only here (the runtime never imports them).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from track3d.onnxmodel import OnnxModel, models_of

__all__ = ["EQUIV_RTOL", "EquivalenceError", "TorchModel", "TorchNets"]

EQUIV_RTOL = 1e-3
# the constructor parameter that takes a model of each kind (track3d.siamfc / track3d.boxnet)
PARAMETER = {"siamfc-exemplar": "exemplar_model", "siamfc-search": "search_model", "a3boxnet": "model"}


class EquivalenceError(RuntimeError):
    """torch and onnxruntime disagree on the same inputs."""


class TorchModel:
    """A torch module behind OnnxModel's interface. On its first call it also runs the
    onnxruntime model it stands in for on the same feeds and raises EquivalenceError beyond
    EQUIV_RTOL (max |torch - ort| / max |ort|, per output); the result is kept in ``check``."""

    def __init__(self, torch, module, ref: OnnxModel, checkpoint: Path):
        self._torch = torch
        self.module = module.eval()
        self.meta = ref.meta
        self.input_names = list(ref.input_names)
        self.output_names = list(ref.output_names)
        self.path = Path(checkpoint)
        self.run_ms = 0.0
        self._ref: OnnxModel | None = ref
        self.check: dict | None = None

    def run(self, feeds: dict[str, np.ndarray], outputs: list[str] | None = None) -> list[np.ndarray]:
        torch = self._torch
        t = time.perf_counter()
        args = [torch.from_numpy(np.ascontiguousarray(feeds[n])) for n in self.input_names]
        with torch.inference_mode():
            out = self.module(*args)
        if isinstance(out, torch.Tensor):
            out = (out,)
        got = dict(zip(self.output_names, (o.numpy() for o in out)))
        res = [got[n] for n in (outputs or self.output_names)]
        self.run_ms += (time.perf_counter() - t) * 1e3
        if self._ref is not None:
            self._compare(feeds, outputs, res)
        return res

    def _compare(self, feeds, outputs, res) -> None:
        ref, self._ref = self._ref, None  # once; drop the session
        names = list(outputs or self.output_names)
        want = ref.run(feeds, names)
        self.check = {"kind": self.meta.get("kind"), "rtol": EQUIV_RTOL, "outputs": {}}
        bad = []
        for n, t, o in zip(names, res, want):
            if t.shape != o.shape:
                bad.append(f"{n}: shape torch {t.shape} vs onnxruntime {o.shape}")
                self.check["outputs"][n] = {"shape_torch": list(t.shape), "shape_ort": list(o.shape)}
                continue
            d = float(np.max(np.abs(t.astype(np.float64) - o))) if t.size else 0.0
            scale = float(np.max(np.abs(o))) if o.size else 0.0
            rel = d / max(scale, 1e-12)
            self.check["outputs"][n] = {"max_abs": d, "max_rel": rel}
            if not rel <= EQUIV_RTOL:
                bad.append(f"{n}: max |diff| {d:.3g} = {rel:.2e} of max |ort| {scale:.3g}")
        self.check["ok"] = not bad
        if bad:
            raise EquivalenceError(f"torch vs onnxruntime ({self.meta.get('kind')}, {self.path}): "
                                   + "; ".join(bad) + " -- is this checkpoint the one the ONNX was exported from?")


class TorchNets:
    """Checkpoints -> torch modules (the exported wrappers), loaded once, keyed by ONNX kind."""

    def __init__(self, siamfc: dict[str, Path], boxnet: Path):
        import torch

        self.torch = torch
        self.siamfc_ckpt = siamfc  # tracker name -> checkpoint
        self.boxnet_ckpt = boxnet
        self._cache: dict[Path, dict] = {}

    def needed(self, tracker: str, estimator: str) -> dict[str, Path]:
        """{role: checkpoint} this configuration needs ('2d', '3d'); empty: no network."""
        need = {}
        if tracker in self.siamfc_ckpt:
            need["2d"] = self.siamfc_ckpt[tracker]
        if estimator == "a3boxnet":
            need["3d"] = self.boxnet_ckpt
        return need

    def modules(self, ckpt: Path, role: str) -> dict:
        ckpt = Path(ckpt)
        if ckpt not in self._cache:
            if role == "2d":
                from track3d_train.siamfc.export import ExemplarGraph, SearchGraph
                from track3d_train.siamfc.train import load_checkpoint

                net, _ = load_checkpoint(ckpt)
                net.eval()
                self._cache[ckpt] = {"siamfc-exemplar": ExemplarGraph(net).eval(),
                                     "siamfc-search": SearchGraph(net).eval()}
            else:
                from track3d_train.boxnet.train import load_checkpoint

                model, _ = load_checkpoint(ckpt)  # A3BoxNet is exported as is
                self._cache[ckpt] = {"a3boxnet": model.eval()}
        return self._cache[ckpt]

    def options(self, reference, ckpt: Path, role: str) -> dict:
        """Constructor options {parameter: TorchModel} standing in for the ONNX models that
        `reference` (a tracker or estimator built from the files) runs."""
        mods = self.modules(ckpt, role)
        out = {PARAMETER[m.meta["kind"]]: TorchModel(self.torch, mods[m.meta["kind"]], m, ckpt)
               for m in models_of(reference).values() if m.meta.get("kind") in mods}
        if not out:
            raise RuntimeError(f"{type(reference).__name__} runs no onnxruntime model of kind {sorted(mods)}")
        return out
