"""Pins the CPU math kernels that torch, MKL, OpenBLAS and numpy would otherwise pick by CPU.

Each of these libraries chooses its kernels at run time by the CPU it finds, and the kernels
round differently, so one seed's search parts between hosts at the first decision a last bit
flips (a grasp step count, a feasibility). ``pin_cpu_math`` sets, where not already set:

* ``MKL_CBWR=COMPATIBLE`` (any x86-64): MKL's one code branch that runs alike on Intel and
  non-Intel CPUs. torch's CPU wheels link MKL, and the fabric's and the kinematics' small
  products and solves (SGEMM, SGETRF/SGETRS) reach it on every control step. The earlier pin,
  ``MKL_CBWR=AVX2``, is honoured on Intel CPUs only: MKL on an AMD CPU falls back to its AUTO
  branch (``mkl_branch()`` reads it), so an Intel and an AMD host ran other kernels, and the
  default search parted on every seed (issue 68, docs/architecture.md "Same bits on every host");
* ``ATEN_CPU_CAPABILITY=avx2`` (CPUs with AVX2): torch's own vectorized kernels;
* ``OPENBLAS_CORETYPE=Haswell`` (CPUs with AVX2): the OpenBLAS that numpy and scipy ship picks
  SkylakeX kernels on an AVX-512 CPU and Haswell (or Zen, the same kernels) on an AVX2 one;
* ``NPY_DISABLE_CPU_FEATURES`` (CPUs with AVX-512): numpy's AVX-512 dispatch targets off, so
  numpy runs the AVX2 (``X86_V3``) loops that an AVX2 host runs.

torch and MKL read their variable at their first call, OpenBLAS and numpy when they are loaded:
this runs when ``realize`` is imported, before any of them (``python -m realize`` and the worker
processes import ``realize`` first). A value already set in the environment is kept.
``in_force()`` reads back what each loaded library actually runs, and ``unpinned()`` names the
ones that differ from their pin (numpy imported before ``realize`` in a notebook, say): a run
says so at its start (``warn_unpinned``) and records ``in_force()`` in ``result.json``.

What it doesn't: make GPU runs reproducible, pin anything on a CPU that is not x86-64 (those
keep their libraries' own choice), or pin what is built into a binary rather than chosen at run
time. PhysX's box-box contact generation executes ``rcpps``, whose approximate reciprocals
differ between Intel and AMD silicon; no setting reaches it (docs/architecture.md says what was
measured of it).
"""

from __future__ import annotations

import ctypes
import logging
import os
import platform
import sys
from pathlib import Path

__all__ = ["PINNED", "cpu_flags", "pins_for", "pin_cpu_math", "in_force", "unpinned", "warn_unpinned",
           "mkl_branch", "openblas_cores"]

MKL_BRANCH = "COMPATIBLE"
TORCH_CAPABILITY = "avx2"
OPENBLAS_CORE = "Haswell"
NUMPY_AVX512 = "X86_V4 AVX512_ICL AVX512_SPR"  # numpy 2.x's AVX-512 dispatch targets
PINNED = {"MKL_CBWR": MKL_BRANCH, "ATEN_CPU_CAPABILITY": TORCH_CAPABILITY, "OPENBLAS_CORETYPE": OPENBLAS_CORE,
          "NPY_DISABLE_CPU_FEATURES": NUMPY_AVX512}
# MKL's branch codes (mkl_serv_cbwr_get), as its header numbers them
_MKL_BRANCHES = {1: "OFF", 2: "AUTO", 3: "COMPATIBLE", 4: "SSE2", 6: "SSSE3", 7: "SSE4_1", 8: "SSE4_2", 9: "AVX",
                 10: "AVX2", 11: "AVX512_MIC", 12: "AVX512", 13: "AVX512_MIC_E1", 14: "AVX512_E1"}
_log = logging.getLogger(__name__)


