"""Validation and replay: a run's plans re-simulated in perturbed worlds, or again as they ran.

Modules, by what you look for:

* ``candidates``: the K best distinct plans of a run in perturbed worlds; the one returned.
* ``returned_plan``: replicas of the returned plan (``scripts/validate.py``).
* ``action_outcomes``: where in the plan the replicas failed, per action and per segment.
* ``replay`` / ``replay_shard``: the best plan again, in one copy or exactly in its own shard
  (``scripts/replay.py``); ``video``: videos a person can read.

What it doesn't: search (``realize.run``) or repair a plan (``realize.repair``).
"""
