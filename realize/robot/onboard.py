"""One command from a URDF to a checked robot config draft: ``python -m realize.robot.onboard NAME --urdf PATH``.

What it does: :func:`onboard_robot` surveys the URDF (``realize.robot.urdf_survey``: gripper,
finger links, open side, base, arm chain, TCP), fits the collision spheres
(``realize.robot.robot_spheres``, as ``scripts/fit_spheres.py``), drafts
``configs/robot/NAME.yaml`` (every choice a comment in its header), reads the draft as ``realize``
reads a robot config and runs the checks a run's config load runs (the URDF's names,
``realize.robot.urdf_names``; the gripper's geometry, ``realize.robot.grip_geometry``, whose
measured fingertip reach and pad width it writes in), writes the config and the sphere file only
once they pass, and returns an :class:`Onboarded` with a short report: what it chose and why (one
line each), what the user must still check.

Drive gains are the documented defaults of ``realize.robot.spec`` (``Drive``, ``GripperSpec``),
not calibrated; a fixed base is mounted ``--height`` (0.72 m) up, as the Panda and SO-100.

Anything it cannot decide is one ``ConfigError`` line (the CLI prints it as ``error:``, exit 2)
naming the URDF and what is missing, or the flag that settles it (``--gripper-joints``,
``--tcp-link``). An existing config is replaced only with ``--force``.

What it doesn't: calibrate the gripper or the drives by simulation, write a scene or task for
the robot, or run the kinematics tests and the smoke run (the report names them).
"""

from __future__ import annotations

import argparse
import math
import os
import shlex
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import yaml

from realize.config import ConfigError
from realize.paths import REPO_ROOT
from realize.robot.grip_geometry import GripGeometry, grip_geometry
from realize.robot.link_geometry import collision_links, link_geometry
from realize.robot.robot_spheres import FITTED_MARK, FitSettings, fit_robot_spheres, write_fitted_spheres
from realize.robot.sphere_file import SPHERE_DIR, load_spheres
from realize.robot.spec import ROBOT_CONFIG_DIR, Drive, GripperSpec, RobotSpec
from realize.robot.urdf import MANI_SKILL_PREFIX, source_urdf
from realize.robot.urdf_names import check_urdf_names
from realize.robot.urdf_survey import Survey, survey_urdf

__all__ = ["Onboarded", "onboard_robot", "urdf_reference", "main"]

FIXED_HEIGHT = 0.72  # m: a fixed base's stand, level with a 0.72 m table top (the Panda's and SO-100's)


@dataclass
class Onboarded:
    """What :func:`onboard_robot` wrote and found."""

    config_path: Path
    spheres_path: Path
    spec: RobotSpec
    survey: Survey
    geometry: GripGeometry
    chose: list[str] = field(default_factory=list)  # one line per choice, with its reason
    todo: list[str] = field(default_factory=list)  # what the user must still check

    def report(self) -> str:
        return "\n".join([f"drafted {_shown(self.config_path)} and {_shown(self.spheres_path)}; chose:",
                          *(f"  - {c}" for c in self.chose), "still to check:", *(f"  - {t}" for t in self.todo)])


def _shown(p: Path) -> str:
    try:
        return str(p.resolve().relative_to(REPO_ROOT))
    except ValueError:
        return str(p)


def urdf_reference(urdf: str) -> str:
    """The config's ``urdf`` for a path given on the command line: ``mani_skill:<path>`` inside
    ManiSkill's assets, a repository-relative path inside the repository, else the path as given."""
    if urdf.startswith(MANI_SKILL_PREFIX):
        return urdf
    p = Path(urdf).resolve()
    try:
        import mani_skill

        return MANI_SKILL_PREFIX + str(p.relative_to(Path(mani_skill.PACKAGE_ASSET_DIR).resolve()))
    except (ImportError, ValueError):
        pass
    try:
        return str(p.relative_to(REPO_ROOT))
    except ValueError:
        return str(p)


def _footprint(path: Path, link: str) -> tuple[float, str]:
    if link not in collision_links(path):
        return 0.32, f"base.footprint_radius 0.32 m (the default: {link} has no collision geometry)"
    v = link_geometry(path, link).vertices
    r = math.ceil(float(np.hypot(v[:, 0], v[:, 1]).max()) * 100) / 100
    return r, f"base.footprint_radius {r} m ({link}'s collision geometry reaches that far from its axis)"


