"""SDF export (``scene.sdf``, SDFormat 1.9) read back by libsdformat, the SDFormat reference parser
(``scripts/sdf_check.cc`` compiled by the ``sdf_checker`` fixture), against the MJCF of the same
scene: the same masses, centres of mass, joints with their limits, damping and friction, the
input camera with its intrinsics and pose, the static room; surface friction per collision; a
broken file is rejected by both the structural check and libsdformat. The same checks on scenes
the pipeline builds are in ``test_built_scenes.py``."""

from __future__ import annotations

import dataclasses
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from exporters import write_mjcf
from exporters.sdf import CHECKER_ENV, run_checker, structural_problems, validate_sdf, write_sdf
from scene_builder.errors import ExportError
from scene_builder.model import JointType, Scene
from tests.fixtures_scenes import bounded_walls_scene, boxes_scene, cabinet_scene, mixed_scene, pillow_scene


def _revolute_prismatic_scene() -> Scene:
    """The cabinet with its door on a revolute-prismatic joint (hinge that also slides)."""
    base = cabinet_scene()
    cab = base.objects[0].asset
    door = next(p for p in cab.parts if p.name == "door")
    joint = dataclasses.replace(door.joint, type=JointType.REVOLUTE_PRISMATIC, lower2=0.0, upper2=0.05)
    parts = tuple(dataclasses.replace(p, joint=joint) if p.name == "door" else p for p in cab.parts)
    placed = dataclasses.replace(base.objects[0], asset=dataclasses.replace(cab, parts=parts))
    return Scene(base.camera, base.room, (placed,))


SCENES = {
    "boxes": boxes_scene,
    "cabinet": cabinet_scene,
    "fixed_cabinet": lambda: cabinet_scene(is_fixed=True),
    "mixed": mixed_scene,
    "pillow": pillow_scene,
    "bounded_walls": bounded_walls_scene,
    "revolute_prismatic": _revolute_prismatic_scene,
}


@pytest.fixture(params=sorted(SCENES))
def written(request, tmp_path, sdf_checker, monkeypatch):
    """(scene, scene.sdf, libsdformat's report, MuJoCo model of scene.xml) for one fixture scene;
    write_sdf itself validates with libsdformat (the checker named in the environment)."""
    import mujoco

    monkeypatch.setenv(CHECKER_ENV, sdf_checker[0])
    scene = SCENES[request.param]()
    mjcf = write_mjcf(scene, tmp_path)
    path = write_sdf(scene, tmp_path)
    return scene, path, run_checker(path, sdf_checker), mujoco.MjModel.from_xml_path(str(mjcf))


def test_libsdformat_reads_the_mjcf_masses_centres_and_joints(written):
    import mujoco

    scene, path, report, model = written
    assert report["version"] == "1.9" and report["gravity"] == [0, 0, -9.81]
    models = {m["name"]: m for m in report["models"]}
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    n_hinge = n_slide = 0
    for placed in scene.objects:
        asset = placed.asset
        m = models[placed.name]
        links = {link["name"]: link for link in m["links"]}
        if asset.deformable is not None:  # a flex in MuJoCo, its rigid shape in SDF
            assert sum(link["mass"] for link in m["links"]) == pytest.approx(asset.mass_kg, rel=1e-9)
            continue
        for part in asset.parts:
            body = model.body(asset.name if part.parent is None else f"{asset.name}/{part.name}")
            assert links[part.name]["mass"] == pytest.approx(model.body_mass[body.id], rel=1e-7)
            np.testing.assert_allclose(links[part.name]["com"], data.xipos[body.id], atol=1e-7)
            assert links[part.name]["inertia_valid"]
            assert links[part.name]["collisions"] == len(part.collision) and links[part.name]["visuals"] == 1
        joints = {j["name"]: j for j in m["joints"]}
        moving = any(p.joint is not None and p.joint.type is not JointType.FIXED for p in asset.parts)
        # Free objects: no joint to the world; fixed furniture: static, or welded when it has moving parts.
        welded = [j for j in m["joints"] if j["parent"] == "world"]
        assert m["static"] == (asset.is_fixed and not moving)
        assert len(welded) == (1 if asset.is_fixed and moving else 0) and all(j["type"] == "fixed" for j in welded)
        for part in asset.parts:
            if part.joint is None or part.joint.type is JointType.FIXED:
                continue
            for suffix, kind in (("", "revolute" if part.joint.type is not JointType.PRISMATIC else "prismatic"),
                                 ("_slide", "prismatic")):
                mj_name = f"{asset.name}/{part.name}/joint{suffix}"
                if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, mj_name) < 0:
                    continue
                mj, sdf = model.joint(mj_name), joints[f"{part.name}{suffix}_joint"]
                assert sdf["type"] == kind
                np.testing.assert_allclose([sdf["lower"], sdf["upper"]], mj.range, atol=1e-9)
                assert sdf["damping"] == pytest.approx(model.dof_damping[mj.dofadr[0]])
                assert sdf["friction"] == pytest.approx(model.dof_frictionloss[mj.dofadr[0]])
                assert sdf["effort"] == pytest.approx(part.joint.effort_limit)
                n_hinge += kind == "revolute"
                n_slide += kind == "prismatic"
    # Every articulation joint of the MJCF (its flex nodes' slide joints are unnamed) is in the SDF.
    named = [i for i in range(model.njnt) if model.joint(i).name]
    assert n_hinge == sum(model.jnt_type[i] == mujoco.mjtJoint.mjJNT_HINGE for i in named)
    assert n_slide == sum(model.jnt_type[i] == mujoco.mjtJoint.mjJNT_SLIDE for i in named)
    n_free = sum(1 for o in scene.objects if not o.asset.is_fixed and o.asset.deformable is None)
    assert n_free == sum(model.jnt_type[i] == mujoco.mjtJoint.mjJNT_FREE for i in named)
    # The room: static, the floor and one collision plane per wall.
    assert models["room"]["static"] and models["room"]["links"][0]["collisions"] == 1 + len(scene.room.walls)


