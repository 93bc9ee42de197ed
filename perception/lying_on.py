"""Pillows lying on a bed or sofa, cut out of its mask as objects of their own.

A detector boxes a bed, and the cut inside its box takes everything on the mattress with it: on
the SUN RGB-D bedrooms of ``../shared/data/real`` every pillow became part of its bed (the bed's
completion then stood up to the pillows' tops, and no pillow was an object). COCO and the Open
Images SSD have no pillow class to box them apart.

What lies on a mattress is found from the bed's own points:

1. **the top**: :func:`top_height`, the highest dense band of heights (the mattress, a seat);
2. **what rises a little above it**: points :data:`MIN_ABOVE_M` to :data:`MAX_ABOVE_M` above the
   top (a pillow is 10-25 cm high; the headboard goes on far higher), connected in the image;
3. **lying on it**: most of a blob's points stand over the top's plan outline, shrunk by
   :data:`INSET_M` (the headboard and the footboard stand at its edges, not over it), and the
   blob is pillow-sized in plan;
4. **one per pillow**: a blob wider than :data:`SPLIT_WIDTH_M` (pillows side by side touch in the
   image) is split where its height profile dips between two pillows, near equal widths of
   :data:`PILLOW_WIDTH_M` (a bolster, with no dip, stays whole).

Each part becomes a ``pillow`` and leaves the bed's mask and points. Deterministic: no sampling.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["top_height", "mattress_frame", "MattressFrame", "split_lying", "lying_parts", "without_points", "HOSTS"]

#: A top is the highest TOP_BAND_M band of heights holding at least TOP_SHARE of the object's
#: points, at least MIN_TOP_M above the floor.
TOP_BAND_M = 0.06
TOP_SHARE = 0.15
MIN_TOP_M = 0.25
#: Labels whose top may carry pillows.
HOSTS = frozenset({"bed", "sofa"})
#: A pillow's points rise this far above the top: more than MIN_ABOVE_M (the mattress's own
#: relief and noise), less than MAX_ABOVE_M (the headboard goes on above).
MIN_ABOVE_M = 0.04
MAX_ABOVE_M = 0.35
#: Share of a blob's points that must stand over the top's outline shrunk by INSET_M (pillows lean
#: against the headboard, over the top's back edge: 0.48 and 0.60 on sunrgbd_000002 and 000004; the
#: headboard's own lower strip 0.0).
ON_TOP_SHARE = 0.4
INSET_M = 0.05
#: A pillow-sized blob: at least MIN_POINTS points and MIN_WIDTH_M wide, at most MAX_DEPTH_M deep
#: (across its longer plan axis) and MAX_WIDTH_M wide.
MIN_POINTS = 150
MIN_WIDTH_M = 0.25
MAX_DEPTH_M = 0.8
MAX_WIDTH_M = 2.4
#: Pillows side by side: a blob wider than SPLIT_WIDTH_M is round(width / PILLOW_WIDTH_M) pillows,
#: split at the lowest point of its height profile within SPLIT_SEARCH_M of each equal split.
SPLIT_WIDTH_M = 0.95
PILLOW_WIDTH_M = 0.65
SPLIT_SEARCH_M = 0.15
#: ... where the profile (90th height percentile per PROFILE_BIN_M) dips VALLEY_M below the highest
#: point on either side within a pillow's width: no dip, no split (one long bolster).
VALLEY_M = 0.03
PROFILE_BIN_M = 0.02


def top_height(z: np.ndarray) -> float | None:
    """Median height of the highest :data:`TOP_BAND_M` band of heights that holds
    :data:`TOP_SHARE` of ``z`` and starts :data:`MIN_TOP_M` or more up; None when there is none
    (a table seen edge-on)."""
    z = np.asarray(z, dtype=np.float64)
    step = TOP_BAND_M / 3
    edges = np.arange(max(float(z.min()), MIN_TOP_M - step), float(z.max()) + step, step)
    if len(edges) < 4:
        return None
    counts = np.histogram(z, bins=edges)[0]
    band = counts[:-2] + counts[1:-1] + counts[2:]
    dense = np.flatnonzero(band >= TOP_SHARE * len(z))
    if not len(dense):
        return None
    lo, hi = edges[dense[-1]], edges[dense[-1] + 3]
    return float(np.median(z[(z >= lo) & (z <= hi)]))


class MattressFrame(NamedTuple):
    """A bed's top and its plan axes (world frame, floor at z = 0)."""

    top_m: float
    #: (N,) bool: the points within TOP_BAND_M / 2 of the top.
    on_top: np.ndarray
    #: (2,) plan centre of the top's points, the unit axis along them (longest spread) and across.
    centre_m: np.ndarray
    axis: np.ndarray
    across_axis: np.ndarray


