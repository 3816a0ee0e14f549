"""The CPU backend's state I/O: cached reads equal fresh simulator reads after every kind of state
change, writing only the changed drive targets simulates exactly what writing all does, and the
finger-object contact forces equal a plain numpy reading of SAPIEN's contact list."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from realize.robot.spec import load_robot_spec
from realize.scene import BatchedScene, SimSettings
from realize.world.state import load_state

FINGER_LINKS = load_robot_spec("fetch_omni").gripper.finger_links

SIM = SimSettings(backend="cpu")


def _fresh(scene: BatchedScene) -> dict[str, np.ndarray]:
    """Every quantity read straight from SAPIEN, one object at a time (the oracle)."""
    impl = scene._impl
    offsets = np.asarray(scene.u.offsets, dtype=np.float32)

    def poses(bodies: list) -> np.ndarray:
        raw = np.array([np.concatenate([p.p, p.q]) for p in (b.get_entity_pose() for b in bodies)], dtype=np.float32)
        raw[:, :2] -= offsets
        return raw

    return {
        "qpos": np.stack([a.get_qpos() for a in impl._arts]),
        "qvel": np.stack([a.get_qvel() for a in impl._arts]),
        "ee_pose": poses(impl._ee_links),
        "object_poses": np.stack([poses(bodies) for bodies in impl._object_bodies], axis=1),  # (N, m, 7)
        "object_velocities": np.stack([np.array([np.concatenate([b.get_linear_velocity(), b.get_angular_velocity()])
                                                 for b in bodies], dtype=np.float32)
                                       for bodies in impl._object_bodies], axis=1),
    }


def _assert_reads_fresh(scene: BatchedScene) -> None:
    fresh = _fresh(scene)
    for _ in range(2):  # the first read fills the cache, the second comes from it
        for name, want in fresh.items():
            got = getattr(scene, name)().numpy()
            assert got.dtype == np.float32 and np.array_equal(got, want), name
        for k, name in enumerate(scene.object_names):  # one object by name: its slice of the m axis
            assert np.array_equal(scene.object_pose(name).numpy(), fresh["object_poses"][:, k]), name
            assert np.array_equal(scene.object_velocity(name).numpy(), fresh["object_velocities"][:, k]), name
        wb = scene.whole_body_q()
        assert np.array_equal(wb[:, 3:].numpy(), fresh["qpos"][:, scene._wb_idx.numpy()[3:]])
        assert np.array_equal(scene.whole_body_qd().numpy(), fresh["qvel"][:, scene._wb_idx.numpy()])
        assert np.array_equal(scene.base_pose().numpy(), wb[:, :3].numpy())
        assert np.array_equal(scene.finger_width().numpy(), fresh["qpos"][:, scene._finger_idx.numpy()].sum(axis=1))


def test_cached_reads_equal_fresh_reads_after_every_state_change() -> None:
    with BatchedScene(3, sim=SIM) as s:
        s.reset(seed=0)
        _assert_reads_fresh(s)
        s.set_base_velocity(torch.tensor([[0.3, 0.0, 0.2]] * 3))
        for _ in range(3):
            s.step()
            _assert_reads_fresh(s)
        q = s.qpos()
        q[:] = 0.0  # a caller scribbling on a read does not change the next read
        assert not np.array_equal(s.qpos().numpy(), q.numpy())
        s.freeze(torch.tensor([False, True, False]))  # zeroes copy 1's joint velocities
        _assert_reads_fresh(s)
        assert float(s.qvel()[1].abs().max()) == 0.0
        s.push_object("cube", 2, (0.0, 0.5, 0.0))
        _assert_reads_fresh(s)
        assert float(s.object_velocity("cube")[2, 1]) == 0.5
        s.place_object("cube", s.object_pose("cube")[:, :3] + torch.tensor([0.0, 0.0, 0.05]))
        _assert_reads_fresh(s)
        s.step()
        _assert_reads_fresh(s)
        s.reset(seed=1, randomize=True)
        _assert_reads_fresh(s)
        # a change behind the scene's back, announced with state_changed()
        art = s._impl._arts[0]
        art.set_qpos(art.get_qpos() + np.float32(0.01))
        s.state_changed()
        _assert_reads_fresh(s)


def _scripted(scene: BatchedScene, steps: int) -> list[np.ndarray]:
    """Motion with a long stretch where no target changes (held arm, still base: a robot nobody
    writes to falls asleep after ~1 s), a gripper that closes and a copy frozen midway; returns
    every step's joint positions, velocities and object poses."""
    n = scene.n_envs
    q0 = scene.whole_body_q()
    trace = []
    for k in range(steps):
        v = torch.zeros(n, 3)
        arm = q0[:, 3:].clone()
        moving = k < 10 or 45 <= k < 55  # otherwise the same targets step after step
        if moving:
            v[:, 0] = 0.3
            v[:, 2] = 0.2 * np.sin(0.2 * k) * torch.arange(n)
            arm[:, 1] += 0.3 * np.sin(0.1 * k)
        scene.set_base_velocity(v)
        scene.set_arm_targets(arm, torch.full_like(arm, 0.1) if moving and k % 3 == 0 else None)
        scene.set_gripper(torch.full((n,), 50 <= k < 65))
        if k == 30:
            scene.freeze(torch.arange(n) == 1)
        scene.step()
        trace.append(np.concatenate([scene.qpos().numpy(), scene.qvel().numpy(),
                                      scene.object_poses().flatten(1).numpy()], axis=1))
    return trace