def test_camera_sensor_is_the_input_camera(written):
    import mujoco
    from scipy.spatial.transform import Rotation

    scene, path, report, model = written
    k = scene.camera.intrinsics
    (cam,) = [c for m in report["models"] for link in m["links"] for c in link["cameras"]]
    assert (cam["width"], cam["height"]) == (k.width_px, k.height_px)
    assert cam["horizontal_fov"] == pytest.approx(2 * np.arctan(k.width_px / 2 / k.fx_px), rel=1e-8)
    assert (cam["fx"], cam["fy"]) == pytest.approx((k.fx_px, k.fy_px))
    # Gazebo's pixel corners are integers: OpenCV's centred (W - 1) / 2 is its W / 2.
    assert (cam["cx"], cam["cy"]) == pytest.approx((k.cx_px + 0.5, k.cy_px + 0.5))
    # SDFormat cameras look along +X with +Z up; MuJoCo's along -Z with +Y up: the same view.
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    pose = ET.parse(path).getroot().find("world/model[@name='input_camera']/pose").text.split()
    r = Rotation.from_euler("xyz", [float(v) for v in pose[3:]]).as_matrix()
    mj = model.camera("input_camera").id
    mj_r = data.cam_xmat[mj].reshape(3, 3)
    np.testing.assert_allclose(r[:, 0], -mj_r[:, 2], atol=1e-8)
    np.testing.assert_allclose(r[:, 2], mj_r[:, 1], atol=1e-8)
    np.testing.assert_allclose([float(v) for v in pose[:3]], data.cam_xpos[mj], atol=1e-8)


def test_collision_surfaces_carry_the_material(written):
    scene, path, _, _ = written
    root = ET.parse(path).getroot()
    for placed in scene.objects:
        for part in placed.asset.parts:
            link = root.find(f"world/model[@name='{placed.name}']/link[@name='{part.name}']")
            cols = link.findall("collision")
            assert len(cols) == len(part.collision)
            for col in cols:
                f = col.find("surface/friction")
                mu = part.material.dynamic_friction
                assert float(f.findtext("ode/mu")) == pytest.approx(mu) and float(f.findtext("bullet/friction")) == pytest.approx(mu)
                assert float(f.findtext("torsional/patch_radius")) > 0
                assert float(col.findtext("surface/bounce/restitution_coefficient")) == pytest.approx(part.material.restitution)
                assert (path.parent / col.findtext("geometry/mesh/uri")).is_file()


