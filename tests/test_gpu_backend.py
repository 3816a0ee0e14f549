"""The PhysX GPU backend's bookkeeping, checked without a GPU.

* Apply/fetch order (``realize.scene.gpu``): PhysX GPU keeps its state in device buffers that
  ManiSkill's setters write; ``gpu_apply_*`` pushes a buffer into the simulation, a step
  simulates, ``gpu_fetch_*`` overwrites buffers with the simulation's state, and link poses follow
  new joints only after ``gpu_update_articulation_kinematics`` (or a step). ``_GpuPhysx`` below
  records that protocol (a write lost, a stale link pose) while the backend runs against it with
  ManiSkill's own ``_gpu_apply_all`` / ``_gpu_fetch_all``.
* The PhysX GPU library check and fetch (``realize.physx_gpu``), with HOME in a temporary
  folder, a real ELF library from this environment and a local HTTP server.
* ``device: auto`` picks the CPU where torch reports CUDA; ``gpu`` warns once (CUDA mocked).
* The task's PhysX GPU settings (``envs.pick_place``): contact buffers, no enhanced determinism.
What it doesn't: run PhysX GPU (``tests/test_gpu_rollout.py`` does, on a CUDA machine).
"""

from __future__ import annotations

import http.server
import io
import shutil
import subprocess
import sys
import threading
import time
import warnings
import zipfile
from pathlib import Path
from types import MethodType, SimpleNamespace

import numpy
import pytest
import torch
from mani_skill.envs.scene import ManiSkillScene
from mani_skill.envs.tasks.mobile_manipulation.open_cabinet_drawer import OpenCabinetDrawerEnv

import realize.scene.backends as backends
from envs.pick_place import RealizePickPlaceEnv
from envs.tiling import gpu_memory_config
from realize.config import ConfigError
from realize.world.geometry import GeometryCfg, build_geometry
from realize import physx_gpu
from realize.scene.gpu import GpuBackend

REPO = Path(__file__).resolve().parents[1]
N = 4

# gpu_apply_<name> / gpu_fetch_<name> -> the buffer it pushes / overwrites (None: reads only)
APPLY = {"rigid_dynamic_data": "rigid", "articulation_qpos": "qpos", "articulation_qvel": "qvel",
         "articulation_qf": "qf", "articulation_root_pose": "root_pose", "articulation_root_velocity": "root_vel",
         "articulation_target_position": "target_qpos", "articulation_target_velocity": "target_qvel"}
FETCH = {"rigid_dynamic_data": "rigid", "articulation_link_pose": None, "articulation_link_velocity": None,
         "articulation_qpos": "qpos", "articulation_qvel": "qvel", "articulation_qacc": None,
         "articulation_target_qpos": "target_qpos", "articulation_target_qvel": "target_qvel"}


class _GpuPhysx:
    """A recording stand-in for ``sapien.physx.PhysxGpuSystem``'s buffer protocol (see the module
    docstring); ``problems`` lists every write lost and every stale link pose read."""

    def __init__(self) -> None:
        self.log: list[str] = []
        self.problems: list[str] = []
        self.dirty: set[str] = set()
        self.links_stale = False

    def write(self, buf: str) -> None:
        self.log.append(f"write {buf}")
        self.dirty.add(buf)

    def __getattr__(self, name: str):
        if name.startswith("gpu_apply_"):
            return lambda: self._apply(name[len("gpu_apply_"):])
        if name.startswith("gpu_fetch_"):
            return lambda: self._fetch(name[len("gpu_fetch_"):])
        raise AttributeError(name)

    def _apply(self, what: str) -> None:
        buf = APPLY[what]
        self.log.append(f"apply {buf}")
        self.dirty.discard(buf)
        self.links_stale |= buf in ("qpos", "root_pose")

    def gpu_update_articulation_kinematics(self) -> None:
        self.log.append("update kinematics")
        self.links_stale = False

    def step(self) -> None:
        self.log.append("step")
        self.problems += [f"{b} written, not applied before a step: the write is lost" for b in sorted(self.dirty)]
        self.dirty.clear()
        self.links_stale = False

    def _fetch(self, what: str) -> None:
        buf = FETCH[what]
        self.log.append(f"fetch {what}")
        if buf in self.dirty:
            self.problems.append(f"{buf} written, not applied: gpu_fetch_{what} overwrote it")
            self.dirty.discard(buf)
        if what == "articulation_link_pose" and self.links_stale:
            self.problems.append("link poses fetched after new joints without gpu_update_articulation_kinematics")