def test_changed_only_target_writes_give_the_same_trajectory_as_writing_all() -> None:
    with BatchedScene(3, sim=SIM) as s:
        runs = {}
        for rewrite_all in (True, False, True):
            s._impl.rewrite_all_targets = rewrite_all
            s.reset(seed=0)
            runs.setdefault(rewrite_all, []).append(_scripted(s, 70))
    (all_a, all_b), (changed,) = runs[True], runs[False]
    assert all(np.array_equal(a, b) for a, b in zip(all_a, all_b))  # the comparison is deterministic
    for k, (a, b) in enumerate(zip(all_a, changed)):
        assert np.array_equal(a, b), f"step {k}: changed-only writes diverge"


def _finger_forces_oracle(scene: BatchedScene) -> np.ndarray:
    """(N, m, 2) finger-object contact forces straight from SAPIEN's contact list, matched by the
    link and object bodies of each copy, each contact's impulse summed and normed with numpy."""
    impl = scene._impl
    out = np.zeros((scene.n_envs, len(impl._object_bodies), 2))
    fingers = [[a.robot.links_map[ln]._objs[0] for ln in FINGER_LINKS] for a in scene.u.agents]
    for contact in impl._px.get_contacts():
        pair = list(contact.bodies)
        for k, bodies in enumerate(impl._object_bodies):
            for c, body in enumerate(bodies):
                for f, link in enumerate(fingers[c]):
                    if any(b is body for b in pair) and any(b is link for b in pair):
                        total = np.zeros(3)
                        for pt in contact.points:
                            total += pt.impulse
                        out[c, k, f] += np.linalg.norm(total)
    return out * scene.sim.sim_freq


def test_finger_forces_equal_a_numpy_oracle_on_a_held_cube() -> None:
    held = load_state(Path(__file__).parent / "fixtures" / "state_grasped.json")
    with BatchedScene(2, sim=SIM) as s:
        s.reset(state=held)
        pressed = 0
        for _ in range(6):
            s.step()
            want = _finger_forces_oracle(s)
            got = s.finger_forces().numpy()
            assert got.shape == (2, 1, 2) and np.array_equal(got, want.astype(np.float32))
            pressed += int((want > 0).all())
            assert s.holds("cube").tolist() == (got >= s.sim.grasp_min_force).all(axis=2)[:, 0].tolist()
        assert pressed == 6  # both fingers of both copies pressed on the cube at every step