def mattress_frame(points_world_m: np.ndarray, min_points: int) -> MattressFrame | None:
    """The top (:func:`top_height`) of a bed's (N, 3) points and the plan axes of the points on it
    (principal axes), or None when there is no top or fewer than ``min_points`` points on it."""
    pts = np.asarray(points_world_m, dtype=np.float64)
    top = top_height(pts[:, 2])
    if top is None:
        return None
    on_top = np.abs(pts[:, 2] - top) <= TOP_BAND_M / 2
    if on_top.sum() < min_points:
        return None
    mattress = pts[on_top, :2]
    centre = mattress.mean(axis=0)
    _, _, vt = np.linalg.svd(mattress - centre, full_matrices=False)
    return MattressFrame(top, on_top, centre, vt[0], vt[1])


def lying_parts(pix: np.ndarray, points_world_m: np.ndarray) -> list[np.ndarray]:
    """The pillows lying on one bed: (N,) bool selections of ``points_world_m`` (the points of the
    True pixels of the (H, W) ``pix``, in raster order), one per pillow; [] when there is none."""
    import shapely
    from scipy import ndimage

    pts = np.asarray(points_world_m, dtype=np.float64)
    if len(pts) < MIN_POINTS:
        return []
    z = pts[:, 2]
    top = top_height(z)
    if top is None:
        return []
    on_top = np.abs(z - top) <= TOP_BAND_M / 2
    if np.count_nonzero(on_top) < 3:
        return []
    outline = shapely.MultiPoint(pts[on_top, :2]).convex_hull.buffer(-INSET_M)
    if outline.is_empty:
        return []
    rising = (z > top + MIN_ABOVE_M) & (z < top + MAX_ABOVE_M)
    image = np.zeros(pix.shape, dtype=bool)
    flat = np.flatnonzero(pix.ravel())
    image.ravel()[flat[rising]] = True
    image = ndimage.binary_opening(image)  # a one-pixel seam is no link
    labels, n = ndimage.label(image, structure=np.ones((3, 3), dtype=bool))
    point_label = labels.ravel()[flat]
    parts = []
    for k in range(1, n + 1):
        sel = point_label == k
        if np.count_nonzero(sel) < MIN_POINTS:
            continue
        p = pts[sel]
        if np.mean(shapely.contains_xy(outline, p[:, 0], p[:, 1])) < ON_TOP_SHARE:
            continue  # the headboard, the footboard, an arm: at the edge of the top, not on it
        for part in _one_per_pillow(p):
            whole = np.zeros(len(pts), dtype=bool)
            whole[np.flatnonzero(sel)[part]] = True
            parts.append(whole)
    return parts


