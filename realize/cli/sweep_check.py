"""Check every job of a sweep (``realize -m``) before the first one simulates.

What it does: ``check_sweep(args)`` expands the sweep the command line describes (its
``key=a,b`` / ``range(...)`` overrides and the ``hydra.sweeper.params`` a preset such as
``experiment=ramp_ablation`` sets, the command line winning, as Hydra's basic sweeper merges
them), composes each job's config and validates it (``realize.spec.run_spec.build_run_spec``,
and a ``warm_start`` run's files: nothing is simulated). The first bad job is one ``ConfigError`` line naming its overrides, so
``realize -m ce.n_envs=20,abc`` ends with exit code 2 before job 0 runs. A sweep of more than
``MAX_JOBS`` jobs is checked value by value (each swept value once, the other sweeps at their
first value) rather than job by job: every value is checked, combinations of them are not. An
Optuna sweeper's ``interval(a, b)`` is checked at its two ends, so a search space that admits
invalid trials (``ce.n_elite`` above ``ce.n_envs``) is refused before the study starts.
What it doesn't: check the values between an interval's ends (each trial is checked when it
starts), run a job, or replace the per-job checks in ``realize.run.assembly`` (which stay).
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Sequence
from typing import Any

from realize.spec.compose import override_values, parse_overrides
from realize.config import ConfigError

__all__ = ["check_sweep", "sweep_jobs", "MAX_JOBS"]

MAX_JOBS = 64  # more jobs than this: each swept value is checked once (module docstring)


def _listable(o: Any) -> bool:
    """A sweep override whose values can be checked: listed ones (choice, range) or an
    interval's two ends (an Optuna sweeper's search space)."""
    return o.is_sweep_override()


def _values(o: Any) -> list[str]:
    """The values to check of a sweep override: its listed ones, or an interval's ends."""
    listed = override_values(o)
    if listed or not o.is_interval_sweep():
        return listed
    v = o.value()
    return [str(v.start), str(v.end)]


def _sweeper_params(fixed: Sequence[str]) -> dict[str, str]:
    """``hydra.sweeper.params`` of the config the fixed overrides compose ({} if none). Only the
    group choices and ``hydra`` overrides among them can set it, so it is composed once per
    process and set of those (``realize.spec.hydra_edge``)."""
    from realize.spec.hydra_edge import split_overrides

    split = split_overrides(list(fixed))
    return dict(_sweeper_params_of(tuple(split[0]) if split is not None else tuple(fixed)))


@functools.lru_cache(maxsize=32)
def _sweeper_params_of(overrides: tuple[str, ...]) -> tuple[tuple[str, str], ...]:
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from realize.paths import CONFIG_DIR

    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3", job_name="realize"):
        cfg = compose(config_name="config", overrides=list(overrides), return_hydra_config=True)
    params = OmegaConf.select(cfg, "hydra.sweeper.params", default=None)
    if params is None:
        return ()
    return tuple((str(k), str(v)) for k, v in OmegaConf.to_container(params, resolve=False).items())


def sweep_jobs(args: Sequence[str], max_jobs: int = MAX_JOBS) -> tuple[list[str], list[list[str]]]:
    """The overrides every job shares, and the swept overrides of each job to check (every
    job, or every value once past ``max_jobs``)."""
    plain = [str(a) for a in args if not str(a).lstrip("+~").startswith(("hydra.", "hydra/"))]
    parsed = parse_overrides(plain)
    fixed = [o.input_line for o in parsed if not o.is_sweep_override()]
    swept: dict[str, list[str]] = {}
    for o in parsed:
        if _listable(o):
            swept[o.key_or_group] = [f"{o.input_line.split('=', 1)[0]}={v}" for v in _values(o)]
    named = {o.key_or_group for o in parsed}
    for key, values in _sweeper_params(fixed).items():
        if key in named:
            continue
        for o in parse_overrides([f"{key}={values}"]):
            if _listable(o):
                swept[key] = [f"{key}={v}" for v in _values(o)]
            elif not o.is_sweep_override():
                fixed.append(o.input_line)
    axes = list(swept.values())
    n_jobs = 1
    for values in axes:
        n_jobs *= len(values)
    if n_jobs <= max_jobs:
        return fixed, [list(combo) for combo in itertools.product(*axes)]
    first = [values[0] for values in axes]
    jobs = [first]
    for i, values in enumerate(axes):
        jobs += [first[:i] + [v] + first[i + 1:] for v in values[1:]]
    return fixed, jobs


def check_sweep(args: Sequence[str], max_jobs: int = MAX_JOBS) -> int:
    """Compose and validate every job of the sweep ``args`` (module docstring); returns how
    many configs were checked. Raises one ``ConfigError`` line for the first bad job."""
    from realize.spec.compose import compose_config
    from realize.spec.run_spec import build_run_spec

    from realize.search.warm_start import load_warm_start

    fixed, jobs = sweep_jobs(args, max_jobs)
    for k, swept in enumerate(jobs):
        try:
            spec = build_run_spec(compose_config(fixed + swept))
            if spec.warm_start is not None:  # its files, read as the run reads them (nothing simulated)
                load_warm_start(spec.warm_start, spec.task, spec.geometry, spec.ce)
        except ConfigError as e:
            raise ConfigError(f"sweep job {k} ({' '.join(swept)}): {e}") from None
    return len(jobs)
