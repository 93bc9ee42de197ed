"""``--robot``: the robot models (built-in and through MuJoCo Menagerie's downloader), their
placement, MJCF and USD export, and the scripted reach in MuJoCo (issue 15, items 1, 3c and 5).

Fast tests run on the hand-made fixture scenes; the slow ones build the real RGB-D samples
with ``--robot`` and drive the arm there.
"""

from __future__ import annotations

import dataclasses
import hashlib
import http.server
import json
import sys
import tarfile
import threading
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import real_samples
from tests.fixtures_scenes import WOOD, box_asset, boxes_scene, fixture_camera, fixture_room, mixed_scene, pose

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples"))

import robot_reach  # noqa: E402  (examples/robot_reach.py: the scripted controller)

REACH_TOL_M = 0.02


def _robot(name: str, tmp_path: Path):
    from generation.robot import load_robot

    return load_robot(name, tmp_path / f"{name}_model", source="built-in")


def _write_scene(scene, out: Path) -> Path:
    """scene.xml and the robot part of report.json, as a build writes them."""
    from exporters.mjcf import write_mjcf
    from scene_builder.report import robot_report

    path = write_mjcf(scene, out)
    (out / "report.json").write_text(json.dumps({"robot": robot_report(scene)}))
    return path


# --------------------------------------------------------------------------------------------
# The models


@pytest.mark.parametrize("name", ["panda", "mobile_panda"])
def test_builtin_panda_kinematics_and_limits_are_franka_published(name, tmp_path):
    """The built-in Panda at Franka's ready pose puts its flange where Franka's DH table does
    (x 0.307 m, z 0.590 m above link0), its joints carry Franka's limits, and every actuator
    and sensor the robot model declares is there."""
    import mujoco

    model = _robot(name, tmp_path)
    m = mujoco.MjModel.from_xml_path(str(model.mjcf_path))
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    mujoco.mj_forward(m, d)
    flange = d.xpos[m.body("hand").id] - d.xpos[m.body("link0").id]
    np.testing.assert_allclose(flange, [0.3069, 0.0, 0.5903], atol=2e-3)
    assert np.degrees(m.joint("joint4").range).round(1).tolist() == [-176.0, -4.0]
    assert m.nu == 8 + 3 * model.mobile and m.actuator("actuator1").forcerange.tolist() == [-87.0, 87.0]
    assert {m.sensor(s).name for s in range(m.nsensor)} >= {"joint1_pos", "joint7_vel", "tcp_pos"}
    assert model.source == "built-in" and model.arm_joints == tuple(f"joint{i}" for i in range(1, 8))
    assert model.base_joints == (("base_x", "base_y", "base_yaw") if model.mobile else ())
    # Franka's published maximum reach is 855 mm to the flange; the tool centre point is 10 cm on.
    assert 0.85 < model.reach_m < 0.97
    from generation.robot_builtin import PANDA_MASS_KG

    # Each link's published mass spread over its solids; inertia integrated over them by MuJoCo.
    assert m.body_subtreemass[m.body("link0").id] == pytest.approx(sum(PANDA_MASS_KG) + 2 * 0.015, abs=1e-4)
    assert m.body_mass[m.body("link4").id] == pytest.approx(PANDA_MASS_KG[4], abs=1e-4)
    assert (m.body_inertia[m.body("link4").id] > 1e-3).all()


def _serve(folder: Path):
    """An HTTP server on 127.0.0.1 serving ``folder``; returns (server, base url)."""

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def __init__(self, *a, **k):
            super().__init__(*a, directory=str(folder), **k)

        def log_message(self, *a):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}"


def _menagerie_archive(tmp_path: Path, registry_name: str, oid: str) -> tuple[Path, Path]:
    """A model directory in Menagerie's layout (``panda.xml`` with its meshes under ``assets/``)
    packed as Menagerie packs its release assets (``<name>/...`` in a .tar.xz). The MJCF is the
    built-in Panda's plus a mesh on link0, so the test exercises copying Menagerie's files."""
    from generation.robot_builtin import build_panda
    import mujoco

    src = tmp_path / "src" / registry_name
    (src / "assets").mkdir(parents=True)
    (src / "assets" / "base.obj").write_text(
        "v -0.05 -0.05 0.01\nv 0.05 -0.05 0.01\nv 0 0.05 0.01\nv 0 0 0.06\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 3 1 4\n"
    )
    spec = build_panda()
    spec.modelfiledir = str(src)
    spec.meshdir = "assets"
    spec.add_mesh(name="base", file="base.obj")
    spec.body("link0").add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname="base", contype=0, conaffinity=0, group=2)
    # Menagerie's panda.xml has no tool site: the loader adds it.
    for sensor in [s for s in spec.sensors if s.name.startswith("tcp")]:
        spec.delete(sensor)
    spec.delete(spec.site("tcp"))
    (src / "panda.xml").write_text(spec.to_xml())
    archive = tmp_path / "assets" / f"{registry_name}-{oid[:16]}.tar.xz"
    archive.parent.mkdir()
    with tarfile.open(archive, "w:xz") as tf:
        tf.add(src, arcname=registry_name)
    return src, archive


