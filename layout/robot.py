"""Where the robot stands: a free floor spot inside the room, facing a support surface its arm
reaches, preferably seen by the input camera and not hiding the target from it.

The floor plan (shapely polygons, the well-kept library for 2-D geometry): every collision piece
of the scene (objects, fixed furniture, the background's boxes and pieces) that rises above the
floor and starts below the robot's height is an obstacle, as its footprint (a convex piece
projects to the convex hull of its vertices); walls are half-planes. Candidate spots lie on a
:data:`GRID_M` grid; a spot is free when the robot's footprint circle (measured on its model at
the start pose) keeps :data:`CLEARANCE_M` from every obstacle and wall.

Targets: a height map of the same collision geometry on :data:`CELL_M` cells (each convex
piece's exact top); a cell is a target when nothing rises above it within
:data:`ON_TOP_CLEARANCE_M` (clear of what stands on it) and its top (an object's, fixed
furniture's or the background's) is flat within :data:`TOP_BAND_M` over :data:`TARGET_INSET_M`
around it (a table, away from its edges), or it is the highest cell of a movable object (where a
gripper would come down on it); the target point is :data:`TARGET_HEIGHT_M` above that top. In
rooms with neither within reach (tall, merged furniture), points beside a movable object over
open floor (:data:`SIDE_GAP_M` from its outline, at half its height) are targets too. A spot reaches a target when the point lies within
:data:`REACH_FRACTION` of the arm's sampled reach from the shoulder. Each spot keeps its best
target whose floor-plan path from the spot passes :data:`PATH_CLEARANCE_M` under it over
everything (:meth:`_Footprints.path_clear`: the arm comes in over the top); spots are ranked by how comfortably they reach (distance near :data:`COMFORT_FRACTION` of
the reach), standing on floor the camera saw (:func:`_seen_floor`), a table before an object's
top before its side (:data:`KIND_BONUS`), visibility from the input camera, not
standing between the camera and the target, then grid order (deterministic).

:mod:`layout.reach` then measures each candidate in MuJoCo (overlap at the start and home poses,
the scripted reach swept kinematically); the pipeline keeps the first that passes.
"""

from __future__ import annotations

import numpy as np

from scene_builder.errors import InputError
from scene_builder.model import Scene
from scene_builder.robot import RobotModel, RobotPlacement

GRID_M = 0.05
CELL_M = 0.04
CLEARANCE_M = 0.05
FLOOR_EPS_M = 0.003  # geometry lower than this is the floor itself (the robot's geoms start at 5 mm)
TARGET_HEIGHT_M = 0.18
TARGET_INSET_M = 0.06
ON_TOP_CLEARANCE_M = 0.12
MIN_TOP_M = 0.05
TOP_BAND_M = 0.03
REACH_FRACTION = 0.75
COMFORT_FRACTION = 0.55
MIN_HORIZONTAL_M = 0.25
ROOM_MARGIN_M = 1.5
CANDIDATES = 8
CHUNK = 128
TOP, OBJECT_TOP, SIDE = 0, 1, 2
KIND_NAMES = ("top", "object_top", "side")
KIND_BONUS = np.array([0.2, 0.1, 0.0])  # a table first, then above an object, then beside one
SIDE_GAP_M = (0.10, 0.14)
SIDE_HEIGHTS_M = (0.3, 0.7)
SIDE_FLOOR_M = 0.05
TARGETS_PER_SPOT = 24
PATH_CLEARANCE_M = 0.1
PATH_WIDTH_M = 0.06
ARM_BAND_M = 0.5
SEEN_FLOOR_BAND_M = 0.03
SEEN_FLOOR_WEIGHT = 1.0
CANDIDATE_SPACING_M = 0.3