class _Cube:
    """ManiSkill's Actor on GPU: pose and velocity setters write the rigid-body buffer."""

    def __init__(self, px: _GpuPhysx) -> None:
        self.px = px
        self.pose = SimpleNamespace(raw_pose=torch.zeros(N, 7))
        self.linear_velocity = torch.zeros(N, 3)
        self.angular_velocity = torch.zeros(N, 3)

    def set_pose(self, pose: torch.Tensor) -> None:
        self.px.write("rigid")

    def set_linear_velocity(self, v: torch.Tensor) -> None:
        self.px.write("rigid")

    set_angular_velocity = set_linear_velocity


class _Robot:
    """ManiSkill's Articulation on GPU: joint and drive-target setters write their buffers."""

    def __init__(self, px: _GpuPhysx) -> None:
        self.px = px

    def set_qpos(self, q: torch.Tensor) -> None:
        self.px.write("qpos")

    def set_qvel(self, qd: torch.Tensor) -> None:
        self.px.write("qvel")

    def set_joint_drive_targets(self, targets: torch.Tensor, joints: list) -> None:
        self.px.write("target_qpos")

    def set_joint_drive_velocity_targets(self, targets: torch.Tensor, joints: list) -> None:
        self.px.write("target_qvel")


def _recorded_backend() -> tuple[GpuBackend, _GpuPhysx]:
    """A ``GpuBackend`` wired to the recording PhysX and ManiSkill's own apply-all/fetch-all."""
    px = _GpuPhysx()
    cube, robot = _Cube(px), _Robot(px)
    scene = SimpleNamespace(px=px, _needs_fetch=False, non_static_actors=[cube], articulations={"robot": robot})
    scene._gpu_apply_all = MethodType(ManiSkillScene._gpu_apply_all, scene)
    scene._gpu_fetch_all = MethodType(ManiSkillScene._gpu_fetch_all, scene)
    b = object.__new__(GpuBackend)  # everything but building a PhysX GPU env
    b.n_envs, b.device, b.u = N, torch.device("cpu"), SimpleNamespace(scene=scene)
    b._robot, b._objects, b._base_j, b._arm_j, b._finger_j = robot, [cube], [], [], []
    return b, px


def test_every_gpu_write_is_applied_before_the_next_step_or_fetch() -> None:
    b, px = _recorded_backend()
    z = torch.zeros(N, 8)
    b.apply_targets(torch.zeros(N, 3), z, z, torch.zeros(N), torch.zeros(N, dtype=torch.bool))
    b.step(3)
    b.push_object(0, 1, (0.2, 0.0, 0.0))
    b.step(3)
    b.place_object(0, torch.ones(N, 3))
    b.step(3)
    b.set_state(torch.zeros(N, 15), torch.zeros(N, 1, 7))
    assert px.problems == [], "\n".join(px.problems + ["log:"] + px.log)
    log = px.log
    last = len(log) - 1 - log[::-1].index("write qpos")  # set_state: apply, then kinematics, then fetch
    after = log[last:]
    assert after.index("apply qpos") < after.index("update kinematics") < after.index("fetch articulation_link_pose")


def test_the_recorder_catches_a_lost_write_and_stale_link_poses() -> None:
    # what the backend did before the fix: a cube write with no apply before the step, and a
    # restore of joints with apply-all and fetch-all only (ManiSkill's reset updates kinematics)
    b, px = _recorded_backend()
    b._objects[0].set_linear_velocity(torch.zeros(N, 3))
    px.step()
    b._robot.set_qpos(torch.zeros(N, 15))
    b.u.scene._gpu_apply_all()
    b.u.scene._gpu_fetch_all()
    assert px.problems == ["rigid written, not applied before a step: the write is lost",
                           "link poses fetched after new joints without gpu_update_articulation_kinematics"]


