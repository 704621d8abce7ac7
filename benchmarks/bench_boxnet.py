"""A3BoxNet benchmark: the paper's "A3BoxNet" row, ablations, speed.

1. Oracle row (paper Table 2, "A3BoxNet"): the box net alone on the frustum of the
   ground-truth 2D box of every test frame where the target is present, next to the
   baseline estimator (minimum enclosing box of the whole frustum) on the SAME frustums:
   AO_bev, AO_3d, ACE_3d (per sequence, averaged over sequences; track3d.evaluation).
2. Speed: the estimator behind the loop's seam (sampling in the C++ ext + the model's size
   coding, track3d.size_coding, normalising + ONNX + decode) on real full-size frustums, onnxruntime at 1 thread (process pinned to one core)
   and 2 threads; the network alone; the frustum crop; the baseline estimator.
3. onnxruntime vs torch eager on the same inputs (batch 1, 1 thread): the speed ratio.
4. Ablations (paper Fig. 13 / Table 3): any number of `name=model.onnx` models evaluated on the
   same oracle frustums (points 512..4096, with / without category, paper / points size
   coding, width), plus a test-time sweep of N for the shipped model: a table and a plot.

    python benchmarks/bench_boxnet.py --data data/med --cache runs/boxnet/cache/test.npz \
        --model runtime/track3d/models/a3boxnet.onnx --checkpoint runs/boxnet-engine/more/best.pt \
        --ablation p512=runs/boxnet/ablation/p512.onnx ...

(the cache: export/scripts/ablation_boxnet.sh; the checkpoint: `track3d-train recipe run a3boxnet-engine`)

Writes <out>/boxnet.json, boxnet.md (tables) and boxnet_ablation.png.
"""
from __future__ import annotations

import json
import re
import sys
import time
from pathlib import Path

import numpy as np
from benchlib.output import add_out_argument
from benchlib.paper import TABLE2, TABLE3_NO_CATEGORY
from benchlib.record import finish_record, start_record

from track3d.argparsing import ArgumentParser, hidden_alias, run_main
from track3d.boxnet import DEFAULT_MODEL
from track3d.jsonable import write_json
from track3d.machine import START_CPUS, pin_threads
from track3d.onnxmodel import MODELS_DIR

PAPER_A3BOXNET, PAPER_BASELINE = TABLE2["A3BoxNet"], TABLE2["3D Tracking Baseline"]


def _pin(one_core: bool) -> None:
    """One core: the first of the cores this process was started on (so `taskset` chooses it)."""
    pin_threads(1 if one_core else len(START_CPUS))


def _timeit(fn, items, repeat: int = 1, warmup: int = 10):
    for x in items[:warmup]:
        fn(x)
    t = []
    for _ in range(repeat):
        for x in items:
            t0 = time.perf_counter()
            fn(x)
            t.append(time.perf_counter() - t0)
    t = np.array(t) * 1e3
    return {"median_ms": float(np.median(t)), "mean_ms": float(t.mean()), "p99_ms": float(np.percentile(t, 99)),
            "fps_median": float(1e3 / np.median(t)), "n": int(len(t))}


def oracle_row(model: str, cache, num_points: int | None = None, seed: int = 0) -> dict:
    from track3d.boxnet import A3BoxNetEstimator
    from track3d_train.boxnet.evaluate import onnx_runner, oracle_metrics, predict

    est = A3BoxNetEstimator(model, threads=2)
    n = num_points or est.num_points
    pred = predict(onnx_runner(est), cache, n, est.num_categories, seed=seed, size_norm=est.size_norm)
    m = oracle_metrics(pred, cache.field("gt3d"), cache.field("seq"))
    m["num_points"] = n
    m["model_meta"] = {k: est.meta.get(k) for k in ("num_points", "width", "use_category", "size_norm", "version",
                                                   "train_data_hash", "trained")}
    return m


