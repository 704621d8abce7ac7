"""Writing track3d metadata into exported ONNX files (read back by track3d.onnxmodel)."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

from track3d.onnxmodel import META_KEY

__all__ = ["attach_metadata", "file_hash", "hash_files", "refuse_shipped"]


def attach_metadata(onnx_path: str | Path, meta: dict) -> None:
    """Store `meta` (JSON-serialisable, must hold 'kind' and 'version') in the ONNX file."""
    import onnx

    if "kind" not in meta or "version" not in meta:
        raise ValueError("model metadata needs 'kind' and 'version'")
    model = onnx.load(str(onnx_path))
    del model.metadata_props[:]
    entry = model.metadata_props.add()
    entry.key = META_KEY
    entry.value = json.dumps(meta, sort_keys=True)
    onnx.save(model, str(onnx_path))


def file_hash(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def hash_files(paths) -> str:
    """One sha256 over several files (names and bytes), e.g. the labels a model was trained on."""
    h = hashlib.sha256()
    for p in sorted(Path(x) for x in paths):
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def refuse_shipped(paths, force: bool = False) -> None:
    """ValueError when an export would overwrite a model shipped in track3d/models (unless force)."""
    from track3d.onnxmodel import MODELS_DIR

    shipped = MODELS_DIR.resolve()
    hit = [Path(p) for p in paths if Path(p).exists() and Path(p).resolve().parent == shipped]
    if hit and not force:
        raise ValueError(f"{hit[0]} is a shipped model: write elsewhere with --out, or pass --force to replace it")
