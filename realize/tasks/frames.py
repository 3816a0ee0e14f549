"""Object frames of parameter regions: a region's numbers relative to an object of the scene.

What it does: a task's region may name a frame (``frame: cube``, ``frame: table2``; default
``world``). ``object_frames(scene)`` gives the origin of every frame the scene has, from its
config: every movable object (``scene.objects``) at its centre where it rests, every table and
the push variant's open box at the centre of their top face, ``world`` at (0, 0, 0). ``place_region`` turns a
region written in a frame into the same region in the world frame (what the search samples and
the controllers read), and ``move_points`` carries sample rows of a region from one placement of
its frame to another (a warm start from a run whose cube or table stood elsewhere).
Frames only translate (an object's configured yaw does not turn its regions): moving an object
or a table in the scene config moves its regions with it.
What it doesn't: parse the rest of a region (``realize.tasks.param_layout``) or read run directories
(``realize.search.warm_start``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch
from torch import Tensor

from realize.config import ConfigError
from realize.world.geometry import SceneGeometry
from realize.tasks.hemisphere import Hemisphere
from realize.tasks.regions import Annulus, Box, Fixed, Region

__all__ = ["WORLD", "Frame", "object_frames", "place_region", "move_points", "position_columns"]

WORLD = "world"


@dataclass(frozen=True)
class Frame:
    """A named frame: its origin (x, y, z) in one copy's world frame (m)."""

    name: str
    origin: tuple[float, float, float]


def object_frames(scene: SceneGeometry) -> dict[str, Frame]:
    """Every frame a region of ``scene`` may name, by name."""
    frames = {WORLD: Frame(WORLD, (0.0, 0.0, 0.0))}
    for o in scene.objects:
        frames[o.name] = Frame(o.name, tuple(o.position))
    for b in list(scene.tables) + list(scene.containers):
        frames[b.name] = Frame(b.name, (b.center[0], b.center[1], b.top_z))
    return frames


def position_columns(region: Region) -> int:
    """How many leading columns of ``region`` are a position (x, y[, z]) that a frame moves:
    2 for an annulus, 3 for a hemisphere (its yaw column stays), a box's or a fixed point's
    dimension when it is 2 or 3; 0 for anything else."""
    if isinstance(region, Annulus):
        return 2
    if isinstance(region, Hemisphere):
        return 3
    if isinstance(region, (Box, Fixed)) and region.dim in (2, 3):
        return region.dim
    return 0


def _shift(values: tuple[float, ...], origin: tuple[float, float, float]) -> tuple[float, ...]:
    """Translate, rounded to 1e-12 m: binary sums such as 0.72 + 0.0225 = 0.7424999999999999
    would otherwise make a region written relative to an object differ in its last bit from
    the same region written in world numbers (0.7425), and so every sample drawn in it."""
    return tuple(round(v + o, 12) for v, o in zip(values, origin))


def place_region(region: Region, frame: Frame, where: str) -> Region:
    """``region`` written in ``frame`` -> the same region in the world frame (``where`` names it
    in errors: a region whose numbers are not a position cannot follow an object)."""
    if frame.name == WORLD:
        return region
    k = position_columns(region)
    if k == 0:
        raise ConfigError(f"{where}.frame = {frame.name!r} is invalid: a {region.type_name} region of dimension "
                          f"{region.dim} is not a position (only annulus, hemisphere and 2-D or 3-D box or "
                          "fixed regions can follow an object)")
    o = frame.origin
    if isinstance(region, (Annulus, Hemisphere)):
        return replace(region, center=_shift(region.center, o))
    if isinstance(region, Box):
        return replace(region, low=_shift(region.low, o), high=_shift(region.high, o))
    assert isinstance(region, Fixed)
    return replace(region, value=_shift(region.value, o))


def move_points(z: Tensor, region: Region, old: Frame, new: Frame) -> Tensor:
    """Rows ``z (n, dim)`` of ``region`` placed by ``old`` -> the same rows relative to the
    frame, placed by ``new`` (a translation of the position columns; the others stay)."""
    k = position_columns(region)
    if k == 0 or old.origin == new.origin:
        return z.clone()
    d = torch.tensor([n - o for n, o in zip(new.origin[:k], old.origin[:k])], dtype=z.dtype, device=z.device)
    out = z.clone()
    out[:, :k] += d
    return out