def full_frustums(data: str, split: str, cache, count: int, seed: int = 0):
    """(points, category) of `count` oracle test frames re-cut from their depth maps, full size."""
    from track3d.dataset import Dataset
    from track3d.frustum import extract_frustum

    ds = Dataset(data)
    seqs = ds.sequences(split)
    rng = np.random.default_rng(seed)
    idx = np.sort(rng.choice(len(cache), min(count, len(cache)), replace=False))
    out, clouds = [], []
    for i in idx:
        j = cache.index[i]
        seq = seqs[int(cache.seq[j])]
        f = int(cache.frame[j])
        cloud = seq.points(f)
        fr = extract_frustum(cloud, seq.gt2d[f], ds.camera.M)
        out.append((fr, int(cache.category[j])))
        clouds.append((cloud, seq.gt2d[f].astype(np.float64)))
    return out, clouds, ds.camera.M


def speed(model: str, frustums, clouds, M, threads: int) -> dict:
    from track3d.boxnet import A3BoxNetEstimator
    from track3d.estimators import create_estimator
    from track3d.frames import point_bounds
    from track3d.frustum import extract_frustum

    est = A3BoxNetEstimator(model, threads=threads)
    base = create_estimator("baseline")

    def centred(p):   # the network's input as estimate() makes it: the model's size coding normalises
        bounds = np.stack(point_bounds(p))[None] if est.coding.needs_bounds else None
        return est.coding.normalise(est.sample(p)[None], bounds)[0]

    samp = [centred(p) for p, _ in frustums]
    cats = [c for _, c in frustums]
    r = {"threads": threads, "mean_frustum_points": float(np.mean([len(p) for p, _ in frustums])),
         "estimator": _timeit(lambda x: est.estimate(*x), frustums, repeat=2),
         "network": _timeit(lambda i: est.infer(samp[i], [cats[i]]), list(range(len(samp))), repeat=2),
         "sampling": _timeit(lambda x: est.sample(x[0]), frustums),
         "baseline_estimator": _timeit(lambda x: base.estimate(*x), frustums),
         "frustum_crop": _timeit(lambda x: extract_frustum(x[0], x[1], M), clouds)}
    return r


def torch_ratio(ckpt: str, model: str, num_points: int, reps: int = 200) -> dict:
    import torch

    from track3d.boxnet import A3BoxNetEstimator, one_hot
    from track3d_train.boxnet.train import load_checkpoint

    torch.set_num_threads(1)
    tm, _ = load_checkpoint(ckpt)
    est = A3BoxNetEstimator(model, threads=1)
    rng = np.random.default_rng(0)
    xs = [rng.normal(size=(1, num_points, 3)).astype(np.float32) for _ in range(reps)]
    cat = one_hot([0], 3)
    with torch.inference_mode():
        t_torch = _timeit(lambda x: tm(torch.from_numpy(x), torch.from_numpy(cat)), xs)
    t_ort = _timeit(lambda x: est.infer(x, [0]), xs)
    return {"torch_eager_ms": t_torch["median_ms"], "onnxruntime_ms": t_ort["median_ms"],
            "ratio_torch_over_ort": t_torch["median_ms"] / t_ort["median_ms"], "threads": 1,
            "torch": torch.__version__}


def _group(rows: list[dict], key) -> list[tuple]:
    """(key, mean AO_3d, AO_bev, ACE_3d, min AO_3d, max AO_3d, count) per key, in key order:
    models retrained with other seeds (names `p512_s1`, ...) make one point with a spread."""
    out = []
    for k in sorted({key(r) for r in rows}):
        g = [r for r in rows if key(r) == k]
        a = np.array([[r["AO_3d"], r["AO_bev"], r["ACE_3d"]] for r in g])
        out.append((k, *a.mean(axis=0), a[:, 0].min(), a[:, 0].max(), len(g)))
    return out


