"""bench_table2's record: the paths it names are relative to its output folder (an absolute
--out once put the machine's folders into a committed table2.json)."""
from __future__ import annotations

import json

from benchlib.output import relative_to


def test_relative_to_hand_case(tmp_path):
    assert relative_to(tmp_path / "out" / "report" / "report.json", tmp_path / "out") == "report/report.json"
    assert relative_to(tmp_path / "x.png", tmp_path / "out") == "../x.png"


def test_table2_record_names_no_absolute_path(tiny_dataset, tmp_path):
    import bench_table2

    out = tmp_path / "t2"
    rc = bench_table2.main(["--data", str(tiny_dataset), "--variants", "edge", "--no-ope", "--trackers", "edgetrack",
                            "--sweep-estimators", "a3boxnet", "--max-sequences", "1", "--max-frames", "4",
                            "--out", str(out), "--quiet"])
    assert rc == 0
    rec = json.loads((out / "table2.json").read_text())
    assert rec["reports"] and all(not p.startswith("/") and str(tmp_path) not in p for p in rec["reports"].values())
    assert all(not p.startswith("/") for p in rec["plots"])
    assert (out / rec["reports"]["main"]).is_file()
