"""Manhattan yaw snapping: turn an object to the room's wall directions when the turn is small
(perception's yaw error, at most :data:`SNAP_MAX_DEG`) and its observed points fit the snapped pose
nearly as well as the initial one. A larger turn is never made: the asset's geometry and photo
texture were built at the observed yaw, and turning it by tens of degrees would move what was
seen (a twin keeps objects where they were seen)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scene_builder.frames import rot_z, yaw_of
from scene_builder.model import ObjectAsset, Room

# Snap a turn of up to SNAP_MAX_DEG when the snapped fit cost is within 10 % (plus 2 mm of
# sensor noise) of the initial one (with too few points to judge a fit, snap it anyway).
SNAP_COST_RATIO = 1.10
SNAP_COST_SLACK_M = 0.002
MIN_POINTS_FOR_FIT = 20
SNAP_MAX_DEG = 12.0
MAX_FIT_POINTS = 300
# The snapped pose's plan position may move this far to re-fit the points.
MAX_REFIT_M = 0.15


@dataclass(frozen=True)
class YawSnap:
    """Outcome of snapping one object.

    snapped: whether the yaw changed. delta_deg: applied yaw change (0 when not snapped).
    cost_initial_m, cost_snapped_m: mean distance of the observed points to the asset's box
    surface at the initial and at the snapped pose (NaN without points).
    """

    snapped: bool
    delta_deg: float
    cost_initial_m: float
    cost_snapped_m: float


def reference_yaw(room: Room) -> float:
    """Yaw (rad) of the room's Manhattan axes modulo 90 deg: from the wall with the most inliers,
    else 0 (perception's world X)."""
    if not room.walls:
        return 0.0
    wall = max(room.walls, key=lambda w: (w.inlier_count, -abs(yaw_of_normal(w.normal))))
    return float(np.mod(yaw_of_normal(wall.normal), np.pi / 2))


def yaw_of_normal(normal: np.ndarray) -> float:
    return float(np.arctan2(normal[1], normal[0]))


def asset_bounds(asset: ObjectAsset) -> np.ndarray:
    """(2, 3) min/max corner of all visual vertices in the asset frame."""
    v = np.concatenate([p.visual.vertices_m for p in asset.parts])
    return np.stack([v.min(axis=0), v.max(axis=0)])


def box_surface_distance(points_asset_m: np.ndarray, bounds_m: np.ndarray) -> np.ndarray:
    """(N,) unsigned distance of (N, 3) points (asset frame) to the surface of the box ``bounds_m`` (2, 3)."""
    lo, hi = bounds_m
    outside = np.maximum(np.maximum(lo - points_asset_m, points_asset_m - hi), 0.0)
    d_out = np.linalg.norm(outside, axis=1)
    d_in = np.minimum(points_asset_m - lo, hi - points_asset_m).min(axis=1)
    return np.where(d_out > 0.0, d_out, np.abs(d_in))


def _fit_cost(points: np.ndarray, bounds: np.ndarray, rotation: np.ndarray, position: np.ndarray) -> float:
    local = (points - position) @ rotation
    return float(np.mean(box_surface_distance(local, bounds)))


def _refit_xy(points: np.ndarray, bounds: np.ndarray, rotation: np.ndarray, position: np.ndarray) -> np.ndarray:
    """Best plan translation (3,) for a fixed rotation: robust least squares of point-to-box distance."""
    from scipy.optimize import least_squares

    def residual(dxy):
        p = position + np.array([dxy[0], dxy[1], 0.0])
        return box_surface_distance((points - p) @ rotation, bounds)

    sol = least_squares(residual, np.zeros(2), loss="soft_l1", f_scale=0.01, xtol=1e-6)
    dxy = np.clip(sol.x, -MAX_REFIT_M, MAX_REFIT_M)
    return position + np.array([dxy[0], dxy[1], 0.0])


def snap_yaw(
    asset: ObjectAsset,
    world_from_asset: np.ndarray,
    observed_points_world_m: np.ndarray,
    ref_yaw_rad: float,
    seed: int = 0,
) -> tuple[np.ndarray, YawSnap]:
    """Snap the yaw of ``world_from_asset`` (4, 4) to ``ref_yaw_rad`` + k * 90 deg when supported.

    The candidate keeps the asset's front direction class (the nearest multiple of 90 deg, so a
    change of at most 45 deg) and re-fits its plan position to the points. Returns the new
    (4, 4) pose (the input unchanged when not snapped) and the decision. Geometry is never changed.
    """
    rotation = world_from_asset[:3, :3]
    position = world_from_asset[:3, 3]
    if asset.observed_shape:
        # Built from the observed surface at the observed pose: turning it moves what was seen.
        return world_from_asset, YawSnap(False, 0.0, np.nan, np.nan)
    yaw = yaw_of(rotation)
    quarter = np.pi / 2
    delta = float(ref_yaw_rad + np.round((yaw - ref_yaw_rad) / quarter) * quarter - yaw)
    delta = float(np.arctan2(np.sin(delta), np.cos(delta)))
    if abs(delta) < 1e-9 or abs(np.degrees(delta)) > SNAP_MAX_DEG:
        return world_from_asset, YawSnap(False, 0.0, np.nan, np.nan)
    new_rot = rot_z(delta) @ rotation
    pts = np.asarray(observed_points_world_m, dtype=np.float64)
    if len(pts) < MIN_POINTS_FOR_FIT:
        ok = True
        cost0 = cost1 = float("nan")
        new_pos = position
    else:
        if len(pts) > MAX_FIT_POINTS:
            idx = np.sort(np.random.default_rng(seed).choice(len(pts), MAX_FIT_POINTS, replace=False))
            pts = pts[idx]
        bounds = asset_bounds(asset)
        # Both poses get the same freedom (a plan re-fit), so the comparison is fair.
        cost0 = _fit_cost(pts, bounds, rotation, _refit_xy(pts, bounds, rotation, position))
        new_pos = _refit_xy(pts, bounds, new_rot, position)
        cost1 = _fit_cost(pts, bounds, new_rot, new_pos)
        ok = cost1 <= SNAP_COST_RATIO * cost0 + SNAP_COST_SLACK_M
    if not ok:
        return world_from_asset, YawSnap(False, 0.0, cost0, cost1)
    out = np.eye(4)
    out[:3, :3] = new_rot
    out[:3, 3] = new_pos
    return out, YawSnap(True, float(np.degrees(delta)), cost0, cost1)
