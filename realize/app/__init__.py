"""The run layer: the command line, the config edge, the search loop, replay and replanning.

Modules: ``cli`` / ``cli_keys`` (the ``realize`` command), ``run_config`` (Hydra's config checked
into a ``RunSpec``), ``task_plans`` (a run's task and candidate plans), ``run`` and ``loop`` (one
run: searcher, sinks, ask -> rollout -> tell), ``guard`` (how a run ends), ``realizers`` (the
scene and realizers of a run), ``workers`` (rollout workers: processes or Ray), ``replay`` /
``replay_shard`` / ``video`` (a run's best plan again), ``validation``, ``replan``,
``sweep_summary`` (a sweep's ``summary.csv``).
What it doesn't: simulate or search by itself (the packages below do).
"""
