"""URDFs as they come (issue 71): mesh files are found where SAPIEN's URDF loader finds them, by
every reader of the project, and a URDF the project cannot read is one line.

* ``package://`` names: the files ``realize.robot.urdf.mesh_file`` gives for every mesh of
  ManiSkill's Koch arm (``package://koch/meshes/...``, the files in the URDF's own folder) and of
  a small URDF whose ``package://pkg/meshes/box.stl`` lies two folders up are the files SAPIEN's
  loader reads (its parsed shapes' file names); relative names are read beside the URDF only.
* The readers: the link geometry of the Koch's fingers is the named files' triangles, placed
  by their origins (trimesh and its own Euler matrices, not ours); the recording's link meshes,
  the sphere fitting script and the grasp geometry of the Koch configured as its user did (a
  copy of ``configs/robot/so100.yaml``: ``tests/_koch.py``) read them.
* One ``ConfigError`` line, naming the file and what is missing: a mesh found nowhere (the
  filename as written and the places tried), a mesh file that is not a mesh, a URDF that is not
  XML, a joint without its child link, finger links or gripper joints the URDF lacks; through
  the robot config's check (``realize.robot.urdf_names.check_urdf_names``) each names the key.
* ``urdf_for_pytorch_kinematics`` fills only the ``effort`` and ``velocity`` a limit lacks.
"""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import pytorch_kinematics as pk
import trimesh

from _koch import FINGERS, KOCH_URDF, koch_spec
from helpers import load_script
from realize.config import ConfigError
from realize.recording.robot import link_meshes
from realize.robot.grip_geometry import grip_geometry
from realize.robot.link_geometry import collision_links, link_geometry
from realize.robot.urdf import mesh_file, parse_urdf_joints, source_urdf, urdf_for_pytorch_kinematics
from realize.robot.urdf_names import check_urdf_names

BOX = (0.1, 0.2, 0.3)  # m: the synthetic mesh's extents
OFFSET = (0.5, 0.0, 0.0)  # m: its collision origin

PKG_URDF = """<?xml version="1.0"?>
<robot name="pkg_robot">
  <link name="root"/>
  <link name="arm">
    <visual><geometry><mesh filename="../meshes/box.stl"/></geometry></visual>
    <collision>
      <origin xyz="0.5 0 0"/>
      <geometry><mesh filename="{collision}"/></geometry>
    </collision>
  </link>
  <joint name="hinge" type="revolute">
    <parent link="root"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1"/>
  </joint>
</robot>
"""


def _one_line(e: pytest.ExceptionInfo[ConfigError], *needles: str) -> str:
    text = str(e.value)
    assert "\n" not in text, text
    for n in needles:
        assert n in text, f"{n!r} not in {text!r}"
    return text


def _pkg_urdf(tmp_path: Path, collision: str = "package://pkg/meshes/box.stl") -> Path:
    """``ws/pkg/urdf/robot.urdf`` naming ``collision``; ``ws/pkg/meshes/box.stl`` a box of ``BOX``."""
    (tmp_path / "ws/pkg/meshes").mkdir(parents=True)
    (tmp_path / "ws/pkg/urdf").mkdir(parents=True)
    trimesh.creation.box(extents=BOX).export(tmp_path / "ws/pkg/meshes/box.stl")
    urdf = tmp_path / "ws/pkg/urdf/robot.urdf"
    urdf.write_text(PKG_URDF.format(collision=collision))
    return urdf


def _sapien_mesh_files(urdf: Path) -> dict[str, set[Path]]:
    """Per link, the mesh files SAPIEN's URDF loader reads (its parsed shapes' file names)."""
    import sapien

    arts, actors, _ = sapien.Scene().create_urdf_loader().parse(str(urdf))
    builders = [lb for a in arts for lb in a.link_builders] + list(actors)
    return {b.name: {Path(r.filename).resolve() for r in [*b.collision_records, *b.visual_records] if r.filename}
            for b in builders}