def _pieces(scene: Scene) -> list[tuple[str, np.ndarray]]:
    """(owner, (N, 3) world vertices) of every collision piece: objects' parts, the background's
    pieces and boxes (owner ``background``)."""
    out = []
    for o in scene.objects:
        t = o.world_from_asset
        for part in o.asset.parts:
            for piece in part.collision:
                out.append((o.name, piece.vertices_m @ t[:3, :3].T + t[:3, 3]))
    bg = scene.room.background
    if bg is not None:
        for piece in bg.static_pieces:
            out.append(("background", np.asarray(piece.vertices_m)))
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
        for c, h, yaw in zip(bg.box_centers_m, bg.box_half_extents_m, bg.box_yaws_rad):
            cy, sy = np.cos(yaw), np.sin(yaw)
            rot = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
            out.append(("background", (corners * h) @ rot.T + c))
    return out


def _hull(xy: np.ndarray):
    import shapely

    return shapely.MultiPoint(xy.tolist()).convex_hull


def _height_map(pieces: list[tuple[str, np.ndarray]]):
    """Top of the collision geometry over the floor plan: (origin (2,), heights (X, Y), owner
    index (X, Y) into the owners list, owners). A cell's height is the highest top of a piece
    whose footprint covers the cell's centre (0 for the floor); the owner is that piece's."""
    import shapely

    allxy = np.concatenate([v[:, :2] for _, v in pieces])
    lo = np.floor(allxy.min(axis=0) / CELL_M) * CELL_M - CELL_M
    shape = np.ceil((allxy.max(axis=0) + CELL_M - lo) / CELL_M).astype(int) + 1
    heights = np.zeros(shape)
    owner = np.full(shape, -1)
    owners = sorted({o for o, _ in pieces})
    index = {o: k for k, o in enumerate(owners)}
    for name, v in pieces:
        if float(v[:, 2].max()) <= FLOOR_EPS_M:
            continue
        i0, j0 = np.floor((v[:, :2].min(axis=0) - lo) / CELL_M).astype(int)
        i1, j1 = np.ceil((v[:, :2].max(axis=0) - lo) / CELL_M).astype(int)
        ii, jj = np.meshgrid(np.arange(i0, i1 + 1), np.arange(j0, j1 + 1), indexing="ij")
        x, y = lo[0] + ii * CELL_M, lo[1] + jj * CELL_M
        inside = shapely.contains_xy(_hull(v[:, :2]).buffer(1e-9), x, y)
        ii, jj = ii[inside], jj[inside]
        top = _convex_top(v, x[inside], y[inside])
        higher = heights[ii, jj] < top
        heights[ii[higher], jj[higher]] = top[higher]
        owner[ii[higher], jj[higher]] = index[name]
    return lo, heights, owner, owners


def _convex_top(v: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Height of the top of the convex piece with vertices ``v`` over points (x, y) inside its
    footprint: the lowest of its upward faces' planes there (qhull's facet equations); a flat
    piece qhull cannot take answers its highest vertex."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        eq = ConvexHull(v).equations
    except (QhullError, ValueError):
        return np.full(len(x), float(v[:, 2].max()))
    up = eq[eq[:, 2] > 1e-6]
    z = -(up[:, 3][None] + up[:, 0][None] * x[:, None] + up[:, 1][None] * y[:, None]) / up[:, 2][None]
    return np.minimum(z.min(axis=1), float(v[:, 2].max()))


def _disk(radius_m: float) -> np.ndarray:
    r = int(np.ceil(radius_m / CELL_M))
    y, x = np.mgrid[-r : r + 1, -r : r + 1]
    return (x * x + y * y) * CELL_M * CELL_M <= radius_m * radius_m + 1e-12


