"""What a URDF says about a robot, read to draft its config (``realize.robot.onboard``).

What it does: :func:`survey_urdf` reads a URDF's joint tree and its finger links' collision
geometry and decides, each choice with a one-line reason in ``Survey.why``:

* the **gripper**: the movable joints with no movable joint after them, grouped by the joint
  they follow; a group of one revolute jaw, or two prismatic fingers (the second may mimic the
  first), is a candidate; of several, the one at the end of the longest chain (``--gripper-joints``
  picks one); its fingers must close to within 5 mm at one limit (an arm's last joint is no jaw).
  Its finger links (two fingers: the joints' children; one jaw: the fixed jaw, the joint's parent,
  then the moving one) and which limit opens them (the nearest distance from a moving finger's far
  end, its last 2 cm from its joint, to the other finger at each limit: open is wider); the
  targets: a prismatic pair opens to its open limit and closes a quarter of its range past the
  other (a squeeze, as the Panda's), a jaw opens to mid-range and closes to its limit;
* the **base**: mobile where the chain from the root starts with prismatic x, prismatic y and a
  revolute (or continuous) z joint, as ManiSkill's mobile Panda and Fetch; else fixed at the root;
* the **upper joints**: the movable joints from the base to the gripper, in order; every other
  movable joint that mimics nothing is held; the rest pose: 0, or mid-range where 0 is outside
  a joint's limits, the gripper open;
* the **TCP**: a frame-only child of the hand named ``*tcp*`` (the one nearest the pads), else the
  hand link (``--tcp-link`` picks one); the closing axis (a prismatic finger's axis; a jaw's
  sweep); the approach (the way the fingers stand out from their joints, or the last arm joint's
  axis where it is within 30 degrees of that: a wrist roll), each snapped to a frame axis within
  10 degrees; and the offset of the point between the pads' tips (each finger's last
  :data:`TIP_DEPTH` along the approach) at a middle opening.

Anything it cannot decide is one ``ConfigError`` line naming the URDF, what is missing, and the
flag that settles it.

What it doesn't: write the config or check it (``realize.robot.onboard``), fit spheres, or
calibrate anything by simulation (drive gains, the jaw's squeeze).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from realize.config import ConfigError
from realize.robot.link_geometry import collision_links, link_geometry
from realize.robot.robot_spheres import link_poses
from realize.robot.urdf import JointSpec, parse_urdf_joints, read_urdf

__all__ = ["GripperDraft", "TcpDraft", "Survey", "survey_urdf", "TIP_DEPTH"]

TIP_DEPTH = 0.02  # m: the pads' tips are each finger's last 2 cm along the approach; the TCP is their middle
CLOSES = 0.005  # m: a gripper found by itself closes its fingers to within this at one limit
SNAP_COS = math.cos(math.radians(10.0))  # an axis this close to a frame axis is that axis
SAMPLES = 1500  # surface samples per finger link


@dataclass(frozen=True)
class GripperDraft:
    joints: tuple[str, ...]  # the driven joint first, then its mimics
    joint_type: str  # "prismatic" | "revolute"
    finger_links: tuple[str, str]
    hand_link: str  # the link the gripper joints hang from
    closed_limit: float
    open_limit: float
    width_closed: float  # m: from the moving finger's far end to the other finger at the closed limit
    width_open: float  # and at the open limit
    open: float  # the drafted targets (joint unit)
    closed: float


@dataclass(frozen=True)
class TcpDraft:
    link: str
    offset: tuple[float, float, float]
    approach_axis: tuple[float, float, float]
    closing_axis: tuple[float, float, float]


@dataclass
class Survey:
    path: Path
    root: str
    base_joints: tuple[str, ...]  # () for a fixed base
    base_link: str
    upper: tuple[str, ...]
    held: dict[str, float]
    gripper: GripperDraft
    tcp: TcpDraft
    rest: dict[str, float]
    why: list[str] = field(default_factory=list)  # one line per choice


def _mimics(path: Path) -> dict[str, str]:
    out = {}
    for j in read_urdf(path).findall("joint"):
        m = j.find("mimic")
        if m is not None and m.get("joint"):
            out[j.get("name", "")] = m.get("joint", "")
    return out


class _Tree:
    def __init__(self, path: Path) -> None:
        self.path = path
        self.by_child = parse_urdf_joints(str(path))
        self.by_name = {j.name: j for j in self.by_child.values()}
        self.mimic = _mimics(path)
        self.with_geometry = set(collision_links(path))
        children = {j.child for j in self.by_child.values()}
        roots = sorted({j.parent for j in self.by_child.values()} - children)
        if len(roots) != 1:
            raise ConfigError(f"URDF {path}: one root link is needed, found {roots or 'none'}")
        self.root = roots[0]

    def chain(self, link: str) -> list[JointSpec]:
        """Joints from the root to ``link``, in order."""
        out = []
        while link in self.by_child:
            out.append(self.by_child[link])
            link = self.by_child[link].parent
        return out[::-1]

    def movable_chain(self, link: str) -> list[JointSpec]:
        return [j for j in self.chain(link) if j.type != "fixed"]

    def below(self, link: str) -> list[JointSpec]:
        """Every joint in the subtree under ``link``."""
        out, todo = [], [link]
        while todo:
            l = todo.pop()
            for j in self.by_child.values():
                if j.parent == l:
                    out.append(j)
                    todo.append(j.child)
        return out

    def geometry_link(self, link: str) -> str | None:
        """``link`` if it has collision geometry, else the first under it through fixed joints."""
        if link in self.with_geometry:
            return link
        for j in self.below(link):
            if j.type == "fixed" and j.child in self.with_geometry and all(
                    k.type == "fixed" for k in self.chain(j.child)[len(self.chain(link)):]):
                return j.child
        return None


def _axis(j: JointSpec) -> np.ndarray:
    """The joint's axis in its parent link's frame."""
    from realize.robot.link_geometry import origin_matrix

    return origin_matrix(j.xyz, j.rpy)[:3, :3] @ np.asarray(j.axis, dtype=float) / np.linalg.norm(j.axis)


def _snap(v: np.ndarray) -> np.ndarray:
    v = v / np.linalg.norm(v)
    i = int(np.argmax(np.abs(v)))
    if abs(v[i]) >= SNAP_COS:
        out = np.zeros(3)
        out[i] = math.copysign(1.0, v[i])
        return out
    return v


def _gripper_candidates(t: _Tree) -> dict[str, list[str]]:
    """Terminal movable joints (no movable joint after them) grouped by the movable joint before them."""
    groups: dict[str, list[str]] = {}
    for j in t.by_child.values():
        if j.type == "fixed" or any(k.type != "fixed" for k in t.below(j.child)):
            continue
        before = t.movable_chain(j.parent)
        groups.setdefault(before[-1].name if before else "", []).append(j.name)
    ok = {}
    for anchor, names in groups.items():
        driven = [n for n in names if n not in t.mimic]
        types = {t.by_name[n].type for n in names}
        if len(types) == 1 and ((types == {"revolute"} and len(names) == 1) or
                                (types == {"prismatic"} and len(names) == 2 and len(driven) >= 1)):
            ok[anchor] = names
    return ok


def _pick_gripper(t: _Tree, given: Sequence[str] | None) -> list[str]:
    if given:
        unknown = [n for n in given if n not in t.by_name or t.by_name[n].type == "fixed"]
        if unknown:
            raise ConfigError(f"URDF {t.path}: --gripper-joints {unknown} are not movable joints of it")
        return list(given)
    cands = _gripper_candidates(t)
    if not cands:
        raise ConfigError(f"URDF {t.path}: no gripper joints found (one revolute jaw or two prismatic fingers after "
                          "the last arm joint); name them with --gripper-joints")
    depth = {a: len(t.movable_chain(t.by_name[a].child)) if a else 0 for a in cands}
    best = max(depth.values())
    top = [a for a in cands if depth[a] == best]
    if len(top) > 1:
        found = "; ".join(",".join(cands[a]) for a in top)
        raise ConfigError(f"URDF {t.path}: several candidate grippers at the end of equally long chains ({found}); "
                          "pick one with --gripper-joints")
    names = cands[top[0]]
    return sorted(names, key=lambda n: n in t.mimic)  # the driven joint first


def _points(t: _Tree, links: Sequence[str], frame: str, values: dict[str, float]) -> list[np.ndarray]:
    poses = link_poses(t.by_child, values, [*links, frame])
    inv = np.linalg.inv(poses[frame])
    out = []
    for l in links:
        p = link_geometry(t.path, l).sample_surface(SAMPLES, seed=0)
        m = inv @ poses[l]
        out.append(p @ m[:3, :3].T + m[:3, 3])
    return out


def _gap(a: np.ndarray, b: np.ndarray) -> float:
    from scipy.spatial import cKDTree

    return float(cKDTree(b).query(a)[0].min())


def survey_urdf(path: Path, gripper_joints: Sequence[str] | None = None, tcp_link: str | None = None) -> Survey:
    """The survey of the URDF file ``path`` (module docstring)."""
    t = _Tree(path)
    why: list[str] = []
    names = _pick_gripper(t, gripper_joints)
    joints = [t.by_name[n] for n in names]
    kind = joints[0].type
    if kind not in ("prismatic", "revolute") or any(j.type != kind for j in joints):
        raise ConfigError(f"URDF {path}: gripper joints {names} must all be prismatic or all revolute")
    hand = joints[0].parent
    why.append(f"gripper: {', '.join(names)} ({len(names)} {kind} joint{'s' * (len(names) > 1)} after the last arm "
               f"joint, moving finger links; {', '.join(n for n in names if n in t.mimic) or 'none'} mimicking)")
    unmimicked = [n for n in names[1:] if t.mimic.get(n) != names[0]]
    if unmimicked:
        why.append(f"gripper: {unmimicked} do not mimic {names[0]} in the URDF; realize drives them to one target")
    if len(joints) == 1:
        fixed, moving = t.geometry_link(hand), t.geometry_link(joints[0].child)
        fingers = (fixed, moving)
        why.append(f"finger links: {fixed} (the fixed jaw, the joint's parent) and {moving} (the moving jaw)")
    else:
        fingers = (t.geometry_link(joints[0].child), t.geometry_link(joints[1].child))
        why.append(f"finger links: {fingers[0]} and {fingers[1]} (the finger joints' children)")
    if None in fingers:
        raise ConfigError(f"URDF {path}: the gripper joints {names} move no link with collision geometry; "
                          "name the gripper with --gripper-joints")
    f0, f1 = str(fingers[0]), str(fingers[1])
    lo, hi = joints[0].lower, joints[0].upper
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ConfigError(f"URDF {path}: gripper joint {names[0]} has no finite limits; give it <limit lower upper>")
    widths = {}
    for v in (lo, hi):  # from the moving finger's far end (its points farthest from its joint) to the other
        fixed, moving = _points(t, [f0, f1], hand, {n: v for n in names})
        if len(joints) == 2:
            fixed, moving = moving, fixed
        d = np.linalg.norm(moving - np.asarray(joints[-1 if len(joints) == 1 else 0].xyz), axis=1)
        widths[v] = _gap(moving[d >= d.max() - TIP_DEPTH], fixed)
    if not gripper_joints and min(widths.values()) > CLOSES:
        raise ConfigError(f"URDF {path}: no gripper joints found: {', '.join(names)}, the only candidate, never "
                          f"brings {f1}'s far end within {CLOSES * 1e3:.0f} mm of {f0} (nearest "
                          f"{min(widths.values()) * 1e3:.1f} mm at its limits); name the gripper with --gripper-joints")
    if abs(widths[hi] - widths[lo]) < 1e-3:
        raise ConfigError(f"URDF {path}: the fingers {f0}, {f1} are as far apart at {names[0]}'s lower limit as at "
                          f"its upper ({widths[lo] * 1e3:.1f} mm): cannot tell open from closed")
    if widths[lo] > widths[hi]:
        raise ConfigError(f"URDF {path}: {names[0]} opens toward its lower limit ({widths[lo] * 1e3:.1f} mm there, "
                          f"{widths[hi] * 1e3:.1f} mm at the upper); realize needs gripper.open above gripper.closed")
    unit = "m" if kind == "prismatic" else "rad"
    if kind == "prismatic":
        open_, closed = hi, lo - 0.25 * (hi - lo)
        why.append(f"open {open_:g} {unit} (the upper limit: fingers {widths[hi] * 1e3:.1f} mm apart, "
                   f"{widths[lo] * 1e3:.1f} at the lower); closed {closed:g} {unit}, a quarter of the range past "
                   "the closed limit (a squeeze)")
    else:
        open_, closed = 0.5 * (lo + hi), lo
        why.append(f"open {open_:g} {unit} (mid-range: the jaws {widths[hi] * 1e3:.1f} mm apart at the upper limit, "
                   f"{widths[lo] * 1e3:.1f} at the lower); closed {closed:g} {unit}, the closed limit")
    grip = GripperDraft(tuple(names), kind, (f0, f1), hand, lo, hi, widths[lo], widths[hi], open_, closed)
    base_joints, base_link, upper = _base_and_upper(t, grip, why)
    tcp = _tcp(t, grip, t.by_name[upper[-1]], tcp_link, why)
    held = {}
    for j in t.by_child.values():
        if j.type != "fixed" and j.name not in (*names, *base_joints, *upper) and j.name not in t.mimic:
            held[j.name] = _rest(j)
    if held:
        why.append(f"held (movable, outside the arm's chain and the gripper): {', '.join(held)}")
    rest = {n: _rest(t.by_name[n]) for n in upper}
    rest.update({n: open_ for n in names})
    why.append("rest: every upper joint at 0, or mid-range where 0 is outside its limits; the gripper open")
    return Survey(path, t.root, base_joints, base_link, upper, held, grip, tcp, rest, why)


def _rest(j: JointSpec) -> float:
    if j.lower <= 0.0 <= j.upper:
        return 0.0
    return round(0.5 * (j.lower + j.upper), 4)


def _base_and_upper(t: _Tree, g: GripperDraft, why: list[str]) -> tuple[tuple[str, ...], str, tuple[str, ...]]:
    chain = t.movable_chain(g.hand_link)
    first = chain[:3]
    want = (("prismatic", (1.0, 0.0, 0.0)), ("prismatic", (0.0, 1.0, 0.0)), ("revolute", (0.0, 0.0, 1.0)))
    mobile = len(first) == 3 and all(
        (j.type == k or (k == "revolute" and j.type == "continuous")) and np.allclose(_axis(j), ax)
        for j, (k, ax) in zip(first, want))
    if mobile:
        base = tuple(j.name for j in first)
        why.append(f"base: mobile ({', '.join(base)}: prismatic x, prismatic y, yaw from the root), "
                   f"carrying {first[2].child}")
        link, rest = first[2].child, chain[3:]
    else:
        base = ()
        why.append(f"base: fixed at the root link {t.root} (the chain does not start with planar x, y, yaw joints)")
        link, rest = t.root, chain
    bad = [j.name for j in rest if j.name in t.mimic]
    if bad:
        raise ConfigError(f"URDF {t.path}: arm joints {bad} mimic other joints; realize drives each arm joint")
    upper = tuple(j.name for j in rest)
    if not upper:
        raise ConfigError(f"URDF {t.path}: no arm joint between the base and the gripper's link {g.hand_link}")
    why.append(f"upper: {len(upper)} joints from {link} to {g.hand_link}: {', '.join(upper)}")
    return base, link, upper


def _approach(t: _Tree, hand: str, wrist: JointSpec, e: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The approach: the last arm joint's axis (a wrist roll turns the gripper about it) where it lies
    within 30 degrees of the way the fingers stand out (``e``), else ``e``; square to ``normal``."""
    e = e - (e @ normal) * normal
    e = e / np.linalg.norm(e)
    poses = link_poses(t.by_child, {}, [hand, wrist.child])
    w = poses[hand][:3, :3].T @ poses[wrist.child][:3, :3] @ (np.asarray(wrist.axis) / np.linalg.norm(wrist.axis))
    w = w - (w @ normal) * normal
    if np.linalg.norm(w) > 0.5 and abs(w @ e) / np.linalg.norm(w) >= math.cos(math.radians(30.0)):
        e = math.copysign(1.0, w @ e) * w / np.linalg.norm(w)
    return _snap(e)


