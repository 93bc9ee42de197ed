"""URDF (read by yourdfpy and MuJoCo's URDF importer) and GLB (read by trimesh): the same bodies at
the same poses with the same masses and joint limits as the MJCF. The per-object URDFs
(``urdf/<object>.urdf``): one robot each, root link first, no world link and no floating joint,
placed by ``placements.json`` where the MJCF has them, joints with the asset's dynamics."""

from __future__ import annotations

import json

import numpy as np
import pytest

from exporters import write_gltf, write_mjcf, write_object_urdfs, write_urdf
from exporters.gltf import GLTF_FROM_WORLD
from scene_builder.frames import pose
from tests.fixtures_scenes import DOOR_RANGE_RAD, DRAWER_RANGE_M, mixed_scene


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    scene = mixed_scene()
    out = tmp_path_factory.mktemp("urdf")
    return scene, write_mjcf(scene, out), write_urdf(scene, out), write_gltf(scene, out)


def _mj_poses(path) -> dict[str, np.ndarray]:
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return {model.body(i).name: pose(data.xmat[i].reshape(3, 3), data.xpos[i]) for i in range(1, model.nbody)}, model


def _body_names(scene):
    return [a.name if p.parent is None else f"{a.name}/{p.name}" for a in (o.asset for o in scene.objects) for p in a.parts]


def test_mujoco_urdf_import_matches_the_mjcf(exported):
    import mujoco

    scene, mjcf, urdf, _ = exported
    ref, ref_model = _mj_poses(mjcf)
    got, model = _mj_poses(urdf)
    for name in _body_names(scene):
        # Link frames sit at joint anchors, MJCF body frames at the asset origin: compare the COMs.
        i, j = model.body(name).id, ref_model.body(name).id
        assert model.body_mass[i] == pytest.approx(ref_model.body_mass[j], rel=1e-6)
        com = got[name][:3, :3] @ model.body_ipos[i] + got[name][:3, 3]
        com_ref = ref[name][:3, :3] @ ref_model.body_ipos[j] + ref[name][:3, 3]
        np.testing.assert_allclose(com, com_ref, atol=1e-6)
        np.testing.assert_allclose(got[name][:3, :3], ref[name][:3, :3], atol=1e-6)
    for o in scene.objects:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"{o.name}/free")
        assert (jid >= 0) == (not o.asset.is_fixed)
        if jid >= 0:
            assert model.jnt_type[jid] == mujoco.mjtJoint.mjJNT_FREE
    np.testing.assert_allclose(model.joint("cabinet/door/joint").range, DOOR_RANGE_RAD, atol=1e-8)
    np.testing.assert_allclose(model.joint("cabinet/drawer/joint").range, DRAWER_RANGE_M, atol=1e-8)
    # Same collision geometry: as many collision geoms as pieces, plus one visual per part.
    n_pieces = sum(len(p.collision) for o in scene.objects for p in o.asset.parts)
    assert model.ngeom == n_pieces + len(_body_names(scene))


def test_yourdfpy_loads_meshes_and_poses(exported):
    import yourdfpy

    scene, mjcf, urdf, _ = exported
    robot = yourdfpy.URDF.load(str(urdf), mesh_dir=str(urdf.parent), build_collision_scene_graph=True, load_collision_meshes=True)
    assert robot.validate()
    ref, ref_model = _mj_poses(mjcf)
    n_pieces = sum(len(p.collision) for o in scene.objects for p in o.asset.parts)
    assert sum(len(link.collisions) for link in robot.link_map.values()) == n_pieces
    for link in robot.link_map.values():
        for c in link.collisions:
            assert (urdf.parent / c.geometry.mesh.filename).is_file()
    # Visual geometry in the world equals the asset meshes placed by world_from_asset.
    bounds = robot.scene.bounds
    lo = np.min([(o.world_from_asset[:3, :3] @ p.visual.vertices_m.T).T.min(0) + o.world_from_asset[:3, 3] for o in scene.objects for p in o.asset.parts], axis=0)
    hi = np.max([(o.world_from_asset[:3, :3] @ p.visual.vertices_m.T).T.max(0) + o.world_from_asset[:3, 3] for o in scene.objects for p in o.asset.parts], axis=0)
    np.testing.assert_allclose(bounds, [lo, hi], atol=1e-6)
    # Opening the door by the joint limit moves it like MuJoCo does.
    robot.update_cfg({"cabinet/door/joint": DOOR_RANGE_RAD[1]})
    door_link = robot.get_transform("cabinet/door", "world")
    assert door_link[:3, 3] == pytest.approx(ref["cabinet"][:3, :3] @ np.array([0.25, -0.4, 0.45]) + ref["cabinet"][:3, 3], abs=1e-6)
    del ref_model


