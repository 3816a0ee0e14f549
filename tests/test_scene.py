"""The batched scene on CPU: shapes, independence of copies, determinism, rendering, hooks, errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from realize.config import ConfigError
from realize.world.geometry import GeometryCfg, build_geometry
from realize.scene import BatchedScene, SimSettings

SIM = SimSettings(backend="cpu")
# configs/scene/push.yaml's objects: the stick on the floor, the cube on its top
PUSH_OBJECTS = {"stick": {"size": [0.04, 0.04, 0.7], "rests_on": "floor"}, "cube": {"rests_on": "stick"}}


def _drive(scene: BatchedScene, steps: int) -> None:
    """A fixed scripted motion: base drives diagonally while the arm swings."""
    q0 = scene.whole_body_q()
    for k in range(steps):
        v = torch.zeros(scene.n_envs, 3)
        v[:, 0] = 0.3
        v[:, 1] = 0.1 * np.sin(k * 0.1)
        scene.set_base_velocity(v)
        arm = q0[:, 3:].clone()
        arm[:, 1] += 0.3 * np.sin(k * 0.05)
        scene.set_arm_targets(arm)
        scene.step()


@pytest.mark.parametrize("n", [1, 8])
def test_builds_and_shapes(n: int) -> None:
    with BatchedScene(n, sim=SIM) as s:
        s.reset()
        assert s.qpos().shape == (n, 15)
        assert s.whole_body_q().shape == (n, 11)
        assert s.whole_body_qd().shape == (n, 11)
        assert s.base_pose().shape == (n, 3)
        assert s.ee_pose().shape == (n, 7)
        assert s.object_names == ("cube",)
        assert s.object_pose("cube").shape == (n, 7) and s.object_poses().shape == (n, 1, 7)
        assert s.object_velocity("cube").shape == (n, 6) and s.object_velocities().shape == (n, 1, 6)
        assert s.holds("cube").shape == (n,) and s.holds("cube").dtype == torch.bool
        assert s.holding().shape == (n, 1) and s.finger_forces().shape == (n, 1, 2)
        assert s.held_object().tolist() == [-1] * n
        # every copy starts in the same local state, at the configured start pose
        g = s.geometry
        assert torch.allclose(s.base_pose()[:, :2], torch.tensor(g.robot_start[:2]).repeat(n, 1), atol=1e-5)
        assert torch.allclose(s.object_pose("cube")[:, :3], torch.tensor(g.object("cube").position, dtype=torch.float32).repeat(n, 1), atol=1e-4)


def test_base_follows_velocity_command() -> None:
    with BatchedScene(2, sim=SIM) as s:
        s.reset()
        start = s.base_pose()
        v = torch.tensor([[0.4, 0.0, 0.0], [0.0, -0.3, 0.5]])
        s.set_base_velocity(v)
        for _ in range(20):  # 1 s
            s.step()
        moved = s.base_pose() - start
        assert moved[0, 0] == pytest.approx(0.4, abs=0.03) and abs(moved[0, 1]) < 0.01
        assert moved[1, 1] == pytest.approx(-0.3, abs=0.03) and moved[1, 2] == pytest.approx(0.5, abs=0.05)


def test_pushing_one_copy_leaves_the_others_unchanged() -> None:
    def run(push: bool) -> tuple[torch.Tensor, torch.Tensor]:
        with BatchedScene(4, sim=SIM) as s:
            s.reset(seed=1)
            if push:
                s.push_object("cube", 2, (0.0, -1.5, 0.5))
            _drive(s, 30)
            return s.object_pose("cube"), s.whole_body_q()

    cube_a, q_a = run(False)
    cube_b, q_b = run(True)
    others = [0, 1, 3]
    assert torch.equal(cube_a[others], cube_b[others])
    assert torch.equal(q_a[others], q_b[others])
    assert (cube_a[2, :3] - cube_b[2, :3]).norm() > 0.1  # the pushed cube did move


def test_same_seed_gives_identical_states_after_200_steps() -> None:
    def run() -> torch.Tensor:
        with BatchedScene(3, sim=SIM) as s:
            s.reset(seed=7, randomize=True)
            _drive(s, 200)
            return torch.cat([s.whole_body_q(), s.object_pose("cube"), s.ee_pose()], dim=1)

    assert torch.equal(run(), run())


@pytest.mark.slow  # a first frame builds lavapipe's renderer (22 s on a busy 2-core host): make test keeps
# every robot's frame through env.render, as BatchedScene.render calls it (tests/test_env_robots.py)
def test_renders_a_frame_to_png(tmp_path) -> None:
    from PIL import Image

    with BatchedScene(1, sim=SIM) as s:
        s.reset()
        frame = s.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    assert frame.std() > 10, "frame is blank"
    path = tmp_path / "frame.png"
    Image.fromarray(frame).save(path)
    assert path.stat().st_size > 1000


@pytest.mark.parametrize(
    "geometry, sim, n, key",
    [
        (dict(variant="zigzag"), {}, 1, "scene.variant"),
        (dict(robot_start=(0.0, 1.2, 0.0)), {}, 1, "scene.robot_start"),
        (None, {}, 0, "n_envs"),
        (None, dict(sim_freq=100, control_freq=30), 1, "sim.sim_freq"),
        (None, dict(backend="tpu"), 1, "sim.backend"),
        (None, dict(cpu_workers=-1), 1, "sim.cpu_workers = -1 is invalid: must be >= 0"),
        (dict(bounds_low=(2.0, 0.0), bounds_high=(1.0, 1.0)), {}, 1, "scene.bounds_low"),
        (dict(wrong_key=1), {}, 1, "wrong_key"),
    ],
)
def test_bad_input_names_the_key(geometry, sim, n, key) -> None:
    with pytest.raises(ConfigError) as e:
        BatchedScene(n, geometry=geometry, sim=SimSettings(**dict(dict(backend="cpu"), **sim)))
    assert key in str(e.value)


def test_variants_build() -> None:
    for variant in ("wall", "ramp"):
        with BatchedScene(1, geometry={"variant": variant, f"{variant}s": [{}]}, sim=SIM) as s:  # walls / ramps
            s.reset()
            names = [b.name for b in s.geometry.extras]
            assert names == [variant]


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU (PhysX GPU backend)")
def test_gpu_backend_matches_shapes() -> None:  # pragma: no cover - GPU machines only
    with BatchedScene(16, sim=SimSettings(backend="gpu")) as s:
        s.reset()
        _drive(s, 10)
        assert s.whole_body_q().shape == (16, 11) and s.whole_body_q().device.type == "cuda"
        assert s.object_pose("cube").shape == (16, 7)


def test_ramp_slides_a_released_cube_onto_table2() -> None:
    """Physical fact behind the ramp scenario: a cube let go anywhere above the slippery ramp
    comes to rest on table 2; one let go above the floor beside the ramp does not."""
    over_ramp = [(0.0, -0.4, 1.12), (0.1, -0.6, 1.0), (-0.1, -0.85, 0.88)]
    beside = [(0.6, -0.6, 0.9)]
    with BatchedScene(4, geometry=dict(variant="ramp", ramps=[{}]), sim=SIM) as s:
        s.reset()
        s.place_object("cube", torch.tensor(over_ramp + beside))
        for _ in range(60):
            s.step()
        p = s.object_pose("cube")[:, :3]
        t2 = s.geometry.table("table2")
        top = 2 * t2.half_size[2] + s.geometry.object("cube").half_height
        on_t2 = ((p[:, 0] - t2.center[0]).abs() <= t2.half_size[0]) & ((p[:, 1] - t2.center[1]).abs() <= t2.half_size[1])
        on_t2 &= (p[:, 2] - top).abs() < 0.01
        assert on_t2.tolist() == [True, True, True, False]
        assert float(s.object_velocity("cube")[:3, :3].norm(dim=1).max()) < 0.05


@pytest.mark.parametrize("key, value", [("drop", 0.8), ("friction", -0.1), ("low_table", "table9")])
def test_bad_ramp_names_the_key(key: str, value: object) -> None:
    with pytest.raises(ConfigError, match=rf"scene\.ramps\[0\]\.{key} = "):
        build_geometry(GeometryCfg.from_mapping({"variant": "ramp", "ramps": [{key: value}]}))


@pytest.mark.parametrize("d, key, words", [
    ({"tables": [{"name": "t", "height": 2.0}]}, "scene.tables[0].height", "[0.3, 1.1]"),
    ({"tables": [{"name": "t"}, {"name": "t", "center": [0.0, -1.2]}]}, "scene.tables", "unique"),
    ({"objects": {"cube": {"size": [0.045, 0.0, 0.045]}}}, "scene.objects.cube.size", "every side must be > 0"),
    ({"variant": "push", "tables": [], "objects": {"stick": {"size": [0.04, 0.04, 2.0], "rests_on": "floor"}}},
     "scene.objects.stick.size", "<= 1.5 m"),
    ({"objects": {"cube": {"rests_on": "table9"}}}, "scene.objects.cube.rests_on", "no table or object of that name"),
    ({"objects": {"cube": {"offset": [0.5, 0.0]}}}, "scene.objects.cube.offset", "must rest on table1's top"),
    ({"variant": "push", "tables": [], "objects": PUSH_OBJECTS, "containers": [{"inner": [0.03, 0.4]}]},
     "scene.containers[0].inner", "larger than the objects"),
    ({"containers": [{"wall_height": 0.0}]}, "scene.containers[0].wall_height", "must be > 0"),
    ({"variant": "push", "tables": [], "objects": PUSH_OBJECTS}, "scene.containers", "needs an open box"),
    ({"bounds_low": [3.3, -3.0]}, "scene.bounds_low", "bounds_high"),
])
def test_geometry_config_errors(d: dict, key: str, words: str) -> None:
    """``GeometryCfg`` is a ``Settings``: single values by field metadata, how parts fit by ``check``."""
    with pytest.raises(ConfigError) as e:
        GeometryCfg.from_mapping(d)
    assert key in str(e.value) and words in str(e.value)


def test_every_variant_builds_from_the_config_files() -> None:
    from helpers import compose_config

    extras = {"plain": [], "wall": ["wall"], "ramp": ["ramp"],
              "push": ["box_floor", "box_wall_xn", "box_wall_xp", "box_wall_yn", "box_wall_yp"]}
    for variant in ("plain", "wall", "ramp", "push"):  # configs/scene/<variant>.yaml, composed as a run does
        g = build_geometry(GeometryCfg.from_mapping(compose_config(f"scene={variant}")["scene"]))
        stick = [b.name for b in g.floor_objects] == ["stick"]
        assert g.variant == variant and stick == (variant == "push")
        assert [b.name for b in g.extras] == extras[variant] and bool(g.containers) == (variant == "push")


def test_step_hooks_env_options_and_friction() -> None:
    """What replay and validation use: step hooks, forced randomized resets with the task's noise,
    per-copy object friction (the scene builds its task from the scene's variant)."""
    from realize.scene import EnvOptions

    seen: list[int] = []
    opts = EnvOptions(object_xy_noise=0.03, randomize_resets=True)
    with BatchedScene(2, sim=SIM, env=opts) as s:
        s.add_step_hook(seen.append, every=2)
        s.reset(seed=3)
        for _ in range(5):
            s.step()
        assert seen == [0, 2, 4] and s.step_count == 5
        assert s.object_xy_noise == 0.03 and s.robot_xy_noise == pytest.approx(0.05)
        off = (s.object_pose("cube")[:, :2] - torch.tensor(s.geometry.object("cube").position[:2])).abs()
        assert (off.max(dim=1).values > 1e-4).all()  # randomized although reset() did not ask
        mu = s.set_object_friction("cube", [0.5, 2.0])
        assert torch.allclose(s.object_friction("cube"), torch.stack([mu, mu], dim=1).to(torch.float64))
        with pytest.raises(ConfigError, match=r"1 friction factors for 2 copies"):
            s.set_object_friction("cube", [1.0])
        with pytest.raises(ConfigError, match=r"every = 0 is invalid"):
            s.add_step_hook(seen.append, every=0)