def test_a_broken_sdf_is_rejected(tmp_path, sdf_checker):
    scene = mixed_scene()
    path = write_sdf(scene, tmp_path)
    text = path.read_text()
    assert structural_problems(path) == []
    validate_sdf(path, scene, sdf_checker)  # the unbroken file passes

    def broken(name: str, new: str):
        p = tmp_path / name
        p.write_text(new)
        return p

    # An element SDFormat does not define: libsdformat refuses it (the structural check does not look).
    unknown = broken("unknown.sdf", text.replace("<mass>", "<weight>1</weight><mass>", 1))
    with pytest.raises(ExportError, match="libsdformat rejects"):
        run_checker(unknown, sdf_checker)
    # A joint to a link that does not exist: both refuse it.
    dangling = broken("dangling.sdf", text.replace("<child>door</child>", "<child>lid</child>", 1))
    assert any("lid" in p for p in structural_problems(dangling))
    with pytest.raises(ExportError, match="libsdformat rejects"):
        run_checker(dangling, sdf_checker)
    # Not SDFormat 1.9 or later.
    old = broken("old.sdf", text.replace('version="1.9"', 'version="1.6"', 1))
    assert any("version" in p for p in structural_problems(old))
    # A mesh that is not there, or outside the folder.
    missing = broken("missing.sdf", text.replace("meshes/box_a__body__visual.obj", "meshes/nothing.obj", 1))
    assert any("nothing.obj" in p for p in structural_problems(missing))
    outside = broken("outside.sdf", text.replace("meshes/box_a__body__visual.obj", "../../etc/passwd", 1))
    assert any("passwd" in p for p in structural_problems(outside))
    # Masses that differ from the scene's, and a mass matrix no body can have.
    heavier = broken("heavier.sdf", re.sub(r"<mass>([0-9.e+-]+)</mass>", "<mass>99</mass>", text, count=1))
    with pytest.raises(ExportError, match="kg"):
        validate_sdf(heavier, scene, sdf_checker)
    impossible = broken("impossible.sdf", re.sub(r"<ixx>[^<]+</ixx>", "<ixx>1000</ixx>", text, count=1))
    with pytest.raises(ExportError, match="invalid inertia"):  # libsdformat checks the triangle inequality
        validate_sdf(impossible, scene, sdf_checker)


def test_without_a_checker_the_structural_check_still_runs(tmp_path, monkeypatch):
    import exporters.sdf as sdf

    monkeypatch.setattr(sdf, "find_checker", lambda: None)
    scene = cabinet_scene()
    path = write_sdf(scene, tmp_path)
    assert validate_sdf(path, scene) is None  # no libsdformat report, but no error either
    (tmp_path / "meshes" / "cabinet__door__visual.obj").unlink()
    with pytest.raises(ExportError, match="cabinet__door__visual.obj"):
        validate_sdf(path, scene)


@pytest.mark.parametrize("name", ["panda", "mobile_panda"])
def test_the_robot_is_a_model_that_libsdformat_reads_as_mujoco_compiles_it(name, tmp_path, sdf_checker, monkeypatch):
    """--robot in scene.sdf: model ``robot`` with a link per MuJoCo body (its mass and, over
    all links, the centre of mass at the placement as MuJoCo computes it: validate_sdf checks
    both through libsdformat), the arm's revolute joints with Franka's limits, the fingers
    prismatic, the base welded to the world (panda) or on prismatic x, y and revolute yaw joints
    through two 1 g links (mobile_panda), and a position controller per driven joint. A robot
    link moved or made heavier is caught."""
    import mujoco

    from exporters.robot import compiled_robot
    from generation.robot import load_robot
    from layout.robot import place_robot

    monkeypatch.setenv(CHECKER_ENV, sdf_checker[0])
    model = load_robot(name, tmp_path / "model", source="built-in")
    scene = dataclasses.replace(boxes_scene(), robot=place_robot(boxes_scene(), model)[0])
    path = write_sdf(scene, tmp_path)
    report = validate_sdf(path, scene, sdf_checker)
    robot = next(m for m in report["models"] if m["name"] == "robot")
    m, _ = compiled_robot(scene.robot, "SDF")
    joints = {j["name"]: j for j in robot["joints"]}
    arm = [joints[f"joint{k}"] for k in range(1, 8)]
    assert all(j["type"] == "revolute" for j in arm)
    assert [round(j["upper"], 4) for j in arm] == [round(float(m.joint(f"joint{k}").range[1]), 4) for k in range(1, 8)]
    assert joints["finger_joint1"]["type"] == joints["finger_joint2"]["type"] == "prismatic"
    welded = sum(int(m.body_jntnum[b]) == 0 for b in range(1, m.nbody))  # the hand; the Panda's link0
    assert sum(j["type"] == "fixed" for j in robot["joints"]) == welded
    if name == "panda":
        assert len(robot["links"]) == m.nbody - 1
        assert any(j["parent"] == "world" and j["type"] == "fixed" for j in robot["joints"])
    else:
        assert len(robot["links"]) == m.nbody - 1 + 2
        base = [j for j in robot["joints"] if j["name"].startswith("base_")]
        assert sorted(j["type"] for j in base) == ["prismatic", "prismatic", "revolute"] and base[0]["parent"] == "world"
    root = ET.parse(path).getroot()
    controllers = [p for p in root.iter("plugin") if p.get("filename") == "gz-sim-joint-position-controller-system"]
    assert len(controllers) == sum(int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT) for a in range(m.nu)) + 1  # + the coupled finger
    text = path.read_text()
    link0 = re.search(r'<link name="link0">\s*<pose>([^<]+)</pose>', text)
    moved = tmp_path / "moved.sdf"
    x = link0.group(1).split()
    moved.write_text(text.replace(link0.group(0), link0.group(0).replace(link0.group(1), " ".join([str(float(x[0]) + 0.1)] + x[1:]))))
    with pytest.raises(ExportError, match="centre of mass"):
        validate_sdf(moved, scene, sdf_checker)
    heavier = tmp_path / "heavier.sdf"
    start = text.index('<model name="robot">')
    heavier.write_text(text[:start] + re.sub(r"<mass>([0-9.e+-]+)</mass>", "<mass>99</mass>", text[start:], count=1))
    with pytest.raises(ExportError, match="kg of robot"):
        validate_sdf(heavier, scene, sdf_checker)


