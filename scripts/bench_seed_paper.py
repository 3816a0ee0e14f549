"""Seed-paper runs over several seeds: wall time, peak memory and fidelity, one CSV row per seed.

Runs ``python -m realize experiment=seed_paper seed=S validation=off`` (the search, without the
validation stage) for each seed, one at a time, in a child
process (so wall time includes start-up, as a user sees it), and appends a row to ``--out`` as
soon as a run ends: seed, wall_s, peak_rss_mb (the child's maximum resident set), feasible,
success_iter0, success_last, best_cost, best_cost_iter0, commit, note, stopped_last. The success
columns are the share of the rows that ran to their end that ended feasible
(``finished_success_per_iter``): with ``ce.prune`` the rows stopped as "could not be an elite"
are left out (``stopped_last``: how many in the last iteration), where ``success_per_iter`` would
count them as failed; without pruning (every reference row) the two are the same share. A CSV
written before ``stopped_last`` keeps its columns. With ``--reference CSV`` it
prints, for the seeds both files hold, the wall-time ratio and the fidelity checks of the
throughput issue (feasible in every run, iteration-0 success 3-30 %, last-iteration success
>= 85 % mean, mean best cost no more than 2 % above the reference's).

The runs take today's defaults, speed levers included (docs/results.md, "Speed levers"); the reference
rows predate them: pass ``levers=exact`` as an override to compare like with like. Today's default
(``levers=stitched``) runs batches of two segments and a confirmation, so its per-iteration
success shares (iteration 0, last) are those of a prefix batch and of the confirmation, not the
fidelity checks' CE iterations: compare those with ``levers=exact``.

What it doesn't: run seeds in parallel (timings would interfere) or judge timing across
machines: compare only rows measured on the same machine.

    python scripts/bench_seed_paper.py --seeds 0-9 --out seed_paper.csv
    python scripts/bench_seed_paper.py --seeds 0-9 --out new.csv \
        --reference scripts/bench_data/seed_paper_1fc1637.csv
    python scripts/bench_seed_paper.py --summary scripts/bench_data/seed_paper_1fc1637.csv
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from realize.run_dir.directory import RunDir  # noqa: E402

FIELDS = ["seed", "wall_s", "peak_rss_mb", "feasible", "success_iter0", "success_last",
          "best_cost", "best_cost_iter0", "commit", "note", "stopped_last"]


def parse_seeds(text: str) -> list[int]:
    seeds: list[int] = []
    for part in text.split(","):
        if "-" in part:
            lo, hi = part.split("-")
            seeds.extend(range(int(lo), int(hi) + 1))
        else:
            seeds.append(int(part))
    return seeds


def commit_of(code: Path) -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=code, capture_output=True,
                             text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=code,
                               capture_output=True, text=True).stdout.strip()
        return out + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def run_seed(seed: int, code: Path, run_dir: Path, extra: list[str]) -> dict[str, object]:
    # the search only, as the reference rows measured it (they predate the validation stage a run
    # now ends with); a checkout from before the validation group has none to turn off
    quiet = ["validation=off"] if (code / "configs" / "validation" / "off.yaml").is_file() else []
    cmd = [sys.executable, "-m", "realize", "experiment=seed_paper", f"seed={seed}",
           f"hydra.run.dir={run_dir}", "logging.progress=false", *quiet, *extra]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=code, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read() if proc.stderr else ""
    if proc.returncode != 0:
        raise SystemExit(f"seed {seed}: realize exited {proc.returncode}:\n{err[-2000:]}")
    rd = RunDir(run_dir)
    doc = rd.result()
    success = rd.finished_success_per_iter()  # of the rows that finished: ce.prune's stopped rows left out
    stopped = rd.n_stopped_per_iter()
    per_iter = rd.best_cost_per_iter()
    return {"seed": seed, "wall_s": round(wall, 1), "peak_rss_mb": round(usage.ru_maxrss / 1024.0),
            "feasible": int(bool(doc.feasible)), "success_iter0": round(float(success[0]), 4),
            "success_last": round(float(success[-1]), 4), "best_cost": doc.best_cost,
            "best_cost_iter0": float(per_iter[0]), "commit": commit_of(code), "note": "",
            "stopped_last": "" if stopped is None or not len(stopped) else int(stopped[-1])}


def read_rows(path: Path) -> dict[int, dict[str, float]]:
    """Numeric columns per seed; text columns (commit, note) and empty cells are left out."""
    rows: dict[int, dict[str, float]] = {}
    with open(path) as f:
        for r in csv.DictReader(f):
            vals: dict[str, float] = {}
            for k, v in r.items():
                try:
                    vals[k] = float(v)
                except (TypeError, ValueError):
                    continue
            rows[int(r["seed"])] = vals
    return rows


def summary(rows: dict[int, dict[str, float]], name: str) -> None:
    n = len(rows)
    if not n:
        print(f"{name}: no rows")
        return
    col = lambda k: [r[k] for r in rows.values()]  # noqa: E731
    mean = lambda xs: sum(xs) / len(xs)  # noqa: E731
    rss = [r["peak_rss_mb"] for r in rows.values() if "peak_rss_mb" in r]
    print(f"{name}: {n} seeds, wall {mean(col('wall_s')):.1f} s mean ({min(col('wall_s')):.1f}-"
          f"{max(col('wall_s')):.1f}), peak rss {max(rss) if rss else float('nan'):.0f} MB, feasible "
          f"{int(sum(col('feasible')))}/{n}, success of the rows that finished iter0 "
          f"{min(col('success_iter0')):.3f}-{max(col('success_iter0')):.3f}, last {mean(col('success_last')):.3f} "
          f"mean{stopped_text(rows)}, best cost {mean(col('best_cost')):.1f} mean")


def stopped_text(rows: dict[int, dict[str, float]]) -> str:
    """', stopped last iter M mean' where the rows say (runs with ce.prune); else nothing."""
    stopped = [r["stopped_last"] for r in rows.values() if "stopped_last" in r]
    return f" (stopped in the last iteration: {sum(stopped) / len(stopped):.1f} mean)" if stopped else ""


def compare(new: dict[int, dict[str, float]], ref: dict[int, dict[str, float]]) -> bool:
    seeds = sorted(set(new) & set(ref))
    if not seeds:
        print("no seeds in common with the reference")
        return False
    mean = lambda xs: sum(xs) / len(xs)  # noqa: E731
    wall_ratio = mean([new[s]["wall_s"] for s in seeds]) / mean([ref[s]["wall_s"] for s in seeds])
    cost_ratio = mean([new[s]["best_cost"] for s in seeds]) / mean([ref[s]["best_cost"] for s in seeds])
    checks = {
        "feasible in every run": all(new[s]["feasible"] == 1 for s in seeds),
        "iteration-0 success 3-30 %": all(0.03 <= new[s]["success_iter0"] <= 0.30 for s in seeds),
        "last-iteration success >= 85 % mean": mean([new[s]["success_last"] for s in seeds]) >= 0.85,
        "mean best cost <= 1.02 x reference": cost_ratio <= 1.02,
        "wall <= 120 s every run": all(new[s]["wall_s"] <= 120.0 for s in seeds),
    }
    print(f"seeds compared: {seeds}")
    for k, ok in checks.items():
        print(f"  {'ok ' if ok else 'NO '} {k}")
    print(f"best_cost_ratio_vs_reference: {cost_ratio:.4f}")
    print(f"wall_ratio_vs_reference: {wall_ratio:.3f}")
    return all(checks.values())


def main() -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--seeds", default="0-9", help="e.g. 0-9 or 0,3,5")
    ap.add_argument("--out", type=Path, help="CSV to append rows to (seeds already in it are skipped)")
    ap.add_argument("--code", type=Path, default=REPO, help="checkout whose realize to run (default: this one)")
    ap.add_argument("--reference", type=Path, help="reference CSV to compare with")
    ap.add_argument("--summary", type=Path, help="only print the summary of this CSV")
    ap.add_argument("--note", default="", help="text for the note column (e.g. what else ran)")
    ap.add_argument("overrides", nargs="*", help="extra realize overrides")
    args = ap.parse_args()
    if args.summary:
        summary(read_rows(args.summary), str(args.summary))
        return
    if args.out is None:
        ap.error("--out is required unless --summary is given")
    done = read_rows(args.out) if args.out.exists() else {}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    new_file = not args.out.exists() or args.out.stat().st_size == 0
    fields = FIELDS
    if not new_file:  # an older CSV keeps its header (no stopped_last column)
        with open(args.out, newline="") as f:
            fields = next(csv.reader(f), None) or FIELDS
    with open(args.out, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
        if new_file:
            w.writeheader()
        for seed in parse_seeds(args.seeds):
            if seed in done:
                continue
            with tempfile.TemporaryDirectory(prefix=f"seed{seed}-") as tmp:
                row = run_seed(seed, args.code.resolve(), Path(tmp) / "run", args.overrides)
            row["note"] = args.note
            w.writerow(row)
            f.flush()
            print(", ".join(f"{k}={v}" for k, v in row.items()), flush=True)
    rows = read_rows(args.out)
    summary(rows, str(args.out))
    if args.reference:
        compare(rows, read_rows(args.reference))


if __name__ == "__main__":
    main()
