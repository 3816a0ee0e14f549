"""Interleaved A/B of the physics step under several ``sim`` settings, on a real rollout's commands.

What it does: rolls out one batch of plans (``--history H.npz --key Z_005``: a saved CE
iteration's samples, ``--late``: ``scripts/bench_rollout.py``'s committed late-iteration batch,
or ``--uniform``: the task's iteration-0 distribution) in a scene with the
app's default settings, recording the drive targets of its first ``--steps`` control steps;
then builds one scene per setting (each argument: comma-separated Hydra overrides, e.g.
``sim.lean_robot=true`` or ``sim.lean_robot=true,sim.solver_position_iterations_robot=4``; an
empty string is the baseline) and replays the recorded targets open-loop in all of them, step by
step interleaved, timing the PhysX step and the target writes. Interleaving makes the ratios
robust to load from other processes. Prints ms per control step and the ratio to the first
setting.
What it doesn't: score plans (open-loop replay diverges from a closed-loop rollout once the
settings differ; use ``scripts/uniform_success.py`` with the same overrides for fidelity).

Usage::

    python scripts/bench_physics.py --history outputs/.../history.npz --key Z_005 "" sim.lean_robot=true
"""

from __future__ import annotations

import argparse
import gc
import sys
import time
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))

from realize.workers.realizers import open_realization  # noqa: E402
from realize.scene import BatchedScene  # noqa: E402
from uniform_success import load_spec  # noqa: E402


class _Enough(Exception):
    pass


def main() -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--history", help="a run's history.npz")
    ap.add_argument("--key", default="Z_005", help="the samples' key in --history")
    ap.add_argument("--uniform", action="store_true", help="uniform samples instead of --history")
    ap.add_argument("--late", action="store_true", help="bench_rollout.py's late-iteration batch (bench_data/late_batch.json)")
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--steps", type=int, default=260, help="control steps recorded and replayed")
    ap.add_argument("--task-file", default="configs/task/pick_place.yaml")
    ap.add_argument("settings", nargs="+", help="comma-separated overrides per setting ('' = baseline)")
    a = ap.parse_args()
    spec = load_spec(a.task_file, 0, "cpu", ["experiment=seed_paper"])
    if a.late:
        from bench_rollout import load_batch
        Z = load_batch()[1][: a.n].to(spec.placement.dtype)
    elif a.uniform or not a.history:
        g = torch.Generator()
        g.manual_seed(0)
        Z = spec.task.layout.sample_uniform(a.n, g, spec.placement.dtype)
    else:
        Z = torch.from_numpy(np.load(a.history)[a.key][: a.n]).to(spec.placement.dtype)
    scene, (realizer,) = open_realization(spec, n_envs=len(Z))
    rec: list[tuple[torch.Tensor, ...]] = []
    write = scene._apply_targets

    def recording() -> None:
        if len(rec) > a.steps:
            raise _Enough
        rec.append((scene._base_cmd.clone(), scene._arm_target.clone(), scene._arm_vel_target.clone(),
                    scene._grip_target.clone(), scene._frozen.clone()))
        write()

    scene._apply_targets = recording
    try:
        realizer.rollout(Z)
    except _Enough:
        pass
    scene.close()
    del scene, realizer
    gc.collect()
    rec = rec[1:]  # the first write is the reset's
    scenes = []
    for s in a.settings:
        sp = load_spec(a.task_file, 0, "cpu", ["experiment=seed_paper", *[o for o in s.split(",") if o]])
        sc = BatchedScene.from_spec(sp, len(Z))
        sc.reset(seed=0)
        scenes.append(sc)
    phys = np.zeros((len(scenes), len(rec)))
    total = np.zeros_like(phys)
    for k, (base, arm, arm_v, grip, frozen) in enumerate(rec):
        for i, sc in enumerate(scenes):
            t0 = time.perf_counter()
            new = frozen & ~sc._frozen
            if bool(new.any()):
                sc._frozen |= new
                sc._impl.freeze(torch.nonzero(new).flatten().tolist())
            sc._impl.apply_targets(base, arm, arm_v, grip, sc._frozen)
            t1 = time.perf_counter()
            sc._impl.step(sc.substeps)
            phys[i, k] = time.perf_counter() - t1
            total[i, k] = time.perf_counter() - t0
    print(f"N={len(Z)}, {len(rec)} control steps replayed, settings interleaved step by step")
    for i, s in enumerate(a.settings):
        print(f"{s or 'baseline':60s} physics {1e3 * phys[i].mean():7.2f} ms/step (median {1e3 * np.median(phys[i]):7.2f}) "
              f"ratio {phys[i].sum() / phys[0].sum():.3f}  writes+physics {1e3 * total[i].mean():7.2f} ms/step "
              f"ratio {total[i].sum() / total[0].sum():.3f}")
    for sc in scenes:
        sc.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
