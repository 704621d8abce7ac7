"""CLI conventions: one-line errors (exit 2), --version, help with defaults on every flag,
hidden aliases, checkpoint mix-ups, shipped models never overwritten, folder-kind messages,
extras named when missing."""
from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from track3d.cli import _parser, main

ROOT = Path(__file__).resolve().parents[1]


def _one_line(capsys, *needles):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for n in needles:
        assert n in err[0], err
    return err[0]


def _walk(parser):
    yield parser
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            for sub in a.choices.values():
                yield from _walk(sub)


def _parsers():
    """Every parser of the three commands: track3d, track3d-sim and each `track3d-train`
    command (taken from its COMMANDS table, so a new one cannot be left out)."""
    out = [("track3d", _parser())]
    try:
        from track3d_sim.cli import build_parser as simp
        out.append(("track3d-sim", simp()))
    except ImportError:
        pass
    try:
        import importlib

        import torch  # noqa: F401  (the train extra)
        from track3d_train.cli import COMMANDS
        out += [(f"track3d-train {n}", importlib.import_module(m).build_parser()) for n, (m, _) in COMMANDS.items()]
    except ImportError:
        pass
    return out


BENCH_SCRIPTS = sorted(p.name for p in (ROOT / "benchmarks").glob("*.py"))


def _bench_parsers():
    """Every benchmark script's parser (each has build_parser(); the scripts import as modules:
    pyproject's pytest pythonpath), skipping those whose extra is not installed."""
    import importlib

    out = []
    for name in BENCH_SCRIPTS:
        try:
            out.append((name, importlib.import_module(name[:-3]).build_parser()))
        except ImportError:
            pass
    return out


def _all_parsers():
    return _parsers() + _bench_parsers()


def _visible_flags(parser):
    for p in _walk(parser):
        for a in p._actions:
            if a.option_strings and a.help != argparse.SUPPRESS:
                yield p.prog, a


def test_every_command_of_the_three_clis_is_covered():
    names = [n for n, _ in _parsers()]
    pytest.importorskip("track3d_sim")
    pytest.importorskip("torch")
    assert names == ["track3d", "track3d-sim", "track3d-train boxnet", "track3d-train siamfc",
                     "track3d-train quantize", "track3d-train edgetrack", "track3d-train recipe"]
    progs = {p.prog for _, parser in _parsers() for p in _walk(parser)}
    for sub in ("track3d track", "track3d bench", "track3d-sim generate", "track3d-sim shapes",
                "track3d-train edgetrack export", "track3d-train quantize"):
        assert sub in progs


@pytest.mark.parametrize("name,parser", _all_parsers())
def test_every_flag_has_help_and_shows_its_default(name, parser):
    for p in _walk(parser):
        text = p.format_help()
        for a in p._actions:
            if not a.option_strings or a.help == argparse.SUPPRESS or isinstance(a, (argparse._HelpAction,
                                                                                   argparse._VersionAction)):
                continue
            assert a.help, f"{name} {p.prog} {a.option_strings} has no help"
            if a.default not in (None, False, [], argparse.SUPPRESS):
                h = p.formatter_class(p.prog)._get_help_string(a)
                assert "default" in h.lower(), f"{name} {p.prog} {a.option_strings}: default not shown"
        assert "==SUPPRESS==" not in text


# One name per flag across the CLIs; the older spellings parse (scripts keep working) but are
# never shown.
OLD_SPELLINGS = {"--ckpt": "--checkpoint", "--steps": "--max-steps", "--no-progress": "--quiet",
                 "--max-minutes": "--time-budget-min", "--stride": "--frame-step", "--max-seqs": "--max-sequences"}


@pytest.mark.parametrize("name,parser", _parsers())
def test_every_sub_command_says_what_it_does_in_its_own_help(name, parser):
    for p in _walk(parser):
        if p is not parser:
            assert p.description, f"{p.prog} --help has no description"


