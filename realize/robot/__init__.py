"""A robot as data: its spec, URDF, sphere model and batched kinematics.

Modules: ``spec`` (``RobotSpec`` from ``configs/robot/<name>.yaml``), ``urdf`` (finding or deriving
the URDF, its joints), ``sphere_file`` (a robot's collision spheres), ``link_geometry`` and
``sphere_fit`` (fitting spheres to collision meshes), ``chain``, ``jacobians`` and ``kinematics``
(``RobotKinematics``: FK, TCP, spheres, closed-form Jacobians), ``layout`` (the slices of the
whole-body vector ``q``). Everything true of one robot lives here and in its config; generic code
asks the spec.
What it doesn't: build the simulated robot (``envs.robot_agent``) or control it (``realize.controllers``).
"""
