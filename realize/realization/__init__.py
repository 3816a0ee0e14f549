"""Plan realization: run a task's plan for N parameter samples at once and score each by eq. (2).

Modules (one job each):
  * ``config``: ``RolloutConfig`` (Hydra ``controller``: tolerances, timeouts, controller
    settings) and ``AStarConfig``;
  * ``failures``: the ``Failure`` codes of a failed plan;
  * ``context``: ``StepContext``, what one control step knows (scene reads, the fabric, the
    grid) and the command buffers the templates write;
  * ``actions``: the action templates (one module each) and their registry ``TEMPLATES``;
  * ``result``: ``RolloutResult``; ``rollout``: the rollout phases and ``PlanRealizer``.
The goal predicates psi_g live in ``realize.tasks.goals`` (the ManiSkill tasks' ``evaluate()``
uses them too). This package's ``__init__`` imports nothing, so importing one module stays light.
"""
