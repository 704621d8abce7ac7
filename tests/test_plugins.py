"""Plug-ins: --plugin MODULE / file, entry points (groups track3d.trackers / track3d.estimators),
the shipped example (examples/tm_tracker.py) through `track3d track` and `track3d eval`, and
bad factory options as one line."""
from __future__ import annotations

import importlib.metadata
import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from track3d import estimators, plugins, trackers2d
from track3d.camera import Camera
from track3d.cli import main
from track3d.synthetic import make_synthetic_dataset

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "tm_tracker.py"


@pytest.fixture(autouse=True)
def clean_registry(monkeypatch):
    monkeypatch.setattr(trackers2d, "_REGISTRY", dict(trackers2d._REGISTRY))
    monkeypatch.setattr(estimators, "_REGISTRY", dict(estimators._REGISTRY))
    monkeypatch.setattr(plugins, "_loaded", set())


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    return make_synthetic_dataset(tmp_path_factory.mktemp("plug") / "ds", {"a": 6, "b": 5})


def _write_module(folder: Path, name: str) -> None:
    (folder / f"{name}.py").write_text(textwrap.dedent('''
        import numpy as np
        from track3d.estimators import register_estimator

        class CentroidBox:
            """A 1 m cube at the points' centroid."""
            def __init__(self, side=1.0):
                self.side = float(side)
            def estimate(self, points, category=-1):
                c = np.asarray(points, np.float64).mean(axis=0)
                return np.concatenate([c, [self.side] * 3])

        register_estimator("centroid", CentroidBox)
    '''))


def test_plugin_module_on_sys_path(tmp_path, monkeypatch, capsys, synth):
    _write_module(tmp_path, "my_box_plugin")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert main(["trackers", "--plugin", "my_box_plugin"]) == 0
    assert "centroid" in capsys.readouterr().out
    res = tmp_path / "res"
    assert main(["track", "--plugin", "my_box_plugin", "--data", str(synth), "--tracker", "oracle",
                 "--estimator", "centroid", "--estimator-option", "side=2", "--results", str(res),
                 "--video", "none", "--quiet"]) == 0
    boxes = np.loadtxt(res / "test" / "oracle+centroid" / "a" / "a_3d_001.txt", delimiter=",")
    assert np.allclose(boxes[1:, 3:], 2.0)


def test_example_plugin_tracks_and_evaluates(tmp_path, capsys, synth):
    assert main(["trackers", "--plugin", str(EXAMPLE)]) == 0
    assert "tm" in capsys.readouterr().out.split("3D estimators")[0]
    res, rep = tmp_path / "res", tmp_path / "rep"
    assert main(["--plugin", str(EXAMPLE), "track", "--data", str(synth), "--tracker", "tm",
                 "--results", str(res), "--video", "none", "--quiet"]) == 0
    assert main(["eval", "--data", str(synth), "--results", str(res), "--out", str(rep), "--no-plots",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "tm+a3boxnet" in out
    report = json.loads((rep / "report.json").read_text())
    assert report["trackers"]["tm+a3boxnet"]["overall"]["ao_2d"] > 0.3


def test_entry_points_are_loaded(tmp_path, monkeypatch, capsys):
    _write_module(tmp_path, "ep_box_plugin")
    (tmp_path / "ep_tracker_plugin.py").write_text(
        "from track3d.trackers2d import OracleTracker\ndef make(**kw):\n    return OracleTracker(**kw)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    eps = {plugins.TRACKER_GROUP: [importlib.metadata.EntryPoint("ep-oracle", "ep_tracker_plugin:make",
                                                                 plugins.TRACKER_GROUP),
                                   importlib.metadata.EntryPoint("broken", "no_such_module:x", plugins.TRACKER_GROUP)],
           plugins.ESTIMATOR_GROUP: [importlib.metadata.EntryPoint("ep-centroid", "ep_box_plugin:CentroidBox",
                                                                   plugins.ESTIMATOR_GROUP)]}
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group=None: eps.get(group, []))
    with pytest.warns(RuntimeWarning, match="broken"):
        assert main(["trackers"]) == 0
    out = capsys.readouterr().out
    assert "ep-oracle" in out and "ep-centroid" in out and "broken" not in out
    t = trackers2d.create_tracker("ep-oracle", gt=np.zeros((3, 4)))
    assert isinstance(t, trackers2d.OracleTracker)
    assert estimators.create_estimator("ep-centroid").estimate(np.ones((4, 3)), 0)[3] == 1.0


