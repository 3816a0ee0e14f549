"""The package's shape, checked from its source text: module size, import cycles, backend branches;
and the tests' own: a broken install fails them instead of skipping them.

Import cycles are found on the import statements of every module in ``realize/`` and ``envs/``
(read with ``ast``, so ``if TYPE_CHECKING:`` and function-local imports count too), as a
directed graph whose strongly connected components must all be single modules (networkx).

Skips are found the same way in every file under ``tests/``: a ``pytest.skip(...)`` or
``pytest.importorskip(...)`` call, ``skip`` / ``importorskip`` imported from pytest, or an
``except ImportError`` clause (a missing package made a branch) is an error unless it is one of
``ALLOWED_SKIPS``, the skips on the machine (its OS, a CUDA device) rather than the install.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import networkx as nx
import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("realize", "envs")
MAX_LINES = 400
# the scene backends are the only modules that may ask which backend runs
BACKEND_MODULES = {"realize.scene.cpu_tiled", "realize.scene.gpu", "realize.scene.backends"}


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for p in sorted((REPO / pkg).rglob("*.py")):
            rel = p.relative_to(REPO).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = p
    return out


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    tree = ast.parse(path.read_text())
    is_pkg = path.name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(tree):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base if is_pkg else base[:-1]
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [mod] + [f"{mod}.{a.name}" for a in node.names]
        for t in targets:
            # the deepest known module the import names (``from realize.x import y`` -> realize.x)
            parts = t.split(".")
            for i in range(len(parts), 0, -1):
                cand = ".".join(parts[:i])
                if cand in known:
                    if cand != name:
                        out.add(cand)
                    break
    return out


def test_no_module_over_400_lines() -> None:
    long = {n: len(p.read_text().splitlines()) for n, p in _modules().items()}
    long = {n: k for n, k in long.items() if k > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"


def test_scripts_use_the_public_api_never_the_tests() -> None:
    """A script is a thin shell over the library: it imports nothing from ``tests/`` (the
    helpers there may change with the tests) and puts no ``tests`` folder on ``sys.path``."""
    bad = []
    for path in sorted((REPO / "scripts").glob("*.py")):
        text = path.read_text()
        tree = ast.parse(text)
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in ("helpers", "tests"):
                bad.append(f"{path.name}: from {node.module} import ...")
            if isinstance(node, ast.Import) and any(a.name.split(".")[0] in ("helpers", "tests") for a in node.names):
                bad.append(f"{path.name}: import {', '.join(a.name for a in node.names)}")
        if re.search(r"""sys\.path\.insert\([^)]*["']tests["']""", text):
            bad.append(f"{path.name}: puts tests/ on sys.path")
    assert not bad, bad


def test_test_files_share_helpers_through_one_module() -> None:
    """A test file imports what it shares with other test files from ``helpers.py`` (or the golden
    runs' ``golden_runs.py``), never from another test file: a test file can then change alone."""
    bad = []
    for path in sorted((REPO / "tests").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [node.module or ""] if isinstance(node, ast.ImportFrom) else (
                [a.name for a in node.names] if isinstance(node, ast.Import) else [])
            bad += [f"{path.name}: imports {n}" for n in names if n.split(".")[-1].startswith("test_")]
    assert not bad, bad


def test_no_import_cycle() -> None:
    mods = _modules()
    g = nx.DiGraph()
    g.add_nodes_from(mods)
    for n, p in mods.items():
        for m in _imports(n, p, set(mods)):
            # a package's __init__ importing its own submodules is not a cycle of two jobs
            if not m.startswith(n + "."):
                g.add_edge(n, m)
    cycles = [sorted(c) for c in nx.strongly_connected_components(g) if len(c) > 1]
    assert not cycles, f"import cycles: {cycles}"


def test_backend_branches_only_in_backend_modules() -> None:
    pat = re.compile(r"\bbackend\s*[!=]=")
    hits = [f"{n}:{i + 1}" for n, p in _modules().items() if n not in BACKEND_MODULES
            for i, line in enumerate(p.read_text().splitlines()) if pat.search(line)]
    assert not hits, f"'backend ==' branches outside the scene backends: {hits}"


@pytest.mark.parametrize("name", sorted(_modules()))
def test_module_has_docstring(name: str) -> None:
    tree = ast.parse(_modules()[name].read_text())
    assert ast.get_docstring(tree), f"{name} has no module docstring"


def _robot_names() -> set[str]:
    """Every joint and link name of every robot's URDF (names with an underscore: 'root' is a word)."""
    import xml.etree.ElementTree as ET

    from realize.robot.spec import known_robots, load_robot_spec
    from realize.robot.urdf import source_urdf

    names: set[str] = set()
    for robot in known_robots():
        root = ET.parse(source_urdf(load_robot_spec(robot).urdf)).getroot()
        names |= {e.get("name", "") for e in [*root.iter("joint"), *root.iter("link")]}
    return {n for n in names if "_" in n}


# where a robot's own joints and links may be named: its package and the one agent class
ROBOT_MODULES = ("realize.robot", "envs.robot_agent")


def test_no_robot_joint_or_link_named_outside_the_robot_package() -> None:
    """Robots are data: generic code asks the spec, it never names a joint or link of a robot
    (in code, strings or docstrings)."""
    names = _robot_names()
    assert {"torso_lift_joint", "gripper_link", "right_panda_hand", "linear_actuator_height"} <= names
    word = re.compile(r"[A-Za-z0-9_]+")
    hits = []
    for n, p in _modules().items():
        if n.startswith(ROBOT_MODULES):
            continue
        for i, line in enumerate(p.read_text().splitlines()):
            found = sorted(set(word.findall(line)) & names)
            if found:
                hits.append(f"{n}:{i + 1} {found}")
    assert not hits, "robot joints/links named outside realize/robot/ and envs/robot_agent.py:\n" + "\n".join(hits)


def _package(module: str) -> str:
    """The layer a module belongs to: ``envs``, or ``realize.<package>`` (a top-level module is its own)."""
    parts = module.split(".")
    return "envs" if parts[0] == "envs" else ".".join(parts[:2])


def test_no_import_cycle_between_packages() -> None:
    """The packages are layers: no import runs back up between them (robot, world, tasks, run_dir,
    search, controllers, scene, realization, recording, sinks, figures, execution, spec, workers,
    validation, run, repair, cli; envs above the scene, which asks gym for its tasks by id and never
    imports envs)."""
    mods = _modules()
    g = nx.DiGraph()
    for n, p in mods.items():
        for m in _imports(n, p, set(mods)):
            a, b = _package(n), _package(m)
            if a != b:
                g.add_edge(a, b)
    cycles = [sorted(c) for c in nx.strongly_connected_components(g) if len(c) > 1]
    assert not cycles, f"import cycles between packages: {cycles}"
    assert not any(_package(m) == "envs" for n, p in mods.items() if n.startswith("realize")
                   for m in _imports(n, p, set(mods))), "realize imports envs"


def test_scene_task_ids_agree_with_envs() -> None:
    import envs
    from realize.scene.physics import task_id
    from realize.world.geometry import VARIANTS

    assert all(task_id(v) == envs.env_id_for(v) for v in VARIANTS)


# ------------------------------------------------------------------------------ tests fail on a broken install
TESTS = REPO / "tests"
# the only skips a test may take, (file under tests/, reason): the machine's, never the install's
# (every dependency, the ray extra and a Vulkan driver come with scripts/setup.sh)
ALLOWED_SKIPS = {
    ("test_gpu_backend.py", "the library is checked on Linux only"),
    ("test_gpu_check.py", "a CUDA device is here: the check runs instead of refusing"),
}
SKIP_NAMES = {"skip", "importorskip"}
IMPORT_ERRORS = {"ImportError", "ModuleNotFoundError"}


def _caught(handler: ast.ExceptHandler) -> set[str]:
    """The exception names an ``except`` clause catches (``except (A, b.B):`` -> {A, B})."""
    kinds = handler.type.elts if isinstance(handler.type, ast.Tuple) else [handler.type]
    return {k.attr if isinstance(k, ast.Attribute) else getattr(k, "id", "") for k in kinds if k is not None}


def _skips(source: str) -> list[tuple[int, str, str]]:
    """Every skip in a test file's source, in line order: (line, what, the skip's reason as
    written, or "")."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in SKIP_NAMES
                and isinstance(node.func.value, ast.Name) and node.func.value.id == "pytest"):
            arg = node.args[0] if node.args else None
            reason = arg.value if isinstance(arg, ast.Constant) else ast.unparse(arg) if arg is not None else ""
            found.append((node.lineno, f"pytest.{node.func.attr}", str(reason)))
        elif isinstance(node, ast.ImportFrom) and node.module == "pytest":
            found += [(node.lineno, f"from pytest import {a.name}", "") for a in node.names if a.name in SKIP_NAMES]
        elif isinstance(node, ast.ExceptHandler) and _caught(node) & IMPORT_ERRORS:
            found.append((node.lineno, "except " + "/".join(sorted(_caught(node) & IMPORT_ERRORS)), ""))
    return sorted(found)


def _test_skips() -> list[tuple[str, int, str, str]]:
    """``_skips`` of every Python file under tests/: (file relative to tests/, line, what, reason)."""
    return [(p.relative_to(TESTS).as_posix(), line, what, reason) for p in sorted(TESTS.rglob("*.py"))
            for line, what, reason in _skips(p.read_text())]


def test_skip_finder_sees_every_form() -> None:
    """The finder on a made-up test file holding each form once (an unrelated except beside)."""
    src = """import pytest
from pytest import importorskip
nx = pytest.importorskip("networkx")
try:
    import ray
except (ModuleNotFoundError, KeyError):
    ray = None
def test_x():
    pytest.skip(f"no device: {ray}")
"""
    assert _skips(src) == [(2, "from pytest import importorskip", ""), (3, "pytest.importorskip", "networkx"),
                           (6, "except ModuleNotFoundError", ""), (9, "pytest.skip", "f'no device: {ray}'")]


def test_tests_fail_instead_of_skipping_on_a_broken_install() -> None:
    """A missing dependency, a missing Vulkan device or an ImportError in the project itself must
    fail a test: the only skips are the allowed ones (the machine's OS, a CUDA device)."""
    found = _test_skips()
    bad = [f"tests/{f}:{line} {what}" + (f"({reason!r})" if reason else "") for f, line, what, reason in found
           if (f, reason) not in ALLOWED_SKIPS]
    assert not bad, ("skips of a broken install (import the package, let a missing one fail; or add a skip on "
                     "the machine to ALLOWED_SKIPS):\n" + "\n".join(bad))
    stale = ALLOWED_SKIPS - {(f, reason) for f, _, _, reason in found}
    assert not stale, f"ALLOWED_SKIPS names skips no test takes: {sorted(stale)}"
