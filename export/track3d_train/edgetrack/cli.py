"""`track3d-train edgetrack prepare|train|export|eval|fit-threshold|time`: the EdgeTrack pipeline.

    track3d-train edgetrack prepare --data DATA --out CACHE
    track3d-train edgetrack train   --cache CACHE --out RUN --time-budget-min 180   # resumes from RUN/ckpt.pt
    track3d-train edgetrack export  --checkpoint RUN/ckpt.pt --out runtime/track3d/models/edgetrack --force
    track3d-train edgetrack eval    --model runtime/track3d/models/edgetrack --data DATA --split test --compare siamfc-edge
    track3d-train edgetrack time    --model runtime/track3d/models/edgetrack --pin
    track3d-train edgetrack fit-threshold --model runtime/track3d/models/edgetrack --data data/engine-calib data/engine-calib2 \\
        --split train --motion-grid 0,0.5,1,1.5 --write --force   # motion weight, lost threshold: held-out sequences

The long-run recipe (resumable) is `track3d-train recipe run edgetrack-engine`;
the shipped short-run model is described in docs/models.md.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from track3d.argparsing import ArgumentParser, apply_formatter, bounded, hidden_alias, thread_count


def _prepare(a) -> int:
    from .data import prepare

    if not a.synthetic and not a.data:
        raise ValueError("give --data ROOT (a dataset) or --synthetic N")
    t0 = time.perf_counter()
    info = prepare(a.out, data=a.data, split=a.split, synthetic=a.synthetic, synthetic_frames=a.synthetic_frames,
                   max_frames=a.max_frames, max_background=a.max_background, seed=a.seed, progress=not a.quiet,
                   pad=a.pad)
    print(f"cache {a.out}: {info['target_crops']} target crops, {info['background_crops']} background crops "
          f"in {time.perf_counter() - t0:.0f} s")
    return 0


def _train(a) -> int:
    from .model import EdgeTrackConfig
    from .train import train

    if not (Path(a.cache) / "target" / "index.json").is_file():
        raise ValueError(f"{a.cache} is no EdgeTrack cache (run `track3d-train edgetrack prepare` first)")
    cfg = EdgeTrackConfig()
    print(f"EdgeTrack: widths {cfg.widths}, crops {cfg.exemplar_size}/{cfg.instance_size}, batch {a.batch}, "
          f"{a.steps} steps, {a.threads} thread(s)")
    s = train(cfg, a.cache, a.out, steps=a.steps, batch=a.batch, lr=a.lr, seed=a.seed, threads=a.threads,
              time_budget_s=a.time_budget_min * 60 if a.time_budget_min else None,
              ckpt_every_s=a.ckpt_every_min * 60, val_every=a.val_every, max_gap=a.max_gap,
              resume=not a.no_resume, init_from=a.init_from, border_cut=a.border_cut, progress=not a.quiet)
    print(json.dumps(s))
    return 0


def _export(a) -> int:
    import dataclasses

    from ..onnx_meta import refuse_existing, refuse_shipped, remove_stale_twins
    from .export import export_onnx, parity
    from .train import load_checkpoint

    if not a.checkpoint:
        raise ValueError("give --checkpoint CKPT (an EdgeTrack ckpt.pt)")
    if Path(a.out).is_dir():
        raise ValueError(f"--out {a.out} is a folder: give a path prefix (e.g. {Path(a.out) / 'edgetrack'} writes "
                         f"edgetrack_template.onnx and edgetrack_search.onnx in it)")
    outs = [Path(f"{a.out}_template.onnx"), Path(f"{a.out}_search.onnx")]
    refuse_shipped(outs, a.force)
    twins = refuse_existing(outs, a.force)   # they had been overwritten without a word
    net, ck = load_checkpoint(a.checkpoint)
    over = {k: getattr(a, k) for k in ("window_influence", "penalty_k", "size_lr", "score_threshold",
                                       "instance_size", "lost_instance_size") if getattr(a, k) is not None}
    if over:
        net.cfg = dataclasses.replace(net.cfg, **over)
    ident = {k: ck.get(k) for k in ("train_data_hash", "train_data")}
    if ident["train_data_hash"] is None and a.cache:       # a checkpoint from before it recorded them
        from ..siamfc.data import cache_data_info
        from .data import MAKER
        ident = cache_data_info(Path(a.cache) / "target", MAKER)
    if ident["train_data_hash"] is None:
        raise ValueError(f"{a.checkpoint} does not record its training data: give --cache (the run's cache folder)")
    data = a.data_note or ident["train_data"] or "track3d simulator train split"
    extra = {"train_data": data, "train_data_hash": ident["train_data_hash"],
             "training": {"steps": ck.get("step"), "batch": ck.get("batch"), "seed": ck.get("seed"),
                          "elapsed_s": round(float(ck.get("elapsed_s", 0)), 1), "data": data,
                          "border_cut": float(ck.get("border_cut", 0.0))}}
    if ck.get("init_from"):            # a fine-tune: the model it started from
        extra["training"]["fine_tuned_from"] = ck["init_from"]
    if ck.get("pad") is not None:     # the colour the runtime's crop fills outside the image with
        extra["pad"] = [float(v) for v in ck["pad"]]
    p: dict = {}
    pz, px = export_onnx(net, a.out, extra, check=lambda z, x: p.update(parity(net, z, x)))
    remove_stale_twins(twins)   # the int8 files of the pair just replaced: its old weights
    print(f"wrote {pz} ({pz.stat().st_size / 1e3:.0f} kB), {px} ({px.stat().st_size / 1e3:.0f} kB)")
    print("parity torch vs onnxruntime:", json.dumps(p))
    return 0


def _eval(a) -> int:
    """One pass of the model (and --compare trackers) through the runtime's evaluation toolkit."""
    from track3d.evaluation import TrackerSpec, evaluate_2d

    specs = [TrackerSpec(name, "none", threads=a.threads) for name in a.compare]
    if a.model:
        specs.insert(0, TrackerSpec("edgetrack", "none", threads=a.threads, tracker_options={"model": a.model},
                                    name=f"model {Path(a.model).name}"))
    elif "edgetrack" not in a.compare:
        # without --model the shipped pair is the model under test (it once evaluated nothing and
        # wrote a report of zero sequences)
        specs.insert(0, TrackerSpec("edgetrack", "none", threads=a.threads))
    from track3d.jsonable import jsonable, write_json

    rows = evaluate_2d(a.data, a.split, specs, max_sequences=a.max_sequences or None, quiet=a.quiet)
    if a.json:
        print(json.dumps(jsonable(rows), indent=1))   # a missing number (nan) is null: JSON has no NaN
    else:
        from track3d.evaluation.tables import tracker_2d_table

        print(tracker_2d_table(rows))
    if a.out:
        sequences = next(iter(rows.values()))["sequences"] if rows else 0
        write_json(a.out, {"data_split": a.split, "sequences": sequences, "trackers": rows})
    return 0


