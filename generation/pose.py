"""Initial pose of an object: a gravity-aligned oriented box around its observed points.

The box's yaw is the minimum-area rectangle of the points projected on the floor (convex hull +
rotating calipers: the optimal rectangle has a side collinear with a hull edge), after trimming
the 2 % outliers. Its +X (the asset's front) is the side face whose outward normal points most
toward the camera. Objects whose bottom is within ``floor_snap_m`` of the floor stand on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scene_builder.frames import pose, rot_z, transform_points

__all__ = ["BoxFit", "extend_depth", "fit_box", "min_area_rectangle", "plan_fit_cost"]


@dataclass(frozen=True, eq=False)
class BoxFit:
    """world_from_box: (4, 4) rotation about Z, origin at the bottom-centre of the box.
    size_m: (3,) extents along the box's x (front-back depth), y (width), z (height).
    on_floor: the bottom was snapped to z = 0. observed_depth_m: the x extent the points
    themselves span (before any completion to a prior depth)."""

    world_from_box: np.ndarray
    size_m: np.ndarray
    on_floor: bool
    observed_depth_m: float


#: A category at least this much wider than deep (or deeper than wide) has a plan orientation
#: its observed extents can tell (:func:`fit_box`) ...
PLAN_ANISOTROPY = 1.5
#: ... when the two ways of reading them differ by more than this (squared log-size units: the
#: sofa seen end-on scores 2.9 one way, 0.3 the other).
PLAN_SWAP_MARGIN = 0.5
#: Points spanning at most this share of their width in depth are one seen face (a microwave's
#: door, a cabinet's front) ...
FACE_DEPTH_SHARE = 0.2
#: ... and a face this near a wall (its nearest 10 % of points, m) ...
FACE_NEAR_WALL_M = 0.6
#: ... turned at most this far from it (degrees) stands parallel to that wall (:func:`fit_box`).
FACE_TO_WALL_MAX_DEG = 35.0


def plan_fit_cost(depth_m: float, width_m: float, typical_depth_m: float, typical_width_m: float) -> float:
    """Squared log-size distance of an observed plan (depth, width) from a category's: a depth
    short of the typical one costs 0.6 as much (the unseen back makes it look shallower, as in
    :func:`perception.naming_prior.size_distance`)."""
    dd = float(np.log(max(depth_m, 0.01) / typical_depth_m))
    dw = float(np.log(max(width_m, 0.01) / typical_width_m))
    if dd < 0.0:
        dd *= 0.6
    return dd * dd + dw * dw


def min_area_rectangle(xy: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Minimum-area enclosing rectangle of (N, 2) points by rotating calipers over hull edges.

    Returns (angle_rad of the rectangle's first axis, (2,) min corner, (2,) max corner) with the
    corners expressed in the rectangle's own axes ``[cos a, sin a]`` and ``[-sin a, cos a]``.
    """
    from scipy.spatial import ConvexHull, QhullError

    pts = np.asarray(xy, dtype=np.float64)
    try:
        hull = pts[ConvexHull(pts).vertices]
    except (QhullError, ValueError):
        # collinear or too few points: the principal axis is the rectangle's axis
        c = pts - pts.mean(axis=0)
        _, _, vt = np.linalg.svd(c, full_matrices=False)
        angles = np.array([np.arctan2(vt[0, 1], vt[0, 0])])
        hull = pts
    else:
        edges = np.diff(np.vstack([hull, hull[:1]]), axis=0)
        angles = np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2)
        angles = np.unique(np.round(angles, 12))
    c, s = np.cos(angles), np.sin(angles)
    # project the hull on both axes of every candidate: (A, H)
    u = hull[None, :, 0] * c[:, None] + hull[None, :, 1] * s[:, None]
    v = -hull[None, :, 0] * s[:, None] + hull[None, :, 1] * c[:, None]
    area = (u.max(1) - u.min(1)) * (v.max(1) - v.min(1))
    best = int(np.argmin(area))
    return float(angles[best]), np.array([u[best].min(), v[best].min()]), np.array([u[best].max(), v[best].max()])