def _one_per_pillow(p: np.ndarray) -> list[np.ndarray]:
    """Selections of the points ``p`` of one blob, one per pillow ([] when it is not
    pillow-sized): split along its longer plan axis at the valleys of its height profile."""
    xy = p[:, :2] - p[:, :2].mean(axis=0)
    _, _, vt = np.linalg.svd(xy, full_matrices=False)
    along, across = xy @ vt[0], xy @ vt[1]
    lo, hi = np.percentile(along, [2, 98])
    width = float(hi - lo)
    depth = float(np.ptp(np.percentile(across, [2, 98])))
    if width < MIN_WIDTH_M or width > MAX_WIDTH_M or depth > MAX_DEPTH_M:
        return []
    count = int(round(width / PILLOW_WIDTH_M)) if width > SPLIT_WIDTH_M else 1
    cuts = []
    if count > 1:
        bins = np.arange(lo, hi + PROFILE_BIN_M, PROFILE_BIN_M)
        which = np.clip(np.digitize(along, bins) - 1, 0, len(bins) - 2)
        height = np.full(len(bins) - 1, np.inf)
        for b in np.unique(which):
            height[b] = np.percentile(p[which == b, 2], 90)
        centres = 0.5 * (bins[:-1] + bins[1:])
        for j in range(1, count):
            nominal = lo + j * width / count
            near = np.flatnonzero((np.abs(centres - nominal) <= SPLIT_SEARCH_M) & np.isfinite(height))
            if not len(near):
                continue
            k = near[np.argmin(height[near])]
            left = height[max(0, k - int(PILLOW_WIDTH_M / PROFILE_BIN_M)):k]
            right = height[k + 1:k + 1 + int(PILLOW_WIDTH_M / PROFILE_BIN_M)]
            left, right = left[np.isfinite(left)], right[np.isfinite(right)]
            if len(left) and len(right) and height[k] <= min(left.max(), right.max()) - VALLEY_M:
                cuts.append(float(centres[k]))  # a dip between two pillows (a bolster has none)
    edges = [-np.inf, *cuts, np.inf]
    segments = [(along >= a) & (along < b) for a, b in zip(edges[:-1], edges[1:])]
    return [s for s in segments if np.count_nonzero(s) >= MIN_POINTS]


def without_points(mask: np.ndarray, pix: np.ndarray, points: np.ndarray, drop: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """An object's (mask, pixels with points) and points (raster order) without the points
    ``drop`` (N,) bool selects and their pixels (new arrays; the inputs are left as they are)."""
    idx = np.flatnonzero(pix.ravel())[drop]
    mask, pix = mask.copy(), pix.copy()
    mask.ravel()[idx] = False
    pix.ravel()[idx] = False
    return (mask, pix), points[~drop]


def split_lying(
    kept: list[tuple[np.ndarray, np.ndarray]], points_world: list[np.ndarray], names: list[tuple[str, float]], confidence: float = 0.5
) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[np.ndarray], list[tuple[str, float]], int]:
    """Cut the pillows lying on each bed or sofa out of it (:func:`lying_parts`): each becomes a
    ``pillow`` (at ``confidence``) with its own (mask, pixels) and points, appended after the
    others; its pixels leave the host. ``kept``: (mask, pixels with points) per object;
    ``points_world``: their points in raster order; ``names``: (label, confidence). Returns the
    three lists and the number of pillows cut out."""
    out_kept, out_points, out_names = list(kept), list(points_world), list(names)
    added = 0
    for i, ((mask, pix), pts, (label, _)) in enumerate(zip(kept, points_world, names)):
        if label not in HOSTS:
            continue
        parts = lying_parts(pix, pts)
        if not parts:
            continue
        flat = np.flatnonzero(pix.ravel())
        taken = np.zeros(len(pts), dtype=bool)
        for sel in parts:
            part_pix = np.zeros_like(pix)
            part_pix.ravel()[flat[sel]] = True
            out_kept.append((part_pix.copy(), part_pix))
            out_points.append(pts[sel])
            out_names.append(("pillow", confidence))
            taken |= sel
            added += 1
        out_kept[i], out_points[i] = without_points(mask, pix, pts, taken)
    return out_kept, out_points, out_names, added
