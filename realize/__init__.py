"""realize: physically grounded realizations of symbolic robot plans.

Samples N parameter vectors of a symbolic plan, simulates all N realizations at once in a
batched ManiSkill/SAPIEN scene with the robot's own controllers, and refines the sampling
distribution by cross-entropy optimization.
"""

from realize.reproducible import pin_cpu_math

pin_cpu_math()  # before numpy, OpenBLAS, torch or MKL loads: the same kernels on every x86-64 host

__version__ = "0.1.0"

# The Python API, imported on first use so that `import realize` stays fast (no simulator, no Hydra):
#   from realize import Planner           (realize.run.planner)
_LAZY = {
    "Planner": "realize.run.planner",
    "PlanResult": "realize.run.planner",
    "ReplanBudget": "realize.run.planner",
    "compose_config": "realize.spec.compose",
    "compose_execution": "realize.spec.execution_config",
    "SceneState": "realize.world.state",
    "execute": "realize.repair.study",
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name: str):  # PEP 562
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'realize' has no attribute {name!r}")
