"""realize.reproducible: every library that picks its kernels by CPU runs its pinned kernels once
``realize`` is imported, and a library loaded before the pin is named.

The oracle is each library's own read-back (torch's capability, MKL's ``mkl_serv_cbwr_get``,
OpenBLAS's core name, numpy's CPU feature table), not the environment variables the pin sets."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from realize import reproducible
from realize.reproducible import PINNED, cpu_flags, pin_cpu_math, pins_for, unpinned

REPO = Path(__file__).resolve().parent.parent
X86 = bool(cpu_flags())
# loaded libraries that choose kernels by CPU, and the key of in_force() that reads each back
DISPATCHERS = {r"libtorch_cpu\.so": "torch", r"openblas": "openblas", r"_multiarray_umath": "numpy"}
# library families known to dispatch by CPU: one loaded without an entry above fails the test
DISPATCHING = re.compile(r"mkl|openblas|blis|flexiblas|dnnl|sleef|_multiarray_umath|libtorch_cpu", re.I)


def _cpuinfo(tmp_path: Path, flags: str) -> Path:
    p = tmp_path / "cpuinfo"
    p.write_text(f"processor\t: 0\nmodel name\t: some cpu\nflags\t\t: fpu sse2 {flags}\n\n")
    return p


def test_flags_are_read_from_the_flags_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(reproducible.platform, "machine", lambda: "x86_64")
    assert {"avx2", "fma"} <= cpu_flags(_cpuinfo(tmp_path, "avx avx2 fma"))
    assert cpu_flags(tmp_path / "missing") == frozenset()
    monkeypatch.setattr(reproducible.platform, "machine", lambda: "aarch64")
    assert cpu_flags(_cpuinfo(tmp_path, "avx avx2 fma")) == frozenset()


def test_the_pins_follow_the_cpu() -> None:
    assert pins_for(frozenset({"sse2", "avx", "avx2", "fma", "avx512f"})) == PINNED
    assert pins_for(frozenset({"sse2", "avx", "avx2", "fma"})) == {
        "MKL_CBWR": "COMPATIBLE", "ATEN_CPU_CAPABILITY": "avx2", "OPENBLAS_CORETYPE": "Haswell"}
    assert pins_for(frozenset({"sse2", "avx"})) == {"MKL_CBWR": "COMPATIBLE"}  # the one branch any x86-64 runs
    assert pins_for(frozenset()) == {}  # not x86-64: every library keeps its own choice


def test_pins_unset_variables_and_keeps_the_users(monkeypatch: pytest.MonkeyPatch) -> None:
    for key in PINNED:
        monkeypatch.delenv(key, raising=False)
    monkeypatch.setenv("ATEN_CPU_CAPABILITY", "default")
    monkeypatch.setattr(reproducible, "cpu_flags", lambda: frozenset({"avx2"}))
    assert pin_cpu_math() == {"MKL_CBWR": "COMPATIBLE", "ATEN_CPU_CAPABILITY": "default", "OPENBLAS_CORETYPE": "Haswell"}


def test_a_library_off_its_pin_is_named() -> None:
    flags = frozenset({"avx2", "avx512f"})
    now = {"torch": "avx2", "mkl": "COMPATIBLE", "openblas": "Haswell", "numpy": "AVX-512 off"}
    assert unpinned(now, flags) == []
    assert unpinned({**now, "mkl": "AUTO", "openblas": "SkylakeX"}, flags) == [
        "mkl runs AUTO, pinned COMPATIBLE", "openblas runs SkylakeX, pinned Haswell"]
    assert unpinned({**now, "numpy": None}, flags) == []  # not loaded: nothing to say
    assert unpinned({**now, "numpy": "AVX-512 on"}, frozenset({"avx2"})) == []  # no AVX-512 here: not pinned


def _fresh(code: str) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter with none of the pinned variables set."""
    env = {k: v for k, v in os.environ.items() if k not in PINNED}
    return subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True,
                          check=True, timeout=120)


_USE_ALL = ("import numpy as np, scipy.linalg, torch; a = torch.randn(24, 24); (a @ a).sum(); "
            "torch.linalg.solve(a + 24 * torch.eye(24), a); np.linalg.inv(np.eye(4) * 2); "
            "scipy.linalg.lu_factor(np.eye(30) * 3); ")


@pytest.mark.skipif(not X86, reason="pins apply on x86-64 only")
def test_every_library_that_dispatches_by_cpu_runs_its_pin_after_import_realize() -> None:
    # realize first, as `python -m realize` and its worker processes do; then every library used
    code = ("import realize, json; " + _USE_ALL + "from realize.reproducible import in_force, unpinned; "
            "print(json.dumps({'now': in_force(), 'bad': unpinned(), "
            "'libs': sorted({l.split()[-1] for l in open('/proc/self/maps') if '/' in l})}))")
    doc = json.loads(_fresh(code).stdout.splitlines()[-1])
    assert doc["bad"] == [], doc["now"]
    pins = pins_for(cpu_flags())
    assert doc["now"]["mkl"] == pins["MKL_CBWR"]
    if "ATEN_CPU_CAPABILITY" in pins:
        assert doc["now"]["torch"] == pins["ATEN_CPU_CAPABILITY"] and doc["now"]["openblas"] == pins["OPENBLAS_CORETYPE"]
    # a library that picks kernels by CPU and that in_force() does not read back has no pin: fail
    loaded = [Path(p).name for p in doc["libs"] if DISPATCHING.search(Path(p).name)]
    assert loaded, "no CPU-dispatching library found loaded: the scan is broken"
    unread = [n for n in loaded if not any(re.search(p, n) for p in DISPATCHERS)]
    assert unread == [], f"loaded without a pin in realize.reproducible: {unread}"
    assert {DISPATCHERS[p] for p in DISPATCHERS for n in loaded if re.search(p, n)} <= set(doc["now"])


@pytest.mark.skipif(not X86, reason="pins apply on x86-64 only")
def test_a_library_loaded_and_used_before_realize_is_named() -> None:
    # torch's first MKL call before realize: MKL keeps the branch it started with, and the run says so
    code = ("import torch; a = torch.randn(8, 8); a @ a; import realize; "
            "from realize.reproducible import unpinned; print(unpinned())")
    out = _fresh(code).stdout
    assert "mkl runs OFF, pinned COMPATIBLE" in out


@pytest.mark.skipif(not X86, reason="pins apply on x86-64 only")
def test_the_test_processes_run_pinned_too() -> None:
    # in-process runs (execution worlds, replans) compute here: pyproject's `-p realize` imports
    # realize before pytest's plugins load numpy
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401
    import torch

    torch.randn(8, 8) @ torch.randn(8, 8)
    assert unpinned() == []
    loaded = list(sys.modules)  # in import order: realize pinned before numpy and torch loaded
    assert loaded.index("realize") < min(loaded.index("numpy"), loaded.index("torch"))
