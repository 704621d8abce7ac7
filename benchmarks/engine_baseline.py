"""Collect `track3d eval` reports of the data engine's evaluation sets into one JSON and one
markdown table: per depth sensor, split (test / test_unseen) and protocol (restart / one pass).

The reports come from (per sensor S, split P, protocol M; see benchmarks/README.md):

    track3d-sim generate --preset small --train 0 --test 9 --test-unseen 9 --frames 60 --sensors S \\
        --seed 0 --out data/engine-S
    track3d track --data data/engine-S --split P --tracker T --estimator a3boxnet \\
        --results RESULTS/engine-S/P-M [--no-restart]
    track3d eval --data data/engine-S --split P --results RESULTS/engine-S/P-M --out RESULTS/engine-S/P-M-report

    python benchmarks/engine_baseline.py --results RESULTS --out benchmarks/results/engine_baseline
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

from track3d.argparsing import ArgumentParser, run_main
from track3d.evaluation.tables import columns
from track3d.jsonable import write_json
from track3d.table_text import cell, markdown_table

COLUMNS = columns("ao_2d", "ao_bev", "ao_3d", "ace_3d", "restarts", "frames")   # the evaluation table's
SENSOR_ORDER = ("ideal", "flash-lidar", "tof", "stereo")


def models_of_run(run: dict | None) -> dict:
    """{model file: first 12 hex of its sha256} of the networks a run used (its run record's
    ``track3d.models``): every row names the models that made it, whatever changes later."""
    models = ((run or {}).get("track3d") or {}).get("models") or []
    return {m["file"]: m["sha256"][:12] for m in models if m.get("file") and m.get("sha256")}


PROTOCOLS = {True: "restart", False: "onepass"}


def protocol_of(run: dict | None, folder: str, report: Path) -> str:
    """The run's protocol from its run record (``restart``), the folder's name (<split>-<protocol>)
    only for a run without one; a folder named for the other protocol is named on stderr (a
    one-pass run in a *-restart folder had been tabled as "restart")."""
    restart = (run or {}).get("restart")
    if restart is None:
        return folder
    protocol = PROTOCOLS[bool(restart)]
    if protocol != folder:
        print(f"engine_baseline: warning: {report.parent} is named '{folder}' but its run was made "
              f"{'with restarts' if restart else 'in one pass'}: tabled as '{protocol}'", file=sys.stderr)
    return protocol


def collect(results: Path) -> list[dict]:
    """One row per (sensor, split, protocol, tracker) from RESULTS/engine-*/*-report/report.json."""
    rows = []
    for rep in sorted(results.glob("engine-*/*-report/report.json")):
        sensor = rep.parents[1].name.removeprefix("engine-")
        split, _, folder = rep.parent.name.removesuffix("-report").rpartition("-")
        r = json.loads(rep.read_text())
        paired = r.get("paired") or {}
        for name, t in r["trackers"].items():
            ov = t["overall"]
            protocol = protocol_of(t.get("run"), folder, rep)
            rows.append({"sensor": sensor, "split": split, "protocol": protocol, "tracker": name,
                         "dataset": Path(r["dataset"]).name, "cpu": r.get("cpu"),
                         **{k: ov.get(k) for _, k, _ in COLUMNS}, "models": models_of_run(t.get("run")),
                         # the means' bootstrap intervals over sequences (reports since they have them)
                         **({"intervals": t["intervals"]} if t.get("intervals") else {}),
                         # ... and this run against the report's baseline, sequence by sequence
                         **({"paired": {"baseline": paired["baseline"], **paired["trackers"][name]}}
                            if name in paired.get("trackers", {}) else {})})
    return ordered(rows)


def ordered(rows: list[dict]) -> list[dict]:
    """The table's row order: sensor (SENSOR_ORDER), split, protocol, tracker."""
    key = {s: i for i, s in enumerate(SENSOR_ORDER)}
    return sorted(rows, key=lambda x: (key.get(x["sensor"], 99), x["split"], x["protocol"], x["tracker"]))


def markdown(rows: list[dict]) -> str:
    head = ["sensor", "split", "protocol", "tracker"] + [c[0] for c in COLUMNS]
    return markdown_table(head, [[r["sensor"], r["split"], r["protocol"], r["tracker"]]
                                 + [cell(r[k], fmt) for _, k, fmt in COLUMNS] for r in rows]) + "\n"


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__)
    ap.add_argument("--results", required=True, type=Path, help="folder holding engine-<sensor>/ result folders")
    ap.add_argument("--out", required=True, type=Path, help="folder for engine_baseline.json / .md")
    ap.add_argument("--update", action="store_true",
                    help="replace only the rows of the (sensor, split, protocol) report folders found under "
                         "--results and keep the others of the existing --out/engine_baseline.json (re-running "
                         "one sensor's sets, or one protocol, without the others'; default: write the rows "
                         "found, nothing else)")
    return ap


def merge(old: list[dict], new: list[dict]) -> list[dict]:
    """`new` with the rows of `old` whose (sensor, split, protocol) report is not in `new`, in the
    table's order: a report folder re-run replaces all its rows, one not re-run keeps its own."""
    group = lambda r: (r["sensor"], r["split"], r["protocol"])   # noqa: E731
    found = {group(r) for r in new}
    return ordered([r for r in old if group(r) not in found] + list(new))


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    rows = collect(a.results)
    if not rows:
        print(f"engine_baseline: error: no engine-*/*-report/report.json under {a.results}", file=sys.stderr)
        return 2
    if a.update:
        old = a.out / "engine_baseline.json"
        try:
            rows = merge(json.loads(old.read_text())["rows"], rows)
        except (OSError, ValueError, KeyError, TypeError) as e:
            print(f"engine_baseline: error: --update needs a readable {old}: {e}", file=sys.stderr)
            return 2
    write_json(a.out / "engine_baseline.json", {"rows": rows})
    (a.out / "engine_baseline.md").write_text(markdown(rows))
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main, "engine_baseline.py"))
