"""GPU check: the torch-batched controllers and the CE optimizer on CUDA against the CPU, in one command.

Sized for an offline CUDA machine with only a preinstalled Python (torch, numpy, scipy, PyYAML):
it imports this checkout's ``realize`` controllers and nothing of ManiSkill, SAPIEN, Hydra or
rerun. The robot's URDF is the one file it needs from ManiSkill: ``--urdf FILE`` (default:
ManiSkill's ``fetch.urdf`` where ManiSkill is installed; ``--bundle DIR`` copies it into DIR, a
folder to carry to a machine without ManiSkill).

Parts, each in a child process with its own time limit, for every N of ``--sizes``: the same
inputs (made on the CPU from a fixed seed) run on ``--device`` and on the CPU; a row gives the
time per call on both, the largest difference and the tolerance it is held to:

  kinematics  forward kinematics + closed-form Jacobian jets of the TCP and spheres (float64)
  fabric      3 steps of the whole-body fabric from perturbed rest poses (float32, the rollout's)
  astar       batched A* on the seed world's padded grid, start to random goals (costs, statuses)
  field       the distance-field planner (``planner="field"``) on the same queries (same paths)
  pid         20 PID steps along straight waypoint lines, pose integrated (float32)
  ce          3 CE iterations ask/tell, a 10-D box layout, a quadratic cost on the device (exact)

The table (``gpu_check.md``), the rows (``rows.jsonl``) and one log per part are written to
``--out`` (or ``$OUT``; default ``outputs/gpu_check/<time>``) as each part ends. A part that
reaches its limit keeps its finished rows and adds one saying where it stopped; the whole run
stays within ``--budget`` seconds. Then, where ManiSkill and SAPIEN are installed (or with
``--physics``; ``--no-physics`` skips them), the PhysX GPU parts with their own limits: ``pytest
-m gpu`` and a seed-paper run on ``device=cuda`` (they need SAPIEN's PhysX GPU library:
``python -m realize.physx_gpu --fetch``, or ``make setup``, where there is network).
What it doesn't: simulate physics without ``--physics``, or judge speed (it reports it).

    python3 scripts/gpu_check.py [--device cuda|cpu] [--sizes 200,3000,30000] [--out DIR]
                                 [--urdf FILE] [--budget S] [--[no-]physics] [--bundle DIR]
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
URDF_IN_MANISKILL = ("assets", "robots", "fetch", "fetch.urdf")
# part -> (limit on CUDA in s, tolerance, what the difference is measured in)
PARTS: dict[str, tuple[float, float, str]] = {
    "kinematics": (25.0, 1e-9, "m (positions, Jacobians, velocities, curvature)"),
    "fabric": (60.0, 1e-3, "rad or m (q and q' after 3 steps)"),
    "astar": (50.0, 1e-9, "cells (path cost; statuses must be equal)"),
    "field": (25.0, 1e-9, "cells (path cost; statuses, lengths, paths equal)"),
    "pid": (20.0, 1e-3, "m/s or rad/s (commands over 20 steps)"),
    "ce": (25.0, 0.0, "samples and costs (bit for bit)"),
}
PHYSICS: dict[str, tuple[float, str]] = {"physx gpu tests": (240.0, "physx_tests.log"),
                                         "seed paper (200 x 10) on PhysX GPU": (600.0, "seed_paper.log")}


# ------------------------------------------------------------------ the parts (child processes)

def _inputs_fabric(n: int, spec: Any) -> dict[str, Any]:
    import torch

    g = torch.Generator().manual_seed(n)
    q = torch.tensor(spec.rest_q(), dtype=torch.float64).expand(n, -1) + 0.1 * torch.randn(n, spec.n_dof, generator=g,
                                                                                         dtype=torch.float64)
    q[:, 0] = 0.9 + 0.3 * torch.rand(n, generator=g, dtype=torch.float64)
    q[:, 1] = 1.2 + 0.3 * (2 * torch.rand(n, generator=g, dtype=torch.float64) - 1)
    q[:, 2] = math.pi
    qd = 0.3 * torch.randn(n, spec.n_dof, generator=g, dtype=torch.float64)
    return {"q": q, "qd": qd}


class Parts:
    """Each part: ``make(n)`` (CPU inputs) and ``run(inputs, device)`` (a tuple of result tensors;
    ``calls`` of them per run, for the time per call), using what ``built(part, device)`` made once
    (a kinematic model, a fabric, an occupancy grid: not part of the time per call)."""

    def __init__(self, urdf: str | None) -> None:
        import torch

        from realize.world.geometry import GeometryCfg, build_geometry
        from realize.realization.config import RolloutConfig
        from realize.robot.spec import load_robot_spec

        self.torch = torch
        spec = load_robot_spec("fetch_omni")
        self.spec = spec if urdf is None else dataclasses.replace(spec, urdf=str(Path(urdf).resolve()))
        self.geometry = build_geometry(GeometryCfg())
        self.cfg = RolloutConfig()
        self.calls = {"fabric": 3, "pid": 20, "ce": 3}
        self._built: dict[tuple[str, str], Any] = {}

    def built(self, part: str, dev: Any) -> Any:
        """The part's controller on ``dev`` (None where it has none), made on first use."""
        key = (part, str(dev))
        if key not in self._built:
            make = getattr(self, f"build_{part}", None)
            self._built[key] = None if make is None else make(dev)
        return self._built[key]

    # kinematics --------------------------------------------------
    def make_kinematics(self, n: int) -> dict[str, Any]:
        return _inputs_fabric(n, self.spec)

    def build_kinematics(self, dev: Any) -> Any:
        from realize.robot.kinematics import RobotKinematics

        return RobotKinematics(self.spec, device=dev, dtype=self.torch.float64)

    def run_kinematics(self, x: dict[str, Any], dev: Any) -> tuple:
        ee, sph = self.built("kinematics", dev).jets(x["q"].to(dev), x["qd"].to(dev))
        return (*ee, *sph)

    # whole-body fabric -------------------------------------------
    def make_fabric(self, n: int) -> dict[str, Any]:
        t = self.torch
        x = _inputs_fabric(n, self.spec)
        x["goal"] = (t.tensor([0.0, 1.2, 0.82]).expand(n, 3), t.tensor([0.0, 0.0, -1.0]).expand(n, 3),
                     t.tensor([0.0, 1.0, 0.0]).expand(n, 3))
        return x

    def build_fabric(self, dev: Any) -> Any:
        from realize.controllers.whole_body import WholeBodyFabric

        return WholeBodyFabric(self.geometry, self.cfg.fabric, dt=0.05, device=dev, dtype=self.torch.float32,
                               robot=self.spec)

    def run_fabric(self, x: dict[str, Any], dev: Any) -> tuple:
        f32, fab = self.torch.float32, self.built("fabric", dev)
        q = x["q"].to(dev, f32)
        goal = fab.goal_points(*(g.to(dev, f32) for g in x["goal"]))
        state = fab.start(q, x["qd"].to(dev, f32))
        for _ in range(self.calls["fabric"]):
            state, valid = fab.step(state, state.q, goal)
        return state.q, state.qd, valid

    # A* and the distance-field planner ---------------------------
    def build_astar(self, dev: Any) -> tuple[Any, Any]:
        """The seed world's grid and padded occupancy (on ``dev``), as the rollout builds them."""
        from realize.controllers.occupancy import grid_from_bounds, occupancy_from_boxes
        from realize.robot.spec import DEFAULT_ROBOT, load_robot_spec

        t, g, a = self.torch, self.geometry, self.cfg.astar
        footprint = load_robot_spec(DEFAULT_ROBOT).base.footprint_radius
        grid = grid_from_bounds((g.bounds_low[0], g.bounds_low[1], g.bounds_high[0], g.bounds_high[1]), a.resolution)
        obs = g.obstacles
        occ = occupancy_from_boxes(grid, t.tensor([b.center[:2] for b in obs]),
                                   t.tensor([list(b.footprint_half_size()) for b in obs]),
                                   t.tensor([b.yaw for b in obs]), padding=a.padding + footprint)
        return grid, occ.to(dev)

    build_field = build_astar

    def make_astar(self, n: int) -> dict[str, Any]:
        t, g = self.torch, self.geometry
        gen = t.Generator().manual_seed(n)
        lo, hi = t.tensor(g.bounds_low[:2]), t.tensor(g.bounds_high[:2])
        goal = lo + (hi - lo) * t.rand(n, 2, generator=gen, dtype=t.float64)
        start = t.tensor(g.robot_start[:2], dtype=t.float64).expand(n, 2)
        return {"start": start, "goal": goal}

    make_field = make_astar

    def _plan(self, x: dict[str, Any], dev: Any, planner: str):
        from realize.controllers.astar import astar_world

        grid, occ = self.built(planner if planner == "field" else "astar", dev)
        return astar_world(occ, grid, x["start"].to(dev), x["goal"].to(dev), planner=planner)

    def run_astar(self, x: dict[str, Any], dev: Any) -> tuple:
        r = self._plan(x, dev, "astar")
        return r.status.double(), r.cost.nan_to_num(posinf=-1.0)

    def run_field(self, x: dict[str, Any], dev: Any) -> tuple:
        r = self._plan(x, dev, "field")
        return r.status.double(), r.cost.nan_to_num(posinf=-1.0), r.lengths.double(), r.path.double()

    # PID ---------------------------------------------------------
    def make_pid(self, n: int) -> dict[str, Any]:
        t = self.torch
        gen = t.Generator().manual_seed(n)
        pose = t.zeros(n, 3)
        pose[:, 2] = math.pi * (2 * t.rand(n, generator=gen) - 1)
        ends = 2.0 * (2 * t.rand(n, 2, generator=gen) - 1)
        wps = t.stack([0.5 * ends, ends], dim=1)  # two waypoints on a straight line
        return {"pose": pose, "waypoints": wps, "lengths": t.full((n,), 2, dtype=t.long)}

    def run_pid(self, x: dict[str, Any], dev: Any) -> tuple:
        from realize.controllers.pid import pid_init, pid_step

        t, cfg, dt = self.torch, self.cfg.pid, 0.05
        pose, wps, lengths = x["pose"].to(dev), x["waypoints"].to(dev), x["lengths"].to(dev)
        state = pid_init(cfg, pose, wps, lengths)
        cmds = []
        for _ in range(self.calls["pid"]):
            out = pid_step(cfg, state, pose, wps, lengths, dt)
            state, cmd = out.state, out.cmd
            c, s = t.cos(pose[:, 2]), t.sin(pose[:, 2])
            v = t.stack([c * cmd[:, 0] - s * cmd[:, 1], s * cmd[:, 0] + c * cmd[:, 1], cmd[:, 2]], dim=1)
            pose = pose + dt * v
            cmds.append(cmd)
        return t.stack(cmds), pose

    # CE ask/tell -------------------------------------------------
    def make_ce(self, n: int) -> dict[str, Any]:
        return {"n": n}

    def run_ce(self, x: dict[str, Any], dev: Any) -> tuple:
        from realize.search.ce.config import CEConfig
        from realize.search.ce.optimizer import CrossEntropyOptimizer
        from realize.tasks.param_layout import ParamLayout
        from realize.tasks.regions import Box
        from realize.search.protocol import EvalResult

        t, n = self.torch, x["n"]
        layout = ParamLayout({"p": Box([-5.0] * 10, [5.0] * 10)})
        cfg = CEConfig(n_envs=n, n_elite=max(2, n // 20), iterations=self.calls["ce"], seed=0)
        opt = CrossEntropyOptimizer(layout, cfg, device=dev)
        target = t.linspace(-1.0, 1.0, 10, dtype=t.float64, device=dev)
        Zs, costs = [], []
        while (batch := opt.ask()) is not None:
            cost = ((batch.Z - target) ** 2).sum(dim=1)
            opt.tell(EvalResult(cost=cost, feasible=cost < 60.0))
            Zs.append(batch.Z)
            costs.append(cost)
        return t.stack(Zs), t.stack(costs)


def _timed(fn: Callable[[], Any], sync: Callable[[], None], budget_s: float) -> tuple[float, Any, int]:
    """Median seconds of the calls after the first (warm-up: kernels, caches, allocations): at
    least one more unless the first took over 10 ``budget_s``, more while within ``budget_s``
    (at most 10); the last output, and how many calls ran."""
    times, out = [], None
    while (not times or (len(times) < 2 and times[0] < 10 * budget_s)
           or (sum(times) < budget_s and len(times) < 10)):
        t0 = time.perf_counter()
        out = fn()
        sync()
        times.append(time.perf_counter() - t0)
    return statistics.median(times[1:] or times), out, len(times)


def _max_diff(a: tuple, b: tuple) -> float:
    worst = 0.0
    for x, y in zip(a, b):
        x, y = x.detach().cpu().double(), y.detach().cpu().double()
        if x.shape != y.shape:
            return math.inf
        if x.numel():
            worst = max(worst, float((x - y).abs().nan_to_num(nan=math.inf).max()))
    return worst


def run_part(name: str, device: str, sizes: list[int], urdf: str | None, records: Path, timing_s: float) -> None:
    """One part in this (child) process; a JSON line per size and stage, flushed at once."""
    import torch

    dev = torch.device(device)
    sync = torch.cuda.synchronize if dev.type == "cuda" else (lambda: None)
    parts = Parts(urdf)
    make, run = getattr(parts, f"make_{name}"), getattr(parts, f"run_{name}")
    calls = parts.calls.get(name, 1)
    tol = PARTS[name][1]
    cpu = torch.device("cpu")
    parts.built(name, dev), parts.built(name, cpu)
    with open(records, "a") as rec:
        def emit(**kw: Any) -> None:
            rec.write(json.dumps({"part": name, **kw}) + "\n")
            rec.flush()

        for n in sizes:
            x = make(n)
            emit(n=n, stage="started")
            t_dev, out_dev, reps = _timed(lambda: run(x, dev), sync, timing_s)
            emit(n=n, stage="device", device_s=t_dev / calls, device_reps=reps)
            t_cpu, out_cpu, cpu_reps = _timed(lambda: run(x, cpu), lambda: None, timing_s)
            err = _max_diff(out_dev, out_cpu)
            emit(n=n, stage="done", cpu_s=t_cpu / calls, cpu_reps=cpu_reps, max_diff=err, ok=err <= tol)


# ------------------------------------------------------------------ the driver

def _rows(records: Path, name: str, sizes: list[int], status: str) -> list[dict[str, Any]]:
    """The part's rows from its records: one per size it finished, one saying where it stopped."""
    by_n: dict[int, dict[str, Any]] = {}
    if records.exists():
        for line in records.read_text().splitlines():
            try:
                r = json.loads(line)
            except json.JSONDecodeError:  # a line cut short by the kill at a limit
                continue
            if r["part"] == name:
                by_n.setdefault(r["n"], {}).update(r)
    rows = []
    for n in sizes:
        r = by_n.get(n)
        if r is None:
            if status != "ok":
                rows.append({"part": name, "n": n, "result": f"not reached ({status})"})
            break
        if r["stage"] == "done":
            r["result"] = "ok" if r["ok"] else "MISMATCH"
        else:
            r["result"] = f"{status} while timing the {'device' if r['stage'] == 'started' else 'CPU'}"
        rows.append(r)
        if r["stage"] != "done":
            break
    return rows


def _fmt(v: Any, unit: float = 1e3) -> str:
    return "-" if v is None else f"{v * unit:.3g}"


def table(rows: list[dict[str, Any]], head: str) -> str:
    lines = [head, "", "| part | N | device ms/call | CPU ms/call | CPU / device | max diff | tolerance | result |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "n" not in r:  # a physics part
            lines.append(f"| {r['part']} | - | - | - | - | - | - | {r['result']} ({r['wall_s']:.0f} s) |")
            continue
        dev, cpu = r.get("device_s"), r.get("cpu_s")
        ratio = f"{cpu / dev:.2g}x" if dev and cpu else "-"
        diff = "-" if r.get("max_diff") is None else f"{r['max_diff']:.2g}"
        lines.append(f"| {r['part']} | {r['n']} | {_fmt(dev)} | {_fmt(cpu)} | {ratio} | {diff} | "
                     f"{PARTS[r['part']][1]:g} {PARTS[r['part']][2]} | {r['result']} |")
    return "\n".join(lines) + "\n"


def _run_child(cmd: list[str], log: Path, limit_s: float, env: dict[str, str] | None = None) -> tuple[str, float]:
    t0 = time.perf_counter()
    with open(log, "w") as f:
        proc = subprocess.Popen(cmd, cwd=REPO, stdout=f, stderr=subprocess.STDOUT, start_new_session=True, env=env)
        try:
            rc = proc.wait(timeout=max(1.0, limit_s))
            status = "ok" if rc == 0 else f"failed (exit {rc}, see {log.name})"
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, 9)
            proc.wait()
            status = f"stopped at its {limit_s:.0f} s limit"
    return status, time.perf_counter() - t0


def default_urdf() -> str | None:
    """ManiSkill's fetch.urdf, located without importing ManiSkill (None where it is not installed)."""
    spec = importlib.util.find_spec("mani_skill")
    if spec is None or not spec.submodule_search_locations:
        return None
    path = Path(list(spec.submodule_search_locations)[0]).joinpath(*URDF_IN_MANISKILL)
    return str(path) if path.is_file() else None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--device", default="cuda", help="cuda (default) or cpu (a check of this script itself)")
    ap.add_argument("--sizes", default="200,3000,30000", help="comma-separated N")
    ap.add_argument("--parts", default=",".join(PARTS), help=f"comma-separated subset of {','.join(PARTS)}")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default $OUT, else outputs/gpu_check/<time>)")
    ap.add_argument("--urdf", default=None, help="Fetch's URDF (default: ManiSkill's, where it is installed)")
    ap.add_argument("--budget", type=float, default=280.0, help="seconds for the whole check")
    ap.add_argument("--limit-scale", type=float, default=1.0, help="multiplies every part's time limit")
    ap.add_argument("--timing", type=float, default=2.0, help="seconds of repeated calls per time measurement")
    ap.add_argument("--physics", action=argparse.BooleanOptionalAction, default=None,
                    help="the PhysX GPU parts too (default: where ManiSkill and SAPIEN are installed, on CUDA)")
    ap.add_argument("--bundle", type=Path, default=None, help="copy the URDF into this folder and exit")
    ap.add_argument("--part", default=None, help=argparse.SUPPRESS)  # internal: run one part here
    ap.add_argument("--records", type=Path, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    sizes = [int(s) for s in a.sizes.split(",") if s.strip()]
    urdf = a.urdf or default_urdf()
    if a.part is not None:
        run_part(a.part, a.device, sizes, urdf, a.records, a.timing)
        return 0
    if urdf is None or not Path(urdf).is_file():
        print(f"gpu_check: error: no Fetch URDF ({urdf or 'ManiSkill is not installed'}); pass --urdf FILE "
              "(copy one with `python scripts/gpu_check.py --bundle DIR` where ManiSkill is)", file=sys.stderr)
        return 2
    if a.bundle is not None:
        a.bundle.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(urdf, a.bundle / "fetch.urdf")
        print(f"gpu_check: copied {urdf} to {a.bundle / 'fetch.urdf'}; there: --urdf {a.bundle / 'fetch.urdf'}")
        return 0
    unknown = [p for p in a.parts.split(",") if p not in PARTS]
    if unknown or not sizes or min(sizes) < 1:
        print(f"gpu_check: error: --parts {unknown} unknown (known: {list(PARTS)}) or bad --sizes {a.sizes!r}",
              file=sys.stderr)
        return 2
    import torch

    if a.device == "cuda" and not torch.cuda.is_available():
        print("gpu_check: error: torch sees no CUDA device (use --device cpu to check the script itself)",
              file=sys.stderr)
        return 2
    out = a.out or (Path(os.environ["OUT"]) if os.environ.get("OUT") else
                    REPO / "outputs" / "gpu_check" / time.strftime("%Y%m%d-%H%M%S"))
    out.mkdir(parents=True, exist_ok=True)
    records = out / "rows.jsonl"
    records.unlink(missing_ok=True)
    name = torch.cuda.get_device_name(0) if a.device == "cuda" else "CPU"
    head = (f"GPU check on {name} vs the CPU ({os.cpu_count()} cores, torch {torch.__version__} with "
            f"{torch.get_num_threads()} threads, Python {sys.version.split()[0]}), sizes {sizes}")
    deadline = time.monotonic() + a.budget
    rows: list[dict[str, Any]] = []
    for part in a.parts.split(","):
        limit = min(PARTS[part][0] * a.limit_scale, deadline - time.monotonic())
        if limit < 1.0:
            rows.append({"part": part, "n": sizes[0], "result": f"not run: the {a.budget:.0f} s --budget was spent"})
            continue
        cmd = [sys.executable, str(Path(__file__).resolve()), "--part", part, "--device", a.device,
               "--sizes", a.sizes, "--records", str(records), "--timing", str(a.timing), "--urdf", urdf]
        status, wall = _run_child(cmd, out / f"{part}.log", limit)
        rows += _rows(records, part, sizes, status)
        (out / "gpu_check.md").write_text(table(rows, head))
        print(f"gpu_check: {part}: {status}, {wall:.1f} s", flush=True)
    physics = a.physics if a.physics is not None else (
        a.device == "cuda" and all(importlib.util.find_spec(m) is not None for m in ("mani_skill", "sapien")))
    if physics:
        py, run_dir = sys.executable, out / "seed_paper"
        physics = {"physx gpu tests": [py, "-m", "pytest", "-q", "-m", "gpu", "tests"],
                   "seed paper (200 x 10) on PhysX GPU": [py, "-m", "realize", "device=cuda", "experiment=seed_paper",
                                                          "logging.progress=false", f"hydra.run.dir={run_dir}"]}
        for part, cmd in physics.items():
            limit, log = PHYSICS[part]
            status, wall = _run_child(cmd, out / log, limit * a.limit_scale)
            rows.append({"part": part, "result": status, "wall_s": wall})
            (out / "gpu_check.md").write_text(table(rows, head))
            print(f"gpu_check: {part}: {status}, {wall:.0f} s", flush=True)
    print(table(rows, head))
    print(f"gpu_check: table and logs in {out}")
    return 0 if all(r["result"] == "ok" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
