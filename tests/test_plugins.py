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


@pytest.mark.parametrize("returned", ["notabox", (True, "notabox"), (True, [1, 2, 3, 4], "extra"), None,
                                      ("no", [1, 2, 3, 4]), (True, np.ones((2, 2))), (2, [1, 2, 3, 4])])
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


def _loop(tracker, estimator="baseline"):
    from track3d.estimators import create_estimator
    from track3d.tracker import Track3D

    cam = Camera.from_fov(64, 48, 45.0)
    t = Track3D(cam, tracker, create_estimator(estimator) if isinstance(estimator, str) else estimator)
    img = np.zeros((48, 64, 3), np.uint8)
    t.init(img, [10, 10, 8, 8])
    return t, img


class _Still:
    def __init__(self, **kw):
        self.box = None

    def init(self, image, box):
        self.box = np.array(box, np.float64)

    def update(self, image):
        return True, self.box


@pytest.mark.parametrize("name", ["edgetrack", "EdgeTrack", "oracle", "kcf"])
def test_a_built_in_name_is_not_replaced_silently(name):
    """A plug-in registering "EdgeTrack" had run in the built-in's place and written its results
    under the built-in's name (a plug-in walkthrough); refused unless asked for knowingly."""
    with pytest.raises(ValueError, match="is a built-in tracker of track3d: register yours under another name"):
        trackers2d.register_tracker(name, _Still)
    with pytest.raises(ValueError, match="is a built-in estimator"):
        estimators.register_estimator("baseline", lambda **kw: None)
    trackers2d.register_tracker(name, _Still, replace=True)
    assert isinstance(trackers2d.create_tracker(name), _Still)