def test_menagerie_download_is_checked_cached_and_attached(tmp_path, monkeypatch):
    """The Menagerie path as a networked user runs it, against a local server: the registry entry
    names the archive and its SHA-256, the package downloads and verifies it into its cache, the
    loader measures the model, and the export copies its mesh files beside the scene. A second
    load uses the cache (the server is gone); an archive whose checksum does not match is
    refused and the built-in model answers, saying why."""
    import mujoco_menagerie
    from mujoco_menagerie import Cache, Registry, Robot

    from generation import robot as robot_mod
    from layout.robot import place_robot

    oid = "ab" * 20
    _, archive = _menagerie_archive(tmp_path, "franka_emika_panda", oid)
    data = archive.read_bytes()
    real = mujoco_menagerie.get("franka_emika_panda")
    local = dataclasses.replace(real, oid=oid, asset=archive.name, sha256=hashlib.sha256(data).hexdigest(), download_size=len(data))
    registry = Registry(commit="0" * 40, robots={"franka_emika_panda": local})
    monkeypatch.setattr(mujoco_menagerie, "get", registry.get)
    server, url = _serve(archive.parent)
    cache = Cache(dir=tmp_path / "cache", base_url=url)
    try:
        model = robot_mod.load_robot("panda", tmp_path / "work", cache=cache)
    finally:
        server.shutdown()
    assert model.source == "menagerie" and "franka_emika_panda" in model.detail and "Apache-2.0" in model.detail
    assert cache.is_cached(local) and (cache.model_path(local) / "panda.xml").is_file()
    assert str(cache.model_path(local)) in model.mjcf_path.read_text()  # its meshes are read from the cache
    again = robot_mod.load_robot("panda", tmp_path / "work2", cache=cache)  # no server now: from the cache
    assert again.source == "menagerie" and again.reach_m == pytest.approx(model.reach_m)

    scene = dataclasses.replace(boxes_scene(), robot=place_robot(boxes_scene(), model)[0])
    out = tmp_path / "out"
    path = _write_scene(scene, out)
    assert (out / "meshes" / "robot" / "base.obj").is_file()
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(path))
    assert m.mesh("robot/base").id >= 0 and m.site("robot/tcp").id >= 0

    bad = dataclasses.replace(local, sha256="0" * 64, oid="cd" * 20, asset=archive.name)
    monkeypatch.setattr(mujoco_menagerie, "get", Registry(commit="0" * 40, robots={"franka_emika_panda": bad}).get)
    server, url = _serve(archive.parent)
    try:
        fallback = robot_mod.load_robot("panda", tmp_path / "work3", cache=Cache(dir=tmp_path / "cache2", base_url=url))
    finally:
        server.shutdown()
    assert fallback.source == "built-in" and "does not match the digest" in fallback.detail


def test_menagerie_root_checkout_answers_and_menagerie_only_names_fail_in_one_line(tmp_path, monkeypatch):
    """MENAGERIE_ROOT pointing at a checkout in Menagerie's layout answers without any download;
    a Menagerie-only robot asked for offline without a cache fails with one actionable line."""
    from generation.robot import load_robot
    from scene_builder.errors import InputError, ModelUnavailableError

    src, _ = _menagerie_archive(tmp_path, "franka_emika_panda", "ef" * 20)
    monkeypatch.setenv("MENAGERIE_ROOT", str(src.parent))
    model = load_robot("panda", tmp_path / "work", offline=True)
    assert model.source == "menagerie" and str(src / "assets") in model.mjcf_path.read_text()
    monkeypatch.delenv("MENAGERIE_ROOT")
    monkeypatch.setenv("MENAGERIE_CACHE_DIR", str(tmp_path / "empty_cache"))
    with pytest.raises(ModelUnavailableError) as err:
        load_robot("tidybot", tmp_path / "work", offline=True)
    assert "\n" not in str(err.value) and "MENAGERIE_ROOT" in str(err.value)
    with pytest.raises(InputError, match="unknown robot 'r2d2'; choose one of mobile_panda, panda, tidybot"):
        load_robot("r2d2", tmp_path)
    with pytest.raises(InputError, match="no built-in model"):
        load_robot("tidybot", tmp_path, source="built-in")