def test_a_bounded_wall_is_the_same_box_slab_in_sdf_and_mjcf(tmp_path):
    """A wall seen over a bounded span is a box behind its face in both formats, at the same pose
    and size (an infinite plane would push what stands past its end into the room)."""
    import mujoco

    scene = bounded_walls_scene()
    model = mujoco.MjModel.from_xml_path(str(write_mjcf(scene, tmp_path)))
    root = ET.parse(write_sdf(scene, tmp_path)).getroot()
    for i, wall in enumerate(scene.room.walls):
        col = root.find(f".//model[@name='room']/link[@name='room']/collision[@name='wall_{i}']")
        g = model.geom(f"wall_{i}")
        if not wall.bounded:
            assert col.find("geometry/plane") is not None and g.type[0] == mujoco.mjtGeom.mjGEOM_PLANE
            continue
        assert g.type[0] == mujoco.mjtGeom.mjGEOM_BOX
        size = np.array(col.find("geometry/box/size").text.split(), dtype=float)
        np.testing.assert_allclose(size, 2.0 * g.size, atol=1e-6)
        pose_ = np.array(col.find("pose").text.split(), dtype=float)
        np.testing.assert_allclose(pose_[:3], g.pos, atol=1e-6)
        yaw = 2.0 * np.arctan2(g.quat[3], g.quat[0])
        assert np.cos(pose_[5] - yaw) == pytest.approx(1.0, abs=1e-9)
        # Its room-side face lies on the wall's plane.
        centre, _, half = wall.slab()
        assert float(wall.signed_distance_m(centre[None])[0]) == pytest.approx(-half[1])


def test_export_scene_checks_the_sdf_on_its_thread_and_reports_its_error(tmp_path, sdf_checker, monkeypatch):
    """export_scene writes the SDF on a second thread beside the URDFs and glTF: the files are
    the ones write_sdf alone writes, byte for byte, every other format is there, and a checker's
    rejection reaches the caller as the ExportError it is (not lost on the thread)."""
    import exporters.sdf as sdf
    from exporters import export_scene
    from scene_builder.config import ExportConfig

    scene = mixed_scene()
    config = ExportConfig(viz="off", scene_urdf=True)
    files = export_scene(scene, tmp_path / "all", config)
    alone = write_sdf(scene, tmp_path / "alone")
    assert files.sdf.read_bytes() == alone.read_bytes()
    for name in ("scene.xml", "scene.usda", "scene.urdf", "scene.glb"):
        assert (tmp_path / "all" / name).is_file(), name
    assert sorted(p.name for p in (tmp_path / "all" / "meshes").iterdir()) == sorted(p.name for p in (tmp_path / "alone" / "meshes").iterdir())

    def rejects(path, command=None):
        raise ExportError(f"libsdformat rejects {path.name}: made up for the test")

    monkeypatch.setattr(sdf, "run_checker", rejects)
    with pytest.raises(ExportError, match="made up for the test"):
        export_scene(scene, tmp_path / "again", config)
