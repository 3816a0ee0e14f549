"""The ManiSkill tasks this project registers: the registry, refused geometries, the lean robot.

* the registry lists every task whose class lives in the ``envs`` package (the ids
  ``test_env_robots.py`` makes with every robot: ``gym.make``, ``reset(seed=0)`` twice, 5 random
  steps, ``render()``, ``close()``, as ManiSkill's own env tests do);
* a geometry of a variant a task does not build is refused by name before any scene is built;
* the lean robot (``sim.lean_robot``) keeps the full robot's joints and link poses, and dropping
  a moving or inner link is refused;
* the simulator settings reach what they name: robot solver iterations, hand collision shapes
  (masses kept), the PhysX scene settings.
"""

from __future__ import annotations

import re

import gymnasium as gym
import numpy as np
import pytest
import torch
from mani_skill.utils.registration import REGISTERED_ENVS

import envs
from realize.config import ConfigError

ENV_IDS = sorted(k for k, spec in REGISTERED_ENVS.items() if spec.cls.__module__.partition(".")[0] == envs.__name__)


def test_the_registry_lists_our_tasks() -> None:
    assert envs.ENV_ID in ENV_IDS and envs.MOVE_AND_PUSH_ID in ENV_IDS


@pytest.mark.parametrize("env_id, geometry, words", [
    (envs.MOVE_AND_PUSH_ID, {"variant": "plain"}, "geometry.variant = 'plain'"),
    (envs.ENV_ID, {"variant": "push", "tables": [], "objects": {"stick": {"size": [0.04, 0.04, 0.7], "rests_on": "floor"},
                                                               "cube": {"rests_on": "stick"}},
                   "containers": [{}]},
     "geometry.variant = 'push'"),
    (envs.ENV_ID, {"objects": {"cube": {"size": [1.6, 0.045, 0.045]}}}, "geometry.objects.cube.size"),
])
def test_wrong_geometry_is_refused_by_kwarg_name(env_id: str, geometry: dict, words: str) -> None:
    with pytest.raises(ConfigError) as e:
        gym.make(env_id, geometry=geometry)
    assert words in str(e.value)


def _unprefixed(name: str) -> str:
    """A link or joint name without its tiled agent's prefix (``scene-0-<uid>-agent-<i>_``)."""
    return re.sub(r"^.*-agent-\d+_", "", name)


def test_lean_fetch_keeps_joints_and_kinematics_and_drops_only_fixed_leaves() -> None:
    """The lean robot (``sim.lean_robot``) has the full robot's active joints in the same order
    and, at the same joint positions, the same pose of every link it keeps (checked against the
    full robot, built from the same URDF); only the spec's ``lean_drop_links`` are gone."""
    from realize.robot.spec import load_robot_spec
    from realize.scene import BatchedScene, SimSettings

    LEAN_DROPPED_LINKS = load_robot_spec("fetch_omni").collision.lean_drop_links

    built = {}
    for lean in (False, True):
        with BatchedScene(2, None, SimSettings(lean_robot=lean)) as s:
            art = s._impl._arts[1]
            names = [_unprefixed(ln.name) for ln in art.get_links()]
            poses = {n: ln.entity_pose for n, ln in zip(names, art.get_links())}
            root = art.get_root_pose()
            built[lean] = (names, [_unprefixed(j.name) for j in art.get_active_joints()],
                           {n: root.inv() * p for n, p in poses.items()}, s.qpos())
    (full, jf, pf, qf), (lean, jl, pl, ql) = built[False], built[True]
    assert len(full) == 29 and len(lean) == 18 and len(LEAN_DROPPED_LINKS) == 11
    assert set(full) - set(lean) == set(LEAN_DROPPED_LINKS) and set(lean) < set(full)
    assert jf == jl and torch.equal(qf, ql)
    for n in lean:
        assert np.allclose(pf[n].p, pl[n].p, atol=1e-6) and np.allclose(np.abs(pf[n].q @ pl[n].q), 1, atol=1e-6), n


def test_drop_links_refuses_moving_or_inner_links() -> None:
    """Only fixed-joint leaves may be dropped: the head tilt link moves, the head camera link has
    children that would be left hanging."""
    import sapien
    from mani_skill import format_path

    from envs.robot_agent import drop_links
    from realize.robot.urdf import source_urdf

    def parsed():
        loader = sapien.Scene().create_urdf_loader()
        articulation_builders = loader.parse(format_path(str(source_urdf("mani_skill:robots/fetch/fetch.urdf"))))[0]  # SAPIEN: (articulations, actors, cameras)
        return articulation_builders[0]

    with pytest.raises(ValueError, match="revolute"):
        drop_links(parsed(), ("head_tilt_link", "head_camera_link"))
    with pytest.raises(ValueError, match="child of the dropped head_camera_link"):
        drop_links(parsed(), ("head_camera_link",))
    with pytest.raises(ValueError, match="not in the robot"):
        drop_links(parsed(), ("no_such_link",))


def test_robot_solver_iterations_apply_to_robots_only() -> None:
    """``sim.solver_position_iterations_robot`` sets every robot's count; the objects (cubes) keep the
    scene's ``solver_position_iterations``."""
    from realize.scene import BatchedScene, SimSettings

    with BatchedScene(2, None, SimSettings(solver_position_iterations=12, solver_position_iterations_robot=3)) as s:
        assert [a.get_solver_position_iterations() for a in s._impl._arts] == [3, 3]
        assert [b.get_solver_position_iterations() for b in s._impl._object_bodies[0]] == [12, 12]


def test_hand_collisions_keep_every_mass_and_leave_shapes_on_the_hand_only() -> None:
    """``sim.robot_collisions=hand``: the gripper link and both fingers keep their collision
    shapes, no other link has one, and every link keeps the mass it has with all its shapes (the
    URDF's inertial, not one computed from shapes)."""
    from realize.robot.spec import load_robot_spec
    from realize.scene import BatchedScene, SimSettings

    HAND_LINKS = load_robot_spec("fetch_omni").collision.hand_links

    built = {}
    for mode in ("all", "hand"):
        with BatchedScene(2, None, SimSettings(robot_collisions=mode)) as s:
            built[mode] = {_unprefixed(ln.name): (ln.mass, len(ln.get_collision_shapes()))
                           for ln in s._impl._arts[1].get_links()}
    full, hand = built["all"], built["hand"]
    assert full.keys() == hand.keys()
    assert sum(k for _, k in full.values()) == 15  # the lean robot's convex shapes
    assert {n for n, (_, k) in hand.items() if k} == set(HAND_LINKS)
    assert all(hand[n][1] == full[n][1] for n in HAND_LINKS)
    assert all(hand[n][0] == full[n][0] for n in full)


def test_physx_scene_settings_reach_every_shape_and_the_solver() -> None:
    """``sim.contact_offset`` is every shape's (robot and cube), ``sim.solver`` the scene's."""
    import sapien

    from realize.scene import BatchedScene, SimSettings

    with BatchedScene(1, None, SimSettings(contact_offset=0.007, solver="pgs")) as s:
        shapes = [sh for ln in s._impl._arts[0].get_links() for sh in ln.get_collision_shapes()]
        shapes += s._impl._shapes(0)
        assert len(shapes) == 16 and all(sh.contact_offset == pytest.approx(0.007) for sh in shapes)
        assert sapien.physx.get_scene_config().enable_tgs is False
    with pytest.raises(ConfigError, match="robot_collisions"):
        gym.make(envs.ENV_ID, robot_collisions="arms")
