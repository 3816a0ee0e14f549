"""Regenerate the reference fixtures for ``realize.controllers.fabrics``.

The reference is the ``fabrics`` PyPI package (casadi based), planner
``ParameterizedFabricPlanner`` with its default configuration
(``forcing_type='speed-controlled'``, default geometries, Finsler structures,
attractor and damper). The package pins ``numpy<2`` while this project needs
numpy 2, so it lives in a throw-away side environment that is NOT part of the
project and never committed::

    python3 -m venv /tmp/fabrics-ref-venv
    /tmp/fabrics-ref-venv/bin/pip install "numpy<2" casadi
    /tmp/fabrics-ref-venv/bin/pip install --no-deps \
        fabrics==0.10.0 forwardkinematics==1.2.3 mpscenes==0.4.6 \
        deprecation pyquaternion packaging urdf_parser_py pyyaml omegaconf \
        "antlr4-python3-runtime==4.9.3" sympy mpmath geomdl
    /tmp/fabrics-ref-venv/bin/python scripts/make_fabrics_fixtures.py

(the ``--no-deps`` list is the minimal set the planner's imports need; the
package's other declared dependencies, e.g. pynput or pytest, are not used.)

Two systems are built, each with one spherical (circular) obstacle, a goal
attractor on the end effector and joint-limit avoidance:

* ``point_mass``: 2 DOF, x = q, one collision sphere at x;
* ``planar_arm``: 2 revolute joints, link lengths ``ARM_LENGTHS``, collision
  spheres at the middle of link 1, the elbow and the end effector.

For each, ``N_STATES`` random states (q, qdot, goal, goal weight, obstacle
centre and radius, body radii) are drawn (collision points strictly outside
the obstacle, q strictly inside the limits) and the planner's
``compute_action`` (joint accelerations) is evaluated in float64. Inputs and
outputs go to ``tests/fixtures/fabrics_<system>.npz`` (plain float arrays,
loadable with ``allow_pickle=False``).

The forward maps below are the same ones the torch tests use
(``tests/test_fabrics.py``), written once in casadi here and once in torch
there.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import casadi as ca
import numpy as np
from forwardkinematics.fksCommon.fk import ForwardKinematics
from mpscenes.goals.goal_composition import GoalComposition

from fabrics.planner.parameterized_planner import ParameterizedFabricPlanner

N_STATES = 256
ARM_LENGTHS = (1.0, 0.8)
FIXTURE_DIR = Path(__file__).resolve().parents[1] / "tests" / "fixtures"


class _SymbolicFk(ForwardKinematics):
    """Minimal ForwardKinematics: named links -> casadi position expressions."""

    def __init__(self, n: int, links):
        super().__init__()
        self._n = n
        self._links = links  # name -> callable(q SX) -> SX (2,)

    def casadi(self, q, child_link, parent_link=None, link_transformation=None, position_only=False):
        if child_link in self._links:
            return self._links[child_link](q)
        return ca.SX(np.zeros(2))  # the base frame (goal parent link)


def _point_mass_links():
    return {"body": lambda q: q[0:2]}


def _arm_links():
    l1, l2 = ARM_LENGTHS

    def elbow(q):
        return ca.vertcat(l1 * ca.cos(q[0]), l1 * ca.sin(q[0]))

    def mid1(q):
        return ca.vertcat(0.5 * l1 * ca.cos(q[0]), 0.5 * l1 * ca.sin(q[0]))

    def ee(q):
        return elbow(q) + ca.vertcat(l2 * ca.cos(q[0] + q[1]), l2 * ca.sin(q[0] + q[1]))

    return {"link1_mid": mid1, "elbow": elbow, "ee": ee}


def _numeric_links(system: str, q: np.ndarray) -> np.ndarray:
    """(K, 2) collision points, same order as the collision link list."""
    if system == "point_mass":
        return q[None, :].copy()
    l1, l2 = ARM_LENGTHS
    elbow = l1 * np.array([np.cos(q[0]), np.sin(q[0])])
    ee = elbow + l2 * np.array([np.cos(q[0] + q[1]), np.sin(q[0] + q[1])])
    return np.stack([0.5 * elbow, elbow, ee])


SYSTEMS = {
    "point_mass": dict(
        links=_point_mass_links, collision=["body"], ee="body",
        lower=np.array([-4.0, -4.0]), upper=np.array([4.0, 4.0]),
    ),
    "planar_arm": dict(
        links=_arm_links, collision=["link1_mid", "elbow", "ee"], ee="ee",
        lower=np.array([-2.8, -2.6]), upper=np.array([2.8, 2.6]),
    ),
}


def build_planner(system: str) -> ParameterizedFabricPlanner:
    spec = SYSTEMS[system]
    fk = _SymbolicFk(2, spec["links"]())
    goal = GoalComposition(name="goal", content_dict={
        "subgoal0": {
            "weight": 1.0, "is_primary_goal": True, "indices": [0, 1],
            "parent_link": "base", "child_link": spec["ee"],
            "desired_position": [0.0, 0.0], "epsilon": 0.05, "type": "staticSubGoal",
        }
    })
    planner = ParameterizedFabricPlanner(2, fk)  # all defaults: speed-controlled
    limits = np.stack([spec["lower"], spec["upper"]], axis=1).tolist()
    planner.set_components(
        collision_links=spec["collision"], goal=goal, number_obstacles=1, limits=limits,
    )
    planner.concretize()
    return planner


def sample_states(system: str, n: int, rng: np.random.Generator) -> dict:
    spec = SYSTEMS[system]
    lower, upper = spec["lower"], spec["upper"]
    K = len(spec["collision"])
    out = {k: [] for k in ("q", "qdot", "goal", "weight", "obst", "body_radii")}
    while len(out["q"]) < n:
        span = upper - lower
        q = rng.uniform(lower + 0.05 * span, upper - 0.05 * span)
        i = len(out["q"])
        if i % 16 == 0:
            qdot = np.zeros(2)  # exercises sign(0) in the geometries
        elif i % 16 == 1:
            qdot = np.array([rng.normal(), 0.0])
        else:
            qdot = rng.normal(scale=rng.choice([0.1, 1.0, 2.0]), size=2)
        reach = 4.0 if system == "point_mass" else sum(ARM_LENGTHS)
        goal = rng.uniform(-reach, reach, size=2)
        weight = rng.uniform(0.3, 3.0)
        centre = rng.uniform(-reach, reach, size=2)
        radius = rng.uniform(0.1, 0.8)
        radii = rng.uniform(0.05, 0.3, size=K)
        pts = _numeric_links(system, q)
        phi = np.linalg.norm(pts - centre, axis=1) / (radius + radii) - 1.0
        if phi.min() < 0.1:
            continue
        out["q"].append(q)
        out["qdot"].append(qdot)
        out["goal"].append(goal)
        out["weight"].append(weight)
        out["obst"].append(np.concatenate([centre, [radius]]))
        out["body_radii"].append(radii)
    return {k: np.asarray(v, dtype=np.float64) for k, v in out.items()}


def evaluate(system: str, planner, states: dict) -> np.ndarray:
    spec = SYSTEMS[system]
    actions = []
    for i in range(states["q"].shape[0]):
        kwargs = dict(
            q=states["q"][i], qdot=states["qdot"][i],
            x_goal_0=states["goal"][i], weight_goal_0=states["weight"][i],
            x_obst_0=states["obst"][i, :2], radius_obst_0=states["obst"][i, 2],
        )
        for name, r in zip(spec["collision"], states["body_radii"][i]):
            kwargs[f"radius_body_{name}"] = r
        actions.append(np.asarray(planner.compute_action(**kwargs), dtype=np.float64))
    return np.stack(actions)


def main() -> None:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--n", type=int, default=N_STATES)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=FIXTURE_DIR)
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    args.out.mkdir(parents=True, exist_ok=True)
    for j, system in enumerate(SYSTEMS):
        rng = np.random.default_rng(args.seed + j)
        planner = build_planner(system)
        states = sample_states(system, args.n, rng)
        qddot = evaluate(system, planner, states)
        spec = SYSTEMS[system]
        path = args.out / f"fabrics_{system}.npz"
        np.savez_compressed(
            path, qddot=qddot, lower=spec["lower"], upper=spec["upper"],
            arm_lengths=np.asarray(ARM_LENGTHS), **states,
        )
        print(f"{path.name}: {qddot.shape[0]} states, |qddot| max {np.abs(qddot).max():.3g}")


if __name__ == "__main__":
    main()
