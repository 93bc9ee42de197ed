"""Where the robot stands: a free floor spot inside the room, facing a support surface its arm
reaches, preferably seen by the input camera and not hiding the target from it.

The floor plan (shapely polygons, the well-kept library for 2-D geometry): every collision piece
of the scene (objects, fixed furniture, the background's boxes and pieces) that rises above the
floor and starts below the robot's height is an obstacle, as its footprint (a convex piece
projects to the convex hull of its vertices); walls are half-planes. Candidate spots lie on a
:data:`GRID_M` grid; a spot is free when the robot's footprint circle (measured on its model at
the home pose) keeps :data:`CLEARANCE_M` from every obstacle and wall.

Targets: the top of every object (and object left as background) that is at least
:data:`MIN_TOP_AREA_M2` large, :data:`TARGET_INSET_M` in from its edge and away from whatever
stands on it; the target point is :data:`TARGET_HEIGHT_M` above that top. A spot is reachable when
that point, at its nearest, lies within :data:`REACH_FRACTION` of the arm's sampled reach from the
shoulder. Spots are ranked by how comfortably they reach (distance near :data:`COMFORT_FRACTION`
of the reach), then visibility from the input camera, then grid order (deterministic).

:func:`robot_overlaps` measures the placed robot against the scene in MuJoCo (``mj_geomDistance``,
home pose and start pose); the pipeline takes the first candidate with none.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scene_builder.errors import InputError
from scene_builder.model import Scene
from scene_builder.robot import RobotModel, RobotPlacement

GRID_M = 0.05
CLEARANCE_M = 0.05
FLOOR_EPS_M = 0.003  # geometry lower than this is the floor itself (the robot's geoms start at 5 mm)
TARGET_HEIGHT_M = 0.18
TARGET_INSET_M = 0.08
ON_TOP_CLEARANCE_M = 0.12
MIN_TOP_AREA_M2 = 0.04
MIN_TOP_M = 0.2
TOP_BAND_M = 0.03
REACH_FRACTION = 0.85
COMFORT_FRACTION = 0.65
MIN_HORIZONTAL_M = 0.25
ROOM_MARGIN_M = 1.5
CANDIDATES = 6
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


def _supports(scene: Scene, pieces: list[tuple[str, np.ndarray]], max_top_m: float) -> list[tuple[str, float, object]]:
    """(name, top z, target region polygon) of each surface the arm could work above."""
    import shapely

    tops: list[tuple[str, list[np.ndarray]]] = []
    for o in scene.objects:
        verts = [v for owner, v in pieces if owner == o.name]
        if verts:
            tops.append((o.name, verts))
    bg = scene.room.background
    if bg is not None:
        tops += [(f"background/object/{n}", [np.asarray(m.vertices_m)]) for n, m in zip(bg.static_names, bg.static_meshes)]
    out = []
    for name, verts in tops:
        allv = np.concatenate(verts)
        top = float(allv[:, 2].max())
        if not MIN_TOP_M <= top <= max_top_m:
            continue
        band = allv[allv[:, 2] >= top - TOP_BAND_M]
        if len(band) < 3:
            continue
        region = _hull(band[:, :2])
        if region.area < MIN_TOP_AREA_M2:
            continue
        region = region.buffer(-TARGET_INSET_M)
        # Whatever stands on this top (rises above it over its outline) is kept clear of.
        for owner, v in pieces:
            if owner == name or v[:, 2].max() <= top + 0.02 or v[:, 2].min() > top + TARGET_HEIGHT_M + 0.3:
                continue
            foot = _hull(v[:, :2])
            if foot.intersects(region.buffer(ON_TOP_CLEARANCE_M)):
                region = region.difference(foot.buffer(ON_TOP_CLEARANCE_M))
        if not region.is_empty and region.area > 1e-4:
            out.append((name, top, shapely.make_valid(region)))
    out.sort(key=lambda s: s[0])
    return out


def _candidate_grid(scene: Scene, pieces: list[tuple[str, np.ndarray]]) -> np.ndarray:
    """(G, 2) grid spots over the scene's extent (objects, background, camera) plus a margin."""
    xy = [v[:, :2] for _, v in pieces] + [scene.camera.position_m[None, :2]]
    allxy = np.concatenate(xy)
    lo, hi = allxy.min(axis=0) - ROOM_MARGIN_M, allxy.max(axis=0) + ROOM_MARGIN_M
    xs = np.arange(np.floor(lo[0] / GRID_M) * GRID_M, hi[0] + 1e-9, GRID_M)
    ys = np.arange(np.floor(lo[1] / GRID_M) * GRID_M, hi[1] + 1e-9, GRID_M)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


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
    supports = _supports(scene, pieces, mount_z + reach - 0.05 - TARGET_HEIGHT_M)
    if not supports:
        raise InputError(
            f"--robot {model.name}: no surface in the scene for the arm to work above (tops {MIN_TOP_M:g} m to "
            f"{mount_z + reach - TARGET_HEIGHT_M:.2f} m high, at least {MIN_TOP_AREA_M2:g} m2); build without --robot"
        )
    obstacles = [_hull(v[:, :2]) for _, v in pieces if v[:, 2].max() > FLOOR_EPS_M and v[:, 2].min() < model.height_m + 0.1]
    grid = _candidate_grid(scene, pieces)
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
    best_score = np.full(len(grid), -np.inf)
    best_target = np.zeros((len(grid), 3))
    best_support = np.full(len(grid), -1)
    mount_r = float(np.linalg.norm(model.arm_mount_m[:2]))
    for s, (_name, top, region) in enumerate(supports):
        sel = np.flatnonzero(free)
        lines = shapely.shortest_line(points[sel], region)
        coords = shapely.get_coordinates(lines).reshape(-1, 2, 2)
        target_xy = coords[:, 1]
        away = target_xy - grid[sel]
        h = np.linalg.norm(away, axis=1) - mount_r  # the shoulder sits mount_r towards the target
        v = top + TARGET_HEIGHT_M - mount_z
        dist = np.hypot(h, v)
        ok = (h >= MIN_HORIZONTAL_M) & (dist <= reach)
        # Ranked: comfort of the reach, then seen by the camera, then not in front of the target.
        seg = target_xy - cam_xy
        tpar = np.clip(np.einsum("ij,ij->i", grid[sel] - cam_xy, seg) / np.maximum(np.einsum("ij,ij->i", seg, seg), 1e-9), 0, 1)
        blocks = np.linalg.norm(grid[sel] - (cam_xy + tpar[:, None] * seg), axis=1) < radius
        score = -np.abs(dist - COMFORT_FRACTION * model.reach_m) + 0.2 * visible[sel] - 0.3 * blocks
        score = np.where(ok, score, -np.inf)
        better = score > best_score[sel]
        best_score[sel[better]] = score[better]
        best_target[sel[better]] = np.column_stack([target_xy[better], np.full(better.sum(), top + TARGET_HEIGHT_M)])
        best_support[sel[better]] = s
    order = np.lexsort((np.arange(len(grid)), -np.round(best_score, 6)))
    chosen: list[RobotPlacement] = []
    for g in order:
        if not np.isfinite(best_score[g]) or len(chosen) >= CANDIDATES:
            break
        if any(np.linalg.norm(c.position_m[:2] - grid[g]) < CANDIDATE_SPACING_M for c in chosen):
            continue
        target = best_target[g]
        yaw = float(np.arctan2(target[1] - grid[g][1], target[0] - grid[g][0]))
        name = supports[int(best_support[g])][0]
        chosen.append(RobotPlacement(model, np.array([grid[g][0], grid[g][1], 0.0]), yaw, target, name, TARGET_HEIGHT_M,
                                     float(clearance[g])))
    if not chosen:
        raise InputError(
            f"--robot {model.name}: no free floor spot within reach of a surface ({', '.join(s[0] for s in supports[:4])}); "
            "build without --robot or try another robot"
        )
    return tuple(chosen)