def cpu_flags(cpuinfo: Path = Path("/proc/cpuinfo")) -> frozenset[str]:
    """The CPU's flags on x86-64 (Linux's /proc/cpuinfo); empty elsewhere or where unreadable."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return frozenset()
    try:
        text = cpuinfo.read_text()
    except OSError:
        return frozenset()
    line = next((ln for ln in text.splitlines() if ln.startswith("flags")), "")
    return frozenset(line.partition(":")[2].split())


def pins_for(flags: frozenset[str]) -> dict[str, str]:
    """The variables pinned on a CPU with these flags (none off x86-64)."""
    if not flags:
        return {}
    out = {"MKL_CBWR": MKL_BRANCH}
    if "avx2" in flags:
        out |= {"ATEN_CPU_CAPABILITY": TORCH_CAPABILITY, "OPENBLAS_CORETYPE": OPENBLAS_CORE}
    if "avx512f" in flags:
        out["NPY_DISABLE_CPU_FEATURES"] = NUMPY_AVX512
    return out


def pin_cpu_math() -> dict[str, str]:
    """Set the pinned variables not already set; the values of ``PINNED``'s variables now in force."""
    for key, value in pins_for(cpu_flags()).items():
        os.environ.setdefault(key, value)
    return {k: os.environ[k] for k in PINNED if k in os.environ}


def mkl_branch() -> str | None:
    """The code branch MKL runs in this process (``COMPATIBLE``, ``AUTO``, ``AVX2`` ...), read
    from the MKL inside torch; None where torch is not loaded or has no MKL."""
    torch = sys.modules.get("torch")
    if torch is None:
        return None
    try:
        lib = ctypes.CDLL(str(Path(torch.__file__).parent / "lib" / "libtorch_cpu.so"))
        code = lib.mkl_serv_cbwr_get(1)  # MKL_CBWR_BRANCH
    except (OSError, AttributeError):
        return None
    return _MKL_BRANCHES.get(code, str(code))


def openblas_cores(maps: Path = Path("/proc/self/maps")) -> dict[str, str]:
    """The kernel set (core name) of every OpenBLAS loaded in this process (numpy's, scipy's), by
    library file name."""
    try:
        paths = {line.split()[-1] for line in maps.read_text().splitlines() if "openblas" in line.rsplit("/", 1)[-1]}
    except OSError:
        return {}
    out = {}
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename"):
            fn = getattr(lib, name, None)
            if fn is not None:
                fn.restype = ctypes.c_char_p
                out[Path(path).name] = fn().decode()
                break
    return out


def in_force() -> dict[str, str | None]:
    """What each loaded library that picks kernels by CPU runs now (None: not loaded here)."""
    torch = sys.modules.get("torch")
    numpy = sys.modules.get("numpy")
    features = None
    if numpy is not None:
        umath = getattr(getattr(numpy, "_core", None), "_multiarray_umath", None)
        cpu = getattr(umath, "__cpu_features__", {})
        features = "AVX-512 on" if any(cpu.get(f) for f in NUMPY_AVX512.split()) else "AVX-512 off"
    cores = sorted(set(openblas_cores().values()))
    return {"torch": None if torch is None else torch.backends.cpu.get_cpu_capability().lower(),
            "mkl": mkl_branch(), "openblas": ",".join(cores) or None, "numpy": features}


def unpinned(now: dict[str, str | None] | None = None, flags: frozenset[str] | None = None) -> list[str]:
    """Each loaded library whose kernels differ from its pin on this CPU, as one line naming it."""
    pins = pins_for(cpu_flags() if flags is None else flags)
    now = in_force() if now is None else now
    want = {"torch": pins.get("ATEN_CPU_CAPABILITY"), "mkl": pins.get("MKL_CBWR"),
            "openblas": pins.get("OPENBLAS_CORETYPE"),
            "numpy": "AVX-512 off" if "NPY_DISABLE_CPU_FEATURES" in pins else None}
    return [f"{lib} runs {now[lib]}, pinned {pin}" for lib, pin in want.items()
            if pin is not None and now.get(lib) is not None and now[lib] != pin]


def warn_unpinned() -> list[str]:
    """Log one warning naming each library not on its pinned kernels (its numbers may then differ
    from another host's); the lines."""
    bad = unpinned()
    if bad:
        _log.warning("CPU math not pinned (%s): this run's numbers may differ from another host's; import realize "
                     "before numpy and torch, or set %s", "; ".join(bad),
                     " ".join(f"{k}={v!r}" for k, v in pins_for(cpu_flags()).items()))
    return bad