# --------------------------------------------------------------------------------------------
# Placement and export


@pytest.mark.parametrize("name", ["panda", "mobile_panda"])
@pytest.mark.parametrize("make", [boxes_scene, mixed_scene])
def test_placement_is_free_inside_the_room_and_faces_a_reachable_top(name, make, tmp_path):
    """On the fixture rooms the robot stands inside the walls, overlaps nothing in MuJoCo (home
    and start pose, every pair measured), faces its target (yaw within 1 degree), and the target
    lies above a support top within the arm's reach."""
    import mujoco

    from layout.reach import check_reach, robot_overlaps
    from layout.robot import place_robot

    model = _robot(name, tmp_path)
    scene0 = make()
    placement = place_robot(scene0, model)[0]
    scene = dataclasses.replace(scene0, robot=placement)
    path = _write_scene(scene, tmp_path / "out")
    assert robot_overlaps(path, placement) == 0.0
    error, clearance = check_reach(path, placement)
    assert error < 0.01 and clearance > 0.01
    for wall in scene.room.walls:
        assert float(wall.signed_distance_m(placement.position_m[None])[0]) > model.footprint_radius_m
    to_target = placement.target_m[:2] - placement.position_m[:2]
    assert abs(np.degrees(np.arctan2(to_target[1], to_target[0]) - placement.yaw_rad)) < 1.0
    support = scene.object(placement.target_support)
    top = max((p.vertices_m @ support.world_from_asset[:3, :3].T + support.world_from_asset[:3, 3])[:, 2].max()
              for part in support.asset.parts for p in part.collision)
    assert placement.target_kind in ("top", "object_top")  # the fixture rooms have tops in reach
    assert placement.target_m[2] == pytest.approx(top + 0.18, abs=1e-6)
    m = mujoco.MjModel.from_xml_path(str(path))
    assert m.camera("input_camera").id >= 0 and m.key("robot/home").id >= 0
    assert m.nu == (8 + 3 * model.mobile) and all(m.actuator(a).name.startswith("robot/") for a in range(m.nu))
    shoulder = placement.world_from_robot[:3, :3] @ model.arm_mount_m + placement.position_m
    assert np.linalg.norm(placement.target_m - shoulder) < model.reach_m


def test_no_free_spot_is_one_line_input_error(tmp_path):
    """A room too small for the robot is refused with one line, not placed into a wall."""
    from scene_builder.model import Plane, Room, Scene

    from layout.robot import place_robot
    from scene_builder.errors import InputError

    walls = fixture_room().walls + (Plane(np.array([1.0, 0.0, 0.0]), 0.0, "wall", 10),)  # x >= 0 only, up to x = 2
    base = boxes_scene()
    scene = Scene(fixture_camera(), Room(walls=walls), tuple(o for o in base.objects if o.name == "counter"))
    narrow = Scene(scene.camera, Room(walls=walls + (Plane(np.array([-1.0, 0.0, 0.0]), 1.2, "wall", 10),)), scene.objects)
    with pytest.raises(InputError) as err:
        place_robot(narrow, _robot("panda", tmp_path))
    assert "\n" not in str(err.value) and "--robot panda" in str(err.value)