def plot(res: dict, path: Path) -> None:
    """2 x 2: accuracy against N, ACE against N, the network's cost against N, the category."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    pts = _group(res.get("ablation_points_trained", []), lambda r: r["num_points"])
    tt = res.get("test_time_points", [])
    if pts:
        n = [g[0] for g in pts]
        err = [[g[1] - g[4] for g in pts], [g[5] - g[1] for g in pts]]
        ax[0, 0].errorbar(n, [g[1] for g in pts], yerr=err, fmt="o-", capsize=3, label="AO_3d, retrained per N")
        ax[0, 0].plot(n, [g[2] for g in pts], "s-", label="AO_bev, retrained per N")
        ax[0, 1].plot(n, [g[3] for g in pts], "o-", label="retrained per N")
        cost = {r["num_points"]: r["net_ms_1thread"] for r in res.get("ablation_points_trained", [])
                if r.get("net_ms_1thread")}
        if cost:
            ax[1, 0].plot(sorted(cost), [cost[k] for k in sorted(cost)], "o-")
    if tt:
        n = [r["num_points"] for r in tt]
        ax[0, 0].plot(n, [r["AO_3d"] for r in tt], "o:", alpha=0.6, label="AO_3d, shipped model (full budget), N at test only")
        ax[0, 1].plot(n, [r["ACE_3d"] for r in tt], "o:", alpha=0.6, label="shipped model (full budget), N at test only")
    for a, title, ylabel in ((ax[0, 0], "Accuracy against input points (paper Fig. 13)", "AO"),
                             (ax[0, 1], "Centre error against input points", "ACE_3d (m)"),
                             (ax[1, 0], "Cost: the box network alone, 1 thread", "ms per frustum")):
        a.set_xscale("log", base=2)
        a.set_xlabel("input points N")
        a.set_ylabel(ylabel)
        a.set_title(title, fontsize=10)
        a.grid(alpha=0.3)
        if a.get_legend_handles_labels()[0]:
            a.legend(fontsize=8)
    cat = _category_groups(res)
    if cat:
        labels = [c[0] for c in cat]
        x = np.arange(len(labels))
        ax[1, 1].bar(x - 0.2, [c[1] for c in cat], 0.4, label="AO_3d")
        ax[1, 1].bar(x + 0.2, [c[2] for c in cat], 0.4, label="AO_bev")
        for xi, c in zip(x, cat):
            ax[1, 1].text(xi, 0.05, f"ACE {c[3]:.3f} m", ha="center", fontsize=7, rotation=90, color="white")
        ax[1, 1].set_xticks(x, labels, rotation=15, fontsize=8)
        ax[1, 1].set_ylim(0, 1)
        ax[1, 1].legend(fontsize=8, loc="upper right")
    ax[1, 1].set_title("Category vector (paper Table 3)", fontsize=10)
    fig.tight_layout()
    fig.savefig(str(path), dpi=110)
    plt.close(fig)


def markdown(res: dict) -> str:
    o, b, p, q = res["oracle"]["a3boxnet"], res["oracle"]["baseline"], PAPER_A3BOXNET, PAPER_BASELINE
    lines = [f"# A3BoxNet benchmark ({res['cpu']})", "",
             f"Test split `{res['data']}` ({o['sequences']} sequences, {o['frames']} frames, oracle 2D boxes).", "",
             "| estimator | AO_bev | AO_3d | ACE_3d (m) | SR@0.5 3d | FPS 1 thr | FPS 2 thr |", "|---|---|---|---|---|---|---|"]
    s = {t["threads"]: t for t in res.get("speed", [])}
    f1 = s.get(1, {}).get("estimator", {}).get("fps_median", float("nan"))
    f2 = s.get(2, {}).get("estimator", {}).get("fps_median", float("nan"))
    g1 = s.get(1, {}).get("baseline_estimator", {}).get("fps_median", float("nan"))
    def fps(v: float) -> str:   # "-": not measured in this run (--no-speed)
        return "-" if not np.isfinite(v) else f"{v:.0f}"

    lines.append(f"| A3BoxNet (ours, shipped) | {o['AO_bev']:.3f} | {o['AO_3d']:.3f} | {o['ACE_3d']:.3f} | "
                 f"{o['SR50_3d']:.3f} | {fps(f1)} | {fps(f2)} |")
    lines.append(f"| baseline (enclosing box) | {b['AO_bev']:.3f} | {b['AO_3d']:.3f} | {b['ACE_3d']:.3f} | "
                 f"{b['SR50_3d']:.3f} | {fps(g1)} | |")
    lines.append(f"| paper A3BoxNet (GPU) | {p['AO_bev']} | {p['AO_3d']} | {p['ACE_3d(m)']} | | {p['FPS']} | |")
    lines.append(f"| paper baseline (in the loop) | {q['AO_bev']} | {q['AO_3d']} | {q['ACE_3d(m)']} | | | |")
    for key, title in (("ablation_points_trained", "Input points, retrained per N"),
                       ("test_time_points", "Input points at test time only (shipped model)"),
                       ("ablation_other", "Category vector, size coding, width")):
        rows = res.get(key) or []
        if not rows:
            continue
        lines += ["", f"## {title}", "", "| model | N | AO_bev | AO_3d | ACE_3d (m) | net ms (1 thr) |",
                  "|---|---|---|---|---|---|"]
        for r in rows:
            ms = r.get("net_ms_1thread")
            lines.append(f"| {r.get('name', '')} | {r['num_points']} | {r['AO_bev']:.3f} | {r['AO_3d']:.3f} | "
                         f"{r['ACE_3d']:.3f} | {'' if ms is None else f'{ms:.2f}'} |")
    table3 = _category_table(res)
    if table3:
        lines += ["", "## Category vector (paper Table 3), same training budget and N (mean over seeds)", "",
                  "| model | trained models | AO_3d | AO_bev | ACE_3d (m) |", "|---|---|---|---|---|"] + table3
    if "torch_ratio" in res:
        t = res["torch_ratio"]
        lines += ["", f"onnxruntime {t['onnxruntime_ms']:.2f} ms vs torch eager {t['torch_eager_ms']:.2f} ms "
                      f"(1 thread, batch 1): torch / ORT = {t['ratio_torch_over_ort']:.2f}x"]
    return "\n".join(lines) + "\n"


def _category_groups(res: dict) -> list[tuple]:
    """(label, AO_3d, AO_bev, ACE_3d, models) for: ours with the category at the N of the
    models trained without it, ours without (each the mean over its seeds), then the paper's."""
    nocat = [r for r in res.get("ablation_other", []) if (r.get("model_meta") or {}).get("use_category", True) is False]
    if not nocat:
        return []
    out = []
    for n in sorted({r["num_points"] for r in nocat}):
        withcat = [r for r in res.get("ablation_points_trained", [])
                   if r["num_points"] == n and (r.get("model_meta") or {}).get("use_category", True)]
        without = [r for r in nocat if r["num_points"] == n]
        for rows, label in ((withcat, f"ours N={n}, with"), (without, f"ours N={n}, without")):
            if rows:
                g = _group(rows, lambda r: 0)[0]
                out.append((label, g[1], g[2], g[3], ", ".join(r["name"] for r in rows)))
    p, q = PAPER_A3BOXNET, TABLE3_NO_CATEGORY
    out.append(("paper N=1024, with", p["AO_3d"], p["AO_bev"], p["ACE_3d(m)"], "paper Table 3"))
    out.append(("paper N=1024, without", q["AO_3d"], q["AO_bev"], q["ACE_3d(m)"], "paper Table 3"))
    return out


