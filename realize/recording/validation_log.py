"""A run's candidate validation as a small rerun recording, ``validation.rrd`` in the run directory.

What it does: ``log_validation(run_dir, report)`` takes the ``validation`` block of a run's
``result.json`` (``realize.validation.candidates.CandidatesReport.to_dict()``, or the block read
back from the file: ``candidates`` with ``cost``, ``success_share``, ``ci95``, ``failures``,
``cost_mean``; ``returned``, ``reason``, ``replicas``, ``min_success``, ...) and writes, per candidate
(index ``j`` into ``validation.candidates``):

* on the ``validation_candidate`` timeline (sequence ``j``), scalars under ``/validation/success``
  (share, the 95 % Wilson interval's bounds, ``min_success``) and ``/validation/cost`` (nominal
  cost, mean cost of its successful replicas), the returned candidate as one marked point each;
* static bar charts of every candidate's success share and nominal cost, the returned one as a
  second, coloured bar at its index (``/validation/bars/...``);
* a Markdown table (``/validation/summary``): every candidate's numbers, failure reasons and which
  one was returned, and why.
The recording carries a blueprint (bars | interval plot | table) and needs no viewer to write.
``VALIDATION_RRD`` is the file name; ``ENTITY_VALIDATION`` the entity root.

What it doesn't: decide whether to record (the caller checks ``logging.rerun``), read the run
directory or simulate anything, or log the search itself (``realize.recording.log``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import rerun as rr
import rerun.blueprint as rrb

from realize.recording.paths import entity

__all__ = ["VALIDATION_RRD", "ENTITY_VALIDATION", "VALIDATION_TIMELINE", "log_validation", "summary_markdown"]

VALIDATION_RRD = "validation.rrd"
ENTITY_VALIDATION = "validation"
VALIDATION_TIMELINE = "validation_candidate"

_BLUE = (31, 95, 191)
_GREY = (150, 150, 150)
_ORANGE = (224, 123, 0)
_RED = (200, 40, 40)

# scalar entity under /validation -> (series name, colour, report key per candidate or special)
_SERIES: dict[str, tuple[str, tuple[int, int, int]]] = {
    "success/share": ("success share", _BLUE),
    "success/ci95_low": ("95 % interval, low", _GREY),
    "success/ci95_high": ("95 % interval, high", _GREY),
    "success/min_success": ("min_success", _RED),
    "cost/nominal": ("nominal cost", _BLUE),
    "cost/mean_successful": ("mean cost of successful replicas", _GREY),
}
_RETURNED = {"success/returned": ("returned (success share)", _ORANGE),
             "cost/returned": ("returned (nominal cost)", _ORANGE)}


def _num(v: Any) -> float | None:
    """A finite float, else None (JSON ``null``, ``inf``, a missing key)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    f = float(v)
    return f if math.isfinite(f) else None


