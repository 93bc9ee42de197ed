"""Movable objects caged by static ones: the static collision that holds them is cut back.

An object left where it was seen as static background keeps its generated collision pieces. Where
a movable object's completion wraps around one of those pieces (an open shelf whose compartments
hold a static bed's slab, both reconstructed from one view), the two do not overlap, yet the
movable object cannot slide in any direction: a robot could not push it, and the twin is not the
room (in the room the two stand side by side). Such an object is *caged*: shifted by
:data:`CAGE_TRAVEL_M` along each of :data:`DIRECTIONS` horizontal directions, it reaches more than
:data:`BLOCK_DEPTH_M` into a static piece or a wall every time.

For a caged object, every static piece reaching into the convex hull of its collision pieces is cut
by one plane to the outside of that hull (``layout.trim.clip_convex``: a cut convex piece is still
convex), along the axis that keeps most of the piece (so the bed keeps its slab up to the shelf's
side, not a strip of it); a piece with nothing left outside is dropped. The static space inside a
movable object's outline is that object's. Nothing moves: poses, visual meshes, masses and the
movable object itself are unchanged; the report says whose collision was cut, for whom.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from layout.trim import TRIM_CLEARANCE_M, clip_convex
from scene_builder.model import ObjectAsset, Plane, TriangleMesh

__all__ = ["CAGE_TRAVEL_M", "caged", "uncage"]

#: A movable object must be able to slide this far in some horizontal direction.
CAGE_TRAVEL_M = 0.03
DIRECTIONS = 8
BLOCK_DEPTH_M = 0.002
_STEPS = 3  # the slide is checked at 1/3, 2/3 and all of CAGE_TRAVEL_M


def _world(mesh: TriangleMesh, world_from_asset: np.ndarray) -> np.ndarray:
    return mesh.vertices_m @ world_from_asset[:3, :3].T + world_from_asset[:3, 3]


def _distances(moving: list[np.ndarray], statics: list[np.ndarray]):
    """A function of a shift (3,) giving the deepest penetration (m, >= 0) of the ``moving``
    pieces so shifted into the ``statics`` (MuJoCo's GJK/EPA on mesh geoms: each piece is
    convex)."""
    import mujoco

    spec = mujoco.MjSpec()
    body = spec.worldbody.add_body(name="pieces", mocap=True)
    for k, v in enumerate(moving + statics):
        spec.add_mesh(name=f"p{k}", uservert=v.ravel().tolist())
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"p{k}")
    m = spec.compile()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    base = d.geom_xpos.copy()
    ids = np.arange(len(moving))
    fromto = np.zeros(6)

    def depth(shift: np.ndarray) -> float:
        d.geom_xpos[:] = base
        d.geom_xpos[ids] += shift
        worst = 0.0
        for a in ids:
            for b in range(len(moving), len(moving) + len(statics)):
                worst = min(worst, float(mujoco.mj_geomDistance(m, d, int(a), int(b), 0.0, fromto)))
        return -worst

    return depth


def caged(moving: list[np.ndarray], statics: list[np.ndarray], walls: tuple[Plane, ...]) -> bool:
    """Whether the pieces ``moving`` (world vertices, (V, 3) each) cannot slide CAGE_TRAVEL_M in
    any of DIRECTIONS horizontal directions without reaching BLOCK_DEPTH_M into one of
    ``statics`` or behind a wall."""
    if not statics:
        return False
    depth = _distances(moving, statics)
    allv = np.concatenate(moving)
    for k in range(DIRECTIONS):
        a = 2.0 * np.pi * k / DIRECTIONS
        u = np.array([np.cos(a), np.sin(a), 0.0])
        free = True
        for s in np.linspace(CAGE_TRAVEL_M / _STEPS, CAGE_TRAVEL_M, _STEPS):
            if any(float(np.min((allv + s * u) @ w.normal) + w.offset_m) < -BLOCK_DEPTH_M for w in walls) or depth(s * u) > BLOCK_DEPTH_M:
                free = False
                break
        if free:
            return False
    return True


def _hull_normals(v: np.ndarray) -> np.ndarray:
    from scipy.spatial import ConvexHull, QhullError

    try:
        eq = ConvexHull(v).equations[:, :3]
    except (QhullError, ValueError):
        return np.zeros((0, 3))
    return eq / np.linalg.norm(eq, axis=1, keepdims=True)


def _cut_outside(piece: np.ndarray, hull: np.ndarray) -> tuple[TriangleMesh | None, bool]:
    """(the part of convex ``piece`` (V, 3) kept outside the convex ``hull`` (H, 3) by the one
    plane cut that keeps most of it, or None when none keeps any; whether it reached in at
    all). The cut face lies TRIM_CLEARANCE_M outside the hull."""
    from scipy.spatial import ConvexHull

    a = 2.0 * np.pi * np.arange(DIRECTIONS) / DIRECTIONS
    horizontal = np.column_stack([np.cos(a), np.sin(a), np.zeros(DIRECTIONS)])
    axes = np.concatenate([_hull_normals(hull), -_hull_normals(piece), horizontal, np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])])
    # Along n the hull starts at min(hull . n): the piece is apart when it ends before that.
    starts = (hull @ axes.T).min(axis=0)
    if np.any((piece @ axes.T).max(axis=0) <= starts + 1e-9):
        return None, False
    best, best_volume = None, 0.0
    for n, start in zip(axes, starts):
        kept = clip_convex(piece, n, float(start) - TRIM_CLEARANCE_M)
        if kept is None:
            continue
        volume = float(ConvexHull(kept.vertices_m).volume)
        if volume > best_volume:
            best, best_volume = kept, volume
    return best, True


def uncage(moving: list[np.ndarray], asset: ObjectAsset, world_from_asset: np.ndarray) -> ObjectAsset:
    """``asset`` (static, placed at ``world_from_asset``) with every collision piece that reaches
    into the convex hull of the ``moving`` pieces (world vertices) cut back outside it (see the
    module docstring); the asset itself when none reaches in (a static part may be left with
    no piece: it is background, simulated as its pieces only)."""
    hull = np.concatenate(moving)
    inv = np.linalg.inv(world_from_asset)
    parts = []
    changed = False
    for part in asset.parts:
        pieces = []
        for piece in part.collision:
            kept, reached = _cut_outside(_world(piece, world_from_asset), hull)
            if not reached:
                pieces.append(piece)
                continue
            changed = True
            if kept is not None:
                pieces.append(TriangleMesh(kept.vertices_m @ inv[:3, :3].T + inv[:3, 3], kept.faces))
        parts.append(dataclasses.replace(part, collision=tuple(pieces)))
    return dataclasses.replace(asset, parts=tuple(parts)) if changed else asset