def test_robot_meshes_lie_on_mujocos_geoms_and_reach_rerun_and_gltf(tmp_path, monkeypatch):
    """The robot as rerun and glTF draw it (exporters.robot.robot_meshes): every mesh, taken into
    the frame of its geom in the compiled scene.xml (start pose, robot at its placement), spans
    that geom's bounding box within 1 mm, for the built-in Panda (collision primitives only) and
    a Menagerie-layout Panda whose link0 has a visual mesh (drawn instead of link0's collision
    geoms); the rerun recording and scene.glb carry one entity / node per mesh."""
    import mujoco
    import trimesh
    from rerun.chunk import RrdReader

    from exporters import record_scene
    from exporters.gltf import write_gltf
    from exporters.robot import robot_meshes
    from generation.robot import load_robot
    from layout.robot import place_robot

    src, _ = _menagerie_archive(tmp_path, "franka_emika_panda", "ef" * 20)
    monkeypatch.setenv("MENAGERIE_ROOT", str(src.parent))
    for model in (_robot("panda", tmp_path), load_robot("panda", tmp_path / "menagerie", offline=True)):
        scene = dataclasses.replace(boxes_scene(), robot=place_robot(boxes_scene(), model)[0])
        out = tmp_path / model.source
        m = mujoco.MjModel.from_xml_path(str(_write_scene(scene, out)))
        d = mujoco.MjData(m)
        mujoco.mj_kinematics(m, d)
        meshes = robot_meshes(scene.robot, "test")
        link0 = [x.name for x in meshes if x.name.startswith("link0/")]
        drawn = {x.name.split("/")[0] for x in meshes}
        assert drawn == {m.body(b).name[len("robot/"):] for b in range(1, m.nbody)
                         if m.body(b).name.startswith("robot/") and m.body_geomnum[b] > 0}
        for mesh in meshes:
            body, geom = mesh.name.split("/")
            g = int(m.body_geomadr[m.body("robot/" + body).id]) + int(geom[len("geom_"):])
            local = (mesh.mesh.vertices_m - d.geom_xpos[g]) @ d.geom_xmat[g].reshape(3, 3)
            centre, half = m.geom_aabb[g][:3], m.geom_aabb[g][3:]
            assert np.allclose(local.min(axis=0), centre - half, atol=1e-3), mesh.name
            assert np.allclose(local.max(axis=0), centre + half, atol=1e-3), mesh.name
            assert trimesh.Trimesh(mesh.mesh.vertices_m, mesh.mesh.faces).is_watertight
        if model.source == "menagerie":  # link0's visual mesh replaces its collision geoms
            g = int(m.body_geomadr[m.body("robot/link0").id]) + int(link0[0].split("_")[-1])
            assert link0 == [link0[0]] and m.geom_contype[g] == 0 and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
        else:
            assert len(link0) == int(m.body_geomnum[m.body("robot/link0").id])
        rrd = record_scene(out / "scene.rrd", scene=scene)
        entities = {c.entity_path for c in RrdReader(str(rrd)).store().stream()}
        assert {f"/world/robot/{x.name}" for x in meshes} | {"/world/robot_target"} <= entities
        glb = trimesh.load(str(write_gltf(scene, out)), force="scene")
        assert {f"robot/{x.name}" for x in meshes} <= set(glb.graph.nodes_geometry)


def _tendon_gripper_panda():
    """The built-in Panda with its gripper driven as Menagerie's is: one position actuator on a
    fixed tendon that splits the force equally between the fingers, its control 0-255."""
    import mujoco

    from generation.robot_builtin import build_panda

    spec = build_panda()
    spec.delete(spec.actuator("actuator8"))
    split = spec.add_tendon(name="split")
    split.wrap_joint("finger_joint1", 0.5)
    split.wrap_joint("finger_joint2", 0.5)
    grip = spec.add_actuator(name="actuator8", target="split", trntype=mujoco.mjtTrn.mjTRN_TENDON)
    grip.gainprm[0] = 0.04 / 255.0
    grip.biastype = mujoco.mjtBias.mjBIAS_AFFINE
    grip.biasprm[:3] = [0.0, -100.0, -10.0]
    grip.forcerange, grip.forcelimited = [-100.0, 100.0], True
    grip.ctrlrange, grip.ctrllimited = [0.0, 255.0], True
    return spec.compile()


@pytest.mark.parametrize("gripper", ["joint", "tendon"])
def test_joint_drives_exert_mujocos_actuator_forces(gripper, tmp_path):
    """The joint drives the USD and SDF writers give the robot (exporters.robot.position_drives)
    exert the generalized forces MuJoCo's actuators exert at zero control (clamped to each
    control range), over random poses and velocities, for the built-in Panda (a position servo
    per joint) and for a Panda whose gripper is driven through a fixed tendon as Menagerie's
    (the fingers moving together, as the equality holds them). Every actuated joint has one."""
    import mujoco

    from exporters.robot import position_drives

    m = mujoco.MjModel.from_xml_path(str(_robot("panda", tmp_path).mjcf_path)) if gripper == "joint" else _tendon_gripper_panda()
    drives = position_drives(m)
    actuated = {int(m.actuator_trnid[a, 0]) for a in range(m.nu) if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT}
    for t in {int(m.actuator_trnid[a, 0]) for a in range(m.nu) if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_TENDON}:
        actuated |= {int(m.wrap_objid[w]) for w in range(m.tendon_adr[t], m.tendon_adr[t] + m.tendon_num[t])}
    f1, f2 = m.joint("finger_joint1").id, m.joint("finger_joint2").id
    assert actuated <= set(drives) and {f1, f2} <= set(drives)
    assert drives[f1][3] == pytest.approx(0.0)  # at zero control the gripper is held closed
    rng = np.random.default_rng(0)
    d = mujoco.MjData(m)
    for _ in range(5):
        lo, hi = m.jnt_range[:, 0], m.jnt_range[:, 1]
        d.qpos[:] = lo + rng.uniform(0.1, 0.9, m.nq) * (hi - lo)
        d.qvel[:] = rng.normal(0.0, 0.3, m.nv)
        d.qpos[m.jnt_qposadr[f2]] = d.qpos[m.jnt_qposadr[f1]]  # the fingers move together
        d.qvel[m.jnt_dofadr[f2]] = d.qvel[m.jnt_dofadr[f1]]
        d.ctrl[:] = 0.0
        mujoco.mj_forward(m, d)
        for j in sorted(actuated):
            kp, kv, force, target = drives[j]
            expected = -kp * (d.qpos[m.jnt_qposadr[j]] - target) - kv * d.qvel[m.jnt_dofadr[j]]
            if force > 0.0:
                expected = float(np.clip(expected, -force, force))
            assert d.qfrc_actuator[m.jnt_dofadr[j]] == pytest.approx(expected, rel=1e-6, abs=1e-9), m.joint(j).name


