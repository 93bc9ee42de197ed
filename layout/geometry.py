"""Geometry of collision pieces for the layout solver: pieces in world axes, slab clipping, 2-D
convex hulls, the horizontal minimum-translation vector, top (support) surfaces and footprints.

Everything here is numpy only. The solver moves objects by translation (their rotation is fixed
after yaw snapping), so a piece is stored once with its vertices *relative to the object's
position*, already rotated into world axes: ``world = verts_rel + position``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scene_builder.model import ObjectAsset

# A piece thinner than this along its thinnest principal axis cannot be hulled by MuJoCo/qhull
# ("coplanar vertices"); it is thickened symmetrically to this thickness (see _thicken).
MIN_PIECE_THICKNESS_M = 5e-4
# Angular resolution of the candidate separating axes kept per piece.
AXIS_BIN_DEG = 0.5


@dataclass(frozen=True, eq=False)
class Piece:
    """One convex collision piece of an object, in world axes relative to the object's position.

    verts_rel_m: (V, 3) float64. edges: (E, 2) int64 unique vertex-index pairs of the hull edges.
    lo_rel_m, hi_rel_m: (3,) axis-aligned bounds of ``verts_rel_m``.
    axes_xy: (A, 2) unit vectors: every edge normal that the floor projection of this piece,
      clipped to any horizontal slab, can have (see :func:`separating_axes`).
    """

    verts_rel_m: np.ndarray
    edges: np.ndarray
    lo_rel_m: np.ndarray
    hi_rel_m: np.ndarray
    axes_xy: np.ndarray


@dataclass(frozen=True, eq=False)
class SupportSurface:
    """An upward-facing horizontal face on top of a convex piece, relative to the object position.

    height_rel_m: z of the face. polygon_rel_m: (H, 2) counter-clockwise convex polygon (x, y).
    """

    height_rel_m: float
    polygon_rel_m: np.ndarray


def _thicken(verts: np.ndarray) -> np.ndarray:
    """(V, 3) -> (V', 3): a flat piece (a board modelled as one face) made into a thin slab.

    MuJoCo (qhull) rejects coplanar vertex sets; a 0.5 mm slab changes contacts by at most
    0.25 mm, below the solver's clearance.
    """
    centred = verts - verts.mean(axis=0)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    thin_axis = vt[-1]
    thickness = float(np.ptp(centred @ thin_axis))
    if len(verts) >= 4 and thickness >= MIN_PIECE_THICKNESS_M:
        return verts
    half = 0.5 * MIN_PIECE_THICKNESS_M * thin_axis
    return np.concatenate([verts - half, verts + half])


def _unique_edges(faces: np.ndarray) -> np.ndarray:
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    return np.unique(e, axis=0)


def _all_pair_edges(n: int) -> np.ndarray:
    i, j = np.triu_indices(n, k=1)
    return np.stack([i, j], axis=1).astype(np.int64)


def separating_axes(verts: np.ndarray, edges: np.ndarray, faces: np.ndarray | None) -> np.ndarray:
    """(A, 2) candidate separating axes in the floor plane for a convex piece.

    The projection of the piece clipped to a slab ``z_lo <= z <= z_hi`` is bounded by projections
    of (a) the piece's own edges and (b) the lines where the slab planes cut its faces; a cut line
    of a face with normal n is perpendicular to n's horizontal part. So the 2-D separating-axis
    test between two such projections only needs the perpendiculars of the projected edges and
    the horizontal parts of the face normals: computed once per piece, no 2-D hull per query.
    """
    cand = []
    d = verts[edges[:, 1], :2] - verts[edges[:, 0], :2]
    cand.append(np.stack([d[:, 1], -d[:, 0]], axis=1))
    if faces is not None and len(faces):
        a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
        cand.append(np.cross(b - a, c - a)[:, :2])
    axes = np.concatenate(cand)
    norm = np.linalg.norm(axes, axis=1)
    axes = axes[norm > 1e-9] / norm[norm > 1e-9, None]
    # An axis and its opposite are the same test: fold to a half-plane, then keep one actual axis
    # per 0.5 deg bin (fine pieces of scanned objects have thousands of edges; any axis gives a
    # valid push, so thinning only makes a push at most marginally longer than the minimum).
    angle = np.mod(np.arctan2(axes[:, 1], axes[:, 0]), np.pi)
    bins = np.floor(angle / np.radians(AXIS_BIN_DEG)).astype(np.int64)
    _, first = np.unique(bins, return_index=True)
    a = angle[np.sort(first)]
    return np.stack([np.cos(a), np.sin(a)], axis=1)


def object_pieces(asset: ObjectAsset, rotation: np.ndarray) -> tuple[Piece, ...]:
    """All convex collision pieces of every part (at rest pose), rotated by ``rotation`` (3, 3).

    Articulated parts are taken at their rest pose (doors closed, drawers in), which is the pose
    the exporters write.
    """
    out = []
    for part in asset.parts:
        for mesh in part.collision:
            v = np.asarray(mesh.vertices_m, dtype=np.float64)
            thick = _thicken(v)
            if thick is v and len(mesh.faces):
                faces = np.asarray(mesh.faces)
                edges = _unique_edges(faces)
            else:
                # Thickened (or face-less) piece: every vertex pair is a superset of the hull
                # edges, which is all slab clipping and the axis set need.
                faces = None
                edges = _all_pair_edges(len(thick))
            rel = thick @ rotation.T
            out.append(Piece(rel, edges, rel.min(axis=0), rel.max(axis=0), separating_axes(rel, edges, faces)))
    return tuple(out)


# Corner k of a box has x = hi when k & 4, y = hi when k & 2, z = hi when k & 1; faces outward.
_BOX_FACES = np.array(
    [[0, 1, 2], [1, 3, 2], [4, 6, 5], [5, 6, 7], [0, 4, 1], [1, 4, 5], [2, 3, 6], [3, 7, 6], [0, 2, 4], [2, 6, 4], [1, 5, 3], [3, 5, 7]],
    dtype=np.int64,
)


def box_piece(lo_m: np.ndarray, hi_m: np.ndarray, rotation: np.ndarray) -> Piece:
    """The box ``lo_m..hi_m`` (3,), (3,) of the asset frame as one piece rotated by ``rotation`` (3, 3).

    A deformable is simulated as a flex grid filling its bounding box (``exporters.mjcf.flex_grid``),
    so the solver must reserve that box, not the rounded collision pieces of the rest shape.
    """
    corners = np.array([[x, y, z] for x in (lo_m[0], hi_m[0]) for y in (lo_m[1], hi_m[1]) for z in (lo_m[2], hi_m[2])], dtype=np.float64)
    rel = corners @ np.asarray(rotation, dtype=np.float64).T
    edges = _unique_edges(_BOX_FACES)
    return Piece(rel, edges, rel.min(axis=0), rel.max(axis=0), separating_axes(rel, edges, _BOX_FACES))


def convex_hull_2d(points: np.ndarray) -> np.ndarray:
    """(N, 2) -> (H, 2) convex hull, counter-clockwise, collinear points dropped (monotone chain).

    Written here because scipy's Qhull raises on the degenerate (collinear, duplicate) point sets
    that slab clipping produces routinely; this returns 1 or 2 points for them.
    """
    p = np.unique(np.round(np.asarray(points, dtype=np.float64), 9), axis=0)
    if len(p) <= 2:
        return p

    def half(pts):
        h: list[np.ndarray] = []
        for q in pts:
            while len(h) >= 2:
                a, b = h[-2], h[-1]
                if (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]) > 1e-15:
                    break
                h.pop()
            h.append(q)
        return h

    lower = half(p)
    upper = half(p[::-1])
    return np.array(lower[:-1] + upper[:-1])


def polygon_area(poly: np.ndarray) -> float:
    """Area of a simple polygon (H, 2) (shoelace)."""
    if len(poly) < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def clip_to_slab_xy(verts: np.ndarray, edges: np.ndarray, z_lo: float, z_hi: float) -> np.ndarray:
    """(M, 2) x, y of a convex polytope's points that generate its intersection with the slab
    ``z_lo <= z <= z_hi``: vertices inside plus edge crossings of both planes. Their convex hull
    is the projection of the clipped polytope on the floor plane."""
    z = verts[:, 2]
    inside = verts[(z >= z_lo) & (z <= z_hi), :2]
    a, b = verts[edges[:, 0]], verts[edges[:, 1]]
    za, zb = a[:, 2], b[:, 2]
    parts = [inside]
    for plane in (z_lo, z_hi):
        cross = (za - plane) * (zb - plane) < 0.0
        if np.any(cross):
            t = (plane - za[cross]) / (zb[cross] - za[cross])
            parts.append(a[cross, :2] + t[:, None] * (b[cross, :2] - a[cross, :2]))
    return np.concatenate(parts) if len(parts) > 1 else inside


def hull_edge_normals(points_xy: np.ndarray) -> np.ndarray:
    """(H, 2) outward unit normals of the edges of the convex hull of (N, 2) points."""
    hull = convex_hull_2d(points_xy)
    if len(hull) < 2:
        return np.zeros((0, 2))
    d = np.roll(hull, -1, axis=0) - hull
    n = np.stack([d[:, 1], -d[:, 0]], axis=1)
    norm = np.linalg.norm(n, axis=1)
    return n[norm > 1e-12] / norm[norm > 1e-12, None]


def horizontal_mtv(xy_a: np.ndarray, xy_b: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, float]:
    """Minimum horizontal translation that separates B from A (separating-axis test in 2-D).

    xy_a, xy_b: (N, 2), (M, 2) points whose convex hulls are the two projections.
    axes: (K, 2) unit candidate axes; with both pieces' :attr:`Piece.axes_xy` they contain every
    edge normal of both projections, so the test is exact for the projections. For the
    slab-clipped pieces it is conservative: separated projections imply separated pieces.
    Returns (direction (2,), overlap_m): moving B by ``direction * overlap_m`` (or A by the
    opposite) makes the projections touch; overlap_m < 0 means already separated by that gap.
    """
    pa, pb = xy_a @ axes.T, xy_b @ axes.T  # (N, K), (M, K)
    # Push B along +axis: needs max_a - min_b; along -axis: max_b - min_a.
    plus = pa.max(axis=0) - pb.min(axis=0)
    minus = pb.max(axis=0) - pa.min(axis=0)
    k_plus, k_minus = int(np.argmin(plus)), int(np.argmin(minus))
    if plus[k_plus] <= minus[k_minus]:
        return axes[k_plus], float(plus[k_plus])
    return -axes[k_minus], float(minus[k_minus])


def top_surfaces(pieces: tuple[Piece, ...]) -> tuple[SupportSurface, ...]:
    """The horizontal top face of each piece that has one (its highest vertices span an area).

    A piece's top is a support surface when the vertices within 1 mm of its highest point span
    more than 1 cm^2 (a board, a table top, a box lid); a pointed or rounded top supports nothing.
    """
    out = []
    for p in pieces:
        top = p.hi_rel_m[2]
        ring = p.verts_rel_m[p.verts_rel_m[:, 2] >= top - 1e-3, :2]
        poly = convex_hull_2d(ring)
        if polygon_area(poly) > 1e-4:
            out.append(SupportSurface(float(top), poly))
    return tuple(out)


#: Top faces of one object within this height of each other form one merged top (a dresser's
#: top completed as many convex pieces is one surface to stand a lamp on) ...
MERGE_BAND_M = 0.03
#: ... when the faces cover this share of the convex hull of their union (not two armrests
#: spanning the seat between them).
MERGE_MIN_COVER = 0.5


def merged_top_surfaces(faces: tuple[SupportSurface, ...]) -> tuple[SupportSurface, ...]:
    """Merged tops of an object's per-piece top faces: each group of faces within
    :data:`MERGE_BAND_M` of the highest one not yet grouped, as the convex hull of their
    polygons at the group's highest height, when the faces cover :data:`MERGE_MIN_COVER` of it
    and the group has more than one face. A completed object's top is often many convex pieces
    whose faces step by millimetres; a thing standing on it overlaps no single one enough."""
    import shapely

    out = []
    left = sorted(range(len(faces)), key=lambda k: -faces[k].height_rel_m)
    while left:
        top = faces[left[0]].height_rel_m
        group = [k for k in left if faces[k].height_rel_m >= top - MERGE_BAND_M]
        left = [k for k in left if k not in group]
        if len(group) < 2:
            continue
        hull = convex_hull_2d(np.concatenate([faces[k].polygon_rel_m for k in group]))
        area = polygon_area(hull)
        if area <= 1e-4:
            continue
        cover = shapely.union_all([shapely.Polygon(faces[k].polygon_rel_m) for k in group if len(faces[k].polygon_rel_m) >= 3]).area
        if cover >= MERGE_MIN_COVER * area:
            out.append(SupportSurface(float(top), hull))
    return tuple(out)


def footprint(pieces: tuple[Piece, ...], band_m: float) -> np.ndarray:
    """(H, 2) convex hull of the vertices within ``band_m`` of the object's lowest point: the
    region it stands on (a box's bottom face, the tips of a chair's legs)."""
    bottom = min(p.lo_rel_m[2] for p in pieces)
    pts = np.concatenate([p.verts_rel_m[p.verts_rel_m[:, 2] <= bottom + band_m, :2] for p in pieces])
    return convex_hull_2d(pts)


def clip_convex_polygons(subject: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """Intersection of two convex counter-clockwise polygons (Sutherland-Hodgman), (K, 2)."""
    out = np.asarray(subject, dtype=np.float64)
    if len(clip) < 3:
        return np.zeros((0, 2))
    for i in range(len(clip)):
        if len(out) == 0:
            break
        a, b = clip[i], clip[(i + 1) % len(clip)]
        edge = b - a
        side = edge[0] * (out[:, 1] - a[1]) - edge[1] * (out[:, 0] - a[0])  # >= 0: inside (left)
        nxt = np.roll(out, -1, axis=0)
        side_n = np.roll(side, -1)
        res = []
        for p, q, sp, sq in zip(out, nxt, side, side_n):
            if sp >= 0:
                res.append(p)
            if (sp >= 0) != (sq >= 0):
                t = sp / (sp - sq)
                res.append(p + t * (q - p))
        out = np.array(res) if res else np.zeros((0, 2))
    return out


def clip_half_plane(poly: np.ndarray, normal_xy: np.ndarray, offset: float) -> np.ndarray:
    """The part of a convex polygon (K, 2) where ``normal_xy . p >= offset`` (Sutherland-Hodgman
    against one half-plane); a point or a segment (K < 3) is kept or dropped whole."""
    pts = np.asarray(poly, dtype=np.float64)
    side = pts @ np.asarray(normal_xy, dtype=np.float64) - offset
    if len(pts) < 3:
        return pts[side >= 0]
    res = []
    for p, q, sp, sq in zip(pts, np.roll(pts, -1, axis=0), side, np.roll(side, -1)):
        if sp >= 0:
            res.append(p)
        if (sp >= 0) != (sq >= 0):
            res.append(p + sp / (sp - sq) * (q - p))
    return np.array(res) if res else np.zeros((0, 2))


def inset_polygon(poly: np.ndarray, inset_m: float) -> np.ndarray:
    """(K, 2) the convex CCW polygon ``poly`` (H, 2) with every edge moved inwards by ``inset_m``
    (the points at least ``inset_m`` inside it); (0, 2) when nothing is left."""
    out = np.asarray(poly, dtype=np.float64)
    if inset_m <= 0.0 or len(out) < 3:
        return out
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        e = b - a
        length = float(np.hypot(e[0], e[1]))
        if length <= 1e-12:
            continue
        # Signed distance to the left of the edge (inside a CCW polygon), minus the inset.
        side = (e[0] * (out[:, 1] - a[1]) - e[1] * (out[:, 0] - a[0])) / length - inset_m
        nxt, side_n = np.roll(out, -1, axis=0), np.roll(side, -1)
        res = []
        for p, q, sp, sq in zip(out, nxt, side, side_n):
            if sp >= 0:
                res.append(p)
            if (sp >= 0) != (sq >= 0):
                res.append(p + sp / (sp - sq) * (q - p))
        if len(res) < 3:
            return np.zeros((0, 2))
        out = np.array(res)
    return out


def placements_inside(poly: np.ndarray, footprint_rel: np.ndarray, inset_m: float = 0.0) -> np.ndarray:
    """(K, 2) convex CCW polygon of the offsets p for which ``footprint_rel + p`` (H, 2) lies inside
    ``poly`` (convex, CCW) shrunk by ``inset_m``: the Minkowski difference, the intersection of
    ``poly - f`` over the footprint's vertices f. Empty (0, 2) when the footprint does not fit.

    Written here (a few lines of clipping) because shapely has no Minkowski difference and the
    polygons are small and convex.
    """
    region = inset_polygon(np.asarray(poly, dtype=np.float64), inset_m)
    if len(region) < 3:
        return np.zeros((0, 2))
    out = region - footprint_rel[0]
    for f in footprint_rel[1:]:
        out = clip_convex_polygons(out, region - f)
        if len(out) < 3 or polygon_area(out) <= 1e-10:
            return np.zeros((0, 2))
    return convex_hull_2d(out)


def closest_point_in_polygon(point: np.ndarray, poly: np.ndarray, inset_m: float) -> np.ndarray:
    """(2,) the point itself when it lies inside ``poly`` shrunk by ``inset_m`` (convex, CCW),
    else the nearest point of the shrunk polygon (approximated by shrinking towards the centroid
    when the inset does not fit)."""
    c = poly.mean(axis=0)
    radius = float(np.min(np.linalg.norm(poly - c, axis=1)))
    scale = max(0.0, 1.0 - inset_m / radius) if radius > 0 else 0.0
    shrunk = c + (poly - c) * scale
    if len(shrunk) < 3 or scale == 0.0:
        return c
    d = np.roll(shrunk, -1, axis=0) - shrunk
    side = d[:, 0] * (point[1] - shrunk[:, 1]) - d[:, 1] * (point[0] - shrunk[:, 0])
    if np.all(side >= 0):
        return point
    # Nearest point on the boundary segments.
    w = point - shrunk
    t = np.clip(np.einsum("ij,ij->i", w, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-18), 0.0, 1.0)
    proj = shrunk + t[:, None] * d
    return proj[int(np.argmin(np.linalg.norm(proj - point, axis=1)))]


SWEEP_STEPS = 8  # joint positions sampled over each moving part's range


def swept_part_boxes(asset, world_from_asset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World AABBs (lo (K, 3), hi (K, 3)) of the collision pieces of every part that moves on a
    revolute or prismatic joint (with the parts attached to it), over SWEEP_STEPS positions of its
    range: the room a door needs to swing and a drawer to slide out. Only a part's own joint is
    swept (a handle rides on its door; nested moving joints take their parent's rest pose)."""
    from scipy.spatial.transform import Rotation

    from scene_builder.model import JointType

    parts = {p.name: p for p in asset.parts}
    children: dict[str, list[str]] = {}
    for p in asset.parts:
        if p.parent is not None:
            children.setdefault(p.parent, []).append(p.name)

    def carried(name: str) -> list[str]:
        out, todo = [], [name]
        while todo:
            n = todo.pop()
            out.append(n)
            todo.extend(children.get(n, ()))
        return out

    rot, trans = world_from_asset[:3, :3], world_from_asset[:3, 3]
    lo, hi = [], []
    for p in asset.parts:
        j = p.joint
        if j is None or j.type not in (JointType.REVOLUTE, JointType.PRISMATIC, JointType.REVOLUTE_PRISMATIC):
            continue
        verts = np.concatenate([piece.vertices_m for n in carried(p.name) for piece in parts[n].collision])
        swept = []
        for q in np.linspace(j.lower, j.upper, SWEEP_STEPS):
            if j.type is JointType.PRISMATIC:
                moved = verts + q * j.axis
            else:
                r = Rotation.from_rotvec(q * j.axis).as_matrix()
                moved = (verts - j.anchor_m) @ r.T + j.anchor_m
            swept.append(moved @ rot.T + trans)
        pts = np.concatenate(swept)
        lo.append(pts.min(axis=0))
        hi.append(pts.max(axis=0))
    if not lo:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return np.array(lo), np.array(hi)