def _tcp(t: _Tree, g: GripperDraft, wrist: JointSpec, tcp_link: str | None, why: list[str]) -> TcpDraft:
    names, hand = g.joints, g.hand_link
    mid = 0.5 * (g.closed_limit + g.open)
    j0 = t.by_name[names[0]]
    if g.joint_type == "prismatic":
        c = _axis(j0)  # finger 0 moves along +c as the gripper opens: c points from finger 1 to finger 0
        a_pts = np.concatenate(_points(t, list(g.finger_links), hand, {n: mid for n in names}))
        origin = np.mean([t.by_name[n].xyz for n in names], axis=0)
        a = _approach(t, hand, wrist, a_pts.mean(axis=0) - origin, c)
        c = _snap(c - (c @ a) * a)
    else:
        n = _axis(j0)
        (moving,) = _points(t, [g.finger_links[1]], hand, {names[0]: g.closed_limit})
        a = _approach(t, hand, wrist, moving.mean(axis=0) - np.asarray(j0.xyz), n)
        c = np.cross(n, a)
        p0, p1 = _points(t, list(g.finger_links), hand, {names[0]: g.open})
        if c @ (_tip(p0, a).mean(axis=0) - _tip(p1, a).mean(axis=0)) < 0:
            c = -c
        c = _snap(c - (c @ a) * a)
    p0, p1 = _points(t, list(g.finger_links), hand, {n: mid for n in names})
    t0, t1 = _tip(p0, a), _tip(p1, a)
    (hi, lo) = (t0, t1) if t0.mean(axis=0) @ c > t1.mean(axis=0) @ c else (t1, t0)
    across = 0.5 * float((hi @ c).min() + (lo @ c).max())
    along = 0.5 * float(t0.mean(axis=0) @ a + t1.mean(axis=0) @ a)
    b = np.cross(a, c)
    sideways = 0.5 * float(t0.mean(axis=0) @ b + t1.mean(axis=0) @ b)
    point = along * a + across * c + sideways * b  # in the hand's frame
    if tcp_link is None:
        frames = [j.child for j in t.below(hand) if j.type == "fixed" and "tcp" in j.child.lower()
                  and j.child not in t.with_geometry and all(k.type == "fixed" for k in
                                                             t.chain(j.child)[len(t.chain(hand)):])]
        if frames:
            poses = link_poses(t.by_child, {}, [hand, *frames])
            inv = np.linalg.inv(poses[hand])
            dist = {f: float(np.linalg.norm((inv @ poses[f])[:3, 3] - point)) for f in frames}
            tcp_link = min(frames, key=dist.__getitem__)
            why.append(f"tcp.link: {tcp_link} (a frame of {hand} named *tcp*, {dist[tcp_link] * 1e3:.1f} mm from the "
                       "pads' middle" + (f"; of {len(frames)}, the nearest)" if len(frames) > 1 else ")"))
        else:
            tcp_link = hand
            why.append(f"tcp.link: {hand} (the gripper's link; it has no frame named *tcp*)")
    elif tcp_link not in {hand, *(j.child for j in t.below(hand))} or any(
            k.type != "fixed" for k in t.chain(tcp_link)[len(t.chain(hand)):]):
        raise ConfigError(f"URDF {t.path}: --tcp-link {tcp_link!r} is not {hand} or a link fixed to it")
    else:
        why.append(f"tcp.link: {tcp_link} (--tcp-link)")
    m = np.linalg.inv(link_poses(t.by_child, {}, [hand, tcp_link])[tcp_link]) @ link_poses(t.by_child, {}, [hand])[hand]
    r = m[:3, :3]
    off = tuple(round(float(v), 4) + 0.0 for v in r @ point + m[:3, 3])
    ax = tuple(round(float(v), 6) + 0.0 for v in _snap(r @ a))
    cl = tuple(round(float(v), 6) + 0.0 for v in _snap(r @ c))
    why.append(f"tcp.offset {list(off)}: between the fingers' last {TIP_DEPTH * 1e3:.0f} mm at a middle opening "
               f"({mid:g}); approach {list(ax)} (the way the fingers stand out, or {wrist.name}'s axis within 30 "
               f"degrees of it), closing {list(cl)} (toward {g.finger_links[0]})")
    return TcpDraft(tcp_link, off, ax, cl)  # type: ignore[arg-type]


def _tip(p: np.ndarray, a: np.ndarray) -> np.ndarray:
    s = p @ a
    return p[s >= s.max() - TIP_DEPTH]
