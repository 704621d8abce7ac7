"""The training recipes (track3d_train.recipes): every full-size command parses with its CLI, the
tiny variants run end to end (data -> caches -> training -> ONNX), errors are one line."""
from __future__ import annotations

import importlib

import pytest

pytest.importorskip("torch")

from track3d_train.recipes import RECIPES, commands, main, recipe  # noqa: E402

_PARSERS = {("track3d-sim", None): "track3d_sim.cli", ("track3d-train", "boxnet"): "track3d_train.boxnet.cli",
            ("track3d-train", "edgetrack"): "track3d_train.edgetrack.cli",
            ("track3d-train", "siamfc"): "track3d_train.siamfc.cli",
            ("track3d-train", "quantize"): "track3d_train.quantize"}


@pytest.mark.parametrize("name", list(RECIPES))
@pytest.mark.parametrize("tiny", [False, True])
def test_every_command_of_every_recipe_parses_with_its_cli(name, tiny):
    for step, argv, _ in commands(recipe(name), "d", "r", tiny=tiny):
        prog, rest = argv[0], argv[1:]
        key = (prog, None) if prog == "track3d-sim" else (prog, rest[0])
        if prog == "track3d-train":
            rest = rest[1:]
        parser = importlib.import_module(_PARSERS[key]).build_parser()
        a = parser.parse_args(rest)          # SystemExit(2) on an unknown or ill-typed option
        assert a is not None, step.label
        assert not any("{" in x for x in argv), argv      # every placeholder filled


@pytest.mark.parametrize("name", list(RECIPES))
def test_tiny_recipe_runs_end_to_end(name, tmp_path):
    from track3d.onnxmodel import OnnxModel

    r = recipe(name)
    assert main(["run", name, "--tiny", "--data", str(tmp_path / "d"), "--runs", str(tmp_path / "r")]) == 0
    made = sorted((tmp_path / "r").rglob("*.onnx"))
    assert made, "the recipe exported no model"
    for p in made:
        assert OnnxModel(p, 1).meta["kind"]
    assert r.tiny and set(r.tiny) <= set(r.knobs)
    if name == "a3boxnet-stereo":   # a fine-tune of the shipped model, for stereo clouds
        meta = OnnxModel(made[-1], 1).meta
        assert meta["depth_sensor"] == "stereo" and meta["trained"]["fine_tuned_from"]["file"] == "a3boxnet.onnx"
    if name == "a3boxnet-stereo-narrow":   # half width, distilled from the shipped stereo model, for stereo clouds
        meta = OnnxModel(tmp_path / "r" / "boxnet-stereo-narrow" / "a3boxnet_stereo_narrow.onnx", 1).meta
        assert meta["depth_sensor"] == "stereo" and meta["width"] == 0.5
        assert meta["trained"]["distilled_from"] == {"file": "a3boxnet_stereo.onnx", "weight": 1.0}
    if name == "a3boxnet-narrow":   # the default: half width, distilled from the full-width model, an int8 twin
        meta = OnnxModel(tmp_path / "r" / "boxnet-narrow" / "a3boxnet_narrow.onnx", 1).meta
        assert meta["width"] == 0.5 and meta["trained"]["distilled_from"] == {"file": "a3boxnet.onnx", "weight": 1.0}
        # stage 3: stage 2 fine-tuned with the Gaussian random spheres in its training world as well
        assert meta["trained"]["fine_tuned_from"]["file"] == "a3boxnet_narrow.onnx"
        assert meta["train_data"].split("+") == ["engine-train-po", "engine-train-po2", "engine-train-sq",
                                                 "engine-train-gs"]
        assert (tmp_path / "r" / "boxnet-narrow" / "stage2" / "a3boxnet_narrow.onnx").is_file()
        assert (tmp_path / "r" / "boxnet-narrow" / "a3boxnet_narrow_int8.onnx").is_file()
    if name == "a3boxnet-engine":
        # a second run resumes: every step finds its work done or continues from its checkpoint
        assert main(["run", name, "--tiny", "--data", str(tmp_path / "d"), "--runs", str(tmp_path / "r")]) == 0


def test_show_prints_commands_and_knobs(capsys):
    assert main(["show", "edgetrack-engine", "--tiny", "--set", "steps=7"]) == 0
    out = capsys.readouterr().out
    assert "--max-steps 7" in out and "not in the tiny variant: fit the motion weight and the lost threshold" in out
    assert main(["list"]) == 0
    listed = capsys.readouterr().out
    assert all(n in listed for n in RECIPES)


