"""A bed's headboard, fixed to the wall behind it, grown into the bed's mask.

A detector's box and the cut inside it end a bed at its mattress where its headboard is a thin
panel against the wall: the headboard's points lie a few centimetres off the wall plane, so the
room's planes take them as wall and the bed is built without it (sunrgbd_imvotenet_000005: a
leather headboard 0.5 m high over the mattress, 1-10 cm off the wall, median 3.3 cm; the ground
truth boxes that bed 1.59 m high, the twin's bed was 0.85 m). From any viewpoint but the photo's
it then stays painted on the wall behind a bed that ends at its mattress.

The headboard is told apart from the wall by where it is and by standing off it:

1. **the mattress**: the bed's top (:func:`perception.lying_on.mattress_frame`) and its plan axes
   (principal axes of the top's points);
2. **at one end**: pixels no object holds whose points lie past one end of the bed's points
   along the mattress's axis by at most :data:`HEAD_DEPTH_M` (or up to :data:`INSIDE_M` inside
   it), across no wider than the mattress (:data:`SIDE_MARGIN_M`), from the mattress's top up
   to :data:`MAX_RISE_M` over it;
3. **off the walls**: their distance to every wall plane, median-filtered over
   :data:`SMOOTH_PX` pixels (a sensor's noise on a wall is a centimetre or two either way), at
   least :data:`OFF_WALL_M`;
4. **a panel with a top**: the pixels joined to the bed's mask (:data:`TOUCH_PX`), at least
   :data:`MIN_POINTS` of them, rising :data:`MIN_RISE_M` or more over the mattress, at least
   :data:`MIN_WIDTH_SHARE` of the bed's width across, and ending under the search's ceiling by
   :data:`TOP_CLEARANCE_M` (what runs on up to it is a wall the room's planes missed, a
   curtain, a wardrobe behind: no headboard); the convex hull of its measured pieces of
   :data:`MIN_PIECE_PX` pixels or more, with the unmeasured pixels in it, joins them (a dark
   headboard is measured at its edges and studs only);
5. **its unmeasured pixels**: those no object holds whose rays meet its panel (the vertical
   plane of its measured points, as wide as the bed, up to their heights' 99th percentile),
   joined to its measured ones, lie on that panel (:func:`grow_headboards`).

Of the two ends, the one with more such pixels is the head. Deterministic: no sampling.
"""

from __future__ import annotations

import numpy as np

from perception.lying_on import TOP_BAND_M, mattress_frame
from scene_builder.model import Plane

__all__ = ["grow_headboards", "headboard_pixels"]

#: The headboard lies past the end of the bed's points (2nd percentile) by at most HEAD_DEPTH_M,
#: or up to INSIDE_M inside it: pillows, cut out as objects, hide the head of the mattress and
#: the base under them (sunrgbd_imvotenet_000005: the headboard stands 0.35-0.42 m past the
#: end of the bed's points, which reach it with 0.5 % of them).
HEAD_DEPTH_M = 0.5
INSIDE_M = 0.1
#: ... across the bed's width (mattress, 2nd to 98th percentile) and SIDE_MARGIN_M either side ...
SIDE_MARGIN_M = 0.05
#: ... from the mattress's top (less TOP_BAND_M) up to MAX_RISE_M over it.
MAX_RISE_M = 1.0
#: Off every wall by at least OFF_WALL_M, median-filtered over SMOOTH_PX x SMOOTH_PX pixels.
OFF_WALL_M = 0.015
SMOOTH_PX = 7
#: Joined to the bed's mask within TOUCH_PX pixels, through the convex hull of its measured
#: pieces of MIN_PIECE_PX pixels or more (no speck of noise).
TOUCH_PX = 3
MIN_PIECE_PX = 20
#: At least MIN_POINTS points, rising MIN_RISE_M over the mattress (98th percentile), at least
#: MIN_WIDTH_SHARE of the mattress's width across, with its top (98th percentile) TOP_CLEARANCE_M
#: or more under the search's ceiling.
MIN_POINTS = 300
MIN_RISE_M = 0.15
MIN_WIDTH_SHARE = 0.5
TOP_CLEARANCE_M = 0.15


