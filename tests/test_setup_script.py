"""``scripts/setup.sh`` installs the same torch version with and without an NVIDIA GPU.

The script runs in a scratch copy of the checkout with a stand-in ``python3`` (it records its
arguments, makes a venv of itself, fails ``import torch`` and the package check) and, for the GPU
case, an ``nvidia-smi`` that lists a GPU; what pip was asked to install is read from the record.
What it doesn't: install anything, or reach a network.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FAKE_PYTHON = """#!/bin/bash
echo "$*" >> "$SETUP_LOG"
case "$1" in
  -c) [[ "$2" == *version_info* ]] && exit 0; exit 1 ;;
  -m) if [ "$2" = venv ]; then mkdir -p "$3/bin"; cp "$0" "$3/bin/python"; exit 0; fi
      [ "$2" = pip ] && exit 0 ;;
esac
exit 1
"""


@pytest.mark.parametrize("gpu", [False, True])
def test_setup_pins_the_same_torch_with_and_without_a_gpu(tmp_path: Path, gpu: bool) -> None:
    work = tmp_path / "checkout"
    (work / "scripts").mkdir(parents=True)
    shutil.copy(REPO / "scripts" / "setup.sh", work / "scripts" / "setup.sh")
    shutil.copy(REPO / "pyproject.toml", work / "pyproject.toml")
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for name, text in [("python3", FAKE_PYTHON)] + ([("nvidia-smi", "#!/bin/sh\necho 'GPU 0: H200'\n")] if gpu else []):
        (bin_dir / name).write_text(text)
        (bin_dir / name).chmod(0o755)
    log = tmp_path / "calls.log"
    env = {"PATH": f"{bin_dir}:/usr/bin:/bin", "SETUP_LOG": str(log), "HOME": str(tmp_path)}
    p = subprocess.run(["bash", "scripts/setup.sh"], cwd=work, env=env, capture_output=True, text=True, timeout=60)
    assert p.returncode == 1 and "the package install failed" in p.stderr, p.stdout + p.stderr  # the stand-in's end
    pins = re.findall(r"-m pip install -q (torch\S*)", log.read_text())
    wanted = re.search(r"^TORCH_VERSION=(\S+)", (REPO / "scripts" / "setup.sh").read_text(), re.M).group(1)
    assert pins == ([f"torch=={wanted}"] if gpu else [f"torch=={wanted}+cpu"]), (pins, p.stdout)
    assert not (gpu and "torch>=" in log.read_text())
    assert os.path.isfile(work / ".venv" / "bin" / "python")
