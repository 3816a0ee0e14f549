"""Fuzz every input realize takes: every case is refused in one line, or runs; nothing else.

Usage: python scripts/fuzz_inputs.py [--cases N] [--seed S] [--simulate K] [--show M] [--out FILE]

What it does: Hypothesis (generation only, no shrinking, a fixed seed) draws N cases, each of one
kind: command-line override sets (every group choice and leaf key of the composed config, values
of every type: wrong types, NaN and inf, negative and huge numbers, empty and unicode strings,
lists and mappings, unknown and misspelled keys), task files (the default task with keys set,
deleted, added or renamed: regions, frames, goal predicates, plan shapes; or a YAML document of
anything), robot spec edits (``robot.*`` overrides), scene state files (a saved state edited, given
to ``replan_from``) and disturbance lists (``execute`` presets' ``disturbances``). Each case goes
through the edge the command line uses (``preflight``, the composition, ``build_run_spec``; the
disturbance reader for disturbance lists) and, where it is valid, the first ``--simulate`` valid
cases are also run (``realize.run.one_run.run``) at tiny N (2 plans, 1 iteration, a 2 s horizon). It
prints the count of cases, of refusals (a ``ConfigError`` of one line: exit code 2 on the command
line), of valid ones (and of those simulated), and of anything else: a traceback, a message over
several lines, a hang (``--limit`` seconds). Exit code 1 if there is anything else. ``--out``
writes every case and its outcome as JSON lines (to read the refusals).
What it doesn't: fuzz the simulator's numerics, or shrink a failing case (the case is printed whole).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import signal
import sys
import tempfile
import traceback
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from hypothesis import HealthCheck, Phase, given, seed, settings
from hypothesis import strategies as st

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from realize.cli.main import preflight  # noqa: E402
from realize.spec.compose import CONFIG_GROUPS, compose_config, group_options  # noqa: E402
from realize.spec.run_spec import build_run_spec  # noqa: E402
from realize.config import ConfigError  # noqa: E402
from realize.paths import CONFIG_DIR  # noqa: E402

TINY = ["ce.n_envs=2", "ce.n_elite=1", "ce.iterations=1", "controller.max_time_s=2", "validation=off",
        "logging.rerun=false", "logging.progress=false", "workers.n=1", "device=cpu"]
KINDS = ("overrides", "task_file", "robot", "state_file", "disturbances")
DEFAULT = compose_config([])
TASK = yaml.safe_load((CONFIG_DIR / "task" / "pick_place.yaml").read_text())
STATE = json.loads((REPO / "tests" / "fixtures" / "state_grasped.json").read_text())
DISTURBANCES = yaml.safe_load((CONFIG_DIR / "execute" / "table_moved.yaml").read_text())["disturbances"]


def _leaves(x: Any, path: str = "") -> Iterator[tuple[str, Any]]:
    if isinstance(x, dict):
        for k, v in x.items():
            yield from _leaves(v, f"{path}.{k}" if path else str(k))
    elif isinstance(x, list) and x and all(isinstance(v, dict) for v in x):
        for i, v in enumerate(x):
            yield from _leaves(v, f"{path}.{i}")
    else:
        yield path, x


LEAF_DEFAULTS = {k: v for k, v in _leaves(DEFAULT) if not k.startswith(("hydra", "task."))}
LEAVES = sorted(LEAF_DEFAULTS)
ROBOT_LEAVES = [k for k in LEAVES if k.startswith("robot.")]


# ------------------------------------------------------------------------------------ values
def scalars() -> st.SearchStrategy[Any]:
    return st.one_of(
        st.booleans(), st.none(),
        st.integers(min_value=-10**12, max_value=10**12), st.sampled_from([0, 1, 2, -1, 10**9, 2**63]),
        st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.0, -0.0, 1e-300, 1e300, 0.5]),
        st.text(max_size=12), st.sampled_from(["", " ", "null", "cube", "table2", "Exit", "fetch_omni", "ü→🤖"]),
    )


def values() -> st.SearchStrategy[Any]:
    return st.recursive(scalars(), lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                           st.dictionaries(st.text(max_size=6), inner, max_size=3)),
                        max_leaves=6)


def near(default: Any) -> st.SearchStrategy[Any]:
    """Values close to a key's default, of its type: the edits a user makes (off by a sign, a
    factor, zero, one element of a list), which reach deeper checks than random values do."""
    if isinstance(default, bool):
        return st.booleans()
    if isinstance(default, (int, float)):
        factors = st.sampled_from([0, -1, 0.5, 2, 10, 1e6, -1e-9])
        return factors.map(lambda f: type(default)(default * f) if isinstance(default, int) else default * f)
    if isinstance(default, list) and default and all(isinstance(v, (int, float)) for v in default):
        return st.tuples(st.integers(0, len(default) - 1), st.sampled_from([0.0, -1.0, 2.0, 100.0])).map(
            lambda t: [v * t[1] if i == t[0] else v for i, v in enumerate(default)])
    return values()


def render(v: Any) -> str:
    """A value as one types it on the command line (Hydra's override grammar)."""
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return "'" + v.replace("\\", "\\\\").replace("'", "\\'") + "'"
    if isinstance(v, list):
        return "[" + ",".join(render(a) for a in v) + "]"
    return "{" + ",".join(f"{render(str(k))}:{render(a)}" for k, a in v.items()) + "}"


def misspelled(key: str) -> st.SearchStrategy[str]:
    return st.sampled_from([key + "x", key[:-1], key.replace(".", "_", 1), key.upper(), "+" + key, "~" + key])


# ------------------------------------------------------------------------------------ cases
@dataclass
class Case:
    kind: str
    args: list[str] = field(default_factory=list)
    files: dict[str, str] = field(default_factory=dict)  # name -> content, written next to each other
    data: Any = None  # disturbance lists: the entries


@st.composite
def override_case(draw: Any, keys: list[str] = LEAVES, kind: str = "overrides") -> Case:
    args = []
    for _ in range(draw(st.integers(1, 3))):
        how = draw(st.sampled_from(["leaf", "leaf", "leaf", "group", "typo", "junk"]))
        if how == "group":
            g = draw(st.sampled_from(CONFIG_GROUPS))
            args.append(f"{g}={draw(st.one_of(st.sampled_from(group_options(g) or ['x']), st.text(max_size=8)))}")
        elif how == "typo":
            args.append(f"{draw(misspelled(draw(st.sampled_from(keys))))}={render(draw(scalars()))}")
        elif how == "junk":
            args.append(draw(st.text(max_size=20)))
        else:
            key = draw(st.sampled_from(keys))
            value = draw(near(LEAF_DEFAULTS[key])) if draw(st.booleans()) else draw(values())
            args.append(f"{key}={render(value)}")
    return Case(kind, args)


def _mutate(draw: Any, doc: Any, n: int) -> Any:
    """``doc`` (JSON-like) with ``n`` random edits: a leaf set, a key deleted, renamed or added."""
    doc = json.loads(json.dumps(doc))
    for _ in range(n):
        paths = [p for p, _ in _leaves(doc)] or [""]
        path = draw(st.sampled_from(paths)).split(".")
        node = doc
        for part in path[:-1]:
            node = node[int(part)] if isinstance(node, list) else node.get(part, {})
        if not isinstance(node, dict):
            continue
        last = path[-1]
        op = draw(st.sampled_from(["set", "set", "delete", "rename", "add"]))
        if op == "set" or last not in node:
            node[last] = draw(near(node[last])) if last in node and draw(st.booleans()) else draw(values())
        elif op == "delete":
            node.pop(last, None)
        elif op == "rename":
            node[last + draw(st.sampled_from(["s", "_", "x", " "]))] = node.pop(last)
        else:
            node[draw(st.text(max_size=8))] = draw(values())
    return doc


@st.composite
def task_case(draw: Any) -> Case:
    if draw(st.integers(0, 9)) == 0:  # a YAML document of anything
        doc = draw(values())
    else:
        doc = _mutate(draw, TASK, draw(st.integers(1, 3)))
        if draw(st.booleans()):
            doc["plan"] = draw(st.lists(st.one_of(st.sampled_from(TASK["plan"]), st.text(max_size=20)), max_size=6))
    text = yaml.safe_dump(doc, allow_unicode=True) if draw(st.integers(0, 9)) else draw(st.text(max_size=60))
    return Case("task_file", ["task_file={dir}/task.yaml"], {"task.yaml": text})


@st.composite
def state_case(draw: Any) -> Case:
    doc = _mutate(draw, STATE, draw(st.integers(1, 3)))
    text = json.dumps(doc, allow_nan=True) if draw(st.integers(0, 9)) else draw(st.text(max_size=40))
    action = draw(st.one_of(st.integers(-1, 6), st.just(2)))
    return Case("state_file", ["replan_from={run}", f"replan.action={action}", "replan.state={dir}/state.json"],
                {"state.json": text})


@st.composite
def disturbance_case(draw: Any) -> Case:
    entries = draw(st.one_of(st.just(DISTURBANCES), values())) if draw(st.integers(0, 4)) == 0 else \
        _mutate(draw, {"d": DISTURBANCES}, draw(st.integers(1, 3)))["d"]
    return Case("disturbances", data=entries)


def cases() -> st.SearchStrategy[Case]:
    return st.one_of(override_case(), task_case(), override_case(ROBOT_LEAVES, "robot"), state_case(),
                     disturbance_case())


# ------------------------------------------------------------------------------------ running
class Hang(Exception):
    pass


@contextlib.contextmanager
def time_limit(seconds: float) -> Iterator[None]:
    def alarm(*_: Any) -> None:
        raise Hang(f"over {seconds:.0f} s")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


@dataclass
class Outcome:
    result: str  # refused | valid | simulated | traceback | multi-line | hang
    detail: str
    case: Case


class Fuzzer:
    """Runs cases through the command line's edge (module docstring) and keeps the outcomes."""

    def __init__(self, work: Path, simulate: int, limit_s: float) -> None:
        self.work, self.simulate_left, self.limit_s = work, simulate, limit_s
        self.outcomes: list[Outcome] = []
        self._run_dir: Path | None = None

    def run_dir(self) -> Path:
        """A finished tiny run for replan_from (made once)."""
        if self._run_dir is None:
            from realize.run.one_run import run

            self._run_dir = self.work / "source_run"
            run(compose_config(TINY), self._run_dir)
        return self._run_dir

    def edge(self, case: Case, where: Path) -> None:
        if case.kind == "disturbances":
            from realize.execution.disturbances import read_disturbances

            spec = build_run_spec(compose_config(["device=cpu"]))
            read_disturbances(case.data, spec.geometry, [str(a) for a in spec.task.plan])
            return
        args = [a.replace("{dir}", str(where)).replace("{run}", str(self.run_dir()) if "{run}" in a else "")
                for a in case.args]
        preflight(list(args))
        build_run_spec(compose_config(args))
        if self.simulate_left > 0:
            from realize.run.one_run import run

            self.simulate_left -= 1
            run(compose_config(args + TINY), where / "run")
            raise _Simulated()

    def __call__(self, case: Case) -> None:
        where = Path(tempfile.mkdtemp(dir=self.work))
        for name, text in case.files.items():
            (where / name).write_text(text)
        result, detail = "valid", ""
        try:
            with time_limit(self.limit_s):
                self.edge(case, where)
        except _Simulated:
            result = "simulated"
        except ConfigError as e:
            msg = str(e)
            result, detail = ("refused", msg) if msg.strip() and "\n" not in msg else ("multi-line", msg)
        except Hang as e:
            result, detail = "hang", str(e)
        except Exception:  # anything else is what the fuzzer looks for
            result, detail = "traceback", traceback.format_exc()
        self.outcomes.append(Outcome(result, detail, case))


class _Simulated(Exception):
    """A valid case that was also simulated (raised past the edge to count it)."""


def fuzz(n_cases: int, seed_value: int, simulate: int = 0, limit_s: float = 120.0) -> list[Outcome]:
    """Draw and run ``n_cases`` cases (module docstring); the outcomes in order."""
    with tempfile.TemporaryDirectory(prefix="realize-fuzz-") as tmp:
        fuzzer = Fuzzer(Path(tmp), simulate, limit_s)

        @seed(seed_value)
        @settings(max_examples=n_cases, database=None, deadline=None, phases=[Phase.generate],
                  suppress_health_check=list(HealthCheck))
        @given(cases())
        def one(case: Case) -> None:
            fuzzer(case)

        one()
        return fuzzer.outcomes


BAD = ("traceback", "multi-line", "hang")


def main() -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--cases", type=int, default=100, help="cases to draw (default 100)")
    ap.add_argument("--seed", type=int, default=0, help="Hypothesis seed (default 0)")
    ap.add_argument("--simulate", type=int, default=5, help="valid cases also run at tiny N (default 5)")
    ap.add_argument("--limit", type=float, default=120.0, help="seconds a case may take (default 120)")
    ap.add_argument("--show", type=int, default=5, help="refusals to print, one per kind of message (default 5)")
    ap.add_argument("--out", type=Path, default=None, help="every case and its outcome, as JSON lines")
    a = ap.parse_args()
    out = fuzz(a.cases, a.seed, a.simulate, a.limit)
    if a.out is not None:
        with a.out.open("w") as f:
            for o in out:
                f.write(json.dumps(dict(result=o.result, detail=o.detail, kind=o.case.kind, args=o.case.args,
                                        files=o.case.files, data=o.case.data), default=repr) + "\n")
    counts = Counter(o.result for o in out)
    by_kind = Counter(o.case.kind for o in out)
    print(f"cases: {len(out)} ({', '.join(f'{k} {by_kind[k]}' for k in KINDS)})")
    print(f"refused (one line, exit 2): {counts['refused']}; valid: {counts['valid'] + counts['simulated']} "
          f"(simulated at tiny N: {counts['simulated']}); anything else: {sum(counts[b] for b in BAD)} "
          f"(tracebacks {counts['traceback']}, multi-line {counts['multi-line']}, hangs {counts['hang']})")
    seen: set[str] = set()
    for o in out:
        head = o.detail.split(":")[0]
        if o.result == "refused" and head not in seen and len(seen) < a.show:
            seen.add(head)
            print(f"  refused [{o.case.kind}] {o.case.args or o.case.data!r:.120}\n    -> {o.detail[:300]}")
    for o in out:
        if o.result in BAD:
            print(f"\n{o.result} [{o.case.kind}] args={o.case.args} files={o.case.files} data={o.case.data!r}\n"
                  f"{o.detail}")
    sys.exit(1 if any(o.result in BAD for o in out) else 0)


if __name__ == "__main__":
    main()
