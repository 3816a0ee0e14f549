"""docs/task_files.md stays true: its complete example is a valid task equal to the seed task,
and it names every region type, every task key and every goal predicate the reader accepts."""

from __future__ import annotations

import re

import yaml

from helpers import doc_block
from realize.world.geometry import GeometryCfg, build_geometry
from realize.tasks.goal_spec import GOAL_KEYS
from realize.tasks.param_layout import REGION_TYPES
from realize.paths import CONFIG_DIR
from realize.spec.task_plans import build_task, load_task_file

DOC = CONFIG_DIR.parent / "docs" / "task_files.md"


def test_the_example_is_the_seed_task() -> None:
    block = doc_block("docs/task_files.md", "yaml")
    geometry = build_geometry(GeometryCfg())
    example = build_task(yaml.safe_load(block.text), geometry, "docs/task_files.md")
    seed_d, src = load_task_file(str(CONFIG_DIR / "task" / "pick_place.yaml"))
    seed = build_task(seed_d, geometry, src)
    assert example.describe() == seed.describe() and example.goal == seed.goal
    assert example.layout.column_names == seed.layout.column_names
    assert example.layout.regions == seed.layout.regions  # every region whole: type, centre, radii, box corners, yaw
    assert example.final_cost == seed.final_cost


def test_every_key_type_and_goal_is_documented() -> None:
    text = DOC.read_text()
    for kind in REGION_TYPES:
        assert f"`{kind}`" in text, kind
    for key in ("name", "params", "plan", "goal", "final_cost", "planner", "frame"):
        assert re.search(rf"`{key}:?`", text), key
    for goal in GOAL_KEYS:
        assert f"`{goal}`" in text, goal
