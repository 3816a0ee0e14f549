"""The robustness table of docs/validation.md ("Plans that survive perturbations"): each preset's
run with its default settings, then its plans under the task's perturbations.

Usage: python scripts/robustness_table.py [--presets seed_paper ramp wall move_and_push]
            [--seeds 0] [--replicas 64] [--out runs/robustness] [--reuse] [-- OVERRIDES...]

For each preset and seed: `python -m realize experiment=PRESET seed=S OVERRIDES` into
OUT/PRESET_sS (its validation stage picks the plan to return from its 5 best under 64 perturbed
worlds, drawn with the run's seed S), then `scripts/validate.py` on the same run: the search's
nominal best (`--nominal`) in those worlds ("before"), and both plans in 64 other worlds (drawn
with seed S + 1, "held out": worlds no choice was made in). Prints one markdown row per run;
`--reuse` keeps finished runs. A seed-paper run takes 3-4 min on 2 cores, a ramp run 3-5 min.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _json(out: str) -> dict:
    return json.loads(out[out.index("{"):])  # the simulator may print a warning line first


def _validate(run: Path, replicas: int, seed: int, nominal: bool) -> dict:
    cmd = [sys.executable, str(REPO / "scripts" / "validate.py"), str(run), "--replicas", str(replicas), "--seed",
           str(seed), "--dry-run", "--json"] + (["--nominal"] if nominal else [])
    print(f"robustness_table: {' '.join(cmd[1:])}", file=sys.stderr, flush=True)
    p = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(f"robustness_table: {' '.join(cmd)} failed:\n{p.stderr[-2000:]}")
    return _json(p.stdout)


def _share(r: dict) -> str:
    return f"{round(r['success_share'] * r['replicas'])}/{r['replicas']}"


def row(preset: str, seed: int, out: Path, replicas: int, overrides: list[str], reuse: bool) -> str:
    run = out / f"{preset}_s{seed}"
    result = run / "result.json"
    if not (reuse and result.is_file() and json.loads(result.read_text()).get("status") == "done"):
        cmd = [sys.executable, "-m", "realize", f"experiment={preset}", f"seed={seed}", "logging.progress=false",
               *overrides, f"hydra.run.dir={run}"]
        p = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
        if p.returncode != 0:
            raise SystemExit(f"robustness_table: {' '.join(cmd)} failed:\n{p.stderr[-2000:]}")
    d = json.loads(result.read_text())
    v = d.get("validation")
    before = _validate(run, replicas, seed, nominal=True)  # the worlds the run chose in
    held_nominal = _validate(run, replicas, seed + 1, nominal=True)
    if not v:
        return (f"| {preset} | {seed} | {d['best_cost']:.0f} | {_share(before)} | {_share(held_nominal)} | - | - | - | - "
                f"| {d['wall_time_s']:.0f} s |")
    c = v["candidates"][v["returned"]]
    held = _validate(run, replicas, seed + 1, nominal=False)
    lo, hi = c["ci95"]
    return (f"| {preset} | {seed} | {d['best_cost']:.0f} | {_share(before)} | {_share(held_nominal)} | {c['cost']:.0f} "
            f"| {round(c['success_share'] * v['replicas'])}/{v['replicas']} [{lo:.2f}, {hi:.2f}] | {_share(held)} "
            f"| {v['wall_time_s']:.0f} s | {d['wall_time_s']:.0f} s |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--presets", nargs="+", default=["seed_paper", "ramp", "wall", "move_and_push"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0])
    ap.add_argument("--replicas", type=int, default=64, help="worlds per check (default 64)")
    ap.add_argument("--out", type=Path, default=REPO / "runs" / "robustness")
    ap.add_argument("--reuse", action="store_true", help="keep runs that finished")
    ap.add_argument("overrides", nargs="*", help="realize overrides for every run (after --)")
    args = ap.parse_args(argv)
    print("| preset | seed | nominal best cost | nominal best: success | held out | returned cost | returned: "
          "success [95 %] | held out | validation | run |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for preset in args.presets:
        for seed in args.seeds:
            print(row(preset, seed, args.out, args.replicas, args.overrides, args.reuse), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
