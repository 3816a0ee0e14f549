"""Hydra callback: a ``summary.csv`` of every job of a sweep, in the sweep directory.

What it does: after each job (``on_job_end``) it writes ``job_status.json`` into the job's run
directory (overrides, Hydra's job status, the error if the job raised) and rebuilds
``<sweep dir>/summary.csv`` from all job directories found so far, merging each job's
``result.json`` (feasible, best cost, wall time, ...). The rebuild is serialised with a file
lock and written atomically, so it is correct with jobs finishing in parallel (joblib, submitit)
and complete even when Hydra stops the sweep after a failed job (its basic sweeper re-raises the
first failure after the batch and never reaches ``on_multirun_end``). ``on_multirun_end``
rebuilds it once more.

Columns: ``job``, then one column per key the jobs override (``ce.n_envs``, ``seed``: the swept
keys and any fixed override, each job's value; empty where a job lacks it), then ``overrides,
status, error, feasible, best_cost, objective, final_success, final_finished_success, final_stopped,
wall_time_s, iterations_done, interrupted, run_dir`` (``objective``: what the run returned to the
sweeper, ``realize.run.objective``). ``status`` is ``done``, ``failed`` or ``interrupted``;
``final_success`` is the share of successful samples in the job's last iteration (a row stopped
by ``ce.prune`` counts as not successful); with ``ce.prune``, ``final_stopped`` is how many rows
of that iteration were stopped and ``final_finished_success`` the share of the rest (the rows
that ran to their end) that ended feasible (both empty without pruning; ``result.json``'s
``n_stopped_per_iter`` and ``finished_success_per_iter``). Each update prints where it wrote the table.
Both files are read and written through ``realize.run_dir.directory.RunDir`` (``JobStatusDoc``,
``ResultDoc``/``FailureDoc``).
What it doesn't: run or retry jobs, or read anything but JSON files (no unpickling).
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Any

from hydra.core.utils import JobReturn, JobStatus
from hydra.types import RunMode
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from realize.file_lock import file_lock
from realize.run_dir.directory import RunDir
from realize.run_dir.jsonio import atomic_write_text
from realize.run_dir.names import JOB_STATUS_FILE
from realize.run_dir.summaries import JobStatusDoc

__all__ = ["SweepSummary", "write_summary", "COLUMNS"]

COLUMNS = (
    "job",
    "overrides",
    "status",
    "error",
    "feasible",
    "best_cost",
    "objective",
    "final_success",
    "final_finished_success",
    "final_stopped",
    "wall_time_s",
    "iterations_done",
    "interrupted",
    "run_dir",
)


def _one_line(text: str, limit: int = 500) -> str:
    s = " ".join(str(text).split())
    return s if len(s) <= limit else s[: limit - 3] + "..."


def _row(status_file: Path, sweep_dir: Path) -> dict[str, Any]:
    job = RunDir(status_file.parent)
    st = job.job_status() or JobStatusDoc(job_num=None)
    try:
        res = job.result()
    except (KeyError, TypeError, ValueError, AttributeError):  # a malformed result: the job's own status
        res = None
    status = st.status
    error = (res.error if res is not None else None) or st.error or ""
    if status == "done" and res is not None and res.status == "failed":
        status = "failed"
    if status == "done" and res is not None and res.interrupted:
        status = "interrupted"
    try:
        rel = str(job.path.relative_to(sweep_dir))
    except ValueError:
        rel = str(job.path)
    row: dict[str, Any] = {
        "job": "" if st.job_num is None else st.job_num,
        "overrides": " ".join(st.overrides),
        "status": status,
        "error": _one_line(error) if error else "",
        "feasible": "", "best_cost": "", "objective": "", "final_success": "", "final_finished_success": "",
        "final_stopped": "", "wall_time_s": "", "iterations_done": "", "interrupted": "",
        "run_dir": rel,
    }
    if res is not None:
        row.update(
            feasible=res.feasible,
            best_cost=res.best_cost if math.isfinite(res.best_cost) else "",
            objective=res.extra.get("objective", "") if isinstance(getattr(res, "extra", None), dict) else "",
            wall_time_s=round(res.wall_time_s, 3) if math.isfinite(res.wall_time_s) else "",
            iterations_done=res.iterations_done,
            interrupted=res.interrupted,
        )
        last = getattr(res, "success_per_iter", None)
        if last and math.isfinite(last[-1]):
            row["final_success"] = last[-1]
        stopped = getattr(res, "n_stopped_per_iter", None)
        if stopped:  # ce.prune: the share above counts the stopped rows as failed
            row["final_stopped"] = stopped[-1]
            finished = res.finished_success_per_iter()
            if finished and finished[-1] is not None:
                row["final_finished_success"] = finished[-1]
    row.update(_override_values(st.overrides))
    return row


def _override_values(overrides: list[str]) -> dict[str, str]:
    """``["ce.n_envs=100", "+x=1"]`` -> ``{"ce.n_envs": "100", "x": "1"}``."""
    out = {}
    for o in overrides:
        key, sep, value = str(o).partition("=")
        key = key.lstrip("+~")
        if sep and key not in COLUMNS:
            out[key] = value
    return out


def write_summary(sweep_dir: Path | str, filename: str = "summary.csv") -> Path:
    """Rebuild ``<sweep_dir>/<filename>`` from the ``job_status.json`` files under it."""
    sweep_dir = Path(sweep_dir)
    rows = [_row(p, sweep_dir) for p in sweep_dir.rglob(JOB_STATUS_FILE)]

    def order(r: dict[str, Any]) -> tuple[int, str]:
        j = r["job"]
        return (int(j) if isinstance(j, int) or str(j).isdigit() else 1 << 30, str(r["run_dir"]))

    rows.sort(key=order)
    keys = list(dict.fromkeys(k for r in rows for k in r if k not in COLUMNS))
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=[COLUMNS[0], *keys, *COLUMNS[1:]], restval="", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(r)
    out = sweep_dir / filename
    atomic_write_text(out, buf.getvalue())
    return out


class SweepSummary(Callback):
    """Hydra callback writing ``summary.csv`` in the sweep directory (see module docstring)."""

    def __init__(self, filename: str = "summary.csv") -> None:
        self.filename = filename

    def _update(self, sweep_dir: Path) -> None:
        with file_lock(sweep_dir / f".{self.filename}.lock"):
            out = write_summary(sweep_dir, self.filename)
        print(f"sweep summary: {out}", flush=True)

    def on_job_end(self, config: DictConfig, job_return: JobReturn, **kwargs: Any) -> None:
        hydra = config.get("hydra")
        if hydra is None or hydra.get("mode") != RunMode.MULTIRUN:
            return
        job_dir = Path(str(hydra.runtime.output_dir))
        ok = job_return.status == JobStatus.COMPLETED
        error = ""
        if not ok:
            err = job_return._return_value  # the exception (reading .return_value would re-raise)
            error = f"{type(err).__name__}: {err}" if err is not None else "unknown error"
        status = JobStatusDoc(
            job_num=int(hydra.job.num) if hydra.job.get("num") is not None else None,
            overrides=[str(o) for o in (job_return.overrides or [])],
            status="done" if ok else "failed",
            error=error,
        )
        RunDir(job_dir).write_job_status(status)
        self._update(Path(str(hydra.sweep.dir)))

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(str(OmegaConf.select(config, "hydra.sweep.dir")))
        if sweep_dir.is_dir():
            self._update(sweep_dir)
