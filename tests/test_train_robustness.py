"""Training-side robustness (a walkthrough's findings): checkpoints and exports are written whole
or not at all; a damaged --init-from, an --out that is a file or a folder, a cache that is
incomplete, --num-points beyond the cache are one line and leave no empty run folder; a resumed
run refuses another cache or other flags than its checkpoint's (the cache compared by its data,
not its path's spelling); a finished time-budgeted run stays finished; one trainer per run folder,
and a recipe's running step dies with the recipe. Tiny networks on tiny caches, seconds each."""
from __future__ import annotations

import os
import shutil

import pytest

torch = pytest.importorskip("torch")

from track3d.onnxmodel import MODELS_DIR  # noqa: E402
from track3d_train.cli import main as train_main  # noqa: E402

ET_TINY = dict(exemplar_size=128, instance_size=256, lost_instance_size=336, widths=(8, 16, 24, 32),
               feat_channels=32, head_channels=32, head_blocks=1)


class Killed(BaseException):
    """A kill in the middle of a write (as SIGKILL would: nothing after it runs)."""


def _one_line(capsys, *needles) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "error: " in err[0], err
    for n in needles:
        assert n in err[0], err
    return err[0]


def _files(folder) -> dict:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


# -- tiny caches ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def bx_caches(tiny_dataset, tmp_path_factory):
    """Two frustum caches of the same data, cut with other seeds (other jitters)."""
    from track3d_train.boxnet.data import prepare_split

    out = tmp_path_factory.mktemp("bx_robust")
    return [prepare_split(tiny_dataset, "train", out / f"train_s{s}.npz", jitters=1, max_points=128, min_points=8,
                          seed=s, progress=False) for s in (0, 1)]


@pytest.fixture(scope="module")
def et_caches(tmp_path_factory):
    from track3d_train.edgetrack.data import prepare

    root = tmp_path_factory.mktemp("et_robust")
    for s in (0, 1):
        prepare(root / f"cache{s}", synthetic=2, synthetic_frames=6, max_frames=12, max_background=6, seed=s,
                exemplar_size=128, instance_size=256, progress=False, pad=None)
    return [root / "cache0", root / "cache1"]


@pytest.fixture(scope="module")
def sf_caches(tmp_path_factory):
    from track3d_train.siamfc.data import build_cache, synthetic_sequences

    root = tmp_path_factory.mktemp("sf_robust")
    for s in (0, 1):
        build_cache(synthetic_sequences(2, frames=6, seed=s), root / f"cache{s}", max_frames=12, progress=False)
    return [root / "cache0", root / "cache1"]


def _bx_cfg(cache, out, **kw):
    from track3d_train.boxnet.train import TrainConfig

    return TrainConfig(**{**dict(train_cache=[str(cache)], out=str(out), num_points=32, width=0.25, epochs=1,
                                 batch=4, val_every=2, val_max=8, seed=0), **kw})


def _bx_run(cache, out, *extra, steps: int = 1):
    return ["boxnet", "train", "--cache", str(cache), "--out", str(out), "--num-points", "32", "--width", "0.25",
            "--batch", "4", "--epochs", "3", "--max-steps", str(steps), "--val-every", "0", "--quiet", *extra]


def _sf_cfg(width=0.125, variant="edge"):
    from track3d_train.siamfc.model import config_for

    return config_for(variant, width=width, train_instance_size=159)


ET_KW = dict(batch=2, val_every=100, val_sequences=1, val_pairs=8, log_every=1, progress=False)
SF_KW = dict(batch=2, log_every=1, progress=False)


