"""The CPU's arithmetic instructions, as one set of portable names (for picking a model variant).

x86-64 (Linux ``/proc/cpuinfo`` "flags") and aarch64 ("Features") are mapped to the names the
runtime reasons with:

    avx2, avx512, vnni (AVX-512 VNNI or AVX-VNNI), avx512_bf16, amx_int8, amx_bf16   (x86-64)
    neon, dotprod (asimddp), i8mm, bf16                                               (aarch64)

plus ``int8_dot`` (any int8 dot-product instruction: vnni, amx_int8, dotprod, i8mm) and
``bf16_dot`` (any bf16 arithmetic: avx512_bf16, amx_bf16, bf16), the two facts the variant
choice in ``track3d.onnxmodel`` uses. Without /proc/cpuinfo (not Linux) the set is empty:
the runtime then stays at fp32 unless told otherwise.
"""
from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

__all__ = ["isa_flags", "forced_isa_flags", "parse_cpuinfo", "cpu_model", "with_derived", "INT8_DOT", "BF16_DOT"]

_X86 = {"avx2": "avx2", "avx512f": "avx512", "avx512_vnni": "vnni", "avx512vnni": "vnni", "avx_vnni": "vnni",
        "avx512_bf16": "avx512_bf16", "amx_int8": "amx_int8", "amx_bf16": "amx_bf16"}
_ARM = {"asimd": "neon", "asimddp": "dotprod", "i8mm": "i8mm", "bf16": "bf16"}
INT8_DOT = frozenset({"vnni", "amx_int8", "dotprod", "i8mm"})
BF16_DOT = frozenset({"avx512_bf16", "amx_bf16", "bf16"})


def parse_cpuinfo(text: str) -> frozenset[str]:
    """The portable ISA names of a /proc/cpuinfo text (first processor's flags / Features)."""
    raw: set[str] = set()
    for line in text.splitlines():
        key, _, value = line.partition(":")
        if key.strip().lower() in ("flags", "features"):
            raw.update(value.split())
            break
    return with_derived({_X86[f] for f in raw if f in _X86} | {_ARM[f] for f in raw if f in _ARM})


@lru_cache(maxsize=1)
def _cpuinfo() -> str:
    try:
        return Path("/proc/cpuinfo").read_text(errors="replace")
    except OSError:
        return ""


def isa_flags() -> frozenset[str]:
    """This CPU's arithmetic instruction sets (see the module doc for the names).

    ``TRACK3D_ISA_FLAGS`` (comma-separated portable names, e.g. ``avx2``) replaces them: to see
    what precision="auto" does on a CPU that lacks this one's instructions (``forced_isa_flags``)."""
    forced = forced_isa_flags()
    return parse_cpuinfo(_cpuinfo()) if forced is None else forced


def forced_isa_flags() -> frozenset[str] | None:
    """The flags ``TRACK3D_ISA_FLAGS`` forces (what ``isa_flags`` then returns), or None when it is
    unset. A record of the machine lists the CPU's real flags; this says what auto believed."""
    forced = os.environ.get("TRACK3D_ISA_FLAGS")
    if forced is None:
        return None
    return with_derived(f.strip() for f in forced.split(",") if f.strip())


def with_derived(names) -> frozenset[str]:
    """Portable names plus the derived int8_dot / bf16_dot."""
    out = set(names)
    if out & INT8_DOT:
        out.add("int8_dot")
    if out & BF16_DOT:
        out.add("bf16_dot")
    return frozenset(out)


def cpu_model() -> str:
    """The CPU's name: the one implementation is track3d.machine.cpu_name."""
    from .machine import cpu_name

    return cpu_name()