@pytest.mark.parametrize("name,parser", _all_parsers())
def test_every_name_a_help_text_points_to_exists(name, parser):
    # help that says where a default lives ("track3d.sensor_options.section_limbs_for") must name
    # something that is there: the option tables moved out of track3d.tracker and one help text
    # still named the old place
    import importlib
    import re

    for prog, a in _visible_flags(parser):
        text = a.help or ""
        for m in re.finditer(r"\btrack3d(?:\.[A-Za-z_][A-Za-z_0-9]*)+", text):
            ref = m.group(0)
            if "group" in text[max(0, m.start() - 30):m.start()]:
                continue   # an entry-point group's name ("the groups track3d.trackers / ..."), not a module
            parts = ref.split(".")
            for cut in range(len(parts), 0, -1):   # the longest importable module, then attributes
                try:
                    obj = importlib.import_module(".".join(parts[:cut]))
                    break
                except ImportError:
                    continue
            for attr in parts[cut:]:
                assert hasattr(obj, attr), f"{prog} {a.option_strings[0]}: {ref} does not exist"
                obj = getattr(obj, attr)


@pytest.mark.parametrize("name,parser", _all_parsers())
def test_no_command_shows_an_old_flag_spelling(name, parser):
    shown = [(prog, o) for prog, a in _visible_flags(parser) for o in a.option_strings if o in OLD_SPELLINGS]
    assert not shown, f"{name}: {shown} (show {[OLD_SPELLINGS[o] for _, o in shown]}; keep the old as hidden_alias)"


@pytest.mark.parametrize("cli,argv,dest,value", [
    ("track3d-sim", ["generate", "--out", "x", "--no-progress"], "no_progress", True),
    ("track3d-sim", ["generate", "--out", "x", "--quiet"], "no_progress", True),
    ("track3d-sim", ["shapes", "--out", "x.png", "--no-progress"], "no_progress", True),
    ("track3d-train edgetrack", ["train", "--cache", "c", "--out", "o", "--steps", "7"], "steps", 7),
    ("track3d-train edgetrack", ["train", "--cache", "c", "--out", "o", "--max-steps", "7"], "steps", 7),
    ("track3d-train edgetrack", ["train", "--cache", "c", "--out", "o", "--no-progress"], "quiet", True),
    ("track3d-train edgetrack", ["prepare", "--out", "o", "--no-progress"], "quiet", True),
    ("track3d-train edgetrack", ["export", "--ckpt", "k.pt", "--out", "o"], "checkpoint", "k.pt"),
    ("track3d-train boxnet", ["train", "--cache", "c", "--max-minutes", "3"], "max_minutes", 3.0),
    ("track3d-train boxnet", ["train", "--cache", "c", "--time-budget-min", "3"], "max_minutes", 3.0),
    ("track3d-train siamfc", ["prepare", "--out", "o", "--stride", "2"], "stride", 2),
    ("track3d-train siamfc", ["prepare", "--out", "o", "--frame-step", "2"], "stride", 2),
    ("track3d-train siamfc", ["eval", "--model", "m", "--data", "d", "--max-seqs", "2"], "max_sequences", 2),
    ("track3d-train siamfc", ["eval", "--model", "m", "--data", "d", "--max-sequences", "2"], "max_sequences", 2),
    ("track3d-train edgetrack", ["eval", "--data", "d", "--max-seqs", "2"], "max_sequences", 2),
    ("track3d-train edgetrack", ["eval", "--data", "d", "--max-sequences", "2"], "max_sequences", 2),
    ("track3d-train boxnet", ["eval", "--model", "m", "--cache", "c", "--json", "r.json"], "out", "r.json"),
    ("track3d-train boxnet", ["eval", "--model", "m", "--cache", "c", "--out", "r.json"], "out", "r.json"),
    ("bench_boxnet.py", ["--cache", "c", "--ckpt", "k.pt"], "checkpoint", "k.pt"),
    ("bench_boxnet.py", ["--cache", "c", "--checkpoint", "k.pt"], "checkpoint", "k.pt"),
    ("bench_2d.py", ["--max-seqs", "3"], "max_sequences", 3),
    ("bench_table2.py", ["--data", "d", "--max-seqs", "3"], "max_sequences", 3),
])
def test_old_and_new_spellings_parse_alike(cli, argv, dest, value):
    parsers = dict(_all_parsers())
    if cli not in parsers:
        pytest.skip(f"{cli} not installed")
    assert getattr(parsers[cli].parse_args(argv), dest) == value


