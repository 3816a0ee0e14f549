"""A/B of the speed levers (issue 35): the paper's exact algorithm against the levers, one sitting.

For each experiment and seed, runs ``python -m realize experiment=E seed=S levers=exact`` (the
seed paper's algorithm, bit for bit: today's numbers) and then each variant given with
``--variant NAME=OVERRIDES`` (default: ``all``, the new defaults, i.e. no override), one run at a
time in child processes, alternating so that drift of a noisy machine hits both sides alike. A
run keeps its validation stage (``validation.replicas`` perturbed worlds), as ``make run`` does.
Per run it appends a CSV row to ``--out`` as soon as the run ends:

* ``search_s``: the CE iterations' wall time (sum of ``iteration_time_s``), the issue's "search
  wall time"; ``wall_s``: the child's whole wall time (start-up, setup, search, validation);
* ``iterations``: CE iterations done; ``samples``: plans simulated (sum of ``n_envs_per_iter``);
* ``row_steps``: control steps summed over every simulated plan (every history file of the run) (a stopped plan counts to where
  it stopped); ``batch_steps``: the sum over iterations of the batch's longest plan, which an
  iteration's physics time follows (every copy is stepped until the batch ends);
* ``stopped``: plans stopped because they could no longer be an elite (``ce.prune``);
* ``screened``: draws rejected by the kinematic screen before simulation and drawn again
  (``ce.screen``): spent, not simulated, so not in ``samples``;
* ``best_cost``, ``feasible``, ``validated`` (the returned plan's success share in the perturbed
  worlds).

Then it prints, per experiment and seed, each variant's search-time ratio to ``exact``, its best
cost ratio and validated share, with the issue's bounds (ratio <= 0.5 for the seed task, <= 0.6
for ``wall`` and ``ramp``; cost within 2 %; validated >= 0.95) marked ok/NO.

What it doesn't: run in parallel (timings would interfere), or compare rows from two machines.

    python scripts/bench_levers.py --seeds 0-2 --out levers.csv
    python scripts/bench_levers.py --experiments wall,ramp --seeds 0 --out levers.csv \
        --variant all= --variant prune=levers=exact,ce.prune=true
    python scripts/bench_levers.py --summary levers.csv
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from realize.run_dir.directory import RunDir  # noqa: E402

sys.path.insert(0, str(REPO / "scripts"))
from bench_seed_paper import commit_of, parse_seeds  # noqa: E402  (the same seed list and commit stamp)

FIELDS = ["experiment", "seed", "variant", "overrides", "search_s", "wall_s", "iterations", "samples",
          "row_steps", "batch_steps", "stopped", "best_cost", "feasible", "validated", "commit", "screened"]
RATIO_BOUND = {"seed_paper": 0.5, "wall": 0.6, "ramp": 0.6}


def run_one(experiment: str, seed: int, overrides: list[str], run_dir: Path) -> dict[str, object]:
    cmd = [sys.executable, "-m", "realize", f"experiment={experiment}", f"seed={seed}",
           f"hydra.run.dir={run_dir}", "logging.progress=false", "logging.rerun=false", *overrides]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{experiment} seed {seed} {overrides}: realize exited {proc.returncode}:\n"
                         f"{proc.stderr[-2000:]}")
    rd = RunDir(run_dir)
    doc = rd.result_json() or {}
    # every history file: a stitched run's segments are in history.npz, history_c1.npz and history_c2.npz
    keys = [None] + [int(p.stem.rsplit("_c", 1)[1]) for p in sorted(run_dir.glob("history_c*.npz"))]
    hists = [rd.history_arrays(k) for k in keys]
    steps = [h[k] for h in hists for k in sorted(h) if k.startswith("steps_")]
    val = doc.get("validation") or {}
    return {
        "search_s": round(float(sum(doc["iteration_time_s"])), 1), "wall_s": round(wall, 1),
        "iterations": doc["iterations_done"], "samples": int(sum(doc["n_envs_per_iter"])),
        "row_steps": int(sum(int(s.sum()) for s in steps)),
        "batch_steps": int(sum(int(s.max()) for s in steps)),
        "stopped": int(sum(doc.get("n_stopped_per_iter") or [0])),
        "screened": int(sum(doc.get("n_screened_per_iter") or [0])),
        "best_cost": doc["best_cost"], "feasible": int(bool(doc["feasible"])),
        "validated": val.get("success_share", ""),
    }


def read(path: Path) -> list[dict[str, str]]:
    with open(path) as f:
        return list(csv.DictReader(f))


def report(rows: list[dict[str, str]]) -> bool:
    ok_all = True
    key = lambda r: (r["experiment"], int(r["seed"]))  # noqa: E731
    for exp, seed in sorted({key(r) for r in rows}):
        mine = [r for r in rows if key(r) == (exp, seed)]
        ref = next((r for r in mine if r["variant"] == "exact"), None)
        if ref is None:
            continue
        for r in mine:
            if r["variant"] == "exact":
                continue
            ratio = float(r["search_s"]) / float(ref["search_s"])
            cost = float(r["best_cost"]) / float(ref["best_cost"])
            val = float(r["validated"] or "nan")
            bound = RATIO_BOUND.get(exp, 0.6)
            checks = [ratio <= bound, cost <= 1.02, val >= 0.95]
            ok_all &= all(checks)
            mark = lambda ok: "ok" if ok else "NO"  # noqa: E731
            print(f"{exp} seed {seed} {r['variant']}: search {r['search_s']} s vs {ref['search_s']} s "
                  f"ratio {ratio:.3f} [{mark(checks[0])} <= {bound}], best cost {r['best_cost']} vs "
                  f"{ref['best_cost']} ({cost:.4f}) [{mark(checks[1])}], validated {val:.3f} "
                  f"[{mark(checks[2])}], iterations {r['iterations']}/{ref['iterations']}, batch steps "
                  f"{r['batch_steps']}/{ref['batch_steps']}, row steps {r['row_steps']}/{ref['row_steps']}, "
                  f"stopped {r['stopped']}, screened {r.get('screened') or 0}")
    return ok_all


def main() -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--experiments", default="seed_paper", help="comma-separated presets")
    ap.add_argument("--seeds", default="0", help="e.g. 0-2 or 0,3")
    ap.add_argument("--variant", action="append", default=None,
                    help="NAME=OVERRIDES (comma-separated) against exact; default all= (new defaults)")
    ap.add_argument("--out", type=Path, help="CSV to append rows to")
    ap.add_argument("--summary", type=Path, help="only print the ratios of this CSV")
    args = ap.parse_args()
    if args.summary:
        sys.exit(0 if report(read(args.summary)) else 1)
    if args.out is None:
        ap.error("--out is required unless --summary is given")
    variants = {"exact": ["levers=exact"]}
    for v in args.variant or ["all="]:
        name, _, ov = v.partition("=")
        variants[name] = [o for o in ov.split(",") if o]
    new_file = not args.out.exists() or args.out.stat().st_size == 0
    with open(args.out, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        if new_file:
            w.writeheader()
        for exp in args.experiments.split(","):
            for seed in parse_seeds(args.seeds):
                for name, ov in variants.items():
                    with tempfile.TemporaryDirectory(prefix=f"{exp}-{seed}-{name}-") as tmp:
                        row = run_one(exp, seed, ov, Path(tmp) / "run")
                    row = {"experiment": exp, "seed": seed, "variant": name, "overrides": " ".join(ov),
                           **row, "commit": commit_of(REPO)}
                    w.writerow(row)
                    f.flush()
                    print(", ".join(f"{k}={v}" for k, v in row.items()), flush=True)
    sys.exit(0 if report(read(args.out)) else 1)


if __name__ == "__main__":
    main()
