"""The models shipped in runtime/track3d/models: present, self-describing, and better than
the baseline they replace (so a broken or untrained export fails here)."""
from __future__ import annotations

import numpy as np
import pytest

from track3d.boxes import SIZE_TEMPLATES
from track3d.onnxmodel import MODELS_DIR, OnnxModel

SHIPPED = {
    "a3boxnet_narrow.onnx": "a3boxnet",
    "a3boxnet.onnx": "a3boxnet",
    "a3boxnet_stereo.onnx": "a3boxnet",
    "a3boxnet_stereo_narrow.onnx": "a3boxnet",
    "a3boxnet_stereo_backlit.onnx": "a3boxnet",
    "a3boxnet_views.onnx": "a3boxnet",
    "siamfc_edge_exemplar.onnx": "siamfc-exemplar",
    "siamfc_edge_search.onnx": "siamfc-search",
    "siamfc_faithful_exemplar.onnx": "siamfc-exemplar",
    "siamfc_faithful_search.onnx": "siamfc-search",
}


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_model_is_present_and_carries_its_metadata(name):
    m = OnnxModel(MODELS_DIR / name, threads=1, kind=SHIPPED[name])
    assert m.meta.get("version") or m.meta.get("model_version")
    if SHIPPED[name] == "a3boxnet":
        np.testing.assert_allclose(np.asarray(m.meta["size_templates"]), SIZE_TEMPLATES, atol=1e-6)
        assert m.meta["num_points"] >= 64 and len(m.meta["train_data_hash"]) == 64
        # a sensor's own model says so, and is a fine-tune of the shared one
        assert m.meta.get("depth_sensor") == ("stereo" if name.startswith("a3boxnet_stereo") else None)
        if name == "a3boxnet_stereo.onnx":
            assert m.meta["trained"]["fine_tuned_from"]["file"] == "a3boxnet.onnx"
        if name == "a3boxnet_stereo_narrow.onnx":   # what the loop runs for stereo: the stereo model at half width
            assert m.meta["width"] == 0.5 and m.meta["trained"]["fine_tuned_from"]["file"] == "a3boxnet_stereo.onnx"
            assert m.meta["trained"]["distilled_from"] == {"file": "a3boxnet_stereo.onnx", "weight": 1.0}
        if name == "a3boxnet_views.onnx":   # the default, fine-tuned beside the body's past views
            from track3d.boxnet import PAST_VIEWS

            assert m.meta["past_views"] == PAST_VIEWS and m.meta["width"] == 0.5
            assert m.meta["trained"]["fine_tuned_from"]["file"] == "a3boxnet_narrow.onnx"
        else:
            assert "past_views" not in m.meta
        if name == "a3boxnet_stereo_backlit.onnx":   # the stereo model, shown crescents
            assert m.meta["trained"]["fine_tuned_from"]["file"] == "a3boxnet_stereo.onnx"
        # the default is the full-width model cut to half width and distilled from it
        if name == "a3boxnet_narrow.onnx":
            assert m.meta["width"] == 0.5 and m.meta["trained"]["fine_tuned_from"]["file"] == "a3boxnet_narrow.onnx"  # its recipe's last stage
            assert m.meta["trained"]["distilled_from"] == {"file": "a3boxnet.onnx", "weight": 1.0}
    else:
        assert m.meta["exemplar_size"] == 127 and m.meta["total_stride"] == 8


def _score(root, spec, tmp_path):
    from track3d.evaluation import Experiment

    exp = Experiment(root, "test", tmp_path / "res", tmp_path / "rep")
    exp.run(spec, quiet=True)
    scores = exp.score(spec.label)
    return float(np.mean([s.ao_3d for s in scores])), scores


@pytest.mark.parametrize("model", ["a3boxnet_narrow.onnx", "a3boxnet.onnx", "a3boxnet_views.onnx"])
def test_shipped_a3boxnet_beats_the_baseline_on_oracle_boxes(model, tiny_dataset, tmp_path):
    from track3d.evaluation import TrackerSpec

    net, _ = _score(tiny_dataset, TrackerSpec("oracle", "a3boxnet", fusion=False, estimator_options={"model": model}),
                    tmp_path / "net")
    base, _ = _score(tiny_dataset, TrackerSpec("oracle", "baseline", fusion=False), tmp_path / "base")
    assert net > base + 0.05, (net, base)


def test_default_track3d_tracks_the_tiny_test_split(tiny_dataset, tmp_path):
    from track3d.evaluation import TrackerSpec

    ao3d, scores = _score(tiny_dataset, TrackerSpec("siamfc-edge", "a3boxnet"), tmp_path)
    assert ao3d > 0.4 and all(s.frames > 0 for s in scores)


def test_a_shipped_model_is_chosen_by_its_bare_name(tmp_path, monkeypatch):
    """`--estimator-option model=a3boxnet_narrow.onnx` (a name, not a path) loads the shipped file;
    a file of that name in the working folder wins; a name shipped nowhere is a one-line error."""
    import shutil

    from track3d.boxnet import NARROW_MODEL, A3BoxNetEstimator
    from track3d.onnxmodel import ModelError

    monkeypatch.chdir(tmp_path)
    est = A3BoxNetEstimator(model=NARROW_MODEL)
    assert est.model.path == MODELS_DIR / NARROW_MODEL and est.model.meta["width"] == 0.5
    shutil.copy(MODELS_DIR / "a3boxnet.onnx", tmp_path / NARROW_MODEL)
    assert A3BoxNetEstimator(model=NARROW_MODEL).model.path.resolve() == (tmp_path / NARROW_MODEL).resolve()
    with pytest.raises(ModelError, match="does not exist"):
        A3BoxNetEstimator(model="a3boxnet_nowhere.onnx")
