"""A bench or ottoman standing at the foot of a bed, cut out of the bed's mask as an object.

A detector's box around a bed takes in the bench at its foot (a bedroom's storage bench, a
showroom's ottoman), and the cut inside the box keeps it: on sunrgbd_imvotenet_000004 the bed
reached 2.8 m from its headboard over the bench, the bench was no object (the ground truth boxes
it as an ottoman) and the bed's shape was completed over both.

A bench is told apart from the bed by its own top, seen in the bed's points:

1. **the mattress**: the bed's top and its plan axis (:func:`perception.lying_on.mattress_frame`)
   (the principal axis of the top's points: a bed is longer than wide, and the bench stands
   beyond one of its ends);
2. **a lower plateau**: the highest dense band of heights :data:`MIN_DROP_M` or more under the
   mattress and :data:`MIN_SEAT_M` or more over the floor (a seat), holding :data:`MIN_POINTS`
   points or more;
3. **beyond the mattress's end**: that plateau lies past one end of the mattress along its axis
   (:data:`END_MARGIN_M`, :data:`INSIDE_SHARE`), reaching :data:`MIN_DEPTH_M` or more past it and
   :data:`MIN_WIDTH_M` or more across (a bed frame's rail or a platform's lip is a few
   centimetres);
4. **the cut**: every point more than :data:`END_MARGIN_M` past the mattress's end is the
   bench's (the footboard, at the mattress's end, stays with the bed).

The part becomes a ``bench`` with its own mask (the bed's mask pixels nearer to its points than
to the bed's) and points. Deterministic: no sampling.
"""

from __future__ import annotations

import numpy as np

from perception.lying_on import TOP_BAND_M, mattress_frame, without_points

__all__ = ["foot_bench", "split_foot_benches"]

#: The bench's top lies at least MIN_DROP_M under the mattress's and MIN_SEAT_M over the floor.
MIN_DROP_M = 0.12
MIN_SEAT_M = 0.3
#: ... is a dense band (TOP_BAND_M thick) of at least MIN_POINTS points ...
MIN_POINTS = 300
#: ... lying past the mattress's end (by more than END_MARGIN_M: the mattress's rounded edge and
#: its end's face fall in the plateau's band too), with less than INSIDE_SHARE of as many of its
#: points as far inside the mattress's end (a bed frame's side rails), reaching MIN_DEPTH_M past
#: it, MIN_WIDTH_M wide.
END_MARGIN_M = 0.08
INSIDE_SHARE = 0.2
MIN_DEPTH_M = 0.25
MIN_WIDTH_M = 0.5


def _plateau(z: np.ndarray, below_m: float) -> float | None:
    """Median height of the highest dense :data:`TOP_BAND_M` band of ``z`` between MIN_SEAT_M and
    ``below_m`` holding MIN_POINTS points, or None."""
    step = TOP_BAND_M / 3
    z = z[(z >= MIN_SEAT_M) & (z <= below_m)]
    if len(z) < MIN_POINTS:
        return None
    edges = np.arange(MIN_SEAT_M, below_m + step, step)
    if len(edges) < 4:
        return None
    counts = np.histogram(z, bins=edges)[0]
    band = counts[:-2] + counts[1:-1] + counts[2:]
    dense = np.flatnonzero(band >= MIN_POINTS)
    if not len(dense):
        return None
    lo, hi = edges[dense[-1]], edges[dense[-1] + 3]
    return float(np.median(z[(z >= lo) & (z <= hi)]))


def foot_bench(points_world_m: np.ndarray) -> np.ndarray | None:
    """The points of a bed's ((N, 3) world points, floor at z = 0) that are a bench at its foot
    ((N,) bool, see the module docstring), or None when there is none."""
    pts = np.asarray(points_world_m, dtype=np.float64)
    if len(pts) < 2 * MIN_POINTS:
        return None
    z = pts[:, 2]
    frame = mattress_frame(pts, MIN_POINTS)
    if frame is None or frame.top_m - MIN_DROP_M < MIN_SEAT_M:
        return None
    top, centre, axis, across_axis = frame.top_m, frame.centre_m, frame.axis, frame.across_axis
    seat = _plateau(z, top - MIN_DROP_M)
    if seat is None:
        return None
    on_seat = np.abs(z - seat) <= TOP_BAND_M / 2
    along = (pts[:, :2] - centre) @ axis
    m_lo, m_hi = np.percentile(along[frame.on_top], [2, 98])
    s_along = along[on_seat]
    for sign, end in ((1.0, m_hi), (-1.0, m_lo)):
        past = sign * (s_along - end) > END_MARGIN_M
        inside = sign * (s_along - end) < -END_MARGIN_M
        if past.sum() < MIN_POINTS or inside.sum() >= INSIDE_SHARE * past.sum():
            continue
        reach = float(np.percentile(sign * (s_along[past] - end), 98))
        across = (pts[on_seat][past, :2] - centre) @ across_axis
        width = float(np.subtract(*np.percentile(across, [98, 2])))
        if reach < MIN_DEPTH_M or width < MIN_WIDTH_M:
            continue
        cut = end + sign * END_MARGIN_M
        part = sign * (along - cut) > 0
        return part if MIN_POINTS <= part.sum() < len(pts) - MIN_POINTS else None
    return None


def split_foot_benches(
    kept: list[tuple[np.ndarray, np.ndarray]], points_world: list[np.ndarray], names: list[tuple[str, float]], confidence: float = 0.5
) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[np.ndarray], list[tuple[str, float]], int]:
    """Cut the bench at the foot of each bed out of it (:func:`foot_bench`): it becomes a
    ``bench`` (at ``confidence``) with its own (mask, pixels) and points, appended after the
    others; the bed keeps the rest. The bed's mask pixels without points go to whichever of the
    two holds the nearest pixel with a point. ``kept``: (mask, pixels with points) per object;
    ``points_world``: their points in raster order; ``names``: (label, confidence). Returns the
    three lists and the number of benches cut out."""
    from scipy import ndimage

    out_kept, out_points, out_names = list(kept), list(points_world), list(names)
    added = 0
    for i, ((mask, pix), pts, (label, _)) in enumerate(zip(kept, points_world, names)):
        if label != "bed":
            continue
        part = foot_bench(pts)
        if part is None:
            continue
        flat = np.flatnonzero(pix.ravel())
        bench_pix = np.zeros_like(pix)
        bench_pix.ravel()[flat[part]] = True
        (bed_mask, bed_pix), bed_points = without_points(mask, pix, pts, part)
        # The mask's pixels with no point (no depth there) go to the nearer part.
        _, (rr, cc) = ndimage.distance_transform_edt(~pix, return_indices=True)
        nearest_is_bench = bench_pix[rr, cc]
        bench_mask = bench_pix | (mask & ~pix & nearest_is_bench)
        bed_mask = bed_mask & ~bench_mask
        out_kept[i], out_points[i] = (bed_mask, bed_pix), bed_points
        out_kept.append((bench_mask, bench_pix))
        out_points.append(pts[part])
        out_names.append(("bench", confidence))
        added += 1
    return out_kept, out_points, out_names, added
