"""The world side of executing a plan: disturbances as data, a one-copy world that stands in
for the real robot's, the monitor's checks and the trajectory file a driver follows.

Modules: ``disturbances`` (triggers, effects, reading, drawing, the schedule), ``settings``
(``ExecuteSettings``, the ``configs/execute/`` presets), ``world`` (``ExecutionWorld``,
``Observation``, belief updates), ``monitor`` (``Deviation`` checks), ``trajectory`` (the
``.npz`` format of docs/execution_format.md). Nothing here searches or replans
(``realize.app.execute`` does, on top of these).
"""
