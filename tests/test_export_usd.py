"""USD export: stage metadata, UsdPhysics content read back by usd-core's own physics parser,
validation (and that validation catches a broken stage), camera, names."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

from exporters import names, write_usd
from exporters.usd import build_stage, validate_stage
from scene_builder.frames import transform_points
from scene_builder.model import PlacedObject, Scene
from tests.fixtures_scenes import DOOR_RANGE_RAD, bounded_walls_scene, DRAWER_RANGE_M, box_asset, cabinet_scene, mixed_scene, pillow_scene


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    from pxr import Usd

    scene = mixed_scene()
    path = write_usd(scene, tmp_path_factory.mktemp("usd"))
    return scene, Usd.Stage.Open(str(path))


def _parse(stage):
    from pxr import UsdPhysics

    parsed = UsdPhysics.LoadUsdPhysicsFromRange(stage, ["/World"])
    return {str(k): dict(zip((str(p) for p in v[0]), v[1])) for k, v in parsed.items()}


def test_stage_metadata(mixed):
    from pxr import UsdGeom, UsdPhysics

    _, stage = mixed
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdPhysics.GetStageKilogramsPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert stage.GetDefaultPrim().GetPath() == "/World"
    assert validate_stage(stage) == []


def test_physics_parser_reads_bodies_masses_and_joints(mixed):
    from pxr import UsdPhysics

    scene, stage = mixed
    parsed = _parse(stage)
    bodies = parsed["RigidBody"]
    free = [o for o in scene.objects if not o.asset.is_fixed]
    assert len(bodies) == sum(len(o.asset.parts) for o in free)
    assert "/World/Objects/counter" not in bodies  # fixed furniture is a static collider
    assert list(parsed["Articulation"]) == ["/World/Objects/cabinet"]
    for placed in free:
        a = placed.asset
        for part in a.parts:
            path = f"/World/Objects/{a.name}" if len(a.parts) == 1 else f"/World/Objects/{a.name}/{part.name}"
            prim = stage.GetPrimAtPath(path)
            mass = UsdPhysics.MassAPI(prim)
            assert mass.GetMassAttr().Get() == pytest.approx(part.inertial.mass_kg, rel=1e-6)
            np.testing.assert_allclose(mass.GetCenterOfMassAttr().Get(), part.inertial.com_m, atol=1e-6)
            # Principal moments and axes reconstruct the inertia tensor.
            q = mass.GetPrincipalAxesAttr().Get()
            from scene_builder.frames import matrix_from_quat_wxyz

            r = matrix_from_quat_wxyz([q.GetReal(), *q.GetImaginary()])
            tensor = r @ np.diag(mass.GetDiagonalInertiaAttr().Get()) @ r.T
            np.testing.assert_allclose(tensor, part.inertial.inertia_kg_m2, atol=1e-6 * np.abs(part.inertial.inertia_kg_m2).max())
    door = parsed["RevoluteJoint"]["/World/Objects/cabinet/Joints/door_joint"]
    assert str(door.body0) == "/World/Objects/cabinet/body" and str(door.body1) == "/World/Objects/cabinet/door"
    assert door.limit.lower == pytest.approx(np.degrees(DOOR_RANGE_RAD[0]))
    assert door.limit.upper == pytest.approx(np.degrees(DOOR_RANGE_RAD[1]), rel=1e-6)
    drawer = parsed["PrismaticJoint"]["/World/Objects/cabinet/Joints/drawer_joint"]
    assert drawer.limit.upper == pytest.approx(DRAWER_RANGE_M[1], rel=1e-6)
    # Joint frame: localPos is the anchor; local X (the joint axis token) maps to Joint.axis.
    cab = scene.object("cabinet").asset
    j = next(p for p in cab.parts if p.name == "door").joint
    np.testing.assert_allclose(np.array(door.localPose0Position), j.anchor_m, atol=1e-6)
    from scene_builder.frames import matrix_from_quat_wxyz

    q = door.localPose0Orientation
    np.testing.assert_allclose(matrix_from_quat_wxyz([q.GetReal(), *q.GetImaginary()])[:, 0], j.axis, atol=1e-6)
    # Every collider is a convex hull bound to a physics material.
    meshes = parsed["MeshShape"]
    assert len(meshes) == sum(len(p.collision) for o in scene.objects for p in o.asset.parts)
    assert all(str(d.approximation) == "convexHull" and len(d.materials) == 1 for d in meshes.values())


def test_validation_catches_a_broken_stage():
    from pxr import Sdf, UsdPhysics

    stage = build_stage(cabinet_scene())
    assert validate_stage(stage) == []
    joint = UsdPhysics.RevoluteJoint(stage.GetPrimAtPath("/World/Objects/cabinet/Joints/door_joint"))
    joint.GetBody1Rel().SetTargets([Sdf.Path("/World/Nowhere")])
    problems = validate_stage(stage)
    assert problems and "door_joint" in problems[0]


def test_fixed_articulated_object_is_welded_to_the_world():
    stage = build_stage(cabinet_scene(is_fixed=True))
    assert validate_stage(stage) == []
    fixed = _parse(stage)["FixedJoint"]
    weld = fixed["/World/Objects/cabinet/Joints/world_weld"]
    assert str(weld.body0) == "" and str(weld.body1) == "/World/Objects/cabinet/body"


def test_camera_projects_like_the_intrinsics(mixed):
    from pxr import Gf, Usd, UsdGeom

    scene, stage = mixed
    k = scene.camera.intrinsics
    frustum = UsdGeom.Camera(stage.GetPrimAtPath("/World/InputCamera")).GetCamera(Usd.TimeCode.Default()).frustum
    view_proj = frustum.ComputeViewMatrix() * frustum.ComputeProjectionMatrix()
    pts = transform_points(scene.object("cabinet").world_from_asset, scene.object("cabinet").asset.root.visual.vertices_m)
    expected = k.project(transform_points(np.linalg.inv(scene.camera.world_from_camera), pts))
    got = []
    for p in pts:
        ndc = view_proj.Transform(Gf.Vec3d(*p))
        got.append(((ndc[0] + 1) / 2 * k.width_px - 0.5, (1 - ndc[1]) / 2 * k.height_px - 0.5))
    np.testing.assert_allclose(np.array(got), expected, atol=0.01)


def test_camera_with_off_centre_principal_point(tmp_path):
    from pxr import Gf, Usd, UsdGeom

    from scene_builder.model import Camera, CameraIntrinsics

    base = mixed_scene()
    k = CameraIntrinsics(500.0, 520.0, 300.0, 260.0, 640, 480)
    scene = Scene(Camera(k, base.camera.world_from_camera), base.room, base.objects[:1])
    stage = build_stage(scene)
    frustum = UsdGeom.Camera(stage.GetPrimAtPath("/World/InputCamera")).GetCamera(Usd.TimeCode.Default()).frustum
    view_proj = frustum.ComputeViewMatrix() * frustum.ComputeProjectionMatrix()
    p = transform_points(scene.camera.world_from_camera, np.array([[0.3, -0.2, 2.0]]))[0]
    ndc = view_proj.Transform(Gf.Vec3d(*p))
    u, v = (ndc[0] + 1) / 2 * k.width_px - 0.5, (1 - ndc[1]) / 2 * k.height_px - 0.5
    np.testing.assert_allclose([u, v], k.project(np.array([[0.3, -0.2, 2.0]]))[0], atol=0.01)


@settings(max_examples=60, deadline=None)
@given(st.text(min_size=0, max_size=12))
@example("\x000")  # a leading NUL becomes "_" and the rest is kept ("_0"); a later NUL ends the name
@example("a\x000")
@example("0\x00a")
def test_valid_identifier_matches_tf(name):
    from pxr import Tf

    assert names.valid_identifier(name) == Tf.MakeValidIdentifier(name)


def test_names_are_sanitised_unique_and_displayed():
    from pxr import Usd

    base = mixed_scene()
    objs = (
        PlacedObject(box_asset("box 1", (0.2, 0.2, 0.2)), base.objects[0].world_from_asset),
        PlacedObject(box_asset("box_1", (0.2, 0.2, 0.2)), base.objects[2].world_from_asset),
        PlacedObject(box_asset("3d-box", (0.2, 0.2, 0.2)), base.objects[3].world_from_asset),
    )
    stage = build_stage(Scene(base.camera, base.room, objs))
    kids = stage.GetPrimAtPath("/World/Objects").GetChildren()
    assert [p.GetName() for p in kids] == ["box_1", "box_1_1", "_d_box"]
    assert [p.GetDisplayName() for p in kids] == ["box 1", "box_1", "3d-box"]
    assert validate_stage(stage) == []


def test_deformable_rigid_fallback_keeps_soft_parameters():
    stage = build_stage(pillow_scene())
    prim = stage.GetPrimAtPath("/World/Objects/pillow")
    assert prim.GetAttribute("sceneBuilder:deformable:youngsModulusPa").Get() == pytest.approx(5.0e4)
    assert prim.GetAttribute("sceneBuilder:deformable:poissonRatio").Get() == pytest.approx(0.3)
    assert validate_stage(stage) == []


def test_a_bounded_wall_is_a_cube_collider_behind_its_face(tmp_path):
    """A wall seen over a bounded span is a guide-purpose UsdGeom.Cube collider: its world box is
    the wall's slab (face on the plane, over the span); an unbounded wall stays a plane."""
    from pxr import Usd, UsdGeom, UsdPhysics

    scene = bounded_walls_scene()
    stage = Usd.Stage.Open(str(write_usd(scene, tmp_path)))
    assert validate_stage(stage) == []
    cache = UsdGeom.BBoxCache(Usd.TimeCode.Default(), [UsdGeom.Tokens.guide])
    for i, wall in enumerate(scene.room.walls):
        prim = stage.GetPrimAtPath(f"/World/Room/Wall_{i}")
        assert prim.HasAPI(UsdPhysics.CollisionAPI)
        if not wall.bounded:
            assert prim.IsA(UsdGeom.Plane)
            continue
        assert prim.IsA(UsdGeom.Cube)
        box = cache.ComputeWorldBound(prim).ComputeAlignedRange()
        centre, _, half = wall.slab()
        lo, hi = np.array(box.GetMin()), np.array(box.GetMax())
        np.testing.assert_allclose((lo + hi) / 2, centre, atol=1e-5)
        # Axis-aligned walls here: the box's extent along the wall is the span with its margins.
        along = np.abs(wall.tangent) > 0.5
        assert float((hi - lo)[along][0]) == pytest.approx(2.0 * half[0], abs=1e-5)
