"""Two-graph trackers (EdgeTrack, SiamFC) load their two files as one export's pair.

An export writes both files through temporaries renamed into place one after the other
(track3d_train.onnx_meta.AtomicFiles): a kill between the renames left a new template / exemplar
graph beside an old search graph, which loaded and tracked silently with features the search
graph was not trained on. Each export now writes one export id into both files' metadata and the
runtime refuses a pair whose ids differ (track3d.onnxmodel.check_pair)."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import track3d.edgetrack as et  # noqa: E402
import track3d.siamfc as sf  # noqa: E402
from track3d.onnxmodel import EXPORT_ID, ModelError, OnnxModel  # noqa: E402
from track3d_train import onnx_meta  # noqa: E402

ET_TINY = dict(exemplar_size=128, instance_size=256, lost_instance_size=336, widths=(8, 16, 24, 32),
               feat_channels=32, head_channels=32, head_blocks=1)
PAIRS = {"edgetrack": (("template", "search"), et.create), "siamfc": (("exemplar", "search"), sf.create)}


def _net(name: str, seed: int):
    torch.manual_seed(seed)
    if name == "edgetrack":
        from track3d_train.edgetrack.model import EdgeTrack, EdgeTrackConfig

        return EdgeTrack(EdgeTrackConfig(**ET_TINY))
    from track3d_train.siamfc.model import SiamFC, config_for

    return SiamFC(config_for("edge", width=0.125, train_instance_size=159))


def _export(name: str, net, prefix: Path) -> tuple[Path, Path]:
    import importlib

    return importlib.import_module(f"track3d_train.{name}.export").export_onnx(net, prefix)


@pytest.fixture(scope="module")
def exports(tmp_path_factory):
    """{name: (prefix of export 0, prefix of export 1)}: two tiny pairs of other weights each."""
    root = tmp_path_factory.mktemp("pairs")
    out = {}
    for name in PAIRS:
        out[name] = tuple(root / f"{name}{seed}" / "m" for seed in (0, 1))
        for seed, prefix in enumerate(out[name]):
            _export(name, _net(name, seed), prefix)
    return out


def _files(prefix: Path, parts) -> list[Path]:
    return [prefix.parent / f"{prefix.name}_{p}.onnx" for p in parts]


def _tracks(create, prefix: Path) -> None:
    t = create(model=prefix)
    image = np.random.default_rng(0).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    t.init(image, [100, 100, 40, 40])
    t.update(image)


@pytest.mark.parametrize("name", list(PAIRS))
def test_one_export_writes_one_id_into_both_files(exports, name):
    parts, create = PAIRS[name]
    a, b = (OnnxModel(f).meta for f in _files(exports[name][0], parts))
    assert a[EXPORT_ID] == b[EXPORT_ID] and len(a[EXPORT_ID]) == 64
    assert OnnxModel(_files(exports[name][1], parts)[0]).meta[EXPORT_ID] != a[EXPORT_ID]   # other weights
    _tracks(create, exports[name][0])


@pytest.mark.parametrize("name", list(PAIRS))
@pytest.mark.parametrize("new_first", [True, False])
def test_a_pair_mixed_from_two_exports_is_refused_in_one_line(exports, tmp_path, name, new_first):
    parts, create = PAIRS[name]
    old, new = (_files(p, parts) for p in exports[name])
    mixed = _files(tmp_path / "m", parts)
    shutil.copy(new[0] if new_first else old[0], mixed[0])
    shutil.copy(old[1] if new_first else new[1], mixed[1])
    with pytest.raises(ModelError, match=rf"{mixed[0]} and {mixed[1]} are not one export's pair \(export ids "
                                         rf"[0-9a-f]{{12}} and [0-9a-f]{{12}}\): `track3d-train {name} export`") as e:
        create(model=tmp_path / "m")
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("name", list(PAIRS))
def test_an_export_killed_between_its_two_renames_leaves_a_pair_the_runtime_refuses(exports, tmp_path, monkeypatch,
                                                                                    name):
    """The kill the export's all-or-none write cannot prevent: after the first file's rename."""
    parts, create = PAIRS[name]
    prefix = tmp_path / "m"
    for src, dst in zip(_files(exports[name][0], parts), _files(prefix, parts)):
        shutil.copy(src, dst)
    _tracks(create, prefix)
    search = _files(prefix, parts)[1]
    real = os.replace

    class Killed(BaseException):
        pass

    def replace(src, dst):
        if Path(dst) == search:
            raise Killed
        return real(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(Killed):
        _export(name, _net(name, 1), prefix)
    monkeypatch.setattr(os, "replace", real)
    assert OnnxModel(search).meta[EXPORT_ID] == OnnxModel(_files(exports[name][0], parts)[1]).meta[EXPORT_ID]
    with pytest.raises(ModelError, match="are not one export's pair"):
        create(model=prefix)


@pytest.mark.parametrize("name", list(PAIRS))
def test_a_file_without_an_id_beside_one_with_it_is_refused(exports, tmp_path, name):
    """An export before the id (none in its files) and one after it: two exports as well."""
    parts, create = PAIRS[name]
    files = _files(tmp_path / "m", parts)
    for src, dst in zip(_files(exports[name][0], parts), files):
        shutil.copy(src, dst)
    meta = OnnxModel(files[1]).meta
    del meta[EXPORT_ID]
    onnx_meta.rewrite_metadata(files[1], meta)
    with pytest.raises(ModelError, match=r"export ids [0-9a-f]{12} and none\)"):
        create(model=tmp_path / "m")


@pytest.mark.parametrize("create, variant", [(et.create, None), (sf.create, "edge"), (sf.create, "faithful")])
def test_the_shipped_pairs_still_load(create, variant):
    """Their files carry no export id (they predate it): neither file has one, so they load."""
    t = create(variant=variant) if variant else create()
    image = np.random.default_rng(0).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    t.init(image, [100, 100, 40, 40])
    t.update(image)


def test_atomic_files_flush_the_temporaries_before_the_first_replace(tmp_path, monkeypatch):
    """A rename can reach the disk before the data it names: after a power cut the new name held
    an empty or short file."""
    events = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(os, "fsync", lambda fd: events.append("fsync") or real_fsync(fd))
    monkeypatch.setattr(os, "replace", lambda a, b: events.append(f"replace {Path(b).name}") or real_replace(a, b))
    a, b = tmp_path / "a.onnx", tmp_path / "b.onnx"
    with onnx_meta.AtomicFiles(a, b) as (ta, tb):
        ta.write_bytes(b"new a")
        tb.write_bytes(b"new b")
    assert events[:4] == ["fsync", "fsync", "replace a.onnx", "replace b.onnx"], events
    assert a.read_bytes() == b"new a" and b.read_bytes() == b"new b"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.onnx", "b.onnx"]


# --- int8 twins (`<stem>_int8.onnx`, written by `track3d-train quantize`) beside a replaced model.
# A twin carries its parent's metadata, export id included, and the sha256 of the fp32 file it was
# made from (PARENT_SHA256). A re-export (--force) or a retraining replaced the fp32 files and left
# the twins: precision="int8" read both ids from the old twins, check_pair passed, and the tracker
# ran the previous export's weights without a word.

def _quantize(fp32: Path, seeds=(0, 1)) -> Path:
    """The int8 twin of `fp32` as `track3d-train quantize` writes it (calibrated on fixed random
    inputs of the model's shapes: the weights' provenance is tested here, not their accuracy)."""
    from track3d.onnxmodel import variant_path
    from track3d.variant_choice import example_feeds
    from track3d_train.quantize import quantize_file

    feeds = [example_feeds(fp32, OnnxModel(fp32).meta, seed) for seed in seeds]
    return quantize_file(fp32, variant_path(fp32, "int8"), feeds, ["Conv"], "x", "train")


def _copy_pair(prefix: Path, parts, dst: Path) -> list[Path]:
    files = _files(dst, parts)
    for src, f in zip(_files(prefix, parts), files):
        shutil.copy(src, f)
    return files


@pytest.mark.parametrize("name", list(PAIRS))
def test_int8_twins_left_beside_a_re_exported_pair_are_refused_in_one_line(exports, tmp_path, name):
    from track3d.onnxmodel import variant_path

    parts, create = PAIRS[name]
    prefix = tmp_path / "m"
    files = _copy_pair(exports[name][0], parts, prefix)
    for f in files:
        _quantize(f)
    create(model=prefix, precision="int8")                          # export 0's twins load
    _copy_pair(exports[name][1], parts, prefix)                     # what a re-export with --force leaves
    with pytest.raises(ModelError, match=rf"{variant_path(files[0], 'int8')} was made from another "
                                         rf"{files[0].name} \(its recorded parent sha256 [0-9a-f]{{12}} is not the "
                                         rf"file's [0-9a-f]{{12}}.*`track3d-train quantize`") as e:
        create(model=prefix, precision="int8")
    assert "\n" not in str(e.value)
    _tracks(create, prefix)                                         # fp32 reads the new pair
    _quantize(files[1])                                             # one twin remade: the other is still old
    with pytest.raises(ModelError, match=rf"{variant_path(files[0], 'int8').name} was made from another"):
        create(model=prefix, precision="int8")
    _quantize(files[0])
    t = create(model=prefix, precision="int8")
    nets = [v for v in vars(t).values() if isinstance(v, OnnxModel)]
    assert len(nets) == 2 and all(n.precision == "int8" for n in nets)
    assert {n.meta[EXPORT_ID] for n in nets} == {OnnxModel(files[0]).meta[EXPORT_ID]}


@pytest.mark.parametrize("name", list(PAIRS))
def test_a_pair_of_int8_twins_from_two_exports_names_quantize_not_the_export(exports, tmp_path, name):
    """Twins that record no parent (made by hand: the fp32 graphs under the int8 names) from two
    exports: exporting the pair again, as the message had said, does not rewrite them."""
    from track3d.onnxmodel import variant_path

    parts, create = PAIRS[name]
    prefix = tmp_path / "m"
    files = _copy_pair(exports[name][1], parts, prefix)
    shutil.copy(_files(exports[name][0], parts)[0], variant_path(files[0], "int8"))
    shutil.copy(files[1], variant_path(files[1], "int8"))
    with pytest.raises(ModelError, match=r"are not made from one export's pair \(export ids [0-9a-f]{12} and "
                                         rf"[0-9a-f]{{12}}\): `track3d-train quantize` writes the int8 files.*"
                                         rf"after `track3d-train {name} export`") as e:
        create(model=prefix, precision="int8")
    assert "\n" not in str(e.value) and "export the pair again" not in str(e.value)


def test_a3boxnet_int8_twin_of_a_changed_model_is_refused(tmp_path):
    """The rule is every variant's, not the pairs': the shipped A3BoxNet and its twin, then the fp32
    file changed (here its metadata rewritten, as fit-threshold --write or a re-export does; the
    twin carries the old metadata)."""
    pytest.importorskip("onnx")
    from track3d.boxnet import A3BoxNetEstimator
    from track3d.onnxmodel import MODELS_DIR, variant_path

    src = MODELS_DIR / "a3boxnet.onnx"
    if not variant_path(src, "int8").is_file():
        pytest.skip("no shipped A3BoxNet int8 twin")
    fp32 = tmp_path / src.name
    shutil.copy(src, fp32)
    shutil.copy(variant_path(src, "int8"), variant_path(fp32, "int8"))
    assert OnnxModel(fp32, precision="int8").precision == "int8"
    onnx_meta.rewrite_metadata(fp32, {**OnnxModel(fp32).meta, "note": "changed"})
    with pytest.raises(ModelError, match=r"a3boxnet_int8.onnx was made from another a3boxnet.onnx .*"
                                         r"`track3d-train quantize`, or load precision 'fp32'") as e:
        A3BoxNetEstimator(fp32, precision="int8")
    assert "\n" not in str(e.value)
    assert A3BoxNetEstimator(fp32).model.precision == "fp32"


def test_every_shipped_twin_records_the_fp32_file_beside_it():
    """The shipped twins load as before: their recorded parent hash is their fp32 file's today
    (fix_model_metadata.py rewrote the parents' metadata and the recorded hash with it)."""
    from track3d.onnxmodel import MODELS_DIR, PARENT_SHA256, made_from, variant_path

    twins = [(f, variant_path(f, "int8")) for f in sorted(MODELS_DIR.glob("*.onnx")) if not f.stem.endswith("_int8")]
    for fp32, twin in [(f, t) for f, t in twins if t.is_file()]:
        meta = OnnxModel(fp32, precision="int8").meta
        assert meta.get(PARENT_SHA256) and made_from(fp32, meta) is True, twin.name


def test_siamfc_export_int8_twin_records_its_parent(exports, tmp_path):
    """`track3d-train siamfc export --int8` writes the search twin itself: it recorded no parent
    and no precision, so neither the loader nor check_pair could tell it from a current file."""
    import hashlib

    from track3d.onnxmodel import variant_path
    from track3d.variant_choice import example_feeds
    from track3d_train.siamfc.export import quantize_search

    parts = PAIRS["siamfc"][0]
    _, ex = _copy_pair(exports["siamfc"][0], parts, tmp_path / "m")
    feeds = example_feeds(ex, OnnxModel(ex).meta)
    twin = quantize_search(ex, variant_path(ex, "int8"), feeds["search"], feeds["exemplar_feature"])
    meta = OnnxModel(twin).meta
    assert meta.get("precision") == "int8" and meta.get("parent_model") == ex.name
    assert meta.get("parent_sha256") == hashlib.sha256(ex.read_bytes()).hexdigest()
    shutil.copy(_files(exports["siamfc"][1], parts)[1], ex)
    with pytest.raises(ModelError, match="was made from another m_search.onnx"):
        OnnxModel(ex, precision="int8")


def _edgetrack_checkpoint(path: Path, seed: int) -> Path:
    net = _net("edgetrack", seed)
    torch.save({"config": net.cfg.to_dict(), "model": net.state_dict(), "step": 1,
                "train_data_hash": "0" * 64, "train_data": "tiny"}, path)
    return path


def test_export_refuses_or_removes_the_int8_twins_of_the_model_it_replaces(tmp_path, capsys):
    """A re-export with --force had replaced the pair and left its `_int8` files (the old
    weights); without --force a twin beside the pair it writes is refused like the files."""
    from track3d_train.cli import main as train_main

    prefix = tmp_path / "m"
    files = _files(prefix, ("template", "search"))
    cmd = ["edgetrack", "export", "--out", str(prefix), "--checkpoint"]
    assert train_main(cmd + [str(_edgetrack_checkpoint(tmp_path / "a.pt", 0))]) == 0
    twins = [_quantize(f) for f in files]
    for f in files:
        f.unlink()                        # the pair gone, its twins left: still refused without --force
    capsys.readouterr()
    assert train_main(cmd + [str(_edgetrack_checkpoint(tmp_path / "b.pt", 1))]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and f"{twins[1]} exists (an int8 twin" in err and "--force" in err, err
    assert not any(f.exists() for f in files) and all(t.is_file() for t in twins)
    assert train_main(cmd + [str(tmp_path / "b.pt"), "--force"]) == 0
    out = capsys.readouterr().out
    assert all(f"removed {t}: the int8 twin" in out for t in twins), out
    assert not any(t.exists() for t in twins) and all(f.is_file() for f in files)
    with pytest.raises(ModelError, match="no int8 variant"):
        et.create(model=prefix, precision="int8")


def test_refuse_existing_lists_twins_and_remove_keeps_a_current_one(exports, tmp_path, capsys):
    """A3BoxNet's export writes one file, siamfc export --int8 a twin among its files: only the
    twins beside the files written and not written themselves are the export's to refuse or remove,
    and a twin made from the file now beside it is kept."""
    from track3d.onnxmodel import variant_path

    model = tmp_path / "a.onnx"
    shutil.copy(_files(exports["edgetrack"][0], ("template",))[0], model)
    twin = _quantize(model, seeds=(0,))
    assert onnx_meta.refuse_existing([model], force=True) == [twin]
    assert onnx_meta.refuse_existing([model, twin], force=True) == []        # the export writes it
    assert onnx_meta.remove_stale_twins([twin]) == [] and twin.is_file()     # made from a.onnx as it is
    onnx_meta.rewrite_metadata(model, {**OnnxModel(model).meta, "note": "re-exported"})
    capsys.readouterr()
    assert onnx_meta.remove_stale_twins([twin]) == [twin] and not twin.exists()
    assert capsys.readouterr().out.count("\n") == 1
    junk = variant_path(model, "int8")
    junk.write_bytes(b"not a model")                                         # no parent to tell: removed too
    model.unlink()
    with pytest.raises(ValueError, match=rf"{junk} exists \(an int8 twin.*pass --force.*--out$"):
        onnx_meta.refuse_existing([model])
    shutil.copy(_files(exports["edgetrack"][0], ("template",))[0], model)
    assert onnx_meta.remove_stale_twins(onnx_meta.refuse_existing([model], force=True)) == [junk]


def test_fsync_opens_the_file_for_writing(tmp_path, monkeypatch):
    """os.fsync of a file opened "rb" fails on Windows (EBADF): flushing a temporary before its
    rename raised there."""
    fcntl = pytest.importorskip("fcntl")
    modes = []
    real = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: modes.append(fcntl.fcntl(fd, fcntl.F_GETFL) & os.O_ACCMODE)
                        or real(fd))
    f = tmp_path / "a.onnx"
    f.write_bytes(b"x")
    onnx_meta._fsync(f)
    assert modes == [os.O_RDWR]


def test_a_threshold_fit_written_into_a_pair_removes_its_int8_twins(exports, tmp_path, capsys):
    """fit-threshold --write rewrites the fp32 files' metadata: their twins keep the old threshold
    and the old sha256, refused by the runtime from then on; the write removes them, one line each."""
    from track3d.onnxmodel import variant_path
    from track3d_train.edgetrack.threshold import write_threshold

    parts, create = PAIRS["edgetrack"]
    prefix = tmp_path / "m"
    files = _copy_pair(exports["edgetrack"][0], parts, prefix)
    twins = [_quantize(f) for f in files]
    assert all(t.is_file() for t in twins)
    write_threshold(prefix, 0.3, {"data": "x"})
    assert not any(variant_path(f, "int8").exists() for f in files)
    out = capsys.readouterr().out
    assert out.count("removed ") == 2 and "track3d-train quantize" in out
    assert OnnxModel(files[1]).meta["tracking"]["score_threshold"] == 0.3
