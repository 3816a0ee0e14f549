"""Which way did each run put the cube on table 2: carried there, or slid down the ramp?

What it does: reads every ``result.json`` under the given directories (single runs, a study
directory of seeds, or a Hydra multirun sweep), takes the best plan's release point (the
``place`` action's parameter) and classifies the run's mode from the run's own scene:

* ``slide``: the release point lies over the ramp's footprint (the cube slid onto table 2),
* ``carry``: it lies over table 2 (the robot carried the cube there),
* ``other``: anywhere else; ``none`` when the run found no feasible plan;
* the run's status (``running``, ``interrupted``, ``failed``) when it has not finished.

It prints one row per run and a summary (runs per mode, best cost mean +- std per mode), and
writes both as CSV (``--out``, default ``ramp_modes.csv`` in the first directory). A run's
success shares (iteration 0, last) are of the rows that ran to their end (``ce.prune``'s stopped
rows left out, ``stopped_last`` says how many in the last iteration), where ``success_per_iter``
counts the stopped rows as failed; a run without pruning gives ``success_per_iter``, the same share.
What it doesn't: simulate anything; a plan's mode is read from its parameters only.

Usage::

    python scripts/ramp_modes.py runs/ramp [runs/wall ...] [--out modes.csv]
"""

from __future__ import annotations

import argparse
import csv
import math
import re
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without install

from realize.world.geometry import GeometryCfg, SceneGeometry, build_geometry  # noqa: E402
from realize.run_dir.directory import RunDir  # noqa: E402
from realize.run_dir.names import RESULT_FILE  # noqa: E402
from realize.run_dir.result_doc import FailureDoc, ResultDoc  # noqa: E402

MODES = ("slide", "carry", "other", "none")
MODE_OPTIONS = ("n_modes", "uniform_share", "rank_weighted", "knn_robust")


def release_point(result: ResultDoc) -> tuple[float, float] | None:
    """(x, y) of the best plan's place parameter (a box region: the release point itself; a
    hemisphere: its centre, the place point, is fixed by the task, so the pre-pose is used)."""
    params = result.best_params or {}
    plan = result.plan or ""
    names = [args.split(",")[-1].strip() for tpl, args in re.findall(r"(\w+)\(([^)]*)\)", plan) if tpl == "place"]
    for name in names or [n for n in params if n.lower().startswith("cube_p")]:
        p = params.get(name)
        if p is not None:
            return float(p["x"]), float(p["y"])
    return None


def mode_of(result: ResultDoc | FailureDoc, geometry: SceneGeometry) -> str:
    status = result.status or "done"  # a document that does not say counts as finished
    if status != "done":  # running, interrupted or failed: not counted as a mode
        return status
    if not result.feasible or not isinstance(result, ResultDoc):
        return "none"
    xy = release_point(result)
    if xy is None:
        return "other"
    boxes = {b.name: b for b in geometry.obstacles}
    if boxes.get("table2") is not None and boxes["table2"].contains_xy(*xy):
        return "carry"
    if boxes.get("ramp") is not None and boxes["ramp"].contains_xy(*xy):
        return "slide"
    return "other"


def finished_success(r: ResultDoc) -> list[float]:
    """Per iteration, the share of the rows that finished (not stopped by ``ce.prune``) that ended
    feasible (NaN where every row was stopped); without pruning, ``success_per_iter``."""
    if r.n_stopped_per_iter is None:
        return list(r.success_per_iter)
    return [math.nan if v is None else v for v in r.finished_success_per_iter()]


def rows_from(dirs: list[Path]) -> list[dict[str, Any]]:
    rows = []
    for d in dirs:
        if not d.exists():
            raise FileNotFoundError(f"{d}: no such directory")
        for f in sorted(d.rglob(RESULT_FILE)):
            r = RunDir(f.parent).result()
            if r is None:
                raise ValueError(f"{f}: not a JSON object")
            cfg = r.config or {}
            geometry = build_geometry(GeometryCfg.from_mapping(cfg.get("scene")))
            ce = cfg.get("ce", {})
            done = isinstance(r, ResultDoc)
            success = (finished_success(r) if done else []) or [math.nan]
            stopped = (r.n_stopped_per_iter if done else None) or []
            xy = release_point(r) if done else None
            rows.append({
                "run": str(f.parent), "scene": geometry.variant, "seed": r.seed if done else None,
                "feasible": bool(r.feasible), "best_cost": r.best_cost if math.isfinite(r.best_cost) else None,
                "mode": mode_of(r, geometry), "release_x": xy[0] if xy else None,
                "release_y": xy[1] if xy else None, "success_iter0": success[0],
                "success_last": success[-1], "stopped_last": stopped[-1] if stopped else None,
                "wall_time_s": r.wall_time_s if math.isfinite(r.wall_time_s) else None,
                **{k: ce.get(k) for k in MODE_OPTIONS},
            })
    return rows


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for scene in sorted({r["scene"] for r in rows}):
        sub = [r for r in rows if r["scene"] == scene]
        for mode in sorted({r["mode"] for r in sub}, key=lambda m: (m not in MODES, MODES.index(m) if m in MODES else m)):
            costs = [float(r["best_cost"]) for r in sub if r["mode"] == mode and r["best_cost"] is not None]
            n = sum(r["mode"] == mode for r in sub)
            if not n:
                continue
            mean = sum(costs) / len(costs) if costs else math.nan
            std = math.sqrt(sum((c - mean) ** 2 for c in costs) / len(costs)) if costs else math.nan
            out.append({"scene": scene, "mode": mode, "runs": n, "of": len(sub),
                        "best_cost_mean": mean, "best_cost_std": std})
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("dirs", type=Path, nargs="+", help="run, study or multirun directories")
    ap.add_argument("--out", type=Path, default=None, help="CSV of the per-run rows (summary beside it)")
    args = ap.parse_args(argv)
    try:
        rows = rows_from(args.dirs)
    except (FileNotFoundError, ValueError, KeyError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    if not rows:
        print(f"error: no result.json under {', '.join(map(str, args.dirs))}", file=sys.stderr)
        return 1
    for r in rows:
        cost = "-" if r["best_cost"] is None else f"{r['best_cost']:.0f}"
        print(f"{r['run']:<40} {r['scene']:<6} seed {r['seed']!s:<3} {r['mode']:<6} cost {cost:>5}  "
              f"success {r['success_iter0']:.0%} -> {r['success_last']:.0%}".replace("nan%", "-")
              + ("" if r["stopped_last"] is None else f" of the rows that finished ({r['stopped_last']} stopped)"))
    summ = summary(rows)
    for s in summ:
        print(f"{s['scene']}: {s['mode']} in {s['runs']} of {s['of']} runs, best cost "
              f"{s['best_cost_mean']:.1f} +- {s['best_cost_std']:.1f}")
    out = args.out or args.dirs[0] / "ramp_modes.csv"
    out.parent.mkdir(parents=True, exist_ok=True)
    for path, table in ((out, rows), (out.with_name(out.stem + "_summary.csv"), summ)):
        with path.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(table[0]))
            w.writeheader()
            w.writerows(table)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
