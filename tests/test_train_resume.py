"""A training run killed and resumed ends with the same bytes as one never interrupted: the
weights, the optimiser, EdgeTrack's fitted calibration and the training log's losses, whatever
step the kill came at (the samplers' random streams, torch's, the data order and the partial
log interval are all in the checkpoint). SIGTERM and SIGINT (Ctrl-C) write that checkpoint at
the next step boundary, then end the run (TrainingInterrupted). Tiny networks on tiny synthetic
caches, seconds each."""
from __future__ import annotations

import json
import os
import signal

import numpy as np
import pytest

torch = pytest.importorskip("torch")

ET_TINY = dict(exemplar_size=128, instance_size=256, lost_instance_size=336, widths=(8, 16, 24, 32),
               feat_channels=32, head_channels=32, head_blocks=1)
BATCH = 2            # training pairs per step; the validation batches are larger (told apart by it)


class Killed(BaseException):
    """A kill between two steps (as SIGKILL would: nothing after it runs)."""


def _kill_at_sample(monkeypatch, sampler_cls, call: int):
    """The `call`-th training batch drawn by `sampler_cls` raises Killed instead (the step before
    it has been checkpointed when ckpt_every_s is 0)."""
    real = sampler_cls.sample
    calls = []

    def sample(self, batch, *a, **k):
        if batch == BATCH:
            calls.append(1)
            if len(calls) == call:
                raise Killed
        return real(self, batch, *a, **k)

    monkeypatch.setattr(sampler_cls, "sample", sample)
    return lambda: monkeypatch.setattr(sampler_cls, "sample", real)


def _same_state(a: dict, b: dict):
    assert a.keys() == b.keys()
    diff = {k: float((a[k].double() - b[k].double()).abs().max()) for k in a if not torch.equal(a[k], b[k])}
    assert not diff, f"{len(diff)} tensors differ, up to {max(diff.values()):.3g} ({next(iter(diff))}, ...)"


def _train_losses(log_path, kind=None):
    rows = [json.loads(line) for line in log_path.read_text().splitlines()]
    return [{k: v for k, v in r.items() if k != "elapsed_s"} for r in rows if kind is None or r.get("kind") == kind]


@pytest.fixture(scope="module")
def et_cache(tmp_path_factory):
    from track3d_train.edgetrack.data import prepare

    root = tmp_path_factory.mktemp("et_resume")
    prepare(root / "cache", synthetic=3, synthetic_frames=10, max_frames=30, exemplar_size=128,
            instance_size=256, progress=False, pad=None)
    return root / "cache"


@pytest.mark.parametrize("kill_at", [3, 5])
def test_edgetrack_resumed_after_a_kill_is_bit_identical(et_cache, tmp_path, monkeypatch, kill_at):
    from track3d_train.edgetrack.data import PairSampler
    from track3d_train.edgetrack.model import EdgeTrackConfig
    from track3d_train.edgetrack.train import train

    kw = dict(steps=7, batch=BATCH, val_every=3, val_sequences=1, val_pairs=8, log_every=2, seed=1,
              ckpt_every_s=0.0, progress=False)
    whole = train(EdgeTrackConfig(**ET_TINY), et_cache, tmp_path / "whole", **kw)
    restore = _kill_at_sample(monkeypatch, PairSampler, kill_at)
    with pytest.raises(Killed):
        train(EdgeTrackConfig(**ET_TINY), et_cache, tmp_path / "killed", **kw)
    restore()
    assert torch.load(str(tmp_path / "killed" / "ckpt.pt"), weights_only=False)["step"] == kill_at - 1
    resumed = train(EdgeTrackConfig(**ET_TINY), et_cache, tmp_path / "killed", **kw)
    assert resumed["step"] == whole["step"] == 7
    assert resumed["calib"] == whole["calib"]           # the calibration fitted at the last validation
    a = torch.load(str(tmp_path / "whole" / "ckpt.pt"), weights_only=False)
    b = torch.load(str(tmp_path / "killed" / "ckpt.pt"), weights_only=False)
    _same_state(a["model"], b["model"])
    assert a["config"] == b["config"]
    assert _train_losses(tmp_path / "whole" / "log.jsonl") == _train_losses(tmp_path / "killed" / "log.jsonl")


@pytest.fixture(scope="module")
def sf_cache(tmp_path_factory):
    from track3d_train.siamfc.data import build_cache, synthetic_sequences

    root = tmp_path_factory.mktemp("sf_resume")
    build_cache(synthetic_sequences(3, frames=8, seed=1), root / "cache", max_frames=24, progress=False)
    return root / "cache"


