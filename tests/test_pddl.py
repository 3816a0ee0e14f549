"""PDDL bridge: real Fast Downward / SymK runs on the shipped domains, plus every error path."""

from __future__ import annotations

from pathlib import Path

import pytest
import unified_planning.shortcuts as ups

from realize.tasks.pddl import PlannedAction, PlanningError, plan_from_pddl

PDDL_DIR = Path(__file__).resolve().parents[1] / "configs" / "pddl"
SEED_DOMAIN = PDDL_DIR / "pick_place_domain.pddl"
SEED_PROBLEM = PDDL_DIR / "pick_place_problem.pddl"
DEMO_DOMAIN = PDDL_DIR / "carry_or_push_domain.pddl"
DEMO_PROBLEM = PDDL_DIR / "carry_or_push_problem.pddl"

TEMPLATES = ("move_to", "grasp", "place", "push")
SEED_PARAMS = ("Table1", "Cube_g", "Table2", "Cube_p", "Exit")
DEMO_PARAMS = ("PushSide", "Stick_p", "StickSide", "BoxSide", "Cube_g", "Cube_p")
SEED_OBJECTS = ("cube",)  # scene.objects of the seed scene
DEMO_OBJECTS = ("stick", "cube")  # and of scene=carry_or_push


def A(template: str, *params: str, obj: str | None = None) -> PlannedAction:
    return PlannedAction(template, params, obj)


SEED_PLAN = [
    A("move_to", "Table1"),
    A("grasp", "Cube_g", obj="cube"),
    A("move_to", "Table2"),
    A("place", "Cube_p", obj="cube"),
    A("move_to", "Exit"),
]
PUSH_PLAN = [A("move_to", "PushSide"), A("push", "Stick_p", obj="stick")]  # push handles the stick, not the cube
CARRY_PLAN = [A("move_to", "StickSide"), A("grasp", "Cube_g", obj="cube"), A("place", "Cube_p", obj="cube")]
CARRY_DRIVE_PLAN = [A("move_to", "StickSide"), A("grasp", "Cube_g", obj="cube"), A("move_to", "BoxSide"),
                    A("place", "Cube_p", obj="cube")]


def _variant(tmp_path: Path, src: Path, old: str, new: str) -> Path:
    text = src.read_text()
    assert old in text, f"{old!r} not in {src.name}"
    out = tmp_path / src.name
    out.write_text(text.replace(old, new))
    return out


def test_seed_problem_plans_the_seed_plan(capsys: pytest.CaptureFixture[str]) -> None:
    plans = plan_from_pddl(SEED_DOMAIN, SEED_PROBLEM, TEMPLATES, SEED_PARAMS, objects=SEED_OBJECTS)
    assert plans == [SEED_PLAN]
    assert [str(a) for a in plans[0]] == [
        "move_to(Table1)", "grasp(cube, Cube_g)", "move_to(Table2)", "place(cube, Cube_p)", "move_to(Exit)",
    ]
    assert capsys.readouterr().out == ""  # no planner credits or logs on stdout


def test_top_k_demo_returns_the_three_skeletons_cheapest_first() -> None:
    plans = plan_from_pddl(DEMO_DOMAIN, DEMO_PROBLEM, TEMPLATES, DEMO_PARAMS, objects=DEMO_OBJECTS, top_k=3)
    # unit costs 2, 3 and 4; the one-way road graph leaves only one other (useless) 4-action
    # plan, carry then drive to BoxSide, which the fixed order of equally long plans puts 4th
    assert plans == [PUSH_PLAN, CARRY_PLAN, CARRY_DRIVE_PLAN]
    assert plan_from_pddl(DEMO_DOMAIN, DEMO_PROBLEM, TEMPLATES, DEMO_PARAMS, objects=DEMO_OBJECTS,
                          top_k=2) == [PUSH_PLAN, CARRY_PLAN]
    assert len({tuple(p) for p in plans}) == len(plans)
    assert [len(p) for p in plans] == sorted(len(p) for p in plans)


def test_top_k_drops_duplicates_and_keeps_order_on_seed() -> None:
    plans = plan_from_pddl(SEED_DOMAIN, SEED_PROBLEM, TEMPLATES, SEED_PARAMS, objects=SEED_OBJECTS, top_k=3)
    assert plans[0] == SEED_PLAN
    assert len(plans) == 3 and len({tuple(p) for p in plans}) == 3
    assert [len(p) for p in plans] == sorted(len(p) for p in plans)


