"""Hand-built test scenes (boxes, an articulated cabinet, a soft pillow) with exact physics.

Every part is made of axis-aligned boxes (trimesh primitives): the visual mesh is the
concatenation of non-overlapping closed boxes (so it is watertight and trimesh's mass properties
are exact), the collision pieces are the boxes themselves (each convex). Mass = density x volume,
inertia integrated over the mesh by trimesh. Reusable by any stage's tests:

    from tests.fixtures_scenes import boxes_scene, cabinet_scene, mixed_scene
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scene_builder.frames import pose, rot_z
from scene_builder.model import (
    AssetKind,
    Camera,
    CameraIntrinsics,
    DeformableSettings,
    Inertial,
    Joint,
    JointType,
    Material,
    ObjectAsset,
    Part,
    PlacedObject,
    Plane,
    Room,
    Scene,
    TriangleMesh,
)

WOOD = Material("wood", 600.0, 0.5, 0.4, 0.3, 1.0e10, 0.35, (0.62, 0.45, 0.30, 1.0), "fixture")
CARDBOARD = Material("cardboard", 250.0, 0.6, 0.5, 0.2, 2.0e9, 0.3, (0.80, 0.65, 0.45, 1.0), "fixture")
FABRIC = Material("fabric", 80.0, 0.7, 0.6, 0.05, 5.0e4, 0.3, (0.30, 0.40, 0.80, 1.0), "fixture")


def box_mesh(lo, hi):
    """A trimesh box spanning corners lo (3,) and hi (3,)."""
    import trimesh

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return trimesh.creation.box(extents=hi - lo, transform=pose(np.eye(3), (lo + hi) / 2.0))


def _tri(mesh, rgba=None) -> TriangleMesh:
    colors = None
    if rgba is not None:
        colors = np.tile(np.round(np.asarray(rgba) * 255).astype(np.uint8), (len(mesh.vertices), 1))
    return TriangleMesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), colors)


def part_from_boxes(
    name: str,
    boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]],
    material: Material,
    parent: str | None = None,
    joint: Joint | None = None,
    vertex_colors: bool = False,
) -> Part:
    """A part made of non-overlapping boxes ``[(lo, hi), ...]`` in the asset frame."""
    import trimesh

    pieces = [box_mesh(lo, hi) for lo, hi in boxes]
    visual = trimesh.util.concatenate(pieces)
    assert visual.is_watertight and visual.is_volume
    visual.density = material.density_kg_m3
    inertial = Inertial(float(visual.mass), np.asarray(visual.center_mass), np.asarray(visual.moment_inertia))
    return Part(
        name=name,
        parent=parent,
        joint=joint,
        visual=_tri(visual, material.rgba if vertex_colors else None),
        collision=tuple(_tri(p) for p in pieces),
        material=material,
        inertial=inertial,
    )


def box_asset(name: str, size_m, material: Material = CARDBOARD, is_fixed: bool = False, label: str = "box") -> ObjectAsset:
    sx, sy, sz = size_m
    part = part_from_boxes("body", [((-sx / 2, -sy / 2, 0.0), (sx / 2, sy / 2, sz))], material, vertex_colors=True)
    return ObjectAsset(name, label, AssetKind.RIGID, (part,), np.array(size_m, float), is_fixed=is_fixed, backend="fixture")


# Cabinet: depth x 0.5, width y 0.8, height z 0.9, front at +X. Upper compartment closed by a
# door hinged on its -Y edge, lower compartment holds a drawer sliding along +X.
CAB_D, CAB_W, CAB_H = 0.5, 0.8, 0.9
T = 0.02  # panel thickness
GAP = 0.003  # clearance between moving parts and the carcass
DOOR_RANGE_RAD = (0.0, np.pi / 2)
DRAWER_RANGE_M = (0.0, 0.35)


def cabinet_asset(name: str = "cabinet", is_fixed: bool = False) -> ObjectAsset:
    x0, x1 = -CAB_D / 2, CAB_D / 2 - T  # carcass depth; the front T is taken by door / drawer front
    y0, y1 = -CAB_W / 2, CAB_W / 2
    mid = CAB_H / 2
    carcass = part_from_boxes(
        "body",
        [
            ((x0, y0, 0.0), (x1, y1, T)),  # bottom
            ((x0, y0, CAB_H - T), (x1, y1, CAB_H)),  # top
            ((x0, y0, T), (x1, y0 + T, CAB_H - T)),  # left side
            ((x0, y1 - T, T), (x1, y1, CAB_H - T)),  # right side
            ((x0, y0 + T, T), (x0 + T, y1 - T, CAB_H - T)),  # back
            ((x0 + T, y0 + T, mid - T / 2), (x1, y1 - T, mid + T / 2)),  # shelf
        ],
        WOOD,
    )
    # Door: panel in front of the upper compartment; hinge line on its outer -Y edge. Axis -Z so
    # that a positive angle swings the door outwards (+X).
    door = part_from_boxes(
        "door",
        [((x1 + GAP, y0, mid + GAP), (CAB_D / 2, y1, CAB_H))],
        WOOD,
        parent="body",
        joint=Joint(JointType.REVOLUTE, np.array([0.0, 0.0, -1.0]), np.array([CAB_D / 2, y0, mid]),
                    *DOOR_RANGE_RAD, damping=0.5, friction=0.05, effort_limit=20.0),
    )
    # Drawer: front panel plus a tray (bottom, two sides, back) inside the lower compartment.
    g = GAP
    bx0, bx1 = x0 + T + 0.05, x1
    by0, by1 = y0 + T + g, y1 - T - g
    bz0, bz1 = T + g, mid - T / 2 - g
    drawer = part_from_boxes(
        "drawer",
        [
            ((x1 + g, y0, 0.0 + g), (CAB_D / 2, y1, mid - g)),  # front panel
            ((bx0, by0, bz0), (bx1, by1, bz0 + T)),  # tray bottom
            ((bx0, by0, bz0 + T), (bx1, by0 + T, bz1 - 0.1)),  # tray side
            ((bx0, by1 - T, bz0 + T), (bx1, by1, bz1 - 0.1)),  # tray side
            ((bx0, by0 + T, bz0 + T), (bx0 + T, by1 - T, bz1 - 0.1)),  # tray back
        ],
        WOOD,
        parent="body",
        joint=Joint(JointType.PRISMATIC, np.array([1.0, 0.0, 0.0]), np.array([x1, 0.0, mid / 2]),
                    *DRAWER_RANGE_M, damping=2.0, friction=0.1, effort_limit=50.0),
    )
    return ObjectAsset(
        name, "cabinet", AssetKind.ARTICULATED, (carcass, door, drawer), np.array([CAB_D, CAB_W, CAB_H]),
        description="two-compartment cabinet with a door and a drawer", is_fixed=is_fixed, backend="fixture",
    )


def pillow_asset(name: str = "pillow") -> ObjectAsset:
    size = (0.4, 0.6, 0.12)
    part = part_from_boxes("body", [((-0.2, -0.3, 0.0), (0.2, 0.3, 0.12))], FABRIC, vertex_colors=True)
    return ObjectAsset(
        name, "pillow", AssetKind.DEFORMABLE, (part,), np.array(size),
        deformable=DeformableSettings(youngs_modulus_pa=5.0e4, poisson_ratio=0.3, damping=0.02, resolution=4),
        backend="fixture",
    )


def fixture_camera() -> Camera:
    """A 640x480 camera at (-1.8, -0.2, 1.4) looking along +X, pitched 25 degrees down."""
    k = CameraIntrinsics(525.0, 525.0, 319.5, 239.5, 640, 480, "flag")
    pitch = np.radians(25.0)
    forward = np.array([np.cos(pitch), 0.0, -np.sin(pitch)])
    right = np.array([0.0, -1.0, 0.0])
    down = np.cross(forward, right)
    r = np.stack([right, down, forward], axis=1)  # columns: camera x, y, z in the world
    return Camera(k, pose(r, (-1.8, -0.2, 1.4)))


def fixture_room() -> Room:
    """Back wall at x = 2 and side walls at y = -2 and y = +2 (normals into the room)."""
    return Room(
        walls=(
            Plane(np.array([-1.0, 0.0, 0.0]), 2.0, "wall", 1000),
            Plane(np.array([0.0, 1.0, 0.0]), 2.0, "wall", 800),
            Plane(np.array([0.0, -1.0, 0.0]), 2.0, "wall", 800),
        )
    )


def bounded_walls_scene() -> Scene:
    """:func:`boxes_scene` in a room whose walls were seen over bounded spans (``Plane.span_m``):
    the back wall from y = -1.5 to 1.2 m, a side wall ending at x = -2 m and going on towards
    +x (an open end), one unbounded."""
    base = boxes_scene()
    back, left, right = base.room.walls
    walls = (dataclasses.replace(back, span_m=(-1.2, 1.5)), dataclasses.replace(left, span_m=(None, 2.0)), right)
    return dataclasses.replace(base, room=Room(walls=walls))


def boxes_scene() -> Scene:
    """Two stacked boxes, a yawed box and a fixed counter, all resting exactly."""
    a = box_asset("box_a", (0.4, 0.5, 0.3))
    b = box_asset("box_b", (0.3, 0.3, 0.2))
    c = box_asset("box_c", (0.25, 0.35, 0.25))
    counter = box_asset("counter", (0.6, 1.2, 0.9), WOOD, is_fixed=True, label="counter")
    objects = (
        PlacedObject(a, pose(np.eye(3), (0.4, -0.6, 0.0)), "floor"),
        PlacedObject(b, pose(rot_z(0.3), (0.4, -0.6, 0.3)), "box_a"),
        PlacedObject(c, pose(rot_z(0.7), (0.2, 0.5, 0.0)), "floor"),
        PlacedObject(counter, pose(rot_z(np.pi), (1.6, 0.3, 0.0)), "floor"),
    )
    return Scene(fixture_camera(), fixture_room(), objects)


def cabinet_scene(is_fixed: bool = False) -> Scene:
    """The articulated cabinet alone, on the floor, front facing the camera (yaw pi)."""
    cab = cabinet_asset(is_fixed=is_fixed)
    return Scene(fixture_camera(), fixture_room(), (PlacedObject(cab, pose(rot_z(np.pi), (1.2, 0.0, 0.0)), "floor"),))


def mixed_scene() -> Scene:
    """Boxes, the cabinet and a box on top of the cabinet (a support chain)."""
    base = boxes_scene()
    cab = cabinet_asset()
    top = box_asset("box_on_cabinet", (0.2, 0.25, 0.15))
    objs = base.objects + (
        PlacedObject(cab, pose(rot_z(np.pi), (1.2, -0.9, 0.0)), "floor"),
        PlacedObject(top, pose(rot_z(0.2), (1.2, -0.9, CAB_H)), "cabinet"),
    )
    return Scene(base.camera, base.room, objs)


def pillow_scene() -> Scene:
    """A soft pillow on a box: exercises the deformable (flex) export."""
    box = box_asset("box_a", (0.4, 0.6, 0.3))
    objs = (
        PlacedObject(box, pose(np.eye(3), (0.5, 0.0, 0.0)), "floor"),
        PlacedObject(pillow_asset(), pose(np.eye(3), (0.5, 0.0, 0.3)), "box_a"),
    )
    return Scene(fixture_camera(), fixture_room(), objs)
