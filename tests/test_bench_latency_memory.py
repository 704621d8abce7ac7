"""bench_latency.py and bench_memory.py: pinning refused outside the allowed CPUs and recorded as
read back, --out a folder refused before the run, the shared run record (benchlib/record.py)
with a forced ISA noted, and bench_memory's polish (plain progress lines when piped, a growth
needs readings, standard one-line errors). Tiny runs only."""
from __future__ import annotations

import itertools
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from track3d import machine
from track3d.argparsing import run_main


def _outside_cpu() -> int:
    """The lowest CPU this process was not started on: under `taskset -c 0` a real CPU (1),
    otherwise one past the last (no such CPU)."""
    return next(c for c in itertools.count() if c not in machine.START_CPUS)


def _err_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@pytest.fixture
def restore_affinity():
    """The scripts pin the process to one CPU: give the test process its CPUs back."""
    yield
    machine.pin(machine.START_CPUS)


# --- machine.pin -----------------------------------------------------------------------------------

def test_pin_refuses_a_cpu_that_does_not_exist_instead_of_swallowing_the_error():
    before = machine.affinity_of_all_threads()
    bad = max(os.cpu_count() or 1, *machine.START_CPUS) + 1
    with pytest.raises(ValueError, match=rf"CPU\(s\) {bad} .*may run on: {', '.join(map(str, machine.START_CPUS))}"):
        machine.pin([bad])
    with pytest.raises(ValueError, match="no CPU"):
        machine.pin([])
    assert machine.affinity_of_all_threads() == before


@pytest.mark.skipif((os.cpu_count() or 1) < 2 or not hasattr(os, "sched_setaffinity"), reason="needs 2 CPUs")
def test_pin_does_not_move_a_process_out_of_its_taskset():
    """sched_setaffinity lets a process leave the CPUs `taskset` gave it: pin must not."""
    code = ("import os, sys; os.sched_setaffinity(0, {%d}); from track3d import machine\n"
            "try:\n    machine.pin([%d])\nexcept ValueError as e:\n    print('refused', e); sys.exit(0)\n"
            "print('moved to', sorted(os.sched_getaffinity(0)))" % (machine.START_CPUS[0], 1 - min(1, machine.START_CPUS[0])))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.startswith("refused"), r.stdout + r.stderr


def test_pin_threads_still_pins_and_widens(restore_affinity):
    assert machine.pin_threads(1, [machine.START_CPUS[-1]]) == [machine.START_CPUS[-1]]
    assert machine.affinity_of_all_threads() == [machine.START_CPUS[-1]]
    assert machine.pin_threads(len(machine.START_CPUS)) == machine.START_CPUS   # widening back is allowed
    assert machine.affinity_of_all_threads() == machine.START_CPUS


# --- the command lines -----------------------------------------------------------------------------

@pytest.mark.parametrize("script", ["bench_latency", "bench_memory"])
def test_a_cpu_outside_the_allowed_set_is_refused_before_any_work(script, capsys):
    mod = __import__(script)
    with pytest.raises(SystemExit) as e:
        mod.build_parser().parse_args(["--data", "no/such/dataset", "--cpu", str(_outside_cpu())])
    line = _err_line(capsys)
    assert e.value.code == 2 and "--cpu" in line and str(_outside_cpu()) in line
    assert ", ".join(map(str, machine.START_CPUS)) in line   # which CPUs are allowed


@pytest.mark.parametrize("script", ["bench_latency", "bench_memory"])
def test_out_an_existing_folder_is_refused_before_the_run(script, tmp_path, capsys):
    mod = __import__(script)
    assert run_main(lambda: mod.main(["--data", "no/such/dataset", "--out", str(tmp_path)]), f"{script}.py") == 2
    line = _err_line(capsys)
    assert line.startswith(f"{script}.py: error: --out {tmp_path} is a folder"), line


def test_bench_memory_mistakes_are_standard_one_line_errors(tmp_path, capsys):
    import bench_memory

    from track3d.synthetic import make_synthetic_dataset

    data = make_synthetic_dataset(tmp_path / "d", {"a": 8})
    assert run_main(lambda: bench_memory.main(["--data", str(data), "--sequence", "9999"]), "bench_memory.py") == 2
    assert _err_line(capsys).startswith("bench_memory.py: error: no sequence '9999'")
    # one reading: no growth to speak of (it used to report "slope +0.00 MB / 10k")
    assert run_main(lambda: bench_memory.main(["--data", "no/such/dataset", "--every", "1000", "--updates", "100"]),
                    "bench_memory.py") == 2
    line = _err_line(capsys)
    assert line.startswith("bench_memory.py: error: --updates 100 with --every 1000") and "readings" in line
    assert run_main(lambda: bench_memory.main(["--data", str(data), "--stereo-max-cost", "5"]), "bench_memory.py") == 2
    assert _err_line(capsys).startswith("bench_memory.py: error: ")