def test_usd_robot_is_a_valid_articulation_whose_joint_frames_agree(tmp_path):
    """scene.usda with the robot passes every UsdValidation validator; the robot is an
    articulation with one driven revolute joint per arm joint (Franka's limits in degrees); each
    joint's two frames meet at the same world point (bodies at their exported poses); the base
    of the mobile robot is a generic joint with x, y and yaw free."""
    from pxr import Usd, UsdGeom, UsdPhysics

    from exporters.usd import write_usd
    from layout.robot import place_robot

    for name in ("panda", "mobile_panda"):
        model = _robot(name, tmp_path)
        scene = dataclasses.replace(boxes_scene(), robot=place_robot(boxes_scene(), model)[0])
        stage = Usd.Stage.Open(str(write_usd(scene, tmp_path / name)))
        root = stage.GetPrimAtPath("/World/Robot")
        assert root.HasAPI(UsdPhysics.ArticulationRootAPI)
        revolute = [p for p in Usd.PrimRange(root) if p.IsA(UsdPhysics.RevoluteJoint)]
        assert len(revolute) == 7
        j4 = UsdPhysics.RevoluteJoint(stage.GetPrimAtPath("/World/Robot/Joints/link4"))
        assert (j4.GetLowerLimitAttr().Get(), j4.GetUpperLimitAttr().Get()) == pytest.approx((-176.0, -4.0), abs=0.01)
        assert UsdPhysics.DriveAPI(j4.GetPrim(), "angular").GetStiffnessAttr().Get() == pytest.approx(3500 * np.pi / 180, rel=1e-5)
        cache = UsdGeom.XformCache()
        for prim in Usd.PrimRange(root):
            if not prim.IsA(UsdPhysics.Joint):
                continue
            joint = UsdPhysics.Joint(prim)
            ends = []
            for rel, local in ((joint.GetBody0Rel(), joint.GetLocalPos0Attr()), (joint.GetBody1Rel(), joint.GetLocalPos1Attr())):
                targets = rel.GetTargets()
                p = np.array(local.Get(), dtype=float)
                if targets:
                    mat = np.array(cache.GetLocalToWorldTransform(stage.GetPrimAtPath(targets[0])), dtype=float)
                    p = p @ mat[:3, :3] + mat[3, :3]  # USD row vectors
                ends.append(p)
            np.testing.assert_allclose(ends[0], ends[1], atol=1e-4, err_msg=str(prim.GetPath()))
        if name == "mobile_panda":
            base = stage.GetPrimAtPath("/World/Robot/Joints/base")
            assert base.HasAPI(UsdPhysics.DriveAPI, "transX") and base.HasAPI(UsdPhysics.DriveAPI, "rotZ")
            locked = UsdPhysics.LimitAPI(base, "transZ")
            assert locked.GetLowAttr().Get() > locked.GetHighAttr().Get()  # locked
            free = UsdPhysics.LimitAPI(base, "transX")
            assert free.GetLowAttr().Get() < -100 and free.GetHighAttr().Get() > 100


# --------------------------------------------------------------------------------------------
# The interaction test and the example


def _assert_reaches(out: Path, seconds: float = 4.0):
    outcome = robot_reach.run(out, seconds, render=False)
    assert not outcome.contacts, outcome.contacts[:3]
    assert outcome.final_error_m < REACH_TOL_M, outcome.final_error_m
    return outcome


