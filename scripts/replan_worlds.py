"""Changed worlds of the seed task: a cold search against one warm-started from an earlier run.

What it does: takes one seed-paper run (``--source``; made first with ``experiment=seed_paper
seed=0`` if the directory holds no result), then, for each changed world (the cube moved 5-15 cm
on table 1, table 2 moved 20-40 cm, the robot's start moved 0.5 m, a wall between the tables,
and all at once), runs ``realize`` twice in a child process:
  * cold: the seed paper's search (200 x 10) in that world;
  * warm: ``warm_start=<source>`` with 100 samples x 3 iterations (``--warm`` overrides), in two
    shards of 50 so both cores work.
Regions follow their objects (``frame:`` in configs/task/pick_place.yaml), so both runs search
around where the cube and table 2 now are. One CSV row per run is appended to ``--out`` as soon
as it ends (a killed study keeps what it has; ``--resume`` skips rows already there), and a
table is printed with the issue's checks: warm feasible in every world, its best cost within
5 % of the cold run's in >= 8 of 10, in <= 25 % of the cold run's wall time. The success
columns are the share of the rows that ran to their end that ended feasible
(``finished_success_per_iter``; ``stopped_last``: the rows ``ce.prune`` stopped in the last
iteration), which ``success_per_iter`` would count as failed; a run from before that key gives
``success_per_iter``. A CSV written before ``stopped_last`` keeps its columns.
What it doesn't: run worlds in parallel (timings would interfere) or compare rows measured on
different machines.

    python scripts/replan_worlds.py --source runs/seed0 --out bench/replan_worlds.csv
    python scripts/replan_worlds.py --summary bench/replan_worlds.csv
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# name -> overrides of the seed task's scene (one copy's frame: table 1 at (0, 1.2), table 2 at
# (0, -1.2), the robot starting at (-2, 0))
WORLDS: dict[str, list[str]] = {
    "cube +5 cm x": ["scene.objects.cube.offset=[0.05,0.0]"],
    "cube 10 cm diagonal": ["scene.objects.cube.offset=[-0.08,0.06]"],
    "cube 15 cm -y": ["scene.objects.cube.offset=[0.0,-0.15]"],
    "table 2 +20 cm x": ["scene.tables.1.center=[0.2,-1.2]"],
    "table 2 -30 cm x": ["scene.tables.1.center=[-0.3,-1.2]"],
    "table 2 40 cm diagonal": ["scene.tables.1.center=[0.28,-1.48]"],
    "start +0.5 m y": ["scene.robot_start=[-2.0,0.5,0.0]"],
    "start +0.5 m x": ["scene.robot_start=[-1.5,0.0,0.0]"],
    "wall between tables": ["scene.variant=wall"],
    "cube, table 2 and wall": ["scene.objects.cube.offset=[0.06,-0.05]", "scene.tables.1.center=[0.3,-1.2]",
                               "scene.variant=wall"],
}
COLD = ["experiment=seed_paper"]
WARM = ["experiment=seed_paper", "ce.n_envs=100", "ce.iterations=3", "sim.shard_rows=50"]
QUIET = ["logging.rerun=false", "logging.progress=false"]
FIELDS = ["world", "mode", "wall_s", "realize_wall_s", "feasible", "best_cost", "success_iter0", "success_last",
          "n_envs", "iterations", "run_dir", "stopped_last"]


def realize(args: list[str], run_dir: Path) -> tuple[float, dict]:
    """One ``realize`` run in a child process: (wall seconds, its result.json)."""
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "realize", *args, *QUIET, f"hydra.run.dir={run_dir}"], cwd=REPO,
                       env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        sys.exit(f"realize {' '.join(args)} failed ({p.returncode}):\n{p.stderr[-3000:]}")
    return wall, json.loads((run_dir / "result.json").read_text())


def finished_success(doc: dict) -> list[float]:
    """Per iteration, the share of the rows that finished (not stopped by ``ce.prune``) that ended
    feasible: ``finished_success_per_iter``, else ``success_per_iter`` (no pruning, or an older run)."""
    shares = doc.get("finished_success_per_iter") or doc.get("success_per_iter") or [None]
    return [float("nan") if v is None else float(v) for v in shares]


def row(world: str, mode: str, wall: float, doc: dict, run_dir: Path) -> dict:
    succ = finished_success(doc)
    stopped = doc.get("n_stopped_per_iter") or []
    return {"world": world, "mode": mode, "wall_s": f"{wall:.1f}", "realize_wall_s": f"{doc['wall_time_s']:.1f}",
            "feasible": doc["feasible"], "best_cost": doc["best_cost"], "success_iter0": f"{succ[0]:.3f}",
            "success_last": f"{succ[-1]:.3f}", "n_envs": doc["n_envs_per_iter"][0],
            "iterations": doc["iterations_done"], "run_dir": str(run_dir),
            "stopped_last": stopped[-1] if stopped else ""}


def summary(path: Path) -> None:
    """The table of a study's CSV and the issue's three checks."""
    rows = list(csv.DictReader(path.open()))
    by = {(r["world"], r["mode"]): r for r in rows}
    print("| world | cold: cost, wall s | warm: cost, wall s | warm iter-0 success | cost ratio | wall ratio |")
    print("|---|---|---|---|---|---|")
    feasible = close = fast = n = 0
    for world in WORLDS:
        c, w = by.get((world, "cold")), by.get((world, "warm"))
        if c is None or w is None:
            continue
        n += 1
        wf = w["feasible"] == "True"
        cost_ratio = float(w["best_cost"]) / float(c["best_cost"]) if wf and c["feasible"] == "True" else float("nan")
        wall_ratio = float(w["realize_wall_s"]) / float(c["realize_wall_s"])
        feasible += wf
        close += cost_ratio <= 1.05
        fast += wf and wall_ratio <= 0.25  # an infeasible warm run is not a fast one
        print(f"| {world} | {c['best_cost']}, {float(c['realize_wall_s']):.0f} | {w['best_cost']}, "
              f"{float(w['realize_wall_s']):.0f} | {float(w['success_iter0']):.0%} | {cost_ratio:.3f} | {wall_ratio:.2f} |")
    print(f"\nworlds: {n}; warm feasible {feasible}/{n}; warm cost within 5 % of cold {close}/{n}; "
          f"warm wall <= 25 % of cold {fast}/{n}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--source", type=Path, help="a seed-paper run directory (made if it has no result.json)")
    ap.add_argument("--out", type=Path, help="CSV to append rows to; run directories go beside it")
    ap.add_argument("--worlds", default="", help="comma-separated indices into the world list (default: all)")
    ap.add_argument("--resume", action="store_true", help="skip (world, mode) rows the CSV already has")
    ap.add_argument("--summary", type=Path, help="only print the table of this CSV")
    a = ap.parse_args()
    if a.summary is not None:
        summary(a.summary)
        return
    if a.source is None or a.out is None:
        ap.error("--source and --out are needed (or --summary CSV)")
    names = list(WORLDS)
    if a.worlds:
        names = [names[int(i)] for i in a.worlds.split(",")]
    if not (a.source / "result.json").is_file():
        wall, _ = realize(COLD + ["seed=0"], a.source)
        print(f"source run {a.source}: {wall:.0f} s", flush=True)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    done = set()
    if a.resume and a.out.is_file():
        done = {(r["world"], r["mode"]) for r in csv.DictReader(a.out.open())}
    new_file = not a.out.is_file()
    fields = FIELDS if new_file else (next(csv.reader(a.out.open()), None) or FIELDS)  # an older CSV's header
    with a.out.open("a", newline="") as f:
        w = csv.DictWriter(f, fields, extrasaction="ignore")
        if new_file:
            w.writeheader()
        # every warm run first: they are short, and say early whether the warm start works
        for mode, args in (("warm", WARM + [f"warm_start={a.source.resolve()}"]), ("cold", COLD)):
            for world in names:
                if (world, mode) in done:
                    continue
                run_dir = a.out.parent / f"world{WORLDS_INDEX[world]}_{mode}"
                wall, doc = realize(args + WORLDS[world], run_dir)
                r = row(world, mode, wall, doc, run_dir)
                w.writerow(r)
                f.flush()
                print(f"{world} / {mode}: cost {r['best_cost']}, feasible {r['feasible']}, "
                      f"iter-0 success {r['success_iter0']}, {r['realize_wall_s']} s", flush=True)
    summary(a.out)


WORLDS_INDEX = {name: i for i, name in enumerate(WORLDS)}

if __name__ == "__main__":
    main()
