"""The naive baseline of ``scene-builder bench``: the placement of a published scene application,
as a :class:`~scene_builder.model.Scene` that goes through the project's exporter and physics
check like the pipeline's (see :mod:`scene_builder.bench.suites`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scene_builder import frames
from scene_builder.errors import InputError
from scene_builder.model import AssetKind, Camera, ObjectAsset, Perception, PlacedObject, Room, Scene

__all__ = ["BASELINE_DENSITY_KG_M3", "baseline_box_asset", "naive_baseline"]

BASELINE_DENSITY_KG_M3 = 500.0


# World X = camera z, world Y = camera -x, world Z = camera -y.
_BASE_R_WORLD_CAM = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def baseline_box_asset(name: str, label: str, size_m) -> ObjectAsset:
    """A free, solid, single-part box asset of extents ``size_m`` (3,) (asset frame: x, y, z),
    density ``BASELINE_DENSITY_KG_M3``, friction of the generation table's wood; mass and inertia
    by integration over the box (``generation.assembly``, as for every generated asset)."""
    from generation.assembly import ConvexSolids, PartSpec, assemble_asset, box_solid
    from generation.materials import material

    half = np.asarray(size_m, dtype=np.float64) / 2.0
    mat = dataclasses.replace(material("wood"), name="baseline", density_kg_m3=BASELINE_DENSITY_KG_M3, source="naive baseline: one density for everything")
    part = PartSpec("body", None, ConvexSolids((box_solid([-half[0], -half[1], 0.0], [half[0], half[1], 2.0 * half[2]]),)), mat)
    return assemble_asset(name, label, [part], kind=AssetKind.RIGID, is_fixed=False, backend="naive-baseline")


def naive_baseline(perception: Perception, max_depth_m: float = 10.0) -> Scene:
    """The naive placement as a :class:`Scene`: for each perceived object, the axis-aligned box of
    its depth points (its mask on the observed depth) in the camera frame, as a free box asset.

    The scene's world is the camera's axes permuted (world Z = camera -y: gravity along camera +y,
    world X = camera z), its floor ``z = 0`` at the lowest observed point of the whole image, no
    walls; every box stays where its camera-frame box is (no penetration handling, no settling).
    """
    obs = perception.observation
    k = obs.intrinsics
    depth = obs.depth_m.astype(np.float64)
    valid = (depth > 0) & (depth < max_depth_m)
    if not valid.any():
        raise InputError("the observation has no valid depth; the baseline needs depth")
    pts = k.unproject(depth)
    floor_y = float(pts[..., 1][valid].max())  # camera y points down: the lowest point has the largest y
    world_from_camera = frames.pose(_BASE_R_WORLD_CAM, (0.0, 0.0, floor_y))
    placed = []
    for o in perception.objects:
        m = o.mask & valid
        if not m.any():
            continue
        p = pts[m]
        lo, hi = p.min(axis=0), p.max(axis=0)
        size_cam = np.maximum(hi - lo, 0.01)  # a flat patch still makes a 1 cm box
        # The world is a permutation of the camera axes, so the box stays axis-aligned: its
        # extents along world X, Y, Z are the camera z, x, y sizes.
        size_w = np.array([size_cam[2], size_cam[0], size_cam[1]])
        center_w = frames.transform_points(world_from_camera, ((lo + hi) / 2.0)[None])[0]
        bottom_w = center_w - np.array([0.0, 0.0, size_w[2] / 2.0])
        placed.append(PlacedObject(baseline_box_asset(o.name, o.label, size_w), frames.pose(np.eye(3), bottom_w), "floor"))
    return Scene(Camera(k, world_from_camera), Room(), tuple(placed))