def _our_mesh_files(urdf: Path) -> dict[str, set[Path]]:
    root = ET.parse(urdf).getroot()
    return {lk.get("name", ""): {mesh_file(m.get("filename", ""), urdf).resolve() for m in lk.iter("mesh")}
            for lk in root.findall("link")}


def _koch_copy(tmp_path: Path) -> Path:
    """A copy of ManiSkill's Koch folder (URDF and meshes) to break; its URDF."""
    src = source_urdf(KOCH_URDF)
    shutil.copytree(src.parent, tmp_path / "koch")
    return tmp_path / "koch" / src.name


# ----------------------------------------------------------------------------- where mesh files are


def test_mesh_files_are_the_ones_sapien_reads(tmp_path: Path) -> None:
    koch = source_urdf(KOCH_URDF)
    assert "package://koch/meshes/" in koch.read_text()
    for urdf, files in ((koch, 30), (_pkg_urdf(tmp_path), 1)):  # the box: its visual and collision mesh
        ours, theirs = _our_mesh_files(urdf), _sapien_mesh_files(urdf)
        assert len(set().union(*ours.values())) >= files
        assert {k: v for k, v in ours.items() if v} == {k: v for k, v in theirs.items() if v}
    assert ours["arm"] == {(tmp_path / "ws/pkg/meshes/box.stl").resolve()}


def test_a_package_mesh_two_folders_up_is_read_by_every_reader(tmp_path: Path) -> None:
    urdf = _pkg_urdf(tmp_path)
    box = (tmp_path / "ws/pkg/meshes/box.stl").resolve()
    assert collision_links(urdf) == ["arm"]
    geo = link_geometry(urdf, "arm")
    half = np.asarray(BOX) / 2
    np.testing.assert_allclose(geo.bounds, [np.asarray(OFFSET) - half, np.asarray(OFFSET) + half], atol=1e-9)
    assert geo.area == pytest.approx(2 * (BOX[0] * BOX[1] + BOX[1] * BOX[2] + BOX[0] * BOX[2]))
    assert link_meshes(urdf)["arm"].path == box
    fit = load_script("fit_spheres")
    out = tmp_path / "spheres.yaml"
    assert fit.main(["--urdf", str(urdf), "--out", str(out), "--count", "arm=2", "--samples", "300"]) == 0
    assert out.is_file()


def test_the_koch_fingers_are_their_mesh_files_placed_by_their_origins() -> None:
    urdf = source_urdf(KOCH_URDF)
    meshes = urdf.parent / "meshes"
    # gripper: three collision parts, each at rpy (pi/2, 0, 0)
    turn = trimesh.transformations.euler_matrix(1.570796327, 0.0, 0.0, "sxyz")
    parts = [trimesh.load(meshes / f"gripper_collision_part_{i}.glb", force="mesh") for i in (1, 2, 3)]
    expected = trimesh.util.concatenate([p.copy().apply_transform(turn) for p in parts])
    geo = link_geometry(urdf, "gripper")
    assert len(geo.meshes) == 3
    np.testing.assert_allclose(np.sort(geo.vertices, axis=0), np.sort(np.asarray(expected.vertices), axis=0), atol=1e-9)
    assert {f for f in FINGERS} <= set(collision_links(urdf))


