"""Fit collision spheres to every link of a robot that has collision geometry; write its sphere file.

Usage::

    .venv/bin/python scripts/fit_spheres.py mobile_panda --count adjustable_body=5 ...
    .venv/bin/python scripts/fit_spheres.py fetch_omni --out /tmp/fetch_fitted.yaml --compare fetch_omni
    .venv/bin/python scripts/fit_spheres.py --urdf path/to/robot.urdf --links a b --out x.yaml

ROBOT names ``configs/robot/ROBOT.yaml`` (``realize.robot.spec.load_robot_spec``); its URDF is
read as the source file (collision meshes only, so no derived URDF is needed). ``--urdf`` reads a
URDF directly instead. Each link gets ``--count LINK=N`` spheres, or else the fewest (up to
``--max-spheres``) whose radii are all at most ``--max-radius`` (``realize.robot.sphere_fit``);
without ``--max-radius``, each link's own bound: half the middle edge of its collision geometry's
bounding box (its thickness: a long 20 x 15 x 10 cm arm link gets 7.5 cm, a 10 x 5 x 3 cm jaw
2.5 cm), so a small arm's spheres are sized to its links, not to a Panda's.
The file goes to ``realize/robot/spheres/ROBOT.yaml`` unless ``--out`` says otherwise; a coverage
report (per link: spheres, share of fresh surface samples inside the link's own spheres, how
far the worst sample is outside, largest overshoot; and in total) is printed. ``--compare FILE``
also reports an existing sphere file (a name in ``realize/robot/spheres/`` or a path), and for
links that file gives no spheres of their own, the share covered by all its spheres with the
robot at its joint-limit corners (``realize.robot.robot_spheres.corner_configs``).

``check_floor`` (whether the fabric keeps a sphere above the floor) is false where that cannot
hold at any height: for every sphere of a link whose collision geometry reaches the floor
(z <= ``--floor-tol`` in the URDF root frame, the floor being z = 0) at every corner
configuration, and for a sphere that itself reaches below the floor at every corner
configuration. Corner configurations: the lift/torso and other short-range prismatic joints at
both limits, revolute joints at 0. So a base, or a lift column that hangs down to the floor at
every height, is left out of floor avoidance; a torso that reaches the floor only with the lift
all the way down is kept above it. The spec's ``collision.no_floor_links`` (the simulator's floor
contact filter) is printed beside the result, not used.

Sphere counts: ``--count LINK=N``, else the per-link counts of the file being replaced when it
was written by this script (so ``fit_spheres.py ROBOT`` refits a robot as committed), else the
``--max-radius`` rule. A file not written by this script (Fetch's hand-made one) is never
overwritten; write elsewhere with ``--out``.

Mesh files are found as SAPIEN finds them (``package://`` names searched up the URDF's folders,
``realize.robot.urdf.mesh_file``); a robot config, URDF or mesh it cannot read is one ``error:``
line, exit code 2.

The fitting itself is ``realize.robot.robot_spheres`` (``realize.robot.onboard`` calls it too);
this script is its command line and coverage report.

What it doesn't: fit self-collision models, or change a sphere file it is only comparing.
"""

from __future__ import annotations

import argparse
from collections import Counter
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from realize.config import ConfigError
from realize.paths import REPO_ROOT
from realize.robot.robot_spheres import (FITTED_MARK, FitSettings, corner_configs, fit_robot_spheres, link_poses,
                                         write_fitted_spheres)
from realize.robot.sphere_file import SPHERE_DIR, SphereSpec, load_spheres, sphere_file_path
from realize.robot.sphere_fit import Coverage, LinkGeometry, Sphere, collision_links, coverage, link_geometry
from realize.robot.urdf import JointSpec, parse_urdf_joints


@dataclass(frozen=True)
class LinkReport:
    link: str
    spheres: int
    cov: Coverage
    area: float


# ----------------------------------------------------------------------------- reports


def _fmt(r: LinkReport) -> str:
    c = r.cov
    return (f"  {r.link:28s} {r.spheres:3d}  {100 * c.share_inside:7.2f} %  {1000 * c.worst_outside:6.1f} mm"
            f"  {1000 * c.overshoot:6.1f} mm")


def print_report(title: str, reports: list[LinkReport]) -> None:
    print(f"{title}\n  {'link':28s} {'n':>3s}  {'inside':>9s}  {'worst out':>9s}  {'overshoot':>9s}")
    for r in reports:
        print(_fmt(r))
    sphered = [r for r in reports if r.spheres]
    area = sum(r.area for r in sphered)
    if sphered:
        share = sum(r.cov.share_inside * r.area for r in sphered) / area
        print(f"  total: {sum(r.spheres for r in reports)} spheres; inside {100 * share:.2f} % of the surface "
              f"(area-weighted), worst link {min(r.cov.share_inside for r in sphered) * 100:.2f} % "
              f"({min(sphered, key=lambda r: r.cov.share_inside).link}); largest overshoot "
              f"{1000 * max(r.cov.overshoot for r in sphered):.1f} mm "
              f"({max(sphered, key=lambda r: r.cov.overshoot).link})")


def link_reports(geoms: dict[str, LinkGeometry], spheres: list[SphereSpec], seed: int) -> list[LinkReport]:
    """Coverage of each link's geometry by the spheres on that link (samples seeded apart from the fit)."""
    out = []
    for name, g in geoms.items():
        own = [Sphere(s.offset, s.radius) for s in spheres if s.link == name]
        cov = coverage(g, own, seed=seed) if own else Coverage(0.0, float("inf"), 0.0, 0)
        out.append(LinkReport(name, len(own), cov, g.area))
    return out