def test_bench_latency_mistakes_are_standard_one_line_errors(tmp_path, capsys):
    import bench_latency

    from track3d.synthetic import make_synthetic_dataset

    assert run_main(lambda: bench_latency.main(["--data", "d", "--stereo-max-cost", "5"]), "bench_latency.py") == 2
    assert _err_line(capsys).startswith("bench_latency.py: error: --stereo-max-cost")
    data = make_synthetic_dataset(tmp_path / "d", {"a": 1})   # one frame: nothing to track
    assert run_main(lambda: bench_latency.main(["--data", str(data)]), "bench_latency.py") == 2
    assert _err_line(capsys).startswith("bench_latency.py: error: no trackable sequence")


def test_growth_of_one_reading_has_no_slope():
    import bench_memory

    g = bench_memory.growth(np.array([0.0]), np.array([5.0]))
    assert g["slope_per_10k_updates"] is None and g["first"] == g["last"] == 5.0


def test_docstring_examples_are_one_command_each():
    import bench_latency
    import bench_memory

    for doc in (bench_memory.__doc__, bench_latency.__doc__):
        assert not re.search(r"\S {3,}\S", doc), re.search(r".*\S {3,}\S.*", doc).group(0)


# --- the run record --------------------------------------------------------------------------------

def test_the_record_notes_a_forced_isa(monkeypatch):
    from benchlib.record import start_record

    monkeypatch.delenv("TRACK3D_ISA_FLAGS", raising=False)
    assert "isa_forced" not in start_record("x")
    monkeypatch.setenv("TRACK3D_ISA_FLAGS", "avx2")
    rec = start_record("x")
    assert rec["isa_forced"] == ["avx2"] and rec["machine"]["isa"] == machine.isa_flags()   # the CPU's own
    monkeypatch.setenv("TRACK3D_ISA_FLAGS", "avx2, vnni")
    assert start_record("x")["isa_forced"] == ["avx2", "int8_dot", "vnni"]   # as the variant choice reads it


def _check_shared_record(rec: dict, name: str):
    for k in ("benchmark", "cpu", "machine", "date", "loadavg_before", "loadavg_after", "wall_s"):
        assert k in rec, k
    assert rec["benchmark"] == name and "isa" in rec["machine"] and "isa_flags" not in rec["machine"]
    assert set(rec["machine"]["versions"]) >= {"python", "numpy", "onnxruntime", "track3d"}
    assert rec["machine"]["versions"]["onnxruntime"]
    models = rec["config"]["models"]
    assert models and all(re.fullmatch(r"[0-9a-f]{64}", m["sha256"]) and m["file"].endswith(".onnx")
                          for m in models)


def test_latency_record_is_the_shared_one_and_says_the_affinity_in_force(tmp_path, monkeypatch, capsys,
                                                                         restore_affinity):
    import bench_latency

    from track3d.synthetic import make_synthetic_dataset

    data = make_synthetic_dataset(tmp_path / "d", {"a": 12})
    out = tmp_path / "lat.json"
    cpu = machine.START_CPUS[-1]
    assert bench_latency.main(["--data", str(data), "--frames", "20", "--warmup", "2", "--cpu", str(cpu),
                               "--out", str(out)]) == 0
    rec = json.loads(out.read_text())
    _check_shared_record(rec, "latency")
    assert rec["pinned_cpus"] == [cpu] and rec["config"]["cpu_requested"] == cpu
    # a pin that did nothing: the record says so (the affinity read back), not the flag
    machine.pin(machine.START_CPUS)
    monkeypatch.setattr(machine, "pin", lambda cpus: True)
    assert bench_latency.main(["--data", str(data), "--frames", "20", "--warmup", "2", "--cpu", str(cpu),
                               "--out", str(out)]) == 0
    assert json.loads(out.read_text())["pinned_cpus"] == machine.START_CPUS


def test_memory_record_is_the_shared_one_and_progress_is_plain_lines_when_piped(tmp_path, capsys, restore_affinity):
    import bench_memory

    from track3d.synthetic import make_synthetic_dataset

    data = make_synthetic_dataset(tmp_path / "d", {"a": 8})
    out = tmp_path / "mem.json"
    assert bench_memory.main(["--data", str(data), "--updates", "30", "--warmup", "2", "--every", "10",
                              "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "\r" not in err and len([x for x in err.splitlines() if "updates: RSS" in x]) == 4
    rec = json.loads(out.read_text())
    _check_shared_record(rec, "memory")
    assert rec["pinned_cpus"] == [machine.START_CPUS[0]] and rec["config"]["cpu_requested"] is None
    assert rec["rss_mb"]["slope_per_10k_updates"] is not None


def test_memory_without_warmup_reads_at_zero_too(tmp_path, capsys, restore_affinity):
    """--warmup 0 took no reading at 0 updates: one reading fewer than said, and the windows'
    growth paired their values with one update count too few (a silent wrong result)."""
    import bench_memory

    from track3d.synthetic import make_synthetic_dataset

    data = make_synthetic_dataset(tmp_path / "d", {"a": 8})
    out = tmp_path / "mem.json"
    assert bench_memory.main(["--data", str(data), "--updates", "20", "--warmup", "0", "--every", "10",
                              "--out", str(out)]) == 0
    rec = json.loads(out.read_text())
    assert rec["readings"]["updates"] == [0, 10, 20] and len(rec["readings"]["window_median_ms"]) == 2
    assert sum(rec["statuses"].values()) == 20
