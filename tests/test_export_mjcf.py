"""MJCF export: naming conventions, exact inertials, joints, camera, resting stability, errors."""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from exporters import write_mjcf
from exporters.mjcf import COLLISION_GROUP, VISUAL_GROUP
from scene_builder.errors import ExportError
from scene_builder.frames import transform_points
from scene_builder.model import PlacedObject, Scene, TriangleMesh
from tests.fixtures_scenes import DOOR_RANGE_RAD, DRAWER_RANGE_M, cabinet_scene, mixed_scene, pillow_scene


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    import mujoco

    scene = mixed_scene()
    out = tmp_path_factory.mktemp("mjcf")
    path = write_mjcf(scene, out)
    return scene, path, mujoco.MjModel.from_xml_path(str(path))


def test_names_groups_and_relative_mesh_paths(mixed):
    import mujoco

    scene, path, model = mixed
    root = ET.parse(path).getroot()
    assert root.find("compiler").get("angle") == "radian"
    assert model.opt.timestep == pytest.approx(0.002)
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    np.testing.assert_allclose(model.opt.gravity, [0, 0, -9.81])
    for mesh in root.iter("mesh"):
        f = mesh.get("file")
        assert not f.startswith("/") and (path.parent / "meshes" / f).is_file()
    for placed in scene.objects:
        a = placed.asset
        assert model.body(a.name).parentid == 0
        free = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"{a.name}/free")
        assert (free >= 0) == (not a.is_fixed)
        for part in a.parts:
            bname = a.name if part.parent is None else f"{a.name}/{part.name}"
            vis = model.geom(f"{bname}/visual")
            assert vis.group[0] == VISUAL_GROUP and vis.contype[0] == 0 and vis.conaffinity[0] == 0
            for k in range(len(part.collision)):
                col = model.geom(f"{bname}/collision_{k}")
                assert col.group[0] == COLLISION_GROUP and col.contype[0] == 1
                assert col.friction[0] == pytest.approx(part.material.dynamic_friction)
    assert model.geom("floor").type[0] == mujoco.mjtGeom.mjGEOM_PLANE
    assert [model.geom(f"wall_{i}").id for i in range(len(scene.room.walls))]
    assert model.cam("input_camera").id == 0


def test_inertials_are_the_parts_exact_mass_properties(mixed):
    import mujoco

    scene, _, model = mixed
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    for placed in scene.objects:
        a = placed.asset
        r_world_asset = placed.world_from_asset[:3, :3]
        for part in a.parts:
            b = model.body(a.name if part.parent is None else f"{a.name}/{part.name}")
            assert b.mass[0] == pytest.approx(part.inertial.mass_kg, rel=1e-9)
            # COM and inertia tensor in the world, from MuJoCo's compiled body vs from the part.
            np.testing.assert_allclose(data.xipos[b.id], transform_points(placed.world_from_asset, part.inertial.com_m[None])[0], atol=1e-9)
            r = data.ximat[b.id].reshape(3, 3)
            inertia_mj = r @ np.diag(model.body_inertia[b.id]) @ r.T
            inertia_part = r_world_asset @ part.inertial.inertia_kg_m2 @ r_world_asset.T
            np.testing.assert_allclose(inertia_mj, inertia_part, atol=1e-9 * np.abs(inertia_part).max())


def test_scene_rests(mixed):
    import mujoco

    scene, _, model = mixed
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    start = {o.name: data.xpos[model.body(o.name).id].copy() for o in scene.objects}
    for _ in range(500):  # 1 s
        mujoco.mj_step(model, data)
    for o in scene.objects:
        assert np.linalg.norm(data.xpos[model.body(o.name).id] - start[o.name]) < 2e-3, o.name