MESH_EXTS = (".glb", ".obj", ".stl", ".dae", ".ply")  # where a visual mesh is missing, the shipped file it may be


def _visual_mesh_ext(path: Path) -> tuple[dict[str, str] | None, str | None]:
    """``visual_mesh_ext`` where the URDF names visual meshes that are missing but ship with another
    extension (ManiSkill's mobile Panda: .dae named, .glb shipped); a mesh found under no extension
    is a one-line ``ConfigError``."""
    from realize.robot.urdf import mesh_file, read_urdf

    swap: dict[str, str] = {}
    for el in read_urdf(path).iter("visual"):
        for m in el.iter("mesh"):
            name = m.get("filename", "")
            try:
                mesh_file(name, path)
                continue
            except ConfigError as e:
                missing = e
            stem, ext = os.path.splitext(name)
            if ext in swap:
                continue
            for other in MESH_EXTS:
                try:
                    mesh_file(stem + other, path)
                    swap[ext] = other
                    break
                except ConfigError:
                    pass
            else:
                raise missing
    if not swap:
        return None, None
    return swap, f"visual_mesh_ext {swap} (the URDF's visual meshes of those extensions are missing; these are shipped)"


def _srdf_pairs(path: Path) -> list[list[str]]:
    """An SRDF beside the URDF: its disabled pairs of reason "Default" that are not parent and child."""
    srdf = path.with_suffix(".srdf")
    if not srdf.is_file():
        return []
    from realize.robot.urdf import parse_urdf_joints

    adjacent = {frozenset((j.parent, j.child)) for j in parse_urdf_joints(str(path)).values()}
    out = set()
    for d in ET.parse(srdf).getroot().iter("disable_collisions"):
        a, b = d.get("link1", ""), d.get("link2", "")
        if d.get("reason") == "Default" and frozenset((a, b)) not in adjacent:
            out.add(tuple(sorted((a, b))))
    return [list(p) for p in sorted(out)]


def _hand_links(path: Path, s: Survey) -> list[str]:
    from realize.robot.urdf import parse_urdf_joints

    joints = parse_urdf_joints(str(path))
    under, todo = [s.gripper.hand_link], [s.gripper.hand_link]
    while todo:
        l = todo.pop()
        kids = [j.child for j in joints.values() if j.parent == l]
        under += kids
        todo += kids
    have = set(collision_links(path))
    return [l for l in under if l in have]


def _default(cls: type, key: str) -> float:
    return float(cls.__dataclass_fields__[key].default)  # type: ignore[attr-defined]


def _mapping(name: str, urdf: str, mesh_ext: dict[str, str] | None, s: Survey, spheres_file: str, height: float,
             footprint: float, hand: list[str], pairs: list[list[str]], reach: float, pad: float) -> dict[str, Any]:
    g = s.gripper
    d = {k: _default(Drive, k) for k in ("stiffness", "damping", "force")}
    gd = {k: _default(GripperSpec, k) for k in ("stiffness", "damping", "force")}
    base: dict[str, Any] = {"joints": list(s.base_joints), "link": s.base_link,
                            "height": 0.0 if s.base_joints else height, "footprint_radius": footprint}
    return {
        "name": name, "urdf": urdf, **({"visual_mesh_ext": mesh_ext} if mesh_ext else {}), "base": base,
        "upper": {"joints": list(s.upper), "drives": [{"joints": list(s.upper), **d}]},
        "held": dict(s.held),
        "held_drive": {"stiffness": 1.0e5, "damping": 1.0e4, "force": 1.0e4},
        "gripper": {"joints": list(g.joints), "finger_links": list(g.finger_links), "open": g.open,
                    "closed": round(g.closed, 6), **gd,
                    "fingertip_reach": reach, "pad_half_width": pad},
        "tcp": {"link": s.tcp.link, "offset": list(s.tcp.offset), "approach_axis": list(s.tcp.approach_axis),
                "closing_axis": list(s.tcp.closing_axis)},
        "rest": dict(s.rest),
        "spheres_file": spheres_file,
        "fabric_exclude": [],
        "collision": {"no_floor_links": [], "hand_links": hand, "lean_drop_links": [], "ignore_pairs": pairs},
    }


