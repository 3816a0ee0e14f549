"""Replan time against a cold run, in one sitting: the ratio issue 38 asks for.

What it does: (1) a cold ``python -m realize experiment=seed_paper`` run in a child process (wall
time as a user sees it, start-up and validation included; ``--cold-args`` adds overrides), then
(2) every repair an execution study recorded (``--study DIR``: ``execution/<family>/`` folders of
``scripts/execute.py``; each ``world-*-closed.json`` lists its replans with their start state,
first action, world changes and the run they repaired), repeated by one fresh
``realize.Planner`` (its workers opened first with ``warm_up``, as the executor does), each
timed: setup (workers taken over or scenes rebuilt), search, total. It prints the median and
p95 replan time, re-parameterizing and re-sequencing apart, the cold run's wall time, and the
ratio median / cold (the issue's bound: <= 1/15).
What it doesn't: re-run the executions (the repairs start from their recorded states), or
compare numbers from different machines.

    python scripts/bench_replan.py --study outputs/seed0/execution/table_moved \
        --study outputs/seed0/execution/knocked_out --out bench/replan.json
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def _repairs(study: Path) -> list[dict]:
    out = []
    for f in sorted(study.glob("world-*-closed.json")):
        for r in json.loads(f.read_text()).get("replans", []):
            rd = Path(r["run_dir"])
            res = rd / "result.json"
            if not res.is_file():
                continue
            rep = json.loads(res.read_text()).get("replan") or {}
            out.append({"kind": r["kind"], "study": study.name, "world": f.stem, "run_dir": str(rd),
                        "from": rep.get("from"), "action": rep.get("action"), "changes": r.get("changes", []),
                        "state": str(rd / "start_state.json"), "task": json.loads(res.read_text())["config"]["task"]})
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    p.add_argument("--study", action="append", required=True, help="an execution/<family> folder (repeatable)")
    p.add_argument("--no-cold", action="store_true", help="skip the cold run (report replans only)")
    p.add_argument("--cold-args", nargs="*", default=[], help="overrides of the cold run")
    p.add_argument("--max", type=int, default=None, help="at most this many repairs")
    p.add_argument("--per-study", type=int, default=None, help="at most this many repairs of each study")
    p.add_argument("--out", default=None, help="JSON file of every timing")
    a = p.parse_args(argv)

    from realize.run.planner import Planner
    from realize.world.state import load_state

    repairs = [r for s in a.study for r in _repairs(Path(s))[: a.per_study]][: a.max]
    if not repairs:
        print("no recorded replans in the studies given", file=sys.stderr)
        return 2
    cold_s = None
    if not a.no_cold:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "realize", "experiment=seed_paper", "logging.progress=false",
                            f"hydra.run.dir={tmp}/cold", *a.cold_args], cwd=REPO, check=True,
                           stdout=subprocess.DEVNULL)
            cold_s = time.perf_counter() - t0
        print(f"cold experiment=seed_paper run: {cold_s:.1f} s", flush=True)
    rows = []
    source = repairs[0]["from"]
    with Planner.from_run(source) as planner:
        warm = planner.warm_up()
        with tempfile.TemporaryDirectory() as tmp:
            for i, r in enumerate(repairs):
                state = load_state(r["state"])
                t0 = time.perf_counter()
                if r["kind"] == "re-parameterize" or r["task"].get("plan") == json.loads(
                        (Path(r["from"]) / "result.json").read_text())["config"]["task"].get("plan"):
                    res = planner.replan(state, int(r["action"]), r["changes"], source=r["from"],
                                         run_dir=f"{tmp}/r{i}")
                else:
                    res = planner.resequence(r["task"], state, r["changes"], source=r["from"], run_dir=f"{tmp}/r{i}")
                wall = time.perf_counter() - t0
                rows.append({**{k: r[k] for k in ("kind", "study", "world", "action")}, "wall_s": wall,
                             "feasible": res.feasible, "cost": res.cost if res.feasible else None,
                             "scene": res.scene, **res.timings.to_dict()})
                print(f"{r['study']} {r['world']} {r['kind']}: {wall:.1f} s ({res.scene}; setup "
                      f"{res.timings.setup_s:.1f} s, search {res.timings.search_s:.1f} s), feasible {res.feasible}",
                      flush=True)
    walls = np.array([r["wall_s"] for r in rows])
    report = {"cold_s": cold_s, "planner_start_s": warm, "replans": len(rows), "median_s": float(np.median(walls)),
              "p95_s": float(np.percentile(walls, 95)), "rows": rows}
    for kind in ("re-parameterize", "re-sequence"):
        w = [r["wall_s"] for r in rows if r["kind"] == kind]
        if w:
            report[kind] = {"n": len(w), "median_s": float(np.median(w)), "p95_s": float(np.percentile(w, 95))}
    if cold_s:
        report["ratio_median_to_cold"] = report["median_s"] / cold_s
    print(json.dumps({k: v for k, v in report.items() if k != "rows"}, indent=2))
    if a.out:
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        Path(a.out).write_text(json.dumps(report, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