def test_unknown_name_before_plugins_are_loaded_finds_them(tmp_path, monkeypatch):
    _write_module(tmp_path, "late_plugin")
    monkeypatch.syspath_prepend(str(tmp_path))
    eps = [importlib.metadata.EntryPoint("late", "late_plugin:CentroidBox", plugins.ESTIMATOR_GROUP)]
    monkeypatch.setattr(importlib.metadata, "entry_points",
                        lambda group=None: eps if group == plugins.ESTIMATOR_GROUP else [])
    assert estimators.create_estimator("late", side=3.0).side == 3.0


@pytest.mark.parametrize("argv, message", [
    (["--tracker", "kcf", "--tracker-option", "nope=1"], "bad option for the 2D tracker 'kcf'"),
    (["--tracker", "oracle", "--estimator", "baseline", "--estimator-option", "x=1"],
     "bad option for the 3D box estimator 'baseline'"),
    (["--tracker", "tmx"], "unknown 2D tracker 'tmx'"),
    (["--plugin", "no_such_plugin_module"], "cannot be imported"),
])
def test_bad_options_are_one_line(synth, tmp_path, capsys, argv, message):
    rc = main(["track", "--data", str(synth), "--results", str(tmp_path), "--video", "none", "--quiet", *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and message in err[0], err


def test_factory_errors_name_the_accepted_options():
    with pytest.raises(ValueError, match="takes: correct"):
        trackers2d.create_tracker("kcf", nope=1)
    with pytest.raises(ValueError, match="missing a required argument: 'gt'"):
        trackers2d.create_tracker("oracle")
    from track3d.estimators import create_estimator

    # A3BoxNet's registry wrapper took **options: the list of what it takes was missing
    with pytest.raises(ValueError, match="takes: model, threads, num_points, seed, precision, engine"):
        create_estimator("a3boxnet", nope=1)


@pytest.mark.parametrize("returned", ["notabox", (True, "notabox"), (True, [1, 2, 3, 4], "extra"), None])
def test_a_tracker_breaking_the_protocol_is_named(returned):
    """A plug-in returning something other than (ok, box) ended in numpy's "could not convert
    string to float" or an unpacking error, not naming the tracker or the protocol."""
    from track3d.estimators import create_estimator
    from track3d.tracker import Track3D

    class Broken:
        def init(self, image, box):
            pass

        def update(self, image):
            return returned

    cam = Camera.from_fov(64, 48, 45.0)
    t = Track3D(cam, Broken(), create_estimator("baseline"))
    img = np.zeros((48, 64, 3), np.uint8)
    t.init(img, [10, 10, 8, 8])
    with pytest.raises(ValueError, match=r"returned .* from update\(image\); the protocol is \(ok: bool, box"):
        t.update(img, np.zeros((0, 3), np.float32))


def test_example_tracker_crops_a_box_past_the_image_to_its_visible_part(clean_registry):
    """examples/tm_tracker.py: a first box starting left of / above the image kept its full size
    after its corner was clamped, so the template took background and the box grew."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("tm_tracker_example", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    image = np.zeros((120, 160, 3), np.uint8)
    t = mod.TemplateTracker()
    t.init(image, [-20, 100, 100, 80])
    assert t.template.shape == (20, 80)          # rows 100..119, columns 0..79
    np.testing.assert_array_equal(t.box, [0, 100, 80, 20])
    t.init(image, [10, -5, 30, 25])
    np.testing.assert_array_equal(t.box, [10, 0, 30, 20])
