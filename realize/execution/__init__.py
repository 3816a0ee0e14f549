"""The world side of executing a plan: disturbances as data, a one-copy world that stands in
for the real robot's, what the robot perceives of it, the monitor's checks, the check before a
repair, and the files a robot stack reads.

Modules:
  * ``disturbances``: triggers and effects as data (read, checked, drawn per world);
    ``schedule``: when each fires;
  * ``settings``: ``ExecuteSettings`` and the ``configs/execute/`` presets;
  * ``world``: ``ExecutionWorld`` (the world copy, disturbed on cue) and ``Observation``;
    ``layout_updates``: an observation as changes of the planner's scene config;
  * ``perception``: the observation model (noise, base drift, latency, drops) and the
    filtered ``Belief`` the executor decides from; ``robot_view``: the world or that belief,
    as the executor and the controllers read it;
  * ``monitor``: the ``Deviation`` checks of a belief against what the plan expects;
  * ``precheck``: the rest of the plan simulated from the belief in perturbed copies;
    ``in_hand``: a held object squared in the hand where a restore of its grip slips;
  * ``trajectory``: the ``.npz`` a driver follows (docs/execution_format.md);
    ``time_param``: time-parameterization within the URDF's limits; ``ros2_export``,
    ``lerobot_export`` and ``export``: an MCAP bag and a LeRobot dataset of the executed worlds.
Nothing here searches or replans (``realize.repair.study``, ``realize.repair.executor`` and
``realize.repair.on_deviation`` do, on top of these).
"""