def test_siamfc_resumed_after_a_kill_is_bit_identical(sf_cache, tmp_path, monkeypatch):
    from track3d_train.siamfc.data import PairSampler
    from track3d_train.siamfc.model import config_for
    from track3d_train.siamfc.train import train

    cfg = config_for("edge", width=0.125, train_instance_size=159)
    kw = dict(steps=6, batch=BATCH, log_every=2, seed=3, ckpt_every_s=0.0, progress=False)
    train(cfg, sf_cache, tmp_path / "whole", **kw)
    restore = _kill_at_sample(monkeypatch, PairSampler, 4)
    with pytest.raises(Killed):
        train(cfg, sf_cache, tmp_path / "killed", **kw)
    restore()
    assert torch.load(str(tmp_path / "killed" / "ckpt.pt"), weights_only=False)["step"] == 3
    assert train(cfg, sf_cache, tmp_path / "killed", **kw)["step"] == 6
    a = torch.load(str(tmp_path / "whole" / "ckpt.pt"), weights_only=False)
    b = torch.load(str(tmp_path / "killed" / "ckpt.pt"), weights_only=False)
    _same_state(a["model"], b["model"])
    assert _train_losses(tmp_path / "whole" / "log.jsonl") == _train_losses(tmp_path / "killed" / "log.jsonl")


@pytest.fixture(scope="module")
def bx_cache(tiny_dataset, tmp_path_factory):
    from track3d_train.boxnet.data import prepare_split

    out = tmp_path_factory.mktemp("bx_resume")
    return prepare_split(tiny_dataset, "train", out / "train.npz", jitters=2, max_points=256, min_points=8,
                         progress=False)


def _bx_cfg(cache, out, **kw):
    from track3d_train.boxnet.train import TrainConfig

    return TrainConfig(**{**dict(train_cache=str(cache), out=str(out), num_points=64, width=0.25, epochs=3, batch=8,
                                 val_every=2, val_max=16, lr=3e-3, seed=2), **kw})


def test_boxnet_max_steps_mid_epoch_is_a_partial_epoch_and_resumes_exactly(bx_cache, tmp_path):
    """--max-steps inside an epoch: the log names the step cap (it had said "budget reached"), the
    epoch is recorded as partial (it had been a full one, and a resumed run skipped the rest of
    it), and a run resumed from there ends with the uninterrupted run's bytes."""
    from track3d_train.boxnet.train import train

    logs = []
    whole = train(_bx_cfg(bx_cache, tmp_path / "whole"), progress=False, log=logs.append)
    per_epoch = whole["epochs"][0]["step"]
    assert len(whole["epochs"]) == 3 and per_epoch >= 3 and not any(e.get("partial") for e in whole["epochs"])
    cut = per_epoch + 2                                   # two batches into the second epoch
    logs.clear()
    h = train(_bx_cfg(bx_cache, tmp_path / "cut", max_steps=cut), progress=False, log=logs.append)
    assert [e.get("partial", False) for e in h["epochs"]] == [False, True]
    assert h["epochs"][-1]["batches"] == 2 and h["epochs"][-1]["of"] == per_epoch
    assert logs[-1] == f"stopping in epoch 2 after 2 of {per_epoch} batches, step {cut}: --max-steps {cut} reached"
    assert not any("budget" in m for m in logs)
    ck = torch.load(str(tmp_path / "cut" / "last.pt"), weights_only=False)
    assert ck["epoch"] == 0 and ck["partial"]["epoch"] == 1 and ck["partial"]["batches"] == 2
    # the same command again does nothing more; a higher cap completes the cut epoch, then the rest
    assert len(train(_bx_cfg(bx_cache, tmp_path / "cut", max_steps=cut), progress=False, log=logs.append)
               ["epochs"]) == 2
    h = train(_bx_cfg(bx_cache, tmp_path / "cut", max_steps=0), progress=False, log=logs.append)
    a = torch.load(str(tmp_path / "whole" / "last.pt"), weights_only=False)
    b = torch.load(str(tmp_path / "cut" / "last.pt"), weights_only=False)
    _same_state(a["model"], b["model"])
    assert [e["step"] for e in h["epochs"]] == [e["step"] for e in whole["epochs"]]
    assert [e["train"] for e in h["epochs"]] == [e["train"] for e in whole["epochs"]]
    assert [e["val"] for e in h["epochs"]] == [e["val"] for e in whole["epochs"]]
    assert h["steps"] == whole["steps"]


