"""2D tracker benchmark (paper Fig. 14): accuracy and speed in one run.

On a dataset split, the evaluation toolkit's one-pass 2D protocol (`track3d.evaluation`:
restart=False, the null estimator "none"; init on the first frame with the target present,
absent frames not scored) of

    siamfc-edge, siamfc (faithful), nano (NanoTrack v2, peer model), kcf, csrt, mosse, mil

with AO_2d, SR@0.5, ACE_2d and FPS (tracker time, I/O excluded) at 1 thread (pinned to one
core), and FPS at 2 threads on the first --speed-seqs sequences. Also:
  --sweep      the edge design sweep: width x search size x scales x int8 -> AO vs ms plot
  --ratio      onnxruntime vs torch eager speed of the SiamFC search graph (needs torch)

    python benchmarks/bench_2d.py --data data/small --sweep --ratio

Writes <out>/bench_2d.json, bench_2d.md (the table), success_2d.png / precision_2d.png (the
toolkit's plots), bench_2d_tradeoff.png (--sweep) and the toolkit's result files
(<out>/results, <out>/results_2t).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from benchlib.output import add_out_argument
from benchlib.paper import TABLE2
from benchlib.record import finish_record, start_record

from track3d.argparsing import ArgumentParser, bounded, hidden_alias, run_main
from track3d.evaluation import Experiment, TrackerSpec, average_scores
from track3d.jsonable import write_json
from track3d.machine import pin_threads
from track3d.table_text import cell, markdown_table
from track3d.tracker import STAGES

DEFAULT_TRACKERS = ("siamfc-edge", "siamfc", "nano", "kcf", "csrt", "mosse", "mil")
PROTOCOL = ("one pass (track3d.evaluation, restart=False, estimator 'none'): init on the first present frame, "
            "no restart, absent frames not scored; FPS = tracker time (I/O excluded); 1 thread pinned to one core")


def spec_2d(tracker: str, threads: int = 1, options: dict | None = None, name: str | None = None) -> TrackerSpec:
    """A 2D tracker alone (the null estimator), named `name` (default: the tracker)."""
    return TrackerSpec(tracker, "none", threads=threads, tracker_options=dict(options or {}), name=name or tracker)


def sweep_specs(folders: list[str], sizes: list[int], scales: list[int]) -> dict[str, dict]:
    """Edge design points: every <name>_search.onnx in `folders` x search size x scales ->
    {label: {"spec", "prefix", "instance_size", "scale_num"}}."""
    out = {}
    for d in folders:
        for p in sorted(Path(d).glob("*_search.onnx")):
            pre = p.parent / p.name[: -len("_search.onnx")]
            for n in sizes:
                for s in scales:
                    label = f"{pre.name}@{s}x{n}"
                    out[label] = {"spec": spec_2d("siamfc-edge", 1, {"model": str(pre), "instance_size": n,
                                                                     "scale_num": s}, label),
                                  "prefix": pre.name, "instance_size": n, "scale_num": s}
    return out


def summary(exp: Experiment, name: str) -> tuple[dict, object]:
    """(the JSON row of one tracker: toolkit scores under this benchmark's keys, the OverallScore)."""
    ov = average_scores(exp.score(name))
    ms = exp.stage_ms(name)[:, STAGES.index("total")]
    med = float(np.median(ms)) if len(ms) else float("nan")
    v = ov.values
    return ({"sequences": ov.sequences, "frames": ov.frames, "AO_2d": v["ao_2d"], "SR_0.5": v["sr50_2d"],
             "SR_0.75": v["sr75_2d"], "ACE_2d": v["ace_2d"], "fps_1t": ov.fps, "fps_1t_from_median": 1e3 / med,
             "ms_median_1t": med, "ms_p90_1t": float(np.percentile(ms, 90)) if len(ms) else float("nan"),
             "success_curve": ov.curves.get("success_2d"), "precision_curve": ov.curves.get("precision_2d")}, ov)


def fps_of(scores) -> float:
    t = sum(s.tracker_seconds for s in scores)
    return sum(s.timed_frames for s in scores) / t if t > 0 else float("nan")


def ratio_ort_torch(threads_list) -> list[dict]:
    """onnxruntime vs torch eager on the SiamFC search graph of an untrained network (speed only)."""
    import tempfile

    import torch
    from track3d_train.siamfc.export import export_onnx, time_backbone
    from track3d_train.siamfc.model import SiamFC, config_for

    out = []
    with tempfile.TemporaryDirectory() as d:
        for variant, s, n in (("faithful", 3, 255), ("edge", 1, 191)):
            torch.manual_seed(0)
            net = SiamFC(config_for(variant)).eval()
            _, px = export_onnx(net, Path(d) / variant)
            for th in threads_list:
                pin_threads(th)
                r = time_backbone(net, px, s, n, threads=th, repeats=20)
                r["variant"] = variant
                out.append(r)
                print(f"  ratio {variant} {s}x{n} {th}t: torch {r['torch_ms']:.1f} ms, ort {r['ort_ms']:.1f} ms, "
                      f"torch/ort {r['ratio_torch_over_ort']:.2f}", flush=True)
    return out


def tradeoff_plot(sweep: dict, path: Path) -> None:
    """AO_2d against median ms per frame, one line per model prefix."""
    from track3d.evaluation.plots import pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 5))
    groups: dict[str, list] = {}
    for r in sweep.values():
        groups.setdefault(r["prefix"], []).append(r)
    for g, rs in sorted(groups.items()):
        rs = sorted(rs, key=lambda r: r["ms_median_1t"])
        ax.plot([r["ms_median_1t"] for r in rs], [r["AO_2d"] for r in rs], "o-", label=g, alpha=0.8)
        for r in rs:
            ax.annotate(f"{r['scale_num']}x{r['instance_size']}", (r["ms_median_1t"], r["AO_2d"]), fontsize=7)
    ax.axvline(1000 / 100, color="grey", ls=":", lw=1)
    ax.text(1000 / 100, ax.get_ylim()[0], " whole 3D loop budget\n at 100 FPS", fontsize=7, va="bottom")
    ax.set(xscale="log", xlabel="2D tracker ms / frame (median, 1 thread, pinned)", ylabel="AO_2d (test split)",
           title="SiamFC design: accuracy vs speed")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(results: dict, sweep: dict, ratio: list[dict]) -> str:
    paper = TABLE2["SiamFC"]
    rows = [[n, cell(r["AO_2d"]), cell(r["SR_0.5"]), cell(r["ACE_2d"], "{:.1f}"), cell(r["fps_1t"], "{:.1f}"),
             cell(r.get("fps_2t"), "{:.1f}"), cell(r.get("fps_1t_subset"), "{:.1f}")] for n, r in results.items()]
    rows.append(["SiamFC (paper, RTX 2080Ti)", cell(paper["AO_2d"]), "-", cell(paper["ACE_2d(px)"], "{:.1f}"),
                 cell(paper["FPS"], "{:.1f}") + " (GPU)", "-", "-"])
    md = markdown_table(["tracker", "AO_2d", "SR@0.5", "ACE_2d (px)", "FPS 1 thread", "FPS 2 threads",
                         "FPS 1 thread (same subset)"], rows)
    if sweep:
        md += "\n\n" + markdown_table(
            ["design", "AO_2d", "SR@0.5", "ms/frame (median, 1t)", "FPS 1t"],
            [[k, cell(r["AO_2d"]), cell(r["SR_0.5"]), cell(r["ms_median_1t"], "{:.2f}"), cell(r["fps_1t"], "{:.0f}")]
             for k, r in sorted(sweep.items(), key=lambda kv: kv[1]["ms_median_1t"])])
    if ratio:
        md += "\n\n" + markdown_table(
            ["search graph", "threads", "torch eager ms", "onnxruntime ms", "torch / ORT"],
            [[f"{r['variant']} {r['scales']}x{r['size']}", str(r["threads"]), cell(r["torch_ms"], "{:.1f}"),
              cell(r["ort_ms"], "{:.1f}"), cell(r["ratio_torch_over_ort"], "{:.2f}")] for r in ratio])
    return md


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__)
    ap.add_argument("--data", default="data/small", help="dataset root (default: data/small)")
    ap.add_argument("--split", default="test", help="dataset split")
    ap.add_argument("--trackers", default=",".join(DEFAULT_TRACKERS), help="comma-separated 2D trackers")
    ap.add_argument("--max-sequences", type=bounded(int, 0), default=0, help="only the first N sequences (0: all)")
    hidden_alias(ap, "--max-seqs", "max_sequences", type=bounded(int, 0))
    ap.add_argument("--speed-seqs", type=int, default=3, help="sequences for the 2-thread timing")
    ap.add_argument("--sweep", action="store_true", help="also run the edge design sweep")
    ap.add_argument("--sweep-models", nargs="*", default=[], help="folders with <name>_search.onnx")
    ap.add_argument("--sweep-sizes", type=int, nargs="*", default=[143, 159, 191, 255], help="search sizes of the sweep")
    ap.add_argument("--sweep-scales", type=int, nargs="*", default=[1, 3], help="scale counts of the sweep")
    ap.add_argument("--ratio", action="store_true", help="onnxruntime vs torch eager (needs torch)")
    add_out_argument(ap, "siamfc", committed="benchmarks/results/siamfc")
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    out = Path(a.out)
    rec = start_record("2D trackers (paper Fig. 14)", data=a.data, split=a.split, protocol=PROTOCOL)

    exp = Experiment(a.data, a.split, out / "results", out / "report", restart=False, max_sequences=a.max_sequences or None)
    first = exp.sequences[: max(a.speed_seqs, 0)]
    exp2 = Experiment(a.data, a.split, out / "results_2t", out / "report_2t", restart=False,
                      sequences=[s.name for s in first]) if first else None
    specs, skipped = {}, {}
    for n in (t for t in a.trackers.split(",") if t):
        why = spec_2d(n).unavailable(exp.sequences[0])
        if why:
            skipped[n] = why
            print(f"skip {n}: {why}", flush=True)
        else:
            specs[n] = spec_2d(n)
    sweep = sweep_specs(a.sweep_models, a.sweep_sizes, a.sweep_scales) if a.sweep else {}

    pin_threads(1)
    for spec in list(specs.values()) + [v["spec"] for v in sweep.values()]:
        exp.run(spec)
    pin_threads(2)
    for n in specs if exp2 else ():
        exp2.run(spec_2d(n, threads=2))
    results, overall = {}, {}
    for n in specs:
        results[n], overall[n] = summary(exp, n)
        scores = exp.score(n)
        results[n]["fps_1t_subset"] = fps_of(scores[: len(first)])
        results[n]["fps_2t"] = fps_of(exp2.score(n)) if exp2 else float("nan")
    sweep_res = {}
    for k, v in sweep.items():
        r, _ = summary(exp, k)
        r.pop("success_curve")
        r.pop("precision_curve")
        sweep_res[k] = {**r, **{kk: v[kk] for kk in ("prefix", "instance_size", "scale_num")}}
    ratio = ratio_ort_torch([1, 2]) if a.ratio else []
    pin_threads(2)
    meta = {}
    for n in specs:
        if n.startswith("siamfc"):
            tr = specs[n].build(exp.sequences[0]).tracker2d
            meta[n] = {"instance_size": tr.instance_size, "scale_num": tr.scale_num,
                       "channels": tr.meta.get("channels"), "training": tr.meta.get("training")}
    rec.update(sequences=len(exp.sequences), trackers=results, siamfc_models=meta, skipped=skipped, sweep=sweep_res,
               ort_vs_torch=ratio, paper={"SiamFC": TABLE2["SiamFC"]})
    write_json(out / "bench_2d.json", finish_record(rec))
    md = markdown(results, sweep_res, ratio)
    (out / "bench_2d.md").write_text(f"CPU: {rec['cpu']}\n\n" + md + "\n")
    try:
        from track3d.evaluation.plots import curve_plots

        curve_plots(overall, out)
        if sweep_res:
            tradeoff_plot(sweep_res, out / "bench_2d_tradeoff.png")
    except RuntimeError as e:  # no matplotlib
        print(f"no plots: {e}")
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main, "bench_2d.py"))