@pytest.mark.parametrize("name", ["panda", "mobile_panda"])
def test_arm_reaches_above_the_support_without_touching_the_fixture_scene(name, tmp_path):
    """The scripted reach on the mixed fixture scene: the tool ends within 2 cm of the target,
    18 cm above the support top, and no robot geom touches a scene geom at any step."""
    model = _robot(name, tmp_path)
    from layout.robot import place_robot

    scene = dataclasses.replace(mixed_scene(), robot=place_robot(mixed_scene(), model)[0])
    out = tmp_path / "out"
    _write_scene(scene, out)
    _assert_reaches(out)


@pytest.mark.parametrize("bed_height_m", [0.55, 0.7])
def test_beside_a_bed_the_robot_turns_or_lowers_its_target_and_reaches_above_it(bed_height_m, tmp_path):
    """A bed-high top (a fixed 1.6 x 2.0 m box) is the only thing to work above. Facing it, the
    Panda's home pose pokes its hand into the bed's side at every spot place_robot ranks: none
    passes as it was placed. The alternatives (turned, stepped back, a lower target, the tool's
    axis free) find one that overlaps nothing and whose simulated reach ends above the bed
    without a contact."""
    from layout.reach import PlacementTrials
    from layout.robot import alternatives, place_robot
    from scene_builder.model import PlacedObject, Scene

    bed = box_asset("bed", (1.6, 2.0, bed_height_m), WOOD, is_fixed=True, label="bed")
    scene = Scene(fixture_camera(), fixture_room(), (PlacedObject(bed, pose(np.eye(3), (1.0, 0.5, 0.0)), "floor"),))
    placements = place_robot(scene, _robot("panda", tmp_path))
    assert all(p.target_kind == "top" and p.target_support == "bed" for p in placements)
    path = _write_scene(dataclasses.replace(scene, robot=placements[0]), tmp_path / "first")
    trials = PlacementTrials(path, placements[0])
    assert trials.first_passing(placements)[0] is None
    chosen, why = trials.first_passing(placements, lambda p: alternatives(scene, p))
    assert chosen is not None and why and "overlap" in why[0]
    assert chosen.target_kind == "top" and bed_height_m + 0.08 < chosen.target_m[2] < bed_height_m + 0.2
    assert abs(chosen.target_m[0] - 1.0) < 0.8 - 0.02 and abs(chosen.target_m[1] - 0.5) < 1.0 - 0.02  # over the bed
    out = tmp_path / "out"
    _write_scene(dataclasses.replace(scene, robot=chosen), out)
    _assert_reaches(out)


def test_a_target_inside_the_support_is_not_reached_without_contact(tmp_path):
    """The check can fail: moving the target 10 cm into the support top makes the arm touch it."""
    from layout.robot import place_robot

    model = _robot("panda", tmp_path)
    placement = place_robot(mixed_scene(), model)[0]
    sunk = dataclasses.replace(placement, target_m=placement.target_m - [0.0, 0.0, 0.28])
    out = tmp_path / "out"
    _write_scene(dataclasses.replace(mixed_scene(), robot=sunk), out)
    outcome = robot_reach.run(out, 4.0, render=False)
    assert outcome.contacts


def test_reach_targets_are_a_grid_over_every_flat_top_whatever_the_robot(tmp_path):
    """The fixed target set of the reach figure comes from the scene alone: 18 cm above a flat
    top (a ray straight down meets the top's collision geometry 18 cm below), on a 16 cm grid
    over the counter's top (60 x 120 cm less the 6 cm inset: 4 x 7 points), at least one on each
    smaller top (the boxes', the cabinet's), none on box_a (box_b covers it); the same with the
    robot placed in the scene."""
    import mujoco

    from exporters.mjcf import write_mjcf
    from layout.robot import SCORE_GRID_CELLS, TARGET_HEIGHT_M, place_robot, reach_targets

    scene = mixed_scene()
    points, owners = reach_targets(scene)
    assert sorted(set(owners)) == ["box_b", "box_c", "box_on_cabinet", "cabinet", "counter"]
    counter = points[np.array(owners) == "counter"]
    assert len(counter) == 28 and len(np.unique(counter[:, 2])) == 1
    steps = np.diff(np.unique(np.round(counter[:, 0], 6)))
    np.testing.assert_allclose(steps, 0.04 * SCORE_GRID_CELLS, atol=1e-9)
    m = mujoco.MjModel.from_xml_path(str(write_mjcf(scene, tmp_path / "scene")))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    geom = np.array([-1], dtype=np.int32)
    for p, owner in zip(points, owners):
        dist = mujoco.mj_ray(m, d, p, np.array([0.0, 0.0, -1.0]), np.array([0, 0, 0, 1, 0, 0], dtype=np.uint8), 1, -1, geom)
        assert dist == pytest.approx(TARGET_HEIGHT_M, abs=2e-3), (owner, p, dist)
        assert m.body(int(m.geom_bodyid[geom[0]])).name.split("/")[0] == owner
    with_robot = dataclasses.replace(scene, robot=place_robot(scene, _robot("panda", tmp_path))[0])
    again, owners_again = reach_targets(with_robot)
    np.testing.assert_array_equal(again, points)
    assert owners_again == owners


