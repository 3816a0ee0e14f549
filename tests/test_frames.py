"""Regions in object frames (realize/tasks/frames.py): they follow their object through the scene config."""

from __future__ import annotations

import pytest
import torch

from realize.config import ConfigError
from realize.tasks.frames import Frame, move_points, object_frames, place_region
from realize.world.geometry import GeometryCfg, build_geometry
from realize.tasks.param_layout import region_from_dict
from realize.realization.actions import TEMPLATES
from realize.tasks.spec import task_from_dict
from helpers import compose_config

WORLD_SEED_TASK = {  # the seed paper's regions as the task config wrote them before frames
    "Table1": {"type": "annulus", "center": [0.0, 1.2], "r_min": 0.75, "r_max": 1.25},
    "Cube_g": {"type": "hemisphere", "center": [0.0, 1.2, 0.7425], "radius": 0.15, "polar_max": 1.3},
    "Table2": {"type": "annulus", "center": [0.0, -1.2], "r_min": 0.75, "r_max": 1.25},
    "Cube_p": {"type": "hemisphere", "center": [0.0, -1.2, 0.7475], "radius": 0.15, "polar_max": 1.3},
    "Exit": {"type": "box", "low": [1.8, -0.4], "high": [2.6, 0.4]},
}


def _task(*overrides: str):
    from realize.spec.run_spec import build_run_spec

    return build_run_spec(compose_config(*overrides)).task


def test_object_frames_of_the_default_scene_are_the_seed_task_world_regions():
    task = _task()
    assert task.frames == {"Table1": "table1", "Cube_g": "cube", "Table2": "table2", "Cube_p": "table2"}
    for name, d in WORLD_SEED_TASK.items():
        assert task.layout.regions[name] == region_from_dict(d, name), name  # equal to the last bit


def test_moving_the_cube_and_table2_moves_their_regions():
    base = _task().layout.regions
    moved = _task("scene.objects.cube.offset=[0.06,-0.05]", "scene.tables.1.center=[0.3,-1.5]").layout.regions
    assert moved["Cube_g"].center == pytest.approx((0.06, 1.15, 0.7425), abs=1e-12)
    assert moved["Table2"].center == pytest.approx((0.3, -1.5), abs=1e-12)
    assert moved["Cube_p"].center == pytest.approx((0.3, -1.5, 0.7475), abs=1e-12)
    assert moved["Table1"] == base["Table1"] and moved["Exit"] == base["Exit"]


def test_a_taller_table_lifts_the_regions_on_it():
    moved = _task("scene.tables.1.height=0.8").layout.regions
    assert moved["Cube_p"].center == pytest.approx((0.0, -1.2, 0.8275), abs=1e-12)


def _one_region_task(region: dict):
    scene = build_geometry(GeometryCfg())
    d = {"name": "t", "params": {"P": region, "Exit": WORLD_SEED_TASK["Exit"]},
         "plan": ["move_to(Exit)"], "goal": {}}
    return task_from_dict(d, scene, TEMPLATES, source="t.yaml")


def test_unknown_frame_is_refused_naming_the_key_and_the_frames():
    with pytest.raises(ConfigError, match=r"t.yaml:params.P.frame = 'tabel2' is invalid: .*'table2'"):
        _one_region_task({"type": "annulus", "frame": "tabel2", "center": [0, 0], "r_min": 0.5, "r_max": 1.0})


def test_a_region_that_is_not_a_position_cannot_follow_an_object():
    with pytest.raises(ConfigError, match=r"params.P.frame = 'cube' is invalid: a box region of dimension 1"):
        _one_region_task({"type": "box", "frame": "cube", "low": [0.0], "high": [1.0]})


def test_move_points_carries_rows_with_their_frame_and_back():
    region = place_region(region_from_dict(WORLD_SEED_TASK["Cube_g"], "g"), Frame("world", (0, 0, 0)), "g")
    old, new = Frame("cube", (0.0, 1.2, 0.7425)), Frame("cube", (0.06, 1.15, 0.7425))
    z = region.sample_uniform(8, torch.Generator().manual_seed(0), torch.float64)
    moved = move_points(z, region, old, new)
    assert torch.allclose(moved - z, torch.tensor([0.06, -0.05, 0.0], dtype=torch.float64).expand(8, 3))
    assert torch.allclose(move_points(moved, region, new, old), z)
    frames = object_frames(build_geometry(GeometryCfg()))
    assert set(frames) == {"world", "cube", "table1", "table2"}