@pytest.mark.parametrize("name,parser", _all_parsers())
def test_a_command_line_mistake_is_one_line(name, parser, capsys):
    with pytest.raises(SystemExit) as e:
        parser.parse_args(["--no-such-flag"])
    assert e.value.code == 2
    line = _one_line(capsys, "error: ", "--help)")
    assert "usage:" not in line


def test_every_benchmark_script_follows_the_conventions():
    """Each script builds its parser with build_parser() (track3d.argparsing.ArgumentParser: a
    mistake is one line) and runs main() through run_main (a user's error is one line, exit 2)."""
    import ast

    from track3d.argparsing import ArgumentParser

    assert len(BENCH_SCRIPTS) >= 10
    for name in BENCH_SCRIPTS:
        tree = ast.parse((ROOT / "benchmarks" / name).read_text())
        funcs = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
        assert {"build_parser", "main"} <= funcs, name
        guard = [n for n in tree.body if isinstance(n, ast.If) and "__main__" in ast.unparse(n.test)]
        assert guard and "run_main(main" in ast.unparse(guard[0]), f"{name}: __main__ must call run_main(main, ...)"
    for name, parser in _bench_parsers():
        assert isinstance(parser, ArgumentParser), name


@pytest.mark.parametrize("script,argv", [
    ("bench_latency.py", ["--data", "no/such/dataset"]),      # ended in a DatasetError traceback
    ("bench_precision.py", ["--data", "no/such/dataset", "--no-speed", "--accuracy-data", "no/such/dataset"]),
    ("bench_boxnet.py", ["--cache", "no/such/cache.npz", "--no-speed"]),
    ("bench_latency.py", ["--data", "d", "--frames", "0"]),
    ("bench_accumulation.py", ["--data", "no/such/dataset"]),
])
def test_benchmark_mistakes_are_one_line(script, argv, tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *argv], capture_output=True, text=True,
                       timeout=300, cwd=tmp_path)
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and f"{script}: error: " in err[0], r.stderr[-2000:]


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.startswith("track3d ")
    pytest.importorskip("torch")
    from track3d_train.cli import main as train_main

    assert train_main(["--version"]) == 0 and capsys.readouterr().out.startswith("track3d-train ")
    pytest.importorskip("track3d_sim")
    from track3d_sim.cli import main as sim_main

    with pytest.raises(SystemExit) as e:
        sim_main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.startswith("track3d-sim ")


def _checkpoints(tmp_path, torch):
    """One checkpoint file per network, with the config each trainer really writes (SiamFC's
    and EdgeTrack's both sit under "config")."""
    from track3d_train.edgetrack.model import EdgeTrackConfig
    from track3d_train.siamfc.model import SiamFCConfig

    ck = {"siam.pt": {"config": SiamFCConfig().to_dict(), "model": {}},
          "edge.pt": {"config": EdgeTrackConfig().to_dict(), "model": {}},
          "box.pt": {"model_config": {}, "model": {}}}
    for name, d in ck.items():
        torch.save(d, tmp_path / name)
    return [tmp_path / n for n in ck]


def test_checkpoint_mixups_are_one_line(tmp_path, capsys):
    torch = pytest.importorskip("torch")
    from track3d_train.cli import main as train_main

    siam, edge, box = _checkpoints(tmp_path, torch)
    junk = tmp_path / "junk.pt"
    junk.write_text("not a checkpoint")
    assert train_main(["boxnet", "export", "--checkpoint", str(siam), "--out", str(tmp_path / "a.onnx")]) == 2
    _one_line(capsys, "is a SiamFC checkpoint", "track3d-train siamfc export")
    assert train_main(["siamfc", "export", "--ckpt", str(box), "--out", str(tmp_path / "s")]) == 2   # hidden alias
    _one_line(capsys, "is an A3BoxNet checkpoint", "track3d-train boxnet export")
    assert train_main(["boxnet", "export", "--ckpt", str(junk), "--out", str(tmp_path / "a.onnx")]) == 2
    _one_line(capsys, "not a PyTorch checkpoint")
    assert train_main(["boxnet", "export", "--out", str(tmp_path / "a.onnx")]) == 2
    _one_line(capsys, "--checkpoint")
    # EdgeTrack's exporter used to end in a KeyError (A3BoxNet) or a state-dict RuntimeError (SiamFC)
    assert train_main(["edgetrack", "export", "--checkpoint", str(siam), "--out", str(tmp_path / "e")]) == 2
    _one_line(capsys, "is a SiamFC checkpoint, not an EdgeTrack one", "track3d-train siamfc export")
    assert train_main(["edgetrack", "export", "--ckpt", str(box), "--out", str(tmp_path / "e")]) == 2
    _one_line(capsys, "is an A3BoxNet checkpoint", "track3d-train boxnet export")
    assert train_main(["siamfc", "export", "--checkpoint", str(edge), "--out", str(tmp_path / "s")]) == 2
    _one_line(capsys, "is an EdgeTrack checkpoint", "track3d-train edgetrack export")
    assert train_main(["edgetrack", "export", "--out", str(tmp_path / "e")]) == 2
    _one_line(capsys, "--checkpoint")
    assert not list(tmp_path.glob("*.onnx"))


