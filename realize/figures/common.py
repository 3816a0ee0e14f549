"""What the figures share: matplotlib set-up, colours, the top-down world, CSV output.

What it does: selects matplotlib's Agg backend (no display needed), defines the colours and
resolution, draws the world seen from above (``draw_world``: parameter regions in light grey,
tables/extras in black with their A* padding outline, the movable objects, the robot's start and heading;
``set_world_limits``), fetches a run's scene or says what is missing (``require_scene``), and
writes CSV files of plotted numbers (``write_csv``, ``fmt``: non-finite -> empty cell).
What it doesn't: read run files itself (``realize.run_dir.directory.RunDir``) or draw a whole
figure (``realize.figures.fig2``/``fig3``/``fig4``).
"""

from __future__ import annotations

import csv
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402,F401  (the figure modules use pyplot through here)
from matplotlib.patches import PathPatch, Polygon  # noqa: E402
from matplotlib.path import Path as MplPath  # noqa: E402
import numpy as np  # noqa: E402

from realize.world.geometry import SceneGeometry  # noqa: E402
from realize.tasks.param_layout import ParamLayout  # noqa: E402
from realize.tasks.regions import Fixed  # noqa: E402
from realize.run_dir.directory import RunDir  # noqa: E402
from realize.run_dir.names import SCENE_FILE  # noqa: E402
from realize.run_dir.scene_files import SceneInfo  # noqa: E402
from realize.tasks.topdown import obstacle_outline, padded_outline, region_outlines  # noqa: E402

__all__ = ["plt", "CYAN", "REGION_GREY", "REGION_EDGE", "DPI", "require_scene", "report_written", "write_csv", "fmt", "draw_world",
           "set_world_limits"]

CYAN = "#00c8e6"
REGION_GREY = "#d9d9d9"
REGION_EDGE = "#b0b0b0"
DPI = 150


def require_scene(rd: RunDir, who: str) -> SceneInfo:
    """The run's scene, or a ``FileNotFoundError`` saying what is missing."""
    scene = rd.scene()
    if scene is None:
        raise FileNotFoundError(f"{who}: {rd.path} has no {SCENE_FILE} and its result.json config does not "
                                "describe the scene (task.params, scene)")
    return scene


def report_written(make: Callable[[], tuple[Path, Path]], prefix: str = "") -> int:
    """A figure script's ending: ``make()`` writes the PNG and its CSV; print both paths (after
    ``prefix``) and return 0, or print the one-line error of a missing or unreadable input and
    return 1."""
    try:
        png, csv = make()
    except (FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    print(f"{prefix}wrote {png}\nwrote {csv}")
    return 0


def write_csv(path: Path, header: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)


def fmt(v: Any) -> Any:
    """A CSV cell: floats to 6 significant digits (non-finite: empty), numpy scalars as Python."""
    if isinstance(v, (float, np.floating)):
        return "" if not np.isfinite(v) else float(f"{float(v):.6g}")
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    return v


def draw_world(ax: Any, layout: ParamLayout, geometry: SceneGeometry, padding: float) -> None:
    """Regions (light grey fill), tables/extras (black) with the padding outline, objects, start."""
    for name, region in layout.regions.items():
        outlines = region_outlines(region)
        if not outlines:
            continue
        if isinstance(region, Fixed):
            for o in outlines:
                ax.plot(o[:, 0], o[:, 1], color=REGION_EDGE, lw=1.0, zorder=1)
            continue
        # outer + inner outlines as one compound path
        # (inner outlines reversed, so that the non-zero fill rule leaves an annulus' hole empty)
        rings = [outlines[0]] + [o[::-1] for o in outlines[1:]]
        path = MplPath.make_compound_path(*[MplPath(o) for o in rings])
        ax.add_patch(PathPatch(path, facecolor=REGION_GREY, edgecolor=REGION_EDGE, lw=0.6, alpha=0.7, zorder=1))
    for b in geometry.obstacles:
        if padding > 0:
            p = padded_outline(b, padding)
            ax.plot(p[:, 0], p[:, 1], color="black", lw=0.8, zorder=3)
        ax.add_patch(Polygon(obstacle_outline(b)[:-1], closed=True, facecolor="black", edgecolor="black", zorder=3))
    for o in geometry.objects:
        ax.plot(*o.position[:2], marker="s" if o.shape == "box" else "o", ms=4, color="#e032c8", zorder=9, ls="none")
    sx, sy, syaw = geometry.robot_start
    ax.annotate("", xy=(sx + 0.35 * math.cos(syaw), sy + 0.35 * math.sin(syaw)), xytext=(sx, sy),
                arrowprops=dict(arrowstyle="->", color="0.3", lw=1.2), zorder=9)
    ax.plot(sx, sy, marker="o", ms=4, color="0.3", zorder=9, ls="none")


def set_world_limits(ax: Any, geometry: SceneGeometry) -> None:
    ax.set_xlim(geometry.bounds_low[0], geometry.bounds_high[0])
    ax.set_ylim(geometry.bounds_low[1], geometry.bounds_high[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
