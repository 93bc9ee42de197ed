"""The static background in the layout: what objects rest on when they were seen on something
that is not itself an object, and the background's collision geometry.

* :class:`BackgroundSupport` answers "what background surface was seen right under this
  object?": the tops of the background columns within :data:`SUPPORT_REACH_M` of the object's
  footprint, in the height band just under its bottom (a counter top, a shelf board's edge, a
  bed seen as background). The surface under the object itself is hidden by the object, so its
  height comes from what was seen around it.
* :func:`support_pad`: the hidden part of that surface, as a thin box under the object's
  footprint at the support height (the object rests exactly on it).
* :func:`column_boxes`: the background's observed surface above the floor and in front of the
  walls as collision boxes: the points in each :data:`CELL_M` x :data:`CELL_M` column, split where
  they leave a vertical gap, each run a box whose top is the run's highest point (so boxes follow
  the observed heights, not a voxel grid), merged along x where neighbours agree; then carved
  clear of every object (:func:`carve`).
* :class:`HiddenBelow` answers "was the space right under this object seen?": an object with
  nothing seen under it whose underside space the camera could not see (hidden behind the
  object itself or a nearer one) stands on what lies below; one the camera saw through under it
  (a picture on a wall, a lamp hung from the ceiling) hangs, and becomes background.
* :func:`absorb`: objects that cannot stand where they were seen join the background.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from layout.geometry import clip_convex_polygons, convex_hull_2d, polygon_area
from scene_builder.frames import transform_points
from scene_builder.model import Background, Camera, ObjectAsset, Observation, Plane, TriangleMesh

__all__ = [
    "BackgroundSupport",
    "CELL_M",
    "HiddenBelow",
    "PAD_THICKNESS_M",
    "SUPPORT_REACH_M",
    "absorb",
    "carve",
    "column_boxes",
    "support_pad",
    "clip_pad",
]

#: How far around an object's footprint the surface it rests on is looked for.
SUPPORT_REACH_M = 0.10
#: Column size for support queries; at least this many column tops in the densest layer make a
#: support; a column whose points go on within CLEAR_ABOVE_M above its top is not a top.
SUPPORT_CELL_M = 0.02
MIN_SUPPORT_CELLS = 3
CLEAR_ABOVE_M = 0.15
#: Layer thickness for the densest-layer vote, and the band kept around it.
LAYER_M = 0.01
#: Thickness of the pad under an object resting on the background.
PAD_THICKNESS_M = 0.03
# A neighbour's piece whose plan overlaps a pad by less than this (m^2, a square millimetre) only
# touches it.
PAD_OVERLAP_MIN_M2 = 1e-6
#: Collision boxes: column size, the vertical gap that splits a column, the thickness given to
#: a run of points (a surface seen from above is a thin slab), least points per run.
CELL_M = 0.05
COLUMN_GAP_M = 0.06
SHELL_M = 0.02
MIN_RUN_POINTS = 3
#: Observed points this close to the floor or a wall plane are the floor's or the wall's.
FLOOR_BAND_M = 0.03
WALL_BAND_M = 0.05
#: Neighbouring column boxes whose bottoms and tops agree within this merge into one.
MERGE_TOL_M = 0.01
#: Boxes keep this gap from objects.
CARVE_CLEARANCE_M = 0.002
#: A box cut below an object keeps at least this thickness, else it is dropped.
MIN_BOX_THICKNESS_M = 0.01


def vertex_normals(mesh: TriangleMesh) -> np.ndarray:
    """(V, 3) area-weighted unit vertex normals (faces are counter-clockwise seen from outside:
    for the background surface, seen from the camera)."""
    v, f = mesh.vertices_m, mesh.faces
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    out = np.zeros_like(v)
    for k in range(3):
        np.add.at(out, f[:, k], n)
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, norm, out=np.zeros_like(out), where=norm > 0)


def observed_structure(background: Background, walls: tuple[Plane, ...]) -> np.ndarray:
    """(N, 3) observed background vertices that are neither floor nor wall (world frame)."""
    v = background.surface.vertices_m[background.surface_observed]
    keep = v[:, 2] > FLOOR_BAND_M
    for w in walls:
        keep &= w.clearance_m(v) > WALL_BAND_M
    return v[keep]


class BackgroundSupport:
    """Support heights from the background seen around an object (see the module docstring).

    The observed background structure (neither floor nor wall) is binned into columns of
    :data:`SUPPORT_CELL_M`. Around an object's footprint, a column whose points in the height
    band under the object stop there (nothing of it within :data:`CLEAR_ABOVE_M` above its top
    in the band) is the top of something the object can stand on: a counter or table top seen
    from above, a shelf board's front edge seen from its own height. A column that goes on up
    (a wall or a cabinet side behind the object) is not. The support height is the densest
    1 cm layer of those column tops.
    """

    def __init__(self, background: Background | None, walls: tuple[Plane, ...] = ()) -> None:
        self.cells: dict[tuple[int, int], np.ndarray] = {}
        if background is None:
            return
        v = background.surface.vertices_m
        keep = background.surface_observed & (v[:, 2] > FLOOR_BAND_M)
        for w in walls:
            keep &= w.clearance_m(v) > WALL_BAND_M
        p = v[keep]
        if not len(p):
            return
        ij = np.floor(p[:, :2] / SUPPORT_CELL_M).astype(np.int64)
        order = np.lexsort((p[:, 2], ij[:, 1], ij[:, 0]))
        ij, z = ij[order], p[order, 2]
        starts = np.flatnonzero(np.concatenate([[True], np.any(ij[1:] != ij[:-1], axis=1)]))
        ends = np.concatenate([starts[1:], [len(z)]])
        self.cells = {(int(ij[a, 0]), int(ij[a, 1])): z[a:b] for a, b in zip(starts, ends)}

    def height_under(self, footprint_world_m: np.ndarray, low_m: float, high_m: float) -> float | None:
        """Height (m) of the background top seen around the (K, 2) footprint polygon within
        [low_m, high_m]; None when fewer than MIN_SUPPORT_CELLS columns support it."""
        import shapely

        if not self.cells or len(footprint_world_m) == 0:
            return None
        foot = np.asarray(footprint_world_m, dtype=np.float64)
        region = shapely.Polygon(foot).buffer(SUPPORT_REACH_M) if len(foot) >= 3 else shapely.Point(foot.mean(axis=0)).buffer(SUPPORT_REACH_M)
        x0, y0, x1, y1 = region.bounds
        i0, i1 = int(np.floor(x0 / SUPPORT_CELL_M)), int(np.floor(x1 / SUPPORT_CELL_M))
        j0, j1 = int(np.floor(y0 / SUPPORT_CELL_M)), int(np.floor(y1 / SUPPORT_CELL_M))
        tops, weights = [], []
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                z = self.cells.get((i, j))
                if z is None or not shapely.contains_xy(region, (i + 0.5) * SUPPORT_CELL_M, (j + 0.5) * SUPPORT_CELL_M):
                    continue
                band = z[(z >= low_m) & (z <= high_m)]
                if len(band) == 0:
                    continue
                top = float(band.max())
                if np.any((z > top + 0.5 * LAYER_M) & (z <= top + CLEAR_ABOVE_M)):
                    continue  # the column goes on up: a wall or a side behind, not a top
                tops.append(top)
                weights.append(len(band))
        if len(tops) < MIN_SUPPORT_CELLS:
            return None
        t = np.array(tops)
        layers = np.floor((t - low_m) / LAYER_M).astype(np.int64)
        counts = np.bincount(layers, weights=np.array(weights, dtype=np.float64))
        best = int(len(counts) - 1 - np.argmax(counts[::-1]))  # densest; ties go to the higher
        near = np.abs(t - (low_m + (best + 0.5) * LAYER_M)) <= 1.5 * LAYER_M
        if int(near.sum()) < MIN_SUPPORT_CELLS:
            return None
        return float(np.median(t[near]))


#: HiddenBelow: the slab under an object that is tested (from its bottom down this far, not into
#: the floor), the least margin in front of the observed depth for a sample to count as seen
#: through, and the share of seen samples above which the space counts as seen.
UNDER_SLAB_M = 0.40
SEEN_MARGIN_M = 0.05
SEEN_FREE_SHARE = 0.25


class HiddenBelow:
    """Whether the space right under an object was hidden from the camera.

    Samples points on a grid inside the object's footprint, in the slab from UNDER_SLAB_M below
    its bottom up to 3 cm below it, and projects them into the photo: a sample whose pixel saw
    something farther than the sample by more than SEEN_MARGIN_M (plus the sensor's noise) was
    seen through, so that space is empty. Written here rather than shared with
    ``generation.visibility`` because stage packages do not import each other.
    """

    def __init__(self, observation: Observation, camera: Camera) -> None:
        self.depth = np.asarray(observation.depth_m, dtype=np.float64)
        k = observation.intrinsics
        self.k = (k.fx_px, k.fy_px, k.cx_px, k.cy_px)
        self.camera_from_world = np.linalg.inv(camera.world_from_camera)

    def __call__(self, footprint_world_m: np.ndarray, bottom_m: float) -> bool:
        """True when fewer than SEEN_FREE_SHARE of the samples under the (K, 2) footprint with an
        observed depth were seen through (the space under it is hidden)."""
        import shapely

        foot = np.asarray(footprint_world_m, dtype=np.float64)
        if len(foot) < 3 or bottom_m <= 0.05:
            return True
        poly = shapely.Polygon(foot)
        lo, hi = foot.min(axis=0), foot.max(axis=0)
        gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 7)[1:-1], np.linspace(lo[1], hi[1], 7)[1:-1])
        xy = np.stack([gx.ravel(), gy.ravel()], axis=1)
        xy = xy[shapely.contains_xy(poly, xy[:, 0], xy[:, 1])]
        if len(xy) == 0:
            xy = foot.mean(axis=0, keepdims=True)
        zs = np.linspace(max(0.02, bottom_m - UNDER_SLAB_M), bottom_m - 0.03, 6)
        pts = np.concatenate([np.column_stack([xy, np.full(len(xy), z)]) for z in zs])
        cam = transform_points(self.camera_from_world, pts)
        fx, fy, cx, cy = self.k
        ahead = cam[:, 2] > 0.05
        u = np.full(len(cam), -1, dtype=np.int64)
        v = np.full(len(cam), -1, dtype=np.int64)
        u[ahead] = np.floor(fx * cam[ahead, 0] / cam[ahead, 2] + cx).astype(np.int64)
        v[ahead] = np.floor(fy * cam[ahead, 1] / cam[ahead, 2] + cy).astype(np.int64)
        h, w = self.depth.shape
        inside = ahead & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        obs = np.zeros(len(cam))
        obs[inside] = self.depth[v[inside], u[inside]]
        known = inside & np.isfinite(obs) & (obs > 0)
        if not known.any():
            return True
        # 2.5 sigma of a structured-light sensor's depth noise (sigma = 1.425e-3 z^2, Khoshelham 2012).
        seen = obs[known] > cam[known, 2] + SEEN_MARGIN_M + 2.5 * 1.425e-3 * obs[known] ** 2
        return float(seen.mean()) < SEEN_FREE_SHARE


def support_pad(
    footprint_rel_m: np.ndarray,
    rotation: np.ndarray,
    position_m: np.ndarray,
    height_m: float,
    bottom_m: float | None = None,
    rect_m: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, float]:
    """The box under an object resting on the background: its footprint's bounding rectangle in
    the object's own (yawed) axes (or ``rect_m``: (lo_x, lo_y, hi_x, hi_y) in those axes, a
    rectangle cut back clear of neighbours by :func:`clip_pad`), from ``height_m -
    PAD_THICKNESS_M`` (not below the floor; or from ``bottom_m``, a column standing in for a
    hidden support) up to ``height_m``.
    footprint_rel_m: (K, 2) relative to the object's position in world axes.
    Returns centre (3,), half extents (3,) and yaw (rad)."""
    yaw = float(np.arctan2(rotation[1, 0], rotation[0, 0]))
    c, s = np.cos(yaw), np.sin(yaw)
    if rect_m is not None:
        lo, hi = np.asarray(rect_m[:2], dtype=np.float64), np.asarray(rect_m[2:], dtype=np.float64)
    else:
        local = footprint_rel_m @ np.array([[c, -s], [s, c]])  # world offsets -> object axes
        lo, hi = local.min(axis=0), local.max(axis=0)
    mid = 0.5 * (lo + hi)
    centre_xy = position_m[:2] + np.array([[c, -s], [s, c]]) @ mid
    bottom = max(0.0, height_m - PAD_THICKNESS_M if bottom_m is None else bottom_m)
    thickness = max(height_m - bottom, 1e-3)
    centre = np.array([centre_xy[0], centre_xy[1], height_m - thickness / 2.0])
    half = np.array([max((hi - lo)[0] / 2.0, 1e-3), max((hi - lo)[1] / 2.0, 1e-3), thickness / 2.0])
    return centre, half, yaw


def clip_pad(
    rect_m: np.ndarray,
    yaw: float,
    position_m: np.ndarray,
    z_lo_m: float,
    z_hi_m: float,
    obstacles: list[np.ndarray],
    com_rel_m: np.ndarray,
    inset_m: float,
    probe: bool = False,
) -> np.ndarray | None:
    """A pad rectangle cut back clear of its neighbours, or None when no cut keeps it under the
    object's centre of mass.

    rect_m: (lo_x, lo_y, hi_x, hi_y) in the object's yawed axes relative to ``position_m``;
    obstacles: (N, 3) world vertex sets of the other objects' collision pieces; those reaching
    into the pad's height band [z_lo_m, z_hi_m] whose plan (convex hull) overlaps the rectangle
    are cut away, each by the one side of the pad (the rectangle minus the extent of the overlap
    in the pad's axes, from one of four sides) that keeps the most area with the centre of mass
    (com_rel_m (2,), same axes) ``inset_m`` inside. The overlap, not the piece's extent in the
    pad's axes: a thin piece lying diagonally to the pad (a mirror's frame beside a box on a
    dresser, sunrgbd_imvotenet_000003) has an extent there that covers the pad though the piece
    misses it.
    A pad stands in for the support seen around an object and hidden under it: where a
    neighbour's completion reaches under the object, the pad stops short of it rather than the
    object being left where seen as background. ``probe``: only say whether the rectangle is
    clear (it, or None at the first piece reaching in).
    """
    c, s = np.cos(yaw), np.sin(yaw)
    to_local = np.array([[c, -s], [s, c]])  # world offsets -> object axes (as in support_pad)
    r = np.asarray(rect_m, dtype=np.float64).copy()
    com = np.asarray(com_rel_m, dtype=np.float64)
    for _ in range(4 * len(obstacles) + 1):
        cut = None
        for v in obstacles:
            v = np.asarray(v, dtype=np.float64)
            if v[:, 2].max() <= z_lo_m or v[:, 2].min() >= z_hi_m:
                continue
            loc = (v[:, :2] - position_m[:2]) @ to_local
            if not (np.all(loc.min(axis=0) < r[2:]) and np.all(loc.max(axis=0) > r[:2])):
                continue
            rect = np.array([[r[0], r[1]], [r[2], r[1]], [r[2], r[3]], [r[0], r[3]]])
            inside = clip_convex_polygons(convex_hull_2d(loc), rect)
            if len(inside) >= 3 and polygon_area(inside) > PAD_OVERLAP_MIN_M2:
                cut = (inside.min(axis=0), inside.max(axis=0))
                break
        if cut is None:
            return r
        if probe:
            return None
        olo, ohi = cut
        # The pad keeps the part beyond the piece on one side: lo raised past it, or hi lowered.
        options = [(axis, side, ohi[axis] if side == "lo" else olo[axis]) for axis in (0, 1) for side in ("lo", "hi")]
        best = None
        for axis, side, value in options:
            lo, hi = r[:2].copy(), r[2:].copy()
            if side == "lo":
                lo[axis] = max(lo[axis], value)
            else:
                hi[axis] = min(hi[axis], value)
            if np.any(hi - lo <= 2 * inset_m) or np.any(com < lo + inset_m) or np.any(com > hi - inset_m):
                continue
            area = float(np.prod(hi - lo))
            if best is None or area > best[0]:
                best = (area, np.concatenate([lo, hi]))
        if best is None:
            return None
        r = best[1]
    return None


def column_boxes(points_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned collision boxes (lo (B, 3), hi (B, 3)) over observed structure points (N, 3)
    (see the module docstring)."""
    p = np.asarray(points_m, dtype=np.float64)
    if len(p) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    ij = np.floor(p[:, :2] / CELL_M).astype(np.int64)
    order = np.lexsort((p[:, 2], ij[:, 1], ij[:, 0]))
    ij, z = ij[order], p[order, 2]
    new_col = np.ones(len(z), dtype=bool)
    new_col[1:] = np.any(ij[1:] != ij[:-1], axis=1)
    gap = np.ones(len(z), dtype=bool)
    gap[1:] = new_col[1:] | (z[1:] - z[:-1] > COLUMN_GAP_M)
    run = np.cumsum(gap) - 1
    counts = np.bincount(run)
    starts = np.flatnonzero(gap)
    zlo = z[starts]
    zhi = np.maximum.reduceat(z, starts)
    cells = ij[starts]
    ok = counts >= MIN_RUN_POINTS
    cells, zlo, zhi = cells[ok], zlo[ok] - SHELL_M, zhi[ok]
    # Merge runs of neighbouring cells along x (same y, adjacent x, bottoms and tops agree).
    order = np.lexsort((cells[:, 0], np.round(zhi / MERGE_TOL_M), cells[:, 1]))
    boxes_lo, boxes_hi = [], []
    cur = None
    for k in order:
        i, j = int(cells[k, 0]), int(cells[k, 1])
        if cur is not None and cur[1] == j and cur[2] + 1 == i and abs(cur[3] - zlo[k]) <= MERGE_TOL_M and abs(cur[4] - zhi[k]) <= MERGE_TOL_M:
            cur = [cur[0], j, i, min(cur[3], zlo[k]), max(cur[4], zhi[k])]
            continue
        if cur is not None:
            boxes_lo.append([cur[0] * CELL_M, cur[1] * CELL_M, cur[3]])
            boxes_hi.append([(cur[2] + 1) * CELL_M, (cur[1] + 1) * CELL_M, cur[4]])
        cur = [i, j, i, float(zlo[k]), float(zhi[k])]
    if cur is not None:
        boxes_lo.append([cur[0] * CELL_M, cur[1] * CELL_M, cur[3]])
        boxes_hi.append([(cur[2] + 1) * CELL_M, (cur[1] + 1) * CELL_M, cur[4]])
    lo, hi = np.array(boxes_lo).reshape(-1, 3), np.array(boxes_hi).reshape(-1, 3)
    lo[:, 2] = np.maximum(lo[:, 2], 0.0)
    hi[:, 2] = np.maximum(hi[:, 2], lo[:, 2] + MIN_BOX_THICKNESS_M)
    return lo, hi


