"""Plan realization: run a task's plan for N parameter samples at once and score each by eq. (2).

Modules (one job each):
  * ``config``: ``RolloutConfig`` (Hydra ``controller``: tolerances, timeouts, controller
    settings) and ``AStarConfig``;
  * ``failures``: the ``Failure`` codes of a failed plan;
  * ``context``: ``StepContext``, what one control step knows (scene reads, the fabric, the
    grid) and the command buffers the templates write;
  * ``actions``: the action templates (one module each) and their registry ``TEMPLATES``;
  * ``goals``: the goal predicates psi_g (used by the rollout and by the ManiSkill tasks'
    ``evaluate()``);
  * ``result``: ``RolloutResult``; ``rollout``: the rollout phases and ``PlanRealizer``.
This package's ``__init__`` imports nothing, so importing ``goals`` stays light (the tasks in
``envs`` import it).
"""