_COMMENTS = {
    "upper:": "# drive gains: realize.robot.spec.Drive's defaults, NOT calibrated",
    "gripper:": "# open / closed from the joint's limits and the fingers' geometry; stiffness, damping, force: "
                "realize.robot.spec.GripperSpec's defaults, NOT calibrated (docs/robots.md, Grippers)",
    "rest:": "# 0, or mid-range where 0 is outside a joint's limits; the gripper open: look at it",
}


def _text(mapping: dict[str, Any], header: Sequence[str]) -> str:
    lines = [f"# {h}" for h in header]
    for key, value in mapping.items():
        flow = None if isinstance(value, (dict, list)) else False  # a scalar on its own line, not {key: value}
        body = yaml.safe_dump({key: value}, sort_keys=False, default_flow_style=flow, width=110).rstrip("\n")
        first = body.split("\n", 1)[0]
        if first.split()[0] in _COMMENTS:
            lines.append(_COMMENTS[first.split()[0]])
        lines.append(body)
    return "\n".join(lines) + "\n"


def onboard_robot(name: str, urdf: str, out_dir: Path = ROBOT_CONFIG_DIR, spheres_dir: Path = SPHERE_DIR,
                  gripper_joints: Sequence[str] | None = None, tcp_link: str | None = None,
                  height: float = FIXED_HEIGHT, fit: FitSettings = FitSettings(), force: bool = False,
                  command: str = "") -> Onboarded:
    """Draft, write and check robot ``name``'s config and sphere file from ``urdf`` (module docstring)."""
    out = Path(out_dir) / f"{name}.yaml"
    spheres_out = Path(spheres_dir) / f"{name}.yaml"
    if out.resolve() == spheres_out.resolve():
        raise ConfigError(f"--out and --spheres-out are one folder ({out.parent}): the config and the sphere file "
                          f"would both be {out.name}")
    if out.is_file() and not force:
        raise ConfigError(f"{_shown(out)} exists: pass --force to replace it, or another NAME")
    if spheres_out.is_file() and FITTED_MARK not in spheres_out.read_text():
        raise ConfigError(f"{_shown(spheres_out)} was not fitted by scripts/fit_spheres.py (hand-made?): "
                          "not replacing it; pick another NAME")
    ref = urdf_reference(urdf)
    path = source_urdf(ref)
    s = survey_urdf(path, gripper_joints, tcp_link)
    chose = [f"urdf: {ref}", *s.why]
    mesh_ext, why = _visual_mesh_ext(path)
    if why:
        chose.append(why)
    todo = []
    if Path(ref).is_absolute():
        todo.append(f"the URDF lies outside the repository and ManiSkill's assets ({ref}): copy it into the repository "
                    "and set urdf to its relative path before committing")
    footprint, why = _footprint(path, s.base_link)
    chose.append(why)
    if not s.base_joints:
        chose.append(f"base.height {height} m (--height: the stand a fixed base is bolted on)")
    hand = _hand_links(path, s)
    pairs = _srdf_pairs(path)
    if pairs:
        chose.append(f"collision.ignore_pairs: the {len(pairs)} non-adjacent 'Default' pairs of "
                     f"{path.with_suffix('.srdf').name}")
    spheres_file = name if Path(spheres_dir).resolve() == SPHERE_DIR.resolve() else str(spheres_out)
    # the gripper's measured reach and pad width: first with a reach that cannot fall short
    first = _mapping(name, ref, mesh_ext, s, spheres_file, height, footprint, hand, pairs, 1.0, 0.01)
    probe = RobotSpec.from_mapping(first, f"robot ({name}, drafted)")
    geo = grip_geometry(probe)
    reach = math.ceil(geo.reach * 2000) / 2000
    pad = max(0.001, round(geo.tip_half_width, 4))
    chose.append(f"gripper.fingertip_reach {reach} m, pad_half_width {pad} m (measured: grip_geometry); "
                 f"{geo.width_open * 1e3:.1f} mm between the pads open, {abs(geo.width_closed) * 1e3:.1f} mm closed")
    fitted = fit_robot_spheres(path, fit)
    mapping = _mapping(name, ref, mesh_ext, s, spheres_file, height, footprint, hand, pairs, reach, pad)
    mapping["fabric_exclude"] = [sp.name for sp in fitted if sp.link in hand]
    chose.append(f"spheres: {len(fitted)} on {len({sp.link for sp in fitted})} links ({fit.samples} samples, at most "
                 f"{fit.max_spheres} a link); fabric_exclude: the {len(mapping['fabric_exclude'])} on the hand and "
                 "fingers")
    header = [f"{name}: DRAFTED by python -m realize.robot.onboard from {Path(path).name}; not calibrated.",
              *[f"  {c}" for c in chose]]
    text = _text(mapping, header)
    # checked as a run's config load checks it before anything is written: a draft that fails leaves
    # no file in configs/robot/ (where every robot test would pick it up)
    spec = RobotSpec.from_mapping(yaml.safe_load(text), f"robot ({out.name})")
    check_urdf_names(spec, f"robot ({out.name})")
    spec.fabric_exclusions(None, [sp.name for sp in fitted])
    spheres_out.parent.mkdir(parents=True, exist_ok=True)
    write_fitted_spheres(spheres_out, name, path, fitted, fit.samples,
                         command or f"-m realize.robot.onboard {name} --urdf {ref}")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    load_spheres(spec.spheres_file)  # the file the config names reads back
    chose.append("checks passed: the config loads, its names are in the URDF (urdf_names), the gripper's geometry "
                 "(grip_geometry), the sphere file")
    todo += [
        "the gripper's open, closed, stiffness, damping, force and finger material are not calibrated: "
        "docs/robots.md, Grippers",
        "the drive gains are realize.robot.spec's defaults, not calibrated; the rest pose: the arm clear of the body",
        "run .venv/bin/python -m pytest tests/test_robot_kinematics.py tests/test_env_robots.py "
        "tests/test_sphere_fit.py",
    ]
    if s.base_joints:
        todo.append(f"smoke run: .venv/bin/realize robot={name} ce.n_envs=40 ce.iterations=1")
    else:
        todo.append(f"smoke run (a fixed base: no move_to): .venv/bin/realize robot={name} experiment=so100_pick_place "
                    f"ce.n_envs=40 ce.iterations=1 for an arm of the SO-100's size, experiment=tower3 for the Panda's")
    return Onboarded(out, spheres_out, spec, s, geo, chose, todo)