# -- 1. best.pt written atomically ------------------------------------------------------------------
def test_a_kill_while_best_pt_is_written_keeps_the_previous_best(bx_caches, tmp_path, monkeypatch):
    """best.pt had been written with a direct torch.save: a kill mid-write left a 0-byte best.pt
    and the previous best was lost."""
    from track3d_train.boxnet import train as bt

    out = tmp_path / "run"
    assert "val" in bt.train(_bx_cfg(bx_caches[0], out), progress=False, log=lambda *_: None)["epochs"][0]
    before = (out / "best.pt").read_bytes()
    monkeypatch.setattr(bt, "_validate", lambda *a, **k: {"loss": 1.0, "AO_3d": 2.0, "AO_bev": 1.0, "ACE_3d": 0.0})

    def save(obj, f, *a, **k):   # part of the file, then the kill
        with open(f, "wb") as fh:
            fh.write(b"\x80partial")
        raise Killed

    monkeypatch.setattr(torch, "save", save)
    with pytest.raises(Killed):
        bt.train(_bx_cfg(bx_caches[0], out, epochs=2), progress=False, log=lambda *_: None)
    assert (out / "best.pt").read_bytes() == before
    monkeypatch.undo()
    assert torch.load(str(out / "best.pt"), weights_only=False)["epoch"] == 0
    assert torch.load(str(out / "last.pt"), weights_only=False)["epoch"] == 0


# -- 2. --init-from a damaged file ------------------------------------------------------------------
def _damaged(tmp_path, kind: str):
    p = tmp_path / {"onnx": "half.onnx"}.get(kind, f"{kind}.pt")
    if kind == "empty":
        p.write_bytes(b"")
    elif kind == "garbage":
        p.write_bytes(b"not a checkpoint\n" * 50)
    elif kind == "no-checkpoint":
        torch.save({"weights": [1, 2, 3]}, str(p))
    elif kind == "onnx":
        whole = (MODELS_DIR / "a3boxnet_narrow.onnx").read_bytes()
        p.write_bytes(whole[: len(whole) // 2])
    return p


@pytest.mark.parametrize("kind,says", [("empty", "is not a PyTorch checkpoint"),
                                       ("garbage", "is not a PyTorch checkpoint"),
                                       ("no-checkpoint", "is not an A3BoxNet checkpoint"),
                                       ("onnx", "not a complete ONNX file")])
def test_boxnet_init_from_a_damaged_file_is_one_line_and_leaves_no_run_folder(bx_caches, tmp_path, capsys,
                                                                            kind, says):
    bad = _damaged(tmp_path, kind)
    out = tmp_path / "run"
    assert train_main(_bx_run(bx_caches[0], out, "--init-from", str(bad))) == 2
    _one_line(capsys, str(bad), says)
    assert not out.exists()


def test_siamfc_and_edgetrack_init_from_a_damaged_file_leave_no_run_folder(sf_caches, et_caches, tmp_path, capsys):
    bad = _damaged(tmp_path, "garbage")
    assert train_main(["siamfc", "train", "--cache", str(sf_caches[0]), "--out", str(tmp_path / "sf"),
                       "--init-from", str(bad), "--max-steps", "1", "--quiet"]) == 2
    _one_line(capsys, "is not a PyTorch checkpoint")
    assert train_main(["edgetrack", "train", "--cache", str(et_caches[0]), "--out", str(tmp_path / "et"),
                       "--init-from", str(bad), "--max-steps", "1", "--quiet"]) == 2
    _one_line(capsys, "is not a PyTorch checkpoint")
    assert not (tmp_path / "sf").exists() and not (tmp_path / "et").exists()


# -- 3. exports: atomic, no silent overwrite, folders; train --out a file -----------------------------
def _tiny_nets():
    from track3d_train.boxnet.model import A3BoxNet, BoxNetConfig
    from track3d_train.edgetrack.model import EdgeTrack, EdgeTrackConfig
    from track3d_train.siamfc.model import SiamFC

    torch.manual_seed(0)
    return {"boxnet": A3BoxNet(BoxNetConfig(num_points=32, width=0.25)), "edgetrack": EdgeTrack(EdgeTrackConfig(**ET_TINY)),
            "siamfc": SiamFC(_sf_cfg())}


def _earlier_export(tmp_path, name):
    """(export module, tiny net, the export's target, the files it writes) of network `name`,
    those files already there holding b"the earlier export"."""
    import importlib

    mod = importlib.import_module(f"track3d_train.{name}.export")
    target = tmp_path / ("m.onnx" if name == "boxnet" else "m")
    files = [target] if name == "boxnet" else [tmp_path / f"m_{p}.onnx" for p in
                                               (("template", "search") if name == "edgetrack" else ("exemplar", "search"))]
    for f in files:
        f.write_bytes(b"the earlier export")
    return mod, _tiny_nets()[name], target, files


@pytest.mark.parametrize("name", ["boxnet", "edgetrack", "siamfc"])
def test_an_export_killed_midway_leaves_the_files_that_were_there(tmp_path, monkeypatch, name):
    """The exports wrote torch.onnx.export straight to the target, then saved over it to add the
    metadata: a kill in between left a model without metadata (or half a pair)."""
    mod, net, target, files = _earlier_export(tmp_path, name)
    real, calls = mod.attach_metadata, []

    def attach(path, meta):   # the last file's metadata: the kill
        calls.append(path)
        if len(calls) == len(files):
            raise Killed
        return real(path, meta)

    monkeypatch.setattr(mod, "attach_metadata", attach)
    with pytest.raises(Killed):
        mod.export_onnx(net, target)
    assert [f.read_bytes() for f in files] == [b"the earlier export"] * len(files)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f.name for f in files)   # no temporary left
    monkeypatch.setattr(mod, "attach_metadata", real)
    mod.export_onnx(net, target)
    from track3d.onnxmodel import OnnxModel
    assert all(OnnxModel(f, 1).meta["kind"] for f in files)


@pytest.mark.parametrize("name", ["boxnet", "edgetrack", "siamfc"])
def test_an_export_is_checked_before_it_replaces_anything(tmp_path, name):
    """The exports renamed their files into place, then ran the parity check: a kill in between
    left an unchecked model that the same command then refused to redo ('exists: pass --force'),
    and EdgeTrack's and SiamFC's checks only printed their differences. The check now runs on the
    temporaries: a failing one (or a kill during it) leaves the earlier files and no temporary."""
    mod, net, target, files = _earlier_export(tmp_path, name)
    seen = []

    def check(*temps):
        seen.extend(temps)
        assert all(t.is_file() and t not in files for t in temps)   # the written temporaries
        raise AssertionError("torch and onnxruntime differ")

    with pytest.raises(AssertionError, match="differ"):
        mod.export_onnx(net, target, check=check)
    assert len(seen) == len(files)
    assert [f.read_bytes() for f in files] == [b"the earlier export"] * len(files)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f.name for f in files)


