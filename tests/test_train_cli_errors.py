"""`track3d-train`'s user-facing errors and help (an audit's findings): a path given as a cache that
is not one is one `error:` line naming the command that makes the right cache (never numpy's or
zipfile's traceback, nor numpy's hint to load it "unsafely"); an eval report is valid JSON (a
missing number is null); every flag's help says its default; the top-level help lists each
command once; the edgetrack help's example keeps its line continuation."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from track3d.onnxmodel import MODELS_DIR  # noqa: E402
from track3d_train.cli import COMMANDS  # noqa: E402
from track3d_train.cli import main as train_main  # noqa: E402

BOXNET_MODEL = str(MODELS_DIR / "a3boxnet_narrow.onnx")


def _one_line(capsys, *needles) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "error: " in err[0] and "allow_pickle" not in err[0], err
    for n in needles:
        assert n in err[0], err
    return err[0]


def _not_a_frustum_cache(tmp_path, kind: str):
    """A path that is not a frustum cache, of one kind the audit found."""
    p = tmp_path / f"{kind}.npz"
    if kind == "empty":
        p.write_bytes(b"")
    elif kind == "truncated":
        np.savez(p, points=np.zeros((500, 3), np.float32), offsets=np.arange(3))
        p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    elif kind == "no-info":
        np.savez(p, a=np.zeros(3))
    elif kind == "folder":
        p.mkdir()
    elif kind == "garbage":
        p.write_bytes(b"not a cache at all\n" * 20)
    return p


KINDS = {"empty": "an empty file", "truncated": "not a complete .npz archive",
         "no-info": "without info", "folder": "a folder", "garbage": "not a complete .npz archive"}


@pytest.mark.parametrize("kind", list(KINDS))
def test_boxnet_eval_and_train_name_a_file_that_is_not_a_frustum_cache(tmp_path, capsys, kind):
    bad = _not_a_frustum_cache(tmp_path, kind)
    assert train_main(["boxnet", "eval", "--model", BOXNET_MODEL, "--cache", str(bad)]) == 2
    _one_line(capsys, f"{bad} is not a frustum cache made by `track3d-train boxnet prepare`", KINDS[kind])
    assert train_main(["boxnet", "train", "--cache", str(bad), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    _one_line(capsys, f"{bad} is not a frustum cache made by `track3d-train boxnet prepare`", KINDS[kind])
    assert not (tmp_path / "run").exists()   # no empty run folder left behind


def test_boxnet_prepare_of_an_empty_split_says_so(tmp_path, capsys):
    # it had said "no frustum with >= 16 points" (after an empty progress bar and an --out folder)
    from track3d.synthetic import make_synthetic_dataset

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 3})
    d = json.loads((root / "dataset.json").read_text())
    d["splits"]["train"] = []
    (root / "dataset.json").write_text(json.dumps(d))
    assert train_main(["boxnet", "prepare", "--data", str(root), "--split", "train", "--out", str(tmp_path / "c"),
                       "--quiet"]) == 2
    _one_line(capsys, "split 'train' of", "has no sequences")
    assert not (tmp_path / "c").exists()


def test_a_frustum_cache_from_prepare_reads_and_a_damaged_one_is_named(tmp_path, capsys):
    from track3d.synthetic import make_synthetic_dataset
    from track3d_train.boxnet.data import PointCache, prepare_split

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 3})
    good = prepare_split(root, "test", tmp_path / "c.npz", jitters=0, min_points=4, progress=False)
    c = PointCache(good)
    assert len(c) > 0 and c.info["split"] == "test" and c.points(0).shape[1] == 3
    z = dict(np.load(good))
    np.savez(tmp_path / "short.npz", **{**z, "gt3d": z["gt3d"][:-1]})   # arrays that do not fit together
    info = json.loads(z["info"].tobytes())
    np.savez(tmp_path / "v9.npz", **{**z, "info": np.frombuffer(json.dumps({**info, "version": 9}).encode(), np.uint8)})
    for name, why in (("short.npz", "do not fit together"), ("v9.npz", "cache version 9")):
        assert train_main(["boxnet", "eval", "--model", BOXNET_MODEL, "--cache", str(tmp_path / name)]) == 2
        _one_line(capsys, "is not a frustum cache made by `track3d-train boxnet prepare`", why)


def test_a_prepare_killed_while_writing_leaves_no_cache_behind(tmp_path, monkeypatch):
    """The recipes skip a cache that exists (their steps resume), so a frustum cache appears only
    once complete: it used to be written in place, and a job killed mid-write left a truncated
    .npz that the next run took as done."""
    from track3d.synthetic import make_synthetic_dataset
    from track3d_train.boxnet import data

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 3})
    out = tmp_path / "c.npz"
    real = np.savez

    def killed(f, **arrays):
        real(f, points=arrays["points"])   # part of the file written ...
        raise KeyboardInterrupt            # ... then the job is killed

    monkeypatch.setattr(data.np, "savez", killed)
    with pytest.raises(KeyboardInterrupt):
        data.prepare_split(root, "test", out, jitters=0, min_points=4, progress=False)
    assert not out.exists()
    monkeypatch.setattr(data.np, "savez", real)
    assert data.prepare_split(root, "test", out, jitters=0, min_points=4, progress=False) == out
    assert len(data.PointCache(out)) > 0 and [p.name for p in tmp_path.iterdir() if p.is_file()] == ["c.npz"]


def test_boxnet_train_init_from_an_exported_model_takes_its_flags_or_names_them(tmp_path, capsys):
    """--init-from X.onnx with flags other than its metadata's is one line naming the flags: with
    --no-category alone the shipped extent-coded model had been fine-tuned as "points" in silence."""
    from track3d.synthetic import make_synthetic_dataset
    from track3d_train.boxnet.data import prepare_split

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 3})
    cache = prepare_split(root, "test", tmp_path / "c.npz", jitters=0, min_points=4, progress=False)
    run = ["boxnet", "train", "--cache", str(cache), "--out", str(tmp_path / "run"), "--num-points", "512",
           "--batch", "2", "--max-steps", "1", "--val-every", "0", "--init-from", BOXNET_MODEL, "--quiet"]
    assert train_main([*run, "--no-category", "--width", "0.5"]) == 2
    _one_line(capsys, "a3boxnet_narrow.onnx was trained with other flags than this run's: pass --size-norm extent")
    assert train_main([*run, "--no-category"]) == 2
    _one_line(capsys, "pass --width 0.5 --size-norm extent")
    assert train_main([*run, "--size-norm", "extent", "--width", "0.5"]) == 2
    _one_line(capsys, "pass --no-category")


def test_boxnet_train_init_from_a_views_model_needs_a_cache_with_the_views(tmp_path, capsys):
    """Fine-tuning the default model (a3boxnet_views.onnx, trained beside the body's past views)
    on a frustum-only cache had run without a word and exported a single-frame model; a single-
    frame model on a views cache is how the views model is made (recipe a3boxnet-views)."""
    from track3d.synthetic import make_synthetic_dataset
    from track3d_train.boxnet.data import prepare_split

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 4})
    plain = prepare_split(root, "test", tmp_path / "c.npz", jitters=0, min_points=4, progress=False)
    views = prepare_split(root, "test", tmp_path / "v.npz", jitters=0, min_points=4, progress=False, past_views=True)
    run = ["boxnet", "train", "--out", str(tmp_path / "run"), "--num-points", "512", "--batch", "2", "--max-steps",
           "1", "--val-every", "0", "--no-category", "--width", "0.5", "--size-norm", "extent", "--quiet"]
    views_model = str(MODELS_DIR / "a3boxnet_views.onnx")
    assert train_main([*run, "--cache", str(plain), "--init-from", views_model]) == 2
    _one_line(capsys, "trained beside the body's past views and the cache has none", "--past-views")
    assert not (tmp_path / "run").exists()
    assert train_main([*run, "--cache", str(views), "--init-from", views_model]) == 0
    assert train_main([*run, "--cache", str(views), "--init-from", BOXNET_MODEL, "--out", str(tmp_path / "r2")]) == 0
    # a checkpoint of a views run, too (its history names its cache; a review)
    ck = tmp_path / "run" / "last.pt"
    assert train_main([*run, "--cache", str(plain), "--init-from", str(ck), "--out", str(tmp_path / "r3")]) == 2
    _one_line(capsys, "trained beside the body's past views and the cache has none")


def test_siamfc_and_edgetrack_train_name_a_path_that_is_not_a_crop_cache(tmp_path, capsys):
    from track3d_train.siamfc.data import build_cache, synthetic_sequences

    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a cache at all\n" * 20)
    run = ["--out", str(tmp_path / "run"), "--max-steps", "1", "--quiet"]
    # a file where the cache folder belongs: NotADirectoryError's traceback before
    assert train_main(["siamfc", "train", "--cache", str(garbage), *run]) == 2
    _one_line(capsys, f"{garbage} is not a crop cache folder made by `track3d-train siamfc prepare`", "a file")
    # a crops.npy that is no array: numpy's allow_pickle hint before
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "crops.npy").write_bytes(b"junk\n")
    (bad / "index.json").write_text("{}")
    assert train_main(["siamfc", "train", "--cache", str(bad), *run]) == 2
    _one_line(capsys, "crops.npy is not a crop cache's crops.npy made by `track3d-train siamfc prepare`")
    # EdgeTrack: an index without the cache's keys (a KeyError traceback before), a damaged background
    cache = tmp_path / "et"
    build_cache(synthetic_sequences(1, frames=3, seed=0, h=48, w=64), cache / "target", cache_size=64,
                exemplar_size=32, progress=False)
    index = (cache / "target" / "index.json").read_text()
    (cache / "target" / "index.json").write_text(json.dumps({"cache_size": 64}))
    assert train_main(["edgetrack", "train", "--cache", str(cache), *run]) == 2
    _one_line(capsys, "is not a crop cache index made by `track3d-train edgetrack prepare`", "no sequences")
    (cache / "target" / "index.json").write_text(index)
    (cache / "background").mkdir()
    (cache / "background" / "bg.npy").write_bytes(b"")
    assert train_main(["edgetrack", "train", "--cache", str(cache), *run]) == 2
    _one_line(capsys, "bg.npy is not a background crop array made by `track3d-train edgetrack prepare`",
              "an empty file")


def _strict_json(text: str):
    def no_constant(c):
        raise AssertionError(f"{c} in JSON")
    return json.loads(text, parse_constant=no_constant)


def test_edgetrack_eval_writes_valid_json_with_null_for_a_missing_number(tmp_path, capsys):
    from track3d.synthetic import make_synthetic_dataset

    root = make_synthetic_dataset(tmp_path / "ds", {"a": 3})   # no absent frame: lost precision undefined
    out = tmp_path / "x.json"
    assert train_main(["edgetrack", "eval", "--model", str(MODELS_DIR / "edgetrack"), "--data", str(root),
                       "--split", "test", "--out", str(out), "--quiet", "--json"]) == 0
    printed = _strict_json(capsys.readouterr().out)
    report = _strict_json(out.read_text())
    row = next(iter(report["trackers"].values()))
    assert row["lost_precision"] is None and 0 <= row["ao_2d"] <= 1
    assert next(iter(printed.values()))["lost_precision"] is None


def _help(capsys, argv) -> str:
    with pytest.raises(SystemExit) as e:
        train_main(argv)
    assert e.value.code == 0
    return capsys.readouterr().out


def _flag_help(text: str, flag: str) -> str:
    """The help of `flag` in an argparse help text, on one line."""
    m = re.search(rf"^  {re.escape(flag)}\b.*?(?=^  -|\Z)", text, re.M | re.S)
    assert m, flag
    return " ".join(m.group(0).split())


def test_train_flags_say_their_defaults(capsys):
    from track3d_train.siamfc.model import VARIANTS, SiamFCConfig

    text = _help(capsys, ["siamfc", "train", "--help"])
    width = _flag_help(text, "--width")
    assert "default: the variant's" in width
    for v in ("edge", "faithful"):
        assert f"{VARIANTS[v]['width']} for {v}" in width
    assert f"default: {SiamFCConfig().train_instance_size}" in _flag_help(text, "--train-instance-size")
    assert "default: none" in _flag_help(text, "--time-budget-min")
    text = _help(capsys, ["edgetrack", "train", "--help"])
    assert "default: none" in _flag_help(text, "--time-budget-min")
    num_points = _flag_help(_help(capsys, ["boxnet", "eval", "--help"]), "--num-points")
    assert "override N" not in num_points and "points sampled from each frustum" in num_points
    assert "default: the model's own" in num_points


def test_top_level_help_lists_each_command_once(capsys):
    assert train_main(["--help"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = [ln.split()[0] for ln in lines if ln.startswith("  ") and ln.split()[0] in COMMANDS]
    assert rows == list(COMMANDS)
    for name in COMMANDS:
        assert sum(bool(re.search(rf"\b{name}\b", ln)) for ln in lines) == 1, name
    assert any("--version" in ln for ln in lines)


def test_edgetrack_help_example_keeps_its_line_continuation(capsys):
    text = _help(capsys, ["edgetrack", "--help"])
    assert re.search(r"data/engine-calib2 \\\n +--split train", text), text[:1500]
    assert not re.search(r"\S {4,}--split", text)


def test_epoch_samples_says_it_is_capped_at_the_cache(capsys, tmp_path):
    """--epoch-samples 1024 on a cache of fewer training items had silently given fewer steps per
    epoch: the help says so, and the log once when it happens."""
    from track3d.synthetic import make_synthetic_dataset
    from track3d_train.boxnet.data import PointCache, prepare_split
    from track3d_train.boxnet.train import TrainConfig, train

    assert "capped at the cache's training items" in _flag_help(_help(capsys, ["boxnet", "train", "--help"]),
                                                                 "--epoch-samples")
    cache = prepare_split(make_synthetic_dataset(tmp_path / "ds", {"a": 3}), "test", tmp_path / "c.npz", jitters=1,
                          min_points=4, progress=False)
    items = len(PointCache(cache))
    logs = []
    cfg = TrainConfig(train_cache=str(cache), out=str(tmp_path / "run"), num_points=32, width=0.25, epochs=1,
                      epoch_samples=1024, batch=4, val_every=0, max_steps=1)
    train(cfg, progress=False, log=logs.append)
    capped = [m for m in logs if "epoch_samples 1024" in m]
    assert capped == [f"epoch_samples 1024 is more than the cache's {items} training items: an epoch is one pass "
                      f"over them, {items // 4} steps of 4"]
    logs.clear()
    train(TrainConfig(**{**cfg.__dict__, "epoch_samples": items, "out": str(tmp_path / "run2")}), progress=False,
          log=logs.append)
    assert not [m for m in logs if "training items" in m]


@pytest.mark.parametrize("command,default", [("siamfc", 1.0), ("edgetrack", 3.0)])
def test_train_checkpoint_interval_is_a_flag(capsys, monkeypatch, tmp_path, command, default):
    """SiamFC's 60 s checkpoint interval had no flag (EdgeTrack's had: --ckpt-every-min)."""
    import importlib

    text = _flag_help(_help(capsys, [command, "train", "--help"]), "--ckpt-every-min")
    assert f"default: {default}" in text and "SIGTERM" in text
    seen = {}
    monkeypatch.setattr(importlib.import_module(f"track3d_train.{command}.train"), "train",
                        lambda *a, **k: seen.update(k) or {"step": 0})
    cache = tmp_path / "cache"
    (cache / "target").mkdir(parents=True)
    (cache / "target" / "index.json").write_text("{}")
    assert train_main([command, "train", "--cache", str(cache), "--out", str(tmp_path / "run"),
                       "--ckpt-every-min", "0.5", "--quiet"]) == 0
    assert seen["ckpt_every_s"] == 30.0


def _interrupt_with(monkeypatch, module: str, name: str, exc: BaseException):
    import importlib

    def stop(*a, **k):
        raise exc

    monkeypatch.setattr(importlib.import_module(module), name, stop)


@pytest.mark.parametrize("argv,module,name", [
    (["boxnet", "train", "--cache", "c.npz"], "track3d_train.boxnet.train", "train"),
    (["edgetrack", "train", "--cache", "CACHE"], "track3d_train.edgetrack.train", "train"),
    (["siamfc", "train", "--cache", "c"], "track3d_train.siamfc.train", "train"),
    (["recipe", "run", "siamfc"], "track3d_train.recipes", "run"),
])
def test_ctrl_c_is_one_line_exit_130_that_says_how_to_resume(capsys, monkeypatch, tmp_path, argv, module, name):
    """Ctrl-C had printed KeyboardInterrupt's traceback (60 lines) and exited -2; track3d-sim and
    track3d track say one line and exit 130."""
    cache = tmp_path / "cache"
    (cache / "target").mkdir(parents=True)
    (cache / "target" / "index.json").write_text("{}")
    argv = [str(cache) if a == "CACHE" else a for a in argv]
    _interrupt_with(monkeypatch, module, name, KeyboardInterrupt())
    run = ["--out", str(tmp_path / "run")] if argv[1] == "train" else []
    assert train_main(argv + run) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"track3d-train {argv[0]}: interrupted: run the same command again to resume"]
    if argv[1] == "train":   # started over by --no-resume, the same command would not resume
        assert train_main(argv + run + ["--no-resume"]) == 130
        assert capsys.readouterr().err.strip().endswith(": run it again without --no-resume to resume")


def test_a_training_stopped_by_a_signal_says_where_and_exits_128_plus_it(capsys, monkeypatch, tmp_path):
    import signal

    from track3d_train.interrupt import TrainingInterrupted

    _interrupt_with(monkeypatch, "track3d_train.boxnet.train", "train",
                    TrainingInterrupted(signal.SIGTERM, 41, "runs/x/last.pt"))
    assert train_main(["boxnet", "train", "--cache", "c.npz", "--out", str(tmp_path / "r")]) == 143
    assert capsys.readouterr().err.strip().splitlines() == [
        "track3d-train boxnet: interrupted (SIGTERM) at step 41, checkpoint runs/x/last.pt written: "
        "run the same command again to resume"]


def test_ctrl_c_in_a_command_that_does_not_resume_says_only_interrupted(capsys, monkeypatch, tmp_path):
    _interrupt_with(monkeypatch, "track3d_train.boxnet.data", "prepare_split", KeyboardInterrupt())
    assert train_main(["boxnet", "prepare", "--data", str(tmp_path), "--out", str(tmp_path / "c")]) == 130
    assert capsys.readouterr().err.strip().splitlines() == ["track3d-train boxnet: interrupted"]


def test_ctrl_c_during_edgetrack_train_checkpoints_and_says_one_line(tmp_path):
    """The real thing: SIGINT to a running `track3d-train edgetrack train` (a kill had written no
    checkpoint and printed a traceback; exit -2)."""
    import signal
    import subprocess
    import sys
    import time

    from track3d_train.edgetrack.data import prepare

    prepare(tmp_path / "cache", synthetic=2, synthetic_frames=8, max_frames=16, progress=False, pad=None)
    run = tmp_path / "run"
    code = "import sys; from track3d_train.cli import main; sys.exit(main())"
    p = subprocess.Popen([sys.executable, "-c", code, "edgetrack", "train", "--cache", str(tmp_path / "cache"),
                          "--out", str(run), "--max-steps", "100000", "--batch", "2", "--ckpt-every-min", "60",
                          "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.time()
    while not ((run / "log.jsonl").is_file() and (run / "log.jsonl").read_text()):   # training, 10 steps logged
        assert p.poll() is None and time.time() - t0 < 120, p.communicate()
        time.sleep(0.1)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    ck = torch.load(str(run / "ckpt.pt"), weights_only=False)
    assert err.strip().splitlines() == [f"track3d-train edgetrack: interrupted (SIGINT) at step {ck['step']}, "
                                        f"checkpoint {run / 'ckpt.pt'} written: run the same command again to resume"]
    assert ck["step"] >= 10
