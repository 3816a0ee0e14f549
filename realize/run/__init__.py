"""One run: the importable ``Planner``, the searcher and sinks assembled, the search loop.

Modules, by what you look for (docs/architecture.md draws the path through them):

* ``planner``: the ``Planner`` you import (``from realize import Planner``): built once from a
  config, then ``plan()``, ``replan(...)``, ``close()``; ``plan_result``: what its calls take and
  return (``ReplanBudget``, ``PlanResult``).
* ``one_run``: one run in one call, what the command line does.
* ``assembly`` (searcher and sinks picked), ``loop`` (ask -> rollout -> tell), ``guard`` (how a
  run ends), ``stitched_run`` (a run of stitched segments), ``objective`` (the one number a sweep
  minimizes).

Below it: the run's spec (``realize.spec``), the copies' workers (``realize.workers``), the
returned plan's validation (``realize.validation``). Above it: the command line (``realize.cli``)
and execution and repair (``realize.repair``).
What it doesn't: sample or rank (``realize.search``) or simulate (``realize.scene``,
``realize.realization``).
"""
