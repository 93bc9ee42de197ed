"""The data model validates its invariants and scene.json round-trips exactly."""

from __future__ import annotations

import numpy as np
import pytest

from scene_builder import model as m
from scene_builder.serialize import scene_from_json, scene_to_json


def _box_mesh(sx=0.4, sy=0.3, sz=0.2) -> m.TriangleMesh:
    import trimesh

    b = trimesh.creation.box(extents=(sx, sy, sz))
    b.apply_translation((0, 0, sz / 2))
    return m.TriangleMesh(b.vertices, b.faces)


def _scene(rng: np.random.Generator) -> m.Scene:
    mesh = _box_mesh()
    mat = m.Material("wood", 700.0, 0.5, 0.4, 0.3, 1e10, 0.35, (0.5, 0.3, 0.1, 1.0), "table")
    second = rng.uniform(0.005, 0.05, 3)  # int x_i^2 dm: a body's moments are sums of two of them
    inertia = np.diag(second.sum() - second)
    inertial = m.Inertial(1.7 + rng.random(), rng.normal(size=3) * 0.01, inertia)
    root = m.Part("body", None, None, mesh, (mesh,), mat, inertial, 3, "support", "a box")
    door = m.Part(
        "door",
        "body",
        m.Joint(m.JointType.REVOLUTE, (0, 0, 1.0), (0.2, 0.15, 0.0), 0.0, 1.5, 0.1, 0.05, 5.0),
        mesh,
        (mesh, mesh),
        mat,
        inertial,
        1,
        "pull handle",
        "door",
    )
    asset = m.ObjectAsset("cabinet_1", "cabinet", m.AssetKind.ARTICULATED, (root, door), (0.4, 0.3, 0.2), "cab")
    soft = m.ObjectAsset(
        "pillow_2",
        "pillow",
        m.AssetKind.DEFORMABLE,
        (root,),
        (0.4, 0.3, 0.2),
        deformable=m.DeformableSettings(1e5, 0.3, 0.01, 0.0, 4),
    )
    pose = np.eye(4)
    pose[:3, 3] = rng.normal(size=3)
    cam = m.Camera(m.CameraIntrinsics(500.1, 501.3, 319.5, 239.5, 640, 480, "flag"), np.eye(4))
    room = m.Room((m.Plane((0, 1.0, 0), 2.5, "wall", 1000),))
    return m.Scene(cam, room, (m.PlacedObject(asset, pose, "floor"), m.PlacedObject(soft, np.eye(4), "cabinet_1")))


def test_scene_json_round_trips_exactly():
    scene = _scene(np.random.default_rng(3))
    text = scene_to_json(scene)
    back = scene_from_json(text)
    assert scene_to_json(back) == text
    a, b = scene.objects[0], back.objects[0]
    assert np.array_equal(a.world_from_asset, b.world_from_asset)
    assert np.array_equal(a.asset.parts[1].inertial.com_m, b.asset.parts[1].inertial.com_m)
    assert np.array_equal(a.asset.parts[0].visual.vertices_m, b.asset.parts[0].visual.vertices_m)
    assert b.asset.parts[1].joint.type is m.JointType.REVOLUTE
    assert back.objects[1].asset.deformable == scene.objects[1].asset.deformable
    assert back.camera.intrinsics == scene.camera.intrinsics


@pytest.mark.parametrize(
    "text, message",
    [("{", "not valid JSON"), ('{"format": "x"}', "not a scene-builder"), ('{"format": "scene-builder/scene", "version": 99}', "version")],
)
def test_malformed_scene_json_gives_clear_error(text, message):
    with pytest.raises(ValueError, match=message):
        scene_from_json(text)


def test_arrays_are_frozen_and_validated():
    mesh = _box_mesh()
    with pytest.raises(ValueError):
        mesh.vertices_m[0, 0] = 1.0
    with pytest.raises(ValueError, match="shape"):
        m.TriangleMesh(np.zeros((4, 2)), np.zeros((0, 3)))
    with pytest.raises(ValueError, match="NaN"):
        m.Inertial(1.0, (np.nan, 0, 0), np.eye(3))
    with pytest.raises(ValueError, match="positive definite"):
        m.Inertial(1.0, (0, 0, 0), np.diag([1.0, 1.0, -1.0]))
    # Positive definite but no body's: MuJoCo would reject it ("inertia must satisfy A + B >= C").
    with pytest.raises(ValueError, match="triangle inequality"):
        m.Inertial(1.0, (0, 0, 0), np.diag([0.01, 0.02, 0.05]))
    # A flat plate's moments (A + B = C) within round-off fall short of the exporters' margin.
    with pytest.raises(ValueError, match="triangle inequality"):
        m.Inertial(1.0, (0, 0, 0), np.diag([1.0, 1.0, 2.0]))
    m.Inertial(1.0, (0, 0, 0), np.diag([1.0, 1.0, 2.0 - 1e-5]))
    with pytest.raises(ValueError, match="rotation"):
        m.Camera(m.CameraIntrinsics(1, 1, 0, 0, 2, 2), np.diag([1.0, 1.0, -1.0, 1.0]))


