"""realize.reproducible: the CPU math paths are pinned on AVX2 machines, and only there."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from realize import reproducible
from realize.reproducible import PINNED, cpu_has_avx2, pin_cpu_math

REPO = Path(__file__).resolve().parent.parent


def _cpuinfo(tmp_path: Path, flags: str) -> Path:
    p = tmp_path / "cpuinfo"
    p.write_text(f"processor\t: 0\nmodel name\t: some cpu\nflags\t\t: fpu sse2 {flags}\n\n")
    return p


def test_avx2_is_read_from_the_flags_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(reproducible.platform, "machine", lambda: "x86_64")
    assert cpu_has_avx2(_cpuinfo(tmp_path, "avx avx2 fma"))
    assert not cpu_has_avx2(_cpuinfo(tmp_path, "avx fma avx512f"))  # avx512f alone is not avx2
    assert not cpu_has_avx2(tmp_path / "missing")
    monkeypatch.setattr(reproducible.platform, "machine", lambda: "aarch64")
    assert not cpu_has_avx2(_cpuinfo(tmp_path, "avx avx2 fma"))


def test_pins_unset_variables_and_keeps_the_users(monkeypatch: pytest.MonkeyPatch) -> None:
    for key in PINNED:
        monkeypatch.delenv(key, raising=False)
    monkeypatch.setenv("ATEN_CPU_CAPABILITY", "default")
    monkeypatch.setattr(reproducible, "cpu_has_avx2", lambda: True)
    assert pin_cpu_math() == {"MKL_CBWR": "AVX2", "ATEN_CPU_CAPABILITY": "default"}


def test_nothing_is_pinned_without_avx2(monkeypatch: pytest.MonkeyPatch) -> None:
    for key in PINNED:
        monkeypatch.delenv(key, raising=False)
    monkeypatch.setattr(reproducible, "cpu_has_avx2", lambda: False)
    assert pin_cpu_math() == {}


@pytest.mark.skipif(not cpu_has_avx2(), reason="needs an x86-64 CPU with AVX2")
def test_importing_realize_pins_torch_before_its_first_op() -> None:
    # a fresh interpreter with nothing set: torch imported first, realize next, then the first op
    code = ("import torch, realize; torch.ones(4).sum(); "
            "print(torch.backends.cpu.get_cpu_capability())")
    env = {k: v for k, v in os.environ.items() if k not in PINNED}
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True,
                         check=True).stdout.split()
    assert out[-1] == "AVX2"
