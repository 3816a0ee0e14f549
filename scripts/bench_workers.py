"""Rollout workers: seed-paper wall time with 1 vs 2 (or more) workers in one invocation, the
throughput per worker count, and what the journal budget would take on 1, 4 and 16 nodes.

Runs ``python -m realize experiment=seed_paper workers.n=W`` once per worker count, one after
the other, each in a child process (wall time as a user sees it), and prints per run: wall
time, setup time, realizations per second over the CE iterations, and the ratio to the first
worker count. It checks that every run produced the same numbers (best_cost, success and cost
per iteration, best_z): the workers must not change them (``realize.scene.shards``).
The last lines estimate the journal budget (3000 -> 300 samples x 20 iterations) from the
measured throughput per worker: nodes of ``--node-cores`` cores, one worker per core, every
worker as fast as one measured here, ``sim.shard_rows`` small enough that every worker holds a
shard (a worker holds whole shards; ``deal_rows`` spreads the late, smaller batches over all).

    python scripts/bench_workers.py                  # seed paper, 1 vs 2 workers (~15 min here)
    python scripts/bench_workers.py --quick          # one CE iteration of 200 samples
    python scripts/bench_workers.py --workers 1 2 4 --node-cores 32 ce.iterations=3

What it doesn't: run the workers on several machines (use ``workers.backend=ray``), or compare
numbers across machines.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

SAME = ("best_cost", "success_per_iter", "best_cost_per_iter", "best_z", "n_feasible_per_iter")


def run_once(workers: int, overrides: list[str], out: Path) -> dict:
    cmd = [sys.executable, "-m", "realize", "experiment=seed_paper", f"workers.n={workers}", "validation=off",
           "logging.progress=false",
           "logging.rerun=false", *overrides, f"hydra.run.dir={out}"]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise SystemExit(f"workers.n={workers} failed (exit {p.returncode}):\n{p.stderr[-3000:]}")
    res = json.loads((out / "result.json").read_text())
    res["bench_wall_s"] = wall
    return res


def journal_rows(start: int = 3000, end: int = 300, iterations: int = 20) -> list[int]:
    """Samples per iteration of the journal's linear schedule (as ``realize.search.ce`` draws them)."""
    from realize.search.ce.config import CEConfig

    cfg = CEConfig(n_envs=start, n_envs_end=end, schedule="linear", n_elite=50, iterations=iterations)
    return [cfg.n_envs_at(i) for i in range(iterations)]


def main() -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--quick", action="store_true", help="one CE iteration (ce.iterations=1)")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="worker counts, first is the baseline")
    ap.add_argument("--node-cores", type=int, default=32, help="cores per node of the scaling estimate")
    ap.add_argument("overrides", nargs="*", help="config overrides for every run")
    args = ap.parse_args()
    overrides = (["ce.iterations=1"] if args.quick else []) + args.overrides
    runs = []
    with tempfile.TemporaryDirectory(prefix="bench_workers_") as tmp:
        for w in args.workers:
            res = run_once(w, overrides, Path(tmp) / f"w{w}")
            rows = sum(res["n_envs_per_iter"])
            sim_s = sum(res["iteration_time_s"])
            runs.append((w, res, rows / sim_s))
            print(f"workers {w}: wall {res['bench_wall_s']:.1f} s (run {res['wall_time_s']:.1f} s, setup "
                  f"{res['setup_time_s']:.1f} s), {rows} realizations in {sim_s:.1f} s: {rows / sim_s:.2f} per s, "
                  f"best cost {res['best_cost']}", flush=True)
    base_w, base, base_rate = runs[0]
    print(f"cores here: {len(os.sched_getaffinity(0))}")
    for w, res, rate in runs[1:]:
        print(f"wall_ratio_{w}_vs_{base_w}: {res['bench_wall_s'] / base['bench_wall_s']:.3f}  "
              f"throughput_ratio: {rate / base_rate:.3f}")
    same = all(all(res[k] == base[k] for k in SAME) for _, res, _ in runs[1:])
    print(f"same_numbers: {same}")
    w_top, _, rate_top = max(runs, key=lambda r: r[2])
    per_worker = rate_top / w_top
    rows = journal_rows()
    print(f"journal budget: {sum(rows)} realizations over {len(rows)} iterations; {per_worker:.2f} realizations/s "
          f"per worker (measured with {w_top} workers, 100-copy shards); one worker: {sum(rows) / per_worker / 60:.0f} min")
    for nodes in (1, 4, 16):
        workers = nodes * args.node_cores
        shard = -(-max(rows) // workers)  # sim.shard_rows that gives every worker a shard at iteration 0
        est = sum(r / workers for r in rows) / per_worker
        print(f"  {nodes:>2} node(s) x {args.node_cores} cores: {workers} workers with sim.shard_rows={shard}: "
              f"~{est / 60:.1f} min if a worker keeps its measured rate ({min(100, shard)} copies per shard or fewer "
              f"run less efficiently: a lower bound)")
    if not same:
        raise SystemExit("the worker counts gave different numbers")


if __name__ == "__main__":
    main()