def test_reach_rate_counts_the_targets_in_the_workspace_and_can_fail(tmp_path):
    """score_reach on the mixed fixture scene: the placement's target is reached (within 2 cm,
    no contact); the same point sunk 28 cm, into box_c, is tried and missed (the arm touches
    it); the counter's far corner lies outside the arm's workspace and is not tried."""
    from layout.reach import SCORE_TOL_M, score_reach
    from layout.robot import place_robot

    model = _robot("panda", tmp_path)
    placement = place_robot(mixed_scene(), model)[0]
    path = _write_scene(dataclasses.replace(mixed_scene(), robot=placement), tmp_path / "out")
    targets = np.array([placement.target_m, placement.target_m - [0.0, 0.0, 0.28], [1.84, -0.24, 1.08]])
    shoulder = placement.world_from_robot[:3, :3] @ model.arm_mount_m + placement.position_m
    assert np.linalg.norm(targets[2] - shoulder) > model.reach_m
    reached, sunk, far = score_reach(path, placement, targets, ("box_c", "box_c", "counter"), seconds=3.0)
    assert reached.in_workspace and reached.reached and reached.final_error_m <= SCORE_TOL_M and reached.contacts == 0
    assert sunk.in_workspace and not sunk.reached and sunk.contacts > 0 and not sunk.hold_tool_axis  # both tries made
    assert not far.in_workspace and not far.reached


def test_example_writes_a_video_whose_frames_change(tmp_path):
    """examples/robot_reach.py as a user runs it: an MP4 whose frames show the arm moving."""
    import imageio.v2 as imageio

    from layout.robot import place_robot

    model = _robot("panda", tmp_path)
    out = tmp_path / "out"
    _write_scene(dataclasses.replace(boxes_scene(), robot=place_robot(boxes_scene(), model)[0]), out)
    video = tmp_path / "reach.mp4"
    assert robot_reach.main([str(out), "--seconds", "2", "--fps", "10", "--video", str(video)]) == 0
    frames = [np.asarray(f, dtype=np.float64) for f in imageio.get_reader(video)]
    assert len(frames) >= 18 and frames[0].shape == (360, 480, 3)
    assert np.abs(frames[-1] - frames[0]).mean() > 0.5  # the arm moved
    assert frames[0].std() > 5.0  # a drawn scene, not a blank image


# --------------------------------------------------------------------------------------------
# Real samples (slow): every real RGB-D sample with a movable object, built with --robot panda


def _build_with_robot(src: Path, out: Path, robot: str):
    from scene_builder.config import BuildConfig, ExportConfig, InputSpec, RobotConfig
    from scene_builder.pipeline import build

    cam = json.loads((src / "camera.json").read_text())
    rgb = src / ("rgb.jpg" if (src / "rgb.jpg").exists() else "rgb.png")
    inputs = InputSpec(rgb, src / "depth.png", 0.001, (cam["fx"], cam["fy"], cam["cx"], cam["cy"]))
    config = BuildConfig(export=ExportConfig(usd=True, urdf=False, gltf=False, viz="off"), robot=RobotConfig(robot, "built-in"))
    return build(inputs, out, config)


SAMPLES = real_samples()
#: Every fourth real sample (sorted by name: an NYU and two SUN RGB-D rooms) is built with the
#: robot here: each is a whole build of its own (20-100 s on the CI machine, which runs the whole
#: suite in about 19 of its 20 minutes). ``python -m scene_builder.bench.robot`` builds every
#: sample with the robot and scores the reach over a fixed target set (BENCHMARKS.md).
ROBOT_SAMPLES = SAMPLES[::4]


@pytest.fixture(scope="module", params=ROBOT_SAMPLES, ids=[s.name for s in ROBOT_SAMPLES])
def real_with_panda(request, tmp_path_factory):
    return _build_with_robot(request.param, tmp_path_factory.mktemp(request.param.name) / "out", "panda")


