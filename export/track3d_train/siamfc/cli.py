"""`track3d-train siamfc prepare|train|export|eval`: the SiamFC pipeline.

    track3d-train siamfc prepare --data data/small --out data/cache/siamfc
    track3d-train siamfc train   --variant edge --cache data/cache/siamfc --out runs/siamfc_edge
    track3d-train siamfc export  --checkpoint runs/siamfc_edge/ckpt.pt --out runtime/track3d/models/siamfc_edge --force
    track3d-train siamfc eval    --model runtime/track3d/models/siamfc_edge --data data/small --split test
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from track3d.argparsing import ArgumentParser, apply_formatter, bounded, hidden_alias, thread_count


def _prepare(a) -> int:
    from .data import build_cache, sequences_from_dataset, synthetic_sequences

    if a.synthetic:
        seqs = synthetic_sequences(a.synthetic, frames=a.synthetic_frames, seed=a.seed)
    else:
        if not a.data:
            print("error: give --data ROOT (a dataset) or --synthetic N", file=sys.stderr)
            return 2
        seqs = sequences_from_dataset(a.data, a.split, stride=a.stride)
    if a.synthetic:
        import hashlib

        ident = {"data_hash": hashlib.sha256(f"synthetic:{a.synthetic}:{a.synthetic_frames}:{a.seed}".encode())
                 .hexdigest(), "data_name": f"synthetic x{a.synthetic} (seed {a.seed})"}
    else:
        from track3d.dataset import Dataset

        from ..boxnet.data import split_hash
        ident = {"data_hash": split_hash(Dataset(a.data), a.split), "data_name": f"{Path(a.data).name}/{a.split}"}
    t0 = time.perf_counter()
    out = build_cache(seqs, a.out, max_frames=a.max_frames, progress=not a.quiet, **ident)
    info = json.loads((out / "index.json").read_text())
    print(f"cache {out}: {len(info['seq'])} crops from {len(info['sequences'])} sequences "
          f"in {time.perf_counter() - t0:.0f} s")
    return 0


def _cfg(a):
    from .model import config_for

    return config_for(a.variant, width=a.width, train_instance_size=a.train_instance_size)


def _train(a) -> int:
    from .train import train

    cfg = _cfg(a)
    print(f"SiamFC {cfg.variant}: channels {cfg.channels}, train crops {cfg.exemplar_size}/"
          f"{cfg.train_instance_size}, batch {a.batch}, {a.steps} steps, {a.threads} thread(s)")
    s = train(cfg, a.cache, a.out, steps=a.steps, batch=a.batch, lr=a.lr, lr_end=a.lr_end, seed=a.seed,
              threads=a.threads, time_budget_s=a.time_budget_min * 60 if a.time_budget_min else None,
              ckpt_every_s=a.ckpt_every_min * 60, init_from=a.init_from, resume=not a.no_resume,
              progress=not a.quiet, max_gap=a.max_gap)
    print(json.dumps(s))
    return 0


def _export(a) -> int:
    import dataclasses

    from .export import export_onnx, parity, quantize_search
    from .train import load_checkpoint

    from ..onnx_meta import refuse_existing, refuse_shipped, remove_stale_twins

    if not a.checkpoint:
        raise ValueError("give --checkpoint CKPT (a SiamFC ckpt.pt)")
    from track3d.onnxmodel import variant_path

    # the int8 twin where the runtime looks for it (variant_path: <prefix>_search_int8.onnx); it
    # had been written as <prefix>_int8_search.onnx, which precision="int8" / "auto" never found
    int8_search = variant_path(Path(str(a.out) + "_search.onnx"), "int8")
    if Path(a.out).is_dir():
        raise ValueError(f"--out {a.out} is a folder: give a path prefix (e.g. {Path(a.out) / 'siamfc_edge'} writes "
                         f"siamfc_edge_exemplar.onnx and siamfc_edge_search.onnx in it)")
    outs = [Path(str(a.out) + "_exemplar.onnx"), Path(str(a.out) + "_search.onnx")] + ([int8_search] if a.int8 else [])
    refuse_shipped(outs, a.force)
    twins = refuse_existing(outs, a.force)   # they had been overwritten without a word
    net, ck = load_checkpoint(a.checkpoint)
    over = {k: getattr(a, k) for k in ("instance_size", "scale_num", "window_influence", "scale_lr",
                                       "scale_step", "scale_penalty") if getattr(a, k) is not None}
    if over:
        net.cfg = dataclasses.replace(net.cfg, **over)
    extra = {"training": {"steps": ck.get("step"), "batch": ck.get("batch"), "seed": ck.get("seed"),
                          "elapsed_s": round(float(ck.get("elapsed_s", 0)), 1),
                          "data": a.data_note or "track3d small train split (no ILSVRC-VID pre-training)"},
             "train_data_hash": ck.get("train_data_hash"), "train_data": ck.get("train_data")}
    p: dict = {}
    pz, px = export_onnx(net, a.out, extra, check=lambda z, x: p.update(parity(net, z, x)))
    remove_stale_twins(twins)   # the int8 files of the pair just replaced (--int8 rewrites its own)
    print(f"wrote {pz} ({pz.stat().st_size / 1e6:.2f} MB), {px} ({px.stat().st_size / 1e6:.2f} MB)")
    print("parity torch vs onnxruntime:", json.dumps(p))
    if a.int8:
        import numpy as np

        from track3d.onnxmodel import OnnxModel

        from .data import CropCache
        cache = CropCache(a.int8)
        rng = np.random.default_rng(0)
        ids = rng.choice(len(cache), size=min(64, len(cache)), replace=False)
        n, c0 = net.cfg.instance_size, (cache.crops.shape[1] - net.cfg.instance_size) // 2
        calib = np.stack([cache.crops[i][c0:c0 + n, c0:c0 + n] for i in ids])
        e0 = (cache.crops.shape[1] - net.cfg.exemplar_size) // 2
        z = np.ascontiguousarray(cache.crops[ids[0]][e0:e0 + 127, e0:e0 + 127][None])
        feat = OnnxModel(pz, 1).run({"exemplar": z})[0]
        q = quantize_search(px, int8_search, calib, feat)
        print(f"wrote {q} ({q.stat().st_size / 1e6:.2f} MB): the search network's int8 twin. "
              f"precision='int8' needs the exemplar's twin too, and precision='auto' runs a twin only "
              f"with an accuracy verdict: `track3d-train quantize` makes both twins, "
              f"`benchmarks/bench_precision.py --write-verdicts` the verdicts")
    return 0


def _eval(a) -> int:
    """One pass of the model through the runtime's evaluation toolkit (2D only)."""
    from track3d.evaluation import TrackerSpec, evaluate_2d
    from track3d.jsonable import jsonable

    over = {k: getattr(a, k) for k in ("instance_size", "scale_num", "window_influence", "scale_lr")
            if getattr(a, k) is not None}
    spec = TrackerSpec("siamfc-edge", "none", threads=a.threads, tracker_options={"model": a.model, **over},
                       name="model")
    row = evaluate_2d(a.data, a.split, [spec], max_sequences=a.max_sequences or None)["model"]
    print(json.dumps(jsonable(row), indent=1))   # a missing number (nan) is null: JSON has no NaN
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="track3d-train siamfc", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)

    q = sub.add_parser("prepare", help="crop training pairs once into a cache (.npy memmap)")
    q.add_argument("--data", help="dataset root (dataset.json)")
    q.add_argument("--split", default="train", help="split name")
    q.add_argument("--out", required=True, help="cache folder")
    q.add_argument("--frame-step", dest="stride", type=bounded(int, 1), default=1, metavar="K", help="use every k-th frame")
    hidden_alias(q, "--stride", "stride", type=bounded(int, 1))  # the name before --frame-step
    q.add_argument("--max-frames", type=bounded(int, 1), default=2000, help="bound on cached crops (~195 kB each)")
    q.add_argument("--synthetic", type=bounded(int, 0), default=0, help="N synthetic sequences instead of a dataset")
    q.add_argument("--synthetic-frames", type=bounded(int, 2), default=60, help="frames per synthetic sequence")
    q.add_argument("--seed", type=bounded(int, 0), default=0, help="seed")
    q.add_argument("--quiet", action="store_true", help="no progress bar")
    hidden_alias(q, "--no-progress", "quiet", action="store_true")
    q.set_defaults(fn=_prepare)

    for name, fn, hlp in (("train", _train, "train (resumes from <out>/ckpt.pt)"),):
        t = sub.add_parser(name, help=hlp)
        t.add_argument("--variant", choices=["faithful", "edge"], default="edge", help="network variant")
        t.add_argument("--width", type=bounded(float, above=0), default=None,
                       help="channel width multiplier (default: the variant's, 0.25 for edge, 1.0 for faithful)")
        t.add_argument("--train-instance-size", type=bounded(int, 1), default=None,
                       help="search crop size in training (default: 239, SiamFC's 255 - 2 x 8)")
        t.add_argument("--cache", required=True, help="cache folder from `prepare`")
        t.add_argument("--out", required=True, help="run folder: ckpt.pt, log.jsonl, loss.png")
        t.add_argument("--max-steps", dest="steps", type=bounded(int, 1), default=2000, metavar="N",
                       help="training steps (the LR schedule spans them)")
        hidden_alias(t, "--steps", "steps", type=bounded(int, 1))
        t.add_argument("--batch", type=bounded(int, 1), default=16, help="batch size (pairs)")
        t.add_argument("--lr", type=bounded(float, above=0), default=1e-2, help="initial learning rate")
        t.add_argument("--lr-end", type=bounded(float, above=0), default=1e-4, help="final learning rate (geometric decay)")
        t.add_argument("--max-gap", type=bounded(int, 1), default=50, help="max frame gap of a pair")
        t.add_argument("--ckpt-every-min", type=bounded(float, above=0), default=1.0,
                       help="minutes between atomic checkpoints (SIGTERM / Ctrl-C writes one too)")
        t.add_argument("--seed", type=bounded(int, 0), default=0, help="seed")
        t.add_argument("--threads", type=thread_count, default=1, help="torch threads")
        t.add_argument("--time-budget-min", type=bounded(float, above=0), default=None,
                       help="stop (and checkpoint) after this many minutes of training (default: none, "
                            "only --max-steps)")
        t.add_argument("--init-from", help="start from another run's checkpoint of the same --variant and --width "
                                           "(fine-tuning; default: none, random weights; ignored when the run "
                                           "resumes)")
        t.add_argument("--no-resume", action="store_true", help="start over even if <out>/ckpt.pt exists")
        t.add_argument("--quiet", action="store_true", help="no progress bar")
        hidden_alias(t, "--no-progress", "quiet", action="store_true")
        t.set_defaults(fn=fn)

    e = sub.add_parser("export", help="write <out>_exemplar.onnx + <out>_search.onnx, check parity")
    e.add_argument("--checkpoint", dest="checkpoint", help="SiamFC checkpoint (ckpt.pt); required")
    hidden_alias(e, "--ckpt", "checkpoint")
    e.add_argument("--out", required=True, help="path prefix")
    e.add_argument("--force", action="store_true",
                   help="overwrite files that exist at --out (the shipped models in track3d/models too)")
    e.add_argument("--data-note", default=None,
                   help="what the model was trained on (metadata; default: 'track3d small train split (no "
                        "ILSVRC-VID pre-training)')")
    e.add_argument("--int8", metavar="CACHE",
                   help="also write the search graph's int8 twin (<out>_search_int8.onnx), calibrated on CACHE "
                        "(the exemplar's twin and the accuracy verdict auto needs: track3d-train quantize, "
                        "benchmarks/bench_precision.py --write-verdicts)")
    # bounds: a value the runtime cannot use must not be written into a model file
    unit = bounded(float, 0, high=1)
    for k, ty in (("instance-size", bounded(int, 1)), ("scale-num", bounded(int, 1)), ("window-influence", unit),
                  ("scale-lr", unit), ("scale-step", bounded(float, above=0)),
                  ("scale-penalty", bounded(float, above=0, high=1))):
        e.add_argument(f"--{k}", type=ty, default=None,
                       help="tracking default stored in the metadata (default: the checkpoint's config's)")
    e.set_defaults(fn=_export)

    v = sub.add_parser("eval", help="OPE on a dataset split with the ONNX runtime tracker")
    v.add_argument("--model", required=True, help="prefix of <name>_exemplar/_search.onnx")
    v.add_argument("--data", required=True, help="dataset root")
    v.add_argument("--split", default="test", help="split name")
    v.add_argument("--max-sequences", type=bounded(int, 0), default=0, help="only the first N sequences (0: all)")
    hidden_alias(v, "--max-seqs", "max_sequences", type=bounded(int, 0))
    v.add_argument("--threads", type=thread_count, default=1, help="onnxruntime threads")
    for k, ty in (("instance-size", bounded(int, 1)), ("scale-num", bounded(int, 1)), ("window-influence", unit),
                  ("scale-lr", unit)):
        v.add_argument(f"--{k}", type=ty, default=None,
                       help="override the model's tracking default (default: the model's own)")
    v.set_defaults(fn=_eval)
    return apply_formatter(p)


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    return int(a.fn(a) or 0)


if __name__ == "__main__":
    sys.exit(main())
