"""Long plans (issue 57): search time against plan length, the towers against tower3, one sitting.

For each seed, runs every preset of ``--presets`` one after another in child processes (``python
-m realize experiment=E seed=S ...``, each with its validation stage), so that the presets of one
seed are measured back to back and drift of a noisy machine hits them alike. The presets
(``PRESETS``) are the seed task, ``robot=panda experiment=tower3``, ``tower4``, ``tower5`` and
``rearrange3``, each searched as its preset says (``plain``: the towers whole, the seed task by
its default stitched search) and, with ``--chain``, also as a chain of segments cut after each
place (``chain``: ``levers=stitched stitch.cut=after_each_place stitch.credit=3``). Per run it appends a CSV row to
``--out`` as soon as the run ends: ``scripts/bench_levers.py``'s columns, plus ``actions`` (the
returned plan's length), ``segment_s`` (a stitched run's seconds per segment, ``name:s`` and
``;``-separated),
``validation_s``, ``load`` (the host's 1-minute load average when the run started: a run beside
other jobs reads high) and ``copy_steps``: the control steps the scene's copies were stepped,
summed over the batches (a batch steps all its copies until its longest plan ends). On one
host, wall time is mostly ``copy_steps`` times a cost per copy-step, plus a part per control step
that does not grow with the batch (tower4's chain, 2-core Xeon under load: about 30 ms per step
and 1.2 ms per copy-step); ``--summary`` prints both ratios, the copy steps being the load-free
measure of the search's work where the host is shared.

Then it prints, per preset, the seeds' search time, its ratio to ``tower3``'s of the same
seed searched the plain way (the issue's bounds: tower4 <= 1.6, tower5 <= 2.2) and the returned plan's validated share
(>= 0.90); and a table of search time against plan length, with the least-squares line through
the presets' mean times, the same for the copy steps (below), and whether they grow in
proportion to the plan: time per action within 25 % across presets.

What it doesn't: run presets in parallel (timings would interfere) or compare rows of two hosts.

    python scripts/bench_long_plans.py --seeds 0-2 --out long.csv
    python scripts/bench_long_plans.py --seeds 0 --presets tower3,tower4 --chain --out long.csv
    python scripts/bench_long_plans.py --seeds 0 --presets tower4 --only-chain --out long.csv  # add the chain
    python scripts/bench_long_plans.py --summary long.csv
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import os
import re
import shutil
import statistics
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))
from bench_levers import FIELDS as LEVER_FIELDS  # noqa: E402  (the same run and columns)
from bench_levers import run_one  # noqa: E402
from bench_seed_paper import commit_of, parse_seeds  # noqa: E402

PRESETS = {
    "seed_paper": ["experiment=seed_paper"],
    "tower3": ["robot=panda", "experiment=tower3"],
    "tower4": ["experiment=tower4"],
    "tower5": ["experiment=tower5"],
    "rearrange3": ["experiment=rearrange3"],
}
CHAIN = ["levers=stitched", "stitch.cut=after_each_place", "stitch.credit=3"]
RATIO_BOUND = {"tower4": 1.6, "tower5": 2.2}
MIN_VALIDATED = 0.90
MAX_NAME = 120  # characters of a kept run directory's name (run_dir_name)
FIELDS = ["preset", "variant", "actions", "segment_s", "validation_s", "load", "copy_steps",
          *(f for f in LEVER_FIELDS if f not in ("experiment", "variant"))]


def copy_steps(run_dir: Path) -> int:
    """Control steps of every copy of every batch of the run in ``run_dir``: each batch's copies
    times its longest plan, over every history file (a stitched run has one per segment). A
    robust search's row is a sample realized in R worlds (``world_cost_i`` (N, R)): R copies."""
    total = 0
    for path in sorted(run_dir.glob("history*.npz")):
        with np.load(path) as h:
            for k in h.files:
                if k.startswith("steps_"):
                    worlds = f"world_cost_{k[len('steps_'):]}"
                    copies = int(h[k].size) * (int(h[worlds].shape[1]) if worlds in h.files else 1)
                    total += copies * int(h[k].max(initial=0))
    return total