def headboard_pixels(bed_mask: np.ndarray, bed_points_world_m: np.ndarray, points_world_m: np.ndarray, measured: np.ndarray,
                     claimed: np.ndarray, walls: tuple[Plane, ...]) -> tuple[np.ndarray, np.ndarray] | None:
    """The pixels of a bed's headboard that its mask ``bed_mask`` (H, W) left out (see the module
    docstring): ((H, W) bool mask, (H, W) bool those of them with a measured point), or None.
    ``bed_points_world_m``: (N, 3) the bed's points, floor at z = 0; ``points_world_m``: (H, W, 3)
    every pixel's world point; ``measured``: (H, W) bool, pixels with a measured point;
    ``claimed``: (H, W) bool, pixels an object holds; ``walls``: the room's wall planes."""
    from scipy import ndimage
    from skimage import morphology

    pts = np.asarray(bed_points_world_m, dtype=np.float64)
    if len(pts) < MIN_POINTS:
        return None
    frame = mattress_frame(pts, MIN_POINTS)
    if frame is None:
        return None
    top, centre, axis, across_axis = frame.top_m, frame.centre_m, frame.axis, frame.across_axis
    mattress = pts[frame.on_top, :2]
    m_lo, m_hi = np.percentile((pts[:, :2] - centre) @ axis, [2, 98])
    a_lo, a_hi = np.percentile((mattress - centre) @ across_axis, [2, 98])

    free = measured & ~claimed
    p = np.asarray(points_world_m, dtype=np.float64)
    along = (p[..., :2] - centre) @ axis
    across = (p[..., :2] - centre) @ across_axis
    z = p[..., 2]
    ceiling = top + MAX_RISE_M
    near = free & (z >= top - TOP_BAND_M) & (z <= ceiling) & (across >= a_lo - SIDE_MARGIN_M) & (across <= a_hi + SIDE_MARGIN_M)
    if walls and near.any():
        # The filter reads free pixels only: every other pixel takes the distance of the nearest
        # free one (an object's pixels, or unmeasured ones at the origin, would pull a
        # headboard's edge toward the wall or away from it).
        dist = np.min(np.stack([p @ w.normal + w.offset_m for w in walls]), axis=0)
        _, (rr, cc) = ndimage.distance_transform_edt(~free, return_indices=True)
        # Filtered over the box of the near pixels and the window's reach around it: the same
        # values there as over the whole image (at the image's edges both replicate the edge).
        rows, cols = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
        reach = SMOOTH_PX // 2
        r0, r1 = max(0, rows[0] - reach), min(near.shape[0], rows[-1] + 1 + reach)
        c0, c1 = max(0, cols[0] - reach), min(near.shape[1], cols[-1] + 1 + reach)
        smooth = ndimage.median_filter(dist[rr[r0:r1, c0:c1], cc[r0:r1, c0:c1]], size=SMOOTH_PX, mode="nearest")
        near[r0:r1, c0:c1] &= smooth >= OFF_WALL_M
    touch = ndimage.binary_dilation(bed_mask, iterations=TOUCH_PX)
    best, best_n = None, 0
    for sign, end in ((1.0, m_hi), (-1.0, m_lo)):
        past = sign * (along - end)
        cand = near & (past >= -INSIDE_M) & (past <= HEAD_DEPTH_M)
        if not cand.any():
            continue
        # A dark headboard is measured at its edges and studs only (000005's leather): the
        # convex hull of its measured pieces (of MIN_PIECE_PX pixels or more: no speck of
        # noise) holds the unmeasured pixels inside it; no measured pixel that is not a
        # candidate (the wall), none an object holds.
        pieces = morphology.remove_small_objects(cand, max_size=MIN_PIECE_PX - 1)
        if not pieces.any():
            continue
        region = morphology.convex_hull_image(pieces) & ~claimed & (cand | ~measured)
        lab, n = ndimage.label(region, structure=np.ones((3, 3), dtype=bool))
        joined = np.unique(lab[touch & region])
        region = np.isin(lab, joined[joined > 0])
        seen = region & cand
        count = int(seen.sum())
        if count < MIN_POINTS or count <= best_n:
            continue
        rz = z[seen]
        rise = float(np.percentile(rz, 98)) - top
        width = float(np.subtract(*np.percentile(across[seen], [98, 2])))
        if rise < MIN_RISE_M or width < MIN_WIDTH_SHARE * (a_hi - a_lo) or float(np.percentile(rz, 98)) > ceiling - TOP_CLEARANCE_M:
            continue
        best, best_n = (region, seen), count
    return best