def _robust_extent(values: np.ndarray, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-column extent of (N, K) values ignoring outliers: the q and 1 - q quantiles, widened
    to the farthest values within a margin (5 % of the extent + 1 cm) of them. Quantiles alone
    shrink a densely sampled face by 2 q of its size; the margin recovers the true edge while
    isolated far outliers stay out."""
    lo = np.quantile(values, q, axis=0)
    hi = np.quantile(values, 1.0 - q, axis=0)
    margin = 0.05 * (hi - lo) + 0.01
    lo_out = np.where(values >= lo - margin, values, np.inf).min(axis=0)
    hi_out = np.where(values <= hi + margin, values, -np.inf).max(axis=0)
    return lo_out, hi_out


def fit_box(
    points_world_m: np.ndarray,
    camera_position_m: np.ndarray,
    *,
    trim_fraction: float = 0.02,
    floor_snap_m: float = 0.05,
    min_size_m: float = 0.01,
    typical_size_m: tuple[float, float, float] | None = None,
    walls=(),
    face_normal: np.ndarray | None = None,
) -> BoxFit:
    """Gravity-aligned box around observed points (world frame, Z up, floor z = 0).

    points_world_m: (N, 3). camera_position_m: (3,). ``trim_fraction`` of the points farthest
    from the median (in plan) are ignored for the yaw, and extents use the
    ``trim_fraction / 2`` and ``1 - trim_fraction / 2`` quantiles along each box axis, widened to
    the points within a small margin of them (see ``_robust_extent``).

    ``typical_size_m``: the category's (depth, width, height). For a category much wider than
    deep (a sofa, a bench, a desk, a shelf: :data:`PLAN_ANISOTROPY`), the front is on a long
    side when the observed plan extents fit the category clearly better that way
    (:func:`plan_fit_cost`): a sofa seen end-on, its arm nearest the camera, is 2 m wide and 0.9 m
    deep, not 0.4 m wide and 1.5 m deep (its completion then grows its seat away from the camera
    instead of leaving a 20 cm slab).

    ``walls``: the room's wall planes. Points that are one seen face near a wall, turned from it
    by less than :data:`FACE_TO_WALL_MAX_DEG`, take the wall's direction (:func:`_wall_angle`).
    Points that are one seen face (thinner than :data:`FACE_DEPTH_SHARE` of their width) have
    that face for their front, however obliquely it was seen.

    ``face_normal``: (3,) the horizontal normal of a face whose doors and drawers were seen
    (``perception.fronts``, its direction read on the photo's lines and snapped to the walls): the
    box's axes follow it. The smallest rectangle of a dresser's points (its front, part of its top
    and a mirror behind) was 8 degrees off its face; the layout then turned it to its wall about
    its centre, and its fronts moved off the drawers they were seen on.
    """
    pts = np.asarray(points_world_m, dtype=np.float64)
    if len(pts) < 3:
        raise ValueError(f"fit_box: need at least 3 observed points, got {len(pts)}")
    xy = pts[:, :2]
    r = np.linalg.norm(xy - np.median(xy, axis=0), axis=1)
    keep = r <= np.quantile(r, 1.0 - trim_fraction)
    angle, lo_r, hi_r = min_area_rectangle(xy[keep])
    if face_normal is not None:
        angle = float(np.arctan2(face_normal[1], face_normal[0]))
    angle = _wall_angle(pts[keep], angle, hi_r - lo_r, walls)
    axes = np.array([[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]])  # rows: box axes in plan
    uv = xy @ axes.T
    q = trim_fraction / 2.0
    lo, hi = _robust_extent(np.column_stack([uv, pts[:, 2]]), q)
    z_lo, z_hi = float(lo[2]), float(hi[2])
    lo, hi = lo[:2], hi[:2]
    on_floor = bool(z_lo <= floor_snap_m)
    z_bottom = 0.0 if on_floor else float(z_lo)
    centre_uv = 0.5 * (lo + hi)
    centre_xy = centre_uv @ axes
    # front: the side face whose outward normal points most toward the camera
    to_cam = np.asarray(camera_position_m, dtype=np.float64)[:2] - centre_xy
    normals = np.vstack([axes, -axes])  # +u, +v, -u, -v
    ext_uv = hi - lo
    sides = (0, 1, 2, 3)
    if min(ext_uv) <= FACE_DEPTH_SHARE * max(ext_uv):
        # One seen face: its front is that face, however obliquely it was seen (the dresser at
        # sunrgbd_total3d_demo_5's right edge, seen 60 degrees off, was a box 1 cm wide whose
        # front was the face's end).
        sides = (0, 2) if ext_uv[0] <= ext_uv[1] else (1, 3)
    front = max(sides, key=lambda i: float(normals[i] @ to_cam))
    if typical_size_m is not None:
        td, tw = float(typical_size_m[0]), float(typical_size_m[1])
        if max(td, tw) >= PLAN_ANISOTROPY * min(td, tw):
            cost_u = plan_fit_cost(ext_uv[0], ext_uv[1], td, tw)  # depth along u
            cost_v = plan_fit_cost(ext_uv[1], ext_uv[0], td, tw)
            want = (0, 2) if cost_u < cost_v else (1, 3)
            if front not in want and abs(cost_u - cost_v) > PLAN_SWAP_MARGIN:
                front = max(want, key=lambda i: float(normals[i] @ to_cam))
    x_axis = normals[front]
    yaw = float(np.arctan2(x_axis[1], x_axis[0]))
    depth, width = (ext_uv[0], ext_uv[1]) if front in (0, 2) else (ext_uv[1], ext_uv[0])
    size = np.maximum(np.array([depth, width, float(z_hi) - z_bottom]), min_size_m)
    world_from_box = pose(rot_z(yaw), [centre_xy[0], centre_xy[1], z_bottom])
    return BoxFit(world_from_box, size, on_floor, float(depth))


def _wall_angle(points_m: np.ndarray, angle: float, extent: np.ndarray, walls) -> float:
    """The rectangle angle of an object's plan: ``angle`` (its minimum-area rectangle, sides
    ``extent``), or the direction of the nearest wall when the points are one seen face
    (thinner than :data:`FACE_DEPTH_SHARE` of their width) within :data:`FACE_NEAR_WALL_M` of it
    and turned from it by at most :data:`FACE_TO_WALL_MAX_DEG`. Depth estimated from one photo
    tilts a flat face (COCO 000089's microwave in its cabinet niche read 25 degrees off its wall):
    the rectangle of a tilted face is a 1 cm slab turned into the room, whose completion cannot
    grow it a body behind the face."""
    if not walls or min(extent) > FACE_DEPTH_SHARE * max(extent):
        return angle
    best = None
    for wall in walls:
        n = np.asarray(wall.normal, dtype=np.float64)
        d = wall.clearance_m(points_m)
        d = d[np.isfinite(d)]  # (points past the wall's ends are not against it)
        if len(d) < 0.5 * len(points_m):
            continue
        near = float(np.quantile(d, 0.1))
        if not -0.05 <= near <= FACE_NEAR_WALL_M:
            continue
        wall_angle = float(np.mod(np.arctan2(n[1], n[0]), np.pi / 2))
        turn = float(np.degrees(abs((angle - wall_angle + np.pi / 4) % (np.pi / 2) - np.pi / 4)))
        if turn <= FACE_TO_WALL_MAX_DEG and (best is None or near < best[0]):
            best = (near, wall_angle)
    return angle if best is None else best[1]


def travel_to_walls(points_world_m: np.ndarray, direction: np.ndarray, walls) -> float:
    """How far (m) the (N, 3) world points can move along the unit ``direction`` before the first
    of them reaches a wall of ``walls`` (inf when no wall stands that way, or past its ends)."""
    limit = np.inf
    for wall in walls:
        rate = float(np.asarray(wall.normal, dtype=np.float64) @ direction)  # clearance change per metre
        if rate < -1e-6:
            limit = min(limit, float(np.min(wall.clearance_m(points_world_m))) / -rate)  # (inf past its ends)
    return limit


def extend_depth(fit: BoxFit, depth_m: float) -> BoxFit:
    """The same box made ``depth_m`` deep by growing it away from the camera (the observed
    front face stays where it was)."""
    if depth_m <= fit.size_m[0]:
        return fit
    grow = depth_m - float(fit.size_m[0])
    shift = transform_points(fit.world_from_box, np.array([[-grow / 2.0, 0.0, 0.0]]))[0]
    world_from_box = fit.world_from_box.copy()
    world_from_box[:3, 3] = shift
    size = fit.size_m.copy()
    size[0] = depth_m
    return BoxFit(world_from_box, size, fit.on_floor, fit.observed_depth_m)


#: Another object is a support under an object (floor_snap_height_m) only when its plan box
#: covers at least this share of the object's.
SUPPORT_PLAN_SHARE = 0.25


def floor_snap_height_m(
    points_world_m: np.ndarray,
    other_points_world_m: list[np.ndarray] | tuple[np.ndarray, ...],
    *,
    default_m: float = 0.05,
    max_gap_m: float = 0.3,
    support_tol_m: float = 0.05,
    min_surface_m: float = 0.02,
    margin_m: float = 0.05,
    q: float = 0.01,
) -> float:
    """The ``floor_snap_m`` for :func:`fit_box`: how high an object's lowest observed point may be
    for its box to be extended down to the floor.

    A floor-standing object's lowest points are often not seen: the floor under a chair's seat
    or a sofa's frame shows between thin legs, a low occluder hides its foot. With nothing it
    could stand on, the layout solver drops such an object to the floor, so a box bottomed at its
    lowest observed point ends up with its observed top that gap too low (bench on 20
    procedural rooms: built boxes 3 cm low at the median, up to 15 cm). When the lowest point
    is at most ``max_gap_m`` high and no other object's top (robust ``1 - q`` quantile of its
    heights) lies between ``min_surface_m`` and the lowest point + ``support_tol_m`` under the
    object's plan rectangle (axis-aligned, grown by ``margin_m``, since the support's top under
    the object is hidden by the object itself; the other's plan box covering
    :data:`SUPPORT_PLAN_SHARE` of the object's), the answer is that height (as :func:`fit_box`
    finds the lowest point); else ``default_m``.

    points_world_m: (N, 3); other_points_world_m: (M_k, 3) per other object; world frame, Z up,
    floor z = 0.
    """
    pts = np.asarray(points_world_m, dtype=np.float64)
    if len(pts) < 3:
        return default_m
    z_lo = float(np.quantile(pts[:, 2], q))
    if z_lo <= default_m or z_lo > max_gap_m:
        return default_m
    lo = np.quantile(pts[:, :2], q, axis=0) - margin_m
    hi = np.quantile(pts[:, :2], 1.0 - q, axis=0) + margin_m
    for other in other_points_world_m:
        o = np.asarray(other, dtype=np.float64)
        if len(o) < 3:
            continue
        inside = np.all((o[:, :2] >= lo) & (o[:, :2] <= hi), axis=1)
        if not np.any(inside):
            continue
        # A support lies under a share of the object's plan (its top seen around the object): a
        # bench before a bed's foot reaches only the margin of the bed's rectangle.
        o_lo, o_hi = np.quantile(o[:, :2], q, axis=0), np.quantile(o[:, :2], 1.0 - q, axis=0)
        own = np.maximum(hi - lo - 2.0 * margin_m, 1e-6)
        cover = np.clip(np.minimum(o_hi, hi - margin_m) - np.maximum(o_lo, lo + margin_m), 0.0, None)
        if float(np.prod(cover / own)) < SUPPORT_PLAN_SHARE:
            continue
        top = float(np.quantile(o[:, 2], 1.0 - q))
        if min_surface_m < top <= z_lo + support_tol_m:
            return default_m
    # the lowest point as fit_box finds it (its widened robust bottom, which it compares with
    # this): the raw lowest point, a stray post or a speck under a bed seen over a bench, lay
    # under it and kept the box off the floor
    return float(_robust_extent(pts[:, 2:3], q)[0][0]) + 1e-6
