"""The PhysX GPU backend realizes the seed task's plans as the CPU backend does (CUDA only).

Run by ``make gpu-check`` (``pytest -m gpu``); skipped where there is no CUDA GPU.
"""

from __future__ import annotations

import pytest
import torch

from realize.workers.realizers import open_realization
from realize.spec.run_spec import build_run_spec

from helpers import FAR_SIDE, GOOD, SEED_TASK, SIDE, compose_config

pytestmark = [pytest.mark.gpu,
              pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU (PhysX GPU backend)")]


def test_gpu_rollout_realizes_the_good_plans_and_not_the_far_side() -> None:  # pragma: no cover - GPU only
    cfg = compose_config(f"task_file={SEED_TASK}")
    cfg["device"] = "cuda"
    spec = build_run_spec(cfg)
    Z = torch.tensor([GOOD, SIDE, FAR_SIDE, GOOD], dtype=torch.float64)
    scene, (realizer,) = open_realization(spec, n_envs=4)
    with scene:
        assert scene.backend == "gpu" and scene.device.type == "cuda"
        res = realizer.rollout(Z)
    # a physical fact on any backend: the good plans carry the cube to table 2, the far-side
    # grasp from in front of table 1 cannot
    assert res.feasible.tolist() == [True, True, False, True]
    assert res.cost[0] == res.cost[3]  # identical copies, identical outcome
    assert torch.isfinite(res.cost).all()
