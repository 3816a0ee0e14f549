"""The whole-body fabric step built ahead of time into native code (``controller.fabric.compiled``).

What it does: exports ``WholeBodyFabric.step_tensors`` with ``torch.export`` and builds it with
AOTInductor into a package (a C++ shared library inside a ``.pt2`` file) for the CPU, once per
machine, robot, fabric settings, control period, dtype, source code and torch version. Packages
live in ``realize.paths.cache_dir("fabric")``; a later process loads one in about a second
(building takes about a minute on a 2-core machine). The batch size and the number of scene
boxes are dynamic, so one package serves every shard, subset of plans and world of a robot.
Two processes that need the same package build it once (a file lock); a build is written under
a temporary name and renamed into place, so no process reads half a package. A build deletes all
but the ``KEEP_PER_ROBOT`` newest packages of its robot; a file that does not load is a
``ConfigError`` naming it.

Numbers: per row the result equals the eager step's to within float32 rounding (the compiler sums
in another order: about 3e-7 on the joint targets, tests/test_fabric_package.py), and a row's
result does not depend on its batch mates, bit for bit. The code is built for AVX2
(``SIMD_BITS``) on every x86 host, so hosts with and without AVX-512 run the same code.

What it doesn't: run on other devices than the CPU (there the eager step runs), take a per-plan
attractor weight (the eager step does), or decide when to use the package (``WholeBodyFabric``
does, from its config).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import platform
import sys
import time
import warnings
from pathlib import Path
from typing import Any, Callable

import torch
from torch import Tensor

from realize.config import ConfigError
from realize.file_lock import file_lock
from realize.paths import cache_dir

__all__ = ["package_key", "package_path", "ensure_built", "load_package", "SIMD_BITS"]

KEEP_PER_ROBOT = 8  # packages kept per robot in the cache folder (the newest)
SIMD_BITS = 256  # vector width of the generated code: AVX2 on x86 (the same code on every host)
_SOURCES = (Path(__file__).resolve().parent, Path(__file__).resolve().parent.parent / "robot")
_LOADED: dict[Path, Callable[..., Any]] = {}


def _digest_tensors(obj: Any, h: Any, seen: set[int], depth: int = 0) -> None:
    """Feed every tensor reachable from ``obj`` (attributes, lists, dicts; 4 levels) into ``h``."""
    if id(obj) in seen or depth > 4:
        return
    seen.add(id(obj))
    if isinstance(obj, Tensor):
        h.update(f"{obj.dtype}{tuple(obj.shape)}".encode())
        h.update(obj.detach().cpu().reshape(-1).contiguous().view(torch.uint8).numpy().tobytes())
        return
    if isinstance(obj, dict):
        items = sorted(obj.items(), key=lambda kv: str(kv[0]))
    elif isinstance(obj, (list, tuple)):
        items = list(enumerate(obj))
    elif hasattr(obj, "__dict__") and type(obj).__module__.startswith("realize."):
        items = sorted(vars(obj).items())
    else:
        return
    for key, value in items:
        if key in ("boxes", "_package"):  # the boxes are an input of the package
            continue
        h.update(str(key).encode())
        _digest_tensors(value, h, seen, depth + 1)


def package_key(fabric: Any) -> str:
    """What the package of ``fabric`` (a ``WholeBodyFabric``) depends on, hashed: torch, the
    machine, the robot, the settings, the control period, the dtype, every constant tensor of
    the fabric and the source of ``realize.controllers`` and ``realize.robot``."""
    h = hashlib.sha256()
    h.update(f"{torch.__version__}|{platform.machine()}|{SIMD_BITS}|{fabric.dtype}|{fabric.dt!r}".encode())
    settings = dataclasses.asdict(fabric.cfg)
    settings.pop("compiled", None)
    h.update(json.dumps(settings, sort_keys=True, default=str).encode())
    h.update(json.dumps(dataclasses.asdict(fabric.robot), sort_keys=True, default=str).encode())
    _digest_tensors(fabric, h, set())
    for folder in _SOURCES:
        for src in sorted(folder.glob("*.py")):
            h.update(src.name.encode())
            h.update(src.read_bytes())
    return h.hexdigest()[:24]


def package_path(fabric: Any) -> Path:
    """Where the package of ``fabric`` is (or will be) cached."""
    return cache_dir("fabric") / f"{fabric.robot.name}-{package_key(fabric)}.pt2"


class _Step(torch.nn.Module):
    def __init__(self, fabric: Any):
        super().__init__()
        self.fabric = fabric

    def forward(self, q: Tensor, qd: Tensor, q_meas: Tensor, goal: Tensor, boxes: Tensor
                ) -> tuple[Tensor, Tensor, Tensor]:
        return self.fabric.step_tensors(q, qd, q_meas, goal, boxes)


def _build(fabric: Any, out: Path) -> None:
    """Export ``fabric``'s step for any number of rows and boxes and build it into ``out``."""
    import torch._inductor  # noqa: F401  (import cost only where a package is built or loaded)

    n = 4  # an example batch (1 would be specialised)
    rest = torch.tensor(fabric.robot.rest_q(), dtype=fabric.dtype, device=fabric.device)
    q = torch.maximum(torch.minimum(rest, fabric._clamp_hi), fabric._clamp_lo).expand(n, -1).contiguous()
    goal = (fabric.pose_points(q) + 0.1).contiguous()
    example = (q, torch.zeros_like(q), q.clone(), goal, fabric.boxes)
    rows = torch.export.Dim("rows", min=1, max=1 << 16)
    count = torch.export.Dim("boxes", min=1, max=4096)
    # torch's own notes on the way (a deprecation inside torch.export, "using proxy executor" for
    # linalg_solve_ex) are not the user's to act on: a failure still raises
    inductor_log = logging.getLogger("torch._inductor")
    level = inductor_log.level
    inductor_log.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            with torch.no_grad():
                program = torch.export.export(_Step(fabric), example, strict=False,
                                              dynamic_shapes=({0: rows}, {0: rows}, {0: rows}, {0: rows}, {0: count}))
            with torch._inductor.config.patch({"cpp.simdlen": SIMD_BITS}):
                torch._inductor.aoti_compile_and_package(program, package_path=str(out))
    finally:
        inductor_log.setLevel(level)