def _panel(seen_m: np.ndarray, bed_points_m: np.ndarray) -> tuple[np.ndarray, float, np.ndarray, tuple[float, float], tuple[float, float]]:
    """The headboard's panel: the vertical plane through its measured points ``seen_m`` (N, 3)
    (their plan's principal line), as (normal (3,), offset: normal . x = offset, direction (3,)
    along it, (lo, hi) along it: the bed's width there (``bed_points_m`` and ``seen_m``: a
    headboard may overhang the mattress; SIDE_MARGIN_M either side), (lo, hi) heights: from 5 cm
    under the measured points' lowest to their 99th percentile (not the window over
    sunrgbd_imvotenet_000003's headboard, whose glass the sensor does not measure))."""
    xy = seen_m[:, :2]
    centre = xy.mean(axis=0)
    _, _, vt = np.linalg.svd(xy - centre, full_matrices=False)
    normal = np.array([vt[1, 0], vt[1, 1], 0.0])
    direction = np.array([vt[0, 0], vt[0, 1], 0.0])
    a = np.concatenate([bed_points_m[:, :2] @ vt[0], xy @ vt[0]])
    lo, hi = float(a.min()), float(a.max())
    return (normal, float(np.median(xy @ vt[1])), direction, (float(lo) - SIDE_MARGIN_M, float(hi) + SIDE_MARGIN_M),
            (float(seen_m[:, 2].min()) - 0.05, float(np.percentile(seen_m[:, 2], 99))))


def _on_panel(panel, rays_m: np.ndarray, camera_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the rays ``rays_m`` (M, 3) from ``camera_m`` meet ``panel`` (:func:`_panel`): ((M, 3)
    points, (M,) bool where a ray meets it in front of the camera within its width and heights)."""
    normal, offset, direction, (a_lo, a_hi), (z_lo, z_hi) = panel
    denom = rays_m @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (offset - float(camera_m @ normal)) / denom
    pts = camera_m + t[:, None] * rays_m
    a = pts @ direction
    ok = np.isfinite(t) & (t > 0) & (pts[:, 2] >= z_lo) & (pts[:, 2] <= z_hi) & (a >= a_lo) & (a <= a_hi)
    return pts, ok


def grow_headboards(kept: list[tuple[np.ndarray, np.ndarray]], points_world: list[np.ndarray], names: list[tuple[str, float]],
                    points_world_img: np.ndarray, valid: np.ndarray, walls: tuple[Plane, ...], rays_world_img: np.ndarray,
                    camera_m: np.ndarray) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[np.ndarray], int]:
    """Each bed of ``kept`` ((mask, pixels with points) per object; ``points_world`` their points in
    raster order; ``names`` (label, confidence)) with its headboard's pixels
    (:func:`headboard_pixels`) added to its mask and points: the measured ones as they are, and
    the unmeasured ones no object holds whose rays meet the headboard's panel (the vertical
    plane of the measured ones, as wide as the bed: :func:`_panel`) joined to them, on that
    panel (a dark headboard's middle and the parts of it measured nowhere). ``points_world_img``: (H, W, 3)
    world point of every pixel; ``valid``: (H, W) bool, measured; ``rays_world_img``: (H, W, 3)
    each pixel's ray direction in the world from the camera's centre ``camera_m`` (3,). Returns
    the two lists and the number of beds grown."""
    from scipy import ndimage

    taken = np.zeros(valid.shape, dtype=bool)
    for mask, _ in kept:
        taken |= mask
    out_kept, out_points = list(kept), list(points_world)
    grown = 0
    for i, ((mask, pix), pts, (label, _)) in enumerate(zip(kept, points_world, names)):
        if label != "bed":
            continue
        head = headboard_pixels(mask, pts, points_world_img, valid, taken, walls)
        if head is None:
            continue
        region, seen = head
        # Its unmeasured pixels: those whose rays meet its panel within the bed's width, joined to
        # what was found (the hull of the measured pieces stops at the last one measured: the
        # left fifth of 000005's headboard, measured nowhere, was left on the wall).
        hidden = ~valid & ~taken
        on, ok = _on_panel(_panel(points_world_img[seen], pts), rays_world_img[hidden], np.asarray(camera_m, dtype=np.float64))
        img = points_world_img.copy()
        img[hidden] = on
        hidden.flat[np.flatnonzero(hidden.ravel())[~ok]] = False
        lab, _ = ndimage.label(seen | hidden, structure=np.ones((3, 3), dtype=bool))
        joined = np.unique(lab[seen])
        added = np.isin(lab, joined[joined > 0])
        mask, pix = mask | added, pix | added
        taken |= added
        out_kept[i], out_points[i] = (mask, pix), img[pix]
        grown += 1
    return out_kept, out_points, grown