def test_mapping_is_case_insensitive_and_keeps_task_spelling() -> None:
    params = ("TABLE1", "cube_G", "table2", "Cube_P", "eXit")
    templates = ("Move_To", "GRASP", "place")
    (plan,) = plan_from_pddl(SEED_DOMAIN, SEED_PROBLEM, templates, params, objects=("Cube",))
    assert plan == [
        A("Move_To", "TABLE1"),
        A("GRASP", "cube_G", obj="Cube"),
        A("Move_To", "table2"),
        A("place", "Cube_P", obj="Cube"),
        A("Move_To", "eXit"),
    ]


def test_untyped_domain_maps_every_argument(tmp_path: Path) -> None:
    domain = tmp_path / "d.pddl"
    problem = tmp_path / "p.pddl"
    domain.write_text(
        "(define (domain hop) (:requirements :strips)"
        " (:predicates (at ?x) (link ?x ?y))"
        " (:action move_to :parameters (?from ?to)"
        "  :precondition (and (at ?from) (link ?from ?to))"
        "  :effect (and (not (at ?from)) (at ?to))))"
    )
    problem.write_text(
        "(define (problem p) (:domain hop) (:objects Start Goal)"
        " (:init (at Start) (link Start Goal)) (:goal (at Goal)))"
    )
    plans = plan_from_pddl(domain, problem, ["move_to"], ["Start", "Goal"])
    assert plans == [[A("move_to", "Start", "Goal")]]


@pytest.mark.parametrize("which", ["domain", "problem"])
def test_missing_file_is_named(tmp_path: Path, which: str) -> None:
    missing = tmp_path / f"no_{which}.pddl"
    args = (missing, SEED_PROBLEM) if which == "domain" else (SEED_DOMAIN, missing)
    with pytest.raises(PlanningError, match=rf"{which} file not found: .*no_{which}\.pddl"):
        plan_from_pddl(*args, TEMPLATES, SEED_PARAMS)


def test_domain_parse_error_names_domain_file(tmp_path: Path) -> None:
    old = ":effect (and (not (holding ?c))"
    bad = _variant(tmp_path, SEED_DOMAIN, old, old[:-1])  # unbalanced parentheses
    with pytest.raises(PlanningError, match=r"cannot parse PDDL domain .*pick_place_domain\.pddl"):
        plan_from_pddl(bad, SEED_PROBLEM, TEMPLATES, SEED_PARAMS)


def test_problem_parse_error_names_problem_file(tmp_path: Path) -> None:
    bad = _variant(tmp_path, SEED_PROBLEM, "(robot-at loc_start)", "(robot-at loc_nowhere)")
    msg = r"cannot parse PDDL problem .*pick_place_problem\.pddl"
    with pytest.raises(PlanningError, match=msg) as exc:
        plan_from_pddl(SEED_DOMAIN, bad, TEMPLATES, SEED_PARAMS)
    assert "loc_nowhere" in str(exc.value)  # the parser's own message is kept


def test_action_without_template_is_named_with_known_templates() -> None:
    with pytest.raises(PlanningError) as exc:
        plan_from_pddl(SEED_DOMAIN, SEED_PROBLEM, ("move_to", "grasp"), SEED_PARAMS)
    msg = str(exc.value)
    assert "pick_place_domain.pddl" in msg
    assert "'place' matches no action template" in msg
    assert "['grasp', 'move_to']" in msg


def test_argument_without_param_is_named_with_action_and_params() -> None:
    params = ("Table1", "Cube_g", "Table2", "Cube_p")  # no Exit
    with pytest.raises(PlanningError) as exc:
        plan_from_pddl(SEED_DOMAIN, SEED_PROBLEM, TEMPLATES, params)
    msg = str(exc.value)
    assert "pick_place_problem.pddl" in msg
    assert "argument 'exit'" in msg
    assert "move_to(exit, loc_table2, loc_exit)" in msg
    assert "['Cube_g', 'Cube_p', 'Table1', 'Table2']" in msg


@pytest.mark.parametrize("top_k", [1, 2])
def test_unsolvable_problem_says_so(tmp_path: Path, top_k: int) -> None:
    # without a place pose on table 2 the cube can never get there
    bad = _variant(tmp_path, SEED_PROBLEM, "(place-on Cube_p cube loc_table2)", "")
    msg = r"found no plan .*pick_place_problem\.pddl.*UNSOLVABLE_\w+ \(the problem is unsolvable"
    with pytest.raises(PlanningError, match=msg):
        plan_from_pddl(SEED_DOMAIN, bad, TEMPLATES, SEED_PARAMS, top_k=top_k)


def test_timeout_is_reported() -> None:
    with pytest.raises(PlanningError, match=r"status TIMEOUT \(timed out after timeout_s=0\.001\)"):
        plan_from_pddl(SEED_DOMAIN, SEED_PROBLEM, TEMPLATES, SEED_PARAMS, timeout_s=0.001)


