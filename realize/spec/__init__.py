"""A run's spec: Hydra's config composed (from the command line or from Python) and checked once
into a ``RunSpec`` of plain dataclasses; the config edge, below which the library takes arguments.

Modules, by what you look for (docs/architecture.md draws the path through them):

* ``hydra_edge``: Hydra's parsing and composing, and every settings dataclass registered as its
  config group's schema (``register_schema``); ``compose``: the config from Python
  (``realize.compose_config``), every mistake one line; ``keys``: command-line keys the config
  does not have, with the closest names.
* ``run_spec``: the whole config checked into a ``RunSpec`` (``build_run_spec``).
* The groups the run layer owns: ``run_settings`` (``logging``, ``validation``, ``replan``),
  ``stitch_settings`` (``stitch``), ``workers_settings`` (``workers``).
* ``execution_config``: an execution study's config (``realize.compose_execution``): the
  ``execute`` and ``noise`` groups over ``ExecuteSettings``.
* ``task_plans``: a run's task and candidate plans; ``replan_from``: the spec of a replan (the rest
  of an earlier run's plan from a state); ``resume_config``: what a resumed run takes from the
  command line.

What it doesn't: build scenes or run anything (``realize.workers``, ``realize.run``).
"""
