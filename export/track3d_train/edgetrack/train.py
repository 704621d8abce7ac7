"""EdgeTrack training: AdamW + cosine LR, atomic checkpoints every few minutes, resume after any
interruption, a held-out validation (loss, score calibration, lost-detection precision/recall)
and the curves as JSON + PNG.

Run folder: ckpt.pt (latest, written atomically), log.jsonl (train rows and val rows),
curves.json + curves.png (rewritten at every validation), summary.json.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from track3d.threads import check_threads

from ..checkpoint import random_state, restore_random_state, save_checkpoint, write_text_atomic
from ..interrupt import StopOnSignal
from ..training_log import read_log, trim_log
from .data import MAKER, CropCache, PairSampler, load_background
from .model import EdgeTrack, EdgeTrackConfig, cell_centres, edgetrack_loss

__all__ = ["train", "load_checkpoint", "validate", "fit_platt", "plot_curves"]


def load_checkpoint(path) -> tuple[EdgeTrack, dict]:
    """(network, checkpoint dict) of an EdgeTrack ckpt.pt; another network's is a ValueError."""
    from ..checkpoint import load_checkpoint_dict

    ck = load_checkpoint_dict(path, "EdgeTrack")
    net = EdgeTrack(EdgeTrackConfig.from_dict(ck["config"]))
    net.load_state_dict(ck["model"])
    return net, ck


def fit_platt(logits: np.ndarray, labels: np.ndarray, iters: int = 100) -> tuple[float, float]:
    """Platt scaling p = sigmoid(a * logit + b): Platt's smoothed targets ((N+ + 1) / (N+ + 2),
    1 / (N- + 2)) and a small ridge keep it finite on separable data; damped Newton steps."""
    x = np.asarray(logits, np.float64)
    y = np.asarray(labels, bool)
    if len(x) == 0 or y.all() or not y.any():
        return 1.0, 0.0
    npos, nneg = int(y.sum()), int((~y).sum())
    t = np.where(y, (npos + 1.0) / (npos + 2.0), 1.0 / (nneg + 2.0))
    a, b = 1.0, 0.0
    for _ in range(iters):
        p = 1.0 / (1.0 + np.exp(-np.clip(a * x + b, -50, 50)))
        g = np.array([np.sum((p - t) * x) + 1e-2 * (a - 1.0), np.sum(p - t) + 1e-2 * b])
        wgt = p * (1 - p) + 1e-9
        hm = np.array([[np.sum(wgt * x * x) + 1e-2, np.sum(wgt * x)], [np.sum(wgt * x), np.sum(wgt) + 1e-2]])
        step = np.linalg.solve(hm, g)
        step *= min(1.0, 2.0 / max(np.abs(step).max(), 1e-12))
        a, b = a - step[0], b - step[1]
        if np.abs(step).max() < 1e-9:
            break
    return float(a), float(b)


