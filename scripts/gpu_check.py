"""GPU check: the CUDA tests, a seed-paper run and a journal-budget run on the PhysX GPU backend.

On a machine with a CUDA GPU (``make gpu-check``) it runs, one after the other, each in a child
process with its own time limit:

1. ``pytest -m gpu`` (the tests that need CUDA: GPU scene, batched A* and CE on CUDA);
2. ``realize experiment=seed_paper device=cuda`` (200 plans x 10 iterations);
3. ``realize experiment=journal device=cuda`` (3000 -> 300 plans, 20 iterations);

and prints one Markdown table (part, status, wall time, result) that goes into the README
beside the paper's numbers; the table is also written to ``--out``/gpu_check.md with each
part's log, as soon as each part ends (a part that runs out of time still leaves its row and
log). Each run's own directory (``result.json``, ...) is under ``--out`` too.

What it doesn't: run anything without CUDA (it says so and exits 2), or compare with the CPU
(``scripts/bench_seed_paper.py`` does that on the CPU).

    python scripts/gpu_check.py [--out DIR] [--quick] [--limit-tests S] [--limit-seed S] [--limit-journal S]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


@dataclass
class Part:
    name: str
    cmd: list[str]
    limit_s: float
    run_dir: Path | None = None


@dataclass
class Row:
    name: str
    status: str
    wall_s: float
    result: str


def describe_run(run_dir: Path) -> str:
    from realize.run_dir.directory import RunDir

    rd = RunDir(run_dir)
    doc = rd.result()
    if doc is None:
        return "no result.json"
    try:
        success = rd.success_per_iter()
    except Exception:  # noqa: BLE001 - a partial run may lack history
        success = []
    parts = [f"status {getattr(doc, 'status', '?')}"]
    if getattr(doc, "iterations_done", None) is not None:
        parts.append(f"{doc.iterations_done} iterations")
    parts.append(f"feasible {getattr(doc, 'feasible', '?')}")
    if getattr(doc, "best_cost", None) is not None:
        parts.append(f"best cost {doc.best_cost:.0f}")
    if len(success):
        parts.append(f"success {success[0] * 100:.0f} % -> {success[-1] * 100:.0f} %")
    times = getattr(doc, "iteration_time_s", None) or []
    if times:
        parts.append(f"{sum(times) / len(times):.1f} s per iteration")
    return ", ".join(parts)


def describe_tests(log: str) -> str:
    tail = [ln for ln in log.strip().splitlines() if ln.strip()]
    return tail[-1].strip("= ") if tail else "no output"


def run_part(part: Part, out: Path) -> Row:
    log_path = out / f"{part.name.replace(' ', '_')}.log"
    t0 = time.perf_counter()
    with open(log_path, "w") as log:
        proc = subprocess.Popen(part.cmd, cwd=REPO, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            rc = proc.wait(timeout=part.limit_s)
            status = "ok" if rc == 0 else f"failed (exit {rc})"
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, 15)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, 9)
                proc.wait()
            status = f"stopped at the {part.limit_s:.0f} s limit"
    wall = time.perf_counter() - t0
    text = log_path.read_text(errors="replace")
    result = describe_run(part.run_dir) if part.run_dir is not None else describe_tests(text)
    if status != "ok":
        last = [ln for ln in text.strip().splitlines() if ln.strip()][-1:] or [""]
        result = f"{result}; last log line: {last[0][:160]}"
    return Row(part.name, status, wall, result)


def table(rows: list[Row], device: str) -> str:
    lines = [f"GPU check on {device}", "", "| part | status | wall time | result |", "|---|---|---|---|"]
    lines += [f"| {r.name} | {r.status} | {r.wall_s:.0f} s | {r.result} |" for r in rows]
    return "\n".join(lines) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=REPO / "outputs" / "gpu_check")
    ap.add_argument("--quick", action="store_true", help="seed-paper budget for the journal part too (2 iterations)")
    ap.add_argument("--limit-tests", type=float, default=120.0)
    ap.add_argument("--limit-seed", type=float, default=240.0)
    ap.add_argument("--limit-journal", type=float, default=240.0)
    args = ap.parse_args()
    import torch

    if not torch.cuda.is_available():
        print("gpu_check: no CUDA GPU here (torch.cuda.is_available() is False); nothing to check", file=sys.stderr)
        return 2
    device = torch.cuda.get_device_name(0)
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    py = sys.executable
    realize = [py, "-m", "realize", "device=cuda", "logging.progress=false"]
    journal = ["experiment=journal"] + (["ce.iterations=2"] if args.quick else [])
    parts = [
        Part("CUDA tests", [py, "-m", "pytest", "-q", "-m", "gpu", "tests"], args.limit_tests),
        Part("seed paper (200 x 10)", [*realize, "experiment=seed_paper", f"hydra.run.dir={out / 'seed_paper'}"],
             args.limit_seed, out / "seed_paper"),
        Part("journal (3000 -> 300 x 20)" if not args.quick else "journal (3000 -> 300, 2 iterations)",
             [*realize, *journal, f"hydra.run.dir={out / 'journal'}"], args.limit_journal, out / "journal"),
    ]
    rows: list[Row] = []
    for part in parts:
        rows.append(run_part(part, out))
        (out / "gpu_check.md").write_text(table(rows, device))
        print(f"{part.name}: {rows[-1].status}, {rows[-1].wall_s:.0f} s", flush=True)
    print(table(rows, device))
    return 0 if all(r.status == "ok" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
