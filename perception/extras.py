"""Whether a depth cluster no detection explains is a clear object (the "extras" of the
``"detections"`` segmenter, :mod:`perception.segment_detect`): solid in the image, of a plausible
size, and of 3D shape with a visible top, or alone in the view (a close-up). Everything else stays
in the static background: a missed object is still seen in the background's texture, an invented
one is a box that is not there."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["ISOLATED_AREA", "ISOLATED_SHARE", "MIN_HEIGHT_M", "MIN_THICKNESS_M", "MIN_TOP_SHARE", "TOP_COS", "is_clear", "point_normals", "separated_share", "solidity"]

#: A cluster of this share of the image with this share of its surroundings unknown or far
#: behind is alone in the view (a close-up): clear whatever its shape.
ISOLATED_AREA = 0.05
ISOLATED_SHARE = 0.9
#: An extra object's points (2nd to 98th percentile) rise at least this high: a 10 cm box on the
#: floor is an object, a 2 cm bump of the floor's depth noise is not.
MIN_HEIGHT_M = 0.06
#: An extra object's points spread at least this much (standard deviation, metres) off their
#: best-fit plane.
MIN_THICKNESS_M = 0.015
#: ... and this share of them lies on surfaces facing up (normal within 37 degrees of up).
MIN_TOP_SHARE = 0.08
TOP_COS = 0.8


def separated_share(mask: np.ndarray, depth_m: np.ndarray, valid: np.ndarray, ring_px: int = 4) -> float:
    """Share of the ring of pixels around ``mask`` whose depth is unknown or at least 0.2 m (and
    5 %) behind the nearest pixel of the mask: 1 for a thing with nothing next to it."""
    import cv2
    from scipy.ndimage import distance_transform_edt

    ring = (cv2.dilate(mask.astype(np.uint8), np.ones((2 * ring_px + 1, 2 * ring_px + 1), np.uint8)) > 0) & ~mask
    if not ring.any():
        return 1.0
    _, (ri, ci) = distance_transform_edt(~mask, return_indices=True)
    near = depth_m[ri[ring], ci[ring]]
    d = depth_m[ring]
    apart = ~valid[ring] | (d > near + np.maximum(0.2, 0.05 * near))
    return float(apart.mean())


def solidity(mask: np.ndarray) -> float:
    """Area of ``mask`` over the area of its convex hull (1 for a convex blob)."""
    import cv2

    pts = cv2.findNonZero(mask.astype(np.uint8))
    if pts is None or len(pts) < 3:
        return 0.0
    hull = cv2.convexHull(pts)
    area = cv2.contourArea(hull)
    return float(mask.sum()) / max(area, 1.0)


def is_clear(mask: np.ndarray, points: np.ndarray, off_room: np.ndarray, up: np.ndarray | None, depth_m: np.ndarray, valid: np.ndarray, min_points: int, normals: Callable[[], np.ndarray]) -> bool:
    """A clear object: solid in the image, filling its box, plausible height and footprint,
    and either alone in the view or of 3D shape with a visible top. normals(): the (H, W, 3)
    normals of ``points`` (computed once by the caller, only when needed)."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if len(rows) == 0:
        return False
    fill = float(mask.sum()) / ((rows[-1] - rows[0] + 1) * (cols[-1] - cols[0] + 1))
    if fill < 0.35 or solidity(mask) < 0.5:
        return False
    p = points[mask & off_room]
    if len(p) < min_points:
        return False
    if up is not None:
        z = p @ up
        lo, hi = np.percentile(z, [2, 98])
        if not MIN_HEIGHT_M <= hi - lo <= 2.2:
            return False
        a = np.cross(up, [0.0, 0.0, 1.0]) if abs(up[2]) < 0.9 else np.cross(up, [1.0, 0.0, 0.0])
        a /= np.linalg.norm(a)
        xy = p @ np.stack([a, np.cross(up, a)]).T
        ext = np.percentile(xy, 98, axis=0) - np.percentile(xy, 2, axis=0)
        if float(ext.max()) > 2.5:
            return False
    # Alone in the view (nothing but unknown or far depth around it: a close-up's face) it
    # is clear whatever its shape.
    if mask.sum() >= ISOLATED_AREA * mask.size and separated_share(mask, depth_m, valid) >= ISOLATED_SHARE:
        return True
    # Else a thing has 3D shape: a flat patch (a picture, a door, a patch of wall that a
    # coarse depth estimate stood up as a billboard) is no object to build.
    sub = p[:: max(1, len(p) // 4000)]
    thickness = float(np.linalg.svd(sub - sub.mean(axis=0), compute_uv=False)[-1]) / np.sqrt(len(sub))
    if thickness < MIN_THICKNESS_M:
        return False
    # ... and a camera at standing height sees some of its top (a seat, a table top, a bed, a
    # cabinet top): a cluster of only vertical faces is a wall piece or a coarse estimate's
    # billboard.
    if up is not None:
        n = normals()[mask & off_room]
        if float(np.mean(np.abs(n @ up) > TOP_COS)) < MIN_TOP_SHARE:
            return False
    return True


def point_normals(points: np.ndarray) -> np.ndarray:
    """(H, W, 3) unit normals of the (H, W, 3) point image (cross product of its image
    gradients; zero where undefined)."""
    du = np.gradient(points, axis=1)
    dv = np.gradient(points, axis=0)
    n = np.cross(du, dv)
    norm = np.linalg.norm(n, axis=2, keepdims=True)
    n = np.where(norm > 1e-12, n / np.maximum(norm, 1e-12), 0.0)
    # Across a depth jump the gradients join two surfaces: no normal there.
    z = np.maximum(points[..., 2], 1e-6)
    jump = (np.abs(du[..., 2]) > 0.03 * z) | (np.abs(dv[..., 2]) > 0.03 * z)
    n[jump] = 0.0
    return n