def test_intrinsics_project_unproject_and_scale():
    k = m.CameraIntrinsics(518.9, 519.5, 325.6, 253.7, 640, 480)
    depth = np.full((480, 640), 2.0, np.float32)
    pts = k.unproject(depth)
    uv = k.project(pts.reshape(-1, 3))
    u, v = np.meshgrid(np.arange(640), np.arange(480))
    assert np.allclose(uv[:, 0], u.ravel()) and np.allclose(uv[:, 1], v.ravel())
    half = k.scaled(320, 240)
    # The same ray hits the same point: pixel centre mapping (u + 0.5) * s - 0.5.
    p = np.array([[0.3, -0.2, 2.0]])
    assert np.allclose((k.project(p) + 0.5) / 2 - 0.5, half.project(p))
    fov = m.CameraIntrinsics.from_fov(640, 480, 60.0)
    assert np.isclose(np.degrees(2 * np.arctan(320 / fov.fx_px)), 60.0)


def test_inertial_principal_axes_reconstruct_tensor():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(3, 3))
    second = a @ a.T + np.eye(3) * 0.1  # int x x^T dm about the centre of mass
    tensor = np.trace(second) * np.eye(3) - second
    moments, axes = m.Inertial(2.0, (0, 0, 0), tensor).principal()
    assert np.isclose(np.linalg.det(axes), 1.0)
    assert np.allclose(axes @ np.diag(moments) @ axes.T, tensor)


def test_a_bounded_wall_stands_only_over_its_span_and_its_slab_lies_behind_its_face():
    """A wall x = -3 (room at x > -3) seen from y = -1 to 2 m: a point behind its plane along the
    span is behind it (negative clearance), one behind its plane past either end is not (inf);
    the slab exporters collide with has its face on the plane, runs the span (widened by the end
    margin) and stands on the floor."""
    from scene_builder.planes import WALL_END_MARGIN_M, WALL_OPEN_LENGTH_M, WALL_SLAB_HEIGHT_M, WALL_SLAB_THICKNESS_M

    wall = m.Plane(np.array([1.0, 0.0, 0.0]), 3.0, "wall", 10, span_m=(-1.0, 2.0))
    np.testing.assert_allclose(wall.tangent, [0.0, 1.0, 0.0])  # up x normal
    pts = np.array([[-3.5, 0.0, 1.0], [-3.5, 2.05, 1.0], [-3.5, 2.5, 1.0], [-3.5, -1.5, 0.5], [-2.0, 0.0, 0.0]])
    c = wall.clearance_m(pts)
    assert c[0] == pytest.approx(-0.5) and c[1] == pytest.approx(-0.5)  # (2.05 m: within the margin)
    assert np.isposinf(c[2]) and np.isposinf(c[3])
    assert c[4] == pytest.approx(1.0)
    np.testing.assert_allclose(wall.signed_distance_m(pts), [-0.5, -0.5, -0.5, -0.5, 1.0])
    # Unbounded, the same plane holds back everything behind it.
    np.testing.assert_allclose(m.Plane(wall.normal, 3.0, "wall").clearance_m(pts), wall.signed_distance_m(pts))
    centre, yaw, half = wall.slab()
    rot = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    corners = centre + (np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half) @ rot.T
    np.testing.assert_allclose([corners[:, 0].min(), corners[:, 0].max()], [-3.0 - WALL_SLAB_THICKNESS_M, -3.0])
    np.testing.assert_allclose([corners[:, 1].min(), corners[:, 1].max()], [-1.0 - WALL_END_MARGIN_M, 2.0 + WALL_END_MARGIN_M])
    np.testing.assert_allclose([corners[:, 2].min(), corners[:, 2].max()], [0.0, WALL_SLAB_HEIGHT_M])
    # One end known (seen past at y = 2 m), the other open: the wall goes on towards -y.
    half_open = m.Plane(np.array([1.0, 0.0, 0.0]), 3.0, "wall", 10, span_m=(None, 2.0))
    c = half_open.clearance_m(pts)
    assert c[3] == pytest.approx(-0.5) and np.isposinf(c[2])
    centre, yaw, half = half_open.slab()
    assert centre[1] + half[0] == pytest.approx(2.0 + WALL_END_MARGIN_M)
    assert centre[1] - half[0] == pytest.approx(2.0 + WALL_END_MARGIN_M - WALL_OPEN_LENGTH_M)
    assert m.Plane(np.array([1.0, 0.0, 0.0]), 3.0, "wall", 10, span_m=(None, None)).span_m is None
    with pytest.raises(ValueError, match="span_m"):
        m.Plane(np.array([1.0, 0.0, 0.0]), 3.0, "wall", 10, span_m=(2.0, -1.0))
    with pytest.raises(ValueError, match="span_m"):
        m.Plane(np.array([1.0, 0.0, 0.0]), 3.0, "wall", 10, span_m=(float("inf"), None))
    with pytest.raises(ValueError, match="walls only"):
        m.Plane(np.array([0.0, 0.0, 1.0]), 0.0, "floor", 10, span_m=(0.0, 1.0))
    with pytest.raises(ValueError, match="unbounded"):
        m.Plane(np.array([0.0, 0.0, 1.0]), 0.0, "floor").slab()