@torch.no_grad()
def validate(net: EdgeTrack, batches) -> dict:
    """Loss on fixed held-out batches; per pair the peak logit and whether the peak cell lies in
    the target box (a correct detection): Platt-fit the peak logit to that, then precision and
    recall of 'lost' (calibrated score < threshold) against 'no correct detection'."""
    net.eval()
    cfg = net.cfg
    tot, n, peaks, hits, present, ious = {"loss": 0.0, "cls": 0.0, "reg": 0.0}, 0, [], [], [], []
    for z, x, boxes in batches:
        zt, xt = net.normalise(torch.from_numpy(z)), net.normalise(torch.from_numpy(x))
        bt = torch.from_numpy(boxes).float()
        logit, ltrb = net(zt, xt)
        parts = edgetrack_loss(logit, ltrb, bt, cfg)
        for k in tot:
            tot[k] += float(parts[k]) * len(z)
        n += len(z)
        m = logit.shape[-1]
        flat = logit[:, 0].reshape(len(z), -1)
        pk, idx = flat.max(1)
        p = cell_centres(m, cfg.total_stride)
        px, py = p[idx % m], p[idx // m]
        l, t, r, b = (ltrb[torch.arange(len(z)), k].reshape(len(z), -1)[torch.arange(len(z)), idx] for k in range(4))
        pred = torch.stack([px - l, py - t, px + r, py + b], 1).numpy()
        for j in range(len(z)):
            bx = boxes[j]
            ok = np.all(np.isfinite(bx))
            hit = bool(ok and bx[0] <= px[j] <= bx[2] and bx[1] <= py[j] <= bx[3])
            peaks.append(float(pk[j]))
            hits.append(hit)
            present.append(bool(ok))
            if ok:
                ix = max(0.0, min(pred[j, 2], bx[2]) - max(pred[j, 0], bx[0]))
                iy = max(0.0, min(pred[j, 3], bx[3]) - max(pred[j, 1], bx[1]))
                inter = ix * iy
                u = (pred[j, 2] - pred[j, 0]) * (pred[j, 3] - pred[j, 1]) + (bx[2] - bx[0]) * (bx[3] - bx[1]) - inter
                ious.append(inter / max(u, 1e-6))
    net.train()
    peaks, hits, present = np.array(peaks), np.array(hits), np.array(present)
    a, b = fit_platt(peaks, hits)
    score = 1.0 / (1.0 + np.exp(-np.clip(a * peaks + b, -50, 50)))
    lost = score < cfg.score_threshold
    absent = ~present
    tp = int(np.sum(lost & absent))
    out = {k: v / max(n, 1) for k, v in tot.items()}
    out.update({"calib_a": a, "calib_b": b, "peak_hit_rate": float(hits[present].mean()) if present.any() else 0.0,
                "box_iou": float(np.mean(ious)) if ious else 0.0,
                "lost_precision_absent": tp / max(int(lost.sum()), 1),
                "lost_recall_absent": tp / max(int(absent.sum()), 1)})
    return out


def plot_curves(log_path, json_path, png_path, title="EdgeTrack training") -> None:
    rows = read_log(log_path)
    tr = [r for r in rows if r.get("kind") == "train"]
    va = [r for r in rows if r.get("kind") == "val"]
    Path(json_path).write_text(json.dumps({"train": tr, "val": va}))
    if not tr:
        return
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    st = np.array([r["step"] for r in tr])
    for key, lab in (("loss", "train loss"), ("cls", "train cls"), ("reg", "train reg (1 - IoU)")):
        ax[0].plot(st, [r[key] for r in tr], lw=0.8, label=lab)
    if va:
        sv = [r["step"] for r in va]
        ax[0].plot(sv, [r["loss"] for r in va], "k.-", lw=1.5, label="val loss")
        ax[1].plot(sv, [r["peak_hit_rate"] for r in va], ".-", label="val peak in box")
        ax[1].plot(sv, [r["box_iou"] for r in va], ".-", label="val IoU at peak")
        ax[1].plot(sv, [r["lost_recall_absent"] for r in va], ".-", label="val lost recall (neg. pairs)")
        ax[1].plot(sv, [r["lost_precision_absent"] for r in va], ".-", label="val lost precision")
    ax[0].set_xlabel("step")
    ax[0].set_title(f"{title} ({tr[-1]['elapsed_s'] / 60:.1f} min)")
    ax[0].legend(fontsize=7)
    ax[0].grid(alpha=0.3)
    ax[1].set_xlabel("step")
    ax[1].set_ylim(0, 1)
    ax[1].legend(fontsize=7)
    ax[1].grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(str(png_path), dpi=100)
    plt.close(fig)


def _onnx_source(source, sampler, net, pairs: int = 64) -> dict:
    """An exported pair (e.g. the shipped one) as an init_from checkpoint; the folded BatchNorms
    take their statistics from `pairs` training pairs of `sampler` (`from_onnx`)."""
    from .from_onnx import model_from_onnx

    z, x, _ = sampler.sample(pairs)
    with torch.no_grad():
        crops = (net.normalise(torch.from_numpy(z)).numpy(), net.normalise(torch.from_numpy(x)).numpy())
    return model_from_onnx(source, calibration=crops)[1]


# The settings a resumed run must share with its checkpoint (train()'s argument -> its flag). Not
# compared: where the run stops (--max-steps, --time-budget-min: a run may be given more), how
# often it checkpoints, --threads, and --border-cut (a resumed run keeps its own, as its config).
RESUME_FLAGS = {"batch": "--batch", "lr": "--lr", "weight_decay": "weight_decay", "seed": "--seed",
                "max_gap": "--max-gap", "val_every": "--val-every"}


def train(cfg: EdgeTrackConfig, cache_dir, out_dir, steps: int = 20000, batch: int = 32, lr: float = 3e-3,
          weight_decay: float = 1e-4, seed: int = 0, threads: int = 1, time_budget_s: float | None = None,
          ckpt_every_s: float = 180.0, log_every: int = 10, val_every: int = 200, val_sequences: int = 2,
          val_pairs: int = 256, max_gap: int = 50, resume: bool = True, init_from: str | None = None,
          border_cut: float = 0.0, progress: bool = True) -> dict:
    """Train (or resume) into out_dir; stops at `steps` or after `time_budget_s` of training time
    (summed over resumed runs). `border_cut`: the share of target pairs cut at a simulated image
    border (`data.cut_at_border`; validation pairs the same). Returns a summary dict. A second
    training on the same out_dir while this one runs is refused (checkpoint.RunLock)."""
    kwargs = dict(locals())   # the arguments, as given (first: no other local yet)
    from ..checkpoint import RunLock

    with RunLock() as lock:
        return _train(lock=lock, **kwargs)


def _train(lock, cfg: EdgeTrackConfig, cache_dir, out_dir, steps: int = 20000, batch: int = 32, lr: float = 3e-3,
           weight_decay: float = 1e-4, seed: int = 0, threads: int = 1, time_budget_s: float | None = None,
           ckpt_every_s: float = 180.0, log_every: int = 10, val_every: int = 200, val_sequences: int = 2,
           val_pairs: int = 256, max_gap: int = 50, resume: bool = True, init_from: str | None = None,
           border_cut: float = 0.0, progress: bool = True) -> dict:
    from ..checkpoint import check_run_folder, flag_differences, load_checkpoint_dict, refuse_other_data, \
        refuse_other_flags
    from ..siamfc.data import cache_data_info

    out = check_run_folder(out_dir)   # made once every input is read and checked (no empty run folder)
    lock.acquire(out)   # a run folder that exists: before anything in it is read or changed
    torch.set_num_threads(check_threads(threads))
    torch.manual_seed(seed)
    ck_path, log_path = out / "ckpt.pt", out / "log.jsonl"
    ck = load_checkpoint_dict(ck_path, "EdgeTrack") if resume and ck_path.is_file() else None
    if ck is not None:   # the run's own architecture, calibration and sampling, whatever the caller's defaults
        cfg = EdgeTrackConfig.from_dict(ck["config"])
        border_cut = float(ck.get("border_cut", 0.0))
    cache = CropCache(Path(cache_dir) / "target", maker=MAKER)
    bg = load_background(cache_dir)
    data_info = cache_data_info(Path(cache_dir) / "target", MAKER)   # the training data's identity, for the export
    settings = {"batch": batch, "lr": lr, "weight_decay": weight_decay, "seed": seed, "max_gap": max_gap,
                "val_every": val_every}
    if ck is not None:
        # another cache or other flags had been taken in silence: one line (the cache by its data's hash)
        refuse_other_data(ck_path, cache_dir, ck.get("train_data_hash"), data_info["train_data_hash"])
        refuse_other_flags(ck_path, flag_differences(ck, settings, RESUME_FLAGS))
        done = int(ck["step"]) >= steps or (time_budget_s is not None
                                             and float(ck.get("elapsed_s", 0.0)) >= time_budget_s)
        if done:   # a finished run stays finished, its files as they are (it had trained one more step)
            stopped = "steps" if int(ck["step"]) >= steps else "time budget"
            print(f"{ck_path}: the run is finished (step {int(ck['step'])}, {float(ck.get('elapsed_s', 0.0)) / 60:.1f} "
                  f"min trained; its {'step cap' if stopped == 'steps' else 'time budget'} reached): nothing to do")
            return {"step": int(ck["step"]), "stopped": stopped, "elapsed_s": float(ck.get("elapsed_s", 0.0)),
                    "checkpoint": str(ck_path), "calib": [cfg.calib_a, cfg.calib_b]}
    nseq = len(cache.index["sequences"])
    nval = min(val_sequences, max(0, nseq - 1))
    train_ids, val_ids = list(range(nseq - nval)), list(range(nseq - nval, nseq))
    nbg_val = len(bg) // 5
    sampler = PairSampler(cache, bg[nbg_val:], cfg.exemplar_size, cfg.instance_size, max_gap=max_gap,
                          sequences=train_ids, seed=seed, border_cut=border_cut)
    val_batches = []
    if nval:
        vs = PairSampler(cache, bg[:nbg_val], cfg.exemplar_size, cfg.instance_size, max_gap=max_gap,
                         sequences=val_ids, seed=10_000 + seed, neg_other=0.15, neg_background=0.25,
                         border_cut=border_cut)
        val_batches = [vs.sample(min(64, val_pairs)) for _ in range(max(1, val_pairs // 64))]
    net = EdgeTrack(cfg)
    opt = torch.optim.AdamW(net.parameters(), lr=lr, weight_decay=weight_decay)
    step, elapsed0 = 0, 0.0
    origin = ck.get("init_from") if ck is not None else None   # what a fine-tune started from (its export says)
    if ck is not None:
        net.load_state_dict(ck["model"])
        opt.load_state_dict(ck["optim"])
        step, elapsed0 = int(ck["step"]), float(ck.get("elapsed_s", 0.0))
        if "random" in ck:   # the sampler's and torch's streams go on as if never stopped
            restore_random_state(sampler.rng, ck["random"])
        else:                # a checkpoint from before they were saved
            sampler.rng = np.random.default_rng([seed, step])
            torch.manual_seed(seed + step)
        trim_log(log_path, step)   # rows logged after the checkpoint (a kill between checkpoints)
        print(f"resumed from {ck_path} at step {step} ({elapsed0 / 60:.1f} min trained)")
    else:
        if init_from:
            from .from_onnx import is_exported_pair

            if is_exported_pair(init_from):
                src = _onnx_source(init_from, PairSampler(cache, bg[nbg_val:], cfg.exemplar_size, cfg.instance_size,
                                                          max_gap=max_gap, sequences=train_ids, seed=20_000 + seed,
                                                          border_cut=border_cut), net)
            else:
                src = load_checkpoint_dict(init_from, "EdgeTrack")
            try:
                net.load_state_dict(src["model"])
            except RuntimeError:   # another architecture: a size-mismatch traceback before
                theirs = (src.get("config") or {}).get("widths")
                raise ValueError(f"{init_from} is an EdgeTrack of another architecture (widths {theirs}, this run's "
                                 f"{list(cfg.widths)}): it cannot start this run") from None
            origin = {"name": Path(str(init_from)).name, "step": src.get("step"),
                      "train_data_hash": (src.get("imported_from") or src).get("train_data_hash")}
            print(f"initialised from {init_from} (step {src.get('step')})")
        if log_path.exists():
            log_path.unlink()
    out.mkdir(parents=True, exist_ok=True)
    lock.acquire(out)

    def checkpoint(elapsed):
        save_checkpoint(ck_path, {"model": net.state_dict(), "optim": opt.state_dict(), "step": step,
                        "config": net.cfg.to_dict(), "elapsed_s": elapsed, "steps_planned": steps,
                        **settings, "border_cut": border_cut, "calib": [net.cfg.calib_a, net.cfg.calib_b],
                        "pad": sampler.pad, "init_from": origin, "random": random_state(sampler.rng),
                        "log_acc": [acc, nacc], **data_info})

    net.train()
    t_start = time.perf_counter()
    last_ck = t_start
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=steps, initial=step, desc="edgetrack", unit="step")
    acc = {"loss": 0.0, "cls": 0.0, "reg": 0.0}
    nacc = 0
    if ck is not None and "log_acc" in ck:   # the log interval the checkpoint fell in, part summed
        acc, nacc = dict(ck["log_acc"][0]), int(ck["log_acc"][1])
    stopped = "steps"
    elapsed = elapsed0
    # SIGTERM / SIGINT: a checkpoint at the next step boundary, then TrainingInterrupted
    with open(log_path, "a") as log, StopOnSignal() as stop:
        while step < steps:
            # short warm-up, then cosine to 1% of lr over the steps or the time budget, whichever
            # ends first (the step rate on a shared CPU is not known in advance)
            frac = step / steps
            if time_budget_s:
                frac = max(frac, (elapsed0 + time.perf_counter() - t_start) / time_budget_s)
            warm = min(1.0, (step + 1) / 100.0)
            for g in opt.param_groups:
                g["lr"] = lr * warm * (0.01 + 0.99 * 0.5 * (1 + math.cos(math.pi * min(frac, 1.0))))
            z, x, boxes = sampler.sample(batch)
            logit, ltrb = net(net.normalise(torch.from_numpy(z)), net.normalise(torch.from_numpy(x)))
            parts = edgetrack_loss(logit, ltrb, torch.from_numpy(boxes).float(), cfg)
            opt.zero_grad(set_to_none=True)
            parts["loss"].backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), 10.0)
            opt.step()
            step += 1
            for k in acc:
                acc[k] += float(parts[k].detach())
            nacc += 1
            if bar:
                bar.update(1)
                bar.set_postfix(loss=f"{float(parts['loss']):.3f}")
            now = time.perf_counter()
            elapsed = elapsed0 + now - t_start
            if step % log_every == 0 or step == steps:
                log.write(json.dumps({"kind": "train", "step": step, **{k: v / nacc for k, v in acc.items()},
                                      "lr": opt.param_groups[0]["lr"], "elapsed_s": round(elapsed, 2)}) + "\n")
                log.flush()
                acc, nacc = {k: 0.0 for k in acc}, 0
            budget_hit = time_budget_s is not None and elapsed >= time_budget_s
            if val_batches and (step % val_every == 0 or step == steps or budget_hit):
                v = validate(net, val_batches)
                net.cfg = cfg = replace(cfg, calib_a=v["calib_a"], calib_b=v["calib_b"])
                log.write(json.dumps({"kind": "val", "step": step, "elapsed_s": round(elapsed, 2), **v}) + "\n")
                log.flush()
                try:
                    plot_curves(log_path, out / "curves.json", out / "curves.png")
                except Exception as e:  # plotting is a convenience
                    print(f"curve plot failed: {e}")
            if now - last_ck >= ckpt_every_s or step == steps or budget_hit:
                checkpoint(elapsed)
                last_ck = now
            if budget_hit:
                stopped = "time budget"
                break
            if stop and step < steps:
                stopped = "interrupted"
                break
    if bar:
        bar.close()
    checkpoint(elapsed)
    if stopped == "interrupted":
        raise stop.interrupted(step, ck_path)
    try:
        plot_curves(log_path, out / "curves.json", out / "curves.png")
    except Exception as e:
        print(f"curve plot failed: {e}")
    summary = {"step": step, "stopped": stopped, "elapsed_s": elapsed, "checkpoint": str(ck_path),
               "calib": [net.cfg.calib_a, net.cfg.calib_b]}
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=1))
    return summary