def variant_label(name: str, extra: list[str]) -> str:
    """The ``variant`` column of a row: the search's name, with the ``--extra`` overrides after it
    (``plain[controller.place_lift=true]``), so that runs of one preset with other options keep
    their own rows and each is compared with its own tower3."""
    return f"{name}[{' '.join(extra)}]" if extra else name


def run_dir_name(preset: str, variant: str, seed: int) -> str:
    """A row's kept run directory (the variant's overrides made a file name). A name longer than
    ``MAX_NAME`` (a file system refuses past 255 bytes; six region overrides reach it) keeps its
    head and ends in a digest of the whole, so two variants never share a directory."""
    name = re.sub(r"[^\w.-]+", "_", f"{preset}-{variant}-s{seed}")  # (it goes into a Hydra override)
    if len(name) <= MAX_NAME:
        return name
    digest = hashlib.sha1(name.encode()).hexdigest()[:12]
    return f"{name[:MAX_NAME - 20]}-{digest}-s{seed}"


def measure(preset: str, overrides: list[str], seed: int, run_dir: Path) -> dict[str, object]:
    """One run of ``preset`` (its overrides) at ``seed`` in ``run_dir``: bench_levers' row plus
    the plan's length, the segments' seconds and the validation's."""
    load = os.getloadavg()[0]
    experiment = next(o.split("=", 1)[1] for o in overrides if o.startswith("experiment="))
    rest = [o for o in overrides if not o.startswith("experiment=")]
    row = run_one(experiment, seed, rest, run_dir)
    doc = json.loads((run_dir / "result.json").read_text())
    plan = doc.get("plan") or ""
    seg = (doc.get("stitched") or {}).get("segment_s") or {}  # segment name -> seconds
    return {**row, "actions": plan.count("(") if plan else "",
            "segment_s": ";".join(f"{name}:{float(t):.1f}" for name, t in seg.items()),
            "validation_s": round(float((doc.get("validation") or {}).get("wall_time_s") or 0.0), 1),
            "load": round(load, 2), "copy_steps": copy_steps(run_dir)}


def read(path: Path) -> list[dict[str, str]]:
    with open(path) as f:
        return list(csv.DictReader(f))


def _mean(xs: list[float]) -> float:
    return statistics.fmean(xs) if xs else float("nan")


def _line(points: list[tuple[float, float, str]], unit: str, what: str) -> None:
    """The least-squares line through (plan length, value) points and each point's distance from it."""
    if len(points) < 3:
        print(f"  {what} against plan length: needs three presets or more")
        return
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    slope, icpt = statistics.linear_regression(xs, ys)
    print(f"  {what} against plan length: {slope:.4g} {unit} per action + {icpt:.4g} {unit}")
    for x, y, name in points:
        fit = slope * x + icpt
        off = (y - fit) / fit if fit > 0 else float("inf")
        print(f"    {name:>11}: {x:.0f} actions, {y:.4g} {unit} ({y / x:.4g} per action), line {fit:.4g} ({off:+.0%})")
    per = [y / x for x, y, _ in points]
    print(f"  in proportion to plan length (the most per action within 25 % of the least): "
          f"{'yes' if max(per) <= 1.25 * min(per) else 'no'} ({max(per) / min(per):.2f}x)")