def test_cabinet_joints_follow_their_limits(tmp_path):
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(write_mjcf(cabinet_scene(), tmp_path)))
    data = mujoco.MjData(model)
    door = model.joint("cabinet/door/joint")
    drawer = model.joint("cabinet/drawer/joint")
    np.testing.assert_allclose(door.range, DOOR_RANGE_RAD, atol=1e-12)
    np.testing.assert_allclose(drawer.range, DRAWER_RANGE_M, atol=1e-12)
    # Push the door open with 5 N*m and pull the drawer with 40 N for 2 s: they stop at the limits.
    for _ in range(1000):
        data.qfrc_applied[:] = 0.0
        data.qfrc_applied[door.dofadr[0]] = 5.0
        data.qfrc_applied[drawer.dofadr[0]] = 40.0
        mujoco.mj_step(model, data)
    assert data.qpos[door.qposadr[0]] == pytest.approx(DOOR_RANGE_RAD[1], abs=0.03)
    assert data.qpos[drawer.qposadr[0]] == pytest.approx(DRAWER_RANGE_M[1], abs=0.01)
    # The opened door swings out of the front (+X of the cabinet, which faces -X in the world).
    door_com = data.xipos[model.body("cabinet/door").id]
    assert door_com[0] < 1.2 - 0.25 - 0.1


def test_input_camera_sees_objects_where_the_intrinsics_project_them(mixed):
    import mujoco

    scene, _, model = mixed
    k = scene.camera.intrinsics
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with mujoco.Renderer(model, height=k.height_px, width=k.width_px) as r:
        r.enable_segmentation_rendering()
        opt = mujoco.MjvOption()
        opt.geomgroup[:] = 0
        opt.geomgroup[VISUAL_GROUP] = 1
        r.update_scene(data, camera="input_camera", scene_option=opt)
        seg = r.render()[..., 0]
    placed = scene.object("box_c")
    ys, xs = np.nonzero(seg == model.geom("box_c/visual").id)
    assert len(xs) > 500
    corners = transform_points(placed.world_from_asset, np.array(np.meshgrid(*placed.asset.root.visual.bounds_m.T)).reshape(3, -1).T)
    cam_from_world = np.linalg.inv(scene.camera.world_from_camera)
    uv = k.project(transform_points(cam_from_world, corners))
    assert uv[:, 0].min() - 1 <= xs.min() and xs.max() <= uv[:, 0].max() + 1
    assert uv[:, 1].min() - 1 <= ys.min() and ys.max() <= uv[:, 1].max() + 1


def test_deformable_is_a_flex_that_rests_on_its_support(tmp_path):
    import mujoco

    scene = pillow_scene()
    model = mujoco.MjModel.from_xml_path(str(write_mjcf(scene, tmp_path)))
    assert model.nflex == 1 and mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_FLEX, 0) == "pillow"
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_DISCRETE
    pillow = scene.object("pillow").asset
    flex_mass = model.body_mass[model.flex_vertbodyid[model.flex_vertadr[0]:model.flex_vertadr[0] + model.flex_vertnum[0]]].sum()
    assert flex_mass == pytest.approx(pillow.mass_kg, rel=1e-6)
    data = mujoco.MjData(model)
    for _ in range(500):
        mujoco.mj_step(model, data)
    z = data.flexvert_xpos[:, 2]
    assert np.all(np.isfinite(z))
    assert 0.29 < z.min() < 0.31  # on top of the 0.3 m box, not through it


def test_rejected_object_is_named(tmp_path):
    scene = cabinet_scene()
    cab = scene.objects[0].asset
    # A flat (zero-volume) visual mesh: MuJoCo refuses to compute its hull. (A flat collision
    # piece is refused by the data model itself, before any exporter.)
    flat = TriangleMesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float), np.array([[0, 1, 2], [1, 3, 2]]))
    with pytest.raises(ValueError, match="flat or tiny"):
        dataclasses.replace(cab.parts[0], collision=(flat,))
    parts = (dataclasses.replace(cab.parts[0], visual=flat),) + cab.parts[1:]
    bad = dataclasses.replace(cab, name="broken_cabinet", parts=parts)
    scene = Scene(scene.camera, scene.room, (PlacedObject(bad, scene.objects[0].world_from_asset),))
    with pytest.raises(ExportError, match="broken_cabinet"):
        write_mjcf(scene, tmp_path)


