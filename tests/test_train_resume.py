"""A training run killed and resumed ends with the same bytes as one never interrupted: the
weights, the optimiser, EdgeTrack's fitted calibration and the training log's losses, whatever
step the kill came at (the samplers' random streams, torch's, the data order and the partial
log interval are all in the checkpoint). Tiny networks on tiny synthetic caches, seconds each."""
from __future__ import annotations

import json

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
