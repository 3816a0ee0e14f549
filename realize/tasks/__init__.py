"""Tasks: symbolic parameters with regions, the plan over action templates, goals.

Modules: ``regions`` and ``hemisphere`` (the regions h(z) <= 0 of the paper), ``frames`` (a
region's numbers relative to an object), ``param_layout`` (regions as columns of one sample
matrix), ``spec`` (``TaskSpec``: parameters, plan, goal), ``goals`` (the goal predicates the rollout
and the ManiSkill tasks share), ``suffix`` (a plan's remaining actions from a state), ``pddl``
(symbolic plans from PDDL), ``topdown`` (the ground-plane view of a task that figures and
recordings draw).
What it doesn't: simulate or search (``realize.realization``, ``realize.search``).
"""
