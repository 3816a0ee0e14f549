"""Pins the CPU math kernels that torch and MKL would otherwise pick by CPU (x86-64 with AVX2).

torch's CPU wheels pick their kernels at run time by what the CPU offers: MKL (matrix products,
linear algebra) takes another code path on an AVX-512 Intel CPU than on an AVX2 AMD one, and
torch's own vectorized kernels (reductions, elementwise math) do too. The paths round
differently: the golden seed-task run (``tests/test_golden.py``) ended 1 ulp apart in its best
parameters on an AVX-512 Xeon against the fixture recorded on an AVX2 EPYC. ``pin_cpu_math``
sets ``MKL_CBWR=AVX2`` and ``ATEN_CPU_CAPABILITY=avx2`` when the CPU has AVX2, so every such
machine takes the same torch and MKL paths (the golden runs then match across those two CPUs;
full seed-paper runs still differ a little between them, see docs/architecture.md ("Layout"); both
libraries read them once, at their first call, so this runs
when ``realize`` is imported (before any torch op of the run, and inherited by worker
processes). A value already set in the environment is kept (``ATEN_CPU_CAPABILITY=default``, say).

What it doesn't do: make GPU runs reproducible, or pin anything on a CPU without AVX2 (not
x86-64, or older): those keep their libraries' own choice.
"""

from __future__ import annotations

import os
import platform
from pathlib import Path

PINNED = {"MKL_CBWR": "AVX2", "ATEN_CPU_CAPABILITY": "avx2"}


def cpu_has_avx2(cpuinfo: Path = Path("/proc/cpuinfo")) -> bool:
    """True on an x86-64 CPU whose flags list AVX2 (Linux's /proc/cpuinfo; False where unreadable)."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    try:
        text = cpuinfo.read_text()
    except OSError:
        return False
    return any(line.startswith("flags") and " avx2" in line for line in text.splitlines())


def pin_cpu_math() -> dict[str, str]:
    """Set the pinned variables not already set (only on a CPU with AVX2); the values now in force."""
    if cpu_has_avx2():
        for key, value in PINNED.items():
            os.environ.setdefault(key, value)
    return {k: os.environ[k] for k in PINNED if k in os.environ}
