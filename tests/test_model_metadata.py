"""Every shipped model describes itself truly: standard ONNX fields, metadata consistent with
the model (A3BoxNet's normalisation text matches its size coding), training-data identity, no
absolute paths; the exporters write the same; metadata rewrites leave the graph untouched."""
from __future__ import annotations

import json
from types import SimpleNamespace

import onnxruntime as ort
import pytest

from track3d.onnxmodel import META_KEY, MODELS_DIR

SHIPPED = sorted(MODELS_DIR.glob("*.onnx"))


def _walk_strings(v):
    """Every string of the metadata but ONNX node names (lists under keys ending in 'nodes')."""
    if isinstance(v, dict):
        for k, x in v.items():
            if not str(k).endswith("nodes"):
                yield from _walk_strings(x)
    elif isinstance(v, list):
        for x in v:
            yield from _walk_strings(x)
    elif isinstance(v, str):
        yield v


@pytest.mark.parametrize("path", SHIPPED, ids=[p.name for p in SHIPPED])
def test_shipped_model_metadata(path):
    so = ort.SessionOptions()
    so.log_severity_level = 3
    mm = ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"]).get_modelmeta()
    meta = json.loads(mm.custom_metadata_map[META_KEY])
    assert mm.producer_name == "track3d-train"
    assert mm.version >= 1 and mm.version == int(float(meta["version"]))
    assert meta["kind"] in mm.description or "SiamFC" in mm.description or "A3BoxNet" in mm.description
    assert len(mm.description) > 40
    for s in _walk_strings(meta):
        assert not s.startswith("/") and ":\\" not in s, f"absolute path in metadata: {s!r}"
    assert "train_data_hash" in meta and meta.get("train_data")
    if meta["kind"] == "a3boxnet":
        from track3d.boxnet import SIZE_NORMS

        assert meta["size_norm"] in SIZE_NORMS
        text = meta["normalisation"]
        if meta["size_norm"] in ("extent", "frustum"):
            assert "E * (1 + residual" in text and "* L" not in text
        else:
            assert "* L" in text
        assert len(meta["train_data_hash"]) == 64


def test_exporter_writes_the_normalisation_of_its_coding():
    pytest.importorskip("onnx")
    from track3d.size_coding import SIZE_CODINGS
    from track3d_train.boxnet.export import model_metadata

    for norm, coding in SIZE_CODINGS.items():
        cfg = SimpleNamespace(num_points=512, num_categories=3, use_category=True, width=1.0, size_norm=norm)
        assert model_metadata(SimpleNamespace(config=cfg))["normalisation"] == coding.description
    assert "E * (1 + residual" in SIZE_CODINGS["extent"].description
    assert "WHOLE frustum" not in SIZE_CODINGS["extent"].description and "ALL frustum" in SIZE_CODINGS["frustum"].description


def _tiny_model():
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])
    g = helper.make_graph([helper.make_node("Relu", ["x"], ["y"])], "g", [x], [y])
    return helper.make_model(g, opset_imports=[helper.make_opsetid("", 17)])


def test_rewrite_keeps_the_graph_and_fills_standard_fields(tmp_path):
    onnx = pytest.importorskip("onnx")
    from track3d_train.onnx_meta import PRODUCER, attach_metadata, rewrite_metadata

    p = tmp_path / "m.onnx"
    onnx.save(_tiny_model(), str(p))
    before = onnx.load(str(p)).graph.SerializeToString()
    attach_metadata(p, {"kind": "a3boxnet", "version": "2.0"})
    rewrite_metadata(p, {"kind": "a3boxnet", "version": "2.0", "x": 1})
    m = onnx.load(str(p))
    assert m.graph.SerializeToString() == before
    assert (m.producer_name, m.model_version) == (PRODUCER, 2) and "A3BoxNet" in m.doc_string
    assert json.loads({q.key: q.value for q in m.metadata_props}[META_KEY])["x"] == 1
    with pytest.raises(ValueError, match="absolute path"):
        attach_metadata(p, {"kind": "a3boxnet", "version": 1, "train_data": "/home/me/data"})


def test_siamfc_cache_records_its_data(tmp_path):
    pytest.importorskip("torch")
    from track3d_train.siamfc.data import build_cache, cache_data_info, synthetic_sequences

    out = build_cache(synthetic_sequences(1, frames=3, seed=0, h=64, w=64), tmp_path / "c", cache_size=160,
                      max_frames=3, progress=False, data_hash="ab" * 32, data_name="synthetic")
    assert cache_data_info(out) == {"train_data_hash": "ab" * 32, "train_data": "synthetic"}


def test_model_pair_resolves_a_prefix_either_file_or_explicit_paths():
    """One resolver for the two-graph trackers (EdgeTrack: template / search, SiamFC: exemplar /
    search): a prefix or either file of the pair names both; explicit paths win; one of two is
    an error; neither is the shipped pair."""
    from pathlib import Path

    from track3d.onnxmodel import model_pair

    parts = ("template", "search")
    shipped = lambda: ("ship_t", "ship_s")   # noqa: E731
    want = (Path("m/et_template.onnx"), Path("m/et_search.onnx"))
    for given in ("m/et", "m/et_template.onnx", "m/et_search.onnx", Path("m/et.onnx")):
        assert model_pair(given, None, None, parts, shipped) == want
    assert model_pair("m/et", "x.onnx", None, parts, shipped) == ("x.onnx", want[1])
    assert model_pair(None, None, None, parts, shipped) == ("ship_t", "ship_s")
    with pytest.raises(ValueError, match="give both template_model and search_model"):
        model_pair(None, "x.onnx", None, parts, shipped)