@pytest.mark.parametrize("made", ["none", "typo"])
def test_a_factory_that_builds_no_tracker_is_one_line(made, synth, tmp_path, capsys):
    """A factory without `return`, a class with `upate`: they passed the up-front build and ended
    in an AttributeError traceback mid-run."""
    class Typo:
        def init(self, image, box):
            pass

        def upate(self, image):
            return True, [1, 2, 3, 4]

    trackers2d.register_tracker("mine", (lambda **kw: None) if made == "none" else Typo)
    with pytest.raises(ValueError, match="has no .*update\\(\\)"):
        trackers2d.create_tracker("mine")
    estimators.register_estimator("mybox", lambda **kw: object())
    with pytest.raises(ValueError, match="built object, which has no estimate\\(\\)"):
        estimators.create_estimator("mybox")
    assert main(["track", "--data", str(synth), "--tracker", "mine", "--results", str(tmp_path / "r"),
                 "--video", "none", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the 2D tracker 'mine' built" in err


def test_a_plug_ins_own_error_is_one_line_naming_its_place(synth, tmp_path, capsys):
    """An IndexError in a plug-in's update ended in a traceback, a RuntimeError of its own read as
    track3d's; both now name the plug-in's file, line and function."""
    plug = tmp_path / "oops_plugin.py"
    plug.write_text(textwrap.dedent('''
        from track3d.trackers2d import register_tracker

        class Oops:
            def __init__(self, kind="index"):
                self.kind = kind
            def init(self, image, box):
                self.box = list(box)
            def update(self, image):
                if self.kind == "index":
                    return True, self.box[7]
                raise RuntimeError("boom in my update")

        register_tracker("oops", Oops)
    '''))
    for kind, name in (("index", "IndexError"), ("runtime", "RuntimeError")):
        capsys.readouterr()
        assert main(["track", "--plugin", str(plug), "--data", str(synth), "--tracker", "oops",
                     "--tracker-option", f"kind={kind}", "--results", str(tmp_path / f"r{kind}"),
                     "--video", "none", "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"the plug-in raised {name} at oops_plugin.py:" in err
        assert " in update: " in err and "Traceback" not in err


def test_a_plug_in_cannot_draw_into_the_callers_frame():
    """A tracker that wrote into the image changed the caller's array and the overlay."""
    class Painter(_Still):
        def update(self, image):
            image[:, :10] = 255
            return True, self.box

    t, img = _loop(Painter())
    with pytest.raises(ValueError, match="read-only"):
        t.update(img, np.zeros((0, 3), np.float32))
    assert not img.any()


def test_the_trackers_own_box_is_recorded_before_the_loop_corrects_it():
    """A tracker that returns its own array and moves it in correct() had its fused box recorded
    as its own (box2d_raw)."""
    class Aliased(_Still):
        def correct(self, box):
            self.box[:] = box      # moves the very array update() returned

    from track3d.bench import synthetic_frames

    cam = Camera.from_fov(320, 240, 45.0)
    frames = synthetic_frames(cam, n=3)
    from track3d.estimators import create_estimator
    from track3d.tracker import Track3D

    tr = Aliased()
    t = Track3D(cam, tr, create_estimator("baseline"))
    t.init(frames[0][0], frames[0][2] + np.array([3.0, 2.0, 0.0, 0.0]), 0)
    own = tr.box.copy()
    out = t.update(frames[1][0], frames[1][1])
    assert not np.allclose(out.box2d, own)                   # the case: the loop moved the box
    np.testing.assert_array_equal(out.box2d_raw, own)


def test_protocol_breaks_the_loop_survives_are_said_once():
    """A 2D box that is no box, a score outside 0..1, a 3D box that is no box: taken as lost /
    clamped / no estimate, each with one warning per tracker (they had been silent)."""
    import warnings

    class Scored(_Still):
        score = 2.5

    class NanBox:
        amodal = False

        def estimate(self, points, category=-1):
            return [np.nan] * 6

    t, img = _loop(Scored(), NanBox())
    pts = np.array([[0.0, 0.0, 10.0], [0.3, 0.2, 10.2], [-0.2, 0.1, 10.4]] * 30, np.float32)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):
            out = t.update(img, pts)
    said = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    assert out.score == 1.0
    assert sum("has score 2.5, not a number in 0..1" in m for m in said) == 1
    t2, img = _loop(type("Bad", (_Still,), {"update": lambda self, image: (True, [1.0, 1.0, -3.0, 4.0])})())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):
            assert t2.update(img, pts).status == "lost"
    assert sum("not a box (a non-finite value or a size <= 0): taken as lost" in str(w.message)
               for w in caught) == 1


def test_option_values_that_are_names_stay_names():
    from track3d.cli import _options

    got = _options(["a=1", "b=-2.5", "c=1e-3", "d=nan", "e=inf", "f=1_000", "g=true", "h=.5"])
    assert got == {"a": 1, "b": -2.5, "c": 1e-3, "d": "nan", "e": "inf", "f": "1_000", "g": True, "h": 0.5}


def test_a_tracker_that_cannot_be_checkpointed_is_named_not_its_repr():
    t, img = _loop(_Still())
    with pytest.raises(ValueError, match=r"the 2D tracker '_Still' has no get_state\(\)"):
        t.get_state()


def test_create_takes_threads_for_the_parts_that_run_models():
    """`Track3D.create(cam, tracker="kcf", estimator="a3boxnet", threads=1)` was a TypeError of
    __init__ (a walkthrough with the README's `threads=` of the API)."""
    from track3d.tracker import Track3D

    cam = Camera.from_fov(64, 48, 45.0)
    t = Track3D.create(cam, tracker="kcf", estimator="a3boxnet", threads=1)
    assert t.estimator_options == {"threads": 1} and t.tracker_options == {"threads": 1}
    class Plain(_Still):
        def __init__(self):
            super().__init__()

    trackers2d.register_tracker("plain", Plain)        # a plug-in without a threads option: none given
    assert Track3D.create(cam, tracker="plain", estimator="baseline", threads=1).tracker_options == {}
    t = Track3D.create(cam, tracker="kcf", estimator="a3boxnet", estimator_options={"threads": 2}, threads=1)
    assert t.estimator_options == {"threads": 2}                                  # its own option stands
    with pytest.raises(ValueError, match="threads"):
        Track3D.create(cam, tracker="kcf", estimator="baseline", threads=0)


def test_an_error_in_a_plug_in_packages_submodule_is_one_line(synth, tmp_path, capsys, monkeypatch):
    """--plugin mypkg whose tracker lives in mypkg.trk: its error came out as a traceback (a review)."""
    pkg = tmp_path / "oopspkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("from track3d.trackers2d import register_tracker\n"
                                     "from .trk import Oops\nregister_tracker('oopspkg', Oops)\n")
    (pkg / "trk.py").write_text(textwrap.dedent('''
        class Oops:
            def init(self, image, box):
                self.box = list(box)
            def update(self, image):
                return True, self.box[7]
    '''))
    monkeypatch.syspath_prepend(str(tmp_path))
    assert main(["track", "--plugin", "oopspkg", "--data", str(synth), "--tracker", "oopspkg",
                 "--results", str(tmp_path / "r"), "--video", "none", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the plug-in raised IndexError at trk.py:" in err


@pytest.mark.parametrize("flag", [True, np.bool_(True), np.array(True), np.array(1), 1, np.int64(1)])
def test_ok_may_be_any_zero_d_bool(flag):
    """`ok = score > threshold` on a 0-d array (or a torch tensor) had become a protocol error (a review)."""
    class Flagged(_Still):
        def update(self, image):
            return flag, self.box

    t, img = _loop(Flagged())
    assert t.update(img, np.zeros((0, 3), np.float32)).status != "lost"


def test_a_plug_ins_broken_pipe_is_an_error_not_a_closed_stdout(synth, tmp_path, capsys):
    """Any BrokenPipeError had ended the run with exit 0 and no word, as if `| head` had closed
    stdout (a review): a plug-in's own pipe to a helper process is an error like any other."""
    class Piped(_Still):
        def update(self, image):
            raise BrokenPipeError(32, "Broken pipe")

    trackers2d.register_tracker("piped", Piped)
    assert main(["track", "--data", str(synth), "--tracker", "piped", "--results", str(tmp_path / "r"),
                 "--video", "none", "--quiet"]) == 2
    assert "Broken pipe" in capsys.readouterr().err
