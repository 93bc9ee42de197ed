"""Where the robot stands: a free floor spot inside the room, facing a support surface its arm
reaches, preferably seen by the input camera and not hiding the target from it.

The floor plan (shapely polygons, the well-kept library for 2-D geometry): every collision piece
of the scene (objects, fixed furniture, the background's boxes and pieces) that rises above the
floor and starts below the robot's height is an obstacle, as its footprint (a convex piece
projects to the convex hull of its vertices); walls are half-planes over their spans (past a
bounded wall's end the floor goes on: ``Plane.clearance_m``). Candidate spots lie on a
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
top before its side (each kind's spots in turn), visibility from the input camera, not
standing between the camera and the target, then grid order (deterministic).

:mod:`layout.reach` then measures each candidate in MuJoCo (overlap at the start and home poses,
the scripted reach swept kinematically); the pipeline keeps the first that passes.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scene_builder.errors import InputError
from scene_builder.model import Scene
from scene_builder.robot import RobotModel, RobotPlacement

GRID_M = 0.05
CELL_M = 0.04
CLEARANCE_M = 0.05
FLOOR_EPS_M = 0.003  # geometry lower than this is the floor itself (the robot's geoms start at 5 mm)
TARGET_HEIGHT_M = 0.18
LOW_TARGET_HEIGHT_M = 0.1
TARGET_INSET_M = 0.06
ON_TOP_CLEARANCE_M = 0.12
MIN_TOP_M = 0.05
TOP_BAND_M = 0.03
REACH_FRACTION = 0.75
FREE_REACH_FRACTION = 0.9  # with the tool's axis free and the target lowered (see alternatives)
COMFORT_FRACTION = 0.55
MIN_HORIZONTAL_M = 0.25
ROOM_MARGIN_M = 1.5
CANDIDATES = 8
CHUNK = 128
TOP, OBJECT_TOP, SIDE = 0, 1, 2
KIND_NAMES = ("top", "object_top", "side")
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
TURNS_RAD = (np.pi / 4, -np.pi / 4, np.pi / 2, -np.pi / 2)
STEP_BACK_M = (0.05, 0.1, 0.15)
SCORE_GRID_CELLS = 4  # the fixed reach targets of ``reach_targets``: every 4th cell, 16 cm apart


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

        self.vertices = [v for _, v in pieces]
        self.polys = [_hull(v[:, :2]) for v in self.vertices]
        self.z = np.array([[v[:, 2].min(), v[:, 2].max()] for v in self.vertices])
        self.tree = shapely.STRtree(self.polys)

    def path_clear(self, spot_xy: np.ndarray, target: np.ndarray) -> bool:
        """The arm comes in over the top: no piece within PATH_WIDTH_M of the floor-plan segment
        from the spot to the target reaches into the band from PATH_CLEARANCE_M under the target
        point to ARM_BAND_M above it (where the forearm and the elbow pass). A piece's height
        under the path is its exact top there (a bed's convex piece is low at the mattress and
        high at the headboard), sampled every CELL_M / 2 along the segment and at its sides."""
        import shapely

        line = shapely.LineString([spot_xy.tolist(), target[:2].tolist()]).buffer(PATH_WIDTH_M)
        hits = self.tree.query(line, predicate="intersects")
        floor_z, ceiling_z = target[2] - PATH_CLEARANCE_M, target[2] + ARM_BAND_M
        hits = [h for h in hits if self.z[h, 1] > floor_z and self.z[h, 0] < ceiling_z]
        if not hits:
            return True
        along = target[:2] - spot_xy
        length = float(np.linalg.norm(along))
        side = np.array([-along[1], along[0]]) / max(length, 1e-9)
        t = np.linspace(0.0, 1.0, max(2, int(np.ceil(length / (0.5 * CELL_M))) + 1))
        samples = np.concatenate([spot_xy + t[:, None] * along + o * side for o in (-PATH_WIDTH_M, 0.0, PATH_WIDTH_M)])
        for h in hits:
            inside = shapely.contains_xy(self.polys[h], samples[:, 0], samples[:, 1])
            pts = samples[inside] if inside.any() else np.array(shapely.get_coordinates(self.polys[h].intersection(line).representative_point()))
            if float(_convex_top(self.vertices[h], pts[:, 0], pts[:, 1]).max()) > floor_z:
                return False
        return True


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


class _Scoring:
    """Spots ranked by their best targets among ``targets`` (T, 3): for each free grid spot the
    TARGETS_PER_SPOT best-scored targets it reaches (see the module docstring for the score),
    a target counting as reached when the point ``drop_m`` under it is within ``reach``."""

    def __init__(self, grid, free, targets, on_object, visible, seen, cam_xy, radius, mount_r, mount_z, reach, comfort_m,
                 drop_m: float = 0.0) -> None:
        keep = min(TARGETS_PER_SPOT, len(targets))
        self.scores = np.full((len(grid), keep), -np.inf)
        self.best = np.zeros((len(grid), keep), dtype=int)
        sel_all = np.flatnonzero(free)
        seg = targets[:, :2] - cam_xy
        seg_len2 = np.maximum(np.einsum("ij,ij->i", seg, seg), 1e-9)
        for start in range(0, len(sel_all), CHUNK):
            sel = sel_all[start : start + CHUNK]
            away = targets[None, :, :2] - grid[sel, None, :]
            h = np.linalg.norm(away, axis=2) - mount_r  # the shoulder sits mount_r towards the target
            dist = np.hypot(h, targets[None, :, 2] - mount_z)
            ok = (h >= MIN_HORIZONTAL_M) & (np.hypot(h, targets[None, :, 2] - drop_m - mount_z) <= reach)
            # Ranked: on floor the camera saw (not behind furniture, where a wall may hide), comfort
            # of the reach, an object's top over the background's, seen by the camera, not standing
            # between the camera and the target.
            tpar = np.clip(np.einsum("ftk,tk->ft", grid[sel, None, :] - cam_xy, seg) / seg_len2, 0.0, 1.0)
            closest = cam_xy + tpar[:, :, None] * seg[None]
            blocks = np.linalg.norm(grid[sel, None, :] - closest, axis=2) < radius
            score = (-np.abs(dist - comfort_m) + 0.1 * on_object[None] + 0.2 * visible[sel, None]
                     + SEEN_FLOOR_WEIGHT * seen[sel, None] - 0.3 * blocks)
            score = np.where(ok, score, -np.inf)
            top = np.argsort(-score, axis=1, kind="stable")[:, :keep]
            self.scores[sel] = np.take_along_axis(score, top, axis=1)
            self.best[sel] = top

    def ranked(self):
        """(spot index, target indices reaching it best first) for spots reaching any, best
        spot first (ties in grid order: deterministic)."""
        first = self.scores[:, 0]
        for g in np.lexsort((np.arange(len(first)), -np.round(first, 6))):
            if not np.isfinite(first[g]):
                return
            yield g, [t for t, sc in zip(self.best[g], self.scores[g]) if np.isfinite(sc)]


def _clearance(scene: Scene, pieces: list[tuple[str, np.ndarray]], model: RobotModel, xy: np.ndarray) -> np.ndarray:
    """(G,) distance from the robot's footprint circle at each spot ``xy`` (G, 2) to the nearest
    obstacle footprint (pieces from above the floor to above the robot) or wall; negative
    inside one."""
    import shapely

    obstacles = [_hull(v[:, :2]) for _, v in pieces if v[:, 2].max() > FLOOR_EPS_M and v[:, 2].min() < model.height_m + 0.1]
    clearance = np.full(len(xy), np.inf)
    if obstacles:
        idx, dist = shapely.STRtree(obstacles).query_nearest(shapely.points(xy), return_distance=True, all_matches=False)
        clearance[idx[0]] = dist
    for wall in scene.room.walls:
        clearance = np.minimum(clearance, wall.clearance_m(np.column_stack([xy, np.zeros(len(xy))])))
    return clearance - float(model.footprint_radius_m)


def reach_targets(scene: Scene) -> tuple[np.ndarray, tuple[str, ...]]:
    """The fixed target set of ``scene`` for the reach figure (``layout.reach.score_reach``),
    decided from the scene alone, before and whatever the placement: a point TARGET_HEIGHT_M
    above every flat top (an object's, fixed furniture's or the background's; the height map's
    cells flat within TOP_BAND_M over TARGET_INSET_M, clear of what stands on them within
    ON_TOP_CLEARANCE_M, at least MIN_TOP_M high, inside the walls) on a grid of every
    SCORE_GRID_CELLS-th cell, and on a top the grid misses the cell nearest its middle. Returns
    (T, 3) points and the owner of each (an object's name or ``background``)."""
    from scipy import ndimage

    pieces = _pieces(scene)
    height_map = _height_map(pieces)
    lo = height_map[0]
    points, owner_index, _, owners = _targets(height_map, np.inf, set())
    inside = np.ones(len(points), dtype=bool)
    for wall in scene.room.walls:
        inside &= wall.clearance_m(points) > 0.0
    points, owner_index = points[inside], owner_index[inside]
    if not len(points):
        return np.zeros((0, 3)), ()
    ij = np.round((points[:, :2] - lo) / CELL_M).astype(int)
    keep = (ij % SCORE_GRID_CELLS == 0).all(axis=1)
    # Each connected flat top (one owner's cells at one height) gets a point, on the grid or not.
    grid = np.full(ij.max(axis=0) + 1, -1)
    grid[ij[:, 0], ij[:, 1]] = np.arange(len(points))
    for k in np.unique(owner_index):
        mask = np.zeros(grid.shape, dtype=bool)
        mine = np.flatnonzero(owner_index == k)
        mask[ij[mine, 0], ij[mine, 1]] = True
        labels, n = ndimage.label(mask)
        for c in range(1, n + 1):
            cells = grid[labels == c]
            if keep[cells].any():
                continue
            middle = points[cells, :2].mean(axis=0)
            keep[cells[np.argmin(np.linalg.norm(points[cells, :2] - middle, axis=1))]] = True
    return points[keep], tuple(owners[int(k)] for k in owner_index[keep])


def alternatives(scene: Scene, placement: RobotPlacement) -> list[RobotPlacement]:
    """Placements to try in the stead of ``placement`` when its robot overlaps the scene (its arm's
    home pose reaching over the edge of the bed or table it faces) or its arm falls short: at
    the same spot turned by each of TURNS_RAD (the arm turns to the target during the reach),
    stepped straight back from the target by each of STEP_BACK_M, still facing it (only spots
    free on the floor plan with the target in reach); then all of them again, and the placement
    itself, with a target over a top lowered to LOW_TARGET_HEIGHT_M above it (a high table at
    the edge of a floor-standing arm's reach); last, the placement and its turned and stepped
    back poses with the tool's approach axis free (see ``RobotPlacement.hold_tool_axis``), at
    the target and at the lowered one."""
    model = placement.model
    poses = [dataclasses.replace(placement, yaw_rad=float(placement.yaw_rad + t)) for t in TURNS_RAD]
    heading = np.array([np.cos(placement.yaw_rad), np.sin(placement.yaw_rad)])
    spots = placement.position_m[:2] - np.asarray(STEP_BACK_M)[:, None] * heading
    clearance = _clearance(scene, _pieces(scene), model, spots)
    mount_r, mount_z = float(np.linalg.norm(model.arm_mount_m[:2])), float(model.arm_mount_m[2])
    for xy, clear in zip(spots, clearance):
        horizontal = float(np.linalg.norm(placement.target_m[:2] - xy)) - mount_r
        if clear < CLEARANCE_M or np.hypot(horizontal, placement.target_m[2] - mount_z) > FREE_REACH_FRACTION * model.reach_m:
            continue
        yaw = float(np.arctan2(placement.target_m[1] - xy[1], placement.target_m[0] - xy[0]))
        poses.append(dataclasses.replace(placement, position_m=np.array([xy[0], xy[1], 0.0]), yaw_rad=yaw, clearance_m=float(clear)))
    tried = [placement, *poses]
    if placement.target_kind != "side":
        low = placement.target_m - np.array([0.0, 0.0, TARGET_HEIGHT_M - LOW_TARGET_HEIGHT_M])
        tried += [dataclasses.replace(p, target_m=low) for p in tried]
    return tried[1:] + [dataclasses.replace(p, hold_tool_axis=False) for p in tried]


def place_robot(scene: Scene, model: RobotModel) -> tuple[RobotPlacement, ...]:
    """Placements best first: up to CANDIDATES of each target kind (a top, then an object's top,
    then beside an object), each kind's at least CANDIDATE_SPACING_M apart.

    Raises InputError when no free floor spot reaches any support surface."""
    pieces = _pieces(scene)
    radius = float(model.footprint_radius_m)
    mount_z = float(model.arm_mount_m[2])
    reach = REACH_FRACTION * float(model.reach_m)
    height_map = _height_map(pieces)
    footprints = _Footprints(pieces)
    movable = {o.name for o in scene.objects if not o.asset.is_fixed}
    free_reach = FREE_REACH_FRACTION * float(model.reach_m)
    targets, target_owner, target_kind, owners = _targets(height_map, mount_z + free_reach - LOW_TARGET_HEIGHT_M, movable)
    inside = np.ones(len(targets), dtype=bool)  # a top behind a wall is not the room's
    for wall in scene.room.walls:
        inside &= wall.clearance_m(targets) > 0.0
    targets, target_owner, target_kind = targets[inside], target_owner[inside], target_kind[inside]
    if not len(targets):
        raise InputError(
            f"--robot {model.name}: no flat top nor movable object in the scene for the arm to work above ({MIN_TOP_M:g} m to "
            f"{mount_z + free_reach - LOW_TARGET_HEIGHT_M:.2f} m high); build without --robot"
        )
    grid, shape = _candidate_grid(scene, pieces)
    clearance = _clearance(scene, pieces, model, grid)
    free = clearance >= CLEARANCE_M
    if not free.any():
        raise InputError(f"--robot {model.name}: no free floor spot {2 * radius:.2f} m wide in the room; build without --robot")
    cam_xy = scene.camera.position_m[:2]
    visible = _in_view(scene, grid, 0.5 * model.height_m)
    seen = _seen_floor(scene, grid, shape, radius)
    mount_r = float(np.linalg.norm(model.arm_mount_m[:2]))
    on_object = np.array([owners[k] != "background" for k in target_owner])
    chosen: list[RobotPlacement] = []
    # A table before an object's top before its side: each kind's best spots in turn, so that
    # the pipeline's MuJoCo check tries every spot reaching a top before settling for less.
    for kind in (TOP, OBJECT_TOP, SIDE):
        of_kind = np.flatnonzero(target_kind == kind)
        if not len(of_kind):
            continue
        # Over a top, a spot counts when the lowered target is in the arm's reach with the tool
        # free (:func:`alternatives` tries those last).
        top_kind = kind != SIDE
        ctx = _Scoring(grid, free, targets[of_kind], on_object[of_kind], visible, seen, cam_xy, radius, mount_r, mount_z,
                       free_reach if top_kind else reach, COMFORT_FRACTION * model.reach_m,
                       TARGET_HEIGHT_M - LOW_TARGET_HEIGHT_M if top_kind else 0.0)
        picked = []
        for g, options in ctx.ranked():
            if len(picked) >= CANDIDATES:
                break
            if any(np.linalg.norm(c.position_m[:2] - grid[g]) < CANDIDATE_SPACING_M for c in picked):
                continue
            options = [of_kind[t] for t in options if footprints.path_clear(grid[g], targets[of_kind[t]])]
            if not options:
                continue
            target = targets[options[0]]
            yaw = float(np.arctan2(target[1] - grid[g][1], target[0] - grid[g][0]))
            name = owners[int(target_owner[options[0]])]
            picked.append(RobotPlacement(model, np.array([grid[g][0], grid[g][1], 0.0]), yaw, target, name, KIND_NAMES[kind],
                                         float(clearance[g])))
        chosen.extend(picked)
    if not chosen:
        raise InputError(
            f"--robot {model.name}: no free floor spot within reach of a top or a movable object ({', '.join(sorted(set(owners))[:4])}); "
            "build without --robot or try another robot"
        )
    return tuple(chosen)