def test_export_never_overwrites_a_shipped_model(tmp_path, capsys):
    torch = pytest.importorskip("torch")
    from track3d.onnxmodel import MODELS_DIR
    from track3d_train.cli import main as train_main

    box = tmp_path / "box.pt"
    torch.save({"model_config": {}, "model": {}}, box)
    before = (MODELS_DIR / "a3boxnet.onnx").read_bytes()
    assert train_main(["boxnet", "export", "--checkpoint", str(box), "--out", str(MODELS_DIR / "a3boxnet.onnx")]) == 2
    _one_line(capsys, "shipped model", "--force")
    assert train_main(["siamfc", "export", "--checkpoint", str(box), "--out", str(MODELS_DIR / "siamfc_edge")]) == 2
    _one_line(capsys, "shipped model")
    assert (MODELS_DIR / "a3boxnet.onnx").read_bytes() == before


@pytest.mark.parametrize("argv,stem", [
    (["edgetrack", "export", "--checkpoint", "{edge}", "--out", "{models}/edgetrack"], "edgetrack_template.onnx"),
    (["quantize", "--data", "{data}"], "a3boxnet_int8.onnx"),   # the default --out-dir is the shipped folder
    (["quantize", "--data", "{data}", "--models", "a3boxnet", "--out-dir", "{models}"], "a3boxnet_int8.onnx"),
])
def test_edgetrack_export_and_quantize_never_overwrite_a_shipped_model(tmp_path, capsys, argv, stem):
    torch = pytest.importorskip("torch")
    from track3d.onnxmodel import MODELS_DIR
    from track3d_train.cli import main as train_main

    _, edge, _ = _checkpoints(tmp_path, torch)
    if not (MODELS_DIR / stem).is_file():
        pytest.skip(f"{stem} is not shipped in this checkout")
    before = {p.name: p.stat().st_mtime_ns for p in MODELS_DIR.iterdir()}
    fill = {"edge": str(edge), "models": str(MODELS_DIR), "data": str(tmp_path / "no-data")}
    assert train_main([a.format(**fill) for a in argv]) == 2
    _one_line(capsys, f"{stem} is a shipped model", "--force")
    assert {p.name: p.stat().st_mtime_ns for p in MODELS_DIR.iterdir()} == before


def test_folder_kinds_are_named(tmp_path, capsys):
    from track3d.synthetic import make_synthetic_dataset

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 3})
    seq = next(p for p in (root / "test").iterdir() if p.is_dir())
    assert main(["track", "--data", str(seq)]) == 2
    _one_line(capsys, "is a sequence folder", f"--sequence {seq.name}")
    assert main(["track", "--data", str(root / "test")]) == 2
    _one_line(capsys, "is a split folder", "--split test")
    got = tmp_path / "got10k"
    (got / "GOT-10k_Val_000001").mkdir(parents=True)
    (got / "GOT-10k_Val_000001" / "groundtruth.txt").write_text("1,2,3,4\n")
    (got / "list.txt").write_text("GOT-10k_Val_000001\n")
    assert main(["track", "--data", str(got)]) == 2
    _one_line(capsys, "GOT-10k")


