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