def _pad(text: str):
    from track3d.edgetrack import pad_colour

    if text.strip().lower() == "mean":
        return None
    try:
        return pad_colour(text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected R,G,B in 0..255 or 'mean', got {text!r}") from None


def _grid(text: str) -> list[float]:
    try:
        return [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def _fit_threshold(a) -> int:
    from ..onnx_meta import refuse_shipped
    from .threshold import fit_motion, fit_reacquire, fit_threshold, write_threshold

    if a.write:
        refuse_shipped([Path(f"{a.model}_template.onnx"), Path(f"{a.model}_search.onnx")], a.force, "--model")
    if a.split.startswith("test"):
        raise ValueError(f"fit the threshold on held-out train-like sequences, not on a test split ({a.split!r})")
    motion = None
    if a.motion_grid:
        mfit = fit_motion(a.model, a.data, a.split, a.motion_grid, threads=a.threads,
                          max_sequences=a.max_sequences or None, quiet=a.quiet)
        print(f"{'motion':>9} {'AO_2d':>6} {'precision':>9} {'recall':>6}")
        for r in mfit["rows"]:
            print(f"{r['motion']:9.3g} {r['ao_2d']:6.3f} {r['lost_precision']:9.3f} {r['lost_recall']:6.3f}")
        motion = mfit["motion"]
        print(f"best motion: {motion:g}")
    fit = fit_threshold(a.model, a.data, a.split, a.grid, threads=a.threads,
                        max_sequences=a.max_sequences or None, quiet=a.quiet, motion=motion)
    print(f"{'threshold':>9} {'F1':>5} {'precision':>9} {'recall':>6} {'AO_2d':>6}")
    for r in fit["rows"]:
        print(f"{r['threshold']:9.3g} {r['f1']:5.3f} {r['lost_precision']:9.3f} {r['lost_recall']:6.3f} {r['ao_2d']:6.3f}")
    print(f"best: {fit['threshold']:g}")
    reacquire = None
    if a.reacquire_grid:
        rfit = fit_reacquire(a.model, a.data, a.split, a.reacquire_grid, fit["threshold"], threads=a.threads,
                             max_sequences=a.max_sequences or None, quiet=a.quiet, motion=motion)
        print(f"{'reacquire':>9} {'F1':>5} {'precision':>9} {'recall':>6} {'AO_2d':>6}")
        for r in rfit["rows"]:
            print(f"{r['reacquire_threshold']:9.3g} {r['f1']:5.3f} {r['lost_precision']:9.3f} "
                  f"{r['lost_recall']:6.3f} {r['ao_2d']:6.3f}")
        reacquire = rfit["reacquire_threshold"]
        print(f"best re-acquisition threshold: {reacquire:g}")
    if a.write:
        from track3d_train.boxnet.data import split_hash
        from track3d.dataset import Dataset

        note = {"data": [Path(d).name for d in a.data], "split": a.split,
                "data_hash": [split_hash(Dataset(d), a.split) for d in a.data],
                "criterion": "F1 of lost vs absent frames, one pass; AO_2d breaks ties", "rows": fit["rows"]}
        if motion is not None:
            note["motion"] = {"criterion": "one-pass AO_2d at the model's threshold", "rows": mfit["rows"]}
        if reacquire is not None:
            note["reacquire"] = {"criterion": "F1 of lost vs absent frames, one pass, at the fitted threshold; "
                                              "AO_2d, then the lower value, break ties", "rows": rfit["rows"]}
        for p in write_threshold(a.model, fit["threshold"], note, motion=motion, reacquire=reacquire):
            print(f"wrote the {'motion weight and ' if motion is not None else ''}threshold"
                  f"{' and the re-acquisition threshold' if reacquire is not None else ''} into {p}")
    return 0


def _time(a) -> int:
    """Median ms of the networks and the crop at a thread count, EdgeTrack vs SiamFC-edge,
    interleaved in one process (ratios hold under load, absolute numbers do not)."""
    import os

    import numpy as np

    from track3d.onnxmodel import OnnxModel
    from track3d.siamfc import crop_square, model_paths

    if a.pin and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})
    rng = np.random.default_rng(0)
    et_z, et_x = OnnxModel(f"{a.model}_template.onnx", a.threads), OnnxModel(f"{a.model}_search.onnx", a.threads)
    sz, sx = (OnnxModel(p, a.threads) for p in model_paths("edge"))
    n_et, n_sf = int(et_x.meta["instance_size"]), int(sx.meta["instance_size"])
    n_lost = int(et_x.meta["lost_instance_size"])
    ez = int(et_x.meta["exemplar_size"])
    kern = et_z.run({"template": rng.integers(0, 256, (1, ez, ez, 3), dtype=np.uint8)})[0]
    feat = sz.run({"exemplar": rng.integers(0, 256, (1, 127, 127, 3), dtype=np.uint8)})[0]
    image = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
    jobs = {
        f"edgetrack search {n_et}": lambda: et_x.run({"search": image[None, :n_et, :n_et].copy(), "kernel": kern}),
        f"edgetrack search lost {n_lost}": lambda: et_x.run({"search": image[None, :n_lost, :n_lost].copy(), "kernel": kern}),
        f"siamfc-edge search {n_sf}": lambda: sx.run({"search": image[None, :n_sf, :n_sf].copy(), "exemplar_feature": feat}),
        f"crop {n_et} of a 300 px region": lambda: crop_square(image, np.array([320.0, 240.0]), 300.0, n_et, (9, 9, 9)),
        f"crop {n_sf} of a 300 px region": lambda: crop_square(image, np.array([320.0, 240.0]), 300.0, n_sf, (9, 9, 9)),
    }
    times = {k: [] for k in jobs}
    for _ in range(a.repeats):
        for k, f in jobs.items():
            t0 = time.perf_counter()
            f()
            times[k].append(1e3 * (time.perf_counter() - t0))
    out = {k: round(float(np.median(v[3:])), 3) for k, v in times.items()}
    out["threads"], out["pinned"], out["repeats"] = a.threads, bool(a.pin), a.repeats
    print(json.dumps(out, indent=1))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="track3d-train edgetrack", description=__doc__)
    sub = p.add_subparsers(dest="cmd", required=True)
    d = argparse.ArgumentDefaultsHelpFormatter

    q = sub.add_parser("prepare", help="crop target and background caches once", formatter_class=d)
    q.add_argument("--data", nargs="+", help="dataset root(s) (dataset.json); several are concatenated")
    q.add_argument("--split", default="train", help="dataset split")
    q.add_argument("--out", required=True, help="cache folder")
    q.add_argument("--max-frames", type=bounded(int, 1), default=3000, help="bound on target crops (442 kB each)")
    q.add_argument("--max-background", type=bounded(int, 0), default=1000, help="bound on background crops")
    q.add_argument("--synthetic", type=bounded(int, 0), default=0, help="N synthetic sequences instead of a dataset")
    q.add_argument("--synthetic-frames", type=bounded(int, 2), default=60, help="frames per synthetic sequence")
    q.add_argument("--seed", type=bounded(int, 0), default=0, help="random seed")
    q.add_argument("--pad", type=_pad, default="255,0,255",
                   help="colour of everything outside the image, R,G,B in 0..255 (the exported model "
                        "carries it to the runtime's crop), or 'mean': each frame's mean colour")
    q.add_argument("--quiet", action="store_true", help="no progress bar")
    hidden_alias(q, "--no-progress", "quiet", action="store_true")
    q.set_defaults(fn=_prepare)

    t = sub.add_parser("train", help="train (resumes from <out>/ckpt.pt)", formatter_class=d)
    t.add_argument("--cache", required=True, help="cache folder from `prepare`")
    t.add_argument("--out", required=True, help="run folder: ckpt.pt, log.jsonl, curves.json/png")
    t.add_argument("--max-steps", dest="steps", type=bounded(int, 1), default=20000, metavar="N",
                   help="step cap; the cosine LR ends here or at the time budget, whichever comes first")
    hidden_alias(t, "--steps", "steps", type=bounded(int, 1))  # the name before --max-steps
    t.add_argument("--batch", type=bounded(int, 1), default=32, help="pairs per step")
    t.add_argument("--lr", type=bounded(float, above=0), default=3e-3, help="peak AdamW learning rate")
    t.add_argument("--max-gap", type=bounded(int, 1), default=50, help="max frame gap of a pair")
    t.add_argument("--val-every", type=bounded(int, 1), default=200, help="steps between validations")
    t.add_argument("--ckpt-every-min", type=bounded(float, above=0), default=3.0, help="minutes between atomic checkpoints (SIGTERM / Ctrl-C writes one too)")
    t.add_argument("--seed", type=bounded(int, 0), default=0, help="random seed")
    t.add_argument("--threads", type=thread_count, default=1, help="torch threads")
    t.add_argument("--time-budget-min", type=bounded(float, above=0), default=None,
                   help="stop (and checkpoint) after this many minutes of training, summed over resumed runs "
                        "(default: none, only --max-steps)")
    t.add_argument("--init-from", help="start from another run's checkpoint or from an exported pair (a prefix, "
                                       "either .onnx file, or a shipped name such as edgetrack): fine-tuning "
                                       "(default: none, random weights; ignored when the run resumes)")
    t.add_argument("--border-cut", type=bounded(float, low=0.0, high=1.0), default=0.0,
                   help="share of target pairs cut at a simulated image border (slivers of a body leaving "
                        "the view; a resumed run keeps its own)")
    t.add_argument("--no-resume", action="store_true", help="start over even if <out>/ckpt.pt exists")
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    hidden_alias(t, "--no-progress", "quiet", action="store_true")
    t.set_defaults(fn=_train)

    e = sub.add_parser("export", help="write <out>_template.onnx + <out>_search.onnx, check parity", formatter_class=d)
    e.add_argument("--checkpoint", help="ckpt.pt of an EdgeTrack run; required")
    hidden_alias(e, "--ckpt", "checkpoint")
    e.add_argument("--out", required=True, help="path prefix")
    e.add_argument("--force", action="store_true",
                   help="overwrite files that exist at --out (the shipped models in track3d/models too)")
    e.add_argument("--data-note", default=None,
                   help="what the model was trained on (metadata; default: the data name the checkpoint records, "
                        "else 'track3d simulator train split')")
    e.add_argument("--cache", default=None,
                   help="the run's cache folder: the training data's hash for checkpoints that do not record it "
                        "(default: none, the checkpoint's own record)")
    # bounds: a value the runtime cannot use must not be written into a model file
    unit = bounded(float, 0, high=1)
    for k, ty in (("window-influence", unit), ("penalty-k", bounded(float, 0)), ("size-lr", unit),
                  ("score-threshold", unit), ("instance-size", bounded(int, 1)), ("lost-instance-size", bounded(int, 1))):
        e.add_argument(f"--{k}", type=ty, default=None, help="tracking default stored in the metadata (default: the config's)")
    e.set_defaults(fn=_export)

    v = sub.add_parser("eval", help="one-pass AO_2d + lost precision/recall on a split", formatter_class=d)
    v.add_argument("--model", help="prefix of <name>_template/_search.onnx (default: the shipped pair)")
    v.add_argument("--data", required=True, help="dataset root")
    v.add_argument("--split", default="test", help="dataset split")
    v.add_argument("--compare", nargs="*", default=[], help="registered 2D trackers to run on the same frames")
    v.add_argument("--max-sequences", type=bounded(int, 0), default=0, help="only the first N sequences (0: all)")
    hidden_alias(v, "--max-seqs", "max_sequences", type=bounded(int, 0))
    v.add_argument("--threads", type=thread_count, default=1, help="onnxruntime threads")
    v.add_argument("--out", help="also write the numbers to this JSON file")
    v.add_argument("--json", action="store_true", help="print every number as JSON instead of the table")
    v.add_argument("--quiet", action="store_true", help="no progress bar")
    v.set_defaults(fn=_eval)

    f = sub.add_parser("fit-threshold", help="fit the lost threshold one pass on held-out sequences; --write stores it",
                       formatter_class=d)
    f.add_argument("--model", required=True, help="prefix of <name>_template/_search.onnx")
    f.add_argument("--data", required=True, nargs="+",
                   help="dataset root(s) with absent frames, pooled (not the training data, not a test split)")
    f.add_argument("--split", default="train", help="dataset split (a test split is refused)")
    f.add_argument("--grid", type=_grid, default=[0.02, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7],
                   help="comma-separated candidate thresholds in (0, 1)")
    f.add_argument("--motion-grid", type=_grid, default=None,
                   help="comma-separated candidate motion weights in [0, 2], chosen first by one-pass AO_2d "
                        "(default: keep the model's)")
    f.add_argument("--reacquire-grid", type=_grid, default=None,
                   help="comma-separated candidate re-acquisition thresholds (the score a lost tracker needs to "
                        "take a candidate; at least the lost threshold), fitted after it by the same F1 "
                        "(default: keep the model's)")
    f.add_argument("--max-sequences", type=bounded(int, 0), default=0, help="only the first N sequences (0: all)")
    f.add_argument("--threads", type=thread_count, default=1, help="onnxruntime threads")
    f.add_argument("--write", action="store_true", help="write the best threshold (and motion, re-acquisition threshold) into the model's metadata")
    f.add_argument("--force", action="store_true", help="allow --write on the shipped models in track3d/models")
    f.add_argument("--quiet", action="store_true", help="no progress bar")
    f.set_defaults(fn=_fit_threshold)

    m = sub.add_parser("time", help="median ms of the nets and crops vs SiamFC-edge, interleaved", formatter_class=d)
    m.add_argument("--model", required=True, help="prefix of <name>_template/_search.onnx")
    m.add_argument("--threads", type=thread_count, default=1, help="onnxruntime threads")
    m.add_argument("--repeats", type=bounded(int, 4), default=200, help="calls of each, interleaved (>= 4: the first 3 are warm-up)")
    m.add_argument("--pin", action="store_true", help="pin the process to one core")
    m.set_defaults(fn=_time)
    return apply_formatter(p)


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    return int(a.fn(a) or 0)


if __name__ == "__main__":
    sys.exit(main())
