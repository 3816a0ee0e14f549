"""A/B of stitched segments (issue 35, lever 3) against the paper's exact search, one sitting.

For each experiment and seed it runs ``python -m realize experiment=E seed=S levers=exact`` (as
``scripts/bench_levers.py`` does, with its validation) and then, in a child process, the stitched
search (``realize.app.stitched``: the plan cut after its first grasp, ``--n-prefix`` and
``--n-suffix`` rows per iteration, ``--iterations``, the ``--pool`` cheapest prefixes' end
states, the ``--confirm`` cheapest stitched plans realized whole) with ``levers=all``'s pruning,
then validates its cheapest confirmed plans as a run's validation does (``validation.candidates``
of them in ``validation.replicas`` perturbed worlds, the exact run's seed; the cheapest whose 95 %
lower bound reaches ``validation.min_success`` is returned, else the most robust). Rows go to ``--out`` in ``bench_levers.py``'s columns
(``search_s`` for the stitched search: every segment's rollouts, the bookkeeping and the
confirmation), and its report prints the ratios and the issue's bounds. Each stitched run's
iterations (``StitchedIteration``: rows, feasible rows, pool, cheapest stitched cost so far,
seconds per segment) go to a log beside ``--out``.

    python scripts/bench_stitch.py --seeds 0-2 --out stitch.csv
    python scripts/bench_stitch.py --experiments wall,ramp --seeds 0 --out stitch.csv
    python scripts/bench_levers.py --summary stitch.csv
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))
from bench_levers import FIELDS, read, report, run_one  # noqa: E402
from bench_seed_paper import commit_of, parse_seeds  # noqa: E402

BUDGET = ("n_prefix", "n_suffix", "iterations", "pool", "confirm")


def child(experiment: str, seed: int, budget: dict[str, int], overrides: list[str]) -> dict[str, object]:
    """The stitched search and its validation in this process (``--child``)."""
    from realize.app.compose import compose_config
    from realize.app.run_config import build_run_spec
    from realize.app.stitched import stitched_search, validate_plan
    from realize.search.stitched import StitchConfig

    spec = build_run_spec(compose_config([f"experiment={experiment}", f"seed={seed}", "levers=all",
                                          "logging.progress=false", "logging.rerun=false", *overrides]))
    res, _ = stitched_search(spec, StitchConfig(**budget),
                             on_iteration=lambda r: print(r, file=sys.stderr, flush=True))
    returned, table = validate_plan(spec, res) if res.feasible else (0, [(math.inf, "")])
    return {"search_s": round(res.search_s, 1), "iterations": len(res.history), "samples": res.samples,
            "row_steps": res.row_steps, "batch_steps": res.batch_steps, "stopped": "", "screened": "",
            "best_cost": res.cost, "feasible": int(res.feasible), "validated": table[returned][1],
            "returned_cost": table[returned][0], "validated_all": " ".join(f"{c:g}:{v}" for c, v in table),
            "stitched_cost": res.stitched_cost, "confirm_s": round(res.confirm_s, 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--experiments", default="seed_paper", help="comma-separated presets")
    ap.add_argument("--seeds", default="0", help="e.g. 0-2 or 0,3")
    ap.add_argument("--out", type=Path, help="CSV to append rows to (required but in a child)")
    ap.add_argument("--no-exact", action="store_true", help="only the stitched runs")
    ap.add_argument("--n-prefix", type=int, default=100)
    ap.add_argument("--n-suffix", type=int, default=100)
    ap.add_argument("--iterations", type=int, default=10)
    ap.add_argument("--pool", type=int, default=10)
    ap.add_argument("--confirm", type=int, default=10)
    ap.add_argument("--child", nargs=2, metavar=("EXPERIMENT", "SEED"), help=argparse.SUPPRESS)
    ap.add_argument("overrides", nargs="*", help="config overrides for the stitched run")
    args = ap.parse_args()
    budget = {k: getattr(args, k) for k in BUDGET}
    if args.child:
        print(json.dumps(child(args.child[0], int(args.child[1]), budget, args.overrides)))
        return
    if args.out is None:
        ap.error("--out is required")
    name = "stitch=" + ",".join(f"{k}={v}" for k, v in budget.items())
    new_file = not args.out.exists() or args.out.stat().st_size == 0
    with open(args.out, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS, extrasaction="ignore")
        if new_file:
            w.writeheader()
        for exp in args.experiments.split(","):
            for seed in parse_seeds(args.seeds):
                if not args.no_exact:
                    with tempfile.TemporaryDirectory(prefix=f"{exp}-{seed}-exact-") as tmp:
                        row = run_one(exp, seed, ["levers=exact"], Path(tmp) / "run")
                    w.writerow({"experiment": exp, "seed": seed, "variant": "exact", "overrides": "levers=exact",
                                "commit": commit_of(REPO), **row})
                    f.flush()
                cmd = [sys.executable, __file__, "--child", exp, str(seed), *(f"--{k.replace('_', '-')}={v}"
                       for k, v in budget.items()), *args.overrides]
                t0 = time.perf_counter()
                proc = subprocess.run(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                log = args.out.with_name(f"{args.out.stem}-{exp}-{seed}-{name.replace('=', '_').replace(',', '_')}.log")
                log.write_text(proc.stderr)  # the child's iterations, one line each
                if proc.returncode != 0:
                    raise SystemExit(f"{exp} seed {seed} stitched: exited {proc.returncode}:\n{proc.stderr[-2000:]}")
                row = json.loads(proc.stdout.strip().splitlines()[-1])
                row["wall_s"] = round(time.perf_counter() - t0, 1)
                print(f"{exp} seed {seed} stitched: stitched cost {row['stitched_cost']}, confirmed "
                      f"{row['best_cost']} ({row['confirm_s']} s to confirm); validated (cost:share) "
                      f"{row['validated_all']}, returned {row['returned_cost']}", flush=True)
                w.writerow({"experiment": exp, "seed": seed, "variant": "stitch", "overrides": name,
                            "commit": commit_of(REPO), **row})
                f.flush()
    report(read(args.out))


if __name__ == "__main__":
    main()
