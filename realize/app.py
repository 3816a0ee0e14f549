"""The ``realize`` command (Hydra): validate the config, run the cross-entropy search, save it.

What it does:
  * ``main()`` (console script ``realize`` and ``python -m realize``) checks the command line
    (config group choices such as ``experiment=``, a ``resume=`` directory, and, for a single
    run, the whole composition) and hands over to Hydra; bad input ends with one line
    ``error: <message>`` on stderr and exit code 2, before any simulator is built;
  * ``run(cfg, out_dir)`` is one run: the whole config is validated into dataclasses first
    (``realize.run_config.build_run_spec``), then the batched scene (as many copies as the
    largest batch of the CE schedule), the ``PlanRealizer`` and the ``CrossEntropyOptimizer``
    are built and iterated. After every iteration ``history.npz``, ``checkpoint.json`` and
    ``result.json`` are written atomically (in that order: the checkpoint is the commit point),
    a tqdm bar shows the success share and best cost, the rerun logger (if present and
    ``logging.rerun``) logs the iteration, and with ``logging.record`` the sample trajectories
    go to ``trajectories_iter{k}.npz`` (``realize.figures`` format, with ``scene.json``);
  * with ``task.planner.top_k > 1`` the run is successive halving over the planner's k best
    plans in one shared budget (``realize.candidates``; ``_iterate_halving``): per-candidate
    ``history_c{i}.npz`` and ``<rrd stem>_c{i}.rrd``, and ``result.json`` gains ``candidates``,
    ``winner`` and ``budget`` while its top-level best_* describe the leading candidate (the
    winner once decided), so single-plan readers keep working. No figure trajectory files;
  * ``resume=<run dir>`` continues that run in its own directory from its checkpoint with its
    saved config; on CPU the final result equals that of an uninterrupted run. Top-k runs
    cannot be resumed yet (a clear ``ConfigError``);
  * SIGINT/SIGTERM: the iteration in flight is dropped, ``result.json`` is rewritten with
    ``interrupted: true`` (the last complete iteration stays on disk) and the exit code is
    130/143. Any other failure is written to ``result.json`` and ``error.txt`` and re-raised.
What it doesn't: implement search, simulation or logging backends (``realize.cross_entropy``,
``realize.rollout``, ``realize.rerun_log``), or summarise sweeps (``realize.sweep_summary``).
"""

from __future__ import annotations

import contextlib
import logging
import math
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hydra.errors import CompactHydraException
from omegaconf import DictConfig, OmegaConf

from realize.results import (
    CHECKPOINT_FILE,
    ERROR_FILE,
    HISTORY_FILE,
    RESULT_FILE,
    Checkpoint,
    CheckpointError,
    History,
    atomic_write_json,
    atomic_write_text,
    json_safe,
    load_checkpoint,
    load_history,
    package_versions,
    save_checkpoint,
    series,
)
from realize.run_config import REPO_ROOT, ConfigError, RunSpec, build_run_spec

__all__ = ["main", "run", "RunOutcome", "RunInterrupted", "CONFIG_DIR", "preflight"]

log = logging.getLogger("realize")

CONFIG_DIR = REPO_ROOT / "configs"
CONFIG_GROUPS = ("task", "scene", "sim", "controller", "ce", "logging", "experiment")
EXIT_CONFIG = 2
EXIT_SIGNAL = {signal.SIGINT: 130, signal.SIGTERM: 143}
HALVING_KIND = "successive_halving"  # checkpoint ce_state "kind" of a top-k run
_NO_HALVING_RESUME = (
    "resume: {run_dir} is a top-k run (task.planner.top_k > 1); resuming one is not supported yet "
    "(its checkpoint records every candidate's CE state, but nothing reads it back): start a new run"
)
# overrides a resumed run accepts (everything else comes from the run's saved config)
RESUME_ALLOWED_PREFIXES = ("resume", "logging.", "hydra.")


class SweepJobConfigError(CompactHydraException):
    """A sweep job's config is invalid: Hydra marks the job failed and prints just the message."""