def _cell(v: float | None, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def _interval(c: Mapping[str, Any]) -> tuple[float | None, float | None]:
    ci = c.get("ci95")
    if isinstance(ci, Sequence) and not isinstance(ci, str) and len(ci) == 2:
        return _num(ci[0]), _num(ci[1])
    return None, None


def _candidates(report: Mapping[str, Any]) -> tuple[list[Mapping[str, Any]], int | None]:
    cands = report.get("candidates")
    if not isinstance(cands, Sequence) or isinstance(cands, str) or not cands:
        raise ValueError("log_validation: the report holds no `candidates` (a single-plan validation?)")
    if not all(isinstance(c, Mapping) for c in cands):
        raise ValueError("log_validation: every entry of `candidates` must be a mapping")
    ret = report.get("returned")
    ret = ret if isinstance(ret, int) and not isinstance(ret, bool) and 0 <= ret < len(cands) else None
    return list(cands), ret


def summary_markdown(report: Mapping[str, Any]) -> str:
    """The Markdown table ``log_validation`` logs: a header on the validation, one row per candidate."""
    cands, ret = _candidates(report)
    ms = _num(report.get("min_success"))
    head = (f"**Candidate validation**: {len(cands)} candidate(s) x {report.get('replicas', '?')} replicas, "
            f"min_success {_cell(ms, '.2f')}, seed {report.get('seed', '?')}, backend {report.get('backend', '?')}, "
            f"{_cell(_num(report.get('wall_time_s')), '.1f')} s\n\n"
            + (f"Returned: **candidate {ret}** ({report.get('reason', '?')})\n\n" if ret is not None
               else "Returned: none named\n\n"))
    rows = ["| # | returned | nominal cost | iteration | success | 95 % interval | mean cost (successful) | failures |",
            "|---|---|---|---|---|---|---|---|"]
    for j, c in enumerate(cands):
        lo, hi = _interval(c)
        fails = c.get("failures") if isinstance(c.get("failures"), Mapping) else {}
        most = sorted(fails.items(), key=lambda kv: (-kv[1], str(kv[0])))
        f_text = ", ".join(f"{str(k).replace('|', '/')} x{v}" for k, v in most) or "-"
        rows.append(f"| {j} | {'**yes**' if j == ret else ''} | {_cell(_num(c.get('cost')), '.1f')} "
                    f"| {c.get('iteration', '-')} | {_cell(_num(c.get('success_share')), '.3f')} "
                    f"| [{_cell(lo, '.3f')}, {_cell(hi, '.3f')}] | {_cell(_num(c.get('cost_mean')), '.1f')} "
                    f"| {f_text} |")
    pert = report.get("perturbation")
    tail = ""
    if isinstance(pert, Mapping) and pert:
        tail = "\n\nPerturbation: " + ", ".join(f"{k} = {v}" for k, v in pert.items())
    return head + "\n".join(rows) + tail


def _blueprint() -> rrb.Blueprint:
    root = f"/{ENTITY_VALIDATION}"
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.BarChartView(name="success share per candidate", origin=f"{root}/bars/success"),
                rrb.BarChartView(name="nominal cost per candidate", origin=f"{root}/bars/cost"),
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="success share and 95 % interval", origin=f"{root}/success"),
                rrb.TimeSeriesView(name="cost", origin=f"{root}/cost"),
            ),
            rrb.TextDocumentView(name="validation", origin=f"{root}/summary"),
            column_shares=[2, 2, 3],
        ),
        collapse_panels=True,
    )


def log_validation(run_dir: str | Path, report: Mapping[str, Any], *, name: str = VALIDATION_RRD,
                   application_id: str = "realize") -> Path:
    """Write ``run_dir/name`` (``validation.rrd``) from a ``validation`` block (module docstring);
    returns its path. ``ValueError`` if the block holds no candidates."""
    cands, ret = _candidates(report)
    path = Path(run_dir) / name
    path.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream(application_id)
    rec.save(path, default_blueprint=_blueprint())
    try:
        for sub, (series, rgb) in {**_SERIES, **_RETURNED}.items():
            p = entity(ENTITY_VALIDATION, sub)
            rec.log(p, rr.SeriesPoints(colors=[rgb], names=[series],
                                       marker_sizes=[8.0 if sub in _RETURNED else 4.0]), static=True)
            if sub not in _RETURNED:
                rec.log(p, rr.SeriesLines(colors=[rgb], names=[series], widths=[1.5]), static=True)
        ms = _num(report.get("min_success"))
        shares = [_num(c.get("success_share")) for c in cands]
        costs = [_num(c.get("cost")) for c in cands]
        for j, c in enumerate(cands):
            rec.set_time(VALIDATION_TIMELINE, sequence=j)
            lo, hi = _interval(c)
            values = {"success/share": shares[j], "success/ci95_low": lo, "success/ci95_high": hi,
                      "success/min_success": ms, "cost/nominal": costs[j],
                      "cost/mean_successful": _num(c.get("cost_mean"))}
            if j == ret:
                values.update({"success/returned": shares[j], "cost/returned": costs[j]})
            for sub, v in values.items():
                if v is not None:
                    rec.log(entity(ENTITY_VALIDATION, sub), rr.Scalars(v))
        index = list(range(len(cands)))
        for key, vals in (("success", shares), ("cost", costs)):
            clean = [math.nan if v is None else v for v in vals]
            rec.log(entity(ENTITY_VALIDATION, "bars", key, "candidates"),
                    rr.BarChart(clean, abscissa=index, color=_BLUE), static=True)
            if ret is not None:
                rec.log(entity(ENTITY_VALIDATION, "bars", key, "returned"),
                        rr.BarChart([clean[ret]], abscissa=[ret], color=_ORANGE), static=True)
        rec.log(entity(ENTITY_VALIDATION, "summary"),
                rr.TextDocument(summary_markdown(report), media_type=rr.MediaType.MARKDOWN), static=True)
    finally:
        rec.flush()
        rec.disconnect()
    return path
