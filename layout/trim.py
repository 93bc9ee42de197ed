"""Trimming overlapping collision pieces where two objects' hidden completions meet.

Generation completes each object's unseen back on its own; where two objects stand close, their
convex collision pieces (hulls of completed voxels or fitted shape parts) can reach a few
centimetres into each other behind what the camera saw. Pushing the objects apart would move
what was seen, by far more than the overlap when pieces interlock. Instead the two pieces are
cut apart by a plane: along the axis of least overlap (the face normals of both pieces, the
separating-axis test), each piece keeps its side of the mid-plane minus half the clearance. A cut
convex piece is still convex (the hull of its kept vertices and of the plane's crossings).

Overlaps up to :data:`MAX_TRIM_M` deep are cut at the mid-plane. A deeper overlap is cut only
where the two objects' visual meshes stay on their own sides of the cut (the pieces bulged into
each other, as hulls of voxel staircases do: the objects themselves do not overlap there); the
cut then lies between the visuals. Otherwise it is a real overlap (a perception error) that the
solver resolves by moving the lighter object. Visual meshes, masses and inertias are left as
they are.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scene_builder.arrays import MIN_PIECE_THICKNESS_M, thickness_m
from scene_builder.model import ObjectAsset, TriangleMesh

__all__ = ["MAX_TRIM_M", "MAX_WALL_TRIM_M", "clip_convex", "separating_plane", "trim_pair", "trim_to_walls"]

#: Deepest overlap (m) between two pieces that is cut away rather than pushed apart.
MAX_TRIM_M = 0.06
#: Gap (m) left between the two cut faces.
TRIM_CLEARANCE_M = 0.002
#: A cut piece smaller than this (m^3) is dropped (when its part keeps another piece).
MIN_PIECE_VOLUME_M3 = 1e-7
#: A deep overlap is cut between what the camera saw of the two objects only where it saw at
#: least this many points of each near the overlap.
MIN_OBSERVED_POINTS = 30
#: A piece holding at least this share of its part's collision volume is never cut away whole.
MAIN_PIECE_SHARE = 0.25
#: A piece whose bottom lies within this of its object's lowest collision point is one it stands on
#: (a cut never takes away the last of them).
FOOT_TOL_M = 0.003


def _face_normals(v: np.ndarray) -> np.ndarray:
    from scipy.spatial import ConvexHull, QhullError

    try:
        eq = ConvexHull(v).equations[:, :3]
    except (QhullError, ValueError):
        return np.eye(3)
    return eq / np.linalg.norm(eq, axis=1, keepdims=True)


def separating_plane(va: np.ndarray, vb: np.ndarray, horizontal: bool = False) -> tuple[np.ndarray, float, float]:
    """The axis of least overlap of two convex vertex sets (N, 3), (M, 3) (world frame) among the
    face normals of both (``horizontal``: their horizontal components, a vertical cut plane): unit
    normal n (A on its negative side), mid-plane offset c (n . x = c) and the overlap depth along
    n (<= 0 when they are apart)."""
    axes = np.concatenate([_face_normals(va), _face_normals(vb)])
    if horizontal:
        axes = np.concatenate([axes[:, :2], np.zeros((len(axes), 1))], axis=1)
        norm = np.linalg.norm(axes, axis=1)
        axes = axes[norm > 1e-6] / norm[norm > 1e-6, None]
        if not len(axes):
            axes = np.eye(3)[:2]
    pa, pb = va @ axes.T, vb @ axes.T
    a_lo, a_hi, b_lo, b_hi = pa.min(0), pa.max(0), pb.min(0), pb.max(0)
    up = a_hi - b_lo  # overlap when A is below B along the axis
    down = b_hi - a_lo  # overlap when A is above B
    k_up, k_down = int(np.argmin(up)), int(np.argmin(down))
    if up[k_up] <= down[k_down]:
        n = axes[k_up]
        return n, 0.5 * float(a_hi[k_up] + b_lo[k_up]), float(up[k_up])
    n = -axes[k_down]
    return n, 0.5 * float(-a_lo[k_down] - b_hi[k_down]), float(down[k_down])


def clip_convex(vertices: np.ndarray, normal: np.ndarray, offset: float) -> TriangleMesh | None:
    """The convex hull of ``vertices`` (N, 3) cut to the half-space ``normal . x <= offset``, as a
    closed outward-facing mesh; None when nothing (or nothing with volume) is left."""
    from scipy.spatial import ConvexHull, QhullError

    v = np.asarray(vertices, dtype=np.float64)
    s = v @ normal - offset
    keep, cut = v[s <= 0], v[s > 0]
    if len(keep) == 0:
        return None
    if len(cut) == 0:
        pts = keep
    else:
        sk, sc = s[s <= 0], s[s > 0]
        # Every segment from a kept to a cut vertex crosses the plane inside the polytope: the
        # crossings include the cut face's corners (those of its edges), the rest lie inside.
        t = sk[:, None] / (sk[:, None] - sc[None, :])
        cross = keep[:, None, :] + t[..., None] * (cut[None, :, :] - keep[:, None, :])
        pts = np.concatenate([keep, cross.reshape(-1, 3)])
    try:
        hull = ConvexHull(pts)
    except (QhullError, ValueError):
        return None
    if hull.volume < MIN_PIECE_VOLUME_M3 or thickness_m(pts[hull.vertices]) < MIN_PIECE_THICKNESS_M:
        return None  # nothing a collision piece can be (the data model's rule) is left
    used = np.unique(hull.simplices)
    remap = -np.ones(len(pts), dtype=np.int64)
    remap[used] = np.arange(len(used))
    faces = remap[hull.simplices]
    verts = pts[used]
    # Outward orientation: each face's normal points away from the centroid.
    centre = verts.mean(axis=0)
    tri = verts[faces]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("ij,ij->i", nrm, tri[:, 0] - centre) < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return TriangleMesh(verts, faces)


def split_around(asset: ObjectAsset, world_from_asset: np.ndarray, lo_xy: np.ndarray, hi_xy: np.ndarray) -> ObjectAsset:
    """``asset`` (placed at ``world_from_asset``) with every collision piece that reaches across a
    vertical side of the world plan rectangle [``lo_xy``, ``hi_xy``] split along it, so that a cut
    around what stands in the rectangle (:func:`trim_pair`: a half-space through a whole convex
    piece) takes only the pieces inside it, not a desk's whole top. Pieces too thin to split stay
    whole. The visuals and mass properties are unchanged (``asset`` itself when nothing is split)."""
    rot, t = world_from_asset[:3, :3], world_from_asset[:3, 3]
    planes = []  # (normal, offset) in the asset frame: the outside of each side is n . x > c
    for axis in (0, 1):
        for sign, value in ((-1.0, float(lo_xy[axis])), (1.0, float(hi_xy[axis]))):
            n_w = np.zeros(3)
            n_w[axis] = sign
            planes.append((rot.T @ n_w, sign * value - float(n_w @ t)))
    parts, changed = [], False
    for part in asset.parts:
        pieces = list(part.collision)
        for n, c in planes:
            out = []
            for m in pieces:
                d = m.vertices_m @ n - c
                if d.min() < 0.0 < d.max():
                    inner, outer = clip_convex(m.vertices_m, n, c), clip_convex(m.vertices_m, -n, -c)
                    if inner is not None and outer is not None:
                        out += [inner, outer]
                        changed = True
                        continue
                out.append(m)
            pieces = out
        parts.append(dataclasses.replace(part, collision=tuple(pieces)))
    return dataclasses.replace(asset, parts=tuple(parts)) if changed else asset


def collision_volume_m3(asset: ObjectAsset) -> float:
    """Total volume (m^3) of an asset's collision pieces (each its convex hull's)."""
    return sum(_volume(m) for p in asset.parts for m in p.collision)


def _volume(mesh: TriangleMesh) -> float:
    """Volume (m^3) of a closed convex piece (its hull's; 0 when degenerate)."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        return float(ConvexHull(mesh.vertices_m).volume)
    except (QhullError, ValueError):
        return 0.0


def _world(mesh: TriangleMesh, world_from_asset: np.ndarray) -> np.ndarray:
    return mesh.vertices_m @ world_from_asset[:3, :3].T + world_from_asset[:3, 3]


#: Points spread over each visual mesh to find where it lies inside the other object's pieces.
VISUAL_SAMPLES = 3000


def _surface_points(vertices: np.ndarray, faces: np.ndarray, count: int = VISUAL_SAMPLES) -> np.ndarray:
    """The mesh's vertices plus ``count`` points spread over its faces by area (fixed seed:
    deterministic), (V + count, 3): a face can cross a piece none of its corners is in."""
    if len(faces) == 0:
        return vertices
    t = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    if area.sum() <= 0:
        return vertices
    rng = np.random.default_rng(0)
    f = rng.choice(len(t), size=count, p=area / area.sum())
    r1, r2 = rng.random(count), rng.random(count)
    flip = r1 + r2 > 1.0
    r1[flip], r2[flip] = 1.0 - r1[flip], 1.0 - r2[flip]
    pts = t[f, 0] + r1[:, None] * (t[f, 1] - t[f, 0]) + r2[:, None] * (t[f, 2] - t[f, 0])
    return np.concatenate([vertices, pts])


def _inside(points: np.ndarray, hull_vertices: np.ndarray) -> np.ndarray:
    """(N,) bool: which points lie inside the convex hull of ``hull_vertices``."""
    from scipy.spatial import ConvexHull, QhullError

    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    try:
        eq = ConvexHull(hull_vertices).equations
    except (QhullError, ValueError):
        return np.zeros(len(points), dtype=bool)
    return np.all(points @ eq[:, :3].T + eq[:, 3] <= 1e-9, axis=1)


def _cut_offset(n: np.ndarray, c: float, depth: float, va_vis: np.ndarray, vb_vis: np.ndarray, ma: np.ndarray, mb: np.ndarray,
                max_depth_m: float, strict: bool = False) -> float | None:
    """Where to cut two overlapping pieces along ``n`` (A on the negative side): the mid-plane
    ``c`` for a shallow overlap; for a deep one the offset nearest ``c`` that keeps A's visual
    vertices inside B's piece on A's side and B's inside A's piece on B's side, give or take
    half of ``max_depth_m`` (None when no such offset exists: the objects themselves overlap
    there by more than ``max_depth_m``). ``strict``: for any depth, an offset with every such
    visual vertex on its own side (no tolerance), None when there is none."""
    if depth <= max_depth_m and not strict:
        return c
    a_in = va_vis[_inside(va_vis, mb)] @ n
    b_in = vb_vis[_inside(vb_vis, ma)] @ n
    # The visuals themselves may overlap by up to max_depth_m (voxel surfaces are up to a voxel
    # off), each reaching at most half of that past the cut; a deeper visual overlap is real.
    # Strict: every visual vertex on its own side with the cut faces' clearance.
    slack = -TRIM_CLEARANCE_M if strict else max_depth_m / 2
    lo = float(a_in.max()) - slack if len(a_in) else -np.inf
    hi = float(b_in.min()) + slack if len(b_in) else np.inf
    if lo > hi:
        return None
    return float(np.clip(c, lo, hi))


def _observed_offset(n: np.ndarray, c: float, va: np.ndarray, vb: np.ndarray, obs_a: np.ndarray | None, obs_b: np.ndarray | None) -> float | None:
    """For two pieces whose visuals overlap deeply: a cut along ``n`` (A on the negative side)
    that keeps what the camera saw of each object on its own side, near the overlap (the points
    of ``obs_a`` / ``obs_b`` (N, 3) within the pieces' common box grown by 2 cm; 2 % of them may
    be stray depth); None when they interleave there, or when fewer than
    :data:`MIN_OBSERVED_POINTS` of either were seen there."""
    if obs_a is None or obs_b is None or not len(obs_a) or not len(obs_b):
        return None
    lo_box = np.maximum(va.min(axis=0), vb.min(axis=0)) - 0.02
    hi_box = np.minimum(va.max(axis=0), vb.max(axis=0)) + 0.02
    pa = obs_a[np.all((obs_a >= lo_box) & (obs_a <= hi_box), axis=1)] @ n
    pb = obs_b[np.all((obs_b >= lo_box) & (obs_b <= hi_box), axis=1)] @ n
    if len(pa) < MIN_OBSERVED_POINTS or len(pb) < MIN_OBSERVED_POINTS:
        return None  # too little seen there of one of them to say where either ends
    lo = float(np.quantile(pa, 0.98)) + TRIM_CLEARANCE_M
    hi = float(np.quantile(pb, 0.02)) - TRIM_CLEARANCE_M
    if lo > hi:
        return None
    return float(np.clip(c, lo, hi))


#: Deepest reach (m) of an object's collision into a wall that is cut at the wall, not pushed.
MAX_WALL_TRIM_M = 0.15


def trim_to_walls(asset: ObjectAsset, t: np.ndarray, walls, clearance_m: float, observed: np.ndarray | None = None) -> tuple[ObjectAsset, float]:
    """``asset`` (at the (4, 4) pose ``t``) with its collision pieces cut to the room side of
    every wall (a ``clearance_m`` gap), where they reach at most :data:`MAX_WALL_TRIM_M` into it
    and what the camera saw of the object (``observed``: (N, 3) world points, 2 % stray allowed)
    stays on the room side: a completion that reaches behind the wall is completion, not
    object. A part never loses its last piece. Returns the asset (the same object when nothing
    was cut) and the deepest reach cut."""
    cut_depth = 0.0
    parts = []
    changed = False
    for part in asset.parts:
        pieces = list(part.collision)
        for w in walls:
            n = np.asarray(w.normal, dtype=np.float64)
            reach = 0.0
            for m in pieces:
                if m is not None:  # (a piece wholly past a bounded wall's end is not in it)
                    reach = max(reach, clearance_m - float(np.min(w.clearance_m(_world(m, t)))))
            if reach <= 1e-5 or reach > MAX_WALL_TRIM_M + clearance_m:
                continue
            seen = w.clearance_m(observed) if observed is not None and len(observed) else np.zeros(0)
            seen = seen[np.isfinite(seen)]
            if len(seen) and float(np.quantile(seen, 0.02)) < -0.01:
                continue  # the camera saw it behind the wall plane: the plane is off, not the object
            # Room side: n . (R v + tr) + off >= clearance  <=>  (-R^T n) . v <= off - clearance + n . tr
            na = -(t[:3, :3].T @ n)
            offset = float(w.offset_m - clearance_m + n @ t[:3, 3])
            new = [None if m is None else clip_convex(m.vertices_m, na, offset) for m in pieces]
            if not any(m is not None for m in new):
                continue  # the whole part lies behind the wall: not a completion error to cut
            pieces = new
            cut_depth = max(cut_depth, reach - clearance_m)
        kept = tuple(m for m in pieces if m is not None)
        if len(kept) != len(part.collision) or any(x is not y for x, y in zip(kept, part.collision)):
            changed = True
            part = dataclasses.replace(part, collision=kept)
        parts.append(part)
    return (dataclasses.replace(asset, parts=tuple(parts)) if changed else asset), cut_depth


def trim_pair(
    a: ObjectAsset,
    ta: np.ndarray,
    b: ObjectAsset,
    tb: np.ndarray,
    max_depth_m: float = MAX_TRIM_M,
    observed_a: np.ndarray | None = None,
    observed_b: np.ndarray | None = None,
) -> tuple[ObjectAsset, ObjectAsset, float, float]:
    """Cut apart every pair of overlapping collision pieces of assets ``a`` and ``b`` (placed at
    the (4, 4) poses ``ta``, ``tb``): at the mid-plane when the overlap is at most
    ``max_depth_m`` deep, between the two visuals when deeper (see the module docstring); where
    the visuals themselves overlap deeply (one object's completion of what the camera did not see
    reaches into the other), between what the camera saw of each (``observed_a``,
    ``observed_b``: (N, 3) world points at these poses), when that separates them: the objects
    stay where they were seen instead of being pushed apart.
    Returns the two assets (unchanged objects when nothing was cut), the deepest overlap cut, and
    the deepest overlap left (the visuals overlap, or a part would lose its last piece)."""
    pieces_a = {p.name: list(p.collision) for p in a.parts}
    pieces_b = {p.name: list(p.collision) for p in b.parts}
    parts_a, parts_b = {p.name: p for p in a.parts}, {p.name: p for p in b.parts}
    part_volumes: dict[int, float] = {}  # id(part) -> its collision volume, computed when first needed

    def main_piece(mesh: TriangleMesh, part) -> bool:
        """A main piece of its part (at least :data:`MAIN_PIECE_SHARE` of the part's collision
        volume): a cut may shrink it, never remove it whole."""
        if id(part) not in part_volumes:
            part_volumes[id(part)] = sum(_volume(m) for m in part.collision)
        return _volume(mesh) >= MAIN_PIECE_SHARE * part_volumes[id(part)]

    vis_a = np.concatenate([_surface_points(_world(p.visual, ta), p.visual.faces) for p in a.parts])
    vis_b = np.concatenate([_surface_points(_world(p.visual, tb), p.visual.faces) for p in b.parts])
    # Pieces reaching within FOOT_TOL_M of an object's lowest collision point are what it stands on.
    foot_a = min(float(m.vertices_m[:, 2].min()) for p in a.parts for m in p.collision) + FOOT_TOL_M
    foot_b = min(float(m.vertices_m[:, 2].min()) for p in b.parts for m in p.collision) + FOOT_TOL_M

    def last_foot(mesh: TriangleMesh, pieces: dict[str, list], foot: float) -> bool:
        """Whether ``mesh`` is the only piece left that its object stands on (a sofa keeps its
        other feet when a cut takes one away; a monitor on its base plate has none)."""
        feet = [m for ms in pieces.values() for m in ms if m is not None and float(m.vertices_m[:, 2].min()) <= foot]
        return len(feet) == 1 and feet[0] is mesh

    def offset_for(n: np.ndarray, mid: float, depth: float, va: np.ndarray, vb: np.ndarray) -> float | None:
        """Where the cut along ``n`` lies: between the visuals, else between what was seen."""
        c = _cut_offset(n, mid, depth, vis_a, vis_b, va, vb, max_depth_m)
        return _observed_offset(n, mid, va, vb, observed_a, observed_b) if c is None else c

    def cut_along(n: np.ndarray, offset: float, ma: TriangleMesh, mb: TriangleMesh):
        # Plane in each asset's frame: n . (R v + t) = c  ->  (R^T n) . v = c - n . t
        na, nb = ta[:3, :3].T @ n, tb[:3, :3].T @ n
        return (clip_convex(ma.vertices_m, na, offset - float(n @ ta[:3, 3]) - TRIM_CLEARANCE_M / 2),
                clip_convex(mb.vertices_m, -nb, -(offset - float(n @ tb[:3, 3])) - TRIM_CLEARANCE_M / 2))
    cut_depth, left_depth = 0.0, 0.0
    for pa_name in pieces_a:
        for pb_name in pieces_b:
            for i in range(len(pieces_a[pa_name])):
                for j in range(len(pieces_b[pb_name])):
                    ma, mb = pieces_a[pa_name][i], pieces_b[pb_name][j]
                    if ma is None or mb is None:
                        continue
                    va, vb = _world(ma, ta), _world(mb, tb)
                    if np.any(va.min(0) >= vb.max(0)) or np.any(vb.min(0) >= va.max(0)):
                        continue
                    n, c, depth = separating_plane(va, vb)
                    if depth <= 0.0:
                        continue
                    c = offset_for(n, c, depth, va, vb)

                    def loses_foot(cut_a, cut_b) -> bool:
                        return (cut_a is None and last_foot(ma, pieces_a, foot_a)) or (cut_b is None and last_foot(mb, pieces_b, foot_b))

                    new_a, new_b = cut_along(n, c, ma, mb) if c is not None else (None, None)
                    if c is not None and loses_foot(new_a, new_b):
                        # The cut would take away a piece an object stands on (a monitor's base
                        # plate inside a cabinet's completed side, sunrgbd_imvotenet_000002: it
                        # fell onto its stem and toppled): cut apart sideways instead where that
                        # keeps it, else left to the solver's pushes.
                        n, c, depth = separating_plane(va, vb, horizontal=True)
                        c = offset_for(n, c, depth, va, vb) if depth > 0.0 else None
                        if c is not None:
                            new_a, new_b = cut_along(n, c, ma, mb)
                            if loses_foot(new_a, new_b):
                                c = None
                    if c is None:
                        left_depth = max(left_depth, depth)
                        continue

                    def loses_main_piece(cut_a, cut_b) -> bool:
                        return (cut_a is None and main_piece(ma, parts_a[pa_name])) or (cut_b is None and main_piece(mb, parts_b[pb_name]))

                    if loses_main_piece(new_a, new_b):
                        # The cut would remove a main piece whole (a table top inside the bulged
                        # hull of a bed's piece, within the visuals' tolerance): cut exactly
                        # between the visuals instead where that keeps both main pieces.
                        strict = _cut_offset(n, c, depth, vis_a, vis_b, va, vb, max_depth_m, strict=True)
                        if strict is not None:
                            kept = cut_along(n, strict, ma, mb)
                            if not loses_main_piece(*kept):
                                new_a, new_b = kept
                    alive_a = sum(m is not None for m in pieces_a[pa_name]) - 1 + (new_a is not None)
                    alive_b = sum(m is not None for m in pieces_b[pb_name]) - 1 + (new_b is not None)
                    if alive_a == 0 or alive_b == 0:
                        left_depth = max(left_depth, depth)
                        continue
                    pieces_a[pa_name][i], pieces_b[pb_name][j] = new_a, new_b
                    cut_depth = max(cut_depth, depth)

    def rebuilt(asset: ObjectAsset, pieces: dict[str, list]) -> ObjectAsset:
        parts = []
        changed = False
        for p in asset.parts:
            new = tuple(m for m in pieces[p.name] if m is not None)
            if len(new) != len(p.collision) or any(x is not y for x, y in zip(new, p.collision)):
                changed = True
                p = dataclasses.replace(p, collision=new)
            parts.append(p)
        return dataclasses.replace(asset, parts=tuple(parts)) if changed else asset

    return rebuilt(a, pieces_a), rebuilt(b, pieces_b), cut_depth, left_depth