def test_a_pair_exports_parity_beyond_float32_noise_stops_the_export():
    from track3d_train.onnx_meta import require_parity

    require_parity({"logit_max_abs": 2e-3, "logit_scale": 5.0}, ("logit",), "EdgeTrack")   # 4e-4 of it
    with pytest.raises(AssertionError, match="EdgeTrack logit: torch and onnxruntime differ by 0.01"):
        require_parity({"logit_max_abs": 1e-2, "logit_scale": 5.0}, ("logit",), "EdgeTrack")
    with pytest.raises(AssertionError):
        require_parity({"kernel_max_abs": float("nan")}, ("kernel",), "EdgeTrack")


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory):
    """A tiny checkpoint of each network, as its trainer writes it (not trained)."""
    nets = _tiny_nets()
    root = tmp_path_factory.mktemp("ckpts")
    torch.save({"model": nets["boxnet"].state_dict(), "model_config": nets["boxnet"].config.to_dict(),
                "train_config": {"batch": 4}, "history": {}, "epoch": 0, "step": 0}, str(root / "box.pt"))
    for name in ("edgetrack", "siamfc"):
        torch.save({"model": nets[name].state_dict(), "config": nets[name].cfg.to_dict(), "step": 0,
                    "train_data_hash": "0" * 64, "train_data": "tiny"}, str(root / f"{name}.pt"))
    return root