def robot_overlaps(mjcf_path: Path) -> float:
    """Deepest overlap (m, 0 when none) between a robot geom (bodies ``robot/...``) and any
    other collision geom of the written scene, at the start pose and at keyframe ``robot/home``
    (when the scene has it), measured with ``mj_geomDistance``."""
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(mjcf_path))
    d = mujoco.MjData(m)
    robot_body = np.array([m.body(b).name.startswith("robot/") for b in range(m.nbody)])
    geoms = np.flatnonzero((m.geom_contype != 0) | (m.geom_conaffinity != 0))
    mine = [int(g) for g in geoms if robot_body[m.geom_bodyid[g]]]
    others = [int(g) for g in geoms if not robot_body[m.geom_bodyid[g]]]
    worst = 0.0
    fromto = np.zeros(6)
    key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "robot/home")
    for k in ([-1, key] if key >= 0 else [-1]):
        if k < 0:
            mujoco.mj_resetData(m, d)
        else:
            mujoco.mj_resetDataKeyframe(m, d, k)
        mujoco.mj_forward(m, d)
        for a in mine:
            for b in others:
                if np.linalg.norm(d.geom_xpos[a] - d.geom_xpos[b]) > m.geom_rbound[a] + m.geom_rbound[b] and m.geom_rbound[b] > 0:
                    continue
                dist = float(mujoco.mj_geomDistance(m, d, a, b, 0.01, fromto))
                worst = max(worst, -dist)
    return worst

