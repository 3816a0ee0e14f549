"""Where a replan's whole plan starts holding something (``realize.spec.run_spec._replan_start_held``):
a replan from action 0 starts from its own state; a replan of later actions starts the plan where
the run it replans started it, followed back through a chain of replans. grasp_slip world 14 (seed 0,
``d97601a``): the restack from cube C in hand begins ``place(cube_c, ...)``; its tower knocked again,
the re-sequence planned that restack's last four actions, a replan of it from action 1, and the whole
plan was checked from an empty hand and refused in one line, so the world was lost."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

from realize.spec.run_spec import _replan_start_held
from realize.world.state import ObjectPose, SceneState, save_state


def _run(path: Path, config: dict) -> Path:
    path.mkdir(parents=True)
    (path / "result.json").write_text(json.dumps({"status": "done", "config": config}))
    return path


def _state(path: Path, held: str | None) -> str:
    objects = {"cube_c": ObjectPose((0.0, 1.2, 0.9))}
    return str(save_state(SceneState(base=(0.0, 0.0, 0.0), objects=objects, held=held, gripper_closed=held is not None),
                          path))


def test_a_replan_of_later_actions_starts_the_plan_where_its_first_run_started_it(tmp_path: Path) -> None:
    first = _run(tmp_path / "restack", {"replan_from": str(tmp_path), "replan": {"action": 0, "state": _state(
        tmp_path / "held.json", "cube_c")}})
    second = _run(tmp_path / "again", {"replan_from": str(first), "replan": {"action": 1, "state": _state(
        tmp_path / "empty1.json", None)}})
    empty = _state(tmp_path / "empty2.json", None)
    assert _replan_start_held(SimpleNamespace(replan_from=str(first)), {"replan": {"action": 1, "state": empty}}) \
        == "cube_c"
    assert _replan_start_held(SimpleNamespace(replan_from=str(second)), {"replan": {"action": 2, "state": empty}}) \
        == "cube_c"  # two replans back
    assert _replan_start_held(SimpleNamespace(replan_from=str(first)), {"replan": {"action": 0, "state": empty}}) is None
    plain = _run(tmp_path / "plain", {"seed": 0})  # a search, not a replan: its plan starts with an empty hand
    assert _replan_start_held(SimpleNamespace(replan_from=str(plain)), {"replan": {"action": 2, "state": empty}}) is None
    assert _replan_start_held(SimpleNamespace(replan_from=None), {"replan": None}) is None