def test_export_refuses_an_existing_out_without_force_and_a_folder(checkpoints, tmp_path, capsys):
    box = ["boxnet", "export", "--checkpoint", str(checkpoints / "box.pt"), "--no-parity"]
    keep = tmp_path / "notes.onnx"
    keep.write_bytes(b"someone's file")
    assert train_main([*box, "--out", str(keep)]) == 2
    _one_line(capsys, f"{keep} exists: pass --force to overwrite it")
    assert keep.read_bytes() == b"someone's file"
    assert train_main([*box, "--out", str(tmp_path)]) == 2          # IsADirectoryError's traceback before
    _one_line(capsys, f"--out {tmp_path} is a folder")
    assert train_main([*box, "--out", str(keep), "--force"]) == 0
    assert keep.read_bytes() != b"someone's file"
    for name, part in (("edgetrack", "template"), ("siamfc", "exemplar")):
        run = [name, "export", "--checkpoint", str(checkpoints / f"{name}.pt")]
        (tmp_path / f"{name}_{part}.onnx").write_bytes(b"someone's file")
        assert train_main([*run, "--out", str(tmp_path / name)]) == 2
        _one_line(capsys, f"{name}_{part}.onnx exists: pass --force")
        assert (tmp_path / f"{name}_{part}.onnx").read_bytes() == b"someone's file"
        assert train_main([*run, "--out", str(tmp_path)]) == 2
        _one_line(capsys, "is a folder: give a path prefix")


