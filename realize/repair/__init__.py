"""Execution and repair: a returned plan carried out in a world that changes, watched, repaired.

Modules, by what you look for:

* ``study``: a study of executed worlds (``realize.execute``, ``scripts/execute.py``), the replans
  judged against the open loop afterwards.
* ``executor``: one world carried out segment by segment and repaired through the planner;
  ``on_deviation``: what it does on a deviation (check first, re-parameterize, re-sequence);
  ``records``: what an execution writes. A replan's spec is ``realize.spec.replan_from``.
* ``resequence`` / ``resequence_blocks`` / ``pddl_text``: a new action sequence from the symbolic
  state read off an observed scene.

What it doesn't: simulate the world itself, observe it or export trajectories (the world side is
``realize.execution``), or search (``realize.run``).
"""
