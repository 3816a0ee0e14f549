"""Build, once per machine, the compiled fabric steps that runs with ``controller.fabric.compiled``
will load: ``python -m realize.cli.prebuild [ROBOT ...]`` (default: the default robot).

What it does: for each robot named, the fabric a run builds with the default controller and
simulation settings (the ``controller`` and ``sim`` groups: the same package key), loaded or
built into ``realize.paths.cache_dir("fabric")`` (``realize.controllers.fabric_package``).
Setup does not run it (no preset uses the compiled step): the first run that asks for the
package builds it, and this builds it ahead of time; a package already there costs about two
seconds (its key is computed, nothing is loaded). A failed build is reported, not raised: a run
that needs the package says the same and how to run without it.
What it doesn't: build packages for non-default controller settings (a run builds its own
the first time), or for other devices than the CPU.
"""

from __future__ import annotations

import sys

import torch

from realize.config import ConfigError
from realize.controllers.fabric_package import ensure_built
from realize.controllers.whole_body import WholeBodyConfig, WholeBodyFabric
from realize.robot.spec import DEFAULT_ROBOT, load_robot_spec
from realize.scene.settings import SimSettings
from realize.world.geometry import GeometryCfg, build_geometry

__all__ = ["prebuild"]


def prebuild(robots: list[str]) -> bool:
    """Build the default-settings package of each robot where missing; False if a build failed."""
    ok = True
    dt = 1.0 / SimSettings().control_freq  # the scene's control period (realize.scene.BatchedScene)
    for name in robots:
        try:
            ensure_built(WholeBodyFabric(build_geometry(GeometryCfg()), WholeBodyConfig(), dt=dt,
                                         dtype=torch.float32, robot=load_robot_spec(name)))
        except ConfigError as e:
            print(f"realize.cli.prebuild: {e}", file=sys.stderr, flush=True)
            ok = False
    return ok


if __name__ == "__main__":
    sys.exit(0 if prebuild(sys.argv[1:] or [DEFAULT_ROBOT]) else 1)
