"""Synthetic assets and clutter for the solver's tests and benchmark: boxes, tables (top + legs as
separate convex pieces), random convex pieces, with exact mass properties, dropped overlapping.

Nothing here is used by the pipeline.
"""

from __future__ import annotations

import numpy as np

from scene_builder.frames import pose, rot_z
from scene_builder.model import (
    AssetKind,
    Camera,
    CameraIntrinsics,
    GeneratedAsset,
    Inertial,
    Material,
    ObjectAsset,
    Observation,
    Part,
    Perception,
    Plane,
    Room,
    TriangleMesh,
)

WOOD = Material("wood", 600.0, 0.5, 0.4, 0.1, 1.0e10, 0.3, (0.6, 0.45, 0.3, 1.0), "synthetic")


def _mesh_props(meshes, density: float) -> Inertial:
    """Exact mass, centre of mass and inertia of a union of disjoint closed meshes (trimesh)."""
    import trimesh

    mass, first_moment, inertia = 0.0, np.zeros(3), np.zeros((3, 3))
    parts = []
    for m in meshes:
        tm = trimesh.Trimesh(m.vertices_m, m.faces, process=False)
        tm.density = density
        p = tm.mass_properties
        parts.append((float(p["mass"]), np.asarray(p["center_mass"]), np.asarray(p["inertia"])))
        mass += parts[-1][0]
        first_moment += parts[-1][0] * parts[-1][1]
    com = first_moment / mass
    for m_k, c_k, i_k in parts:
        r = c_k - com
        inertia += i_k + m_k * (np.dot(r, r) * np.eye(3) - np.outer(r, r))
    return Inertial(mass, com, 0.5 * (inertia + inertia.T))


def box_mesh(lo, hi) -> TriangleMesh:
    """Closed box mesh between corners ``lo`` and ``hi`` (3,), outward counter-clockwise faces."""
    import trimesh

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    tm = trimesh.creation.box(extents=hi - lo)
    tm.apply_translation((lo + hi) / 2)
    return TriangleMesh(tm.vertices, tm.faces)


def hull_mesh(points) -> TriangleMesh:
    """Convex hull of (N, 3) points as a closed mesh."""
    import trimesh

    tm = trimesh.convex.convex_hull(np.asarray(points, dtype=np.float64))
    return TriangleMesh(tm.vertices, tm.faces)


def _concat(meshes) -> TriangleMesh:
    v, f, off = [], [], 0
    for m in meshes:
        v.append(m.vertices_m)
        f.append(m.faces + off)
        off += len(m.vertices_m)
    return TriangleMesh(np.concatenate(v), np.concatenate(f))


def asset_from_pieces(name: str, label: str, pieces, fixed: bool = False) -> ObjectAsset:
    """A one-part rigid asset whose collision pieces are ``pieces`` (closed convex meshes)."""
    v = np.concatenate([p.vertices_m for p in pieces])
    part = Part(name="body", parent=None, joint=None, visual=_concat(pieces), collision=tuple(pieces), material=WOOD, inertial=_mesh_props(pieces, WOOD.density_kg_m3))
    return ObjectAsset(name=name, label=label, kind=AssetKind.RIGID, parts=(part,), size_m=np.ptp(v, axis=0), is_fixed=fixed, backend="synthetic")


def box_asset(name: str, size_m, label: str = "box", fixed: bool = False) -> ObjectAsset:
    """A box of extents ``size_m`` (x, y, z) standing on its asset-frame origin."""
    sx, sy, sz = (float(s) for s in size_m)
    return asset_from_pieces(name, label, [box_mesh([-sx / 2, -sy / 2, 0.0], [sx / 2, sy / 2, sz])], fixed)


def table_asset(name: str, size_m, top_m: float = 0.04, leg_m: float = 0.05) -> ObjectAsset:
    """A table: a top slab and four legs, five convex pieces."""
    sx, sy, sz = (float(s) for s in size_m)
    pieces = [box_mesh([-sx / 2, -sy / 2, sz - top_m], [sx / 2, sy / 2, sz])]
    for x in (-sx / 2, sx / 2 - leg_m):
        for y in (-sy / 2, sy / 2 - leg_m):
            pieces.append(box_mesh([x, y, 0.0], [x + leg_m, y + leg_m, sz - top_m]))
    return asset_from_pieces(name, "table", pieces)


def convex_asset(name: str, rng: np.random.Generator, scale_m: float) -> ObjectAsset:
    """A random convex piece (hull of 12 points), shifted so its box bottom centre is the origin."""
    pts = rng.normal(size=(12, 3)) * scale_m * np.array([0.5, 0.5, 0.4])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pts = pts - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    return asset_from_pieces(name, "object", [hull_mesh(pts)])


