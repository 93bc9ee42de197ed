"""Movable objects caged by static ones: the static collision that holds them is cut back.

An object left where it was seen as static background keeps its generated collision pieces. Where
a movable object's completion wraps around one of those pieces (an open shelf whose compartments
hold a static bed's slab, both reconstructed from one view), the two do not overlap, yet the
movable object cannot slide in any direction: a robot could not push it, and the twin is not the
room (in the room the two stand side by side). Such an object is *caged*: shifted by
:data:`CAGE_TRAVEL_M` along each of its four face directions (those a push meets a side along),
it reaches more than :data:`BLOCK_DEPTH_M` into a static piece or a wall every time.

A caged object is freed along one face direction, the cheapest: for each one no wall blocks,
the static pieces it runs into (its *blockers*) would each be cut by the one plane that keeps most
of the piece outside the convex hull of the object's collision pieces (``layout.trim.clip_convex``:
a cut convex piece is still convex). A direction qualifies when every blocker reaches
:data:`MIN_DEPTH_M` or more into that hull (into its compartments: a neighbour touching its side
or a support under it is not cut; a piece wholly inside, a bed leg in its base, goes) and every
static object keeps at least :data:`MIN_KEPT_SHARE` of its collision volume and every part of it
at least one collision piece (a piece wholly inside the hull goes only when its part has
another: a door handle whose one piece lies in the compartment keeps it); of those, the one
removing the least volume is cut, if the object can then slide that way. Nothing
moves: poses, visual meshes, masses and the movable object itself are unchanged; the report says
whose collision was cut, for whom. An object no direction frees stays caged.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from layout.trim import TRIM_CLEARANCE_M, clip_convex
from scene_builder.model import ObjectAsset, Plane, TriangleMesh

__all__ = ["CAGE_TRAVEL_M", "caged", "uncage"]

#: A movable object must be able to slide this far along one of its faces: as far as the push
#: probe (``layout.push``: 6 cm past contact, the settle and a margin: 10 cm) needs free
#: ahead, and a little more.
CAGE_TRAVEL_M = 0.12
DIRECTIONS = 8
BLOCK_DEPTH_M = 0.002
#: A blocker reaching less than this into the object's hull is not cut (see the module docstring).
MIN_DEPTH_M = 0.02
#: The cuts must leave every static object at least this share of its collision volume.
MIN_KEPT_SHARE = 0.8
_STEPS = 5  # the slide is checked every CAGE_TRAVEL_M / _STEPS


def _directions(yaw_rad: float = 0.0) -> np.ndarray:
    """(DIRECTIONS, 3) horizontal unit vectors from ``yaw_rad`` on: the object's four face
    directions (+x, +y, -x, -y of its frame) at even indices, the diagonals between."""
    a = yaw_rad + 2.0 * np.pi * np.arange(DIRECTIONS) / DIRECTIONS
    return np.column_stack([np.cos(a), np.sin(a), np.zeros(DIRECTIONS)])


class _Slider:
    """The ``moving`` pieces (world vertices, (V, 3) each) slid against ``statics``: MuJoCo's
    GJK/EPA on mesh geoms (each piece is convex), positions written directly."""

    def __init__(self, moving: list[np.ndarray], statics: list[np.ndarray], walls: tuple[Plane, ...]) -> None:
        import mujoco

        spec = mujoco.MjSpec()
        body = spec.worldbody.add_body(name="pieces", mocap=True)
        # Only distances are queried: an explicit inertial keeps MuJoCo from summing the pieces'
        # own (sub-millimetre pieces far apart: 'inertia must have positive eigenvalues').
        body.explicitinertial = True
        body.mass, body.inertia = 1.0, [1.0, 1.0, 1.0]
        for k, v in enumerate(moving + statics):
            spec.add_mesh(name=f"p{k}", uservert=v.ravel().tolist())
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"p{k}")
        self.m = spec.compile()
        self.d = mujoco.MjData(self.m)
        mujoco.mj_forward(self.m, self.d)
        self.base = self.d.geom_xpos.copy()
        self.n_moving, self.n_static = len(moving), len(statics)
        self.allv = np.concatenate(moving)
        self.walls = walls

    def depths(self, shift: np.ndarray) -> np.ndarray:
        """(S,) deepest penetration (m, >= 0) of the shifted moving pieces into each static."""
        import mujoco

        d = self.d
        d.geom_xpos[:] = self.base
        d.geom_xpos[: self.n_moving] += shift
        out = np.zeros(self.n_static)
        fromto = np.zeros(6)
        for b in range(self.n_static):
            g = self.n_moving + b
            for a in range(self.n_moving):
                out[b] = max(out[b], -float(mujoco.mj_geomDistance(self.m, d, a, g, 0.0, fromto)))
        return out

    def wall_blocked(self, shift: np.ndarray) -> bool:
        return any(float(np.min(w.clearance_m(self.allv + shift))) < -BLOCK_DEPTH_M for w in self.walls)

    def blockers(self, u: np.ndarray) -> set[int] | None:
        """Static pieces the slide along ``u`` runs into (None: a wall stops it)."""
        hit: set[int] = set()
        for s in np.linspace(CAGE_TRAVEL_M / _STEPS, CAGE_TRAVEL_M, _STEPS):
            if self.wall_blocked(s * u):
                return None
            hit |= set(np.flatnonzero(self.depths(s * u) > BLOCK_DEPTH_M).tolist())
        return hit


def caged(moving: list[np.ndarray], statics: list[np.ndarray], walls: tuple[Plane, ...], yaw_rad: float = 0.0) -> bool:
    """Whether the pieces ``moving`` (world vertices, (V, 3) each) of an object turned by
    ``yaw_rad`` cannot slide CAGE_TRAVEL_M along any of its four face directions without
    reaching BLOCK_DEPTH_M into one of ``statics`` or behind a wall."""
    if not statics:
        return False
    slider = _Slider(moving, statics, walls)
    return all(slider.blockers(u) != set() for u in _directions(yaw_rad)[::2])


def _hull_normals(v: np.ndarray) -> np.ndarray:
    from scipy.spatial import ConvexHull, QhullError

    try:
        eq = ConvexHull(v).equations[:, :3]
    except (QhullError, ValueError):
        return np.zeros((0, 3))
    return eq / np.linalg.norm(eq, axis=1, keepdims=True)


def _volume(v: np.ndarray) -> float:
    from scipy.spatial import ConvexHull, QhullError

    try:
        return float(ConvexHull(v).volume)
    except (QhullError, ValueError):
        return 0.0


def _cut_outside(piece: np.ndarray, hull: np.ndarray) -> tuple[TriangleMesh | None, float]:
    """(the part of convex ``piece`` (V, 3) kept outside the convex ``hull`` (H, 3) by the one
    plane cut that keeps most of it, or None when none keeps any; how deep the piece reaches
    into the hull: the separating-axis depth over the axes tried). The cut face lies
    TRIM_CLEARANCE_M outside the hull."""
    horizontal = _directions()
    axes = np.concatenate([_hull_normals(hull), -_hull_normals(piece), horizontal, np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])])
    on_hull, on_piece = hull @ axes.T, piece @ axes.T
    starts = on_hull.min(axis=0)
    depth = float(np.min(np.minimum(on_piece.max(axis=0) - starts, on_hull.max(axis=0) - on_piece.min(axis=0))))
    best, best_volume = None, 0.0
    for n, start in zip(axes, starts):
        kept = clip_convex(piece, n, float(start) - TRIM_CLEARANCE_M)
        volume = 0.0 if kept is None else _volume(kept.vertices_m)
        if volume > best_volume:
            best, best_volume = kept, volume
    return best, depth


def uncage(moving: list[np.ndarray], statics: list[tuple[ObjectAsset, np.ndarray]], walls: tuple[Plane, ...],
           yaw_rad: float = 0.0) -> list[ObjectAsset] | None:
    """The static assets (each with its world_from_asset) with the collision pieces that cage the
    ``moving`` pieces (world vertices) cut back along the cheapest direction that frees them (see
    the module docstring), in the order given (unchanged ones as they are); None when the
    object is not caged or no direction frees it."""
    ids, world, owner = [], [], []
    pieces_of: dict[tuple[int, int], int] = {}  # (static, part) -> its number of collision pieces
    for k, (asset, t) in enumerate(statics):
        for j, part in enumerate(asset.parts):
            pieces_of[(k, j)] = len(part.collision)
            for i, piece in enumerate(part.collision):
                ids.append((k, j, i))
                world.append(piece.vertices_m @ t[:3, :3].T + t[:3, 3])
                owner.append(k)
    if not world:
        return None
    slider = _Slider(moving, world, walls)
    blocked = [slider.blockers(u) for u in _directions(yaw_rad)[::2]]
    if any(b == set() for b in blocked):
        return None  # not caged
    hull = np.concatenate(moving)
    total = np.bincount(owner, weights=[_volume(v) for v in world], minlength=len(statics))
    cuts: dict[int, tuple[TriangleMesh | None, float, float]] = {}  # piece -> (kept, depth, removed m^3)
    best, best_removed = None, np.inf
    for b in blocked:
        if not b:
            continue
        for p in b - cuts.keys():
            kept, depth = _cut_outside(world[p], hull)
            whole = _volume(world[p])
            cuts[p] = (kept, depth, whole - (0.0 if kept is None else _volume(kept.vertices_m)))
        removed_of = np.bincount([owner[p] for p in b], weights=[cuts[p][2] for p in b], minlength=len(statics))
        if any(cuts[p][1] < MIN_DEPTH_M for p in b) or np.any(removed_of > (1.0 - MIN_KEPT_SHARE) * total):
            continue
        gone: dict[tuple[int, int], int] = {}  # part -> its pieces this direction removes whole
        for p in b:
            if cuts[p][0] is None:
                gone[ids[p][:2]] = gone.get(ids[p][:2], 0) + 1
        if any(n >= pieces_of[part] for part, n in gone.items()):
            continue  # a part would lose its last collision piece
        removed = sum(cuts[p][2] for p in b)
        if removed < best_removed:
            best, best_removed = b, removed
    if best is None:
        return None
    new_world = list(world)
    for p in best:
        kept = cuts[p][0]
        new_world[p] = kept.vertices_m if kept is not None else None
    if caged(moving, [v for v in new_world if v is not None], walls, yaw_rad):
        return None
    out = []
    for k, (asset, t) in enumerate(statics):
        inv = np.linalg.inv(t)
        parts, changed = [], False
        for j, part in enumerate(asset.parts):
            pieces = []
            for i, piece in enumerate(part.collision):
                p = ids.index((k, j, i))
                if p not in best:
                    pieces.append(piece)
                    continue
                changed = True
                kept = cuts[p][0]
                if kept is not None:
                    pieces.append(TriangleMesh(kept.vertices_m @ inv[:3, :3].T + inv[:3, 3], kept.faces))
            parts.append(dataclasses.replace(part, collision=tuple(pieces)))
        out.append(dataclasses.replace(asset, parts=tuple(parts)) if changed else asset)
    return out