def main(argv: list[str] | None = None) -> int:
    """The command line (module docstring); a ``ConfigError`` is one ``error:`` line, exit 2."""
    ap = argparse.ArgumentParser(prog="python -m realize.robot.onboard",
                                 description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("name", help="the robot's name: writes OUT/NAME.yaml and realize/robot/spheres/NAME.yaml")
    ap.add_argument("--urdf", required=True, help="the URDF: a path, or mani_skill:<path in ManiSkill's assets>")
    ap.add_argument("--out", default=str(ROBOT_CONFIG_DIR), help="folder of the config (default configs/robot)")
    ap.add_argument("--spheres-out", default=str(SPHERE_DIR), help="folder of the sphere file")
    ap.add_argument("--tcp-link", help="the TCP's link (default: a *tcp* frame of the hand, else the hand)")
    ap.add_argument("--gripper-joints", help="the gripper's joints, comma-separated, the driven one first")
    ap.add_argument("--height", type=float, default=FIXED_HEIGHT, help="m: a fixed base's mount above the floor")
    ap.add_argument("--samples", type=int, default=3000, help="sphere fit: surface samples per link")
    ap.add_argument("--max-spheres", type=int, default=4, help="sphere fit: spheres per link at most")
    ap.add_argument("--max-radius", type=float, default=None, help="sphere fit: one radius bound for all links (m)")
    ap.add_argument("--force", action="store_true", help="replace an existing config")
    args = ap.parse_args(argv)
    argv_ = argv if argv is not None else sys.argv[1:]
    try:
        done = onboard_robot(args.name, args.urdf, Path(args.out), Path(args.spheres_out),
                             args.gripper_joints.split(",") if args.gripper_joints else None, args.tcp_link,
                             args.height, FitSettings(args.samples, args.max_spheres, args.max_radius),
                             args.force, " ".join(shlex.quote(a) for a in ["-m", "realize.robot.onboard", *argv_]))
    except ConfigError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(done.report())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
