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
    out = [("track3d", _parser())]
    try:
        from track3d_train.boxnet.cli import build_parser as bp
        from track3d_train.siamfc.cli import build_parser as sp
        out += [("boxnet", bp()), ("siamfc", sp())]
    except ImportError:
        pass
    try:
        from track3d_sim.cli import build_parser as simp
        from track3d_train.edgetrack.cli import build_parser as ep
        out += [("track3d-sim", simp()), ("edgetrack", ep())]
    except ImportError:
        pass
    return out


@pytest.mark.parametrize("name,parser", _parsers())
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


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.startswith("track3d ")
    pytest.importorskip("torch")
    from track3d_train.cli import main as train_main

    assert train_main(["--version"]) == 0 and capsys.readouterr().out.startswith("track3d-train ")


def test_checkpoint_mixups_are_one_line(tmp_path, capsys):
    torch = pytest.importorskip("torch")
    from track3d_train.cli import main as train_main

    siam, box, junk = tmp_path / "siam.pt", tmp_path / "box.pt", tmp_path / "junk.pt"
    torch.save({"config": {}, "model": {}}, siam)
    torch.save({"model_config": {}, "model": {}}, box)
    junk.write_text("not a checkpoint")
    assert train_main(["boxnet", "export", "--checkpoint", str(siam), "--out", str(tmp_path / "a.onnx")]) == 2
    _one_line(capsys, "is a SiamFC checkpoint", "track3d-train siamfc export")
    assert train_main(["siamfc", "export", "--ckpt", str(box), "--out", str(tmp_path / "s")]) == 2   # hidden alias
    _one_line(capsys, "is a A3BoxNet checkpoint", "track3d-train boxnet export")
    assert train_main(["boxnet", "export", "--ckpt", str(junk), "--out", str(tmp_path / "a.onnx")]) == 2
    _one_line(capsys, "not a PyTorch checkpoint")
    assert train_main(["boxnet", "export", "--out", str(tmp_path / "a.onnx")]) == 2
    _one_line(capsys, "--checkpoint")


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


def test_folder_kinds_are_named(tmp_path, capsys):
    from test_loop import make_synthetic_dataset

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


def test_gif_without_pillow_says_so(tmp_path, capsys, monkeypatch):
    import importlib.util

    from test_loop import make_synthetic_dataset

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