def test_boxnet_max_steps_at_an_epoch_end_is_a_whole_epoch(bx_cache, tmp_path):
    from track3d_train.boxnet.train import train

    logs = []
    per_epoch = train(_bx_cfg(bx_cache, tmp_path / "probe", epochs=1), progress=False,
                      log=lambda *_: None)["epochs"][0]["step"]
    h = train(_bx_cfg(bx_cache, tmp_path / "r", max_steps=per_epoch), progress=False, log=logs.append)
    assert len(h["epochs"]) == 1 and not h["epochs"][0].get("partial")
    assert logs[-1] == f"stopping after epoch 1, step {per_epoch}: --max-steps {per_epoch} reached"
    assert "partial" not in torch.load(str(tmp_path / "r" / "last.pt"), weights_only=False)


# -- SIGTERM / SIGINT: a checkpoint at the step boundary, then TrainingInterrupted -----------------
class Terminated(BaseException):
    """SIGTERM reached the test's own handler: the training loop did not catch it."""


@pytest.fixture
def sigterm_raises():
    """SIGTERM raises Terminated in this test (its default would end pytest); a training loop
    replaces the handler while it runs and puts this one back after."""
    def handler(signum, frame):
        raise Terminated

    old = signal.signal(signal.SIGTERM, handler)
    yield handler
    signal.signal(signal.SIGTERM, old)


def _signal_at_sample(monkeypatch, sampler_cls, call: int, signum: int):
    """While the `call`-th training batch is drawn, `signum` reaches this process."""
    real = sampler_cls.sample
    calls = []

    def sample(self, batch, *a, **k):
        out = real(self, batch, *a, **k)
        if batch == BATCH:
            calls.append(1)
            if len(calls) == call:
                os.kill(os.getpid(), signum)
        return out

    monkeypatch.setattr(sampler_cls, "sample", sample)
    return lambda: monkeypatch.setattr(sampler_cls, "sample", real)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_edgetrack_a_signal_checkpoints_at_the_step_and_the_resumed_run_is_bit_identical(
        et_cache, tmp_path, monkeypatch, sigterm_raises, signum):
    """A kill had written no checkpoint: up to --ckpt-every-min of work lost (a run killed at 20 s
    restarted at step 0)."""
    from track3d_train.edgetrack.data import PairSampler
    from track3d_train.edgetrack.model import EdgeTrackConfig
    from track3d_train.edgetrack.train import train
    from track3d_train.interrupt import TrainingInterrupted

    kw = dict(steps=7, batch=BATCH, val_every=3, val_sequences=1, val_pairs=8, log_every=2, seed=1,
              ckpt_every_s=1e9, progress=False)
    whole = train(EdgeTrackConfig(**ET_TINY), et_cache, tmp_path / "whole", **kw)
    restore = _signal_at_sample(monkeypatch, PairSampler, 4, signum)
    with pytest.raises(TrainingInterrupted) as e:
        train(EdgeTrackConfig(**ET_TINY), et_cache, tmp_path / "stopped", **kw)
    restore()
    assert (e.value.signum, e.value.step, e.value.exit_code) == (signum, 4, 128 + signum)
    assert e.value.checkpoint == str(tmp_path / "stopped" / "ckpt.pt")
    assert torch.load(e.value.checkpoint, weights_only=False)["step"] == 4
    assert signal.getsignal(signal.SIGTERM) is sigterm_raises                  # the handlers are put back
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    resumed = train(EdgeTrackConfig(**ET_TINY), et_cache, tmp_path / "stopped", **kw)
    assert resumed["step"] == 7 and resumed["calib"] == whole["calib"]
    a = torch.load(str(tmp_path / "whole" / "ckpt.pt"), weights_only=False)
    b = torch.load(str(tmp_path / "stopped" / "ckpt.pt"), weights_only=False)
    _same_state(a["model"], b["model"])
    assert _train_losses(tmp_path / "whole" / "log.jsonl") == _train_losses(tmp_path / "stopped" / "log.jsonl")