@pytest.mark.slow
def test_real_sample_panda_reaches_its_target_without_collision(real_with_panda):
    """Every fourth real sample (ROBOT_SAMPLES) with a movable object, built with --robot panda: the robot is in
    scene.xml and scene.usda, nothing overlaps at t = 0 (the physics check over all pairs,
    robot included), the objects stay at rest, input_camera is kept, and the scripted arm ends
    within 2 cm of its target (18 or 10 cm above a table or a movable object's top, which a ray
    straight down finds; beside a movable object where no top is in reach), touching nothing on
    the way."""
    import mujoco

    result = real_with_panda
    movable = [o for o in result.scene.objects if not o.asset.is_fixed]
    if not movable:
        pytest.skip(f"{result.out_dir.name}: no movable object in this build")
    report = json.loads(result.report_path.read_text())
    assert report["robot"]["name"] == "panda" and report["robot"]["source"] == "built-in"
    assert {"task": "robot", "backend": "built-in"}.items() <= next(b for b in report["backends"] if b["task"] == "robot").items()
    assert result.verdict.max_penetration_m < 1e-3 and result.verdict.stable
    m = mujoco.MjModel.from_xml_path(str(result.files.mjcf))
    assert m.camera("input_camera").id >= 0 and m.body("robot/link0").id >= 0
    assert "/World/Robot" in result.files.usd.read_text()
    from exporters import check_output

    assert check_output(result.out_dir) == ()  # `scene-builder check` passes with the robot in
    robot = report["robot"]
    if robot["target_kind"] != "side":
        # Above a top: straight down from the target, the first thing hit is the scene's (not the
        # floor), 8 to 20 cm below.
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        geom = np.array([-1], dtype=np.int32)
        dist = mujoco.mj_ray(m, d, np.array(robot["target_m"]), np.array([0.0, 0.0, -1.0]), None, 1, -1, geom)
        hit = m.geom(int(geom[0]))
        assert 0.08 - 1e-3 <= dist <= 0.2, (dist, hit.name)
        assert hit.name != "floor" and not m.body(int(hit.bodyid[0])).name.startswith("robot/")
    _assert_reaches(result.out_dir)


@pytest.mark.slow
def test_real_sample_mobile_manipulator_reaches_without_collision(tmp_path):
    """The mobile manipulator on a real sample: placed free of the scene, reaches its target."""
    src = next((s for s in SAMPLES if s.name == "nyuv2_metric3d_00000"), None)
    if src is None:
        pytest.skip("shared data not present: ../shared/data/real/nyuv2_metric3d_00000")
    result = _build_with_robot(src, tmp_path / "out", "mobile_panda")
    assert result.scene.robot is not None and result.scene.robot.model.mobile
    assert result.verdict.max_penetration_m < 1e-3
    _assert_reaches(result.out_dir)


@pytest.mark.newton
@pytest.mark.slow
@pytest.mark.parametrize("name", ["panda", "mobile_panda"])
def test_newton_reads_the_robot_as_an_articulation(name, newton, tmp_path):
    """An independent UsdPhysics consumer (NVIDIA Newton) loads scene.usda with the robot: its
    bodies and degrees of freedom are the MJCF's (Panda: 7 arm + 2 finger joints; the mobile
    base adds x, y and yaw), beside the three free boxes (6 each)."""
    from exporters.usd import write_usd
    from layout.robot import place_robot
    from tests.conftest import load_newton_model

    model = _robot(name, tmp_path)
    scene = dataclasses.replace(boxes_scene(), robot=place_robot(boxes_scene(), model)[0])
    built = load_newton_model(newton, write_usd(scene, tmp_path / "usd"))
    assert built.joint_dof_count == 3 * 6 + 9 + 3 * model.mobile
    assert built.body_count == 3 + 11 + model.mobile


def test_cli_refuses_an_unknown_robot_before_building(tmp_path):
    """`--robot r2d2` fails in one line with the input status (3) before any stage runs;
    `--help` lists the robots and the sources."""
    import subprocess

    from PIL import Image

    (tmp_path / "in").mkdir()
    Image.new("RGB", (64, 48), (120, 110, 100)).save(tmp_path / "in" / "room.png")
    cmd = [sys.executable, "-m", "scene_builder.cli", "build", str(tmp_path / "in" / "room.png"), "--robot", "r2d2", "-o", str(tmp_path / "out")]
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert done.returncode == 3, done.stderr
    assert done.stderr.strip().splitlines()[-1] == "error: unknown robot 'r2d2'; choose one of mobile_panda, panda, tidybot"
    assert not (tmp_path / "out").exists()
    helped = subprocess.run([sys.executable, "-m", "scene_builder.cli", "build", "--help"], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert "--robot NAME" in helped.stdout and "mobile_panda" in helped.stdout and "--robot-source" in helped.stdout