# ------------------------------------------------------------------ the PhysX GPU library

def _an_elf_library() -> Path:
    """A real ELF shared library of this environment (numpy's smallest extension module)."""
    libs = sorted(Path(numpy.__file__).parent.rglob("*.so"), key=lambda p: p.stat().st_size)
    assert libs, "no ELF shared library found in numpy"
    return libs[0]


@pytest.fixture
def home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("HOME", str(tmp_path))
    return tmp_path


def test_library_location_is_sapiens(home: Path) -> None:
    loc = physx_gpu.library_location()
    if loc is None:
        pytest.skip("the library is checked on Linux only")
    path, url = loc
    version = physx_gpu.physx_version()
    assert path == home / ".sapien" / "physx" / version / "libPhysXGpu_64.so"
    assert url.startswith(f"https://github.com/sapien-sim/physx-precompiled/releases/download/{version}/")


def test_missing_partial_and_whole_library(tmp_path: Path) -> None:
    lib = tmp_path / "libPhysXGpu_64.so"
    assert physx_gpu.library_problem(lib) == "is missing"
    whole = _an_elf_library().read_bytes()
    lib.write_bytes(whole)
    assert physx_gpu.library_problem(lib) is None
    for size in (len(whole) - 1, len(whole) // 2, 200):
        lib.write_bytes(whole[:size])
        problem = physx_gpu.library_problem(lib)
        assert problem is not None and problem.startswith(f"is truncated ({size} bytes"), (size, problem)
    lib.write_bytes(b"<html>rate limited</html>" * 10)
    assert physx_gpu.library_problem(lib).startswith("is not an ELF library")


def test_check_library_fails_in_one_line_naming_file_and_url(home: Path) -> None:
    if physx_gpu.library_location() is None:
        pytest.skip("the library is checked on Linux only")
    with pytest.raises(ConfigError) as e:
        physx_gpu.check_library()
    msg = str(e.value)
    assert "\n" not in msg and "libPhysXGpu_64.so, which is missing" in msg and str(home) in msg
    assert "github.com/sapien-sim/physx-precompiled" in msg


def _serve(body: bytes):
    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 - http.server's name
            self.send_response(200)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}/linux-so.zip"


def _zip_of(data: bytes) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("libPhysXGpu_64.so", data)
    return buf.getvalue()


