"""A CE run's rerun recording: what goes where, the 2-D and 3-D views, reading it back.

Modules: ``log`` (``RerunLogger``, on the ``ce_iteration`` timeline), ``paths`` (entity paths and
the viewer's layout), ``scene`` (the top-down world and samples), ``world3d`` and ``robot`` (the
world and the robot in 3-D on a control-step timeline), ``read`` (back into plain data),
``validation_log`` (a run's candidate validation as ``validation.rrd``).
What it doesn't: decide when to log (``realize.sinks.rerun``).
"""
