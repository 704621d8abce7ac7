"""The A3BoxNet training loop: Adam, batch 32, checkpoints every epoch, resume, a loss curve.

An "epoch" is one pass over the training cache (or ``epoch_samples`` random items of it, so
that a slow CPU still checkpoints often). Validation uses held-out TRAIN sequences (every
``val_every``-th sequence), never the test split.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from track3d.threads import check_threads

__all__ = ["TrainConfig", "train", "load_checkpoint", "plot_history"]


@dataclass
class TrainConfig:
    train_cache: str | list = ""     # one .npz or a list of them (concatenated)
    out: str = "runs/boxnet"
    num_points: int = 1024
    width: float = 1.0
    use_category: bool = True
    size_norm: str = "points"
    epochs: int = 25
    epoch_samples: int = 0          # 0: the whole cache per epoch; capped at the training items
    batch: int = 32
    lr: float = 1e-3
    lr_min: float = 1e-5
    weight_decay: float = 0.0
    flip: bool = True
    cat_dropout: float = 0.1        # probability of an all-zero ("unknown") category vector
    flip_y: bool = False            # random y-mirroring too
    scale_aug: float = 0.0          # sigma of the log scale about the camera centre (0: none)
    stretch_aug: float | tuple = 0.0  # sigma of the per-axis log stretch about the box centre (0: none), or (x, y, z)
    val_every: int = 8              # every k-th train sequence is held out for validation (0: none)
    val_max: int = 600              # validation items per epoch (a fixed random subset)
    seed: int = 0
    threads: int = 1
    max_minutes: float = 0.0        # time budget: the cosine LR spans it, training stops there (0: none)
    max_steps: int = 0              # stop after this many steps (tests; 0: no limit)
    num_categories: int = 3
    distill_from: str = ""          # a teacher A3BoxNet (.onnx or .pt) whose outputs the student also fits
    distill_weight: float = 0.0     # weight of losses.distill_loss in the objective (0: none)
    iou_weight: float = 0.0         # weight of the decoded box's 1 - IoU_3d in the objective (0: the paper's loss)
    extra: dict = field(default_factory=dict)


# The settings a resumed run must share with its checkpoint (TrainConfig field -> the flag that sets
# it; (flag, True): a switch that turns it off). Not compared: where the run stops (--epochs,
# --time-budget-min, --max-steps: a run may be given more), --threads, --out, the caches (their
# data is, by `_cache_identity`) and --distill-from (compared as a file, not as text).
RESUME_FLAGS = {"num_points": "--num-points", "width": "--width", "use_category": ("--no-category", True),
                "size_norm": "--size-norm", "epoch_samples": "--epoch-samples", "batch": "--batch", "lr": "--lr",
                "lr_min": "lr_min", "weight_decay": "weight_decay", "flip": ("--no-flip", True),
                "cat_dropout": "--cat-dropout", "flip_y": "--flip-y", "scale_aug": "--scale-aug",
                "stretch_aug": "--stretch-aug", "val_every": "--val-every", "val_max": "val_max", "seed": "--seed",
                "num_categories": "num_categories", "distill_weight": "--distill-weight",
                "iou_weight": "--iou-weight"}


def _cache_identity(info: dict) -> str:
    """A hash of what a training cache holds, from its info (the source data's hash, the jitter,
    the points kept, the seed, the sequences; for caches joined, every part in order; not where
    the dataset lay): the same for the same cache under another path's spelling, another for
    another cache at the same path."""
    import hashlib

    def what(d: dict) -> dict:
        return {k: ([what(x) for x in v] if k == "parts" else v) for k, v in d.items() if k != "root"}

    return hashlib.sha256(json.dumps(what(info), sort_keys=True, default=str).encode()).hexdigest()


def _same_file(a, b) -> bool:
    import os

    if str(a or "") == str(b or ""):
        return True
    try:
        return bool(a) and bool(b) and os.path.samefile(str(a), str(b))
    except OSError:
        return False


def _refuse_other_run(last: Path, ck: dict, cfg: "TrainConfig", cache) -> None:
    """A run resumed from `last` on another cache or with other settings than its own: one line.
    The caches were compared by their path's text: another spelling of the same file was refused
    and another file at the same path resumed in silence; other flags were taken in silence."""
    from ..checkpoint import flag_differences, refuse_other_data, refuse_other_flags

    hist = ck.get("history") or {}
    saved = hist.get("cache_identity") or (_cache_identity(hist["cache"]) if isinstance(hist.get("cache"), dict)
                                           else None)
    refuse_other_data(last, " ".join(str(c) for c in (cfg.train_cache if isinstance(cfg.train_cache, list)
                                                        else [cfg.train_cache])),
                      saved, _cache_identity(cache.info))
    tc = ck.get("train_config") or {}
    differ = flag_differences(tc, asdict(cfg), RESUME_FLAGS)
    if "distill_from" in tc and not _same_file(tc["distill_from"], cfg.distill_from):
        differ.append(f"--distill-from {tc['distill_from']}" if tc["distill_from"] else "no --distill-from")
    refuse_other_flags(last, differ)


def _max_points(cache) -> int | None:
    """The points a cache stores per frustum at most (`prepare --max-points`; for caches joined the
    smallest of theirs), or None when its info does not say."""
    parts = cache.info.get("parts") or [cache.info]
    found = [int(p["max_points"]) for p in parts if p.get("max_points")]
    return min(found) if found else None


def _split_val(cache, every: int, seed: int):
    seqs = np.unique(cache.seq)
    if every <= 0 or len(seqs) < 2:
        return cache, None
    val_seqs = seqs[::every] if len(seqs) >= every else seqs[:1]
    is_val = np.isin(cache.seq, val_seqs)
    return cache.subset(np.nonzero(~is_val)[0]), cache.subset(np.nonzero(is_val)[0])


def load_checkpoint(path: str | Path):
    """-> (model in eval mode, checkpoint dict)."""

    from .model import A3BoxNet, BoxNetConfig

    from ..checkpoint import load_checkpoint_dict

    ck = load_checkpoint_dict(path, "A3BoxNet")
    model = A3BoxNet(BoxNetConfig(**ck["model_config"]))
    model.load_state_dict(ck["model"])
    model.eval()
    return model, ck


def _collate(items):
    import torch

    cols = list(zip(*items))
    return [torch.from_numpy(np.stack(c)) for c in cols]


def _batches(ds, order, batch):
    for s in range(0, len(order) - batch + 1, batch):   # drop the last partial batch (BatchNorm)
        yield _collate([ds[int(i)] for i in order[s:s + batch]])


INTERRUPTED = "interrupted"   # a stop by SIGTERM / SIGINT (interrupt.StopOnSignal)

JOINT_TERMS = ("center1", "center2", "size_cls", "size_res")


def joint_loss_of(terms: dict) -> float:
    """The paper's joint loss out of a logged step or epoch (its four terms), without the extra
    terms of the objective (iou, distill), so that the train curve is the validation loss's kind;
    a record without the four terms gives its "total"."""
    if all(k in terms for k in JOINT_TERMS):
        return float(sum(terms[k] for k in JOINT_TERMS))
    return float(terms["total"])


def _step_label(history: dict) -> str:
    """The loss panel's x-label: the run's batch size from its recorded config (a run resumed
    keeps its first session's config), or just "step" when the history has none."""
    batch = (history.get("config") or {}).get("batch")
    return f"step (batch {batch})" if batch else "step"


def history_figure(history: dict, title: str = "A3BoxNet training"):
    """The loss-curve figure of a training history (plot_history saves it)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    steps = history.get("steps", [])
    if steps:
        s = np.array([x["step"] for x in steps])
        l = np.array([joint_loss_of(x) for x in steps])
        k = max(1, len(l) // 50)
        if k > 1:
            ax[0].plot(s, l, lw=0.5, alpha=0.4, label="train (per logged step)")
            ax[0].plot(s[k - 1:], np.convolve(l, np.ones(k) / k, mode="valid"), label=f"train (mean of {k})")
        else:   # too few logged steps to average: the steps themselves, one entry
            ax[0].plot(s, l, label="train")
    ep = history.get("epochs", [])
    if ep:
        es = [e["step"] for e in ep]
        ax[0].plot(es, [joint_loss_of(e["train"]) for e in ep], "o-", label="train (epoch mean)")
        if ep[0].get("val"):
            ax[0].plot(es, [e["val"]["loss"] for e in ep], "s-", label="val (held-out train seqs)")
            ax[1].plot([e["epoch"] for e in ep], [e["val"]["AO_3d"] for e in ep], "o-", label="val AO_3d")
            ax[1].plot([e["epoch"] for e in ep], [e["val"]["AO_bev"] for e in ep], "s-", label="val AO_bev")
            ax2 = ax[1].twinx()
            ax2.plot([e["epoch"] for e in ep], [e["val"]["ACE_3d"] for e in ep], "^--", color="gray",
                     label="val ACE_3d (m)")
            ax2.set_ylabel("ACE_3d (m)")
            ax2.legend(loc="center right")
    ax[0].set_yscale("log")
    ax[0].set_xlabel(_step_label(history))
    ax[0].set_ylabel("joint loss")
    ax[0].legend()
    ax[0].grid(alpha=0.3)
    ax[1].set_xlabel("epoch")
    ax[1].set_ylabel("AO")
    if ax[1].get_legend_handles_labels()[1]:
        ax[1].legend(loc="lower right")
    else:   # no validation yet (a run stopped inside its first epoch): say so, no empty legend
        ax[1].text(0.5, 0.5, "no validation yet", ha="center", va="center", transform=ax[1].transAxes)
    ax[1].grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_history(history: dict, path: str | Path, title: str = "A3BoxNet training") -> None:
    fig = history_figure(history, title)   # (selects the Agg backend before pyplot)
    import matplotlib.pyplot as plt

    fig.savefig(str(path), dpi=110)
    plt.close(fig)


def _validate(model, val_ds, batch: int):
    import torch

    from track3d.size_coding import size_coding

    from .evaluate import oracle_metrics
    from .losses import boxnet_loss

    model.eval()
    losses, boxes = [], []
    order = np.arange(len(val_ds))
    with torch.no_grad():
        for s in range(0, len(order), batch):
            items = [val_ds[int(i)] for i in order[s:s + batch]]
            pts, cat, crel, cls, res, scale = _collate(items)
            out = model(pts, cat)
            loss, _ = boxnet_loss(out, crel, cls, res, scale)
            losses.append(float(loss) * len(items))
            # the decoding needs the reference and scale of the sampled points: recompute them
            ids = [int(i) for i in order[s:s + batch]]
            coding = size_coding(val_ds.size_norm)
            _, ref, scale = coding.normalise(np.stack([val_ds.sample(i) for i in ids]),
                                             np.stack([val_ds.bounds(i) for i in ids]))
            boxes.append(coding.decode(ref, scale, *[o.numpy() for o in out]))
    c = val_ds.cache
    m = oracle_metrics(np.concatenate(boxes), c.field("gt3d"), c.field("seq"))
    m["loss"] = float(np.sum(losses) / len(order))
    return m


def _onnx_source(path, train_ds, samples: int = 256) -> dict:
    """An exported model (e.g. the shipped a3boxnet.onnx) as an init_from checkpoint; the folded
    BatchNorms take their statistics from the first `samples` training items (from_onnx)."""
    from .from_onnx import model_from_onnx

    n = min(samples, len(train_ds))
    pts = np.stack([train_ds[i][0] for i in range(n)]) if n >= 2 else None
    return model_from_onnx(path, calibration=pts)[1]


def _load_source(path, train_ds) -> tuple[str, dict]:
    """(resolved path, checkpoint dict) of the A3BoxNet a run starts from or learns from: an
    exported .onnx (a bare name such as a3boxnet.onnx: the shipped one) or a checkpoint."""
    from ..checkpoint import load_checkpoint_dict

    if str(path).endswith(".onnx"):
        from track3d.onnxmodel import model_path, shipped_model

        path = model_path(path)
        if not path.is_file() and path.name == str(path):   # a bare name shipped nowhere: say which are
            shipped_model(path.name)
        return str(path), _onnx_source(path, train_ds)
    # a damaged file or another network's checkpoint is one line (it had been EOFError's or
    # UnpicklingError's traceback)
    return str(path), load_checkpoint_dict(path, "A3BoxNet")


def _refuse_views_lost(path, views, cache_info: dict | None) -> None:
    """A model trained beside the body's past views (`views`: its counts, or None) fine-tuned on a
    cache without them would come out a single-frame model without a word. (A single-frame model
    fine-tuned on a views cache is how the views model is made: allowed.)"""
    from .data import cache_past_views

    if views and cache_info is not None and not cache_past_views(cache_info):
        raise ValueError(f"{path} was trained beside the body's past views and the cache has none: prepare it "
                         "with `boxnet prepare --past-views` (or start from a single-frame model, "
                         "a3boxnet_narrow.onnx)")


def _refuse_other_flags(path, src: dict, cfg: TrainConfig, cache_info: dict | None = None) -> None:
    """An exported model (--init-from X.onnx) is fine-tuned only with the flags its metadata
    records: --no-category alone had fine-tuned the shipped extent-coded model as "points"
    without a word. The width may be narrower (the model is cut to it), never wider. A model
    trained beside the body's past views (metadata ``past_views``: the default a3boxnet_views.onnx)
    is fine-tuned on a cache that has them: on a frustum-only cache its export had silently come
    out a single-frame model. (A single-frame model on a views cache is how a views model is made.)"""
    s = src.get("model_config")
    if not isinstance(s, dict):
        return
    _refuse_views_lost(path, (src.get("imported_from") or {}).get("past_views"), cache_info)
    want = []
    if int(s["num_points"]) != cfg.num_points:
        want.append(f"--num-points {int(s['num_points'])}")
    if float(s["width"]) < cfg.width:
        want.append(f"--width {float(s['width']):g}")
    if bool(s["use_category"]) != cfg.use_category:
        want.append("--no-category" if cfg.use_category else "no --no-category")
    recorded = (src.get("imported_from") or {}).get("size_norm")
    if recorded and recorded != cfg.size_norm:
        want.append(f"--size-norm {recorded}")
    if want:
        raise ValueError(f"{path} was trained with other flags than this run's: pass {' '.join(want)} "
                         "to fine-tune it")


def _teacher(cfg: TrainConfig, train_ds, log):
    """The distillation teacher in eval mode (an .onnx, e.g. the shipped model, or a checkpoint)."""
    from .model import A3BoxNet, BoxNetConfig

    path, src = _load_source(cfg.distill_from, train_ds)
    tcfg = src.get("model_config") if isinstance(src, dict) else None
    if (not isinstance(tcfg, dict) or tcfg.get("size_norm") != cfg.size_norm
            or tcfg.get("use_category") != cfg.use_category):
        raise ValueError(f"{path} cannot teach this run: its box coding and category input must be the run's")
    teacher = A3BoxNet(BoxNetConfig(**tcfg))
    teacher.load_state_dict(src["model"])
    teacher.eval()
    for p in teacher.parameters():
        p.requires_grad_(False)
    log(f"distilling from {Path(path).name} (weight {cfg.distill_weight})")
    return teacher


def train(cfg: TrainConfig, resume: bool = True, progress: bool = True, log=print,
          init_from: str | None = None) -> dict:
    """Train (or resume) into cfg.out: last.pt, best.pt, history.json, loss_curve.png.
    ``init_from``: a checkpoint, or an exported A3BoxNet .onnx such as the shipped model, whose
    weights start a new run (fine-tuning: a fresh optimiser and schedule); ignored when the run
    resumes from its own last.pt. A second training on the same cfg.out while this one runs is
    refused (checkpoint.RunLock)."""
    from ..checkpoint import RunLock

    with RunLock() as lock:
        return _train(cfg, resume, progress, log, init_from, lock)


def _train(cfg: TrainConfig, resume: bool, progress: bool, log, init_from: str | None, lock) -> dict:
    import torch

    from ..interrupt import StopOnSignal
    from .data import BoxNetSamples, PointCache, cache_past_views
    from .losses import boxnet_loss, distill_loss
    from .model import A3BoxNet, BoxNetConfig

    if cfg.iou_weight > 0 and cfg.size_norm == "paper":
        # the paper's labels are scaled by max(size), its decoding by L: the label's box cannot be decoded
        raise ValueError("iou_weight needs a box coding whose labels decode as its outputs do: not 'paper'")
    from ..checkpoint import check_run_folder, load_checkpoint_dict, save_checkpoint, write_text_atomic

    torch.set_num_threads(check_threads(cfg.threads))
    out = check_run_folder(cfg.out)
    lock.acquire(out)
    # first: a wrong cache (or --init-from, --num-points) leaves no empty run folder behind
    cache = PointCache.concat(cfg.train_cache)
    stored = _max_points(cache)
    if stored is not None and cfg.num_points > stored:   # it had sampled each frustum's points twice over
        raise ValueError(f"--num-points {cfg.num_points} is more than the {stored} points the cache stores per "
                         f"frustum: give at most {stored}, or prepare the cache with --max-points "
                         f"{cfg.num_points}")
    tr_cache, va_cache = _split_val(cache, cfg.val_every, cfg.seed)
    train_ds = BoxNetSamples(tr_cache, cfg.num_points, cfg.num_categories, cfg.size_norm, cfg.seed, cfg.flip,
                             cfg.cat_dropout if cfg.use_category else 0.0, cfg.flip_y, cfg.scale_aug,
                             cfg.stretch_aug)
    val_ds = None
    if va_cache is not None:
        rng = np.random.default_rng(cfg.seed + 1)
        if len(va_cache) > cfg.val_max:
            va_cache = va_cache.subset(np.sort(rng.choice(len(va_cache), cfg.val_max, replace=False)))
        val_ds = BoxNetSamples(va_cache, cfg.num_points, cfg.num_categories, cfg.size_norm, cfg.seed + 7, False)
        val_ds.epoch = 0
    mcfg = BoxNetConfig(num_points=cfg.num_points, num_categories=cfg.num_categories,
                        use_category=cfg.use_category, width=cfg.width, size_norm=cfg.size_norm)
    torch.manual_seed(cfg.seed)
    model = A3BoxNet(mcfg)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    per_epoch = (min(cfg.epoch_samples, len(train_ds)) if cfg.epoch_samples else len(train_ds)) // cfg.batch
    if per_epoch < 1:
        raise ValueError(f"the training cache has {len(train_ds)} items, fewer than one batch of {cfg.batch}")
    total_steps = per_epoch * cfg.epochs
    if cfg.epoch_samples > len(train_ds):
        log(f"epoch_samples {cfg.epoch_samples} is more than the cache's {len(train_ds)} training items: an epoch "
            f"is one pass over them, {per_epoch} steps of {cfg.batch}")

    budget_s = 60.0 * cfg.max_minutes

    def progress_at(step, seconds):
        """Fraction of the plan done: steps, or the time budget if that comes first."""
        t = step / max(total_steps, 1)
        if budget_s > 0:
            t = max(t, seconds / budget_s)
        return min(t, 1.0)

    def lr_at(t):  # cosine from lr to lr_min over the plan (steps or time budget)
        return cfg.lr_min + 0.5 * (cfg.lr - cfg.lr_min) * (1 + math.cos(math.pi * t))

    history = {"config": asdict(cfg), "steps": [], "epochs": [], "train_items": len(train_ds),
               "val_items": len(val_ds) if val_ds else 0, "data_hash": cache.info.get("data_hash"),
               "cache": cache.info, "cache_identity": _cache_identity(cache.info), "seconds": 0.0}
    start_epoch, step, best = 0, 0, -1.0
    # an epoch a stop cut short (--max-steps, the time budget, a signal): {"epoch", "batches" done,
    # "sums" of the terms, "train_seconds"}; a resumed run completes it, the same batches in order
    partial = None
    last = out / "last.pt"
    if resume and last.is_file():
        ck = load_checkpoint_dict(last, "A3BoxNet")
        _refuse_other_run(last, ck, cfg, cache)
        if ck["model_config"] != mcfg.to_dict():
            raise ValueError(f"{last} was trained with another model; use a new --out or --no-resume")
        model.load_state_dict(ck["model"])
        opt.load_state_dict(ck["optim"])
        start_epoch, step, best, history = ck["epoch"] + 1, ck["step"], ck["best"], ck["history"]
        if "torch_random" in ck:
            torch.set_rng_state(ck["torch_random"])
        partial = ck.get("partial")
        if partial is not None:
            start_epoch = partial["epoch"]
            log(f"resumed from {last}: epoch {start_epoch + 1}, batch {partial['batches']} of {per_epoch}, "
                f"step {step}")
        else:
            log(f"resumed from {last}: epoch {start_epoch}, step {step}")
    elif init_from:
        init_from, src = _load_source(init_from, train_ds)
        if init_from.endswith(".onnx"):
            _refuse_other_flags(init_from, src, cfg, cache.info)
        else:   # a checkpoint: its run's cache says whether it learnt beside the past views
            _refuse_views_lost(init_from, cache_past_views((src.get("history") or {}).get("cache") or {}),
                               cache.info)
        # a checkpoint's weights carry over between box codings (same layers; the heads re-learn
        # what their outputs mean; an exported model's recorded coding must be the run's, above),
        # and to a narrower net (narrow.py: the channels that matter most), not
        # between other architectures
        arch = {k: v for k, v in mcfg.to_dict().items() if k != "size_norm"}
        src_cfg = src.get("model_config") if isinstance(src, dict) else None
        if (isinstance(src_cfg, dict) and float(src_cfg.get("width", 1.0)) > cfg.width
                and {k: v for k, v in src_cfg.items() if k not in ("size_norm", "width")}
                == {k: v for k, v in arch.items() if k != "width"}):
            from .narrow import narrow_checkpoint
            log(f"narrowing {Path(init_from).name} from width {src_cfg['width']} to {cfg.width}")
            src = narrow_checkpoint(src, cfg.width)
            src_cfg = src["model_config"]
        if not isinstance(src_cfg, dict) or {k: v for k, v in src_cfg.items() if k != "size_norm"} != arch:
            raise ValueError(f"{init_from} is not an A3BoxNet checkpoint of this model (N, width, category "
                             "must match)")
        model.load_state_dict(src["model"])
        history["init_from"] = {"file": Path(init_from).name, "epoch": src.get("epoch"), "step": src.get("step"),
                                "size_norm": src_cfg.get("size_norm")}
        log(f"initialised from {init_from} (epoch {src.get('epoch')}, step {src.get('step')})")
    teacher = _teacher(cfg, train_ds, log) if cfg.distill_from and cfg.distill_weight > 0 else None
    out.mkdir(parents=True, exist_ok=True)   # every input read and checked
    lock.acquire(out)
    t_session = time.time()
    t_before = history["seconds"]
    if budget_s > 0 and progress_at(step, t_before) >= 1.0:
        log(f"the time budget of {cfg.max_minutes} min is already spent ({t_before / 60:.1f} min)")
        return history
    if cfg.max_steps and step >= cfg.max_steps:
        log(f"already at --max-steps {cfg.max_steps} (step {step})")
        return history

    def end_epoch(epoch: int, n: int, sums: dict, train_seconds: float, cut: bool) -> None:
        """Record the epoch (validated; `cut`: a stop ended it after n of per_epoch batches, marked
        partial) and write the checkpoints, last.pt able to resume a cut epoch where it stopped."""
        rec = {"epoch": epoch + 1, "step": step, "lr": lr_at(progress_at(step, t_before + time.time() - t_session)),
               "train": {k: v / max(n, 1) for k, v in sums.items()}, "train_seconds": train_seconds}
        if cut:
            rec.update(partial=True, batches=n, of=per_epoch)
        if val_ds is not None:
            rec["val"] = _validate(model, val_ds, 64)
        history["seconds"] = t_before + (time.time() - t_session)
        history["epochs"].append(rec)
        score = rec["val"]["AO_3d"] if "val" in rec else -rec["train"]["total"]
        msg = f"epoch {epoch + 1}{f' (partial: {n} of {per_epoch} batches)' if cut else ''}: " \
              f"train {rec['train']['total']:.4f}"
        if "val" in rec:
            v = rec["val"]
            msg += f" | val loss {v['loss']:.4f} AO_3d {v['AO_3d']:.3f} AO_bev {v['AO_bev']:.3f} ACE {v['ACE_3d']:.3f} m"
        log(msg + f" | {rec['train_seconds']:.0f} s")
        save(epoch, n, sums, train_seconds, cut, score)
        try:
            plot_history(history, out / "loss_curve.png")
        except Exception as e:  # plotting must never kill a training run
            log(f"(plot failed: {e})")

    def save(epoch: int, n: int, sums: dict, train_seconds: float, cut: bool, score: float | None) -> None:
        """last.pt (atomically; `cut`: with what resumes the epoch at batch n), history.json, and
        best.pt when `score` (a validation's; None: none) is the best yet."""
        nonlocal best
        history["seconds"] = t_before + (time.time() - t_session)
        ck = {"model": model.state_dict(), "optim": opt.state_dict(), "epoch": epoch - 1 if cut else epoch,
              "step": step, "best": best if score is None else max(best, score), "history": history,
              "model_config": mcfg.to_dict(), "train_config": asdict(cfg), "torch_random": torch.get_rng_state()}
        if cut:
            ck["partial"] = {"epoch": epoch, "batches": n, "sums": dict(sums), "train_seconds": train_seconds}
        if score is not None and score > best:   # atomically too: a kill while writing keeps the previous best
            best = score
            save_checkpoint(out / "best.pt", ck)
        save_checkpoint(last, ck)
        write_text_atomic(out / "history.json", json.dumps(history, indent=1))

    # SIGTERM / SIGINT: last.pt at the next step boundary (a cut epoch resumes there), then
    # TrainingInterrupted
    with StopOnSignal() as signals:
        for epoch in range(start_epoch, cfg.epochs):
            model.train()
            train_ds.epoch = epoch
            rng = np.random.default_rng(cfg.seed * 1000 + epoch)
            order = rng.permutation(len(train_ds))[:per_epoch * cfg.batch]
            sums, n, t_epoch = {}, 0, 0.0
            if partial is not None and partial["epoch"] == epoch:   # resume within the epoch: its remaining batches
                sums, n, t_epoch = dict(partial["sums"]), int(partial["batches"]), float(partial["train_seconds"])
                order = order[n * cfg.batch:]
                if history["epochs"] and history["epochs"][-1].get("partial"):
                    history["epochs"].pop()   # the cut epoch's record: the completed (or further cut) one replaces it
            partial = None
            it = _batches(train_ds, order, cfg.batch)
            if progress:
                from tqdm import tqdm
                it = tqdm(it, total=per_epoch, initial=n, desc=f"epoch {epoch + 1}/{cfg.epochs}", unit="batch",
                          mininterval=5)
            t0 = time.time()
            stop = None   # why the run stops (a sentence for the log), or None
            for pts, cat, crel, cls, res, scale in it:
                frac = progress_at(step, t_before + time.time() - t_session)
                if budget_s > 0 and frac >= 1.0:
                    stop = f"the time budget of {cfg.max_minutes:g} min is spent"
                    break
                for g in opt.param_groups:
                    g["lr"] = lr_at(frac)
                out_s = model(pts, cat)
                loss, terms = boxnet_loss(out_s, crel, cls, res, scale, cfg.iou_weight)
                if teacher is not None:
                    with torch.no_grad():
                        out_t = teacher(pts, cat)
                    d, dterms = distill_loss(out_s, out_t, scale)
                    loss = loss + cfg.distill_weight * d
                    terms = {**terms, **dterms, "total": loss.item()}
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                step += 1
                n += 1
                for k, v in terms.items():
                    sums[k] = sums.get(k, 0.0) + v
                if step % 10 == 0:
                    history["steps"].append({"step": step, **terms})
                if cfg.max_steps and step >= cfg.max_steps:
                    stop = f"--max-steps {cfg.max_steps} reached"
                    break
                if signals:
                    stop = INTERRUPTED
                    break
            if progress:
                it.close()
            if n == 0:
                break
            cut = n < per_epoch
            if stop is INTERRUPTED and cut:   # fast: no validation, the epoch's record comes when it is complete
                save(epoch, n, sums, t_epoch + time.time() - t0, True, None)
                raise signals.interrupted(step, last)
            end_epoch(epoch, n, sums, t_epoch + time.time() - t0, cut)
            if signals and epoch + 1 < cfg.epochs and stop in (None, INTERRUPTED):   # came at the epoch's end
                raise signals.interrupted(step, last)
            if stop and stop is not INTERRUPTED:
                where = f"in epoch {epoch + 1} after {n} of {per_epoch} batches" if cut else f"after epoch {epoch + 1}"
                log(f"stopping {where}, step {step}: {stop}")
                break
    return history
