"""Where a range-limited sensor's 3D loss lives: one run's per-frame IoU_3d binned by what the returns show.

Each labelled frame of a `track3d track` run is put in one bin by the returns inside its TRUE
2D box (the same tests the loop makes on its own box, `track3d.range_cut`):

- `none`:    no return (the body is wholly past the range, or too dark to answer);
- `cut`:     the returns stop at the range and cover less of the 2D box than the image shows
             (`is_range_cut`: the loop builds the box from the view);
- `reaches`: the returns reach the range but cover the outline (`reaches_range`: the
             estimator's box, pushed back to the view's);
- `within`:  the returns stop short of the range (a whole view of the near side).

Per bin: frames, their share, mean IoU_3d, the mean signed error of the box's front face, back
face and centre along the line of sight (z, metres; + = too far), and the bin's share of the
run's loss (sum of 1 - IoU_3d). A frame with no box counts as IoU 0 and no error. Per sequence
(in the JSON; printed with --per-sequence): its frames per bin, mean IoU_3d and loss, which
names the sequences a bin's loss comes from.

    python benchmarks/bench_range_loss.py --data data/calib-tof3 --split test \\
        --results R/test --tracker oracle+a3boxnet

Writes <out>/range_loss_<split>_<tracker>.json and prints the table.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from benchlib.output import add_out_argument, relative_to
from benchlib.record import finish_record, start_record

from track3d.argparsing import ArgumentParser, run_main
from track3d.boxes import iou_3d
from track3d.camera import Camera
from track3d.dataset import Dataset
from track3d.evaluation.results import read_result, result_folder
from track3d.frustum import extract_frustum_bounds
from track3d.jsonable import write_json
from track3d.progress import progress
from track3d.range_cut import is_range_cut, reaches_range

KINDS = ("none", "cut", "reaches", "within")


def frame_kind(n_points: int, bounds: np.ndarray, box2d: np.ndarray, camera: Camera, range_m: float | None) -> str:
    """The bin of one frame: `n_points` returns in the 2D box `box2d` (4,) [x, y, w, h], their
    bounds (2, 3) [min; max] (ignored when there are none); range_m None: an unlimited sensor."""
    if n_points == 0:
        return "none"
    if is_range_cut(bounds, box2d, camera, range_m):
        return "cut"
    if reaches_range(bounds, box2d, camera, range_m):
        return "reaches"
    return "within"


def face_errors(est: np.ndarray, truth: np.ndarray) -> tuple[float, float, float]:
    """(front, back, centre) z error of box `est` against `truth`, both (6,) [cx, cy, cz, sx, sy, sz]."""
    front = (est[2] - est[5] / 2) - (truth[2] - truth[5] / 2)
    back = (est[2] + est[5] / 2) - (truth[2] + truth[5] / 2)
    return float(front), float(back), float(est[2] - truth[2])


def summarize(rows: list[tuple[str, float, tuple[float, float, float] | None]]) -> dict:
    """Per bin of KINDS: frames, share, mean IoU_3d, mean front / back / centre z error (over
    frames with a box; None without any) and share of the loss. rows: (kind, iou, errors or None)."""
    total_loss = sum(1.0 - iou for _, iou, _ in rows)
    out = {}
    for kind in KINDS:
        mine = [(iou, err) for k, iou, err in rows if k == kind]
        errs = np.array([err for _, err in mine if err is not None]).reshape(-1, 3)
        loss = sum(1.0 - iou for iou, _ in mine)
        out[kind] = {
            "frames": len(mine),
            "share": len(mine) / len(rows) if rows else 0.0,
            "mean_iou_3d": float(np.mean([iou for iou, _ in mine])) if mine else None,
            "front_z_error_m": float(errs[:, 0].mean()) if len(errs) else None,
            "back_z_error_m": float(errs[:, 1].mean()) if len(errs) else None,
            "centre_z_error_m": float(errs[:, 2].mean()) if len(errs) else None,
            "loss_share": loss / total_loss if total_loss > 0 else 0.0,
        }
    return out


def sequence_rows(data: Path, split: str, results: Path, tracker: str) -> dict[str, list]:
    """{sequence name: its labelled frames' (kind, iou, errors)} of one run (module doc), in the
    split's order."""
    out = {}
    for seq in progress(Dataset(data).sequences(split), desc="sequences"):
        rows = out[seq.name] = []
        res = read_result(result_folder(results, split, tracker, seq.name))
        if len(res.box3d) != len(seq):
            raise ValueError(f"{seq.name}: {len(res.box3d)} result boxes for {len(seq)} frames")
        for i in range(len(seq)):
            if seq.absent[i]:
                continue
            pts, bounds = extract_frustum_bounds(seq.points(i), seq.gt2d[i], seq.camera.M)
            kind = frame_kind(len(pts), bounds, seq.gt2d[i], seq.camera, seq.depth_range_m)
            est = res.box3d[i]
            if np.all(np.isfinite(est)):
                rows.append((kind, float(iou_3d(est[None], seq.gt3d[i][None])[0]), face_errors(est, seq.gt3d[i])))
            else:
                rows.append((kind, 0.0, None))
    return out


def sequence_summary(rows: list) -> dict:
    """One sequence's frames: their mean IoU_3d, loss (sum of 1 - IoU_3d) and frames per bin."""
    return {"frames": len(rows), "mean_iou_3d": float(np.mean([iou for _, iou, _ in rows])) if rows else None,
            "loss": float(sum(1.0 - iou for _, iou, _ in rows)),
            "bins": {kind: sum(1 for k, _, _ in rows if k == kind) for kind in KINDS}}


def sequence_table(sequences: dict) -> str:
    """Per-sequence summaries as a plain-text table, the largest loss first."""
    lines = ["sequence frames IoU_3d   loss  " + "  ".join(f"{k:>7s}" for k in KINDS)]
    for name, s in sorted(sequences.items(), key=lambda kv: -kv[1]["loss"]):
        iou = "-" if s["mean_iou_3d"] is None else f"{s['mean_iou_3d']:.3f}"
        lines.append(f"{name:8s} {s['frames']:6d} {iou:>6s} {s['loss']:6.1f}  "
                     + "  ".join(f"{s['bins'][k]:7d}" for k in KINDS))
    return "\n".join(lines)


def table(summary: dict) -> str:
    """The summary as a plain-text table."""
    def f(v, fmt):
        return "-" if v is None else format(v, fmt)
    lines = ["bin      frames  share  IoU_3d  front_m  back_m  centre_m  loss"]
    for kind, s in summary.items():
        lines.append(f"{kind:8s} {s['frames']:6d} {s['share']:6.1%} {f(s['mean_iou_3d'], '7.3f')} "
                     f"{f(s['front_z_error_m'], '+8.2f')} {f(s['back_z_error_m'], '+7.2f')} "
                     f"{f(s['centre_z_error_m'], '+9.2f')} {s['loss_share']:5.0%}")
    return "\n".join(lines)


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="the dataset the run was made on")
    ap.add_argument("--split", default="test", help="its split (default: test)")
    ap.add_argument("--results", type=Path, required=True, help="the run's --results folder (track3d track)")
    ap.add_argument("--tracker", default="edgetrack+a3boxnet",
                    help="the run's name in that folder (default: edgetrack+a3boxnet)")
    ap.add_argument("--per-sequence", action="store_true",
                    help="also print each sequence's frames per bin, mean IoU_3d and loss, the largest loss first "
                         "(the JSON holds them always)")
    add_out_argument(ap, "range_loss")
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    by_seq = sequence_rows(a.data, a.split, a.results, a.tracker)
    summary = summarize([row for rows in by_seq.values() for row in rows])
    sequences = {name: sequence_summary(rows) for name, rows in by_seq.items()}
    a.out.mkdir(parents=True, exist_ok=True)
    rec = start_record("range_loss", data=relative_to(a.data, a.out), split=a.split, tracker=a.tracker)
    rec["bins"] = summary
    rec["sequences"] = sequences
    write_json(a.out / f"range_loss_{a.split}_{a.tracker}.json", finish_record(rec))
    print(table(summary))
    if a.per_sequence:
        print()
        print(sequence_table(sequences))
    return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main, "bench_range_loss.py"))
