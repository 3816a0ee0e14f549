"""A stand-in for ``python -m realize`` in the figure-launcher tests: it parses the same
``key=value`` overrides (``experiment``, ``seed``, ``hydra.run.dir``, ``ce.iterations``) and
writes a ``result.json`` with made-up per-iteration series instead of simulating (numpy only,
so it starts fast). Not a test module."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str]) -> int:
    kv = dict(a.split("=", 1) for a in argv if "=" in a)
    if kv.get("experiment") == "broken":
        print("error: experiment=broken is not a preset", file=sys.stderr)
        return 2
    seed, n_it = int(kv.get("seed", 0)), int(kv.get("ce.iterations", 3))
    rng = np.random.default_rng(seed)
    share = np.minimum(1.0, 0.1 * np.exp(np.arange(n_it)) * rng.uniform(0.5, 1.5))
    cost = np.minimum.accumulate(100.0 - 5.0 * np.arange(n_it) + rng.normal(0, 2, n_it))
    run_dir = Path(kv["hydra.run.dir"].strip("'"))
    run_dir.mkdir(parents=True, exist_ok=True)
    doc = {"status": "done", "seed": seed, "argv": argv, "success_per_iter": share.tolist(),
           "best_cost_per_iter": cost.tolist()}
    (run_dir / "result.json").write_text(json.dumps(doc))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
