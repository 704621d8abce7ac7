"""SiamFC training loop: SGD, exponential LR decay, checkpoints + resume, log + loss curve."""
from __future__ import annotations

import json
import time

import numpy as np
import torch
from track3d.threads import check_threads

from ..checkpoint import random_state, restore_random_state, save_checkpoint, write_text_atomic
from ..interrupt import StopOnSignal
from ..training_log import read_log, trim_log
from .data import CropCache, PairSampler
from .model import SiamFC, SiamFCConfig, balanced_bce

__all__ = ["train", "load_checkpoint", "plot_log"]


def load_checkpoint(path) -> tuple[SiamFC, dict]:
    from ..checkpoint import load_checkpoint_dict

    ck = load_checkpoint_dict(path, "SiamFC")
    net = SiamFC(SiamFCConfig.from_dict(ck["config"]))
    net.load_state_dict(ck["model"])
    return net, ck


def plot_log(log_path, png_path, title="SiamFC training") -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = read_log(log_path)
    if not rows:
        return
    st = np.array([r["step"] for r in rows])
    loss = np.array([r["loss"] for r in rows])
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(st, loss, lw=0.6, alpha=0.5, label="loss (per log interval)")
    if len(loss) > 10:
        k = max(5, len(loss) // 30)
        sm = np.convolve(loss, np.ones(k) / k, mode="valid")
        ax.plot(st[k - 1:], sm, lw=1.5, label=f"moving mean ({k})")
    ax.set_xlabel("step")
    ax.set_ylabel("balanced logistic loss")
    ax.set_title(f"{title} ({rows[-1]['elapsed_s'] / 60:.1f} min)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(str(png_path), dpi=110)
    plt.close(fig)


# The settings a resumed run must share with its checkpoint (train()'s argument -> its flag). Not
# compared: where the run stops (--max-steps, --time-budget-min: a run may be given more), how
# often it checkpoints, --threads. The network (--variant, --width, --train-instance-size) is
# compared by ARCH_FLAGS.
RESUME_FLAGS = {"batch": "--batch", "lr": "--lr", "lr_end": "--lr-end", "weight_decay": "weight_decay",
                "seed": "--seed", "max_gap": "--max-gap"}
ARCH_FLAGS = {"variant": "--variant", "width": "--width", "train_instance_size": "--train-instance-size"}


def _other_network(theirs: dict, cfg: SiamFCConfig) -> list[str]:
    """The flags (as a checkpoint's config `theirs` has them) whose network differs from `cfg`'s: its weights
    do not fit this run's (a size-mismatch traceback before)."""
    from ..checkpoint import flag_differences

    return flag_differences(theirs or {}, cfg.to_dict(), ARCH_FLAGS)


def train(cfg: SiamFCConfig, cache_dir, out_dir, steps: int = 2000, batch: int = 16, lr: float = 1e-2,
          lr_end: float = 1e-4, weight_decay: float = 5e-4, seed: int = 0, threads: int = 1,
          time_budget_s: float | None = None, ckpt_every_s: float = 60.0, log_every: int = 10,
          init_from: str | None = None, resume: bool = True, progress: bool = True,
          max_gap: int = 50) -> dict:
    """Train (or resume) into out_dir: ckpt.pt (latest), log.jsonl, loss.png. Returns a summary. A second
    training on the same out_dir while this one runs is refused (checkpoint.RunLock)."""
    kwargs = dict(locals())   # the arguments, as given (first: no other local yet)
    from ..checkpoint import RunLock

    with RunLock() as lock:
        return _train(lock=lock, **kwargs)


def _train(lock, cfg: SiamFCConfig, cache_dir, out_dir, steps: int = 2000, batch: int = 16, lr: float = 1e-2,
           lr_end: float = 1e-4, weight_decay: float = 5e-4, seed: int = 0, threads: int = 1,
           time_budget_s: float | None = None, ckpt_every_s: float = 60.0, log_every: int = 10,
           init_from: str | None = None, resume: bool = True, progress: bool = True,
           max_gap: int = 50) -> dict:
    from ..checkpoint import check_run_folder, flag_differences, load_checkpoint_dict, refuse_other_data, \
        refuse_other_flags

    out = check_run_folder(out_dir)   # made once every input is read and checked (no empty run folder)
    lock.acquire(out)   # a run folder that exists: before anything in it is read or changed
    torch.set_num_threads(check_threads(threads))
    torch.manual_seed(seed)
    ck_path, log_path = out / "ckpt.pt", out / "log.jsonl"
    net = SiamFC(cfg)
    opt = torch.optim.SGD(net.parameters(), lr=lr, momentum=0.9, weight_decay=weight_decay)
    gamma = (lr_end / lr) ** (1.0 / max(steps, 1))
    step, elapsed0 = 0, 0.0
    acc, nacc = 0.0, 0
    sampler = PairSampler(CropCache(cache_dir), cfg.exemplar_size, cfg.train_instance_size,
                          max_gap=max_gap, seed=seed)
    from .data import cache_data_info

    data_info = cache_data_info(cache_dir)   # the training data's identity, for the export

    settings = {"batch": batch, "lr": lr, "lr_end": lr_end, "weight_decay": weight_decay, "seed": seed,
                "max_gap": max_gap}

    def checkpoint(elapsed):
        save_checkpoint(ck_path, {"model": net.state_dict(), "optim": opt.state_dict(), "step": step,
                                  "config": cfg.to_dict(), "elapsed_s": elapsed, "steps_planned": steps,
                                  **settings, "random": random_state(sampler.rng),
                                  "log_acc": [acc, nacc], **data_info})

    if resume and ck_path.is_file():
        ck = load_checkpoint_dict(ck_path, "SiamFC")
        # another cache, network or flags: one line (they had been taken in silence, or ended in a
        # size-mismatch traceback); the cache by its data's hash
        refuse_other_data(ck_path, cache_dir, ck.get("train_data_hash"), data_info["train_data_hash"])
        refuse_other_flags(ck_path, _other_network(ck.get("config"), cfg)
                           + flag_differences(ck, settings, RESUME_FLAGS))
        ck_elapsed = float(ck.get("elapsed_s", 0.0))
        if int(ck["step"]) >= steps or (time_budget_s is not None and ck_elapsed >= time_budget_s):
            # a finished run stays finished, its files as they are (it had trained one more step)
            stopped = "steps" if int(ck["step"]) >= steps else "time budget"
            print(f"{ck_path}: the run is finished (step {int(ck['step'])}, {ck_elapsed / 60:.1f} min trained; its "
                  f"{'step cap' if stopped == 'steps' else 'time budget'} reached): nothing to do")
            return {"step": int(ck["step"]), "stopped": stopped, "elapsed_s": ck_elapsed, "checkpoint": str(ck_path)}
        net.load_state_dict(ck["model"])
        opt.load_state_dict(ck["optim"])
        step, elapsed0 = int(ck["step"]), float(ck.get("elapsed_s", 0.0))
        if "random" in ck:   # the sampler's and torch's streams go on as if never stopped
            restore_random_state(sampler.rng, ck["random"])
        else:                # a checkpoint from before they were saved
            sampler.rng = np.random.default_rng([seed, step])
            torch.manual_seed(seed + step)
        acc, nacc = ck.get("log_acc", (0.0, 0))   # the log interval the checkpoint fell in, part summed
        trim_log(log_path, step)   # rows logged after the checkpoint (a kill between checkpoints)
        print(f"resumed from {ck_path} at step {step}")
    elif init_from:
        src = load_checkpoint_dict(init_from, "SiamFC")
        other = _other_network(src.get("config"), cfg)
        if other:   # a size-mismatch traceback before
            raise ValueError(f"{init_from} is a SiamFC of another network than this run's: pass {' '.join(other)} "
                             "to start from it")
        net.load_state_dict(src["model"])
        print(f"initialised from {init_from} (step {src.get('step')})")
        if log_path.exists():
            log_path.unlink()
    elif log_path.exists():
        log_path.unlink()
    out.mkdir(parents=True, exist_ok=True)
    lock.acquire(out)
    net.train()
    r_pos_cells = cfg.r_pos / cfg.total_stride
    t_start = time.perf_counter()
    last_ck = t_start
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=steps, initial=step, desc=f"siamfc-{cfg.variant}", unit="step")
    stopped = "steps"
    # SIGTERM / SIGINT: a checkpoint at the next step boundary, then TrainingInterrupted
    with open(log_path, "a") as log, StopOnSignal() as stop:
        while step < steps:
            for g in opt.param_groups:
                g["lr"] = lr * gamma ** step
            z, x = sampler.sample(batch)
            zt, xt = net.normalise(torch.from_numpy(z)), net.normalise(torch.from_numpy(x))
            logits = net(zt, xt)
            loss = balanced_bce(logits, r_pos_cells)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            step += 1
            acc += float(loss.detach())
            nacc += 1
            if bar:
                bar.update(1)
                bar.set_postfix(loss=f"{float(loss):.3f}")
            now = time.perf_counter()
            elapsed = elapsed0 + now - t_start
            if step % log_every == 0 or step == steps:
                log.write(json.dumps({"step": step, "loss": acc / nacc, "lr": opt.param_groups[0]["lr"],
                                      "elapsed_s": round(elapsed, 2)}) + "\n")
                log.flush()
                acc, nacc = 0.0, 0
            budget_hit = time_budget_s is not None and elapsed >= time_budget_s
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
    checkpoint(elapsed0 + time.perf_counter() - t_start)
    if stopped == "interrupted":
        raise stop.interrupted(step, ck_path)
    try:
        plot_log(log_path, out / "loss.png", f"SiamFC {cfg.variant}")
    except Exception as e:  # plotting is a convenience
        print(f"loss plot failed: {e}")
    summary = {"step": step, "stopped": stopped, "elapsed_s": elapsed0 + time.perf_counter() - t_start,
               "checkpoint": str(ck_path)}
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=1))
    return summary
