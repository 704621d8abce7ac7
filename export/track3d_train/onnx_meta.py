"""Writing track3d metadata into exported ONNX files (read back by track3d.onnxmodel)."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

from track3d.onnxmodel import EXPORT_ID, META_KEY, PARENT_SHA256, file_sha256, made_from, variant_path

__all__ = ["attach_metadata", "set_fields", "read_metadata", "rewrite_metadata", "doc_string", "file_hash", "hash_files",
           "refuse_shipped", "refuse_existing", "PRODUCER", "check_portable", "load_model", "save_model",
           "temp_beside", "AtomicFiles", "export_id", "EXPORT_ID", "parent_fields", "remove_stale_twins", "twins_of"]

PRODUCER = "track3d-train"


def _producer_version() -> str:
    try:
        from importlib.metadata import version

        return version("track3d")
    except Exception:  # a bare checkout
        return "unknown"


def doc_string(meta: dict) -> str:
    """One paragraph for ONNX's doc_string: what the model is and where its metadata lives."""
    kind = meta.get("kind", "?")
    what = {"a3boxnet": "A3BoxNet 3D box estimator (Track3D, paper IV-B): centred frustum points "
                        "(+ one-hot category) -> centre corrections, size class scores and residuals",
            "siamfc-exemplar": "SiamFC exemplar branch: uint8 RGB exemplar crop -> exemplar feature",
            "siamfc-search": "SiamFC search branch: uint8 RGB search crops + exemplar feature -> response maps "
                             "(logits)"}.get(kind, kind)
    variant = f", variant {meta['variant']}" if meta.get("variant") else ""
    return (f"{what}{variant}. Made by {PRODUCER} (track3d project); the runtime reads its settings from "
            f"the JSON metadata under the key '{META_KEY}' (version {meta.get('version')}).")


def set_fields(model, meta: dict) -> None:
    """Write `meta` under META_KEY and fill ONNX's standard fields (producer, model_version,
    doc_string) of an onnx.ModelProto in memory."""
    if "kind" not in meta or "version" not in meta:
        raise ValueError("model metadata needs 'kind' and 'version'")
    check_portable(meta)
    del model.metadata_props[:]
    entry = model.metadata_props.add()
    entry.key = META_KEY
    entry.value = json.dumps(meta, sort_keys=True)
    model.producer_name = PRODUCER
    model.producer_version = _producer_version()
    model.model_version = int(float(meta["version"]))
    model.doc_string = doc_string(meta)


def read_metadata(model) -> dict:
    """The track3d metadata (META_KEY's JSON) of an onnx.ModelProto in memory; ValueError if it
    has none (the reader beside set_fields, its writer)."""
    props = {e.key: e.value for e in model.metadata_props}
    if META_KEY not in props:
        raise ValueError("no track3d metadata")
    return json.loads(props[META_KEY])


def load_model(path: str | Path, what: str = "an ONNX model"):
    """onnx.load, a file that is not a whole ONNX model (truncated, another file) being a one-line
    ValueError naming `what` (it had been protobuf's DecodeError traceback)."""
    import onnx

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"model file {p} does not exist" if not p.exists() else f"{p} is a folder, not {what}")
    try:
        return onnx.load(str(p))
    except Exception as e:   # google.protobuf DecodeError, RuntimeError, ...: not a complete ONNX file
        raise ValueError(f"{p} is not {what} (not a complete ONNX file: {type(e).__name__})") from None


def temp_beside(path: str | Path) -> Path:
    """The temporary file an atomic write of `path` goes through (the same folder, so that
    os.replace is a rename)."""
    p = Path(path)
    return p.with_name(p.name + ".tmp")


