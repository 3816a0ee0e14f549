"""Fault isolation: a plan whose simulation goes bad (NaN joint targets) is failed with a
reason and stops being simulated; the other plans of the batch are unaffected bit for bit,
although on CPU all copies share one PhysX scene."""

from __future__ import annotations

import math

import pytest
import torch

from realize.realization.context import StepContext
from realize.workers.realizers import open_realization
from realize.spec.run_spec import build_run_spec
from helpers import GOOD, SEED_TASK, blas_batch_invariant, compose_config

N, BAD = 4, 3


def test_nan_targets_in_one_plan_leave_the_other_plans_unchanged(monkeypatch: pytest.MonkeyPatch) -> None:
    torch.set_num_threads(1)
    spec = build_run_spec(compose_config(f"task_file={SEED_TASK}"))
    Z = spec.task.layout.sample_uniform(N, torch.Generator().manual_seed(11), dtype=torch.float64)
    Z[0] = torch.tensor(GOOD, dtype=torch.float64)
    Z[BAD] = torch.tensor(GOOD, dtype=torch.float64)  # a plan that succeeds without the fault
    scene, (realizer,) = open_realization(spec, n_envs=N)
    with scene:
        clean = realizer.rollout(Z, record=True)

        original = StepContext.run_fabric
        calls = {"n": 0}

        def poisoned(self: StepContext) -> None:
            original(self)
            calls["n"] += 1
            if calls["n"] == 20:  # during the grasp: NaN targets for one plan only
                self.arm_cmd[BAD] = math.nan
                self.base_cmd[BAD] = math.nan

        monkeypatch.setattr(StepContext, "run_fabric", poisoned)
        faulty = realizer.rollout(Z, record=True)

    assert bool(clean.feasible[BAD]) and not bool(faulty.feasible[BAD])
    assert faulty.failure[BAD].split(":")[-1] in ("diverged", "controller_invalid"), faulty.failure[BAD]
    others = [i for i in range(N) if i != BAD]
    assert [clean.failure[i] for i in others] == [faulty.failure[i] for i in others]
    for name in ("feasible", "action_success"):
        assert torch.equal(getattr(clean, name)[others], getattr(faulty, name)[others]), name
    for name in ("traj_base", "traj_ee", "traj_objects"):  # nothing of the NaN leaked into another plan
        assert not getattr(faulty, name)[others].isnan().any(), name
    if blas_batch_invariant():  # bit for bit where the controllers' batched products allow it
        for name in ("cost", "steps", "traj_base", "traj_ee", "traj_objects"):
            assert torch.equal(getattr(clean, name)[others], getattr(faulty, name)[others]), name
    else:  # the fabric's batch lost a row: last-bit differences, amplified by contact, not the NaN
        assert ((faulty.cost[others] - clean.cost[others]).abs() <= 0.05 * clean.cost[others]).all()
