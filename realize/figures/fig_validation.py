"""The validation figure: a run's validated candidates, nominal cost against success share.

What it does: ``fig_validation(run_dir)`` reads the ``validation`` block of the run's
``result.json`` (a candidate validation: ``validation.replicas=R`` after the search, or
``scripts/validate.py --candidates K``) and draws every candidate at (its nominal cost, its
success share under the task's perturbations) with its 95 % Wilson interval as error bars, the
returned candidate highlighted, and ``min_success`` as a dashed line; it writes the PNG and a
CSV with the plotted numbers (default ``RUN_DIR/figures/fig_validation.{png,csv}``).
What it doesn't: validate (``realize.validation.candidates``) or recompute an interval: the
numbers are the block's. A single-plan validation (no ``candidates``) is refused with one line.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from realize.figures.common import CYAN, DPI, fmt, plt, write_csv
from realize.run_dir.directory import RunDir
from realize.run_dir.names import RESULT_FILE

__all__ = ["fig_validation", "validation_rows"]

_BLUE = "#1f5fbf"
_ORANGE = "#e07b00"

HEADER = ["candidate", "returned", "cost", "iteration", "success_share", "ci95_low", "ci95_high", "cost_mean",
          "replicas", "min_success"]


def _num(v: Any) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


def validation_rows(block: Mapping[str, Any]) -> list[list[Any]]:
    """One row per candidate of a ``validation`` block, in ``HEADER``'s order (missing numbers NaN)."""
    cands = block.get("candidates")
    if not isinstance(cands, Sequence) or isinstance(cands, str) or not cands:
        raise ValueError("the validation block holds no candidates")
    ret = block.get("returned")
    ret = ret if isinstance(ret, int) and not isinstance(ret, bool) else None
    rows = []
    for j, c in enumerate(cands):
        if not isinstance(c, Mapping):
            raise ValueError(f"validation.candidates[{j}] is not a mapping")
        ci = c.get("ci95")
        lo, hi = (_num(ci[0]), _num(ci[1])) if isinstance(ci, Sequence) and len(ci) == 2 else (math.nan, math.nan)
        rows.append([j, j == ret, _num(c.get("cost")), c.get("iteration"), _num(c.get("success_share")), lo, hi,
                     _num(c.get("cost_mean")), block.get("replicas"), _num(block.get("min_success"))])
    return rows


def fig_validation(
    run_dir: str | Path,
    out_png: str | Path | None = None,
    out_csv: str | Path | None = None,
) -> tuple[Path, Path]:
    """Candidates' nominal cost (x) against success share (y, in %) with their 95 % intervals,
    the returned one highlighted and ``min_success`` dashed (module docstring). CSV rows:
    candidate, returned, cost, iteration, success_share, ci95_low, ci95_high, cost_mean,
    replicas, min_success."""
    rd = RunDir.existing(run_dir)
    d = rd.result_json() or {}
    block = d.get("validation")
    where = rd.path / RESULT_FILE
    if not isinstance(block, Mapping):
        raise FileNotFoundError(f"fig_validation: {where} holds no `validation` (run with validation.replicas=R, "
                                "or scripts/validate.py RUN_DIR --candidates K)")
    if "candidates" not in block:
        raise ValueError(f"fig_validation: {where}'s validation is a single-plan one (no candidates); "
                         "scripts/validate.py RUN_DIR --candidates K validates several")
    try:
        rows = validation_rows(block)
    except ValueError as e:
        raise ValueError(f"fig_validation: {where}: {e}") from None
    run_dir = Path(run_dir)
    out_png = Path(out_png) if out_png else run_dir / "figures" / "fig_validation.png"
    out_csv = Path(out_csv) if out_csv else out_png.with_suffix(".csv")

    a = np.array([[r[2], r[4], r[5], r[6]] for r in rows], dtype=np.float64)  # cost, share, lo, hi
    cost, share, lo, hi = a[:, 0], 100 * a[:, 1], 100 * a[:, 2], 100 * a[:, 3]
    err = np.stack([np.clip(share - lo, 0, None), np.clip(hi - share, 0, None)])
    err = np.where(np.isfinite(err), err, 0.0)
    returned = [bool(r[1]) for r in rows]
    ms = _num(block.get("min_success"))

    fig, ax = plt.subplots(figsize=(6.0, 3.8))
    others = [j for j, x in enumerate(returned) if not x]
    if others:
        ax.errorbar(cost[others], share[others], yerr=err[:, others], fmt="o", ms=5, color=_BLUE, ecolor=_BLUE,
                    elinewidth=1.2, capsize=3, label="candidate (95 % Wilson interval)", zorder=3)
    for j in (j for j, x in enumerate(returned) if x):
        ax.errorbar(cost[[j]], share[[j]], yerr=err[:, [j]], fmt="D", ms=8, color=_ORANGE, ecolor=_ORANGE,
                    markeredgecolor="black", elinewidth=2.0, capsize=4, label=f"returned (candidate {j})", zorder=4)
    for j in range(len(rows)):
        if np.isfinite(cost[j]) and np.isfinite(share[j]):
            ax.annotate(f"#{j}", (cost[j], share[j]), xytext=(6, -4 - 8 * (j % 3)), textcoords="offset points",
                        fontsize=7, color="0.25")
    if math.isfinite(ms):
        ax.axhline(100 * ms, color=CYAN, ls="--", lw=1.5, label=f"min_success {100 * ms:.0f} %", zorder=2)
    finite = cost[np.isfinite(cost)]
    if finite.size:  # costs of near-identical plans can sit within a fraction of a unit: keep a visible span
        mid, span = (finite.min() + finite.max()) / 2, max(finite.max() - finite.min(), 2.0)
        ax.set_xlim(mid - 0.65 * span, mid + 0.65 * span)
    ax.set_ylim(-3, 106)
    ax.set_xlabel("nominal cost (the search's)")
    ax.set_ylabel("successful replicas [%]")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(f"{len(rows)} candidates x {block.get('replicas', '?')} replicas; {block.get('reason', '')}",
                 fontsize=10)
    fig.tight_layout()
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=DPI)
    plt.close(fig)
    write_csv(out_csv, HEADER, [[fmt(v) for v in r] for r in rows])
    return out_png, out_csv
