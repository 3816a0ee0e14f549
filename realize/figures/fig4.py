"""Fig. 4 of the seed paper: best sampled cost and share of successful samples per iteration,
mean over runs with a +-1 sigma band.

What it does: ``fig4(run_dirs, out_png)`` reads each run's ``best_cost_per_iter`` and its share
of successful samples per iteration, and plots their mean and standard deviation over runs (a
run's cost before its first success is left out of that iteration); it writes the PNG and a CSV
with the plotted numbers and every run's series. The share is ``finished_success_per_iter``: the
rows that ran to their end that ended feasible, so the rows ``ce.prune`` stopped as "could not be
an elite" do not read as failures (``success_per_iter`` counts them so, and reads flat while a
pruned search learns); runs without pruning, or written before that key, give ``success_per_iter``,
the same share there (``RunDir.finished_success_per_iter``). The CSV gives the stopped rows too.
``find_run_dirs`` finds the run directories among paths (a run, or a folder of runs).
What it doesn't: launch the runs (``realize.figures.launch``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from realize.figures.common import DPI, fmt, plt, write_csv
from realize.run_dir.directory import RunDir
from realize.run_dir.names import RESULT_FILE

__all__ = ["fig4", "find_run_dirs"]


def find_run_dirs(paths: Sequence[str | Path]) -> list[Path]:
    """Run directories among ``paths``: each path that holds a ``result.json``, else its
    sub-directories (one level, e.g. a Hydra multirun folder) that do, sorted."""
    out: list[Path] = []
    for p in map(Path, paths):
        if (p / RESULT_FILE).is_file():
            out.append(p)
        elif p.is_dir():
            out += sorted(q for q in p.iterdir() if (q / RESULT_FILE).is_file())
    return out


def fig4(
    run_dirs: Sequence[str | Path],
    out_png: str | Path,
    out_csv: str | Path | None = None,
) -> tuple[Path, Path]:
    """Best sampled cost per iteration (left axis) and share of successful samples (right axis,
    in %), mean over runs with a +-1 sigma band (the paper's Fig. 4). A run's cost before its
    first success is missing and left out of that iteration's mean (``n_cost`` in the CSV).
    The share is of the rows that finished (those ``ce.prune`` stopped left out; module docstring).
    CSV rows: iteration, cost_mean, cost_std, n_cost, share_mean, share_std, n_share,
    stopped_mean (rows stopped per run, mean over the runs that say), then ``cost_<run>``,
    ``share_<run>`` and ``stopped_<run>`` per run (empty: the run does not say)."""
    runs = [RunDir.existing(d) for d in run_dirs]
    if not runs:
        raise ValueError("fig4: no run directories")
    # a cost before the first success (inf: none feasible yet) is missing: NaN
    costs = [np.where(np.isfinite(c), c, np.nan) for c in (r.best_cost_per_iter() for r in runs)]
    shares = [r.finished_success_per_iter() for r in runs]
    stops = [r.n_stopped_per_iter() for r in runs]
    n_it = max(max(len(c), len(s), 0 if t is None else len(t)) for c, s, t in zip(costs, shares, stops))
    if n_it == 0:
        raise ValueError("fig4: the runs hold no per-iteration results (best_cost_per_iter / success_per_iter)")

    def padded(a: np.ndarray) -> np.ndarray:
        return np.concatenate([a, np.full(n_it - len(a), np.nan)])

    cost = np.stack([padded(c) for c in costs])  # (R, I)
    share = 100.0 * np.stack([padded(s) for s in shares])
    stopped = np.stack([padded(np.zeros(0) if s is None else s.astype(np.float64)) for s in stops])

    def stats(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = np.isfinite(a).sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(n > 0, np.nansum(a, axis=0), np.nan) / np.where(n > 0, n, 1)
            dev = np.sqrt(np.where(n > 0, np.nansum((a - s) ** 2, axis=0), np.nan) / np.where(n > 0, n, 1))
        return s, dev, n

    c_mean, c_std, c_n = stats(cost)
    s_mean, s_std, s_n = stats(share)
    stop_mean = stats(stopped)[0]
    it = np.arange(n_it)
    out_png = Path(out_png)
    out_csv = Path(out_csv) if out_csv else out_png.with_suffix(".csv")

    fig, ax = plt.subplots(figsize=(6.0, 3.8))
    c_col, s_col = "#1f5fbf", "#e07b00"
    ax.plot(it, c_mean, color=c_col, lw=2, marker="o", ms=3.5, label="best sampled cost")
    ax.fill_between(it, c_mean - c_std, c_mean + c_std, color=c_col, alpha=0.2, lw=0)
    ax.set_xlabel("CE iteration")
    ax.set_ylabel("cost of the best sampled plan", color=c_col)
    ax.tick_params(axis="y", colors=c_col)
    ax.set_xticks(it)
    ax.grid(alpha=0.3)
    ax2 = ax.twinx()
    ax2.plot(it, s_mean, color=s_col, lw=2, marker="s", ms=3.5, label="successful samples (of those that finished)")
    ax2.fill_between(it, np.clip(s_mean - s_std, 0, 100), np.clip(s_mean + s_std, 0, 100), color=s_col,
                     alpha=0.2, lw=0)
    ax2.set_ylabel("successful sampled plans [%]", color=s_col)
    ax2.tick_params(axis="y", colors=s_col)
    ax2.set_ylim(0, 100)
    lines = ax.get_lines()[:1] + ax2.get_lines()[:1]
    ax.legend(lines, [ln.get_label() for ln in lines], loc="center right", fontsize=8)
    ax.set_title(f"Mean over {len(runs)} runs, band = \u00b11 \u03c3", fontsize=10)
    fig.tight_layout()
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=DPI)
    plt.close(fig)

    names = [r.path.name or str(r.path) for r in runs]
    if len(set(names)) != len(names):
        names = [f"{j}" for j in range(len(runs))]
    header = ["iteration", "cost_mean", "cost_std", "n_cost", "share_mean", "share_std", "n_share", "stopped_mean"]
    header += [f"cost_{n}" for n in names] + [f"share_{n}" for n in names] + [f"stopped_{n}" for n in names]
    rows = [
        [int(i), fmt(c_mean[i]), fmt(c_std[i]), int(c_n[i]), fmt(s_mean[i]), fmt(s_std[i]), int(s_n[i]),
         fmt(stop_mean[i])]
        + [fmt(v) for v in cost[:, i]]
        + [fmt(v) for v in share[:, i]]
        + [fmt(v) for v in stopped[:, i]]
        for i in it
    ]
    write_csv(out_csv, header, rows)
    return out_png, out_csv