def test_fetch_installs_a_whole_library_and_refuses_a_partial_one(tmp_path: Path) -> None:
    whole = _an_elf_library().read_bytes()
    dest = tmp_path / "physx" / "v" / "libPhysXGpu_64.so"
    server, url = _serve(_zip_of(whole[: len(whole) // 2]))
    try:
        with pytest.raises(ConfigError, match="is truncated"):
            physx_gpu.fetch_library(10, url=url, dest=dest)
    finally:
        server.shutdown()
    assert not dest.exists() and list(dest.parent.iterdir()) == []  # nothing half-written left behind
    server, url = _serve(_zip_of(whole))
    try:
        assert physx_gpu.fetch_library(10, url=url, dest=dest) == dest
    finally:
        server.shutdown()
    assert dest.read_bytes() == whole and physx_gpu.library_problem(dest) is None


def test_fetch_without_network_fails_in_one_line(tmp_path: Path) -> None:
    t0 = time.monotonic()
    with pytest.raises(ConfigError, match="could not fetch the PhysX GPU library") as e:
        physx_gpu.fetch_library(5, url="http://127.0.0.1:9/linux-so.zip", dest=tmp_path / "libPhysXGpu_64.so")
    assert "\n" not in str(e.value) and time.monotonic() - t0 < 5


@pytest.mark.slow  # a realize process (15 s on a busy 2-core host): make test keeps the message
# (test_check_library_fails_in_one_line_naming_file_and_url) and the command's one line, exit 2
# (tests/test_app.py, test_cli_bad_input_exit_code_and_one_line)
def test_realize_device_cuda_without_the_library_exits_in_one_line(tmp_path: Path) -> None:
    """``realize device=cuda``, CUDA mocked as available, HOME an empty folder, no network used."""
    home = tmp_path / "home"
    home.mkdir()
    driver = ("import realize, sys, torch; torch.cuda.is_available = lambda: True\n"  # realize first, as the CLI
              "from realize.cli.main import main; main(sys.argv[1:])\n")
    p = subprocess.run([sys.executable, "-c", driver, "device=cuda", f"hydra.run.dir={tmp_path / 'run'}"],
                       cwd=REPO, capture_output=True, text=True, timeout=60,
                       env={"HOME": str(home), "PATH": "/usr/bin:/bin", "PYTHONPATH": str(REPO)})
    lines = [ln for ln in (p.stdout + p.stderr).splitlines() if ln.strip()]
    assert p.returncode == 2 and len(lines) == 1, (p.returncode, lines)
    assert lines[0].startswith("error: device = 'cuda': sim.backend = 'gpu' needs SAPIEN's PhysX GPU library")
    assert str(home) in lines[0] and "libPhysXGpu_64.so" in lines[0] and "github.com/sapien-sim" in lines[0]
    # (no time bound here: the 60 s timeout catches a hang, and a loaded 2-core host took 11 s)


# ------------------------------------------------------------------ device: auto and cuda (#27 item 5)

def test_auto_picks_the_cpu_where_torch_reports_cuda(monkeypatch: pytest.MonkeyPatch) -> None:
    from realize.search.ce.config import CEConfig
    from realize.spec.run_spec import resolve_placement
    from realize.scene.settings import SimSettings

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert backends.resolve_backend("auto") == "cpu"
    sim = SimSettings()
    placement = resolve_placement("auto", sim, CEConfig())
    assert placement.backend == "cpu" and placement.device == torch.device("cpu") and sim.backend == "cpu"


def test_cuda_is_an_explicit_choice_that_warns_once(home: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(backends, "_warned", False)
    loc = physx_gpu.library_location()
    if loc is not None:  # the library where SAPIEN looks, whole
        loc[0].parent.mkdir(parents=True)
        shutil.copyfile(_an_elf_library(), loc[0])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert backends.resolve_backend("gpu") == "gpu"
        assert backends.resolve_backend("gpu") == "gpu"
    ours = [w for w in caught if issubclass(w.category, backends.UnverifiedBackendWarning)]
    assert len(ours) == 1 and "has not been verified on a GPU" in str(ours[0].message)


# ------------------------------------------------------------------ the task's PhysX GPU settings

def test_gpu_contact_buffers_cover_maniskills_fetch_task_and_grow_with_the_copies() -> None:
    theirs = OpenCabinetDrawerEnv._default_sim_config.fget(None).gpu_memory_config  # ManiSkill's Fetch task
    for n in (1, 200, 3000, 30000):
        ours = gpu_memory_config(n)
        assert ours.max_rigid_contact_count >= max(theirs.max_rigid_contact_count, 512 * n)
        assert ours.max_rigid_patch_count >= max(theirs.max_rigid_patch_count, 128 * n)


@pytest.mark.parametrize("device", ["cpu", "cuda"])
def test_enhanced_determinism_only_on_the_cpu(device: str) -> None:
    env = SimpleNamespace(device=torch.device(device), num_envs=3000, geometry=build_geometry(GeometryCfg()),
                          _sim_settings=dict(sim_freq=60, control_freq=20,
                                             scene_config=dict(enable_enhanced_determinism=True)))
    cfg = RealizePickPlaceEnv._default_sim_config.fget(env)
    assert cfg.scene_config.enable_enhanced_determinism == (device == "cpu")
    assert cfg.gpu_memory_config.max_rigid_contact_count == gpu_memory_config(3000).max_rigid_contact_count


def test_no_render_backend_means_no_render_mode() -> None:
    import gymnasium as gym

    env = gym.make("RealizePickPlace-v1", obs_mode="none", render_mode="rgb_array", render_backend="none",
                   sim_backend="physx_cpu")
    try:
        assert env.unwrapped.render_mode is None and not env.unwrapped.scene.can_render()
    finally:
        env.close()