@pytest.mark.parametrize("argv,needles", [
    # a number the estimator checks itself: named, never blamed on the shipped model
    (["--estimator", "a3boxnet", "--estimator-option", "num_points=abc"], ["num_points must be an integer"]),
    (["--estimator", "a3boxnet", "--estimator-option", "threads=abc"], ["threads must be an integer"]),
    (["--estimator", "a3boxnet", "--estimator-option", "num_points=0"], ["num_points must be an integer >= 1"]),
    # a value refused in words that do not name it: the options given are named
    (["--tracker", "siamfc-edge", "--tracker-option", "window_influence=abc"],
     ["could not convert", "(given: --tracker-option window_influence=abc)"]),
    # only what the user typed: not the precision the command passes on to every network
    (["--tracker", "siamfc-edge", "--precision", "fp32", "--tracker-option", "window_influence=abc"],
     ["(given: --tracker-option window_influence=abc)"]),
])
def test_a_bad_option_value_is_named(tmp_path, capsys, argv, needles):
    from track3d.synthetic import make_synthetic_dataset

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 3})
    assert main(["track", "--data", str(root), "--results", str(tmp_path / "r"), "--quiet", *argv]) == 2
    line = _one_line(capsys, *needles)
    assert "metadata is incomplete" not in line


def test_an_unknown_flag_points_to_its_sub_commands_help(capsys):
    # argparse reports it from the top parser: `track3d track --trakcer kcf` had pointed to
    # `track3d --help`, which does not list track's flags
    for argv, needles in [(["track", "--data", "x", "--trakcer", "kcf"],
                           ["unrecognized arguments: --trakcer kcf", "(see track3d track --help)"]),
                          (["trackers", "--bogus"], ["(see track3d trackers --help)"])]:
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 2
        _one_line(capsys, *needles)


def test_what_is_not_a_dataset_is_named(tmp_path, capsys):
    # each had said "dataset.json is missing (generate one with ...)", which for a file or a
    # folder of other things is a command that fails, and for a killed generate the wrong advice
    from track3d.dataset import GENERATE_RUN_FILE

    (tmp_path / "afile.txt").write_text("x")
    (tmp_path / "empty").mkdir()
    (tmp_path / "other" / "test").mkdir(parents=True)
    (tmp_path / "unfinished").mkdir()
    (tmp_path / "unfinished" / GENERATE_RUN_FILE).write_text("{}")
    for name, needles in [("afile.txt", ["is a file, not a folder"]),
                          ("empty", ["the folder is empty", "track3d-sim generate --out"]),
                          ("other", ["holds other things"]),
                          ("unfinished", ["did not finish", "run the same command again"])]:
        assert main(["track", "--data", str(tmp_path / name)]) == 2
        line = _one_line(capsys, *needles)
        if name in ("afile.txt", "other", "unfinished"):
            assert "generate one with" not in line


def test_gif_without_pillow_says_so(tmp_path, capsys, monkeypatch):
    import importlib.util

    from track3d.synthetic import make_synthetic_dataset

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 3})
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda n, *a: None if n == "PIL" else real(n, *a))
    assert main(["track", "--data", str(root), "--video", "gif", "--results", str(tmp_path / "r")]) == 2
    _one_line(capsys, "needs pillow", "track3d[plot]")
    assert main(["track", "--data", str(root), "--results", str(tmp_path / "r"), "--no-progress"]) == 0  # auto: mp4
    assert list((tmp_path / "r").rglob("*_overlay.mp4"))


def test_demo_without_the_sim_extra_names_it(tmp_path, capsys, monkeypatch):
    pytest.importorskip("track3d_sim")
    from track3d_sim import demo
    from track3d_sim.cli import main as sim_main

    monkeypatch.setattr(demo, "missing_demo_modules", lambda: ["tqdm", "trimesh"])
    assert sim_main(["demo", "--out", str(tmp_path / "d")]) == 2
    _one_line(capsys, "pip install 'track3d[sim]'", "tqdm")


