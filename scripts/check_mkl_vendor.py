"""Does MKL give the same bits on an Intel and an AMD CPU? A minimal reproduction on one host.

MKL picks its code path by CPU vendor as well as by instruction set: it honours ``MKL_CBWR=AVX2``
on Intel CPUs only and falls back to its AUTO branch elsewhere. This script runs the matrix calls
the controllers make on every control step (SGEMM of the kinematics' small shapes, the fabric's
batched solve: SGETRF/SGETRS) through torch, once as MKL finds the CPU and once with MKL told it
runs on an Intel CPU (a two-function library preloaded over MKL's ``mkl_serv_intel_cpu_true`` and
``mkl_serv_intel_cpu``, built here with the C compiler), for each ``MKL_CBWR`` branch, and prints
the branch MKL reports and a digest of the results. On an AMD host the two columns differ for
``AVX2`` (the old pin) and agree for ``COMPATIBLE`` (``realize.reproducible``'s pin); on an Intel
host both columns are the native ones. What it doesn't: run the simulator (``check_same_seed.py``
runs whole searches; its runs take the same preload through ``LD_PRELOAD``).

    python scripts/check_mkl_vendor.py
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHIM = "int mkl_serv_intel_cpu_true(void) { return 1; }\nint mkl_serv_intel_cpu(void) { return 1; }\n"
PROBE = """
import hashlib, torch
from realize.reproducible import mkl_branch
g = torch.Generator().manual_seed(0)
h = hashlib.sha256()
for m, n, k in [(11, 24, 3), (5, 24, 3), (64, 64, 64)]:
    h.update((torch.randn(m, k, generator=g) @ torch.randn(k, n, generator=g)).numpy().tobytes())
a = torch.randn(200, 6, 6, generator=g) + 6 * torch.eye(6)
h.update(torch.linalg.solve(a, torch.randn(200, 6, 1, generator=g)).numpy().tobytes())
print(mkl_branch(), h.hexdigest()[:16])
"""


def build_shim(folder: Path) -> Path | None:
    """The preload library, or None without a C compiler."""
    cc = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if cc is None:
        return None
    src, lib = folder / "as_intel.c", folder / "as_intel.so"
    src.write_text(SHIM)
    subprocess.run([cc, "-shared", "-fPIC", "-O2", "-o", str(lib), str(src)], check=True)
    return lib


def probe(branch: str, preload: Path | None) -> str:
    env = dict(os.environ, MKL_CBWR=branch)
    env.pop("LD_PRELOAD", None)
    if preload is not None:
        env["LD_PRELOAD"] = str(preload)
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, cwd=REPO, capture_output=True, text=True, check=True)
    return out.stdout.split("\n")[-2]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--branches", default="AVX2,COMPATIBLE", help="MKL_CBWR values to try (default AVX2,COMPATIBLE)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        shim = build_shim(Path(tmp))
        if shim is None:
            print("error: no C compiler (cc or gcc) to build the preload library", file=sys.stderr)
            return 2
        print("| MKL_CBWR | as found: branch, digest | told Intel: branch, digest | same bits |")
        print("|---|---|---|---|")
        for branch in args.branches.split(","):
            native, intel = probe(branch, None), probe(branch, shim)
            same = native.split()[1] == intel.split()[1]
            print(f"| {branch} | {native} | {intel} | {'yes' if same else 'no'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