def borrowed_coverage(joints: dict[str, JointSpec], geoms: dict[str, LinkGeometry], spheres: list[SphereSpec],
                      link: str, seed: int) -> list[tuple[dict[str, float], float]]:
    """Share of ``link``'s surface inside any sphere of the robot, at each corner configuration."""
    links = sorted({link, *(s.link for s in spheres)})
    out = []
    for cfg in corner_configs([j for j in joints.values()]):
        poses = link_poses(joints, cfg, links)
        world = [Sphere(tuple(poses[s.link][:3, :3] @ np.asarray(s.offset) + poses[s.link][:3, 3]), s.radius)
                 for s in spheres]
        cov = coverage(geoms[link].transformed(poses[link]), world, seed=seed, n_dirs=8)
        out.append((cfg, cov.share_inside))
    return out


# ----------------------------------------------------------------------------- main


def _parse_counts(items: list[str]) -> dict[str, int]:
    counts = {}
    for item in items:
        link, _, n = item.partition("=")
        if not n.isdigit() or int(n) < 1:
            raise SystemExit(f"--count {item!r}: expected LINK=N with N >= 1")
        counts[link] = int(n)
    return counts


def main(argv: list[str] | None = None) -> int:
    """Run the script; a robot config, URDF or mesh it cannot read is one ``error:`` line (exit 2)."""
    try:
        return _fit(argv)
    except ConfigError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


def _fit(argv: list[str] | None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("robot", nargs="?", help="configs/robot/ROBOT.yaml (needed unless --urdf and --out are given)")
    ap.add_argument("--urdf", help="read this URDF instead of the robot config's")
    ap.add_argument("--links", nargs="+", help="fit only these links (default: every link with collision geometry)")
    ap.add_argument("--count", action="append", default=[], metavar="LINK=N", help="spheres for one link")
    ap.add_argument("--max-radius", type=float, default=None,
                    help="radius bound for links without --count (m); default: half the middle edge of each link's "
                         "bounding box")
    ap.add_argument("--max-spheres", type=int, default=4, help="sphere bound per link without --count")
    ap.add_argument("--samples", type=int, default=3000, help="surface samples fitted per link")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--floor-tol", type=float, default=0.01, help="m above the floor that counts as touching it")
    ap.add_argument("--out", help="sphere file to write (default realize/robot/spheres/ROBOT.yaml)")
    ap.add_argument("--compare", help="also report this existing sphere file (name or path)")
    args = ap.parse_args(argv)

    no_floor: tuple[str, ...] = ()
    if args.urdf:
        urdf = Path(args.urdf)
    elif args.robot:
        from realize.robot.spec import load_robot_spec
        from realize.robot.urdf import source_urdf

        spec = load_robot_spec(args.robot)
        urdf = source_urdf(spec.urdf)
        no_floor = spec.collision.no_floor_links
    else:
        ap.error("give ROBOT or --urdf")
    robot = args.robot or urdf.stem
    out = Path(args.out) if args.out else SPHERE_DIR / f"{robot}.yaml"
    if out.is_file() and FITTED_MARK not in out.read_text():
        ap.error(f"{out.name} was not written by this script (hand-made?): not replacing it; give --out")
    counts = _parse_counts(args.count)
    links = args.links or collision_links(urdf)
    unknown = sorted(set(counts) - set(links))
    if unknown:
        ap.error(f"--count names links without collision geometry or not fitted: {unknown}")
    if out.is_file():
        kept = Counter(s.link for s in load_spheres(str(out)))
        counts = {**{l: n for l, n in kept.items() if l in links}, **counts}
    joints = parse_urdf_joints(str(urdf))
    geoms = {l: link_geometry(urdf, l) for l in links}
    report_seed = args.seed + 1_000_003

    settings = FitSettings(args.samples, args.max_spheres, args.max_radius, args.seed, args.floor_tol)
    fitted = fit_robot_spheres(urdf, settings, links, counts, geoms)
    print_report(f"fitted spheres ({urdf.name}, seed {args.seed}):", link_reports(geoms, fitted, report_seed))
    off_floor = [s.name for s in fitted if not s.check_floor]
    print(f"  check_floor: false on {off_floor or 'no sphere'}; the spec's no_floor_links (sim contact filter, "
          f"not used here): {list(no_floor)}")

    try:
        where = out.resolve().relative_to(REPO_ROOT)
    except ValueError:
        where = out.name
    argv_ = argv if argv is not None else sys.argv[1:]
    cmd = " ".join(shlex.quote(a) for a in ["scripts/fit_spheres.py", *argv_])
    without = [l for l in collision_links(urdf) if l not in links]  # --links: the rest is left to neighbours
    write_fitted_spheres(out, robot, urdf, fitted, args.samples, cmd, without_spheres=without)
    print(f"wrote {len(fitted)} spheres to {where}")

    if args.compare:
        existing = list(load_spheres(args.compare))
        print_report(f"\n{sphere_file_path(args.compare).name} (existing):", link_reports(geoms, existing, report_seed))
        have = {s.link for s in existing}
        for link in [l for l in links if l not in have]:
            shares = borrowed_coverage(joints, geoms, existing, link, report_seed)
            text = ", ".join(f"{100 * s:.1f} %" for _, s in shares)
            print(f"  {link}: no spheres of its own; inside the robot's spheres at the {len(shares)} "
                  f"joint-limit corners: {text}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
