"""``scripts/gpu_check.py`` runs on the CPU (``--device cpu``, small N) as it would on an offline
CUDA machine: every part in its own process, nothing of ManiSkill, SAPIEN, Hydra or rerun
imported (a ``sitecustomize`` refuses them) and no package beyond those torch, numpy, scipy and
PyYAML import themselves (the ``sitecustomize`` records every process's modules), the table and
rows written to ``--out``; and a part stopped by its limit keeps its finished rows plus one
saying where it stopped.
What it doesn't: touch a GPU (the check itself does that, on a CUDA machine).
"""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from realize.robot.spec import load_robot_spec
from realize.robot.urdf import source_urdf

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "scripts" / "gpu_check.py"
BLOCKER = '''import atexit, importlib.abc, os, sys
class _NoSimulator(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("mani_skill", "sapien", "gymnasium", "hydra", "omegaconf", "rerun"):
            raise ImportError(f"gpu_check imported {name}: the CUDA machine does not have it")
sys.meta_path.insert(0, _NoSimulator())
def _record():
    with open(os.path.join(os.environ["MODULES_DIR"], f"{os.getpid()}.txt"), "w") as f:
        f.write("\\n".join(sorted({m.split(".")[0] for m in sys.modules})))
atexit.register(_record)
'''
PREINSTALLED = "import torch, numpy, yaml, scipy.sparse, scipy.sparse.csgraph"  # on the CUDA machine


def _script():
    spec = importlib.util.spec_from_file_location("gpu_check", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _imported(modules: Path) -> set[str]:
    names = set().union(*(set(f.read_text().split()) for f in modules.glob("*.txt")))
    return {m for m in names if m not in sys.stdlib_module_names and not m.startswith("_")}


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_gpu_check_runs_on_the_cpu_without_the_simulator(tmp_path: Path) -> None:
    site, modules, baseline = tmp_path / "site", tmp_path / "modules", tmp_path / "baseline"
    for d in (site, modules, baseline):
        d.mkdir()
    (site / "sitecustomize.py").write_text(BLOCKER)
    env = {"PYTHONPATH": f"{site}:{REPO}", "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    subprocess.run([sys.executable, "-c", PREINSTALLED], env={**env, "MODULES_DIR": str(baseline)}, check=True,
                   timeout=60)
    urdf = tmp_path / "fetch.urdf"  # carried as a file, as to a machine without ManiSkill
    shutil.copyfile(source_urdf(load_robot_spec("fetch_omni").urdf), urdf)
    out = tmp_path / "out"
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, str(SCRIPT), "--device", "cpu", "--sizes", "8", "--timing", "0.05",
                        "--urdf", str(urdf), "--out", str(out)], cwd=REPO, capture_output=True, text=True, timeout=120,
                       env={**env, "MODULES_DIR": str(modules)})
    wall = time.monotonic() - t0
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:] + "".join(
        f"\n--- {log.name}\n{log.read_text()[-1500:]}" for log in out.glob("*.log"))
    rows = [json.loads(ln) for ln in (out / "rows.jsonl").read_text().splitlines()]
    done = {(r["part"], r["n"]) for r in rows if r["stage"] == "done" and r["ok"]}
    assert done == {(part, n) for part in _script().PARTS for n in (8,)}
    md = (out / "gpu_check.md").read_text()
    assert md.count("| ok |") == 6 and "MISMATCH" not in md
    assert {f.name for f in out.glob("*.log")} == {f"{part}.log" for part in _script().PARTS}
    assert wall < 60, f"{wall:.0f} s"
    assert len(list(modules.glob("*.txt"))) == 1 + len(_script().PARTS)  # the driver and one process a part
    assert _imported(modules) - _imported(baseline) == {"realize"}


def test_a_part_stopped_at_its_limit_says_how_far_it_got(tmp_path: Path) -> None:
    gc = _script()
    records = tmp_path / "rows.jsonl"
    lines = [dict(part="fabric", n=200, stage="started"), dict(part="fabric", n=200, stage="device", device_s=0.01),
             dict(part="fabric", n=200, stage="done", cpu_s=0.05, max_diff=1e-6, ok=True),
             dict(part="fabric", n=3000, stage="started"), dict(part="fabric", n=3000, stage="device", device_s=0.02)]
    records.write_text("".join(json.dumps(r) + "\n" for r in lines))
    rows = gc._rows(records, "fabric", [200, 3000, 30000], "stopped at its 60 s limit")
    assert [(r["n"], r["result"]) for r in rows] == [
        (200, "ok"), (3000, "stopped at its 60 s limit while timing the CPU")]
    md = gc.table(rows, "head")
    assert "| fabric | 200 | 10 | 50 | 5x | 1e-06 |" in md and "| fabric | 3000 | 20 | - | - | - |" in md
    none = gc._rows(tmp_path / "missing.jsonl", "ce", [200], "failed (exit 1, see ce.log)")
    assert [(r["n"], r["result"]) for r in none] == [(200, "not reached (failed (exit 1, see ce.log))")]


def test_cuda_asked_for_without_cuda_is_one_line(tmp_path: Path) -> None:
    import torch

    if torch.cuda.is_available():
        pytest.skip("a CUDA device is here: the check runs instead of refusing")
    p = subprocess.run([sys.executable, str(SCRIPT), "--out", str(tmp_path)], cwd=REPO, capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 2 and p.stderr.strip().count("\n") == 0 and "no CUDA device" in p.stderr