def test_unknown_names_are_one_line_errors(capsys):
    from track3d_train.cli import main as train_main

    assert train_main(["recipe", "show", "nope"]) == 2
    assert "unknown recipe 'nope'" in capsys.readouterr().err
    assert train_main(["recipe", "show", "siamfc", "--set", "speed=9"]) == 2
    assert "has no knob 'speed'" in capsys.readouterr().err
    assert train_main(["recipe", "show", "siamfc", "--set", "oops"]) == 2
    assert "name=value" in capsys.readouterr().err


def test_a_knob_value_of_the_wrong_type_is_refused_before_any_step(capsys):
    """`--set minutes=abc` had been taken as text and failed only when its step was reached."""
    from track3d_train.cli import main as train_main
    from track3d_train.recipes import RECIPES, knob_values

    r = RECIPES["edgetrack-engine"]
    name = next(k for k, v in r.knobs.items() if type(v) is int)
    assert train_main(["recipe", "show", r.name, "--set", f"{name}=abc"]) == 2
    assert f"knob '{name}'" in capsys.readouterr().err
    assert knob_values(r, overrides={name: "7"})[name] == 7 and type(knob_values(r, overrides={name: "7"})[name]) is int
    assert knob_values(r, overrides={name: "0.5"})[name] == 0.5       # e.g. minutes=0.5: the flag takes it
    text = next((k for k, v in r.knobs.items() if type(v) is str), None)
    if text is not None:
        assert knob_values(r, overrides={text: "anything"})[text] == "anything"


_STEP = """
import pathlib, signal, sys, time
out = pathlib.Path(sys.argv[1])
got = []
for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
    signal.signal(s, lambda signum, frame: got.append(signum))
(out / "ready").write_text("")
t0 = time.time()
while not got and time.time() - t0 < 60:   # never an orphan waiting forever when a test fails
    time.sleep(0.01)
time.sleep(1.0)                      # a checkpoint being written, longer than subprocess.call's 0.25 s
(out / "done").write_text(" ".join(str(int(s)) for s in got))
sys.exit(130)
"""


_DRIVER = """
import os, pathlib, signal, sys, threading, time
from track3d_train.interrupt import Interrupted
from track3d_train.recipes import _call

tmp, sent = pathlib.Path(sys.argv[1]), getattr(signal, sys.argv[2])


def unexpected(signum, frame):
    raise AssertionError(f"{signum} reached the driver, not the recipe")


old = {s: signal.signal(s, unexpected) for s in (signal.SIGTERM, signal.SIGHUP)}


def send():
    t0 = time.time()
    while not (tmp / "ready").exists() and time.time() - t0 < 60:
        time.sleep(0.01)
    os.kill(os.getpid(), sent)


threading.Thread(target=send, daemon=True).start()
try:
    _call([sys.executable, str(tmp / "step.py"), str(tmp)])
    print("not interrupted")
except Interrupted as e:
    print("interrupted", e.signum, e.exit_code, all(signal.getsignal(s) is unexpected for s in old))
print("plain", _call([sys.executable, "-c", "import sys; sys.exit(3)"]))
"""


@pytest.mark.parametrize("sent,passed", [("SIGINT", "SIGINT"), ("SIGTERM", "SIGTERM"), ("SIGHUP", "SIGTERM")])
def test_a_signal_to_the_recipe_reaches_the_running_step_once_and_the_recipe_waits_for_it(tmp_path, sent, passed):
    """Ctrl-C in `recipe run` had printed a traceback, and subprocess.call had killed the step
    (a training writing its checkpoint) 0.25 s after it; a SIGTERM to the recipe never reached
    the step. Now the step gets the signal once (in a session of its own a terminal's Ctrl-C
    does not reach it a second time) and the recipe ends after it, Interrupted. The recipe runs
    in a process of its own: a signal sent to the test runner itself had crashed the whole suite
    (exit 139) after the tests before it."""
    import signal
    import subprocess
    import sys

    (tmp_path / "step.py").write_text(_STEP)
    (tmp_path / "driver.py").write_text(_DRIVER)
    r = subprocess.run([sys.executable, str(tmp_path / "driver.py"), str(tmp_path), sent], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    signum = int(getattr(signal, sent))
    assert r.stdout.split() == ["interrupted", str(signum), str(128 + signum), "True", "plain", "3"], r.stdout
    assert (tmp_path / "done").read_text() == str(int(getattr(signal, passed)))   # once, and not killed
