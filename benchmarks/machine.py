"""One line naming the machine a benchmark ran on (its figures depend on the CPU's vector
units: the same code measured 0.41 and 0.65 of the GEMM roofline on two 2-core machines)."""

from __future__ import annotations

import os
from pathlib import Path


def describe() -> str:
    """CPU model, cores, widest x86 vector extension and the 1-minute load average."""
    model, flags = "unknown CPU", set()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        for line in cpuinfo.read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and model == "unknown CPU":
                model = value.strip()
            elif key.strip() == "flags" and not flags:
                flags = set(value.split())
    vector = next((f for f in ("avx512f", "avx2", "avx", "sse4_2") if f in flags), "-")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{model}, {os.cpu_count()} cores, vector {vector}, load average {load:.2f}"