def carve(lo_m: np.ndarray, hi_m: np.ndarray, obstacles_lo_m: np.ndarray, obstacles_hi_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (lo, hi: (B, 3)) kept clear of the obstacles' boxes ((K, 3), (K, 3), e.g. the world
    bounds of every object's convex pieces) by CARVE_CLEARANCE_M: a box reaching into an
    obstacle from below is cut down to the obstacle's bottom when at least MIN_BOX_THICKNESS_M
    remains, otherwise dropped."""
    lo, hi = np.array(lo_m, dtype=np.float64), np.array(hi_m, dtype=np.float64)
    keep = np.ones(len(lo), dtype=bool)
    c = CARVE_CLEARANCE_M
    for olo, ohi in zip(np.asarray(obstacles_lo_m), np.asarray(obstacles_hi_m)):
        hit = keep & np.all(lo < ohi + c, axis=1) & np.all(hi > olo - c, axis=1)
        if not np.any(hit):
            continue
        cut = olo[2] - c
        can = hit & (cut - lo[:, 2] >= MIN_BOX_THICKNESS_M)
        hi[can, 2] = cut
        keep &= ~(hit & ~can)
    return lo[keep], hi[keep]


def absorb(background: Background, name: str, asset: ObjectAsset, world_from_asset: np.ndarray) -> Background:
    """``background`` with ``asset`` (placed at ``world_from_asset``) made part of it: every
    part's visual mesh (rest pose) joins ``static_meshes`` under ``name`` (``name/part`` for parts
    other than the root) and its convex pieces join ``static_pieces``, in the world frame."""
    meshes, labels, pieces = list(background.static_meshes), list(background.static_names), list(background.static_pieces)
    for part in asset.parts:
        v = part.visual
        meshes.append(dataclasses.replace(v, vertices_m=transform_points(world_from_asset, v.vertices_m)))
        labels.append(name if part.parent is None else f"{name}/{part.name}")
        for piece in part.collision:
            pieces.append(TriangleMesh(transform_points(world_from_asset, piece.vertices_m), piece.faces))
    return dataclasses.replace(background, static_meshes=tuple(meshes), static_names=tuple(labels), static_pieces=tuple(pieces))
