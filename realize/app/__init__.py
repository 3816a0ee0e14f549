"""The run layer: the command line, the config edge, one run, validation and replay, execution and repair, workers.

Modules, by what you look for (docs/architecture.md draws the path through them):

* The command line: ``cli`` (the ``realize`` command), ``cli_keys`` (unknown keys, the closest
  names), ``hydra_edge`` (Hydra's parsing and composing), ``compose`` (the config from Python),
  ``sweep_check`` (every job of a sweep checked first), ``sweep_summary`` (a sweep's
  ``summary.csv``), ``objective`` (the number a sweep minimizes), ``prebuild`` (the compiled
  fabric step, built once per machine).
* The config edge: ``run_config`` (Hydra's config checked into a ``RunSpec``), ``run_settings`` (the
  ``logging`` and ``validation`` groups), ``task_plans`` (a
  run's task and candidate plans), ``resume_config`` (what a resumed run takes from the command line).
* One run: ``planner`` (the importable ``Planner``), ``plan_result`` (what its calls take and
  return), ``run`` (one run in one call), ``assembly`` (searcher and sinks picked), ``loop`` (ask ->
  rollout -> tell), ``guard`` (how a run ends), ``stitched`` (a run of stitched segments), ``stitch_settings`` (the ``stitch`` node),
  ``realizers`` (the scene and realizers of a run), ``workers/`` (rollout workers: this process,
  local processes or Ray actors).
* Validation and replay: ``candidate_validation`` (the K best plans in perturbed worlds, one
  returned), ``validation`` (replicas of the returned plan), ``action_outcomes`` (where in the
  plan the replicas failed: per action and per segment), ``replay`` / ``replay_shard`` (the
  best plan again, in one copy or in its own shard), ``video``.
* Replanning, execution and repair: ``replan`` (the rest of a plan from a state), ``resequence`` /
  ``resequence_blocks`` / ``pddl_text`` (a new action sequence from an observed scene),
  ``execute`` (a study of executed worlds), ``executor`` (one world, watched and repaired),
  ``repair`` (what the executor does on a deviation), ``execution_records`` (what an execution
  writes). The world side of an execution is ``realize.execution``.
What it doesn't: simulate or search by itself (the packages below do).
"""