@pytest.mark.parametrize("young_pa, damping_s", [(1.0e4, 0.3), (5.0e6, 0.05)])  # real pillow; fabric-stiff blanket
def test_flex_steps_without_mujoco_warnings_and_rests(tmp_path, young_pa, damping_s):
    """Settings from generation that make MuJoCo's effective-metric solve fail every step when
    written verbatim are conditioned by the exporter: 3 s without any warning, pillow still."""
    import mujoco

    scene = pillow_scene()
    placed = scene.object("pillow")
    soft = dataclasses.replace(placed.asset.deformable, youngs_modulus_pa=young_pa, damping=damping_s, resolution=8)
    pillow = dataclasses.replace(placed, asset=dataclasses.replace(placed.asset, deformable=soft))
    scene = dataclasses.replace(scene, objects=tuple(pillow if o.name == "pillow" else o for o in scene.objects))
    model = mujoco.MjModel.from_xml_path(str(write_mjcf(scene, tmp_path)))
    assert model.flex_damping[0] >= model.opt.timestep
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    start = data.flexvert_xpos.mean(axis=0).copy()
    for _ in range(1500):
        mujoco.mj_step(model, data)
    assert [int(w.number) for w in data.warning] == [0] * len(data.warning)
    assert np.linalg.norm(data.flexvert_xpos.mean(axis=0) - start) < 0.01
    assert 0.29 < data.flexvert_xpos[:, 2].min() < 0.31


def test_a_part_too_light_for_mujoco_is_named_before_mujoco_refuses_it(tmp_path):
    """A moving 0.2 mm foam cube weighs 2e-10 kg with moments of 2e-18 kg m^2, under MuJoCo's
    mjMINVAL (1e-15): the exporter says which object and part, in one line."""
    from generation.assembly import ConvexSolids, PartSpec, assemble_asset, box_solid

    speck = assemble_asset("speck", "object", [PartSpec("body", None, ConvexSolids((box_solid([0, 0, 0], [2e-4, 2e-4, 2e-4]),)), "foam")])
    scene = cabinet_scene()
    scene = Scene(scene.camera, scene.room, scene.objects + (PlacedObject(speck, scene.objects[0].world_from_asset @ np.diag([1, 1, 1, 1.0])),))
    with pytest.raises(ExportError, match="object speck: part body weighs .* under what MuJoCo simulates"):
        write_mjcf(scene, tmp_path)


def test_writing_a_scene_again_rewrites_only_what_changed(tmp_path):
    """The repair rounds write the same scene again: an unchanged mesh file is left as written
    (same bytes, same mtime), a moved object's meshes are not rewritten either (geometry is in the
    asset frame), a changed mesh is rewritten, and a file changed by anyone else since is
    rewritten with the scene's content."""
    import os

    scene = mixed_scene()
    write_mjcf(scene, tmp_path)
    objs = sorted((tmp_path / "meshes").glob("*.obj"))
    assert objs
    before = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in objs}
    victim = objs[0]
    victim.write_text("tampered\n")
    os.utime(victim, ns=(0, 0))
    first = scene.objects[0]
    lifted = first.world_from_asset.copy()
    lifted[2, 3] += 0.01
    moved = dataclasses.replace(first, world_from_asset=lifted)
    write_mjcf(dataclasses.replace(scene, objects=(moved, *scene.objects[1:])), tmp_path)
    for p in objs:
        if p == victim:
            assert p.read_bytes() == before[p][1]
        else:
            assert (p.stat().st_mtime_ns, p.read_bytes()) == before[p]
    part = first.asset.parts[0]
    grown = dataclasses.replace(part, visual=dataclasses.replace(part.visual, vertices_m=part.visual.vertices_m * 1.01))
    changed = dataclasses.replace(first, asset=dataclasses.replace(first.asset, parts=(grown, *first.asset.parts[1:])))
    write_mjcf(dataclasses.replace(scene, objects=(changed, *scene.objects[1:])), tmp_path)
    rewritten = [p for p in objs if p.read_bytes() != before[p][1]]
    assert len(rewritten) == 1 and "vis" in rewritten[0].name
