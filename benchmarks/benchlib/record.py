"""The record every benchmark JSON starts with: what ran, on which machine, under what load."""
from __future__ import annotations

import time

from track3d.cpu_features import forced_isa_flags
from track3d.machine import cpu_name, load_average, machine_info

__all__ = ["start_record", "finish_record", "model_files"]


def start_record(benchmark: str, **fields) -> dict:
    """{"benchmark", "cpu", "machine" (track3d.machine.machine_info: CPU, ISA flags, versions),
    ["isa_forced"], "date", "loadavg_before", **fields}; the other processes' load makes timings
    noisy. "isa_forced" (only when TRACK3D_ISA_FLAGS is set): the instruction sets the runtime was
    told to assume instead of the CPU's own (machine.isa stays what the CPU has)."""
    return {"benchmark": benchmark, "cpu": cpu_name(), "machine": machine_info(), **_isa_forced(),
            "date": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()), "loadavg_before": load_average(),
            "_t0": time.perf_counter(), **fields}


def finish_record(record: dict) -> dict:
    """Add "loadavg_after" and "wall_s" (seconds since start_record); returns the record."""
    record["wall_s"] = time.perf_counter() - record.pop("_t0")
    record["loadavg_after"] = load_average()
    return record


def _isa_forced() -> dict:
    """{"isa_forced": [names]} when TRACK3D_ISA_FLAGS tells the runtime's variant choice to
    pretend other instruction sets (track3d.cpu_features.forced_isa_flags: the portable names
    with the derived int8_dot / bf16_dot, what precision="auto" then believes), else {}."""
    forced = forced_isa_flags()
    return {} if forced is None else {"isa_forced": sorted(forced)}


def model_files(described: dict) -> list[dict]:
    """[{"file", "sha256", "engine", "precision"}] of the networks a Track3D.describe() names:
    which model files a measurement ran."""
    return [{k: m.get(k) for k in ("file", "sha256", "engine", "precision")} for m in described.get("models", [])]
