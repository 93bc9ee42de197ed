"""Seen free space: what the camera saw through cannot hold an object.

A point lies in *seen free space* when it projects into the photo onto a pixel with a valid
depth and lies in front of that depth by more than the depth's noise: the camera saw something
behind it, so nothing was there. For the object being shaped (``own_mask``), a point that
projects outside its silhouette must moreover lie clearly *behind* what was seen there (hidden
by it), or the object would show where the camera saw something else: its rendered silhouette
is its mask. A generated shape must not fill such space, or rendered from
the photo's camera it hides what was seen behind it (a shape prior fitted to a mask that merged
two things into one wide box, a mirrored completion that pokes out of the silhouette).

Used to carve completed occupancy grids (``generation.completion.complete_occupancy``) and to
test whole assets (:func:`violation`), whose generator then falls back to the observed shell.
"""

from __future__ import annotations

import numpy as np

from scene_builder.frames import transform_points
from scene_builder.model import Camera, Observation, TriangleMesh

__all__ = ["FreeSpace", "surface_samples"]

#: Least margin in front of the observed depth before a point counts as seen free (m); the
#: structured-light noise model of ``perception.room.inlier_threshold_m`` is added on top
#: (2.5 sigma on the object's own pixels, whose surface it is; 1 sigma past its silhouette, where
#: whatever was seen there is not the object and the margin only absorbs depth noise).
FREE_MARGIN_M = 0.03
OFF_MASK_MARGIN_M = 0.01
#: Relative error (1 sigma) of depth estimated from one photo, not measured: monocular metric
#: depth models are good to about 5-10 % AbsRel on indoor benchmarks, and they tilt flat faces
#: (COCO 000089's microwave front read 25 degrees off its wall, 21 cm deep across 45 cm). A whole
#: shape contradicts such depth only beyond 2.5 of it (:meth:`FreeSpace.violation`).
ESTIMATED_DEPTH_REL_SIGMA = 0.05


class FreeSpace:
    """Seen free space of one observation (see the module docstring)."""

    def __init__(self, observation: Observation, camera: Camera, margin_m: float = FREE_MARGIN_M, own_mask: np.ndarray | None = None) -> None:
        """own_mask: (H, W) bool pixels of the object being shaped (its own surface), or None."""
        self.depth = np.asarray(observation.depth_m, dtype=np.float64)
        self.k = observation.intrinsics
        self.camera_from_world = np.linalg.inv(camera.world_from_camera)
        self.margin = float(margin_m)
        self.own = own_mask
        self.estimated = observation.depth_source != "sensor"

    def _lookup(self, points_world_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N,) point depth along the optical axis, (N,) observed depth at its pixel (0 where
        outside the image, behind the camera or unobserved) and (N,) whether that pixel is the
        object's own."""
        p = transform_points(self.camera_from_world, np.asarray(points_world_m, dtype=np.float64).reshape(-1, 3))
        z = p[:, 2]
        h, w = self.depth.shape
        obs = np.zeros(len(p))
        ahead = z > 1e-6
        u = np.full(len(p), -1)
        v = np.full(len(p), -1)
        u[ahead] = np.floor(self.k.fx_px * p[ahead, 0] / z[ahead] + self.k.cx_px + 0.5).astype(np.int64)
        v[ahead] = np.floor(self.k.fy_px * p[ahead, 1] / z[ahead] + self.k.cy_px + 0.5).astype(np.int64)
        inside = ahead & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        obs[inside] = self.depth[v[inside], u[inside]]
        own = np.ones(len(p), dtype=bool)
        if self.own is not None:
            own[inside] = self.own[v[inside], u[inside]]
        return z, obs, own

    def tolerance_m(self, depth_m: np.ndarray, extra_m: float = 0.0) -> np.ndarray:
        """Noise margin at observed depth ``depth_m``: FREE_MARGIN_M + 2.5 sigma of the
        structured-light model sigma = 1.425e-3 z^2 (as ``perception.room.inlier_threshold_m``)."""
        return extra_m + self.margin + 2.5 * 1.425e-3 * np.asarray(depth_m) ** 2

    def free(self, points_world_m: np.ndarray, extra_margin_m: float = 0.0) -> np.ndarray:
        """(N,) bool: the (N, 3) world points lie in seen free space, or (with ``own_mask``)
        would show outside the object's silhouette: in front of, or not clearly behind
        (OFF_MASK_MARGIN_M + 1 sigma), what was seen at their pixel."""
        z, obs, own = self._lookup(points_world_m)
        seen = obs > 0
        out = seen & (z < obs - self.tolerance_m(obs, extra_margin_m))
        if self.own is not None:
            sigma = 1.425e-3 * obs**2
            out |= seen & ~own & (z < obs + OFF_MASK_MARGIN_M + sigma - extra_margin_m)
        return out

    def snap(self, points_world_m: np.ndarray, max_move_m: float) -> np.ndarray:
        """(N, 3) points with those that project onto the object's own pixels (``own_mask``)
        within ``max_move_m`` of the observed depth there moved along their ray onto it: the
        surface the camera saw, where a voxel surface only approximates it."""
        p = np.array(points_world_m, dtype=np.float64).reshape(-1, 3)
        z, obs, own = self._lookup(p)
        sel = own & (obs > 0) & (np.abs(z - obs) <= max_move_m) & (z > 1e-6)
        if not np.any(sel):
            return p
        cam = transform_points(self.camera_from_world, p[sel]) * (obs[sel] / z[sel])[:, None]
        p[sel] = transform_points(np.linalg.inv(self.camera_from_world), cam)
        return p

    def violation(self, points_world_m: np.ndarray) -> float:
        """Share of the (N, 3) world points that project onto observed pixels and lie in seen free
        space (0 when none projects onto an observed pixel). On estimated depth the margin is its
        relative error (:data:`ESTIMATED_DEPTH_REL_SIGMA`) where that is the larger."""
        z, obs, _ = self._lookup(points_world_m)
        seen = obs > 0
        if not np.any(seen):
            return 0.0
        tol = self.tolerance_m(obs[seen])
        if self.estimated:
            tol = np.maximum(tol, 2.5 * ESTIMATED_DEPTH_REL_SIGMA * obs[seen])
        return float(np.mean(z[seen] < obs[seen] - tol))


def surface_samples(meshes: list[TriangleMesh] | tuple[TriangleMesh, ...], count: int, seed: int = 0) -> np.ndarray:
    """(count, 3) points spread over the meshes' surfaces by area (seeded, deterministic)."""
    tris = [m.vertices_m[m.faces] for m in meshes if len(m.faces)]
    if not tris:
        return np.zeros((0, 3))
    t = np.concatenate(tris)  # (F, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    if area.sum() <= 0:
        return t[:, 0]
    rng = np.random.default_rng(seed)
    f = rng.choice(len(t), size=count, p=area / area.sum())
    r1, r2 = rng.random(count), rng.random(count)
    flip = r1 + r2 > 1.0
    r1[flip], r2[flip] = 1.0 - r1[flip], 1.0 - r2[flip]
    return t[f, 0] + r1[:, None] * (t[f, 1] - t[f, 0]) + r2[:, None] * (t[f, 2] - t[f, 0])
