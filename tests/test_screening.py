"""The kinematic screen (``ce.screen``, ``realize.realization.screening``): samples whose grasp
would put the hand's spheres under the table are drawn again before anything simulates.

Checked against independent facts: the rejected samples of a uniform seed-task batch, simulated,
all fail (a small version of ``scripts/screen_check.py``'s 1,000-sample check); a top-down grasp
is never rejected; a batch screens as its rows do. The search side, on a toy cost: rejected
draws are drawn again from their own source and recorded, not evaluated, and with the screen off
the samples are the ones drawn before the screen existed, bit for bit.
"""

from __future__ import annotations

import math

import torch

from helpers import compose_config
from realize.workers.realizers import open_realization
from realize.spec.run_spec import build_run_spec
from realize.realization.screening import HandDepthScreen
from realize.search.ce.config import CEConfig
from realize.search.ce.optimizer import CrossEntropyOptimizer
from realize.search.protocol import EvalResult
from realize.tasks.param_layout import ParamLayout
from realize.tasks.regions import Box

F64 = torch.float64


def _seed_task():
    spec = build_run_spec(compose_config("experiment=seed_paper"))
    return spec, HandDepthScreen(spec.task, spec.geometry, spec.robot, spec.rollout, spec.ce.screen_depth)


def test_rejected_samples_fail_when_simulated() -> None:
    spec, screen = _seed_task()
    g = torch.Generator()
    g.manual_seed(0)
    Z = spec.task.layout.sample_uniform(48, g, torch.float64)
    rejected = screen(Z)
    assert 4 <= int(rejected.sum()) <= 24  # about a quarter of a uniform batch
    assert torch.equal(torch.stack([screen(Z[i:i + 1])[0] for i in range(len(Z))]), rejected)
    scene, (realizer,) = open_realization(spec, n_envs=int(rejected.sum()))
    with scene:
        res = realizer.rollout(Z[rejected])
    assert not bool(res.feasible.any()), res.failure
    assert all(f.startswith("1:grasp:") for f in res.failure), res.failure  # they fail where the screen said


def test_a_top_down_grasp_passes_and_a_grazing_one_does_not() -> None:
    spec, screen = _seed_task()
    cols = spec.task.layout.slices["Cube_g"]
    centre = spec.task.layout.regions["Cube_g"].center
    Z = spec.task.layout.sample_uniform(2, torch.Generator().manual_seed(1), torch.float64)
    polar = 1.3  # the region's polar_max: the pre-pose 15 cm out, 74 degrees off vertical
    Z[0, cols] = torch.tensor([centre[0], centre[1], centre[2] + 0.15], dtype=F64)
    Z[1, cols] = torch.tensor([centre[0] - 0.15 * math.sin(polar), centre[1],
                               centre[2] + 0.15 * math.cos(polar)], dtype=F64)
    assert screen(Z).tolist() == [False, True]


def _toy(screen_on: bool, screen=None) -> CrossEntropyOptimizer:
    layout = ParamLayout({"p": Box([-1.0, -1.0], [1.0, 1.0])})
    cfg = CEConfig(n_envs=40, n_elite=5, iterations=3, seed=3, screen=screen_on)
    return CrossEntropyOptimizer(layout, cfg, screen=screen)


def _cost(Z: torch.Tensor) -> EvalResult:
    return EvalResult(cost=(Z ** 2).sum(1), feasible=torch.ones(len(Z), dtype=torch.bool))


def test_rejected_draws_are_drawn_again_and_recorded() -> None:
    right = lambda Z: Z[:, 0] > 0.5  # noqa: E731  the "certain failure" of this toy
    opt = _toy(True, right)
    for _ in range(3):
        batch = opt.ask()
        assert not bool(right(batch.Z).any())  # nothing rejected is evaluated (10 tries suffice here)
        rec = opt.tell(_cost(batch.Z))
        assert rec.n_screened == len(rec.screened_Z) and bool(right(rec.screened_Z).all())
    assert rec.n_screened is not None


def test_screen_off_draws_the_same_samples_as_before() -> None:
    """With ``ce.screen`` off (``levers=exact``) the screen is never called and the batches are
    those of an optimizer built without one; with it on and a screen that rejects nothing,
    too (the redraw path takes nothing from the generator then)."""
    plain, off, idle = _toy(False), _toy(False, lambda Z: Z[:, 0] > 2.0), _toy(True, lambda Z: Z[:, 0] > 2.0)
    for _ in range(3):
        a, b, c = plain.ask(), off.ask(), idle.ask()
        assert torch.equal(a.Z, b.Z) and torch.equal(a.Z, c.Z)
        for o, bt in ((plain, a), (off, b), (idle, c)):
            rec = o.tell(_cost(bt.Z))
        assert rec.n_screened == 0
