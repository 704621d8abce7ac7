"""Benchmarks as thin wirings of library calls: their library (benchlib) and a smoke run of a
script on the tiny dataset (no timed assertion: only that the wiring holds together)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from track3d.argparsing import run_main


def test_bench_2d_scores_are_the_toolkits(tiny_dataset, tmp_path):
    import bench_2d

    from track3d.evaluation import Experiment, TrackerSpec, average_scores

    out = tmp_path / "b2d"
    assert bench_2d.main(["--data", str(tiny_dataset), "--trackers", "kcf", "--max-sequences", "2", "--speed-seqs", "1",
                          "--out", str(out)]) == 0
    row = json.loads((out / "bench_2d.json").read_text())["trackers"]["kcf"]
    exp = Experiment(tiny_dataset, "test", tmp_path / "r", tmp_path / "p", restart=False, max_sequences=2)
    exp.run(TrackerSpec("kcf", "none"), quiet=True)
    ov = average_scores(exp.score("kcf"))
    assert row["AO_2d"] == pytest.approx(ov.values["ao_2d"], abs=1e-6)
    assert row["ACE_2d"] == pytest.approx(ov.values["ace_2d"], abs=1e-6)
    assert len(row["success_curve"]) == 101 and row["frames"] == ov.frames
    assert "| kcf |" in (out / "bench_2d.md").read_text() and (out / "success_2d.png").is_file()


def test_the_papers_fusion_gain_is_computed_from_its_table():
    from benchlib.paper import TABLE2, fusion_gain

    gain, pct = fusion_gain("3D Tracking Baseline")
    assert gain == pytest.approx(0.568 - 0.513) and pct == pytest.approx(10.72, abs=0.01)
    assert fusion_gain("Track3D")[1] == pytest.approx(5.46, abs=0.01)
    assert TABLE2["A3BoxNet"]["AO_3d"] == 0.721


def test_json_numbers_and_table_cells(tmp_path):
    from track3d.jsonable import jsonable, write_json
    from track3d.table_text import cell, markdown_table

    v = jsonable({"a": np.float32(0.1234567891), "b": float("nan"), "c": np.arange(2), "d": (np.int64(3), True),
                  "e": np.bool_(False), "f": float("inf")})
    assert v == {"a": 0.123457, "b": None, "c": [0, 1], "d": [3, True], "e": False, "f": None}
    assert json.loads(write_json(tmp_path / "x" / "r.json", {"n": np.nan}).read_text()) == {"n": None}
    assert (cell(None), cell(float("nan")), cell(0.5), cell(3, "{:d}")) == ("-", "-", "0.500", "3")
    assert markdown_table(["a", "b"], [["1", "2"]]) == "| a | b |\n|---|---|\n| 1 | 2 |"


def test_bench_fps_times_the_networks_it_passes_in(tiny_dataset, tmp_path):
    """Stage timers read the models' own counters: the SiamFC / A3BoxNet configuration has
    network time, the KCF + baseline one none (no wrapping, no swapping of models)."""
    import bench_fps

    from track3d.onnxmodel import MODELS_DIR

    if not (MODELS_DIR / "siamfc_edge_search.onnx").is_file() or not (MODELS_DIR / "a3boxnet.onnx").is_file():
        pytest.skip("no shipped models")
    out = tmp_path / "fps"
    assert bench_fps.main(["--data", str(tiny_dataset), "--frames", "5", "--preload", "40", "--threads", "1",
                           "--config", "siamfc-edge:a3boxnet", "--config", "kcf:baseline", "--tag", "t",
                           "--config", f"kcf:a3boxnet@{MODELS_DIR / 'a3boxnet_stereo.onnx'}",
                           "--out-dir", str(out)]) == 0
    rows = {r["config"]: r for r in json.loads((out / "fps_t.json").read_text())["results"]}
    # a configuration's own box net, side by side with the default one in the same run
    other = rows[f"kcf:a3boxnet@{MODELS_DIR / 'a3boxnet_stereo.onnx'}"]
    assert other["models"]["estimator_options"]["model"].endswith("a3boxnet_stereo.onnx")
    assert other["stages"]["net3d"]["median_ms"] > 0
    assert "model" not in rows["siamfc-edge:a3boxnet"]["models"]["estimator_options"]
    assert rows["siamfc-edge:a3boxnet"]["stages"]["net2d"]["median_ms"] > 0
    assert rows["siamfc-edge:a3boxnet"]["stages"]["net3d"]["median_ms"] > 0
    assert rows["kcf:baseline"]["stages"]["net2d"]["median_ms"] == 0 == rows["kcf:baseline"]["stages"]["net3d"]["median_ms"]
    assert "| kcf:baseline |" in (out / "fps_t.md").read_text()


def test_bench_fps_matches_the_pair_inside_the_loop_with_depth_stereo(tiny_dataset, tmp_path):
    """--depth stereo: the clouds are matched from the pair inside each update (their time in the
    frustum stage), one row per --stereo-follow, --stereo-max-match and --stereo-max-cost value;
    not with --int8 / --torch."""
    import itertools

    import bench_fps

    out = tmp_path / "fps"
    assert bench_fps.main(["--data", str(tiny_dataset), "--frames", "5", "--preload", "40", "--threads", "1",
                           "--config", "kcf:baseline", "--depth", "stereo", "--stereo-follow", "0", "1.5",
                           "--stereo-max-match", "0", "1024", "--stereo-max-cost", "0", "50000",
                           "--tag", "s", "--out-dir", str(out)]) == 0
    rows = {r["config"]: r for r in json.loads((out / "fps_s.json").read_text())["results"]}
    want = list(itertools.product((0.0, 1.5), (0, 1024), (0, 50000)))
    assert list(rows) == [f"kcf:baseline stereo follow {k:g}" + (f" rows past {px}" if px else "")
                          + (f" cost budget {c}" if c else "") for k, px, c in want]
    for (k, px, c), r in zip(want, rows.values()):
        assert r["stereo_follow"] == k and r["stereo_max_match_px"] == px and r["stereo_max_match_cost"] == c
        assert r["depth"] == "stereo from the pair" and r["frames"] == 5
    with pytest.raises(SystemExit) as e:   # the parser's one-line error, exit 2 (was exit 1, no "error:")
        bench_fps.main(["--data", str(tiny_dataset), "--depth", "stereo", "--int8", "--out-dir", str(out)])
    assert e.value.code == 2


def test_bench_fps_puts_auto_beside_fp32_and_records_the_picks(tiny_dataset, tmp_path, monkeypatch):
    """--precision fp32 auto: one row each in the same run; each row names the engine and
    precision every network ran in (auto's picks; the fp32 row all onnxruntime fp32)."""
    import bench_fps

    monkeypatch.setenv("TRACK3D_CACHE_DIR", str(tmp_path / "cache"))
    out = tmp_path / "fps"
    assert bench_fps.main(["--data", str(tiny_dataset), "--frames", "3", "--preload", "20", "--threads", "1",
                           "--config", "edgetrack:a3boxnet", "--precision", "fp32", "auto", "--tag", "p",
                           "--out-dir", str(out)]) == 0
    rows = {r["config"]: r for r in json.loads((out / "fps_p.json").read_text())["results"]}
    assert set(rows) == {"edgetrack:a3boxnet", "edgetrack:a3boxnet auto"}
    fp32 = rows["edgetrack:a3boxnet"]["networks"]
    from track3d.boxnet import DEFAULT_MODEL

    assert {n["file"] for n in fp32} >= {"edgetrack_search.onnx", DEFAULT_MODEL}
    assert all((n["engine"], n["precision"]) == ("onnxruntime", "fp32") for n in fp32)
    assert rows["edgetrack:a3boxnet auto"]["asked"]["precision"] == "auto"   # its precision: what ran
    assert all(n["precision"] in ("fp32", "int8", "bf16") for n in rows["edgetrack:a3boxnet auto"]["networks"])


def test_torch_stand_ins_are_passed_to_the_tracker_and_checked(tmp_path):
    """A torch module of the same weights, behind OnnxModel's interface, given to SiamFCTracker
    as its models: it tracks, counts its time and checks itself against onnxruntime once."""
    torch = pytest.importorskip("torch")
    from benchlib.torch_models import TorchModel
    from track3d_train.siamfc.export import ExemplarGraph, SearchGraph, export_onnx
    from track3d_train.siamfc.model import SiamFC, config_for

    from track3d.onnxmodel import OnnxModel
    from track3d.siamfc import SiamFCTracker

    torch.manual_seed(0)
    net = SiamFC(config_for("edge")).eval()
    pz, px = export_onnx(net, tmp_path / "s")
    z = TorchModel(torch, ExemplarGraph(net), OnnxModel(pz), tmp_path / "ckpt.pt")
    x = TorchModel(torch, SearchGraph(net), OnnxModel(px), tmp_path / "ckpt.pt")
    t = SiamFCTracker(z, x)
    img = np.random.default_rng(0).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    t.init(img, np.array([100.0, 80, 40, 30]))
    t.update(img)
    assert t.exemplar is z and z.check["ok"] and x.check["ok"] and x.run_ms > 0


def test_the_readme_tables_are_the_committed_results(tmp_path):
    import readme_tables

    assert readme_tables.main(["--check"]) == 0
    readme = tmp_path / "README.md"
    text = readme_tables.REPO.joinpath("README.md").read_text()
    assert text.count("<!-- readme_tables.py: ") == len(readme_tables.TABLES)
    import re

    start = text.index("<!-- readme_tables.py: speed -->")
    m = re.compile(r"\d").search(text, text.index("| **", start))        # a number edited by hand
    edited = text[:m.start()] + str((int(m.group()) + 1) % 10) + text[m.end():]
    assert edited != text
    readme.write_text(edited)
    assert readme_tables.main(["--check", "--readme", str(readme)]) == 1
    assert readme_tables.main(["--write", "--readme", str(readme)]) == 0 and readme.read_text() == text


def test_an_empty_readme_section_is_filled_and_the_next_one_kept():
    """A new, empty section once reached over to the next section's end marker: --write
    replaced both with one table and the other table vanished from the README."""
    import readme_tables

    text = ("a\n<!-- readme_tables.py: speed -->\n<!-- /readme_tables.py -->\nkept prose\n"
            "<!-- readme_tables.py: engine -->\nold\n<!-- /readme_tables.py -->\nz\n")
    out = readme_tables.render(text, readme_tables.REPO)
    assert out.count("<!-- readme_tables.py: ") == 2 and "kept prose" in out and "old" not in out
    assert out.index(readme_tables.speed_table(readme_tables.REPO)) < out.index("kept prose")



def test_the_long_table_bolds_each_sensors_default(tmp_path):
    """The long-watch table: the range sensors' default keeps the views (their runs without are
    ...-noviews), stereo's is one view (its runs with them are ...-views); each row bolds its
    default and puts the views' runs under "past views"."""
    import readme_tables

    rows = []
    for sensor, runs in (("ideal", {"": 0.9, "-noviews": 0.8}), ("stereo", {"": 0.7, "-views": 0.6})):
        for tracker, proto in (("oracle+a3boxnet", "restart"), ("edgetrack+a3boxnet", "onepass")):
            for suffix, ao in runs.items():
                rows.append({"sensor": sensor, "split": "test", "protocol": proto, "tracker": tracker + suffix,
                             "ao_3d": ao + (0.01 if proto == "onepass" else 0.0), "ace_3d": 0.5})
    f = tmp_path / readme_tables.RESULTS / "long_watch" / "engine_baseline.json"
    f.parent.mkdir(parents=True)
    f.write_text(json.dumps({"rows": rows}))
    lines = readme_tables.long_table(tmp_path).splitlines()
    ideal = next(x for x in lines if x.startswith("| ideal"))
    stereo = next(x for x in lines if x.startswith("| stereo"))
    assert ideal.split(" | ")[2:6] == ["0.800 / 0.500", "**0.900 / 0.500**", "0.810 / 0.500", "**0.910 / 0.500**"]
    assert stereo.split(" | ")[2:6] == ["**0.700 / 0.500**", "0.600 / 0.500", "**0.710 / 0.500**", "0.610 / 0.500"]
    assert lines.index(ideal) < lines.index(stereo)



def test_the_aims_table_judges_each_aim_on_its_own_numbers(tmp_path):
    """Hand cases: an aim met exactly at its bounds, one missed by its ACE alone, the held-out
    gap just inside and just outside 0.03, a missing run shown as '-', the peer level within
    0.0005 and behind, and the speed aim."""
    import readme_tables

    def row(sensor, split, protocol, tracker, ao, ace):
        return {"sensor": sensor, "split": split, "protocol": protocol, "tracker": tracker, "ao_3d": ao, "ace_3d": ace}

    short = [{**row("ideal", "test", "restart", "oracle+a3boxnet", 0.85, 0.25),          # both bounds: met
              "intervals": {"ao_3d": [0.8, 0.9], "ace_3d": [0.2, 0.3]}},                 # shown with the values
             row("ideal", "test_unseen", "restart", "oracle+a3boxnet", 0.90, 0.31),     # ACE over: not met
             row("ideal", "test", "onepass", "edgetrack+a3boxnet", 0.90, 0.20),
             row("ideal", "test_unseen", "onepass", "edgetrack+a3boxnet", 0.875, 0.40),  # gap -0.025: met
             row("tof", "test", "onepass", "edgetrack+a3boxnet", 0.749, 0.10),           # AO under: not met
             {**row("ideal", "test", "onepass", "nano+a3boxnet", 0.8996, 0.20),          # the peer 0.0004 behind: level
              "paired": {"baseline": "edgetrack+a3boxnet", "ao_3d": {"lo": -0.001, "hi": 0.0002}}},
             {**row("tof", "test", "onepass", "nano+a3boxnet", 0.760, 0.10),             # the peer ahead, beyond
              "paired": {"baseline": "edgetrack+a3boxnet", "ao_3d": {"lo": 0.002, "hi": 0.02}}},  # the interval
             {**row("tof", "test_unseen", "onepass", "edgetrack+a3boxnet", 0.70, 0.10),  # an interval of no
              "intervals": {"ao_3d": [float("nan"), float("nan")]}}]                    # sequence: not shown
    long_ = [row("ideal", "test", "onepass", "edgetrack+a3boxnet", 0.90, 0.20),
             row("ideal", "test_unseen", "onepass", "edgetrack+a3boxnet", 0.865, 0.20)]  # gap -0.035: not met
    for rel, rows in (("engine_current", short), ("long_watch", long_)):
        f = tmp_path / readme_tables.RESULTS / rel / "engine_baseline.json"
        f.parent.mkdir(parents=True)
        f.write_text(json.dumps({"rows": rows}))
    f = tmp_path / readme_tables.RESULTS / readme_tables.SPEED_ROWS[0][1]
    f.parent.mkdir(parents=True)
    f.write_text(json.dumps({"results": [{"config": readme_tables.SPEED_ROWS[0][2], "backend": "onnxruntime",
                                          "precision": "fp32", "fps_median": 149.6}]}))
    cells = {line.split(" | ")[0][2:]: line.split(" | ")[1:]
             for line in readme_tables.aims_table(tmp_path).splitlines()[2:]}
    aims = [a[0] for a in readme_tables.AIMS]
    assert cells[aims[0]] == ["0.850 (0.800-0.900) / 0.250 (0.20-0.30) m: met", "- |"]
    assert cells[aims[1]][0] == "0.900 / 0.310 m: **not met**"
    assert cells[aims[3]] == ["0.875 vs 0.900 (-0.025): met", "0.865 vs 0.900 (-0.035): **not met** |"]
    tof = next(a for a in aims if "tof depth, test:" in a)
    assert cells[tof] == ["0.749: **not met**", "- |"]
    assert cells[next(a for a in aims if "tof depth, held-out" in a)] == ["0.700: **not met**", "- |"]
    assert next(v for k, v in cells.items() if "150 FPS" in k)[0] == "149 FPS: **not met**"
    peer = [v for k, v in cells.items() if "NanoTrack" in k]
    assert peer[0] == ["ahead on 0, level on 1, behind on 1 (1 beyond the paired 95% interval) of 2: **not met**",
                       "- |"]                                                             # one pass
    assert peer[1] == ["-", "- |"]                                                       # no restart runs
    # a pair not compared sequence by sequence: the counts alone
    del short[5]["paired"]
    (tmp_path / readme_tables.RESULTS / "engine_current" / "engine_baseline.json").write_text(json.dumps({"rows": short}))
    line = next(x for x in readme_tables.aims_table(tmp_path).splitlines() if "NanoTrack" in x and "one pass" in x)
    assert "ahead on 0, level on 1, behind on 1 of 2: **not met**" in line
    # OpenCV's trackers: no run yet -> '-'; then one split with KCF surely behind EdgeTrack and
    # MOSSE level, each paired against EdgeTrack's row of the same report
    opencv = [v for k, v in cells.items() if "OpenCV" in k and "A3BoxNet" in k]
    assert opencv == [["-", "- |"], ["-", "- |"]]
    f = tmp_path / readme_tables.RESULTS / readme_tables.OPENCV_PEERS
    f.parent.mkdir(parents=True)
    f.write_text(json.dumps({"rows": [
        row("tof", "test", "onepass", "edgetrack+a3boxnet", 0.80, 0.3),
        {**row("tof", "test", "onepass", "kcf+a3boxnet", 0.70, 0.5),
         "paired": {"baseline": "edgetrack+a3boxnet", "ao_3d": {"lo": -0.15, "hi": -0.05}}},
        {**row("tof", "test", "onepass", "mosse+a3boxnet", 0.8003, 0.3),
         "paired": {"baseline": "edgetrack+a3boxnet", "ao_3d": {"lo": -0.01, "hi": 0.01}}}]}))
    line = next(x for x in readme_tables.aims_table(tmp_path).splitlines()
                if "OpenCV" in x and "A3BoxNet" in x and "one pass" in x)
    assert "ahead on 1 (1 beyond the paired 95% interval), level on 1, behind on 0 of 2: met" in line
    # 2D alone: ahead of every other tracker on one split, behind the best on the other
    assert next(v for k, v in cells.items() if "2D alone" in k) == ["-", "- |"]
    for split, other in (("test", 0.70), ("test_unseen", 0.90)):
        f = tmp_path / readme_tables.RESULTS / readme_tables.PEERS_2D.format(split=split)
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(json.dumps({"trackers": {"edgetrack": {"ao_2d": 0.86}, "nano": {"ao_2d": other},
                                              "kcf": {"ao_2d": 0.5}}}))
    line = next(x for x in readme_tables.aims_table(tmp_path).splitlines() if "2D alone" in x)
    assert "ahead of all 2 on 1 of 2 splits (AO_2d 0.860 / 0.860 vs the best other 0.700 / 0.900): **not met**" in line
    # the long watches: restarts and OpenCV's trackers from the long watches' table, 2D alone per sensor's watch
    f = tmp_path / readme_tables.RESULTS / readme_tables.LONG_PEERS
    f.parent.mkdir(parents=True, exist_ok=True)
    f.write_text(json.dumps({"rows": [
        row("stereo", "test", "restart", "edgetrack+a3boxnet", 0.70, 0.5),
        {**row("stereo", "test", "restart", "nano+a3boxnet", 0.71, 0.5),                # the peer ahead, inside
         "paired": {"baseline": "edgetrack+a3boxnet", "ao_3d": {"lo": -0.01, "hi": 0.03}}},  # the interval
        row("stereo", "test", "onepass", "edgetrack+a3boxnet", 0.70, 0.5),
        {**row("stereo", "test", "onepass", "csrt+a3boxnet", 0.60, 0.5),
         "paired": {"baseline": "edgetrack+a3boxnet", "ao_3d": {"lo": -0.2, "hi": -0.05}}}]}))
    f = tmp_path / readme_tables.RESULTS / readme_tables.PEERS_2D_LONG.format(sensor="stereo", split="test")
    f.write_text(json.dumps({"trackers": {"edgetrack": {"ao_2d": 0.80}, "nano": {"ao_2d": 0.79}}}))
    cells = {line.split(" | ")[0][2:]: line.split(" | ")[1:]
             for line in readme_tables.aims_table(tmp_path).splitlines()[2:]}
    assert [v[1] for k, v in cells.items() if "NanoTrack v2 + A3BoxNet" in k] == [
        "- |", "ahead on 0, level on 0, behind on 1 (0 beyond the paired 95% interval) of 1: **not met** |"]
    assert [v[1] for k, v in cells.items() if "OpenCV" in k and "A3BoxNet" in k] == [
        "ahead on 1 (1 beyond the paired 95% interval), level on 0, behind on 0 of 1: met |", "- |"]
    assert next(v for k, v in cells.items() if "2D alone" in k)[1] == (
        "ahead of all 1 on 1 of 1 splits (AO_2d 0.800 vs the best other 0.790): met |")
    # the long watches' peers table: each tracker one pass and with restarts (the restarts made)
    rows = json.loads((tmp_path / readme_tables.RESULTS / readme_tables.LONG_PEERS).read_text())["rows"]
    rows[0]["restarts"], rows[1]["restarts"] = 2, 0
    (tmp_path / readme_tables.RESULTS / readme_tables.LONG_PEERS).write_text(json.dumps({"rows": rows}))
    stereo = next(x for x in readme_tables.long_peers_table(tmp_path).splitlines() if x.startswith("| stereo | test |"))
    assert stereo == "| stereo | test | **0.700** | - | - | 0.600 | - | - | **0.700 (2)** | 0.710 (0) | - | - | - | - |"
    table = readme_tables.peers_table(tmp_path).splitlines()
    tof = next(x for x in table if x.startswith("| tof | test |"))
    # EdgeTrack's and NanoTrack's from engine_current, KCF's and MOSSE's from opencv_peers
    assert tof == "| tof | test | **0.749** | 0.760 | 0.700 | - | 0.800 | - |"

@pytest.mark.skipif(not hasattr(__import__("os"), "sched_setaffinity"), reason="no CPU affinity here")
def test_pin_threads_pins_every_thread_and_widens_again():
    import cv2

    from track3d.machine import START_CPUS, affinity_of_all_threads, pin_threads

    before = cv2.getNumThreads()
    try:
        assert pin_threads(1) == [START_CPUS[0]]
        assert affinity_of_all_threads() == [START_CPUS[0]] and cv2.getNumThreads() == 1
        assert pin_threads(len(START_CPUS)) == list(START_CPUS) and affinity_of_all_threads() == list(START_CPUS)
    finally:
        pin_threads(len(START_CPUS))
        cv2.setNumThreads(before)


def test_latency_record_names_the_tracker_that_ran(tmp_path):
    """bench_latency wrote tracker "siamfc-edge" into its record whatever from_default built."""
    import json

    import bench_latency

    from track3d.synthetic import CAM, make_synthetic_dataset
    from track3d.tracker import Track3D

    data = make_synthetic_dataset(tmp_path / "d", {"a": 12})
    out = tmp_path / "lat.json"
    assert bench_latency.main(["--data", str(data), "--frames", "20", "--out", str(out)]) in (0, None)
    rec = json.loads(out.read_text())["config"]
    want = Track3D.from_default(CAM).describe()
    assert (rec["tracker"], rec["estimator"]) == (want["tracker"], want["estimator"])



def test_latency_of_a_stereo_camera_s_loop_reports_what_the_matcher_did(tiny_dataset, tmp_path, capsys):
    """bench_latency --depth stereo: the clouds matched from the pair inside each update, the
    matching cost of every update recorded (the tail's, by quartile), the caps in the record;
    the caps without --depth stereo: one line, status 2."""
    import json

    import bench_latency

    out = tmp_path / "lat.json"
    assert bench_latency.main(["--data", str(tiny_dataset), "--frames", "12", "--warmup", "2", "--depth", "stereo",
                               "--stereo-max-cost", "2000000", "--out", str(out)]) == 0
    rep = json.loads(out.read_text())
    assert rep["config"]["depth"] == "stereo" and rep["config"]["frames"] == 12
    assert rep["config"]["stereo"] == {"max_match_cost": 2000000, "max_match_px": 0}
    m = rep["stereo_matching"]
    assert 0 < m["cost_median"] <= m["cost_p99"] <= m["cost_max"]
    assert 0 <= m["dropped"] <= 12
    assert len(m["by_cost_quartile"]) == 4 and "without a cloud" in capsys.readouterr().out
    assert run_main(lambda: bench_latency.main(["--data", str(tiny_dataset), "--stereo-max-cost", "5"]),
                    "bench_latency.py") == 2
    assert "error: --stereo-max-cost" in capsys.readouterr().err


def test_memory_bench_plays_one_watch_back_and_forth_and_records_each_window(tmp_path, capsys):
    """bench_memory: the frame order is a ping-pong (hand case), the run is one watch without a
    restart, each window gives one reading, the statuses add up to the measured updates; an
    unknown sequence is a one-line error."""
    import itertools

    import bench_memory

    from track3d.synthetic import make_synthetic_dataset

    assert list(itertools.islice(bench_memory.ping_pong(3), 8)) == [0, 1, 2, 1, 0, 1, 2, 1]
    g = bench_memory.growth(np.array([0.0, 1e4, 2e4]), np.array([5.0, 6.0, 7.0]))
    assert g["slope_per_10k_updates"] == pytest.approx(1.0) and g["last_minus_first"] == 2.0
    data = make_synthetic_dataset(tmp_path / "d", {"a": 8})
    out = tmp_path / "mem.json"
    assert bench_memory.main(["--data", str(data), "--updates", "40", "--warmup", "5", "--every", "10",
                              "--trim", "--out", str(out)]) == 0
    rec = json.loads(out.read_text())
    assert len(rec["readings"]["rss_mb_after_trim"]) == 5 and rec["config"]["trim"] is True
    assert rec["readings"]["updates"] == [0, 10, 20, 30, 40] and len(rec["readings"]["window_median_ms"]) == 4
    assert sum(rec["statuses"].values()) == 40 and rec["config"]["frames"] == 8
    assert rec["rss_mb"]["max"] >= rec["rss_mb"]["min"] > 0 and rec["state_kb"]["min"] > 0
    capsys.readouterr()
    assert run_main(lambda: bench_memory.main(["--data", str(data), "--sequence", "nope"]), "bench_memory.py") == 2
    assert "error: no sequence 'nope'" in capsys.readouterr().err


def test_memory_bench_of_a_stereo_camera_s_watch(tiny_dataset, tmp_path, capsys):
    """bench_memory --depth stereo: the pair matched inside each update over the whole watch (the
    matcher's cap recorded); the cap without --depth stereo: one line, status 2."""
    import bench_memory

    out = tmp_path / "mem.json"
    assert bench_memory.main(["--data", str(tiny_dataset), "--updates", "20", "--warmup", "2", "--every", "10",
                              "--depth", "stereo", "--stereo-max-cost", "1000000", "--out", str(out)]) == 0
    rec = json.loads(out.read_text())
    assert rec["config"]["depth"] == "stereo" and rec["config"]["stereo"] == {"max_match_cost": 1000000}
    assert sum(rec["statuses"].values()) == 20 and len(rec["readings"]["window_median_ms"]) == 2
    assert "matched from the pair" in capsys.readouterr().out
    assert run_main(lambda: bench_memory.main(["--data", str(tiny_dataset), "--stereo-max-cost", "5"]),
                    "bench_memory.py") == 2
    assert "add --depth stereo" in capsys.readouterr().err


def test_precision_verdicts_pass_only_on_every_split(tmp_path):
    """A variant measured on two splits is allowed only if its "<network> only" row passed on
    both; the verdict lands on every file of that network."""
    import json

    import bench_precision

    def acc(split, passes_a3, passes_et):
        d = {"restart": {"d_ao_3d": -0.001, "d_ace_3d": 0.002}, "one_pass": {"d_ao_3d": -0.001, "d_ace_3d": 0.002}}
        return {"tracker": "edgetrack", "boxnet": "a3boxnet.onnx", "split": split, "sequences": 9, "frames": 540,
                "rule": "r",
                "rows": {"onnxruntime/fp32": {}, "onnxruntime/int8 a3boxnet only": {"passes": passes_a3, "delta": d},
                         "onnxruntime/int8 edgetrack only": {"passes": passes_et, "delta": d},
                         "onnxruntime/int8 both": {"passes": True, "delta": d}}}

    path = bench_precision.write_verdicts([acc("test", True, True), acc("test_unseen", False, True)], tmp_path)
    models = json.loads(path.read_text())["models"]
    assert models["a3boxnet.onnx"]["onnxruntime/int8"]["passes"] is False
    assert models["a3boxnet.onnx"]["onnxruntime/int8"]["sha256"] == "-"   # bound to the (here absent) file
    assert models["a3boxnet.onnx"]["onnxruntime/int8"]["splits"]["test"]["passes"] is True
    for f in ("edgetrack_search.onnx", "edgetrack_template.onnx"):
        assert models[f]["onnxruntime/int8"]["passes"] is True
        assert set(models[f]["onnxruntime/int8"]["splits"]) == {"test", "test_unseen"}
    # a run that does not name its box network (before --boxnet-model) measured the default of its
    # day: its verdict is refused, not put on today's default
    old = acc("test", True, True)
    del old["boxnet"]
    with pytest.raises(ValueError, match="does not name its A3BoxNet"):
        bench_precision.write_verdicts([old], tmp_path)


def test_precision_loop_rows_are_labelled_by_variant_with_any_box_network():
    """The loop rows of a box network chosen by --boxnet-model keep their plain labels (the
    onnxruntime/fp32 row is every ratio's reference: a run without it crashed at the report)."""
    import bench_precision

    for boxnet in ("a3boxnet.onnx", "a3boxnet_narrow.onnx"):
        cfgs = bench_precision.loop_configs("edgetrack", boxnet)
        assert cfgs[0]["label"] == "onnxruntime/fp32" and cfgs[-1]["label"] == "auto/auto"
        assert all(c["estimator_options"]["model"] == boxnet for c in cfgs)


def test_engine_rows_name_their_models():
    import engine_baseline
    import readme_tables

    run = {"track3d": {"models": [{"file": "a3boxnet.onnx", "sha256": "ab" * 32},
                                  {"file": "edgetrack_search.onnx", "sha256": "cd" * 32}]}}
    assert engine_baseline.models_of_run(run) == {"a3boxnet.onnx": "ab" * 6, "edgetrack_search.onnx": "cd" * 6}
    assert engine_baseline.models_of_run(None) == {} and engine_baseline.models_of_run({"track3d": {}}) == {}
    line = readme_tables.models_line([{"models": {"a3boxnet.onnx": "abababababab"}},
                                      {"models": {"a3boxnet.onnx": "abababababab"}}, {}], "now")
    assert line.endswith("a3boxnet.onnx `abababababab`.") and readme_tables.models_line([{}], "x").endswith("not recorded.")


def test_precision_accuracy_skips_a_variant_that_is_not_there(tmp_path, monkeypatch):
    """A network without an int8 twin is a skipped row, not a crash of the whole run (the
    registries raise TrackerUnavailable for a missing model file; it escaped before). Its runs'
    scratch is outside the results folder (a killed run left a tmp folder there)."""
    import bench_precision

    import track3d.evaluation as evaluation
    from track3d.onnxmodel import MODELS_DIR, variant_path
    from track3d.synthetic import make_synthetic_dataset

    roots, real = [], evaluation.Experiment
    monkeypatch.setattr(evaluation, "Experiment", lambda data, split, out, **kw: (roots.append(Path(out)),
                                                                               real(data, split, out, **kw))[1])
    assert not variant_path(MODELS_DIR / "edgetrack_search.onnx", "int8").is_file()
    data = make_synthetic_dataset(tmp_path / "d", {"a": 4})
    out = tmp_path / "results"
    out.mkdir()
    acc = bench_precision.bench_accuracy(data, "test", out, "edgetrack", only=["onnxruntime/int8"])
    assert "skipped" in acc["rows"]["onnxruntime/int8 edgetrack only"]
    assert "restart" in acc["rows"]["onnxruntime/fp32"]
    assert roots and not any(out in r.parents for r in roots)
    assert not any(out.iterdir())


def test_bench_accumulation_carries_a_view_onto_the_body_in_a_later_frame(tiny_dataset, tmp_path):
    """The true pose maps one frame's returns onto the body in another frame: inside its label
    box there (the pose convention of meta.json's frame_data), and the run writes every variant."""
    import bench_accumulation as bench
    from track3d.dataset import Dataset
    from track3d.frustum import extract_frustum

    seq = Dataset(tiny_dataset).sequences("test")[0]
    fd = seq.meta["frame_data"]
    R, T = np.asarray(fd["R"]).reshape(-1, 3, 3), np.asarray(fd["T"])
    i, j = [k for k in range(len(seq)) if not seq.absent[k]][:2]
    pts = extract_frustum(seq.points(i), seq.gt2d[i], seq.camera.M)
    moved = bench.to_camera(bench.to_body(pts, R[i], T[i]), R[j], T[j])
    g = seq.gt3d[j]
    assert np.all(np.abs(moved - g[:3]) <= g[3:] / 2 + 0.02)
    wrong = bench.to_camera(bench.to_body(pts, R[i].T, T[i]), R[j].T, T[j])    # the transposed pose
    if not np.allclose(R[i], R[j]):
        assert not np.allclose(wrong, moved, atol=1e-3)
    assert bench.main(["--data", str(tiny_dataset), "--split", "test", "--limit", "1", "--out", str(tmp_path)]) == 0
    rec = json.loads((tmp_path / "accumulation.json").read_text())
    assert set(rec["mean_iou_3d"]) == set(bench.VARIANTS)
    assert all(0.0 <= v <= 1.0 for v in rec["mean_iou_3d"].values())
    assert bench.main(["--data", str(tiny_dataset), "--split", "test", "--limit", "1", "--every", "2",
                       "--out", str(tmp_path)]) == 0


def test_carved_back_bounds_the_true_back_face_and_tightens_with_views(tiny_dataset):
    """Space carving with the true pose (ideal depth): the farthest point the past views leave is
    never nearer than the body's true back face (less one sample along the ray), there is no bound
    without a past view, and more views never loosen it."""
    import bench_accumulation as bench
    from track3d.dataset import Dataset

    for seq in Dataset(tiny_dataset).sequences("test")[:2]:
        fd = seq.meta["frame_data"]
        R, T = np.asarray(fd["R"]).reshape(-1, 3, 3), np.asarray(fd["T"])
        frames = [k for k in range(len(seq)) if not seq.absent[k] and (seq.depth(k) > 0).sum() > 20]
        j = frames[-1]
        d = seq.depth(j)
        assert bench.carved_back(seq.camera, d, R[j], T[j], []) == float("inf")
        back = seq.gt3d[j][2] + seq.gt3d[j][5] / 2.0
        bounds = []
        for n in range(1, len(frames)):
            past = [(seq.depth(k), R[k], T[k]) for k in frames[:n]]
            bounds.append(bench.carved_back(seq.camera, d, R[j], T[j], past))
        width = float(np.ptp(seq.points(j)[:, 0])) + float(np.ptp(seq.points(j)[:, 1]))
        step = bench.RAY_REACH * width / (bench.RAY_SAMPLES - 1)
        assert all(b >= back - step - bench.CARVE_TOL_M for b in bounds), (bounds, back)
        assert all(b2 <= b1 + 1e-9 for b1, b2 in zip(bounds, bounds[1:])), bounds


def test_icp_recovers_a_known_rigid_motion_of_a_curved_surface():
    """Hand case: a bumpy patch moved by 3 degrees about a tilted axis and 5 cm; point-to-plane
    ICP from the identity puts it back (the transform that maps the moved points onto the patch)."""
    import bench_accumulation as bench

    g = np.linspace(-1.0, 1.0, 60)
    X, Y = np.meshgrid(g, g)
    Z = 20.0 + 0.3 * np.sin(2.5 * X) * np.cos(1.7 * Y) + 0.2 * X ** 2
    dst = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    dzdx = 0.3 * 2.5 * np.cos(2.5 * X) * np.cos(1.7 * Y) + 0.4 * X
    dzdy = -0.3 * 1.7 * np.sin(2.5 * X) * np.sin(1.7 * Y)
    n = np.stack([-dzdx, -dzdy, np.ones_like(X)], axis=-1).reshape(-1, 3)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    a = np.radians(3.0)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    Rm = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
    centre = dst.mean(axis=0)
    src = (dst - centre) @ Rm.T + centre + np.array([0.05, -0.02, 0.03])
    M = bench.icp(src, dst, n, np.eye(4))
    back = src @ M[:3, :3].T + M[:3, 3]
    assert np.abs(back - dst).max() < 2e-3
    assert not np.allclose(M, np.eye(4), atol=1e-3)


def test_icp_poses_follow_the_true_rotation_of_a_simulated_body(tiny_dataset):
    """The pose from the depth alone, against the simulator's: the rotation between the first
    and the last present frame agrees within a few degrees on clean depth."""
    import bench_accumulation as bench
    from track3d.dataset import Dataset

    def angle(m):
        return float(np.degrees(np.arccos(np.clip((np.trace(m) - 1) / 2, -1, 1))))

    turns = []
    for seq in Dataset(tiny_dataset).sequences("test"):
        Rt = np.asarray(seq.meta["frame_data"]["R"]).reshape(-1, 3, 3)
        frames = [k for k in range(len(seq)) if not seq.absent[k]]
        turns.append((angle(Rt[frames[0]] @ Rt[frames[-1]].T), seq, frames[0], frames[-1]))
    turned, seq, f0, f1 = max(turns, key=lambda t: t[0])
    assert turned > 5.0              # the body turned: the check below can fail
    Rt = np.asarray(seq.meta["frame_data"]["R"]).reshape(-1, 3, 3)
    for projective in (False, True):
        R, T, _ = bench.icp_poses(seq, projective=projective)
        err = angle((R[f1].T @ R[f0]).T @ (Rt[f0] @ Rt[f1].T))
        assert err < 0.15 * turned, (projective, err, turned)


def test_engine_baseline_update_replaces_only_the_sensors_it_found(tmp_path, capsys):
    """--update: a re-run of one sensor's sets replaces that sensor's rows and keeps the others';
    without a readable table to update it says so in one line."""
    import engine_baseline

    def row(sensor, tracker, ao):
        return {"sensor": sensor, "split": "test", "protocol": "onepass", "tracker": tracker, "ao_2d": None,
                "ao_bev": None, "ao_3d": ao, "ace_3d": None, "restarts": 0, "frames": 60}

    old = [row("ideal", "a", 0.9), row("stereo", "a", 0.5), row("stereo", "gone", 0.4), row("tof", "a", 0.8)]
    new = [row("stereo", "a", 0.6)]
    merged = engine_baseline.merge(old, new)
    assert [(r["sensor"], r["tracker"], r["ao_3d"]) for r in merged] == [
        ("ideal", "a", 0.9), ("tof", "a", 0.8), ("stereo", "a", 0.6)]
    rep = tmp_path / "R" / "engine-stereo" / "test-onepass-report"
    rep.mkdir(parents=True)
    (rep / "report.json").write_text(json.dumps({"dataset": "data/engine-stereo", "trackers": {
        "a": {"overall": {"ao_3d": 0.6}}}}))
    assert engine_baseline.main(["--results", str(tmp_path / "R"), "--out", str(tmp_path / "out"), "--update"]) == 2
    assert "--update needs a readable" in capsys.readouterr().err
    out = tmp_path / "out"
    out.mkdir()
    (out / "engine_baseline.json").write_text(json.dumps({"rows": old}))
    assert engine_baseline.main(["--results", str(tmp_path / "R"), "--out", str(out), "--update"]) == 0
    rows = json.loads((out / "engine_baseline.json").read_text())["rows"]
    assert [(r["sensor"], r["tracker"]) for r in rows] == [("ideal", "a"), ("tof", "a"), ("stereo", "a")]
    assert rows[-1]["ao_3d"] == 0.6


def test_engine_baseline_update_replaces_only_the_report_folders_it_finds():
    """--update: a (sensor, split, protocol) report re-run replaces all its rows (a tracker gone
    from it goes); one not re-run keeps its rows (re-running one protocol of a sensor)."""
    import engine_baseline

    def row(sensor, split, protocol, tracker, ao):
        return {"sensor": sensor, "split": split, "protocol": protocol, "tracker": tracker, "ao_3d": ao}

    old = [row("ideal", "test", "onepass", "a", 0.1), row("ideal", "test", "onepass", "b", 0.2),
           row("ideal", "test", "restart", "oracle", 0.3), row("tof", "test", "onepass", "a", 0.4)]
    new = [row("ideal", "test", "onepass", "a", 0.9)]
    got = {(r["sensor"], r["protocol"], r["tracker"]): r["ao_3d"] for r in engine_baseline.merge(old, new)}
    assert got == {("ideal", "onepass", "a"): 0.9, ("ideal", "restart", "oracle"): 0.3, ("tof", "onepass", "a"): 0.4}


def test_bench_crop_times_the_loops_crops_and_checks_the_kernel_against_its_reference(tmp_path, capsys):
    import bench_crop

    assert bench_crop.main(["--repeat", "3", "--out", str(tmp_path)]) == 0
    rec = json.loads((tmp_path / "crop_cpu.json").read_text())
    assert rec["benchmark"] == "crop" and len(rec["cases"]) == len(bench_crop.CASES) == 16
    assert all(c["scale"] >= 0.5 and c["kernel"]["median_ms"] > 0 for c in rec["cases"])
    if rec["opencv"].startswith("5.0."):                      # the release whose arithmetic the kernel fixes
        assert all(c["opencv_equal"] for c in rec["cases"])


def test_engine_rows_take_the_protocol_from_the_run_not_the_folder(tmp_path, capsys):
    """A one-pass run in a *-restart folder had been tabled as "restart" with no word (the folder's
    name decided); the run record's ``restart`` decides now, and the mismatch is named."""
    import engine_baseline

    rep = tmp_path / "engine-tof" / "test-restart-report" / "report.json"
    rep.parent.mkdir(parents=True)
    ov = {"ao_2d": 0.8, "ao_bev": 0.7, "ao_3d": 0.6, "ace_3d": 0.5, "restarts": 0, "frames": 60}
    rep.write_text(json.dumps({"dataset": "data/engine-tof", "trackers": {
        "mosse-op": {"overall": ov, "run": {"restart": False}},
        "kcf": {"overall": ov, "run": {"restart": True}},
        "old": {"overall": ov}}}))
    rows = {r["tracker"]: r["protocol"] for r in engine_baseline.collect(tmp_path)}
    assert rows == {"mosse-op": "onepass", "kcf": "restart", "old": "restart"}
    err = capsys.readouterr().err
    assert "mosse-op" not in err and "named 'restart'" in err and err.count("warning") == 1


def test_a_configuration_without_a_network_names_no_backend():
    """bench_fps printed kcf:baseline as 'onnxruntime fp32': it runs no network at all."""
    import bench_fps

    assert "kcf" not in bench_fps.NETWORK_TRACKERS
    args = bench_fps.build_parser().parse_args(["--data", "unused", "--config", "kcf:baseline",
                                                "--config", "edgetrack:a3boxnet"])
    configs, _ = bench_fps.make_configs(args, None)
    got = {c["label"]: (c["backend"], c["precision"]) for c in configs}
    assert got["kcf:baseline"] == ("none", "-") and got["edgetrack:a3boxnet"] == ("onnxruntime", "fp32")


# --- bench_fps / bench_precision: refusals before any work, honest labels (a user walkthrough) ---

class _WorkStarted(AssertionError):
    """A benchmark started loading frames or timing before its arguments were checked."""


def _no_work(monkeypatch, *modules):
    def stop(*args, **kwargs):
        raise _WorkStarted("work started before the arguments were checked")

    for mod in modules:
        for name in ("load_frames", "time_loop", "bench_networks", "bench_loop", "bench_accuracy"):
            if hasattr(mod, name):
                monkeypatch.setattr(mod, name, stop)


def _up_to_the_timing(monkeypatch, bench_fps):
    """bench_fps up to its first timed configuration (frames "loaded" without a dataset)."""
    def stop(*args, **kwargs):
        raise _WorkStarted("timing started")

    monkeypatch.setattr(bench_fps, "load_frames", lambda *args, **kwargs: (None, []))
    monkeypatch.setattr(bench_fps, "require_trackable", lambda *args, **kwargs: None, raising=False)
    monkeypatch.setattr(bench_fps, "pin_threads", stop)   # the first thing each thread count's timing does


def _run_script(module, argv, capsys):
    """(exit code, stderr lines) of a benchmark's main() run as its __main__ runs it (run_main)."""
    from track3d.argparsing import run_main

    try:
        code = run_main(lambda: module.main(argv), f"{module.__name__}.py")
    except SystemExit as e:
        code = e.code
    return code, capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize("argv", [
    ["--frames", "0"], ["--frames", "-5"], ["--preload", "0"], ["--preload", "-3"],
    ["--config", "foo:bar"], ["--config", "edgetrack:bar"], ["--config", "edgetrack"],
    ["--config", "kcf:a3boxnet@/nonexist.onnx"], ["--config", "kcf:baseline@a3boxnet.onnx"],
    ["--boxnet-model", "/nonexist.onnx"], ["--siamfc-edge-model", "/nonexist/x"], ["--siamfc-model", "/nonexist/x"],
    ["--depth", "stereo", "--int8"], ["--precision", "auto", "--torch"], ["--out-dir", "{file}"],
    ["--depth", "stereo", "--stereo-follow", "-1"], ["--depth", "stereo", "--stereo-follow", "nan"],
])
def test_bench_fps_refuses_a_bad_argument_in_one_line_before_any_work(argv, tmp_path, capsys, monkeypatch):
    """--frames 0 reported FPS over 0 frames (exit 0); --preload 0 and --config foo:bar failed
    after timing everything (exit 1, result files written); --config edgetrack exited 1 without
    "error:"; a wrong ONNX path was only "skipped" (exit 0, empty table); --out-dir naming a file
    ended in FileExistsError after the timing."""
    import bench_fps

    _no_work(monkeypatch, bench_fps)
    (tmp_path / "file").write_text("x")
    out = tmp_path / "out"
    argv = [a.replace("{file}", str(tmp_path / "file")) for a in argv]
    code, err = _run_script(bench_fps, ["--data", str(tmp_path / "d"), "--out-dir", str(out), *argv], capsys)
    assert code == 2 and len(err) == 1 and "error: " in err[0], err
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("argv", [
    ["--sequences", "0"], ["--preload", "0"], ["--net-seconds", "0"], ["--net-seconds", "-5"],
    ["--net-seconds", "nan"], ["--write-verdicts"], ["--data", "{tmp}/no_dataset"], ["--out-dir", "{tmp}/file"],
])
def test_bench_precision_refuses_a_bad_argument_in_one_line_before_any_timing(argv, tmp_path, capsys, monkeypatch):
    """--sequences 0 / --preload 0 marked every loop row skipped (exit 0); --net-seconds 0, -5,
    nan ran; --write-verdicts without --accuracy-data was silently ignored; a bad --data was
    reported only after the per-network timing."""
    import bench_precision

    _no_work(monkeypatch, bench_precision)
    (tmp_path / "file").write_text("x")
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code, err = _run_script(bench_precision, ["--out-dir", str(tmp_path / "out"), *argv], capsys)
    assert code == 2 and len(err) == 1 and "error: " in err[0], err


def test_bench_precision_checks_its_data_before_the_network_timing(tiny_dataset, tmp_path, capsys, monkeypatch):
    import bench_precision

    _no_work(monkeypatch, bench_precision)
    monkeypatch.setattr(bench_precision, "load_frames", __import__("benchlib.loop_timing").loop_timing.load_frames)
    code, err = _run_script(bench_precision, ["--data", str(tiny_dataset), "--split", "nosuch",
                                              "--out-dir", str(tmp_path / "out")], capsys)
    assert code == 2 and len(err) == 1 and "nosuch" in err[0], err


def test_precision_network_rows_name_the_file_timed(monkeypatch):
    """The row "a3boxnet" did not say which file was timed (the views model or the full-width one)."""
    import bench_precision

    monkeypatch.setattr(bench_precision, "NETWORKS_2D", {})
    monkeypatch.setattr(bench_precision, "VARIANTS", (("onnxruntime", "fp32"),))
    monkeypatch.setattr(bench_precision, "measure", lambda models, feeds, seconds: {v: 1.0 for v in models})
    nets = bench_precision.bench_networks(0.01, "a3boxnet_narrow.onnx")
    assert nets["a3boxnet"]["file"] == "a3boxnet_narrow.onnx"
    res = {"cpu": "c", "machine": {"isa": [], "versions": {"onnxruntime": "1"}}, "openvino": None, "networks": nets}
    assert "| a3boxnet (a3boxnet_narrow.onnx) |" in bench_precision.markdown(res)


def test_bench_fps_labels_each_row_by_what_ran(tiny_dataset, tmp_path, monkeypatch):
    """--precision auto rows said backend "onnxruntime" while OpenVINO bf16 ran some networks:
    a row's backend / precision are those its networks ran in (per network when they differ),
    and the record names OpenVINO's version when it ran."""
    import bench_fps

    from track3d.onnxmodel import openvino_version

    assert bench_fps.ran_as([]) == ("none", "-")
    ort = {"engine": "onnxruntime", "precision": "fp32"}
    assert bench_fps.ran_as([{"file": "a.onnx", **ort}, {"file": "b.onnx", **ort}]) == ("onnxruntime", "fp32")
    backend, precision = bench_fps.ran_as([{"file": "siamfc_edge_exemplar.onnx", "engine": "openvino",
                                            "precision": "bf16"}, {"file": "a3boxnet_views.onnx", **ort}])
    assert backend.startswith("mixed") and "openvino (siamfc_edge_exemplar.onnx)" in backend
    assert "onnxruntime (a3boxnet_views.onnx)" in backend
    assert precision.startswith("mixed") and "bf16 (siamfc_edge_exemplar.onnx)" in precision

    monkeypatch.setenv("TRACK3D_CACHE_DIR", str(tmp_path / "cache"))
    out = tmp_path / "fps"
    assert bench_fps.main(["--data", str(tiny_dataset), "--frames", "3", "--preload", "20", "--threads", "1",
                           "--config", "siamfc-edge:a3boxnet", "--precision", "fp32", "auto", "--tag", "l",
                           "--out-dir", str(out)]) == 0
    rec = json.loads((out / "fps_l.json").read_text())
    md = (out / "fps_l.md").read_text()
    for r in rec["results"]:
        assert (r["backend"], r["precision"]) == bench_fps.ran_as(r["networks"])
        assert f"| {r['config']} | {r['backend']} | {r['precision']} |" in md
    rows = {r["config"]: r for r in rec["results"]}
    assert rows["siamfc-edge:a3boxnet auto"]["asked"] == {"engine": "auto", "precision": "auto"}
    assert rows["siamfc-edge:a3boxnet"]["asked"] == {"engine": "onnxruntime", "precision": "fp32"}
    ran_openvino = any(n["engine"] == "openvino" for r in rec["results"] for n in r["networks"])
    assert rec["openvino"] == (openvino_version() if ran_openvino else None)
    assert (f"OpenVINO {openvino_version()}" in md) == ran_openvino


def test_bench_fps_int8_files_are_found_by_the_runtimes_naming_rule(tmp_path, capsys, monkeypatch):
    """bench_fps looked for <prefix>_int8_exemplar.onnx while track3d-train quantize and the
    runtime (track3d.onnxmodel.variant_path) name them <file>_int8.onnx: an int8 pair a user
    made was never found; configurations without one are named in one line."""
    import shutil

    import bench_fps

    from track3d.onnxmodel import MODELS_DIR, variant_path

    d = tmp_path / "m"
    d.mkdir()
    for part in ("exemplar", "search"):
        fp32 = d / f"x_{part}.onnx"
        shutil.copy(MODELS_DIR / f"siamfc_edge_{part}.onnx", fp32)
        shutil.copy(fp32, variant_path(fp32, "int8"))
    args = bench_fps.build_parser().parse_args(["--data", "unused", "--config", "siamfc-edge:a3boxnet",
                                                "--siamfc-edge-model", str(d / "x"), "--int8"])
    configs, skipped = bench_fps.make_configs(args, None)
    int8 = [c for c in configs if c["precision"] == "int8"]
    assert [c["label"] for c in int8] == ["siamfc-edge-int8:a3boxnet"] and not skipped
    assert int8[0]["tracker_options"] == {"model": str(d / "x"), "precision": "int8"}

    if variant_path(MODELS_DIR / "siamfc_faithful_search.onnx", "int8").is_file():
        pytest.skip("an int8 SiamFC (faithful) ships now")
    _up_to_the_timing(monkeypatch, bench_fps)
    with pytest.raises(_WorkStarted):
        bench_fps.main(["--data", "unused", "--config", "siamfc:a3boxnet", "--config", "kcf:baseline",
                        "--int8", "--out-dir", str(tmp_path / "o")])
    said = [line for line in capsys.readouterr().err.splitlines() if "int8" in line]
    assert len(said) == 1 and "siamfc:a3boxnet" in said[0] and "_int8.onnx" in said[0], said
    text = bench_fps.build_parser().format_help() + (Path(bench_fps.__file__).parent / "README.md").read_text()
    assert "siamfc_edge_int8_" not in text and "_int8_exemplar" not in text


def test_bench_fps_warns_when_fewer_cpus_are_allowed_than_threads(tmp_path, capsys, monkeypatch):
    """--threads 2 under `taskset -c 0` gave no warning (track3d bench warns); the help showed
    "(default: [1, 2])"."""
    import bench_fps

    from track3d import machine

    monkeypatch.setattr(machine, "START_CPUS", [0])
    _up_to_the_timing(monkeypatch, bench_fps)
    with pytest.raises(_WorkStarted):
        bench_fps.main(["--data", "unused", "--config", "kcf:baseline", "--threads", "1", "2",
                        "--out-dir", str(tmp_path / "o")])
    said = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert len(said) == 1 and "--threads 2" in said[0] and "1 CPU" in said[0], said
    assert "[1, 2]" not in bench_fps.build_parser().format_help()


def test_bench_fps_auto_row_only_for_configurations_with_networks():
    """--precision fp32 auto gave kcf:baseline (no network) an auto twin whose tracker got
    precision= and failed (ValueError: kcf takes no 'precision'), exit 1."""
    import bench_fps

    args = bench_fps.build_parser().parse_args(["--data", "unused", "--config", "kcf:baseline", "--config",
                                                "kcf:a3boxnet", "--precision", "fp32", "auto"])
    configs, _ = bench_fps.make_configs(args, None)
    got = {c["label"]: (c["tracker_options"], c["estimator_options"]) for c in configs}
    assert list(got) == ["kcf:baseline", "kcf:a3boxnet", "kcf:a3boxnet auto"]
    assert got["kcf:baseline"] == ({}, {}) and got["kcf:a3boxnet auto"] == ({}, {"precision": "auto", "engine": "auto"})