def test_glb_nodes_have_world_poses_and_colours(exported):
    import trimesh

    scene, mjcf, _, glb = exported
    ref, _ = _mj_poses(mjcf)
    loaded = trimesh.load(str(glb), force="scene")
    names = _body_names(scene)
    assert sorted(loaded.graph.nodes_geometry) == sorted(names)
    world_from_gltf = np.linalg.inv(GLTF_FROM_WORLD)
    for name in names:
        t, geom = loaded.graph[name]
        np.testing.assert_allclose(world_from_gltf @ t, ref[name], atol=1e-6)
        mesh = loaded.geometry[geom]
        assert mesh.visual.kind == "vertex" and mesh.visual.vertex_colors.shape == (len(mesh.vertices), 4)
    # glTF is Y-up: the scene's height (world Z) is along glTF +Y.
    assert loaded.bounds[1][1] == pytest.approx(max(o.world_from_asset[2, 3] + o.asset.size_m[2] for o in scene.objects), abs=1e-6)


@pytest.fixture(scope="module")
def per_object(exported):
    scene, mjcf, urdf, _ = exported
    return scene, mjcf, write_object_urdfs(scene, urdf.parent)


def test_per_object_urdfs_have_no_floating_joint_and_the_root_link_first(per_object):
    import yourdfpy

    scene, _, folder = per_object
    placements = json.loads((folder / "placements.json").read_text())
    assert [p["name"] for p in placements["objects"]] == [o.name for o in scene.objects]
    assert sorted(p.name for p in folder.glob("*.urdf")) == sorted(p["urdf"] for p in placements["objects"])
    for placed, entry in zip(scene.objects, placements["objects"]):
        asset = placed.asset
        path = folder / entry["urdf"]
        robot = yourdfpy.URDF.load(str(path), load_meshes=True, build_collision_scene_graph=True, load_collision_meshes=True)
        assert robot.validate()
        assert robot.base_link == asset.name == robot.robot.links[0].name
        assert all(j.type != "floating" for j in robot.robot.joints) and "world" not in robot.link_map
        assert entry["fixed"] == asset.is_fixed
        # Real inertials and every collision piece.
        assert sum(link.inertial.mass for link in robot.robot.links) == pytest.approx(asset.mass_kg, rel=1e-8)
        assert sum(len(link.collisions) for link in robot.robot.links) == sum(len(p.collision) for p in asset.parts)
        for part in asset.parts:
            if part.joint is None:
                continue
            j = robot.joint_map[f"{asset.name}/{part.name}/joint"]
            assert j.type == part.joint.type.value
            assert (j.limit.lower, j.limit.upper) == pytest.approx((part.joint.lower, part.joint.upper))
            assert (float(j.dynamics.damping), float(j.dynamics.friction)) == pytest.approx((part.joint.damping, part.joint.friction))


def test_per_object_urdfs_placed_by_placements_match_the_mjcf(per_object):
    import mujoco

    from scene_builder.frames import matrix_from_quat_wxyz

    scene, mjcf, folder = per_object
    ref, ref_model = _mj_poses(mjcf)
    placements = {p["name"]: p for p in json.loads((folder / "placements.json").read_text())["objects"]}
    for placed in scene.objects:
        entry = placements[placed.name]
        world_from_root = pose(matrix_from_quat_wxyz(entry["quat_wxyz"]), entry["position_m"])
        np.testing.assert_allclose(world_from_root, ref[placed.name], atol=1e-9)
        # MuJoCo's URDF importer puts the object's root at the origin: its bodies' centres of
        # mass, moved by the placement, are the MJCF's.
        got, model = _mj_poses(folder / entry["urdf"])
        for part in placed.asset.parts:
            name = placed.name if part.parent is None else f"{placed.name}/{part.name}"
            i, j = model.body(name).id, ref_model.body(name).id
            assert model.body_mass[i] == pytest.approx(ref_model.body_mass[j], rel=1e-6)
            com = world_from_root[:3, :3] @ (got[name][:3, :3] @ model.body_ipos[i] + got[name][:3, 3]) + world_from_root[:3, 3]
            np.testing.assert_allclose(com, ref[name][:3, :3] @ ref_model.body_ipos[j] + ref[name][:3, 3], atol=1e-6)
        assert not any(model.jnt_type[k] == mujoco.mjtJoint.mjJNT_FREE for k in range(model.njnt))