def _category_table(res: dict) -> list[str]:
    """Markdown rows of the with / without category comparison (see _category_groups)."""
    return [f"| {label} | {models} | {a3:.3f} | {ab:.3f} | {ace:.3f} |"
            for label, a3, ab, ace, models in _category_groups(res)]


def net_ms(model: str, n: int, reps: int = 100) -> float:
    from track3d.boxnet import A3BoxNetEstimator

    est = A3BoxNetEstimator(model, threads=1)
    x = [np.random.default_rng(i).normal(size=(1, n, 3)).astype(np.float32) for i in range(reps)]
    return _timeit(lambda v: est.infer(v, [0]), x)["median_ms"]


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__)
    ap.add_argument("--data", default="data/small", help="dataset root")
    ap.add_argument("--split", default="test", help="dataset split")
    ap.add_argument("--cache", required=True, help="oracle frustum cache of the split (`boxnet prepare --jitters 0`)")
    ap.add_argument("--model", default=str(MODELS_DIR / DEFAULT_MODEL), help=f"A3BoxNet ONNX (default: the shipped {DEFAULT_MODEL})")
    ap.add_argument("--checkpoint", default=None, help="its torch checkpoint (for the ORT vs torch ratio)")
    hidden_alias(ap, "--ckpt", "checkpoint")
    ap.add_argument("--ablation", nargs="*", default=[], metavar="NAME=MODEL.onnx",
                    help="retrained models; names p<N> (or p<N>_s<seed> for another seed of the same "
                         "recipe) go to the points table, models without the category vector to "
                         "the category table")
    ap.add_argument("--test-time-points", nargs="*", type=int, default=[256, 512, 1024, 2048],
                    help="N sweep of the shipped model at test time")
    ap.add_argument("--speed-frames", type=int, default=300, help="frames for the timing runs")
    add_out_argument(ap)
    ap.add_argument("--name", default="boxnet", help="output file stem")
    ap.add_argument("--no-speed", action="store_true", help="skip the timing runs")
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)

    from track3d_train.boxnet.data import PointCache
    from track3d_train.boxnet.evaluate import oracle_metrics

    out = Path(a.out)
    cache = PointCache(a.cache)
    cache = cache.subset(np.nonzero(cache.jittered == 0)[0])
    res = start_record("A3BoxNet: oracle row, ablations, speed", data=a.data, split=a.split, cache=a.cache,
                       data_hash=cache.info.get("data_hash"), model=a.model,
                       paper={"A3BoxNet": PAPER_A3BOXNET, "3D Tracking Baseline": PAPER_BASELINE,
                              "A3BoxNet without category (Table 3)": TABLE3_NO_CATEGORY})
    t0 = time.time()
    res["oracle"] = {"a3boxnet": oracle_row(a.model, cache),
                     "baseline": oracle_metrics(cache.field("baseline"), cache.field("gt3d"), cache.field("seq"))}
    print(json.dumps(res["oracle"], indent=1), flush=True)
    res["test_time_points"] = [{"name": "shipped", **oracle_row(a.model, cache, n)} for n in a.test_time_points]
    pts, other = [], []
    for spec in a.ablation:
        name, path = spec.split("=", 1)
        r = {"name": name, **oracle_row(path, cache)}
        _pin(True)   # the network alone at the model's N: cheap, and what N costs is half the ablation
        r["net_ms_1thread"] = net_ms(path, r["num_points"])
        _pin(False)
        (pts if re.fullmatch(r"p\d+(_s\d+)?", name) else other).append(r)
        print(name, {k: r[k] for k in ("AO_bev", "AO_3d", "ACE_3d", "net_ms_1thread")}, flush=True)
    res["ablation_points_trained"] = sorted(pts, key=lambda r: r["num_points"])
    res["ablation_other"] = other
    res["eval_seconds"] = time.time() - t0
    if not a.no_speed:
        frustums, clouds, M = full_frustums(a.data, a.split, cache, a.speed_frames)
        res["speed"] = []
        for threads in (1, 2):
            _pin(threads == 1)
            res["speed"].append(speed(a.model, frustums, clouds, M, threads))
            print(json.dumps(res["speed"][-1]), flush=True)
        _pin(True)
        if a.checkpoint:
            res["torch_ratio"] = torch_ratio(a.checkpoint, a.model, res["oracle"]["a3boxnet"]["num_points"])
        _pin(False)
    write_json(out / f"{a.name}.json", finish_record(res))
    (out / f"{a.name}.md").write_text(markdown(res))
    plot(res, out / f"{a.name}_ablation.png")
    print(markdown(res))
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main, "bench_boxnet.py"))
