"""The record every benchmark JSON starts with: what ran, on which machine, under what load."""
from __future__ import annotations

import time

from track3d.machine import cpu_name, load_average, machine_info

__all__ = ["start_record", "finish_record"]


def start_record(benchmark: str, **fields) -> dict:
    """{"benchmark", "cpu", "machine" (track3d.machine.machine_info: CPU, ISA flags, versions),
    "date", "loadavg_before", **fields}; the other processes' load makes timings noisy."""
    return {"benchmark": benchmark, "cpu": cpu_name(), "machine": machine_info(),
            "date": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()), "loadavg_before": load_average(),
            "_t0": time.perf_counter(), **fields}


def finish_record(record: dict) -> dict:
    """Add "loadavg_after" and "wall_s" (seconds since start_record); returns the record."""
    record["wall_s"] = time.perf_counter() - record.pop("_t0")
    record["loadavg_after"] = load_average()
    return record