def _fsync(path: Path) -> None:
    """Flush a written file to the disk: a rename is recorded apart from the data it names, and
    after a power cut a file renamed before its data reached the disk can read empty or short."""
    import os

    # opened for writing: on Windows fsync (_commit) of a read-only descriptor fails with EBADF
    fd = os.open(path, os.O_RDWR | getattr(os, "O_BINARY", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_folder(folder: Path) -> None:
    """Flush a folder's entries (the renames into it); not possible on Windows, where a folder
    cannot be opened: skipped there."""
    import os

    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def save_model(model, path: str | Path) -> None:
    """onnx.save through a temporary file beside `path`, flushed to the disk, then os.replace: a
    kill (or a power cut) while writing leaves the file that was there whole."""
    import os

    import onnx

    tmp = temp_beside(path)
    try:
        onnx.save(model, str(tmp))
        _fsync(tmp)
        os.replace(tmp, path)
        _fsync_folder(Path(path).parent)
    finally:
        tmp.unlink(missing_ok=True)


def export_id(paths) -> str:
    """The id an export writes into the metadata of both files of a model pair (key EXPORT_ID;
    the runtime refuses a pair whose ids differ, track3d.onnxmodel.check_pair): the sha256 of the
    files' bytes as exported, before their metadata is attached. Deterministic: the same weights
    exported again give the same id (their files are interchangeable), other weights another.
    Not hash_files (which hashes the names too, sorted): the files hashed here are the export's
    temporaries (temp_beside, `<name>.tmp`), not yet under their final names, and the id must
    not depend on the prefix a pair is exported to; the order is the pair's (first, search)."""
    h = hashlib.sha256()
    for p in paths:
        h.update(Path(p).read_bytes())
    return h.hexdigest()


class AtomicFiles:
    """Write several files all or none: ``with AtomicFiles(a, b) as (ta, tb):`` write the
    temporaries beside them; leaving the block normally flushes them to the disk and replaces a
    then b by them, an exception (or a kill) leaves a and b as they were and no temporary behind
    (after an exception). A kill between the replaces leaves a new a beside an old b: a model pair
    carries one export id in both files for that (export_id), and the runtime refuses a mixed pair."""

    def __init__(self, *paths):
        self.paths = [Path(p) for p in paths]
        self.temps = [temp_beside(p) for p in self.paths]

    def __enter__(self) -> list[Path]:
        for p in self.paths:
            if p.is_dir():
                raise ValueError(f"{p} is a folder: give the path of a file to write")
        return list(self.temps)

    def __exit__(self, kind, value, tb) -> bool:
        import os

        try:
            if kind is None:
                # all flushed before the first replace: the window in which a power cut mixes old
                # and new files is the replaces' alone
                for t in self.temps:
                    _fsync(t)
                for t, p in zip(self.temps, self.paths):
                    os.replace(t, p)
                for folder in {p.parent for p in self.paths}:
                    _fsync_folder(folder)
        finally:
            for t in self.temps:
                t.unlink(missing_ok=True)
        return False


# The largest torch vs onnxruntime difference an export accepts, relative to the output's
# magnitude (at least 1): float32 noise of these graphs is ~1e-6 of it
PARITY_RTOL = 1e-3


def require_parity(diffs: dict, outputs, what: str) -> None:
    """AssertionError when an output's `<name>_max_abs` in `diffs` is beyond PARITY_RTOL of its
    `<name>_scale` (at least 1): the two runtimes disagree on the graph, and the export stops
    before its files replace anything (the check had been printed only)."""
    for name in outputs:
        d, scale = float(diffs[f"{name}_max_abs"]), float(diffs.get(f"{name}_scale", 1.0))
        if not d <= PARITY_RTOL * max(1.0, scale):
            raise AssertionError(f"{what} {name}: torch and onnxruntime differ by {d:.3g} (scale {scale:.3g}, "
                                 f"tolerance {PARITY_RTOL:g} of it): nothing written")


def twins_of(paths) -> list[Path]:
    """The variant files (variant_path: `<stem>_int8.onnx`) that exist beside the files `paths`,
    other than `paths` themselves (an export that writes a twin too, siamfc export --int8)."""
    own = {Path(p) for p in paths}
    twins = [variant_path(p, "int8") for p in own]
    return sorted({t for t in twins if t not in own and t.exists()})


def refuse_existing(paths, force: bool = False, out_flag: str = "--out") -> list[Path]:
    """ValueError when an export would overwrite a file that exists (a model of an earlier export,
    or any other file), or write a model beside an int8 twin (`<stem>_int8.onnx`, made by
    `track3d-train quantize` from the model there before), unless force; a folder where a file goes
    is refused even with force. Returns the twins found: with force the export removes them after
    writing (remove_stale_twins), as a twin left beside a new model is the old model's weights."""
    for p in (Path(x) for x in paths):
        if p.is_dir():
            raise ValueError(f"{out_flag} would write {p}, which is a folder: give the path of a file to write")
    hit = [Path(p) for p in paths if Path(p).exists()]
    if hit and not force:
        raise ValueError(f"{hit[0]} exists: pass --force to overwrite it, or write elsewhere with {out_flag}")
    twins = twins_of(paths)
    if twins and not force:
        raise ValueError(f"{twins[0]} exists (an int8 twin of the model this export would replace): pass --force "
                         f"to export and remove it (remake it with `track3d-train quantize`), or write elsewhere "
                         f"with {out_flag}")
    return twins


def remove_stale_twins(twins) -> list[Path]:
    """After an export: delete each twin (refuse_existing's list) that was not made from the file
    now beside it (made_from is not True: another parent, none recorded, or not a model), saying
    so in one line each; the runtime would refuse the first kind, and could not tell the others.
    Returns the files removed."""
    removed = []
    for t in (Path(x) for x in twins):
        parent = t.with_name(t.stem[: -len("_int8")] + t.suffix)   # variant_path's rule, backwards
        try:
            fresh = parent.is_file() and made_from(parent, read_metadata(load_model(t))) is True
        except ValueError:   # not an ONNX file, or no track3d metadata
            fresh = False
        if not fresh and t.is_file():
            t.unlink()
            removed.append(t)
            print(f"removed {t}: the int8 twin of the model this export replaced (remake it with "
                  f"`track3d-train quantize`)")
    return removed


def parent_fields(parent: str | Path) -> dict:
    """The metadata a variant file records of the fp32 file it is made from: its name and sha256
    (PARENT_SHA256; the runtime refuses a variant whose parent changed since, track3d.onnxmodel.made_from)."""
    return {"parent_model": Path(parent).name, PARENT_SHA256: file_sha256(parent)}


def exported_weights(path: str | Path, kind: str, what: str) -> tuple[dict, dict, list]:
    """(metadata, initialisers by name, (weight, bias or None) of every Conv node in graph order)
    of an exported model whose metadata kind is `kind`; ValueError naming `what` for any other
    ONNX file. The reader the from-ONNX converters (A3BoxNet, EdgeTrack) share."""
    from onnx import numpy_helper

    m = load_model(path, what)
    try:
        meta = read_metadata(m)
    except ValueError:
        meta = {}
    if meta.get("kind") != kind:
        raise ValueError(f"{path} is not {what} (its metadata kind is {meta.get('kind')!r})")
    init = {t.name: numpy_helper.to_array(t) for t in m.graph.initializer}
    convs = [(init[n.input[1]], init[n.input[2]] if len(n.input) > 2 else None)
             for n in m.graph.node if n.op_type == "Conv"]
    return meta, init, convs


def set_folded_bn(bn, mean, var, shift=0.0) -> None:
    """Set a BatchNorm after a convolution whose BatchNorm the export folded: x + shift in eval mode
    ((x - mean) / sqrt(var + eps) times its weight sqrt(var + eps), plus its bias mean + shift), and
    in training mode about the same for a batch with this channel mean and variance. The from-ONNX
    converters' one rule (A3BoxNet's convolutions carry their bias themselves: shift 0)."""
    import torch

    bn.running_mean.copy_(mean)
    bn.running_var.copy_(var)
    bn.weight.copy_(torch.sqrt(var + bn.eps))
    bn.bias.copy_(mean + shift)


def attach_metadata(onnx_path: str | Path, meta: dict) -> None:
    """Store `meta` (JSON-serialisable, must hold 'kind' and 'version') in the ONNX file, with
    the standard ONNX fields filled."""
    import onnx

    model = onnx.load(str(onnx_path))
    set_fields(model, meta)
    save_model(model, onnx_path)


def rewrite_metadata(onnx_path: str | Path, meta: dict) -> None:
    """Replace the metadata of an existing file, weights untouched: raises AssertionError if
    the graph's serialised bytes would change."""
    import onnx

    model = onnx.load(str(onnx_path))
    before = model.graph.SerializeToString()
    set_fields(model, meta)
    if model.graph.SerializeToString() != before:
        raise AssertionError(f"{onnx_path}: the graph changed while rewriting metadata")
    save_model(model, onnx_path)
    if onnx.load(str(onnx_path)).graph.SerializeToString() != before:
        raise AssertionError(f"{onnx_path}: the graph bytes changed on disk")


def check_portable(meta) -> None:
    """No absolute path of the exporting machine in metadata (a user has only the package).
    ONNX node names ('/box_net/fc/fc.0/Gemm', under a key ending in 'nodes') look like paths
    and are not checked."""
    def walk(v):
        if isinstance(v, dict):
            for k, x in v.items():
                if not str(k).endswith("nodes"):
                    walk(x)
        elif isinstance(v, list):
            for x in v:
                walk(x)
        elif isinstance(v, str) and (v.startswith("/") or (len(v) > 2 and v[1:3] in (":\\", ":/"))):
            raise ValueError(f"model metadata holds an absolute path {v!r}: store a name or a hash instead")
    walk(meta)


def file_hash(path: str | Path) -> str:
    """The sha256 of a file's bytes (the runtime's file_sha256: one rule for a recorded and a checked hash)."""
    return file_sha256(path)


def hash_files(paths) -> str:
    """One sha256 over several files (names and bytes), e.g. the labels a model was trained on."""
    h = hashlib.sha256()
    for p in sorted(Path(x) for x in paths):
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def refuse_shipped(paths, force: bool = False, out_flag: str = "--out") -> None:
    """ValueError when an export would overwrite a model shipped in track3d/models (unless force);
    out_flag: the command's option that chooses where it writes."""
    from track3d.onnxmodel import MODELS_DIR

    shipped = MODELS_DIR.resolve()
    hit = [Path(p) for p in paths if Path(p).exists() and Path(p).resolve().parent == shipped]
    if hit and not force:
        raise ValueError(f"{hit[0]} is a shipped model: write elsewhere with {out_flag}, or pass --force to replace it")