def test_siamfc_sigterm_checkpoints_at_the_step_and_the_resumed_run_is_bit_identical(
        sf_cache, tmp_path, monkeypatch, sigterm_raises):
    from track3d_train.interrupt import TrainingInterrupted
    from track3d_train.siamfc.data import PairSampler
    from track3d_train.siamfc.model import config_for
    from track3d_train.siamfc.train import train

    cfg = config_for("edge", width=0.125, train_instance_size=159)
    kw = dict(steps=6, batch=BATCH, log_every=2, seed=3, ckpt_every_s=1e9, progress=False)
    train(cfg, sf_cache, tmp_path / "whole", **kw)
    restore = _signal_at_sample(monkeypatch, PairSampler, 3, signal.SIGTERM)
    with pytest.raises(TrainingInterrupted) as e:
        train(cfg, sf_cache, tmp_path / "stopped", **kw)
    restore()
    assert e.value.step == 3 and torch.load(e.value.checkpoint, weights_only=False)["step"] == 3
    assert train(cfg, sf_cache, tmp_path / "stopped", **kw)["step"] == 6
    _same_state(torch.load(str(tmp_path / "whole" / "ckpt.pt"), weights_only=False)["model"],
                torch.load(str(tmp_path / "stopped" / "ckpt.pt"), weights_only=False)["model"])


def _signal_at_train_step(monkeypatch, call: int, signum: int):
    """While the `call`-th training loss of A3BoxNet is computed (validation runs without
    gradients and is not counted), `signum` reaches this process."""
    from track3d_train.boxnet import losses

    real = losses.boxnet_loss
    calls = []

    def loss(*a, **k):
        if torch.is_grad_enabled():
            calls.append(1)
            if len(calls) == call:
                os.kill(os.getpid(), signum)
        return real(*a, **k)

    monkeypatch.setattr(losses, "boxnet_loss", loss)
    return lambda: monkeypatch.setattr(losses, "boxnet_loss", real)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize("where", ["mid-epoch", "epoch end"])
def test_boxnet_a_signal_checkpoints_at_the_step_and_the_resumed_run_is_bit_identical(
        bx_cache, tmp_path, monkeypatch, sigterm_raises, signum, where):
    """boxnet checkpointed only at an epoch's end: a kill lost the epoch's work."""
    from track3d_train.boxnet.train import train
    from track3d_train.interrupt import TrainingInterrupted

    whole = train(_bx_cfg(bx_cache, tmp_path / "whole"), progress=False, log=lambda *_: None)
    per_epoch = whole["epochs"][0]["step"]
    at = per_epoch + (2 if where == "mid-epoch" else per_epoch)   # in the second epoch, or at its end
    restore = _signal_at_train_step(monkeypatch, at, signum)
    with pytest.raises(TrainingInterrupted) as e:
        train(_bx_cfg(bx_cache, tmp_path / "stopped"), progress=False, log=lambda *_: None)
    restore()
    assert e.value.step == at and e.value.checkpoint == str(tmp_path / "stopped" / "last.pt")
    ck = torch.load(e.value.checkpoint, weights_only=False)
    assert ck["step"] == at
    if where == "mid-epoch":   # no validation, no record of the cut epoch: the resumed run makes it
        assert ck["partial"]["batches"] == 2 and len(ck["history"]["epochs"]) == 1
    else:
        assert "partial" not in ck and len(ck["history"]["epochs"]) == 2
    h = train(_bx_cfg(bx_cache, tmp_path / "stopped"), progress=False, log=lambda *_: None)
    _same_state(torch.load(str(tmp_path / "whole" / "last.pt"), weights_only=False)["model"],
                torch.load(str(tmp_path / "stopped" / "last.pt"), weights_only=False)["model"])
    assert [(e["train"], e["val"]) for e in h["epochs"]] == [(e["train"], e["val"]) for e in whole["epochs"]]


def test_a_second_signal_stops_at_once_and_an_ignored_signal_stays_ignored(sigterm_raises):
    from track3d_train.interrupt import StopOnSignal

    with StopOnSignal() as stop:
        assert not stop
        os.kill(os.getpid(), signal.SIGTERM)
        assert stop and stop.signum == signal.SIGTERM
        with pytest.raises(KeyboardInterrupt):   # the second: while the checkpoint is written, say
            os.kill(os.getpid(), signal.SIGINT)
    assert signal.getsignal(signal.SIGTERM) is sigterm_raises
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)   # nohup, a background job
    try:
        with StopOnSignal() as stop:
            os.kill(os.getpid(), signal.SIGINT)
            assert not stop
    finally:
        signal.signal(signal.SIGINT, old)
