"""The machine a measurement ran on: CPU name, cores, ISA flags, load, thread pinning.

The one place for these (benchmarks and `track3d bench` import it). Linux reads /proc; other
systems fall back to `platform` and skip what they cannot know (pinning, /proc/stat load):
nothing here is x86-only (aarch64 reports its `Features` line as ISA flags).
"""
from __future__ import annotations

import os
import platform
import time
from pathlib import Path

__all__ = ["cpu_name", "isa_flags", "core_count", "allowed_cpus", "pin", "pin_threads", "START_CPUS",
           "affinity_of_all_threads",
           "cpu_busy", "load_average", "versions", "machine_info", "INTERESTING_FLAGS"]

# ISA extensions that matter to onnxruntime / OpenCV kernels (x86 and Arm spellings).
INTERESTING_FLAGS = ("sse4_1", "sse4_2", "avx", "avx2", "fma", "f16c", "avx512f", "avx512bw", "avx512vl",
                     "avx512_vnni", "avx_vnni", "amx_tile", "amx_int8", "amx_bf16", "avx512_bf16",
                     "neon", "asimd", "asimdhp", "asimddp", "sve", "sve2", "i8mm", "bf16", "fphp")


def _cpuinfo() -> list[str]:
    try:
        return Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return []


def cpu_name() -> str:
    """The CPU model name ('model name' on x86, 'Hardware'/'CPU part' style lines on Arm)."""
    lines = _cpuinfo()
    for key in ("model name", "Model", "Hardware", "cpu model", "Processor"):
        for line in lines:
            if line.split(":", 1)[0].strip() == key and ":" in line:
                v = line.split(":", 1)[1].strip()
                if v:
                    return v
    for line in lines:  # Arm without a name: implementer/part codes are still something
        if line.startswith("CPU part"):
            return f"{platform.machine()} (CPU part {line.split(':', 1)[1].strip()})"
    return platform.processor() or platform.machine() or "unknown"


def isa_flags(all_flags: bool = False) -> list[str]:
    """ISA flags of the first CPU (x86 'flags', Arm 'Features'), by default only INTERESTING_FLAGS."""
    for line in _cpuinfo():
        key = line.split(":", 1)[0].strip()
        if key in ("flags", "Features") and ":" in line:
            flags = line.split(":", 1)[1].split()
            return sorted(flags) if all_flags else [f for f in INTERESTING_FLAGS if f in flags]
    return []


def core_count() -> int:
    """Logical CPUs of the machine."""
    return os.cpu_count() or 1


def allowed_cpus() -> list[int]:
    """CPUs this process may run on (all of them where affinity is not supported)."""
    if hasattr(os, "sched_getaffinity"):
        return sorted(os.sched_getaffinity(0))
    return list(range(core_count()))


def _thread_ids() -> list[int]:
    """The process's thread ids (Linux: /proc/self/task); [0], the calling thread, elsewhere."""
    try:
        return [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        return [0]


def pin(cpus) -> bool:
    """Set the affinity of EVERY thread of the process (os.sched_setaffinity(0) sets only the
    calling thread's; pools started earlier would keep the old set). False where unsupported.

    A CPU the process may not run on is a ValueError naming those it may (START_CPUS, the set it
    was started on, or any its threads run on now), raised before any thread is touched: the
    kernel would move the process out of its `taskset` onto any online CPU, and refuses a CPU
    that does not exist (that refusal used to be swallowed, the process left unpinned)."""
    cpus = set(int(c) for c in cpus)
    if not cpus:
        raise ValueError("no CPU to pin to")
    if not hasattr(os, "sched_setaffinity"):
        return False
    allowed = set(START_CPUS) | set(affinity_of_all_threads())
    if not cpus <= allowed:
        raise ValueError(f"CPU(s) {', '.join(map(str, sorted(cpus - allowed)))} not allowed: this process may run on: "
                         f"{', '.join(map(str, sorted(allowed)))}")
    for tid in _thread_ids():
        try:
            os.sched_setaffinity(tid, cpus)
        except ProcessLookupError:  # a thread that just exited
            pass
    return True


START_CPUS = allowed_cpus()   # the CPUs this process was started on (`taskset` chooses them)


def pin_threads(threads: int, cpus: list[int] | None = None) -> list[int]:
    """Run on `threads` CPUs: every thread of the process pinned to the first `threads` of
    `cpus` (default START_CPUS, so that a later call can widen again), OpenCV's pool set to
    `threads` (so that 1 thread means one thread). Returns the CPUs pinned to ([] where
    affinity is unsupported). The one pinning of benchmarks and `track3d bench`."""
    from .threads import set_threads

    chosen = list(START_CPUS if cpus is None else cpus)[: max(int(threads), 1)]
    set_threads(threads)
    return chosen if pin(chosen) else []


def affinity_of_all_threads() -> list[int]:
    """Union of the CPUs any thread of the process may run on."""
    if not hasattr(os, "sched_getaffinity"):
        return allowed_cpus()
    cpus: set[int] = set()
    for tid in _thread_ids():
        try:
            cpus |= os.sched_getaffinity(tid)
        except OSError:
            pass
    return sorted(cpus)


def _stat() -> tuple[int, int] | None:
    try:
        f = [int(x) for x in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]
    except (OSError, ValueError, IndexError):
        return None
    idle = f[3] + (f[4] if len(f) > 4 else 0)
    return sum(f[:8]), idle


def cpu_busy(seconds: float = 0.5) -> float | None:
    """Fraction (0..1) of all CPUs' time spent busy over the next `seconds` (/proc/stat);
    measured while this process sleeps, so it is the other processes' load. None off Linux."""
    a = _stat()
    if a is None:
        return None
    time.sleep(seconds)
    b = _stat()
    total = b[0] - a[0]
    return None if total <= 0 else max(0.0, min(1.0, 1.0 - (b[1] - a[1]) / total))


def load_average() -> list[float] | None:
    """1, 5, 15 minute load averages (None where the OS has none)."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (OSError, AttributeError):
        return None


def versions() -> dict:
    """Versions of what a measurement depends on."""
    import numpy

    out = {"python": platform.python_version(), "numpy": numpy.__version__}
    try:
        import onnxruntime
        out["onnxruntime"] = onnxruntime.__version__
    except ImportError:
        out["onnxruntime"] = None
    try:
        import cv2
        out["opencv"] = cv2.__version__
    except ImportError:
        out["opencv"] = None
    # a missing or stale C++ extension gives the same results more slowly: a timing says which ran
    from . import frustum, resample
    out["extension"] = ("compiled" if frustum.EXTENSION_COMPLETE and resample.HAVE_EXTENSION
                        else "missing: the numpy reference ran (slower)" if not frustum.HAVE_EXTENSION
                        else "partly: an older build, some functions ran in numpy (slower)")
    try:
        from importlib.metadata import version
        out["track3d"] = version("track3d")
    except Exception:  # not installed as a distribution (a bare checkout)
        out["track3d"] = None
    return out


def machine_info() -> dict:
    """CPU name, architecture, cores, allowed CPUs, ISA flags, OS and versions."""
    return {"cpu": cpu_name(), "arch": platform.machine(), "logical_cpus": core_count(),
            "allowed_cpus": allowed_cpus(), "isa": isa_flags(), "os": platform.platform(),
            "versions": versions()}