def report(rows: list[dict[str, str]]) -> bool:
    """Print the ratios and the time-vs-length table; True when every bound holds."""
    ok_all = True
    mark = lambda ok: "ok" if ok else "NO"  # noqa: E731
    by = {(r["preset"], r["variant"], int(r["seed"])): r for r in rows}
    for variant in sorted({r["variant"] for r in rows}):
        print(f"== {variant}")
        means: list[tuple[float, float, str]] = []
        for preset in PRESETS:
            mine = sorted((k[2], r) for k, r in by.items() if k[:2] == (preset, variant))
            if not mine:
                continue
            times = [float(r["search_s"]) for _, r in mine]
            vals = [float(r["validated"] or "nan") for _, r in mine]
            ratios, work = [], []
            for seed, r in mine:
                ref = by.get(("tower3", "plain", seed))  # tower3 as it is searched today
                if ref is not None and preset != "tower3":
                    ratios.append(float(r["search_s"]) / float(ref["search_s"]))
                    if r.get("copy_steps") and ref.get("copy_steps"):
                        work.append(float(r["copy_steps"]) / float(ref["copy_steps"]))
            bound = RATIO_BOUND.get(preset)
            line = (f"{preset:>11}: {int(mine[0][1]['actions'] or 0):2d} actions, seeds {[s for s, _ in mine]}, "
                    f"search {', '.join(f'{t:.0f}' for t in times)} s (mean {_mean(times):.0f}), "
                    f"validated {', '.join(f'{v:.2f}' for v in vals)}")
            if ratios:
                line += f", x tower3 {', '.join(f'{q:.2f}' for q in ratios)}"
            if work:
                line += f" (copy steps x tower3 {', '.join(f'{q:.2f}' for q in work)})"
            if bound is not None and ratios:
                ok = all(q <= bound for q in ratios)
                ok_all &= ok
                line += f" [{mark(ok)} <= {bound}]"
            if preset != "seed_paper":
                ok = all(v >= MIN_VALIDATED for v in vals)
                ok_all &= ok
                line += f" [{mark(ok)} validated >= {MIN_VALIDATED}]"
            print(line)
            means.append((float(mine[0][1]["actions"] or 0), _mean(times), preset))
        _line(means, "s", "search time")
        steps = [(x, _mean([float(r["copy_steps"]) for k, r in by.items() if k[:2] == (name, variant)
                            and r.get("copy_steps")]), name) for x, _, name in means]
        _line([m for m in steps if math.isfinite(m[1])], "copy steps", "work (copy steps)")
    return ok_all


def main() -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--presets", default=",".join(PRESETS), help=f"comma-separated, of {', '.join(PRESETS)}")
    ap.add_argument("--seeds", default="0", help="e.g. 0-2 or 0,3")
    ap.add_argument("--chain", action="store_true", help="also search each preset as a chain cut after each place")
    ap.add_argument("--only-chain", action="store_true", help="search each preset as a chain only (no plain run)")
    ap.add_argument("--extra", default="", help="comma-separated overrides added to every run")
    ap.add_argument("--keep", type=Path, help="keep each run's directory under this folder (--summary: read "
                    "copy_steps missing from the CSV from there)")
    ap.add_argument("--out", type=Path, help="CSV to append rows to")
    ap.add_argument("--summary", type=Path, help="only print the tables of this CSV")
    args = ap.parse_args()
    if args.summary:
        rows = read(args.summary)
        for r in rows:  # rows written before the column: read it from the kept run directory
            d = (args.keep or Path()) / run_dir_name(r["preset"], r["variant"], int(r["seed"]))
            if not r.get("copy_steps") and args.keep and d.is_dir():
                r["copy_steps"] = str(copy_steps(d))
        sys.exit(0 if report(rows) else 1)
    if args.out is None:
        ap.error("--out is required unless --summary is given")
    presets = [p for p in args.presets.split(",") if p]
    for p in presets:
        if p not in PRESETS:
            ap.error(f"--presets: unknown preset {p!r} (known: {', '.join(PRESETS)})")
    extra = [o for o in args.extra.split(",") if o]
    variants = ({} if args.only_chain else {"plain": []}) | ({"chain": CHAIN} if args.chain or args.only_chain else {})
    keep = args.keep or Path(os.environ.get("TMPDIR", "/tmp")) / "bench_long_plans"
    new_file = not args.out.exists() or args.out.stat().st_size == 0
    with open(args.out, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS, extrasaction="ignore")
        if new_file:
            w.writeheader()
        for seed in parse_seeds(args.seeds):
            for preset in presets:
                for name, ov in variants.items():
                    overrides = [*PRESETS[preset], *ov, *extra]
                    variant = variant_label(name, extra)
                    run_dir = keep / run_dir_name(preset, variant, seed)
                    shutil.rmtree(run_dir, ignore_errors=True)  # a run dir with a checkpoint would resume
                    row = measure(preset, overrides, seed, run_dir)
                    row = {"preset": preset, "variant": variant, "seed": seed,
                           "overrides": " ".join(overrides), **row, "commit": commit_of(REPO)}
                    w.writerow(row)
                    f.flush()
                    print(", ".join(f"{k}={row[k]}" for k in FIELDS if k in row), flush=True)
    sys.exit(0 if report(read(args.out)) else 1)


if __name__ == "__main__":
    main()
