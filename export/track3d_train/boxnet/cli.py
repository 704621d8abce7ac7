"""`track3d-train boxnet`: prepare the frustum caches, train, export and evaluate A3BoxNet.

Typical run (a model of your own, written under runs/mine; see docs/models.md):

    track3d-train boxnet prepare --data data/small --split train --jitters 5 --out runs/mine/cache/train.npz
    track3d-train boxnet prepare --data data/small --split test --jitters 0 --out runs/mine/cache/test.npz
    track3d-train boxnet train --cache runs/mine/cache/train.npz --no-category --size-norm extent --out runs/mine/run
    track3d-train boxnet export --checkpoint runs/mine/run/best.pt --out runs/mine/a3boxnet.onnx
    track3d-train boxnet eval --model runs/mine/a3boxnet.onnx --cache runs/mine/cache/test.npz

The shipped models come from recipes, not from this run: `track3d-train recipe run
a3boxnet-engine` makes a3boxnet.onnx (`track3d-train recipe list` names the others).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from track3d.argparsing import ArgumentParser, apply_formatter, bounded, hidden_alias, thread_count
from track3d.size_coding import SIZE_CODINGS


# --num-points' bound: 16x the paper's 1024 (and 2x prepare's default --max-points). 100000 had run
# until the kernel killed it (24 GB).
MAX_NUM_POINTS = 16384


def _log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


def _sensor_list(text: str) -> tuple[str, ...]:
    """--sensors A,B -> ("a", "b"): names of track3d.sensor_options.DEPTH_SENSORS."""
    from track3d.sensor_options import DEPTH_SENSORS

    names = tuple(dict.fromkeys(n.strip().lower() for n in text.split(",") if n.strip()))
    bad = [n for n in names if n not in DEPTH_SENSORS]
    if not names or bad:
        raise argparse.ArgumentTypeError(f"depth sensors from {', '.join(DEPTH_SENSORS)}, got {text!r}")
    return names


def _prepare(a) -> int:
    from .data import JitterSpec, prepare_split

    spec = JitterSpec(a.center_sigma, a.scale_sigma, a.aspect_sigma, a.fail_prob)
    t = time.time()
    p = prepare_split(a.data, a.split, a.out, jitters=a.jitters, oracle=not a.no_oracle, max_points=a.max_points,
                      min_points=a.min_points, spec=spec, seed=a.seed, max_sequences=a.max_sequences,
                      frame_step=a.frame_step, progress=not a.quiet, stereo_match=a.stereo_match,
                      past_views=a.past_views, sensors=a.sensors)
    from .data import PointCache
    c = PointCache(p)
    _log(f"wrote {p}: {len(c)} frustums from {len(set(c.seq.tolist()))} sequences in {time.time() - t:.0f} s")
    print(p)
    return 0


def _train(a) -> int:
    from .train import TrainConfig, train

    if len(a.stretch_aug) not in (1, 3):
        raise ValueError(f"--stretch-aug takes one sigma or three (x y z), got {len(a.stretch_aug)}")
    stretch = a.stretch_aug[0] if len(a.stretch_aug) == 1 else tuple(a.stretch_aug)

    cfg = TrainConfig(train_cache=[str(c) for c in a.cache], out=str(a.out), num_points=a.num_points, width=a.width,
                      use_category=not a.no_category, size_norm=a.size_norm, epochs=a.epochs,
                      epoch_samples=a.epoch_samples, batch=a.batch, lr=a.lr, flip=not a.no_flip,
                      cat_dropout=a.cat_dropout, flip_y=a.flip_y, scale_aug=a.scale_aug, stretch_aug=stretch,
                      val_every=a.val_every, seed=a.seed, threads=a.threads, max_minutes=a.max_minutes,
                      max_steps=a.max_steps, distill_from=a.distill_from or "", distill_weight=a.distill_weight,
                      iou_weight=a.iou_weight)
    _log(f"training A3BoxNet into {a.out}: {cfg}")
    h = train(cfg, resume=not a.no_resume, progress=not a.quiet, log=_log, init_from=a.init_from)
    full = sum(not e.get("partial") for e in h["epochs"])
    cut = next((e for e in h["epochs"] if e.get("partial")), None)
    part = f" and {cut['batches']} of {cut['of']} batches of epoch {cut['epoch']}" if cut else ""
    _log(f"done: {full} epochs{part}, {h['seconds'] / 60:.1f} min; curve in {Path(a.out) / 'loss_curve.png'}")
    return 0


def _export(a) -> int:
    from .export import export_checkpoint

    from ..onnx_meta import refuse_existing, refuse_shipped, remove_stale_twins

    if not a.ckpt:
        raise ValueError("give --checkpoint CKPT (an A3BoxNet best.pt / last.pt)")
    if Path(a.out).is_dir():   # it had been IsADirectoryError's traceback, after the whole export
        raise ValueError(f"--out {a.out} is a folder: give the ONNX file to write (e.g. {Path(a.out) / 'a3boxnet.onnx'})")
    refuse_shipped([Path(a.out)], a.force)
    twins = refuse_existing([Path(a.out)], a.force)   # it had been overwritten without a word
    try:
        meta = export_checkpoint(a.ckpt, a.out, check=not a.no_parity, log=_log, depth_sensor=a.depth_sensor)
    finally:
        # the int8 twin of the model just replaced (its old weights), also when the parity check
        # inside fails after the write; a twin of a file left as it was is kept (made_from)
        remove_stale_twins(twins)
    if a.meta_json:
        Path(a.meta_json).write_text(json.dumps(meta, indent=1))
    return 0


def _eval(a) -> int:
    import numpy as np

    from track3d.boxnet import A3BoxNetEstimator
    from track3d.jsonable import jsonable, write_json

    from .data import PointCache
    from .evaluate import onnx_runner, oracle_metrics, predict

    cache = PointCache(a.cache)
    if not a.all_boxes:
        cache = cache.subset(np.nonzero(cache.jittered == 0)[0])
    est = A3BoxNetEstimator(a.model, threads=a.threads)
    n = a.num_points or est.num_points
    t = time.time()
    pred = predict(onnx_runner(est), cache, n, est.num_categories, seed=a.seed, size_norm=est.size_norm)
    res = {"model": str(a.model), "num_points": n, "cache": str(a.cache),
           "a3boxnet": oracle_metrics(pred, cache.field("gt3d"), cache.field("seq")),
           "baseline": oracle_metrics(cache.field("baseline"), cache.field("gt3d"), cache.field("seq")),
           "seconds": time.time() - t}
    print(json.dumps(jsonable(res), indent=1))   # a missing number (nan) is null: JSON has no NaN
    if a.out:
        write_json(a.out, res)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="track3d-train boxnet", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)

    q = sub.add_parser("prepare", help="cut the frustum proposals of a split once into a .npz cache",
                       description="Frustum proposals (runtime frustum code) from ground-truth 2D boxes and "
                                   "jittered copies (a 2D tracker's errors), subsampled, with labels.")
    q.add_argument("--data", required=True, help="dataset root (with dataset.json)")
    q.add_argument("--split", default="train", help="split name (train / test / test_unseen; default train)")
    q.add_argument("--out", default="runs/boxnet/cache", help="a folder (file named by the data hash) or a .npz")
    q.add_argument("--jitters", type=bounded(int, 0), default=5, help="jittered boxes per frame (0 for the oracle test set)")
    q.add_argument("--no-oracle", action="store_true", help="do not also keep the exact ground-truth box")
    q.add_argument("--max-points", type=bounded(int, 1), default=4096, help="points stored per frustum (random subset)")
    q.add_argument("--min-points", type=bounded(int, 1), default=16, help="skip frustums with fewer points")
    q.add_argument("--center-sigma", type=bounded(float, 0), default=0.1, help="centre shift std, fraction of w / h")
    q.add_argument("--scale-sigma", type=bounded(float, 0), default=0.1, help="log-scale std (shared by w and h)")
    q.add_argument("--aspect-sigma", type=bounded(float, 0), default=0.05, help="log-aspect std")
    q.add_argument("--fail-prob", type=bounded(float, 0, high=1), default=0.1, help="probability of a 3x larger error")
    q.add_argument("--frame-step", type=bounded(int, 1), default=1, metavar="K", help="use every k-th frame")
    q.add_argument("--stereo-match", type=bounded(int, 0), default=None, metavar="MAX_PX",
                   help="clouds matched from the stereo pair around each box as the loop's StereoCloud does "
                        "(`track3d track --depth stereo`), with --stereo-option max_match_px=MAX_PX (0: every row "
                        "matched); default: the dataset's depth maps")
    q.add_argument("--past-views", action="store_true",
                   help="each frustum also holds the body's past views in its frame, as the loop gives them to "
                        "a model trained with them (track3d.boxnet.PAST_VIEWS; every frame is read in order)")
    q.add_argument("--sensors", type=_sensor_list, default=None, metavar="A,B",
                   help="only the sequences of these depth sensors (from ideal, tof, flash-lidar, stereo; default: "
                        "every sequence): a sensor's own model from a mixed set")
    q.add_argument("--max-sequences", type=bounded(int, 1), default=None, help="only the first k sequences")
    q.add_argument("--seed", type=bounded(int, 0), default=0, help="jitter / subsampling seed")
    q.add_argument("--quiet", action="store_true", help="no progress bar")
    hidden_alias(q, "--no-progress", "quiet", action="store_true")
    q.set_defaults(func=_prepare)

    t = sub.add_parser("train", help="train (resumes from <out>/last.pt)",
                       description="Adam, batch 32, cosine LR, checkpoints every epoch (last.pt, best.pt by "
                                   "validation AO_3d on held-out train sequences), history.json, loss_curve.png.")
    t.add_argument("--cache", required=True, nargs="+", help="training .npz file(s) from `prepare` (several are concatenated)")
    t.add_argument("--out", default="runs/boxnet/main", help="run folder")
    t.add_argument("--num-points", type=bounded(int, 1, high=MAX_NUM_POINTS), default=512,
                   help="N input points (paper: 1024); at most the points the cache stores per frustum "
                        "(prepare --max-points)")
    t.add_argument("--width", type=bounded(float, above=0), default=1.0, help="channel multiplier (1 = Frustum PointNets v1)")
    t.add_argument("--no-category", action="store_true", help="ablation: no one-hot category vector")
    t.add_argument("--size-norm", choices=list(SIZE_CODINGS), default="points",
                   help="box coding (track3d.size_coding): (template + r) * L of the input points (points), the "
                        "same with the label normalised by max(size) (paper), E * (1 + r) with E the points' "
                        "per-axis extents (extent), or with x / y from the whole frustum's box (frustum)")
    t.add_argument("--epochs", type=bounded(int, 1), default=25, help="planned epochs (the LR schedule spans them)")
    t.add_argument("--epoch-samples", type=bounded(int, 0), default=0,
                   help="items per epoch, drawn at random (0: the whole cache); capped at the cache's training "
                        "items (the validation sequences held out): more gives one pass over them, said once "
                        "in the log")
    t.add_argument("--batch", type=bounded(int, 1), default=32, help="batch size")
    t.add_argument("--lr", type=bounded(float, above=0), default=1e-3, help="initial learning rate")
    t.add_argument("--no-flip", action="store_true", help="no random x-mirroring")
    t.add_argument("--cat-dropout", type=bounded(float, 0, high=1), default=0.1,
                   help="probability of an all-zero (unknown, -1) category vector in training")
    t.add_argument("--flip-y", action="store_true", help="also mirror y at random")
    t.add_argument("--scale-aug", type=bounded(float, 0), default=0.0,
                   help="sigma of a random log scale of points and box about the camera centre (e.g. 0.15)")
    t.add_argument("--stretch-aug", type=bounded(float, 0), nargs="+", default=[0.0], metavar="SIGMA",
                   help="sigma of a random per-axis log stretch of points and box about the box centre "
                        "(other body proportions, e.g. 0.3); three values: x, y, z (e.g. 0.3 0.3 0.5)")
    t.add_argument("--init-from", default=None,
                   help="start from these A3BoxNet weights: a checkpoint (.pt) or an exported model (.onnx; a bare "
                        "name such as a3boxnet.onnx is the shipped model) (fine-tuning; default: random); a wider "
                        "model is cut to --width, keeping its most important channels")
    t.add_argument("--distill-from", default=None, metavar="ONNX_OR_PT",
                   help="a teacher A3BoxNet (.onnx, a bare name such as a3boxnet.onnx = the shipped one, or .pt) "
                        "whose outputs the net also learns, on the same augmented inputs (default: none)")
    t.add_argument("--distill-weight", type=bounded(float, 0), default=1.0,
                   help="weight of the teacher term (losses.distill_loss) when --distill-from is given")
    t.add_argument("--iou-weight", type=bounded(float, 0), default=0.0,
                   help="add this weight times 1 - IoU_3d of the decoded box to the paper's joint loss "
                        "(default 0: the paper's loss alone); not with --size-norm paper")
    t.add_argument("--val-every", type=bounded(int, 0), default=8, help="every k-th train sequence is validation (0: none)")
    t.add_argument("--seed", type=bounded(int, 0), default=0, help="seed")
    t.add_argument("--threads", type=thread_count, default=1, help="torch threads")
    t.add_argument("--time-budget-min", dest="max_minutes", type=bounded(float, 0), default=0.0, metavar="MINUTES",
                   help="time budget in minutes (0: none): the cosine LR spans it and training stops when it "
                        "is spent (resume-aware)")
    hidden_alias(t, "--max-minutes", "max_minutes", type=bounded(float, 0))  # the name before --time-budget-min
    t.add_argument("--max-steps", type=bounded(int, 0), default=0, metavar="N",
                   help="stop after this many steps (0: no cap, the epochs and the time budget decide)")
    t.add_argument("--no-resume", action="store_true", help="start over even if <out>/last.pt exists")
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    hidden_alias(t, "--no-progress", "quiet", action="store_true")
    t.set_defaults(func=_train)

    e = sub.add_parser("export", help="checkpoint -> ONNX (opset 17, dynamic batch, metadata) + parity check",
                       description="Exports, writes the track3d metadata into the file, and checks torch vs "
                                   "onnxruntime on random inputs (fails beyond float32 noise).")
    e.add_argument("--checkpoint", dest="ckpt", help="A3BoxNet checkpoint (best.pt / last.pt); required")
    hidden_alias(e, "--ckpt", "ckpt")
    e.add_argument("--out", required=True,
                   help="ONNX file to write (a shipped model in track3d/models only with --force; a file named "
                        "like a shipped model in the folder a run starts from is taken instead of it)")
    e.add_argument("--force", action="store_true",
                   help="overwrite a file that exists at --out (a shipped model in track3d/models too)")
    e.add_argument("--no-parity", action="store_true", help="skip the torch / onnxruntime parity check")
    e.add_argument("--meta-json", default=None, help="also write the metadata to this JSON file")
    e.add_argument("--depth-sensor", default=None, choices=("ideal", "tof", "flash-lidar", "stereo"),
                   help="the depth sensor the model was trained for (metadata depth_sensor; default: none, "
                        "every sensor)")
    e.set_defaults(func=_export)

    v = sub.add_parser("eval", help="oracle row: the ONNX model on a frustum cache (+ the baseline)",
                       description="AO_bev, AO_3d, ACE_3d per sequence then averaged; baseline = minimum "
                                   "enclosing box of the whole frustum.")
    v.add_argument("--model", required=True, help="ONNX model")
    v.add_argument("--cache", required=True, help="test .npz from `prepare --jitters 0`")
    v.add_argument("--all-boxes", action="store_true", help="also the jittered boxes of the cache")
    v.add_argument("--num-points", type=bounded(int, 1, high=MAX_NUM_POINTS), default=None,
                   help="N, the points sampled from each frustum as the model's input (default: the model's own, "
                        "from its metadata)")
    v.add_argument("--threads", type=thread_count, default=1, help="onnxruntime threads")
    v.add_argument("--seed", type=bounded(int, 0), default=0, help="sampling seed")
    v.add_argument("--out", default=None, help="also write the result to this JSON file")
    hidden_alias(v, "--json", "out")
    v.set_defaults(func=_eval)
    return apply_formatter(p)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