class RunInterrupted(KeyboardInterrupt):
    """Raised in the main thread by SIGTERM (SIGINT raises ``KeyboardInterrupt`` itself)."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"signal {signal.Signals(signum).name}")
        self.signum = signum


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

    @property
    def interrupted(self) -> bool:
        return self.status == "interrupted"


# --------------------------------------------------------------------------------------------
# config plumbing
# --------------------------------------------------------------------------------------------


def _plain(cfg: DictConfig | Mapping[str, Any]) -> dict[str, Any]:
    """Resolved plain data of the task config (no ``hydra`` node)."""
    if isinstance(cfg, DictConfig):
        try:
            d = OmegaConf.to_container(cfg, resolve=True, throw_on_missing=True)
        except Exception as e:  # interpolation / missing-value errors from OmegaConf
            raise ConfigError(" ".join(str(e).split())) from None
    else:
        d = OmegaConf.to_container(OmegaConf.create(dict(cfg)), resolve=True)
    assert isinstance(d, dict)
    d.pop("hydra", None)
    return d


def _resume_config(current: dict[str, Any], ckpt: Checkpoint, overrides: Sequence[str]) -> dict[str, Any]:
    """The config a resumed run uses: the saved one, with the current ``logging`` group."""
    extra = [o for o in overrides if not str(o).lstrip("+~").startswith(RESUME_ALLOWED_PREFIXES)]
    if extra:
        raise ConfigError(
            f"resume: a resumed run uses its saved config; drop the override(s) {extra} "
            "(only logging.* may change)"
        )
    cfg = dict(ckpt.config)
    cfg["resume"] = current.get("resume")
    if "logging" in current:
        cfg["logging"] = current["logging"]
    return cfg


# --------------------------------------------------------------------------------------------
# result document
# --------------------------------------------------------------------------------------------


def _best_params(task: Any, best_z: Any) -> dict[str, dict[str, float]] | None:
    if best_z is None:
        return None
    import torch

    z = torch.as_tensor(best_z, dtype=torch.float64).reshape(1, -1)
    out: dict[str, dict[str, float]] = {}
    for name, part in task.layout.split(z).items():
        coords = task.layout.regions[name].coord_names
        out[name] = {c: float(v) for c, v in zip(coords, part[0].tolist())}
    return out


def _result_doc(
    spec: RunSpec,
    run_dir: Path,
    *,
    status: str,
    state: Any,
    records: list[dict[str, Any]],
    wall_time_s: float,
    error: str | None = None,
    extra: Mapping[str, Any] | None = None,
    task: Any = None,
) -> dict[str, Any]:
    """The result document; ``task`` (default ``spec.task``) is the plan ``state`` searched over."""
    task = spec.task if task is None else task
    best_feasible = bool(state.best_feasible) if state is not None else False
    best_cost = float(state.best_cost) if (state is not None and best_feasible) else None
    doc: dict[str, Any] = {
        "status": status,
        "interrupted": status == "interrupted",
        "error": error,
        "feasible": best_feasible,
        "best_cost": best_cost,
        "best_iteration": state.best_iteration if state is not None and state.best_z is not None else None,
        "best_params": _best_params(task, None if state is None else state.best_z),
        "best_z": None if state is None or state.best_z is None else state.best_z.tolist(),
        "columns": task.layout.column_names,
        "iterations_done": len(records),
        "iterations": spec.ce.iterations,
        "converged": bool(state.converged) if state is not None else False,
        "success_per_iter": series(records, "success_share"),
        "best_cost_per_iter": series(records, "best_cost"),
        "iteration_best_cost_per_iter": series(records, "iteration_best_cost"),
        "n_samples_per_iter": series(records, "n_samples"),
        "n_feasible_per_iter": series(records, "n_feasible"),
        "elite_per_iter": [
            {
                "n_elite": r.get("n_elite"),
                "refit": r.get("refit"),
                "cost_min": json_safe(_num(r.get("elite_cost_min"))),
                "cost_mean": json_safe(_num(r.get("elite_cost_mean"))),
                "cost_max": json_safe(_num(r.get("elite_cost_max"))),
            }
            for r in records
        ],
        "iteration_time_s": series(records, "wall_time"),
        "final_mean": None if state is None or state.mean is None else state.mean.tolist(),
        "final_std": None if state is None or state.std is None else state.std.tolist(),
        # mixture weights (ce.n_modes > 1; final_mean/final_std are then k lists of D)
        "final_weights": None if state is None or state.weights is None else state.weights.tolist(),
        "wall_time_s": wall_time_s,
        "seed": spec.seed,
        "task": {"name": task.name, "source": task.source},
        "plan": task.describe(),
        "config": spec.config,
        "versions": package_versions(),
        "run_dir": str(run_dir),
        "files": {"history": HISTORY_FILE, "checkpoint": CHECKPOINT_FILE},
    }
    if extra:
        doc.update(extra)
    return doc


def _num(v: Any) -> Any:
    if isinstance(v, str):
        try:
            return float(v)
        except ValueError:
            return v
    return v


def _write_failure(run_dir: Path, message: str, detail: str | None = None, config: Any = None) -> None:
    """Record a run that failed before (or without) a RunSpec: result.json + error.txt.

    Never in a directory that holds a run (``resume=DIR`` with a bad override must not
    overwrite DIR's result)."""
    if (run_dir / CHECKPOINT_FILE).exists():
        return
    try:
        atomic_write_text(run_dir / ERROR_FILE, (detail or message).rstrip() + "\n")
        atomic_write_json(
            run_dir / RESULT_FILE,
            {
                "status": "failed",
                "interrupted": False,
                "error": message,
                "feasible": False,
                "best_cost": None,
                "iterations_done": 0,
                "simulated": False,
                "wall_time_s": None,
                "config": config,
                "versions": package_versions(),
            },
        )
    except OSError:  # pragma: no cover - the run dir itself is unwritable
        pass


# --------------------------------------------------------------------------------------------
# the run
# --------------------------------------------------------------------------------------------


class _Signals:
    """SIGINT/SIGTERM -> ``RunInterrupted`` in the main thread while the run is active.

    SIGINT gets an explicit handler too: a process started in the background by a
    non-interactive shell inherits SIGINT as *ignored*, and ``kill -INT`` should still stop it.
    """

    def __init__(self) -> None:
        self.old: dict[int, Any] = {}

    def __enter__(self) -> _Signals:
        if threading.current_thread() is threading.main_thread():

            def handler(signum: int, frame: Any) -> None:
                raise RunInterrupted(signum)

            for s in (signal.SIGINT, signal.SIGTERM):
                try:
                    self.old[s] = signal.signal(s, handler)
                except (ValueError, OSError):  # pragma: no cover
                    pass
        return self

    def __exit__(self, *exc: Any) -> None:
        for s, h in self.old.items():
            signal.signal(s, h)


@contextlib.contextmanager
def _shielded() -> Iterator[None]:
    """Ignore SIGINT/SIGTERM while the final files are written (main thread only)."""
    old: dict[int, Any] = {}
    if threading.current_thread() is threading.main_thread():
        for s in (signal.SIGINT, signal.SIGTERM):
            try:
                old[s] = signal.signal(s, signal.SIG_IGN)
            except (ValueError, OSError):  # pragma: no cover
                pass
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


class _RunGuard:
    """End of a run loop, however it ends: ``status`` becomes ``done``, ``interrupted`` (SIGINT,
    or SIGTERM via :class:`RunInterrupted`; swallowed, ``exit_code`` set) or ``failed`` (the
    traceback goes to ``error.txt`` and the exception propagates). The result is written one
    last time and ``close`` runs in every case, shielded from a second Ctrl-C."""

    def __init__(self, n_done: Callable[[], int], write_result: Callable[..., None], close: Callable[[], None],
                 error_file: Path | None = None) -> None:
        self.n_done, self.write_result, self.close = n_done, write_result, close
        self.error_file = error_file
        self.status, self.exit_code, self.error = "running", 0, None

    def __enter__(self) -> "_RunGuard":
        return self

    def __exit__(self, kind: Any, exc: Any, tb: Any) -> bool:
        if kind is None:
            self.status = "done"
        elif issubclass(kind, KeyboardInterrupt):
            signum = exc.signum if isinstance(exc, RunInterrupted) else signal.SIGINT
            self.status, self.exit_code = "interrupted", EXIT_SIGNAL.get(signum, 130)
            self.error = f"interrupted by {signal.Signals(signum).name} after {self.n_done()} complete iteration(s)"
        elif issubclass(kind, Exception):
            self.status, self.error = "failed", f"{kind.__name__}: {exc}"
            with _shielded():
                try:
                    if self.error_file is not None:
                        atomic_write_text(self.error_file, "".join(traceback.format_exception(kind, exc, tb)))
                    self.write_result(self.status, self.error)
                finally:
                    self.close()
            return False
        else:
            return False
        with _shielded():  # a second Ctrl-C must not cut the final write short
            try:
                self.write_result(self.status, self.error if self.status == "interrupted" else None)
            finally:
                self.close()
        return True


def _make_rerun_logger(spec: RunSpec, run_dir: Path, start_iteration: int) -> Any:
    if not spec.logging.rerun:
        return None
    try:
        from realize.rerun_log import RerunLogger
    except ImportError as e:
        log.warning("rerun logging is on but realize.rerun_log is not available (%s); no .rrd written", e)
        return None
    name = Path(spec.logging.rrd)
    if start_iteration > 0:  # a resumed segment gets its own recording
        name = name.with_name(f"{name.stem}.from-it{start_iteration}{name.suffix}")
    return RerunLogger(run_dir / name, spec.task.layout, spec.geometry, padding=spec.rollout.astar.padding,
                       n_iterations=spec.ce.iterations)


def run(
    cfg: DictConfig | Mapping[str, Any],
    out_dir: Path | str,
    *,
    cli_overrides: Sequence[str] = (),
    after_iteration: Callable[[int], None] | None = None,
) -> RunOutcome:
    """One realize run into ``out_dir`` (or into the resumed run's directory).

    ``cfg`` is the composed config (Hydra's, without the ``hydra`` node, or plain data);
    ``cli_overrides`` the command-line overrides (checked when resuming); ``after_iteration(i)``
    is called after iteration ``i`` is on disk (tests use it to interrupt a run).
    Raises ``ConfigError`` (nothing simulated) for bad input.
    """
    t_start = time.perf_counter()
    run_dir = Path(out_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    current: dict[str, Any] | None = None
    try:
        current = _plain(cfg)
        ckpt: Checkpoint | None = None
        if current.get("resume") is not None:
            try:
                ckpt = load_checkpoint(str(current["resume"]))
            except CheckpointError as e:
                raise ConfigError(str(e)) from None
            run_dir = Path(str(current["resume"]))
            if ckpt.ce_state.get("kind") == HALVING_KIND:
                raise ConfigError(_NO_HALVING_RESUME.format(run_dir=run_dir))
            current = _resume_config(current, ckpt, cli_overrides)
        spec = build_run_spec(current)
        if ckpt is not None and spec.halving:
            raise ConfigError(_NO_HALVING_RESUME.format(run_dir=run_dir))
        if not spec.halving:
            state, history, records, wall_before, segments = _restore(spec, run_dir, ckpt)
    except ConfigError as e:
        _write_failure(Path(out_dir), str(e), config=json_safe(current))
        raise
    if spec.halving:
        return _iterate_halving(spec, run_dir, t_start, after_iteration)
    return _iterate(spec, run_dir, state, history, records, wall_before, segments, t_start, after_iteration)


def _restore(spec: RunSpec, run_dir: Path, ckpt: Checkpoint | None) -> tuple[Any, History, list, float, int]:
    from realize.cross_entropy import CEState

    if ckpt is None:
        return None, History(spec.task.layout.column_names), [], 0.0, 1
    try:
        state = CEState.from_dict(ckpt.ce_state, dtype=spec.ce.torch_dtype)
    except (KeyError, TypeError, ValueError) as e:
        raise ConfigError(f"resume: {run_dir / CHECKPOINT_FILE} has a malformed ce_state ({e})") from None
    if state.iteration != ckpt.iteration:
        raise ConfigError(f"resume: {run_dir / CHECKPOINT_FILE} is inconsistent (iteration vs ce_state.iteration)")
    hist_path = run_dir / HISTORY_FILE
    if not hist_path.is_file():
        raise ConfigError(f"resume: {hist_path} is missing (the run's per-iteration history)")
    try:
        history = load_history(hist_path, keep=ckpt.iteration)
    except (OSError, KeyError, ValueError) as e:
        raise ConfigError(f"resume: {hist_path} cannot be read ({e})") from None
    if len(history) != ckpt.iteration or history.column_names != spec.task.layout.column_names:
        raise ConfigError(f"resume: {hist_path} does not match {CHECKPOINT_FILE} (iterations or columns differ)")
    return state, history, list(ckpt.records), ckpt.wall_time_s, ckpt.segments + 1


def _iterate(
    spec: RunSpec,
    run_dir: Path,
    state: Any,
    history: History,
    records: list[dict[str, Any]],
    wall_before: float,
    segments: int,
    t_start: float,
    after_iteration: Callable[[int], None] | None,
) -> RunOutcome:
    from tqdm import tqdm

    from realize.cross_entropy import CrossEntropyOptimizer
    from realize.realization.rollout import PlanRealizer
    from realize.scene import BatchedScene

    def wall() -> float:
        return wall_before + (time.perf_counter() - t_start)

    start_it = 0 if state is None else state.iteration
    extra: dict[str, Any] = {"segments": segments, "resumed_from_iteration": start_it if start_it else None}
    cur_state = state

    def write_result(status: str, error: str | None = None) -> None:
        atomic_write_json(
            run_dir / RESULT_FILE,
            _result_doc(spec, run_dir, status=status, state=cur_state, records=records, wall_time_s=wall(),
                        error=error, extra=extra),
        )

    if start_it:
        log.info("resuming %s after iteration %d of %d", run_dir, start_it, spec.ce.iterations)
    if state is not None and (state.iteration >= spec.ce.iterations or state.converged):
        log.info("%s is already complete; nothing to run", run_dir)
        write_result("done")
        best = state.best_cost if state.best_feasible else math.inf
        outcome = RunOutcome(run_dir, "done", bool(state.best_feasible), best, len(records), wall())
        _report(outcome, spec)
        return outcome
    write_result("running")
    scene = realizer = rr_logger = bar = None
    guard = _RunGuard(lambda: len(records), write_result, lambda: _close(bar, rr_logger, scene),
                      run_dir / ERROR_FILE)
    with guard:
        with _Signals():
            t0 = time.perf_counter()
            scene = BatchedScene(spec.n_envs_max, spec.geometry_cfg, spec.sim)
            realizer = PlanRealizer(spec.task, scene, spec.rollout, seed=spec.seed)
            opt = CrossEntropyOptimizer(spec.task.layout, spec.ce, device=scene.device, state=state)
            extra.update(backend=scene.backend, n_envs_scene=scene.n_envs, setup_time_s=time.perf_counter() - t0)
            log.info("plan %s; %d copies on %s (setup %.1f s)", spec.task.describe(), scene.n_envs, scene.backend,
                     extra["setup_time_s"])
            rr_logger = _make_rerun_logger(spec, run_dir, start_it)
            figure_files = _figure_files(spec, run_dir)
            bar = tqdm(total=spec.ce.iterations, initial=start_it, desc="CE", unit="it", dynamic_ncols=True,
                       disable=not spec.logging.progress, file=sys.stderr)
            while not opt.done:
                Z = opt.ask()
                # the distribution this batch is drawn from (None: uniform over the regions)
                drawn_from = (None, None, None) if cur_state is None else (cur_state.mean, cur_state.std,
                                                                              cur_state.weights)
                t_eval = time.perf_counter()
                res = realizer.rollout(Z, record=spec.logging.record)
                t_eval = time.perf_counter() - t_eval
                rec = opt.tell(res.to_eval())
                rec.eval_time = t_eval
                new_state = opt.state
                history.append(
                    {
                        "Z": rec.Z,
                        "cost": rec.cost,
                        "feasible": rec.feasible,
                        "progress": rec.progress,
                        "distance": rec.distance,
                        "elite_idx": rec.elite_idx,
                        "action_success": res.action_success,
                        "goal": res.goal,
                        "steps": res.steps,
                    },
                    n_samples=rec.n_samples,
                    success_share=rec.success_share,
                    best_cost=rec.best_cost,
                    mean=rec.mean,
                    std=rec.std,
                    weights=rec.weights,
                )
                new_records = records + [json_safe(rec.summary())]
                history.save(run_dir / HISTORY_FILE)
                save_checkpoint(  # the commit point of the iteration
                    run_dir,
                    Checkpoint(new_state.iteration, new_state.to_dict(), spec.config, new_records, wall(), segments),
                )
                records[:] = new_records
                cur_state = new_state
                write_result("running")
                if rr_logger is not None:
                    rr_logger = _log_rerun(rr_logger, rec, res, *drawn_from)
                if figure_files is not None and res.traj_base is not None:
                    figure_files = _save_trajectories(figure_files, run_dir, rec, res)
                bar.set_postfix_str(
                    f"success {rec.success_share:.0%}, best cost "
                    + (f"{rec.best_cost:.0f}" if math.isfinite(rec.best_cost) else "-")
                )
                bar.update(1)
                if after_iteration is not None:
                    after_iteration(rec.iteration)
    status, exit_code = guard.status, guard.exit_code
    best = cur_state.best_cost if (cur_state is not None and cur_state.best_feasible) else math.inf
    feasible = bool(cur_state is not None and cur_state.best_feasible)
    outcome = RunOutcome(run_dir, status, feasible, best, len(records), wall(), exit_code)
    _report(outcome, spec)
    return outcome


def _candidate_file(name: str, index: int) -> str:
    """``history.npz`` -> ``history_c1.npz`` (per-candidate file of a top-k run)."""
    p = Path(name)
    return str(p.with_name(f"{p.stem}_c{index}{p.suffix}"))


def _iterate_halving(
    spec: RunSpec,
    run_dir: Path,
    t_start: float,
    after_iteration: Callable[[int], None] | None,
) -> RunOutcome:
    """A top-k run (``task.planner.top_k > 1``): successive halving over the candidate plans
    (``realize.candidates``), all realized in one batched scene of ``ce.n_envs`` copies.

    Files: ``result.json`` (top level: the leader, i.e. the winner once decided; plus
    ``candidates``, ``winner``, ``budget``), ``history_c{i}.npz`` per candidate (its own
    columns), ``checkpoint.json`` (every candidate's CE state; resume refuses it), rerun
    recordings ``<rrd stem>_c{i}.rrd`` per candidate. No trajectory/scene files for the figures
    (their readers assume one parameter layout)."""
    from tqdm import tqdm

    from realize.candidates import CandidateSpec, SuccessiveHalving
    from realize.realization.rollout import PlanRealizer
    from realize.scene import BatchedScene

    assert spec.budget is not None
    tasks = spec.candidates
    budget = spec.budget

    def wall() -> float:
        return time.perf_counter() - t_start

    sh = SuccessiveHalving([CandidateSpec(t.describe(), t.layout, t.n_actions) for t in tasks], spec.ce, budget)
    histories = [History(t.layout.column_names) for t in tasks]
    records: list[dict[str, Any]] = []  # every iteration of every candidate, in run order
    extra: dict[str, Any] = {"segments": 1, "resumed_from_iteration": None, "top_k": spec.planner.top_k}

    def write_result(status: str, error: str | None = None) -> None:
        lead = sh.candidates[sh.leader]
        summary = sh.summary()
        doc = _result_doc(spec, run_dir, status=status, state=lead.optimizer.state, records=lead.records,
                          wall_time_s=wall(), error=error, extra=extra, task=tasks[lead.index])
        doc.update(
            n_candidates=len(tasks),
            leader={"index": lead.index, "plan": lead.spec.plan},
            winner=summary["winner"],
            budget=summary["budget"],
            spent_iterations=summary["spent_iterations"],
            spent_samples=summary["spent_samples"],
            halving_round=summary["round"],
            candidates=[dict(c, history=_candidate_file(HISTORY_FILE, c["index"])) for c in summary["candidates"]],
            files={"history": [_candidate_file(HISTORY_FILE, i) for i in range(len(tasks))],
                   "checkpoint": CHECKPOINT_FILE},
        )
        atomic_write_json(run_dir / RESULT_FILE, doc)

    if len(tasks) < spec.planner.top_k:
        log.info("the planner returned %d distinct plan(s) for top_k = %d", len(tasks), spec.planner.top_k)
    write_result("running")
    scene = bar = None
    loggers: dict[int, Any] = {}
    guard = _RunGuard(lambda: len(records), write_result, lambda: _close_all(bar, loggers, scene),
                      run_dir / ERROR_FILE)
    with guard:
        with _Signals():
            t0 = time.perf_counter()
            scene = BatchedScene(spec.ce.n_samples, spec.geometry_cfg, spec.sim)
            # one realizer per candidate on the same scene: every rollout starts with a reset,
            # which is history-free on CPU (a used scene equals a fresh one bit for bit)
            realizers = [PlanRealizer(t, scene, spec.rollout, seed=spec.seed) for t in tasks]
            extra.update(backend=scene.backend, n_envs_scene=scene.n_envs, setup_time_s=time.perf_counter() - t0)
            for i, t in enumerate(tasks):
                log.info("candidate %d: %s", i, t.describe())
            log.info("%d candidate(s), halving budget %s; %d copies on %s (setup %.1f s)", len(tasks),
                     budget.to_dict(), scene.n_envs, scene.backend, extra["setup_time_s"])
            bar = tqdm(total=budget.total_iterations, desc="CE top-k", unit="it", dynamic_ncols=True,
                       disable=not spec.logging.progress, file=sys.stderr)
            while (job := sh.ask()) is not None:
                i, Z = job
                cand = sh.candidates[i]
                drawn_from = (cand.optimizer.state.mean, cand.optimizer.state.std)
                t_eval = time.perf_counter()
                res = realizers[i].rollout(Z, record=spec.logging.record and spec.logging.rerun)
                t_eval = time.perf_counter() - t_eval
                rec = sh.tell(res.to_eval())
                rec.eval_time = t_eval
                cand.records[-1]["eval_time"] = t_eval
                histories[i].append(
                    {"Z": rec.Z, "cost": rec.cost, "feasible": rec.feasible, "progress": rec.progress,
                     "distance": rec.distance, "elite_idx": rec.elite_idx, "action_success": res.action_success,
                     "goal": res.goal, "steps": res.steps},
                    n_samples=rec.n_samples, success_share=rec.success_share, best_cost=rec.best_cost,
                    mean=rec.mean, std=rec.std,
                )
                records.append(json_safe(dict(rec.summary(), candidate=i, eval_time=t_eval)))
                histories[i].save(run_dir / _candidate_file(HISTORY_FILE, i))
                save_checkpoint(
                    run_dir,
                    Checkpoint(len(records), {"kind": HALVING_KIND, **sh.to_dict()}, spec.config, list(records),
                               wall(), 1),
                )
                write_result("running")
                if spec.logging.rerun:
                    if i not in loggers:
                        loggers[i] = _make_candidate_logger(spec, run_dir, tasks[i], i, budget.total_iterations)
                    if loggers[i] is not None:
                        loggers[i] = _log_rerun(loggers[i], rec, res, *drawn_from)
                best = rec.best_cost
                bar.set_postfix_str(
                    f"candidate {i} (round {min(sh.round, budget.n_rounds)}), success {rec.success_share:.0%}, "
                    f"best cost " + (f"{best:.0f}" if math.isfinite(best) else "-")
                )
                bar.update(1)
                if after_iteration is not None:
                    after_iteration(len(records) - 1)
    status, exit_code = guard.status, guard.exit_code
    lead = sh.candidates[sh.leader].optimizer.state
    feasible = bool(lead.best_feasible)
    outcome = RunOutcome(run_dir, status, feasible, lead.best_cost if feasible else math.inf, len(records), wall(),
                         exit_code)
    _report(outcome, spec)
    w = sh.winner
    print(f"top-k: {len(tasks)} candidate(s); "
          + (f"winner {w}: {tasks[w].describe()}" if w is not None else f"no winner yet (leader {sh.leader})"),
          flush=True)
    return outcome


def _make_candidate_logger(spec: RunSpec, run_dir: Path, task: Any, index: int, n_iterations: int) -> Any:
    try:
        from realize.rerun_log import RerunLogger
    except ImportError as e:
        log.warning("rerun logging is on but realize.rerun_log is not available (%s); no .rrd written", e)
        return None
    try:
        return RerunLogger(run_dir / _candidate_file(spec.logging.rrd, index), task.layout, spec.geometry,
                           padding=spec.rollout.astar.padding, n_iterations=n_iterations)
    except Exception as e:  # logging must not cost the search
        log.warning("rerun recording of candidate %d failed to open (%s: %s)", index, type(e).__name__, e)
        return None


def _close_all(bar: Any, loggers: Mapping[int, Any], scene: Any) -> None:
    for lg in loggers.values():
        _close(None, lg, None)
    _close(bar, None, scene)


def _figure_files(spec: RunSpec, run_dir: Path) -> Any:
    """``realize.figures`` (scene.json now, trajectories_iter{k}.npz per iteration), if present."""
    try:
        from realize import figures
    except ImportError as e:
        log.warning("realize.figures is not available (%s); no scene.json / trajectory files", e)
        return None
    try:
        figures.save_scene(run_dir, spec.task.layout, spec.geometry, padding=spec.rollout.astar.padding)
    except Exception as e:  # figure inputs must not cost the search
        log.warning("writing scene.json failed (%s: %s)", type(e).__name__, e)
        return None
    return figures


def _save_trajectories(figures: Any, run_dir: Path, rec: Any, res: Any) -> Any:
    top = int(rec.best_idx) if rec.elite_idx.numel() else -1  # best_idx: elite_idx[0] unless kNN-reordered
    best = top if top >= 0 and bool(rec.feasible[top]) else -1
    try:
        figures.save_trajectories(run_dir, rec.iteration, res.traj_base, res.traj_ee, res.feasible, best,
                                  Z=rec.Z, cost=res.cost, progress=res.progress, traj_t=res.traj_t)
        return figures
    except Exception as e:
        log.warning("saving trajectories of iteration %d failed (%s: %s); stops", rec.iteration,
                    type(e).__name__, e)
        return None


def _log_rerun(rr_logger: Any, rec: Any, res: Any, mean: Any, std: Any, weights: Any = None) -> Any:
    try:
        rr_logger.log_iteration(rec, res, mean, std, weights)
        return rr_logger
    except Exception as e:  # a logging bug must not cost the search
        log.warning("rerun logging failed at iteration %d (%s: %s); logging stops", rec.iteration,
                    type(e).__name__, e)
        try:
            rr_logger.close()
        except Exception:
            pass
        return None


def _close(bar: Any, rr_logger: Any, scene: Any) -> None:
    if bar is not None:
        bar.close()
    if rr_logger is not None:
        try:
            rr_logger.close()
        except Exception as e:  # pragma: no cover
            log.warning("closing the rerun recording failed: %s", e)
    if scene is not None:
        try:
            scene.close()
        except Exception:  # pragma: no cover
            pass


def _report(o: RunOutcome, spec: RunSpec) -> None:
    cost = f"{o.best_cost:.0f}" if math.isfinite(o.best_cost) else "none"
    if spec.halving:
        hist, rrd = _candidate_file(HISTORY_FILE, 0) + ", ...", _candidate_file(spec.logging.rrd, 0) + ", ..."
    else:
        hist, rrd = HISTORY_FILE, spec.logging.rrd
    print(
        f"realize: {o.status} after {o.iterations_done}/{spec.ce.iterations} CE iterations; "
        f"best cost {cost}; feasible {o.feasible}; wall time {o.wall_time_s:.1f} s\n"
        f"results: {o.run_dir / RESULT_FILE} (also {hist}, {CHECKPOINT_FILE}"
        + (f", {rrd}" if spec.logging.rerun else "")
        + ")",
        flush=True,
    )


# --------------------------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------------------------


def _group_options(group: str) -> list[str]:
    d = CONFIG_DIR / group
    return sorted(p.stem for p in d.glob("*.yaml")) if d.is_dir() else []


def preflight(args: list[str]) -> list[str]:
    """Check the command line before Hydra runs; returns the (possibly extended) arguments.

    Checks config group choices (``experiment=foo`` -> one-line error listing the presets) and
    ``resume=`` (must be a run directory); a resumed single run writes its Hydra files into
    the resumed directory. For a single run without Hydra flags it also composes the config
    once, so composition errors become one line too.
    """
    from hydra.core.override_parser.overrides_parser import OverridesParser

    flags = [a for a in args if a.startswith("-")]
    plain = [a for a in args if not a.startswith("-")]
    if any(f not in ("-m", "--multirun") for f in flags):
        return args  # --cfg, --config-dir, --help, ...: Hydra's own business (and its own checks)
    multirun = bool(flags)
    parser = OverridesParser.create()
    parsed = []
    for a in plain:
        try:
            parsed.extend(parser.parse_overrides([a]))
        except Exception as e:
            msg = " ".join(str(e).split()).split(" See https://")[0]
            raise ConfigError(f"cannot parse the override {a!r}: {msg}") from None
    resume_dir: str | None = None
    has_run_dir = False
    # config dirs added through hydra.searchpath may hold more group options than configs/ does
    check_groups = not any(o.key_or_group.startswith("hydra.searchpath") for o in parsed)
    for o in parsed:
        key = o.key_or_group
        if key == "hydra.run.dir":
            has_run_dir = True
        if o.is_delete():
            continue
        values = list(o.sweep_string_iterator()) if o.is_sweep_override() else [o.get_value_element_as_str()]
        if check_groups and key in CONFIG_GROUPS and o.package is None:
            options = _group_options(key)
            for v in values:
                if v not in options and v != "null":
                    what = "preset" if key == "experiment" else "option"
                    raise ConfigError(
                        f"{key}={v}: unknown {key} {what} {v!r}; available: {', '.join(options)} "
                        f"(files in configs/{key}/)"
                    )
        if key == "resume":
            for v in values:
                if v in ("null", "None"):
                    continue
                if not (Path(v) / CHECKPOINT_FILE).is_file():
                    raise ConfigError(f"resume: {v} is not a realize run directory (no {CHECKPOINT_FILE})")
                resume_dir = v
    if resume_dir is not None and not multirun and not has_run_dir:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        args = args + [f"hydra.run.dir={resume_dir}", f"hydra.output_subdir=.hydra/resume-{stamp}"]
    if not flags and not multirun:
        _trial_compose([a for a in args if not a.startswith("-")])
    return args


def _trial_compose(overrides: list[str]) -> None:
    """Compose once with Hydra's compose API; composition errors become one ``ConfigError``."""
    from hydra import compose, initialize_config_dir

    try:
        with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3", job_name="realize"):
            compose(config_name="config", overrides=overrides)
    except Exception as e:
        lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
        if e.__cause__ is not None and str(e.__cause__).strip():
            lines.append(str(e.__cause__).strip().splitlines()[0])
        lines = [ln for ln in lines if "HYDRA_FULL_ERROR" not in ln]
        cut = next((i for i, ln in enumerate(lines) if ln.startswith("Config search path")), len(lines))
        raise ConfigError("; ".join(lines[:cut]) or type(e).__name__) from None


def _hydra_task(cfg: DictConfig) -> Any:
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    hc = HydraConfig.get()
    multirun = hc.mode == RunMode.MULTIRUN
    out_dir = Path(hc.runtime.output_dir)
    try:
        outcome = run(cfg, out_dir, cli_overrides=list(hc.overrides.task))
    except ConfigError as e:
        if multirun:  # Hydra records the job as failed; the other jobs still run
            raise SweepJobConfigError(f"error: {e}") from None
        print(f"error: {e}", file=sys.stderr, flush=True)
        sys.exit(EXIT_CONFIG)
    if outcome.interrupted:
        if multirun:
            raise KeyboardInterrupt  # stop the sweep, as a user's Ctrl-C means
        sys.exit(outcome.exit_code)
    return {"feasible": outcome.feasible, "best_cost": outcome.best_cost, "run_dir": str(outcome.run_dir)}


def main(argv: Sequence[str] | None = None) -> None:
    """Console entry point: ``realize [overrides]`` / ``python -m realize [overrides]``."""
    import hydra

    args = list(sys.argv[1:] if argv is None else argv)
    try:
        args = preflight(args)
    except ConfigError as e:
        print(f"error: {e}", file=sys.stderr, flush=True)
        sys.exit(EXIT_CONFIG)
    sys.argv = [sys.argv[0] if sys.argv else "realize"] + args
    entry = hydra.main(config_path=str(CONFIG_DIR), config_name="config", version_base="1.3")(_hydra_task)
    entry()


if __name__ == "__main__":  # pragma: no cover
    main()