def test_the_koch_added_as_its_user_did_passes_the_config_check_and_measures_its_jaw() -> None:
    spec = koch_spec()
    check_urdf_names(spec)  # names, and the gripper: it reads the finger meshes
    geo = grip_geometry(spec)
    assert geo.joint_type == "revolute" and geo.unit == "rad" and geo.one_sided
    assert geo.width_closed < 0.005 < 0.03 < geo.width_open < 0.08  # m between the pads
    assert geo.widths[0] < geo.widths[len(geo.widths) // 2] < geo.widths[-1]  # the jaw opens as joint_6 grows
    assert set(FINGERS) <= set(link_meshes(source_urdf(KOCH_URDF)))


# ----------------------------------------------------------------------------- one line, not a traceback


def test_a_package_mesh_found_nowhere_names_the_urdf_the_name_and_the_places_tried(tmp_path: Path) -> None:
    urdf = _pkg_urdf(tmp_path, "package://pkg/meshes/nope.stl")
    above = len(urdf.parent.absolute().parents)
    with pytest.raises(ConfigError) as e:
        link_geometry(urdf, "arm")
    _one_line(e, f"URDF {urdf}", "'package://pkg/meshes/nope.stl' not found",
              f"tried pkg/meshes/nope.stl in {urdf.parent.absolute()} and in each of the {above} folders above it")


def test_a_relative_mesh_name_is_read_beside_the_urdf_only(tmp_path: Path) -> None:
    urdf = _pkg_urdf(tmp_path, "meshes/box.stl")  # the file is ../meshes/box.stl: as for SAPIEN, not found
    with pytest.raises(ConfigError) as e:
        link_geometry(urdf, "arm")
    _one_line(e, f"URDF {urdf}", "'meshes/box.stl' not found", f"tried {urdf.parent.absolute() / 'meshes/box.stl'})")


@pytest.mark.parametrize("name, data", [("box.stl", b"not a mesh at all"), ("box.glb", b"glTF?")])
def test_an_unreadable_mesh_is_one_line_naming_the_file(tmp_path: Path, name: str, data: bytes,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    urdf = _pkg_urdf(tmp_path, f"package://pkg/meshes/{name}")
    (tmp_path / "ws/pkg/meshes" / name).write_bytes(data)
    with pytest.raises(ConfigError) as e:
        link_geometry(urdf, "arm")
    _one_line(e, f"URDF {urdf}", f"'package://pkg/meshes/{name}'", "is not a readable mesh")
    fit = load_script("fit_spheres")
    assert fit.main(["--urdf", str(urdf), "--out", str(tmp_path / "s.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: URDF ") and "\n" not in err and "is not a readable mesh" in err


def test_a_broken_or_missing_finger_mesh_is_one_line_naming_the_key_and_the_file(tmp_path: Path) -> None:
    urdf = _koch_copy(tmp_path)
    part = urdf.parent / "meshes" / "gripper_collision_part_2.glb"
    part.write_bytes(b"\0" * 64)
    with pytest.raises(ConfigError) as e:
        check_urdf_names(koch_spec(str(urdf)))
    _one_line(e, "robot.gripper.finger_links = ['link_6', 'gripper']: ", f"URDF {urdf}",
              "'package://koch/meshes/gripper_collision_part_2.glb'", "is not a readable mesh")
    part.unlink()
    with pytest.raises(ConfigError) as e:
        check_urdf_names(koch_spec(str(urdf)))
    _one_line(e, "robot.gripper.finger_links", "'package://koch/meshes/gripper_collision_part_2.glb' not found",
              f"tried koch/meshes/gripper_collision_part_2.glb in {urdf.parent}")


@pytest.mark.parametrize("text, needle", [
    ("<robot name='r'><link name='a'></robot>", "not readable XML (mismatched tag: line 1"),
    ("<sdf version='1.6'><model name='m'/></sdf>", "its root element is <sdf>, not <robot>"),
    ("<robot name='r'><link name='a'/><joint name='j' type='fixed'><parent link='a'/></joint></robot>",
     "joint 'j': no <child link=...>"),
    ("<robot name='r'><link name='a'/><link name='b'/><joint name='j' type='revolute'><parent link='a'/>"
     "<child link='b'/><limit lower='-1' upper='one'/></joint></robot>", "joint 'j': could not convert"),
])
def test_a_urdf_that_cannot_be_read_is_one_line(tmp_path: Path, text: str, needle: str) -> None:
    urdf = tmp_path / "broken.urdf"
    urdf.write_text(text)
    with pytest.raises(ConfigError) as e:
        parse_urdf_joints(urdf)
    _one_line(e, f"URDF {urdf}: ", needle)
    with pytest.raises(ConfigError) as e:
        check_urdf_names(koch_spec(str(urdf)))
    _one_line(e, f"robot.urdf = '{urdf}': URDF {urdf}: ", needle)


def test_finger_links_the_urdf_lacks_are_one_line() -> None:
    spec = koch_spec(finger_links=["link_6", "jaw"])
    with pytest.raises(ConfigError) as e:
        check_urdf_names(spec)
    _one_line(e, "robot.gripper.finger_links: link 'jaw' is not in follower_arm_v1.1.urdf", "its links: ")
    with pytest.raises(ConfigError) as e:
        grip_geometry(spec)
    _one_line(e, "robot.gripper.finger_links: 'jaw' is not a link of follower_arm_v1.1.urdf")


def test_gripper_joints_the_urdf_lacks_are_one_line(tmp_path: Path) -> None:
    spec = koch_spec(joints=["joint_6", "joint_7"])  # a mimic the URDF lacks
    with pytest.raises(ConfigError) as e:
        check_urdf_names(spec)
    _one_line(e, "robot.gripper.joints: movable joint 'joint_7' is not in follower_arm_v1.1.urdf")
    with pytest.raises(ConfigError) as e:
        grip_geometry(spec)
    _one_line(e, "robot.gripper.joints: 'joint_7' is not a joint of follower_arm_v1.1.urdf")
    # a URDF with no gripper joint at all: the Koch's jaw made fixed
    urdf = _koch_copy(tmp_path)
    root = ET.parse(urdf).getroot()
    (jaw,) = [j for j in root.findall("joint") if j.get("name") == "joint_6"]
    jaw.set("type", "fixed")
    ET.ElementTree(root).write(urdf)
    with pytest.raises(ConfigError) as e:
        check_urdf_names(koch_spec(str(urdf)))
    _one_line(e, "robot.gripper.joints: movable joint 'joint_6' is not in follower_arm_v1.1.urdf",
              "; its movable joints: joint_1, joint_2, joint_3, joint_4, joint_5")


# ----------------------------------------------------------------------------- pytorch_kinematics


def test_urdf_for_pytorch_kinematics_fills_only_what_a_limit_lacks(tmp_path: Path) -> None:
    urdf = tmp_path / "limits.urdf"
    urdf.write_text(
        "<robot name='r'><link name='a'/><link name='b'/><link name='c'/><link name='d'/>"
        "<joint name='given' type='revolute'><parent link='a'/><child link='b'/>"
        "<limit lower='-1' upper='1' effort='5' velocity='2'/></joint>"
        "<joint name='bare' type='prismatic'><parent link='b'/><child link='c'/><limit lower='0' upper='0.3'/></joint>"
        "<joint name='fast' type='revolute'><parent link='c'/><child link='d'/><limit velocity='7'/></joint></robot>")
    with pytest.raises(Exception, match="effort|velocity"):
        pk.build_chain_from_urdf(urdf.read_bytes())
    out = urdf_for_pytorch_kinematics(urdf)
    limits = {j.get("name"): dict(j.find("limit").attrib) for j in ET.fromstring(out).findall("joint")}
    assert limits == {"given": {"lower": "-1", "upper": "1", "effort": "5", "velocity": "2"},
                      "bare": {"lower": "0", "upper": "0.3", "effort": "0", "velocity": "0"},
                      "fast": {"velocity": "7", "effort": "0"}}
    assert pk.build_chain_from_urdf(out).get_joint_parameter_names() == ["given", "bare", "fast"]
    assert parse_urdf_joints(urdf)["d"].velocity == 7.0  # our reader needs none of it