def ensure_built(fabric: Any) -> Path:
    """The package of ``fabric``, built first if this machine has none yet (a failed build
    raises ``ConfigError``)."""
    path = package_path(fabric)
    if path.is_file():
        return path
    with file_lock(path.with_suffix(".lock")):  # another process may be building it: wait for it
        if path.is_file():
            return path
        print(f"realize: building the compiled fabric step of {fabric.robot.name} once for this "
              f"machine (about a minute), cached as {path}", file=sys.stderr, flush=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}.pt2")
        start = time.perf_counter()
        try:
            _build(fabric, tmp)
            os.replace(tmp, path)
        except Exception as e:  # no compiler, an export failure: say what to do
            tmp.unlink(missing_ok=True)
            first = str(e).splitlines()[0] if str(e) else ""
            raise ConfigError(f"controller.fabric.compiled = true: building the fabric step failed "
                              f"({type(e).__name__}: {first}); set controller.fabric.compiled=false "
                              "to run it eagerly") from e
        print(f"realize: built in {time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
    _prune(path)
    return path


def _prune(kept: Path, keep: int = KEEP_PER_ROBOT) -> None:
    """Delete all but the ``keep`` newest packages of ``kept``'s robot (each source change of the
    fabric's code makes a new one)."""
    robot = kept.name.rsplit("-", 1)[0]
    packages = sorted(kept.parent.glob(f"{robot}-*.pt2"), key=lambda p: p.stat().st_mtime, reverse=True)
    for old in packages[keep:]:
        if old != kept:
            old.unlink(missing_ok=True)
            old.with_suffix(".lock").unlink(missing_ok=True)


def load_package(fabric: Any) -> Callable[..., tuple[Tensor, Tensor, Tensor]]:
    """The built step of ``fabric``: ``(q_ref, qd_ref, q_meas, goal, boxes) -> (q, qd, valid)``
    (``ensure_built`` first)."""
    path = ensure_built(fabric)
    if path not in _LOADED:
        import torch._inductor

        try:
            _LOADED[path] = torch._inductor.aoti_load_package(str(path))
        except Exception as e:  # a damaged file: say which, and how to get a good one
            raise ConfigError(f"controller.fabric.compiled = true: cannot load the fabric step {path} "
                              f"({type(e).__name__}); delete the file to build it again, or set "
                              "controller.fabric.compiled=false") from e
    return _LOADED[path]
