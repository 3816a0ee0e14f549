"""Same seed, same plan: run the default search for some seeds and compare with a committed record.

The contract of a CPU run is that the same config and seed give the same numbers on every run
and host. This script checks it where a unit test cannot: the full default search
(``realize experiment=seed_paper seed=S``, validation off, since it only picks among the
search's plans) for each seed, one run at a time, compared bit for bit (``best_z``, ``best_cost``,
the best cost of every batch and, where the record has them, a digest of every batch's per-row
costs) with ``scripts/bench_data/same_seed.json``. Each line says which
seeds matched, on which host (CPU model, torch's CPU capability, the package versions).
``--record`` writes the record instead (only when a change is meant to move the search's
numbers; say so in the commit). Exit 1 when a seed differs.

What it doesn't: time anything (``scripts/bench_levers.py`` does), or hide a difference:
a mismatch prints both sides.

    python scripts/check_same_seed.py --seeds 0-4
    python scripts/check_same_seed.py --seeds 0-4 --record
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))
from bench_seed_paper import commit_of, parse_seeds  # noqa: E402  (the same seed list and commit stamp)
from realize.run_dir.history import batch_digests  # noqa: E402

RECORD = REPO / "scripts" / "bench_data" / "same_seed.json"
OVERRIDES = ["experiment=seed_paper", "validation=off", "logging.progress=false", "logging.rerun=false"]
KEYS = ("best_cost", "best_z", "best_cost_per_iter", "feasible")


def cpuinfo(field: str) -> str:
    """The first ``field`` line of /proc/cpuinfo ("" where there is none)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith(field):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


def host() -> dict[str, str]:
    """What a reader needs to tell two hosts apart."""
    import torch

    flags = set(cpuinfo("flags").split())
    vector = next((f for f in ("avx512f", "avx2", "sse4_2") if f in flags), "")
    return {"cpu": cpuinfo("model name") or platform.processor() or platform.machine(), "machine": platform.machine(),
            "vector_isa": vector, "torch_cpu_capability": torch.backends.cpu.get_cpu_capability()}


def run_seed(seed: int, run_dir: Path) -> dict[str, object]:
    cmd = [sys.executable, "-m", "realize", *OVERRIDES, f"seed={seed}", f"hydra.run.dir={run_dir}"]
    proc = subprocess.run(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"seed {seed}: realize exited {proc.returncode}:\n{proc.stderr[-2000:]}")
    doc = json.loads((run_dir / "result.json").read_text())
    return {"seed": seed, **{k: doc[k] for k in KEYS}, "batch_digests": batch_digests(run_dir),
            "versions": doc.get("versions", {})}


def first_parting(got: dict[str, list[str]], want: dict[str, list[str]]) -> str:
    """Where two runs' batch digests first differ, per history file ("" where they agree or one
    has none)."""
    parts = []
    for name in sorted(set(got) & set(want)):
        first = next((i for i, (a, b) in enumerate(zip(got[name], want[name])) if a != b), None)
        if first is not None:
            parts.append(f"{name} batch {first}")
    return ", ".join(parts)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()), epilog=__doc__.split("\n\n", 1)[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-4", help="e.g. 0-4 or 0,3 (default 0-4)")
    ap.add_argument("--record", action="store_true", help="write the record instead of comparing with it")
    ap.add_argument("--file", type=Path, default=RECORD, help="the record (default scripts/bench_data/same_seed.json)")
    args = ap.parse_args(argv)
    seeds = parse_seeds(args.seeds)
    record = json.loads(args.file.read_text()) if args.file.is_file() else None
    if not args.record and record is None:
        print(f"error: no record at {args.file} (write one with --record)", file=sys.stderr)
        return 2
    recorded = {r["seed"]: r for r in (record or {}).get("runs", [])}
    missing = [s for s in seeds if s not in recorded]
    if not args.record and missing:
        print(f"error: seeds {missing} are not in {args.file} (recorded: {sorted(recorded)})", file=sys.stderr)
        return 2
    me = host()
    print(f"host: {me['cpu']} ({me['machine']}, {me['vector_isa']}, torch CPU capability {me['torch_cpu_capability']}), "
          f"commit {commit_of(REPO)}", flush=True)
    runs, differ = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            got = run_seed(seed, Path(tmp) / f"seed{seed}")
            runs.append(got)
            if args.record:
                print(f"seed {seed}: best cost {got['best_cost']}", flush=True)
                continue
            want = recorded[seed]
            bad = [k for k in KEYS if got[k] != want[k]]
            parting = first_parting(got["batch_digests"], want.get("batch_digests") or {})
            if parting:
                bad.append(f"batch_digests (first at {parting})")
            if bad:
                differ.append(seed)
                print(f"seed {seed}: DIFFERS in {bad}: best cost {got['best_cost']} here, {want['best_cost']} "
                      f"recorded on {record['host']['cpu']}", flush=True)
                if got["versions"] != want.get("versions"):
                    print(f"  package versions differ: here {got['versions']}, recorded {want.get('versions')}")
            else:
                print(f"seed {seed}: same bits (best cost {got['best_cost']})", flush=True)
    if args.record:
        from datetime import date

        args.file.write_text(json.dumps({"date": date.today().isoformat(), "commit": commit_of(REPO), "host": me,
                                         "overrides": OVERRIDES, "runs": runs}, indent=1) + "\n")
        print(f"recorded {len(runs)} seed(s) in {args.file}")
        return 0
    print(f"{len(seeds) - len(differ)} of {len(seeds)} seeds match the record of {record['date']} "
          f"({record['commit']}, {record['host']['cpu']})")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
