"""The observation model (realize/execution/perception.py): noise statistics against the
configured spreads, latency and drops counted, the belief's filter, and bad keys refused."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from helpers import REPO
from realize.config import ConfigError
from realize.execution.perception import Belief, Noise, Sensor, load_noise, noise_presets
from realize.execution.world import BoxSeen, Observation, TablePose
from realize.world.state import ObjectPose, SceneState

DT = 0.05
CUBE = (0.4, -0.2, 0.8)


def truth(step: int, held: str | None = None, cube=CUBE) -> Observation:
    state = SceneState(base=(1.0, 2.0, 0.3), joints={}, gripper_closed=held is not None,
                       objects={"cube": ObjectPose(cube, (1.0, 0.0, 0.0, 0.0))}, held=held)
    return Observation(step, step * DT, state, {"table1": TablePose(0.5, -0.5)},
                       (BoxSeen("box", (2.0, 0.0), (0.5, 0.5, 0.5)),))


def readings(noise: Noise, n: int, spacing: int = 1) -> list:
    sensor = Sensor(noise, DT, seed=3)
    out = []
    for i in range(n):
        sensor.read(truth(i * spacing))
        out += sensor.deliver(i * spacing + 10 ** 6)
    return out


def test_object_and_table_readings_have_the_configured_spread() -> None:
    noise = Noise(object_m=0.003, object_deg=2.5, table_m=0.004)
    rs = readings(noise, 4000)
    p = np.array([r.objects["cube"][0] for r in rs])
    yaw = np.array([r.objects["cube"][1] for r in rs])
    t = np.array([r.tables["table1"] for r in rs])
    b = np.array([r.boxes["box"] for r in rs])
    # the sample std of 4000 normal draws is within 5 % of sigma with > 99.9 % probability
    assert np.allclose(p.std(axis=0), 0.003, rtol=0.05) and np.allclose(p.mean(axis=0), CUBE, atol=3e-4)
    assert math.isclose(np.degrees(yaw.std()), 2.5, rel_tol=0.05) and abs(yaw.mean()) < math.radians(0.2)
    assert np.allclose(t.std(axis=0), 0.004, rtol=0.05) and np.allclose(t.mean(axis=0), (0.5, -0.5), atol=4e-4)
    assert np.allclose(b.std(axis=0), 0.004, rtol=0.05)


def test_the_base_drifts_with_the_configured_stationary_spread_and_correlation() -> None:
    noise = Noise(base_m=0.01, base_deg=1.0, drift_s=0.5)
    far = np.array([r.base_error for r in readings(noise, 4000, spacing=100)])  # 5 s apart: independent
    assert np.allclose(far[:, :2].std(axis=0), 0.01, rtol=0.06)
    assert math.isclose(np.degrees(far[:, 2].std()), 1.0, rel_tol=0.06)
    near = np.array([r.base_error for r in readings(noise, 4000, spacing=1)])  # 0.05 s apart
    lag1 = np.corrcoef(near[:-1, 0], near[1:, 0])[0, 1]
    assert math.isclose(lag1, math.exp(-DT / 0.5), abs_tol=0.02)  # a first-order Gauss-Markov error


def test_readings_arrive_late_by_the_latency_and_a_share_is_dropped() -> None:
    noise = Noise(latency_s=0.1, drop=0.05)
    sensor = Sensor(noise, DT, seed=0)
    assert sensor.latency_steps == 2
    taken, arrived = [], []
    for step in range(20000):
        if sensor.read(truth(step)) is not None:
            taken.append(step)
        for r in sensor.deliver(step):
            arrived.append((r.step, step))
    assert all(now - at == 2 for at, now in arrived) and len(arrived) == len(taken) - 2
    lost = 1 - len(taken) / 20000
    assert abs(lost - 0.05) < 4 * math.sqrt(0.05 * 0.95 / 20000)


def test_the_same_seed_reads_the_same() -> None:
    noise = load_noise("realistic")
    a, b = readings(noise, 50), readings(noise, 50)
    assert [(r.step, r.objects, r.base) for r in a] == [(r.step, r.objects, r.base) for r in b]


def test_the_belief_averages_its_window_and_starts_over_when_a_thing_moves() -> None:
    noise = Noise(object_m=0.003, window=5, jump_m=0.05)
    rs = readings(noise, 2000)
    means = []
    for i in range(0, 2000, 5):
        belief = Belief(noise)
        for r in rs[i:i + 5]:
            belief.update(r)
        means.append(belief.observation(truth(i)).state.objects["cube"].position)
    assert np.allclose(np.std(means, axis=0), 0.003 / math.sqrt(5), rtol=0.15)  # sigma / sqrt(window)
    belief = Belief(noise)
    for r in rs[:5]:
        belief.update(r)
    sensor = Sensor(noise, DT, seed=9)
    sensor.read(truth(10, cube=(0.6, -0.2, 0.8)))  # the cube moved 20 cm: the old readings no longer count
    belief.update(sensor.deliver(10)[0])
    x = belief.observation(truth(10, cube=(0.6, -0.2, 0.8))).state.objects["cube"].position[0]
    assert abs(x - 0.6) < 0.015


def test_the_belief_keeps_a_held_object_in_the_hand_and_the_joints_exact() -> None:
    noise = Noise(object_m=0.003, base_m=0.01, base_deg=1.0)
    sensor, belief = Sensor(noise, DT, seed=1), Belief(noise)
    t = truth(0, held="cube")
    r = sensor.read(t)
    assert "cube" not in r.objects  # the camera does not report what the hand holds
    belief.update(r)
    seen = belief.observation(t).state
    ex, ey, eyaw = r.base_error
    # the cube keeps its place relative to the base: distance and bearing from the believed base
    d_true = np.hypot(CUBE[0] - 1.0, CUBE[1] - 2.0)
    d_seen = np.hypot(seen.objects["cube"].position[0] - seen.base[0], seen.objects["cube"].position[1] - seen.base[1])
    assert math.isclose(d_true, d_seen, abs_tol=1e-9) and seen.base == pytest.approx((1.0 + ex, 2.0 + ey, 0.3 + eyaw))
    assert seen.held == "cube" and seen.joints == t.state.joints


def test_zero_noise_is_off_and_the_realistic_preset_is_the_issues_numbers() -> None:
    assert Noise().off and load_noise("none").off
    r = load_noise("realistic")
    assert not r.off and "realistic" in noise_presets()
    assert (r.object_m, r.object_deg, r.base_m, r.latency_s, r.drop) == (0.003, 2.5, 0.01, 0.1, 0.05)


@pytest.mark.parametrize("mapping, needle", [
    ({"object_m": -0.01}, "execute.noise.object_m = -0.01"),
    ({"drop": 1.0}, "execute.noise.drop = 1.0"),
    ({"latency": 0.1}, "latency"),
    ({"every": 0}, "execute.noise.every = 0"),
])
def test_bad_noise_keys_are_refused_in_one_line(mapping: dict, needle: str) -> None:
    with pytest.raises(ConfigError) as e:
        Noise.from_mapping(mapping)
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_an_unknown_noise_preset_names_the_presets() -> None:
    with pytest.raises(ConfigError, match="realistic"):
        load_noise("foggy")


def test_the_script_refuses_bad_noise_before_anything_runs(tmp_path) -> None:
    (tmp_path / "result.json").write_text("{}")
    bad = tmp_path / "noise.yaml"
    bad.write_text("object_m: -1\n")
    for arg in (str(bad),):  # (an unknown preset name: test_an_unknown_noise_preset_names_the_presets)
        p = subprocess.run([sys.executable, str(REPO / "scripts" / "execute.py"), str(tmp_path), "--noise", arg],
                           capture_output=True, text=True, timeout=120)
        assert p.returncode == 2, p.stderr
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error:"), p.stderr