def test_benchmark_scripts_missing_data_is_one_line(tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_fps.py"), "--data", str(tmp_path / "no")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "no dataset" in r.stderr


@pytest.mark.parametrize("cli,argv,module,extra", [
    ("track3d-sim", ["generate", "--preset", "tiny", "--out", "{tmp}/g"], "tqdm", "sim"),
    ("track3d-sim", ["shapes", "--out", "{tmp}/s.png", "--count", "1"], "PIL", "sim"),
    ("track3d-sim", ["stats", "{data}", "--out", "{tmp}/s.png"], "matplotlib", "sim"),
    ("track3d-train", ["boxnet", "export", "--checkpoint", "{tmp}/x.pt", "--out", "{tmp}/a.onnx"], "torch", "train"),
    ("track3d-train", ["boxnet", "train", "--cache", "{tmp}/c.npz", "--out", "{tmp}/run"], "torch", "train"),
])
def test_a_missing_extra_is_named_not_a_traceback(tmp_path, capsys, monkeypatch, cli, argv, module, extra):
    """The base install has all three commands; without the extras they used to end in a
    ModuleNotFoundError traceback (tqdm, torch, PIL, matplotlib)."""
    pytest.importorskip("track3d_sim")
    pytest.importorskip("torch")
    from track3d.synthetic import make_synthetic_dataset
    from track3d_sim.cli import main as sim_main
    from track3d_train.cli import main as train_main

    data = make_synthetic_dataset(tmp_path / "ds", {"a": 3})
    monkeypatch.setitem(sys.modules, module, None)   # `import module` now raises ModuleNotFoundError
    run = sim_main if cli == "track3d-sim" else train_main
    assert run([a.format(tmp=tmp_path, data=data) for a in argv]) == 2
    _one_line(capsys, f"pip install 'track3d[{extra}]'", f"(missing: {module})")


def test_a_missing_module_of_no_extra_keeps_its_traceback(monkeypatch):
    from track3d.argparsing import missing_extra

    e = ModuleNotFoundError("No module named 'track3d_nonexistent'", name="track3d_nonexistent")
    assert missing_extra(e, {"tqdm": "sim"}) is None
    assert "track3d[sim]" in missing_extra(ModuleNotFoundError("x", name="tqdm.auto"), {"tqdm": "sim"})


def test_every_number_of_the_training_commands_has_bounds():
    """A plain int / float flag takes 0, -5 or nan: boxnet prepare --jitters -1 wrote a cache,
    train --batch 0 ended in a ZeroDivisionError, --threads 0 in torch's RuntimeError; the eval
    sub-commands too (siamfc eval --scale-num 0, --threads 0)."""
    pytest.importorskip("torch")
    plain = [(p.prog, a.option_strings) for name, parser in _parsers() if name.startswith("track3d-train")
             for p in _walk(parser)
             for a in p._actions if a.option_strings and a.type in (int, float)]
    assert not plain, f"give these a track3d.argparsing.bounded type: {plain}"


@pytest.mark.parametrize("argv", [
    ["boxnet", "prepare", "--data", "d", "--jitters", "-1"],          # wrote a cache named j-1
    ["boxnet", "prepare", "--data", "d", "--max-points", "0"],        # wrote empty frustums
    ["boxnet", "prepare", "--data", "d", "--frame-step", "0"],        # range() arg 3 must not be zero
    ["boxnet", "train", "--cache", "c", "--batch", "0"],              # ZeroDivisionError
    ["boxnet", "train", "--cache", "c", "--threads", "0"],            # torch RuntimeError traceback
    ["boxnet", "train", "--cache", "c", "--epochs", "0"],             # "done: 0 epochs", exit 0
    ["boxnet", "train", "--cache", "c", "--lr", "nan"],
    ["siamfc", "prepare", "--out", "o", "--frame-step", "0"],
    ["siamfc", "train", "--cache", "c", "--out", "o", "--steps", "0"],
    ["siamfc", "export", "--out", "o", "--scale-penalty", "2"],
    ["edgetrack", "prepare", "--out", "o", "--synthetic", "-2"],      # an empty cache, exit 0
    ["edgetrack", "train", "--cache", "c", "--out", "o", "--val-every", "0"],
    ["edgetrack", "export", "--out", "o", "--instance-size", "-5"],   # written into the model's metadata
    ["edgetrack", "time", "--model", "m", "--repeats", "2"],          # median of an empty list
    ["quantize", "--data", "d", "--samples", "0"],
    ["siamfc", "eval", "--model", "m", "--data", "d", "--scale-num", "0"],   # the eval commands took any number
    ["edgetrack", "eval", "--data", "d", "--threads", "0"],
    ["boxnet", "eval", "--model", "m", "--cache", "c", "--num-points", "-5"],
    ["boxnet", "prepare", "--data", "d", "--seed", "-1"],
])
def test_bad_numbers_of_the_training_commands_are_one_line(argv, capsys, tmp_path, monkeypatch):
    pytest.importorskip("torch")
    monkeypatch.chdir(tmp_path)       # the relative paths above: a regression writes there, not here
    from track3d_train.cli import main as train_main

    with pytest.raises(SystemExit) as e:
        train_main(argv)
    assert e.value.code == 2
    _one_line(capsys, "error: argument", "expected ")


def _script_commands(text: str):
    """(command, argv) of every track3d-sim / track3d-train call in a shell script: lines
    joined at backslashes, shell variables given a dummy value, redirections dropped."""
    import re
    import shlex

    text = re.sub(r"\\\n\s*", " ", text)
    for line in text.splitlines():
        m = re.search(r'"\$BIN/(track3d-sim|track3d-train)"(.*)', line)
        if not m:
            continue
        rest = re.sub(r'"\$@"', "", m.group(2))          # the caller's extra flags
        rest = re.sub(r'"?\$\(\([^)]*\)\)"?|"?\$\{CACHES\[@\]\}"?|"?\$\{\w+(:-[^}]*)?\}"?|\$\w+', "1", rest)
        words = shlex.split(re.split(r"\s(?:>>?|2>&1|&|;|\|\|)(?:\s|$)", " " + rest)[0])
        yield m.group(1), [w for w in words if w]


def test_the_scripts_in_export_scripts_parse():
    """The scripts and the training recipes keep working with the renamed flags (and use the shown
    spellings)."""
    pytest.importorskip("torch")
    pytest.importorskip("track3d_sim")
    parsers = dict(_parsers())
    seen = 0
    from track3d_train.recipes import RECIPES, commands

    sources = [(script.name, _script_commands(script.read_text()))
               for script in sorted((ROOT / "export" / "scripts").glob("*.sh"))]
    sources += [(f"recipe {name}", [(argv[0], argv[1:]) for _, argv, _ in commands(r, "d", "r")])
                for name, r in RECIPES.items()]
    for where, cmds in sources:
        for cmd, argv in cmds:
            argv = list(argv)
            parser = parsers["track3d-sim"] if cmd == "track3d-sim" else parsers[f"track3d-train {argv.pop(0)}"]
            parser.parse_args(argv)          # exits 2 on an unknown flag or a bad value
            old = [w for w in argv if w in OLD_SPELLINGS]
            assert not old, f"{where}: {cmd} {' '.join(argv)} uses the old spelling(s) {old}"
            seen += 1
    assert seen >= 20


@pytest.mark.parametrize("name,parser", _all_parsers())
def test_every_threads_flag_refuses_a_count_no_machine_runs(name, parser):
    """`--threads 99999` had onnxruntime start 99,999 threads a session: it took every process
    slot of the machine (nothing else could fork) before failing. Every --threads takes 1 to
    track3d.threads.max_threads() (THREADS_PER_CPU per CPU)."""
    from track3d.threads import max_threads

    for p in _walk(parser):
        for a in p._actions:
            if "--threads" not in a.option_strings:
                continue
            assert a.type("1") == 1 and a.type(str(max_threads())) == max_threads()
            for bad in ("0", "99999", str(max_threads() + 1), "x"):
                with pytest.raises(argparse.ArgumentTypeError, match="expected an integer from 1 to"):
                    a.type(bad)


def test_the_api_refuses_a_thread_count_no_machine_runs():
    from track3d.camera import Camera
    from track3d.onnxmodel import OnnxModel, shipped_model
    from track3d.threads import max_threads
    from track3d.tracker import Track3D

    cam = Camera.from_fov(320, 240, 45.0)
    for bad in (0, max_threads() + 1, 99999, 2.5, float("inf"), float("nan"), "2"):
        with pytest.raises(ValueError, match="threads must be an integer from 1 to"):
            Track3D.from_default(cam, threads=bad)
    with pytest.raises(ValueError, match="threads must be"):
        OnnxModel(shipped_model("a3boxnet.onnx"), threads=99999)
    # every way a count reaches an engine (a review: open_session took 0 and 2.7 for OpenVINO)
    from track3d.onnxmodel import open_session
    for engine in ("onnxruntime", "openvino"):
        for bad in (0, 2.7, float("inf")):
            with pytest.raises(ValueError, match="threads must be"):
                open_session(shipped_model("a3boxnet.onnx"), bad, engine)