def _targets(height_map, max_top_m: float, movable: set[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Where the arm may go: (T, 3) target points, (T,) owner index, (T,) kind (TOP, OBJECT_TOP,
    SIDE) and the owners' names. Over a top the point is TARGET_HEIGHT_M above it; a cell
    qualifies when its top is between MIN_TOP_M and ``max_top_m`` and either nothing rises above it within
    ON_TOP_CLEARANCE_M (clear of what stands on it) and the top is flat within TOP_BAND_M over
    TARGET_INSET_M around it (a table, away from its edges), or it is the highest cell of a
    movable object (the point above it from which a gripper would come down on the object;
    whatever stands close beside it is left to :mod:`layout.reach`'s sweep)."""
    from scipy import ndimage

    lo, h, owner, owners = height_map
    flat = (ndimage.maximum_filter(h, footprint=_disk(TARGET_INSET_M), mode="constant", cval=0.0)
            - ndimage.minimum_filter(h, footprint=_disk(TARGET_INSET_M), mode="constant", cval=0.0)) <= TOP_BAND_M
    clear = ndimage.maximum_filter(h, footprint=_disk(ON_TOP_CLEARANCE_M), mode="constant", cval=0.0) <= h + TOP_BAND_M
    usable = (h >= MIN_TOP_M) & (h <= max_top_m) & (owner >= 0)
    ok = flat & clear & usable
    for k, name in enumerate(owners):
        if name in movable and (owner == k).any():
            # Its highest cell; what stands close beside it is left to the sweep in MuJoCo.
            cell = np.unravel_index(np.argmax(np.where(owner == k, h, -np.inf)), h.shape)
            ok[cell] |= usable[cell]
    ii, jj = np.nonzero(ok)
    points = [np.column_stack([lo[0] + ii * CELL_M, lo[1] + jj * CELL_M, h[ii, jj] + TARGET_HEIGHT_M])]
    owned, kinds = [owner[ii, jj]], [np.where(flat[ii, jj], TOP, OBJECT_TOP)]
    # Beside a movable object: over open floor SIDE_GAP_M from its outline, at half its height
    # (within SIDE_HEIGHTS_M), where a hand would push it or grasp it from the side.
    inner, outer = _disk(SIDE_GAP_M[0]), _disk(SIDE_GAP_M[1])
    for k, name in enumerate(owners):
        mask = owner == k
        if name not in movable or not mask.any():
            continue
        z = float(np.clip(0.5 * h[mask].max(), *SIDE_HEIGHTS_M))
        if z > max_top_m + TARGET_HEIGHT_M or z + 0.05 > h[mask].max():
            continue
        ring = ndimage.binary_dilation(mask, outer) & ~ndimage.binary_dilation(mask, inner) & (h <= SIDE_FLOOR_M)
        ri, rj = np.nonzero(ring)
        points.append(np.column_stack([lo[0] + ri * CELL_M, lo[1] + rj * CELL_M, np.full(len(ri), z)]))
        owned.append(np.full(len(ri), k))
        kinds.append(np.full(len(ri), SIDE))
    return np.concatenate(points), np.concatenate(owned), np.concatenate(kinds), owners


class _Footprints:
    """Floor-plan footprints of the collision pieces with their height ranges (an STRtree)."""

    def __init__(self, pieces: list[tuple[str, np.ndarray]]) -> None:
        import shapely

        self.polys = [_hull(v[:, :2]) for _, v in pieces]
        self.z = np.array([[v[:, 2].min(), v[:, 2].max()] for _, v in pieces])
        self.tree = shapely.STRtree(self.polys)

    def path_clear(self, spot_xy: np.ndarray, target: np.ndarray) -> bool:
        """The arm comes in over the top: no piece within PATH_WIDTH_M of the floor-plan segment
        from the spot to the target reaches into the band from PATH_CLEARANCE_M under the target
        point to ARM_BAND_M above it (where the forearm and the elbow pass)."""
        import shapely

        line = shapely.LineString([spot_xy.tolist(), target[:2].tolist()]).buffer(PATH_WIDTH_M)
        hits = self.tree.query(line, predicate="intersects")
        z = self.z[hits]
        return not bool(((z[:, 1] > target[2] - PATH_CLEARANCE_M) & (z[:, 0] < target[2] + ARM_BAND_M)).any())


def _candidate_grid(scene: Scene, pieces: list[tuple[str, np.ndarray]]) -> np.ndarray:
    """(G, 2) grid spots over the scene's extent (objects, background, camera) plus a margin."""
    xy = [v[:, :2] for _, v in pieces] + [scene.camera.position_m[None, :2]]
    allxy = np.concatenate(xy)
    lo, hi = allxy.min(axis=0) - ROOM_MARGIN_M, allxy.max(axis=0) + ROOM_MARGIN_M
    xs = np.arange(np.floor(lo[0] / GRID_M) * GRID_M, hi[0] + 1e-9, GRID_M)
    ys = np.arange(np.floor(lo[1] / GRID_M) * GRID_M, hi[1] + 1e-9, GRID_M)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    return np.stack([gx.ravel(), gy.ravel()], axis=1), gx.shape


def _seen_floor(scene: Scene, grid: np.ndarray, shape: tuple[int, int], radius_m: float) -> np.ndarray:
    """(G,) share of the footprint disk around each spot where the camera saw the floor (the
    background surface's measured vertices at floor height); all ones without a background."""
    from scipy import ndimage

    bg = scene.room.background
    if bg is None or not len(bg.surface.vertices_m):
        return np.ones(len(grid))
    v = bg.surface.vertices_m[bg.surface_observed]
    floor = v[np.abs(v[:, 2]) < SEEN_FLOOR_BAND_M, :2]
    lo = grid[0]
    idx = np.round((floor - lo) / GRID_M).astype(int)
    keep = (idx >= 0).all(axis=1) & (idx[:, 0] < shape[0]) & (idx[:, 1] < shape[1])
    seen = np.zeros(shape)
    seen[idx[keep, 0], idx[keep, 1]] = 1.0
    r = int(np.ceil(radius_m / GRID_M))
    y, x = np.mgrid[-r : r + 1, -r : r + 1]
    disk = ((x * x + y * y) <= r * r).astype(float)
    return (ndimage.convolve(seen, disk, mode="constant", cval=0.0) / disk.sum()).ravel()


def _in_view(scene: Scene, xy: np.ndarray, z_m: float) -> np.ndarray:
    """(G,) bool: the point (x, y, z_m) projects inside the input image, in front of the camera."""
    cam = scene.camera
    pts = np.column_stack([xy, np.full(len(xy), z_m)])
    t = np.linalg.inv(cam.world_from_camera)
    pc = pts @ t[:3, :3].T + t[:3, 3]
    k = cam.intrinsics
    ok = pc[:, 2] > 0.1
    z = np.where(ok, pc[:, 2], 1.0)
    u = k.fx_px * pc[:, 0] / z + k.cx_px
    v = k.fy_px * pc[:, 1] / z + k.cy_px
    return ok & (u >= 0) & (u < k.width_px) & (v >= 0) & (v < k.height_px)


def place_robot(scene: Scene, model: RobotModel) -> tuple[RobotPlacement, ...]:
    """Up to CANDIDATES placements, best first, at least CANDIDATE_SPACING_M apart.

    Raises InputError when no free floor spot reaches any support surface."""
    import shapely

    pieces = _pieces(scene)
    radius = float(model.footprint_radius_m)
    mount_z = float(model.arm_mount_m[2])
    reach = REACH_FRACTION * float(model.reach_m)
    height_map = _height_map(pieces)
    footprints = _Footprints(pieces)
    movable = {o.name for o in scene.objects if not o.asset.is_fixed}
    targets, target_owner, target_kind, owners = _targets(height_map, mount_z + reach - 0.05, movable)
    if not len(targets):
        raise InputError(
            f"--robot {model.name}: no flat top nor movable object in the scene for the arm to work above ({MIN_TOP_M:g} m to "
            f"{mount_z + reach - 0.05:.2f} m high); build without --robot"
        )
    obstacles = [_hull(v[:, :2]) for _, v in pieces if v[:, 2].max() > FLOOR_EPS_M and v[:, 2].min() < model.height_m + 0.1]
    grid, shape = _candidate_grid(scene, pieces)
    points = shapely.points(grid)
    free = np.ones(len(grid), dtype=bool)
    clearance = np.full(len(grid), np.inf)
    if obstacles:
        tree = shapely.STRtree(obstacles)
        idx, dist = tree.query_nearest(points, return_distance=True, all_matches=False)
        clearance[idx[0]] = dist
    for wall in scene.room.walls:
        clearance = np.minimum(clearance, np.column_stack([grid, np.zeros(len(grid))]) @ wall.normal + wall.offset_m)
    clearance = clearance - radius
    free &= clearance >= CLEARANCE_M
    if not free.any():
        raise InputError(f"--robot {model.name}: no free floor spot {2 * radius:.2f} m wide in the room; build without --robot")
    cam_xy = scene.camera.position_m[:2]
    visible = _in_view(scene, grid, 0.5 * model.height_m)
    seen = _seen_floor(scene, grid, shape, radius)
    mount_r = float(np.linalg.norm(model.arm_mount_m[:2]))
    on_object = np.array([owners[k] != "background" for k in target_owner])
    keep = min(TARGETS_PER_SPOT, len(targets))
    best_scores = np.full((len(grid), keep), -np.inf)
    best_targets = np.zeros((len(grid), keep), dtype=int)
    sel_all = np.flatnonzero(free)
    seg = targets[:, :2] - cam_xy
    seg_len2 = np.maximum(np.einsum("ij,ij->i", seg, seg), 1e-9)
    for start in range(0, len(sel_all), CHUNK):
        sel = sel_all[start : start + CHUNK]
        away = targets[None, :, :2] - grid[sel, None, :]
        h = np.linalg.norm(away, axis=2) - mount_r  # the shoulder sits mount_r towards the target
        dist = np.hypot(h, targets[None, :, 2] - mount_z)
        ok = (h >= MIN_HORIZONTAL_M) & (dist <= reach)
        # Ranked: on floor the camera saw (not behind furniture, where a wall may hide), comfort
        # of the reach, an object's top over the background's, seen by the camera, not standing
        # between the camera and the target.
        tpar = np.clip(np.einsum("ftk,tk->ft", grid[sel, None, :] - cam_xy, seg) / seg_len2, 0.0, 1.0)
        closest = cam_xy + tpar[:, :, None] * seg[None]
        blocks = np.linalg.norm(grid[sel, None, :] - closest, axis=2) < radius
        score = (-np.abs(dist - COMFORT_FRACTION * model.reach_m) + 0.1 * on_object[None] + KIND_BONUS[target_kind][None]
                 + 0.2 * visible[sel, None]
                 + SEEN_FLOOR_WEIGHT * seen[sel, None] - 0.3 * blocks)
        score = np.where(ok, score, -np.inf)
        top = np.argsort(-score, axis=1, kind="stable")[:, :keep]
        best_scores[sel] = np.take_along_axis(score, top, axis=1)
        best_targets[sel] = top
    best_score = best_scores[:, 0]
    order = np.lexsort((np.arange(len(grid)), -np.round(best_score, 6)))
    chosen: list[RobotPlacement] = []
    for g in order:
        if not np.isfinite(best_score[g]) or len(chosen) >= CANDIDATES:
            break
        if any(np.linalg.norm(c.position_m[:2] - grid[g]) < CANDIDATE_SPACING_M for c in chosen):
            continue
        options = [t for t, sc in zip(best_targets[g], best_scores[g]) if np.isfinite(sc)
                   and footprints.path_clear(grid[g], targets[t])]
        if not options:
            continue
        target = targets[options[0]]
        yaw = float(np.arctan2(target[1] - grid[g][1], target[0] - grid[g][0]))
        name = owners[int(target_owner[options[0]])]
        kind = KIND_NAMES[int(target_kind[options[0]])]
        chosen.append(RobotPlacement(model, np.array([grid[g][0], grid[g][1], 0.0]), yaw, target, name, kind, float(clearance[g])))
    if not chosen:
        raise InputError(
            f"--robot {model.name}: no free floor spot within reach of a top or a movable object ({', '.join(sorted(set(owners))[:4])}); "
            "build without --robot or try another robot"
        )
    return tuple(chosen)

