"""The one place where a run's batched scene and its plan realizers are built.

What it does: ``open_realization(spec, tasks)`` builds the batched scene of ``ce.n_envs``
copies (or ``n_envs``) from the run spec's geometry and physics settings, and one
``PlanRealizer`` per task on it (a top-k run realizes every candidate plan in the same scene:
each rollout starts with a reset, history-free on CPU). The search loop, replay-like scripts
(``scripts/uniform_success.py``) and tests call it instead of wiring the classes themselves.
What it doesn't: simulate (``realize.realization``), or choose the backend (``RunSpec.placement``,
resolved at the config edge, is already in ``spec.sim``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from realize.realization.rollout import PlanRealizer
    from realize.spec.run_spec import RunSpec
    from realize.scene import BatchedScene, EnvOptions
    from realize.tasks.spec import TaskSpec
    from realize.tasks.worlds import Worlds

__all__ = ["open_realization"]


def open_realization(spec: RunSpec, tasks: Sequence[TaskSpec] | None = None, n_envs: int | None = None, *,
                     env: EnvOptions | None = None, seed: int | None = None, worlds: Worlds | None = None
                     ) -> tuple[BatchedScene, list[PlanRealizer]]:
    """``(scene, realizers)``: a scene of ``n_envs`` (default ``spec.ce.n_envs``) copies with the
    env options ``env`` (camera, reset noise; default none), copy ``k`` in the perturbed world
    ``worlds[k]`` (``realize.tasks.worlds``; default: the task's world in every copy), and one
    realizer per task (default ``[spec.task]``), seeded with ``seed`` (default ``spec.seed``).
    The caller closes the scene (it is a context manager)."""
    from realize.realization.rollout import PlanRealizer
    from realize.scene import BatchedScene

    tasks = [spec.task] if tasks is None else list(tasks)
    scene = BatchedScene.from_spec(spec, spec.ce.n_envs if n_envs is None else n_envs, env=env)
    try:
        if worlds is not None:
            scene.set_worlds(worlds)
        realizers = [PlanRealizer.from_spec(spec, t, scene, seed=seed) for t in tasks]
    except BaseException:
        scene.close()
        raise
    return scene, realizers