@pytest.mark.parametrize(("top_k", "package"), [(1, "up-fast-downward"), (3, "up-symk")])
def test_missing_engine_names_the_pip_package(
    monkeypatch: pytest.MonkeyPatch, top_k: int, package: str
) -> None:
    factory = ups.get_environment().factory
    monkeypatch.setattr(type(factory), "engines", property(lambda self: []))
    with pytest.raises(PlanningError, match=rf"not installed: pip install {package}"):
        plan_from_pddl(SEED_DOMAIN, SEED_PROBLEM, TEMPLATES, SEED_PARAMS, top_k=top_k)


def test_case_only_param_clash_and_bad_top_k() -> None:
    with pytest.raises(PlanningError, match="differ only in case"):
        plan_from_pddl(SEED_DOMAIN, SEED_PROBLEM, TEMPLATES, (*SEED_PARAMS, "exit"))
    with pytest.raises(PlanningError, match="top_k"):
        plan_from_pddl(SEED_DOMAIN, SEED_PROBLEM, TEMPLATES, SEED_PARAMS, top_k=0)


# ------------------------------------------------------------------------------ the blocks domain
BLOCKS_DOMAIN = PDDL_DIR / "blocks_domain.pddl"
TOWER_PARAMS = ("CubeA_g", "CubeB_g", "CubeC_g", "CubeB_on_a", "CubeC_on_b")
BLOCKS = ("cube_a", "cube_b", "cube_c")


def test_tower3_plans_bottom_up_and_binds_to_grasp_and_place() -> None:
    """Three blocks on the table: cube_b onto cube_a, then cube_c onto cube_b; the supports
    (cube_a, the table) are bookkeeping, the handled block is the first block argument."""
    plans = plan_from_pddl(BLOCKS_DOMAIN, PDDL_DIR / "tower3_problem.pddl", TEMPLATES, TOWER_PARAMS, objects=BLOCKS)
    assert plans == [[A("grasp", "CubeB_g", obj="cube_b"), A("place", "CubeB_on_a", obj="cube_b"),
                      A("grasp", "CubeC_g", obj="cube_c"), A("place", "CubeC_on_b", obj="cube_c")]]


def test_blocks_unstack_to_the_table_before_restacking(tmp_path: Path) -> None:
    """cube_b starts on cube_a; the goal is cube_a on cube_b: cube_b must come off (onto a table
    spot) first, and a table stays clear for every block put on it (ontable holds after)."""
    problem = tmp_path / "swap.pddl"
    problem.write_text("""(define (problem swap) (:domain blocks)
  (:objects CubeA_g CubeB_g - grasp_region CubeB_t CubeA_on_b - place_region cube_a cube_b - block table1 - table)
  (:init (hand-empty) (on cube_a table1) (ontable cube_a) (on cube_b cube_a) (clear cube_b) (clear table1)
         (is-block cube_a) (is-block cube_b) (is-table table1) (grasps CubeA_g cube_a) (grasps CubeB_g cube_b)
         (place-on CubeB_t cube_b table1) (place-on CubeA_on_b cube_a cube_b))
  (:goal (and (on cube_a cube_b) (ontable cube_b))))""")
    plans = plan_from_pddl(BLOCKS_DOMAIN, problem, TEMPLATES, ("CubeA_g", "CubeB_g", "CubeB_t", "CubeA_on_b"),
                           objects=BLOCKS[:2])
    assert plans == [[A("grasp", "CubeB_g", obj="cube_b"), A("place", "CubeB_t", obj="cube_b"),
                      A("grasp", "CubeA_g", obj="cube_a"), A("place", "CubeA_on_b", obj="cube_a")]]


def test_the_planner_runs_in_a_private_working_directory(tmp_path, monkeypatch) -> None:
    """Fast Downward's driver writes output.sas into its working directory (and deletes it at
    the end); the planner subprocess runs in a private one, so planners started at once from one
    directory (a sweep's jobs, two studies) cannot read each other's, and the caller's
    directory is left as it was."""
    import os
    import subprocess

    monkeypatch.chdir(tmp_path)
    started_in: list[str] = []
    real = subprocess.Popen

    def popen(*args, **kwargs):  # the planner's subprocess inherits the working directory
        started_in.append(kwargs.get("cwd") or os.getcwd())
        return real(*args, **kwargs)

    monkeypatch.setattr(subprocess, "Popen", popen)
    for top_k in (1, 2):
        assert plan_from_pddl(SEED_DOMAIN, SEED_PROBLEM, TEMPLATES, SEED_PARAMS, objects=SEED_OBJECTS, top_k=top_k)
    assert len(started_in) >= 2 and str(tmp_path) not in started_in
    assert len(set(started_in)) == len(started_in)  # a directory of its own each time
    assert os.getcwd() == str(tmp_path) and list(tmp_path.iterdir()) == []