def test_train_out_that_is_a_file_is_one_line(bx_caches, et_caches, sf_caches, tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_text("x")
    for argv in (_bx_run(bx_caches[0], afile),
                 ["edgetrack", "train", "--cache", str(et_caches[0]), "--out", str(afile), "--quiet"],
                 ["siamfc", "train", "--cache", str(sf_caches[0]), "--out", str(afile), "--quiet"]):
        assert train_main(argv) == 2            # FileExistsError's traceback before
        _one_line(capsys, f"--out {afile} is a file, not a run folder")
    assert afile.read_text() == "x"


# -- 4. a resumed run: the same data and flags --------------------------------------------------------
def test_boxnet_resume_compares_the_data_not_the_path(bx_caches, tmp_path, capsys):
    """The cache's PATH text had been compared: another spelling of the same file was refused and
    another file at the same path resumed in silence; other flags were taken in silence."""
    cache = tmp_path / "c.npz"
    shutil.copy(bx_caches[0], cache)
    out = tmp_path / "run"
    assert train_main(_bx_run(cache, out)) == 0
    capsys.readouterr()
    other_spelling = tmp_path / "sub" / ".." / "c.npz"
    (tmp_path / "sub").mkdir()
    assert train_main(_bx_run(other_spelling, out, steps=2)) == 0
    assert "resumed from" in capsys.readouterr().out
    shutil.copy(bx_caches[1], cache)             # another cache (other jitters) at the same path
    assert train_main(_bx_run(cache, out, steps=3)) == 2
    _one_line(capsys, "last.pt was trained on other data than", "start a new --out")
    shutil.copy(bx_caches[0], cache)
    assert train_main(_bx_run(cache, out, "--lr", "0.01", "--no-flip", steps=3)) == 2
    _one_line(capsys, "last.pt was trained with other flags than this run's", "--lr 0.001", "no --no-flip")
    assert torch.load(str(out / "last.pt"), weights_only=False)["step"] == 2


def test_edgetrack_resume_refuses_another_cache_and_other_flags(et_caches, tmp_path):
    from track3d_train.edgetrack.model import EdgeTrackConfig
    from track3d_train.edgetrack.train import train

    out = tmp_path / "run"
    train(EdgeTrackConfig(**ET_TINY), et_caches[0], out, steps=1, **ET_KW)
    with pytest.raises(ValueError, match="ckpt.pt was trained on other data than"):
        train(EdgeTrackConfig(**ET_TINY), et_caches[1], out, steps=2, **ET_KW)
    with pytest.raises(ValueError, match=r"other flags than this run's: resume with the same flags \(--batch 2, --seed 0\)"):
        train(EdgeTrackConfig(**ET_TINY), et_caches[0], out, steps=2, **{**ET_KW, "batch": 4}, seed=3)
    assert train(EdgeTrackConfig(**ET_TINY), et_caches[0], out, steps=2, **ET_KW)["step"] == 2


def test_siamfc_resume_and_init_from_refuse_another_network_cache_or_flags(sf_caches, tmp_path):
    """Another --variant or --width on resume, or --init-from a checkpoint of the other network,
    had ended in a size-mismatch traceback; another cache resumed in silence."""
    from track3d_train.siamfc.train import train

    out = tmp_path / "run"
    train(_sf_cfg(), sf_caches[0], out, steps=1, **SF_KW)
    with pytest.raises(ValueError, match=r"resume with the same flags \(--width 0.125\)"):
        train(_sf_cfg(width=0.25), sf_caches[0], out, steps=2, **SF_KW)
    with pytest.raises(ValueError, match=r"\(--variant edge\)"):
        train(_sf_cfg(variant="faithful"), sf_caches[0], out, steps=2, **SF_KW)
    with pytest.raises(ValueError, match="trained on other data than"):
        train(_sf_cfg(), sf_caches[1], out, steps=2, **SF_KW)
    with pytest.raises(ValueError, match=r"\(--lr-end 0.0001\)"):
        train(_sf_cfg(), sf_caches[0], out, steps=2, lr_end=1e-3, **SF_KW)
    with pytest.raises(ValueError, match="is a SiamFC of another network than this run's: pass --width 0.125"):
        train(_sf_cfg(width=0.25), sf_caches[0], tmp_path / "ft", steps=1, init_from=str(out / "ckpt.pt"), **SF_KW)
    assert not (tmp_path / "ft").exists()
    assert train(_sf_cfg(), sf_caches[0], out, steps=2, **SF_KW)["step"] == 2


# -- 5. a finished time-budgeted run stays finished -------------------------------------------------
@pytest.mark.parametrize("name", ["edgetrack", "siamfc"])
def test_a_finished_time_budgeted_run_stays_finished(et_caches, sf_caches, tmp_path, capsys, name):
    """`while step < steps:` checked the budget only after a step: each re-run of a finished run
    trained one more step."""
    if name == "edgetrack":
        from track3d_train.edgetrack.model import EdgeTrackConfig
        from track3d_train.edgetrack.train import train

        def run():
            return train(EdgeTrackConfig(**ET_TINY), et_caches[0], tmp_path / "r", steps=50, time_budget_s=1e-6,
                         **ET_KW)
    else:
        from track3d_train.siamfc.train import train

        def run():
            return train(_sf_cfg(), sf_caches[0], tmp_path / "r", steps=50, time_budget_s=1e-6, **SF_KW)
    first = run()
    assert first["step"] == 1 and first["stopped"] == "time budget"
    files = _files(tmp_path / "r")
    again = run()
    assert again["step"] == 1 and again["stopped"] == "time budget" and "the run is finished" in capsys.readouterr().out
    assert _files(tmp_path / "r") == files


# -- 6. --num-points ------------------------------------------------------------------------------
def test_num_points_beyond_the_cache_or_its_bound_is_refused(bx_caches, tmp_path, capsys):
    """More points than the cache stores had been taken silently (each frustum's points sampled
    twice over); --num-points 100000 ran until the kernel killed it (24 GB)."""
    out = tmp_path / "run"
    argv = _bx_run(bx_caches[0], out)
    at = argv.index("--num-points") + 1
    assert train_main(argv[:at] + ["256"] + argv[at + 1:]) == 2
    _one_line(capsys, "--num-points 256 is more than the 128 points the cache stores per frustum", "--max-points 256")
    assert not out.exists()
    with pytest.raises(SystemExit) as e:
        train_main(argv[:at] + ["100000"] + argv[at + 1:])
    assert e.value.code == 2 and "--num-points" in capsys.readouterr().err
    assert train_main(argv[:at] + ["128"] + argv[at + 1:]) == 0


# -- 7. an incomplete EdgeTrack cache --------------------------------------------------------------
def test_an_edgetrack_cache_without_its_background_is_incomplete(tmp_path, capsys, monkeypatch):
    """A prepare killed before bg.npy was written left a cache that trained with 0 background crops,
    in silence."""
    from track3d_train.edgetrack import data

    cache = tmp_path / "cache"

    def killed(*a, **k):
        raise Killed

    monkeypatch.setattr(data, "_background", killed)
    with pytest.raises(Killed):
        data.prepare(cache, synthetic=2, synthetic_frames=6, max_frames=12, progress=False, pad=None)
    monkeypatch.undo()
    run = ["edgetrack", "train", "--cache", str(cache), "--out", str(tmp_path / "run"), "--max-steps", "1",
           "--batch", "2", "--val-every", "100", "--quiet"]
    assert train_main(run) == 2
    _one_line(capsys, f"{cache} is an incomplete EdgeTrack cache (no background/bg.npy", "run `track3d-train "
              "edgetrack prepare` again")
    assert not (tmp_path / "run").exists()
    # a complete cache whose marker is gone (killed between the two files) is incomplete too; a new
    # prepare cleans what a killed one left
    data.prepare(cache, synthetic=2, synthetic_frames=6, max_frames=12, progress=False, pad=None)
    (cache / "background" / "bg.json").unlink()
    assert train_main(run) == 2
    _one_line(capsys, "no background/bg.json")
    for left in (cache / "target" / "crops.npy.tmp", cache / "background" / "bg.npy.tmp"):
        left.write_bytes(b"left by a killed prepare")
    data.prepare(cache, synthetic=2, synthetic_frames=6, max_frames=12, progress=False, pad=None)
    assert not list(cache.rglob("*.tmp"))
    assert train_main(run) == 0


# -- 9. help: required flags, defaults ---------------------------------------------------------------
def _action(parser, cmd: str, flag: str):
    import argparse

    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[cmd]
    return sub, next(a for a in sub._actions if flag in a.option_strings)


@pytest.mark.parametrize("module,cmd,flag", [
    ("siamfc", "prepare", "--out"), ("edgetrack", "prepare", "--out"), ("edgetrack", "train", "--out"),
    ("edgetrack", "export", "--out"), ("boxnet", "export", "--out"), ("siamfc", "train", "--cache"),
    ("boxnet", "train", "--cache"), ("edgetrack", "time", "--model")])
def test_required_flags_are_required(module, cmd, flag):
    import importlib

    _, a = _action(importlib.import_module(f"track3d_train.{module}.cli").build_parser(), cmd, flag)
    assert a.required


@pytest.mark.parametrize("module,cmd,flag", [
    ("siamfc", "export", "--instance-size"), ("siamfc", "export", "--scale-num"), ("siamfc", "export", "--scale-lr"),
    ("siamfc", "export", "--scale-step"), ("siamfc", "export", "--scale-penalty"),
    ("siamfc", "export", "--window-influence"), ("siamfc", "export", "--data-note"), ("siamfc", "train", "--init-from"),
    ("edgetrack", "export", "--data-note"), ("edgetrack", "export", "--cache"), ("edgetrack", "train", "--init-from")])
def test_flags_without_a_default_value_say_what_the_default_is(module, cmd, flag):
    import importlib

    sub, a = _action(importlib.import_module(f"track3d_train.{module}.cli").build_parser(), cmd, flag)
    # "default:" and what it is ("tracking default stored in the metadata" had passed for one)
    assert "default: " in sub.formatter_class(sub.prog)._get_help_string(a).lower(), a.help


# -- 10. one trainer per run folder; a recipe's step dies with the recipe --------------------------------
def test_a_second_trainer_on_the_same_run_folder_is_refused(sf_caches, bx_caches, tmp_path):
    from track3d_train.boxnet.train import train as bx_train
    from track3d_train.checkpoint import RunLock
    from track3d_train.siamfc.train import train as sf_train

    out = tmp_path / "run"
    out.mkdir()
    with RunLock() as running:      # a trainer at work in `out` (flock: per open file, so this process too)
        running.acquire(out)
        with pytest.raises(ValueError, match=f"another training is running in {out}"):
            sf_train(_sf_cfg(), sf_caches[0], out, steps=1, **SF_KW)
        with pytest.raises(ValueError, match="another training is running"):
            bx_train(_bx_cfg(bx_caches[0], out, max_steps=1), progress=False, log=lambda *_: None)
        assert not list(out.iterdir())
    assert sf_train(_sf_cfg(), sf_caches[0], out, steps=1, **SF_KW)["step"] == 1   # released: it runs


def test_a_file_system_that_cannot_lock_a_folder_trains_with_a_warning(tmp_path, monkeypatch):
    """On NFS flock is emulated with fcntl locks, which need a file open for writing: every training
    there had been refused as "another training is running" (a review)."""
    import errno
    import fcntl

    from track3d_train.checkpoint import RunLock

    def no_flock(fd, op):
        raise OSError(errno.EBADF, "Bad file descriptor")
    monkeypatch.setattr(fcntl, "flock", no_flock)
    with pytest.warns(RuntimeWarning, match="no lock against a second trainer"):
        with RunLock() as lock:
            lock.acquire(tmp_path)
            assert lock.fd is None


_CHILD = """
import os, pathlib, signal, sys, time
out = pathlib.Path(sys.argv[1])
signal.signal(signal.SIGTERM, lambda *a: ((out / "terminated").write_text("yes"), sys.exit(143)))
(out / "child.pid").write_text(str(os.getpid()))
t0 = time.time()
while time.time() - t0 < 60:   # never an orphan for long when the test fails
    time.sleep(0.02)
"""

_RECIPE = """
import sys
from track3d_train.recipes import _call
_call([sys.executable, sys.argv[1], sys.argv[2]])
"""


@pytest.mark.skipif(not os.sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_recipes_running_step_dies_with_the_recipe(tmp_path):
    """kill -9 of `recipe run` had left its running trainer alive (PPID 1)."""
    import signal
    import subprocess
    import sys
    import time

    (tmp_path / "child.py").write_text(_CHILD)
    (tmp_path / "recipe.py").write_text(_RECIPE)
    recipe = subprocess.Popen([sys.executable, str(tmp_path / "recipe.py"), str(tmp_path / "child.py"), str(tmp_path)])
    child = None
    try:
        t0 = time.time()
        while not (tmp_path / "child.pid").is_file() and time.time() - t0 < 60:
            time.sleep(0.02)
        child = int((tmp_path / "child.pid").read_text())
        recipe.send_signal(signal.SIGKILL)
        recipe.wait(timeout=30)
        t0 = time.time()
        while not (tmp_path / "terminated").is_file() and time.time() - t0 < 10:
            time.sleep(0.02)
        assert (tmp_path / "terminated").is_file(), "the step outlived the recipe"
    finally:
        if recipe.poll() is None:
            recipe.kill()
        if child is not None and not (tmp_path / "terminated").is_file():
            try:
                os.kill(child, signal.SIGKILL)
            except ProcessLookupError:
                pass


def test_a_second_sigterm_does_not_cut_the_checkpoint_short():
    """A recipe killed with kill -9 sends its step's death signal once per thread the orphan is
    handed to: two SIGTERMs had ended the training before its checkpoint (a review). A second
    Ctrl-C still stops at once."""
    import signal as S

    from track3d_train.interrupt import StopOnSignal

    stop = StopOnSignal()
    stop._handle(S.SIGTERM, None)
    stop._handle(S.SIGTERM, None)               # ignored: the checkpoint is still written
    assert stop.signum == S.SIGTERM
    with pytest.raises(KeyboardInterrupt):
        stop._handle(S.SIGINT, None)
    ctrl_c = StopOnSignal()
    ctrl_c._handle(S.SIGINT, None)
    with pytest.raises(KeyboardInterrupt):
        ctrl_c._handle(S.SIGINT, None)