def surface_points(asset: ObjectAsset, world_from_asset: np.ndarray, rng: np.random.Generator, n: int, noise_m: float) -> np.ndarray:
    """(n, 3) noisy points on the asset's box faces that face -X and +Z (what a camera looking
    along +X from above would see), in the world."""
    lo = np.concatenate([p.visual.vertices_m for p in asset.parts]).min(axis=0)
    hi = np.concatenate([p.visual.vertices_m for p in asset.parts]).max(axis=0)
    u = rng.uniform(size=(n, 3)) * (hi - lo) + lo
    front = rng.uniform(size=n) < 0.5
    u[front, 0] = lo[0]
    u[~front, 2] = hi[2]
    u += rng.normal(scale=noise_m, size=u.shape)
    return u @ world_from_asset[:3, :3].T + world_from_asset[:3, 3]


def empty_perception(walls: tuple[Plane, ...] = (), width_px: int = 64, height_px: int = 48, depth_m: float = 0.0) -> Perception:
    """A perception with a blank small observation, a camera at (-3, 0, 1.5) looking along +X and
    tilted 20 deg down, the given walls and no perceived objects (the solver does not need them).
    depth_m: the planar depth seen at every pixel (0: none, nothing was seen through; 20: a far
    backdrop, the camera saw through the whole room)."""
    k = CameraIntrinsics.from_fov(width_px, height_px, 60.0)
    pitch = np.radians(20.0)
    # OpenCV camera: z forward (+X world, tilted down), x right (-Y world), y down.
    fwd = np.array([np.cos(pitch), 0.0, -np.sin(pitch)])
    right = np.array([0.0, -1.0, 0.0])
    down = np.cross(fwd, right)
    world_from_camera = pose(np.stack([right, down, fwd], axis=1), [-3.0, 0.0, 1.5])
    obs = Observation("synthetic", np.zeros((height_px, width_px, 3), np.uint8), np.full((height_px, width_px), depth_m, np.float32), k, "synthetic")
    return Perception(observation=obs, camera=Camera(k, world_from_camera), room=Room(walls), objects=())


def clutter_layout_config():
    """The layout settings for :func:`clutter`: it drops objects at random, half-sizes deep into
    its walls, up to 5 cm above the floor and tens of centimetres into each other, to exercise the
    solver's pushes; with the defaults (meant for perceived objects) much of it would be left where
    it was dropped as background or stand on legs."""
    from scene_builder.config import LayoutConfig

    return LayoutConfig(max_wall_push_m=1.0, max_lower_m=0.1, max_push_m=10.0)


def clutter(
    n: int, seed: int = 0, points_per_object: int = 60, mix: tuple[float, float, float, float] = (0.6, 0.2, 0.1, 0.1)
) -> tuple[Perception, tuple[GeneratedAsset, ...]]:
    """``n`` objects dropped overlapping on a floor patch sized for about 0.5 m^2 each.

    ``mix``: shares of boxes, random convex pieces, tables (5 pieces) and small boxes started
    near the top of a table (within +-3 cm); default 60/20/10/10 %. Yaws are multiples of 90 deg plus up to +-20 deg;
    floor objects start with their bottom between 3 cm below and 5 cm above the floor.
    Two walls bound the patch (x = -side/2 - 0.05 and y = -side/2 - 0.05, normals into the room).
    """
    rng = np.random.default_rng(seed)
    side = float(np.sqrt(0.5 * n))
    walls = (
        Plane(np.array([1.0, 0.0, 0.0]), side / 2 + 0.05, "wall", 1000),
        Plane(np.array([0.0, 1.0, 0.0]), side / 2 + 0.05, "wall", 800),
    )
    out: list[GeneratedAsset] = []
    tables: list[tuple[np.ndarray, np.ndarray]] = []
    kinds = rng.choice(4, size=n, p=np.asarray(mix) / np.sum(mix))
    kinds = np.sort(kinds)  # tables (2) before things placed on them (3)
    for i, kind in enumerate(kinds):
        name = f"obj_{i:04d}"
        yaw = rng.integers(4) * np.pi / 2 + np.radians(rng.uniform(-20, 20))
        xy = rng.uniform(-side / 2, side / 2, size=2)
        z = rng.uniform(-0.03, 0.05)
        if kind == 0:
            asset = box_asset(name, rng.uniform([0.2, 0.2, 0.15], [0.8, 0.8, 0.9]))
        elif kind == 1:
            asset = convex_asset(name, rng, float(rng.uniform(0.2, 0.6)))
        elif kind == 2:
            asset = table_asset(name, rng.uniform([0.6, 0.8, 0.6], [1.0, 1.4, 0.8]))
            tables.append((xy, asset.size_m))
        else:
            asset = box_asset(name, rng.uniform([0.08, 0.08, 0.05], [0.25, 0.25, 0.3]))
            if tables:
                t_xy, t_size = tables[int(rng.integers(len(tables)))]
                xy = t_xy + rng.uniform(-0.3, 0.3, size=2) * t_size[:2]
                z = float(t_size[2]) + rng.uniform(-0.03, 0.03)
        pose_ = pose(rot_z(yaw), [xy[0], xy[1], z])
        pts = surface_points(asset, pose_, rng, points_per_object, 0.005)
        out.append(GeneratedAsset(asset, pose_, pts))
    return empty_perception(walls), tuple(out)
