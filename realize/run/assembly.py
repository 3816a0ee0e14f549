"""One ``realize`` run assembled: config -> run spec -> searcher and sinks -> the search loop -> outcome.

What it does: ``prepare_run(cfg, out_dir)`` validates the whole config first (``realize.spec.run_spec``;
a ``ConfigError`` leaves a ``failed`` result.json and nothing simulated), picks the searcher
(``CrossEntropyOptimizer`` for one plan; ``SuccessiveHalving`` over the planner's candidates
with ``task.planner.top_k > 1``; ``ChainSearch`` with ``stitch.enabled``, whose batches are
the plan's segments (one cut: a prefix and a suffix) and the confirmation:
``realize.run.stitched_run.run_segments``) and the sinks, in their order per iteration:

  1. ``CheckpointSink``: ``history.npz`` (``history_c{i}.npz`` per candidate), then
     ``checkpoint.json``, the commit point;
  2. ``ResultSink``: ``result.json`` (a top-k run's top level is its leading candidate, the
     winner once decided, plus ``candidates``/``winner``/``budget``);
  3. ``RerunSink`` (``logging.rerun``): ``logging.rrd``, ``<stem>_c{i}.rrd`` per candidate;
  4. ``TrajectorySink`` (single-plan runs): ``scene.json``, ``trajectories_iter{k}.npz``;
  5. ``ProgressSink``: the tqdm bar (``logging.progress``);

and runs ``realize.run.loop.search_loop``. ``resume=<run dir>`` continues that run (one plan or
top-k) in its own directory from its checkpoint with its saved config: the searcher's
``load_state_dict`` and the history files restore it, and on CPU the final result equals that
of an uninterrupted run. ``warm_start=<run dir>`` starts the search from that earlier run's
final distribution (``realize.search.warm_start``; read before anything is simulated).
``replan_from=<run dir>`` (``realize.spec.replan_from``) starts a new run from that run's saved config with
the command line's changes on top, over the plan's remaining actions from a given state,
warm-started from that run's distribution of those actions (``replan.warm``). SIGINT/SIGTERM
end a run as ``interrupted`` (exit code 130/143).
``execute`` runs it (``realize.run.planner.Planner`` calls both, keeping the workers; ``realize.run.one_run.run``
is the one-call form). What it doesn't: parse the command line (``realize.cli.main``), or search, simulate and write
files itself (``realize.run.loop``, ``realize.sinks``, ``realize.run_dir``).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from realize.search.candidates import CandidateSpec, SuccessiveHalving
from realize.search.ce.optimizer import CrossEntropyOptimizer
from realize.realization.screening import plan_screen
from realize.config import ConfigError
from realize.spec.hydra_edge import register_resolvers, resolution_error
from realize.run.loop import search_loop
from realize.run.objective import record_objective
from realize.spec.replan_from import replan_config
from realize.spec.resume_config import RESUME_ALLOWED_PREFIXES, resume_config
from realize.workers.pool import RolloutPool, open_pool
from realize.spec.run_spec import RunSpec, build_run_spec
from realize.spec.task_plans import load_task_file
from realize.run_dir.build import RunInfo, failure_doc, result_doc
from realize.run_dir.checkpoint import Checkpoint, CheckpointError, load_checkpoint
from realize.run_dir.directory import RunDir
from realize.run_dir.history import History
from realize.run_dir.names import CHECKPOINT_FILE, ERROR_FILE, HISTORY_FILE, RESULT_FILE, WORKER_LOG_DIR, candidate_file
from realize.run_dir.result_doc import ResultDoc
from realize.run_dir.summaries import IterationSummary
from realize.search.protocol import SearchReport, Searcher
from realize.sinks.base import Iteration, Sink, SinkSet
from realize.sinks.files import CheckpointSink, ResultSink, RunClock
from realize.sinks.progress import ProgressSink
from realize.sinks.rerun import RerunSink, recording_name
from realize.sinks.trajectories import TrajectorySink
from realize.recording.validation_log import VALIDATION_RRD, log_validation
from realize.search.warm_start import WarmStart, load_warm_start

__all__ = ["prepare_run", "RunOutcome", "plain_config", "PoolSource", "RESUME_ALLOWED_PREFIXES"]

log = logging.getLogger("realize")

# (spec, tasks, worker log dir) -> the run's rollout workers (a planner's, which it keeps open)
PoolSource = Callable[[RunSpec, Sequence[Any], Path], RolloutPool]


@dataclass
class RunOutcome:
    """What ``run`` returns: where the results are and how the run ended."""

    run_dir: Path
    status: str  # done | interrupted
    feasible: bool
    best_cost: float
    iterations_done: int
    wall_time_s: float
    exit_code: int = 0
    objective: float = math.inf  # what a sweep minimizes (realize.run.objective; result.json: objective)

    @property
    def interrupted(self) -> bool:
        return self.status == "interrupted"


def plain_config(cfg: DictConfig | Mapping[str, Any]) -> dict[str, Any]:
    """Resolved plain data of the run config (no ``hydra`` node)."""
    register_resolvers()  # a config composed outside realize's own compose (a notebook's Hydra)
    if isinstance(cfg, DictConfig):
        try:
            d = OmegaConf.to_container(cfg, resolve=True, throw_on_missing=True)
        except Exception as e:  # interpolation / missing-value errors from OmegaConf
            raise resolution_error(e) from None
    else:
        d = OmegaConf.to_container(OmegaConf.create(dict(cfg)), resolve=True)
    assert isinstance(d, dict)
    d.pop("hydra", None)
    return d



def prepare_run(cfg: DictConfig | Mapping[str, Any], out_dir: Path | str, cli_overrides: Sequence[str] = (), *,
                merged: bool = False) -> _Assembly:
    """The validated run of ``cfg`` in ``out_dir`` (``resume``: the resumed run's directory and
    checkpoint; ``replan_from``: the earlier run's config with the command line's changes on
    top, unless ``merged``: ``cfg`` is that config already, as ``Planner.replan`` makes it),
    ready to ``execute``. A ``ConfigError`` leaves a ``failed`` result.json in ``out_dir`` and
    is raised."""
    clock = RunClock()
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    current: dict[str, Any] | None = None
    try:
        current = plain_config(cfg)
        run_dir, ckpt = Path(out_dir), None
        if current.get("resume") is not None:
            try:
                ckpt = load_checkpoint(str(current["resume"]))
            except CheckpointError as e:
                raise ConfigError(str(e)) from None
            run_dir = Path(str(current["resume"]))
            current = resume_config(current, ckpt, cli_overrides)
        elif current.get("replan_from") is not None and not merged:  # the earlier run's config, changes on top
            current = replan_config(current, cli_overrides)
        return _Assembly(build_run_spec(current), run_dir, ckpt, clock)
    except ConfigError as e:
        RunDir(out_dir).write_failure(failure_doc(str(e), config=_as_given(current)))
        raise


def _as_given(config: dict[str, Any] | None) -> dict[str, Any] | None:
    """A failed run's config as it was given: with ``task_file``, the file's content as its
    ``task`` (None where the file cannot be read), not the default task group it replaces."""
    if config is None or config.get("task_file") is None:
        return config
    out = dict(config)
    try:
        out["task"], _ = load_task_file(config["task_file"])
    except ConfigError:
        out["task"] = None
    return out


class _Assembly:
    """A validated run, ready to simulate: its searcher (restored when resuming) and sinks."""

    def __init__(self, spec: RunSpec, run_dir: Path, ckpt: Checkpoint | None, clock: RunClock) -> None:
        self.spec, self.run_dir, self.rd, self.clock = spec, run_dir, RunDir(run_dir), clock
        self.tasks = list(spec.candidates) if spec.halving else [spec.task]
        self.keys: list[int | None] = list(range(len(self.tasks))) if spec.halving else [None]
        self.stitched: Searcher | None = None
        if spec.stitch is not None:  # the whole plan (its confirmation) and its segments
            from realize.run.stitched_run import run_segments

            self.tasks, self.keys, self.stitched = run_segments(spec)
        self.batches = spec.ce.iterations if spec.stitch is None else spec.stitch.batches
        self.warm: WarmStart | None = None
        warm_from = spec.warm_start
        if warm_from is None and spec.replan is not None and spec.replan.warm:
            warm_from = spec.replan.run_dir  # a replan starts from that run's distribution of the remaining actions
        self.warm_from = warm_from
        if warm_from is not None and ckpt is None:  # a resumed run goes on from its checkpoint
            self.warm = load_warm_start(warm_from, spec.task, spec.geometry, spec.ce)
        self.searcher = self._searcher()
        histories, records = self._restore(ckpt)
        self.start = self.searcher.iterations_done
        clock.before = 0.0 if ckpt is None else ckpt.wall_time_s
        self.info = RunInfo(segments=1 if ckpt is None else ckpt.segments + 1,
                            resumed_from_iteration=None if ckpt is None else ckpt.iteration,
                            warm_start=self._warm_record(ckpt))
        self.result = ResultSink(self.rd, self._doc, self.searcher.report(), records)
        self.sinks = self._sinks(histories, records)

    def _searcher(self) -> Searcher:
        spec = self.spec
        if self.stitched is not None:
            return self.stitched
        if spec.halving:
            assert spec.budget is not None
            plans = [CandidateSpec(t.describe(), t.layout, t.n_actions) for t in self.tasks]
            return SuccessiveHalving(plans, spec.ce, spec.budget, device=spec.placement.device,
                                     top_k=spec.planner.top_k)
        return CrossEntropyOptimizer(spec.task.layout, spec.ce, device=spec.placement.device,
                                     warm=None if self.warm is None else self.warm.distribution,
                                     screen=plan_screen(spec.task, spec.geometry, spec.robot, spec.rollout,
                                                        spec.ce) if spec.ce.screen else None)

    def _warm_record(self, ckpt: Checkpoint | None) -> dict[str, Any] | None:
        """What result.json says of the warm start (a resumed run keeps its earlier record)."""
        if self.warm is not None:
            return self.warm.to_dict()
        if ckpt is not None and self.warm_from is not None:  # a resumed warm run or replan
            earlier = (self.rd.result_json() or {}).get("warm_start")
            return earlier if isinstance(earlier, dict) else {"run_dir": self.warm_from}
        return None

    def _restore(self, ckpt: Checkpoint | None) -> tuple[dict[int | None, History], list[IterationSummary]]:
        """Fresh histories, or the checkpoint's state, histories and records (``ConfigError``)."""
        histories = {k: History(t.layout.column_names) for k, t in zip(self.keys, self.tasks)}
        if ckpt is None:
            return histories, []
        where = self.run_dir / CHECKPOINT_FILE
        try:
            self.searcher.load_state_dict(ckpt.ce_state)
        except ValueError as e:
            raise ConfigError(f"resume: {where} has a malformed ce_state ({e})") from None
        if self.searcher.iterations_done != ckpt.iteration:
            raise ConfigError(f"resume: {where} is inconsistent (iteration vs ce_state.iteration)")
        for k, t in zip(self.keys, self.tasks):
            n = sum(1 for r in ckpt.records if r.candidate == k)
            path = self.rd.history_path(k)
            if n == 0:
                continue
            if not path.is_file():
                raise ConfigError(f"resume: {path} is missing (the run's per-iteration history)")
            try:
                histories[k] = self.rd.load_history(keep=n, candidate=k)
            except (OSError, KeyError, ValueError) as e:
                raise ConfigError(f"resume: {path} cannot be read ({e})") from None
            if len(histories[k]) != n or histories[k].column_names != t.layout.column_names:
                raise ConfigError(f"resume: {path} does not match {CHECKPOINT_FILE} (iterations or columns differ)")
        return histories, list(ckpt.records)

    def _doc(self, status: str, error: str | None, report: SearchReport,
             records: Sequence[IterationSummary]) -> ResultDoc:
        spec, lead = self.spec, report.lead
        mine = records if spec.stitch is not None else [r for r in records if r.candidate == lead]  # (all segments)
        doc = result_doc(status=status, state=report.state, summaries=mine,
                          task=self.tasks[0 if lead is None else lead], iterations=self.batches,
                          seed=spec.seed, config=spec.config, run_dir=self.run_dir, wall_time_s=self.clock.wall(),
                          error=error, info=self.info, halving=report.halving)
        if spec.stitch is not None:
            from realize.run.stitched_run import stitched_doc

            doc.extra["stitched"] = stitched_doc(spec.stitch, self.tasks, records)
        if spec.replan is not None:  # where this run replanned from
            doc.extra["replan"] = spec.replan.to_json(warm_start=self.info.warm_start)
        if getattr(self, "stopped_early", False):  # a replan that had its plan before its last iteration
            doc.extra["stopped_early"] = True
        if spec.ce.replicas > 1:  # a robust search: best_cost is the risk cost over the worlds
            doc.extra["robust"] = {"replicas": spec.ce.replicas, "risk": spec.ce.risk, "cvar_alpha": spec.ce.cvar_alpha,
                                   "best_share": report.state.best_share}
        return doc

    def _sinks(self, histories: dict[int | None, History], records: list[IterationSummary]) -> list[Sink]:
        spec, padding = self.spec, self.spec.rollout.astar.padding
        sinks: list[Sink] = [CheckpointSink(self.rd, histories, records, spec.config, self.clock, self.info.segments),
                             self.result]
        if spec.logging.rerun:
            plans = {k: (self.run_dir / recording_name(spec.logging.rrd, k, len(histories[k])), t.layout)
                     for k, t in zip(self.keys, self.tasks)}
            actions = {k: [str(a) for a in t.plan] for k, t in zip(self.keys, self.tasks)}
            sinks.append(RerunSink(plans, spec.geometry, padding, spec.ce.iterations, record=spec.logging.record,
                                   actions=actions, control_freq=spec.sim.control_freq, robot=spec.robot))
        if not spec.halving:  # the figures' readers assume one parameter layout (a stitched run's: the whole plan)
            sinks.append(TrajectorySink(self.rd, spec.task.layout, spec.geometry, padding, record=spec.logging.record,
                                        whole_plans_only=spec.stitch is not None))
        desc = "CE top-k" if spec.halving else "CE stitched" if spec.stitch is not None else "CE"
        labels = None
        if spec.stitch is not None:
            from realize.run.stitched_run import segment_names

            labels = {k: segment_names(spec.stitch)[k] for k in self.keys}
        sinks.append(ProgressSink(self.batches, self.start, desc, spec.logging.progress, labels))
        return sinks

    def _open_pool(self, source: PoolSource | None = None) -> RolloutPool:
        spec, t0 = self.spec, time.perf_counter()
        log_dir = self.run_dir / WORKER_LOG_DIR
        pool = open_pool(spec, self.tasks, log_dir=log_dir) if source is None else source(spec, self.tasks, log_dir)
        self.info.backend, self.info.n_envs, self.info.setup_time_s = pool.backend, pool.n_envs, time.perf_counter() - t0
        self.info.workers = pool.n_workers
        if pool.n_workers > 1:
            where = getattr(pool, "log_location", None) or self.run_dir / WORKER_LOG_DIR
            log.info("%d rollout workers (%s; logs: %s)", pool.n_workers, pool.kind, where)
        if spec.halving:
            assert spec.budget is not None
            for i, t in enumerate(self.tasks):
                log.info("candidate %d: %s", i, t.describe())
            log.info("%d candidate(s), halving budget %s; %d copies on %s (setup %.1f s)", len(self.tasks),
                     spec.budget.to_dict(), pool.n_envs, pool.backend, self.info.setup_time_s)
        else:
            log.info("plan %s; %d copies on %s (setup %.1f s)", spec.task.describe(), pool.n_envs, pool.backend,
                     self.info.setup_time_s)
        if spec.stitch is not None:
            log.info("stitched segments: %s; %s", ", then ".join(t.describe() for t in self.tasks[1:]), spec.stitch)
        return pool

    def execute(self, after_iteration: Callable[[int], None] | None = None, *, pools: PoolSource | None = None,
                until: Callable[[Iteration], bool] | None = None) -> RunOutcome:
        """Search (and validate) to the end. ``pools(spec, tasks, log_dir)`` gives the workers
        (a planner's, kept open: it closes them) instead of opening and closing them here;
        ``until(iteration)`` true ends the search after that iteration (``stopped_early``)."""
        spec, run_dir = self.spec, self.run_dir
        self.stopped_early, self.search_s, self.validation_s = False, 0.0, 0.0
        complete = self.searcher.done  # a resumed run that had already finished: nothing changes
        if complete:
            log.info("%s is already complete: nothing to run, its results stay as they are", run_dir)
            status, exit_code, n_done = "done", 0, self.start
        else:
            if self.start:
                log.info("resuming %s after iteration %d of %d", run_dir, self.start, self.batches)
            if spec.halving and len(self.tasks) < spec.planner.top_k:
                log.info("the planner returned %d distinct plan(s) for top_k = %d", len(self.tasks),
                         spec.planner.top_k)
            t_search = time.perf_counter()
            end = search_loop(self.searcher, SinkSet(self.sinks), lambda: self._open_pool(pools),
                              error_file=run_dir / ERROR_FILE, after_iteration=after_iteration,
                              keep_pool=pools is not None, until=until)
            status, exit_code, n_done = end.status, end.exit_code, end.iterations
            self.stopped_early = end.stopped
            self.search_s = time.perf_counter() - t_search
        report = self.result.report
        feasible = bool(report.state.best_feasible)
        validated = complete and "validation" in (self.rd.result_json() or {})
        if status == "done" and feasible and spec.validation is not None and spec.validation.replicas > 0 \
                and not validated:  # (a complete run whose validation was cut off validates now)
            t_validation = time.perf_counter()
            self._validate()
            self.validation_s = time.perf_counter() - t_validation
        outcome = RunOutcome(run_dir, status, feasible, report.state.best_cost if feasible else math.inf, n_done,
                             self.clock.wall(), exit_code)
        if status == "done":  # what a sweep minimizes, into result.json too
            outcome.objective = record_objective(self.rd, spec.rollout.max_time_s, spec.sim.control_freq,
                                                 spec.task.final_cost)
        if complete:
            print(f"realize: {run_dir} was already complete; nothing changed", flush=True)
        self._print(outcome, report)
        return outcome

    def _validate(self) -> None:
        """``validation``: the run's candidates under the task's perturbations, into result.json
        (after the search: a failure here is logged and leaves the run's results as they are)."""
        from realize.validation.action_outcomes import weak_lines
        from realize.validation.candidates import validate_candidates
        from realize.validation.replay import ReplayError

        v = self.spec.validation
        if self.spec.logging.progress:  # a minute or two on a CPU: say what runs now
            print(f"validation: the {v.candidates} best plans, each in {v.replicas} perturbed worlds and the "
                  f"unperturbed one ({v.candidates * (v.replicas + 1)} copies at most) ...", flush=True)
        try:
            rep = validate_candidates(self.run_dir, v.candidates, v.replicas, min_success=v.min_success,
                                      iterations=v.iterations, seed=self.spec.seed, spec=self.spec)
        except (ReplayError, ConfigError) as e:
            log.warning("validation skipped: %s", e)
            return
        c = rep.candidates[rep.returned]
        print(f"validation: {len(rep.candidates)} candidate(s) x {rep.replicas} replicas; returned {rep.returned} "
              f"(cost {c.cost:.0f}, success {c.success_share:.2f}, 95 % [{c.ci95[0]:.2f}, {c.ci95[1]:.2f}], "
              f"{rep.reason}); {rep.wall_time_s:.1f} s", flush=True)
        for line in weak_lines(c.per_action or []):  # where the returned plan's failed replicas stopped
            print(f"validation:   {line}", flush=True)
        if self.spec.logging.rerun:
            try:
                log_validation(self.run_dir, rep.to_dict())
            except Exception as e:  # a recording must not fail a run whose results are written
                log.warning("validation.rrd not written: %s", e)

    def _print(self, o: RunOutcome, report: SearchReport) -> None:
        spec = self.spec
        cost = f"{o.best_cost:.0f}" if math.isfinite(o.best_cost) else "none"
        if spec.halving:
            hist, rrd = candidate_file(HISTORY_FILE, 0) + ", ...", candidate_file(spec.logging.rrd, 0) + ", ..."
        elif spec.stitch is not None:  # the confirmation, then each segment's batches
            hist, rrd = (", ".join([f, *(candidate_file(f, k) for k in self.keys[1:])])
                         for f in (HISTORY_FILE, spec.logging.rrd))
        else:
            hist, rrd = HISTORY_FILE, spec.logging.rrd
        early, what = "", "CE iterations" if spec.stitch is None else "batches of a stitched search"
        if o.status == "done" and not spec.halving and o.iterations_done < self.batches:
            early = " (stopped early: ce.patience / ce.converge_std / ce.sample_budget)" if spec.stitch is None else \
                " (no prefix or no stitched plan was feasible)"
        print(
            f"realize: {o.status} after {o.iterations_done}/{self.batches} {what}{early}; "
            f"best cost {cost}; feasible {o.feasible}; wall time {o.wall_time_s:.1f} s\n"
            f"results: {o.run_dir / RESULT_FILE} (also {hist}, {CHECKPOINT_FILE}"
            + (f", {rrd}" if spec.logging.rerun else "")
            + (f", {VALIDATION_RRD}" if (o.run_dir / VALIDATION_RRD).is_file() else "")
            + ")",
            flush=True,
        )
        h = report.halving
        if h is not None:
            w = h.winner
            print(f"top-k: {len(self.tasks)} candidate(s); "
                  + (f"winner {w.index}: {w.plan}" if w is not None else f"no winner yet (leader {report.lead})"),
                  flush=True)
