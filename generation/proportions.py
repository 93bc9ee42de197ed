"""Proportions of beds and tables measured from what the camera saw, for the shape priors.

A category constant put a bed's mattress at three quarters of its height and its headboard at
the far end of the box's depth axis: a bed 1.43 m high to its headboard got a mattress top at
1.07 m (the five SUN RGB-D beds measure 0.65-0.79 m), and a bed seen from its side got its
headboard along its long side. On the five SUN RGB-D bedrooms every bed's prior filled 40-45 %
seen free space with sensor depth; built from the photos alone (estimated depth), the beds of
three of them and of sunrgbd_total3d_demo_5 filled 24-29 % (``generation.visibility``): each
fell back to the extruded observed shell. With the proportions read as below those four keep
their prior (3-5 %); the sensor-depth ones fill 14-27 % and complete their shell with it
(``generation.completion.complete_occupancy``, ``prior_boxes_m``).

:func:`measure_proportions` reads them from the observed points instead, in the fitted box's
frame (origin at its bottom centre, +X its front): a height map of the top surface seen (the
highest point in each cell of a 2-D grid over the footprint); its median is the seat's or the
mattress's top (the largest surface seen from above); the back (headboard, backrest) is the side
whose strip of cells rises highest above that top. Written here, not taken from a library: it is
a few percentiles of a grid, nothing a point-cloud library offers as such.

A table's or desk's top is read the same way (not its box's top: what stands on it, depth noise
at a grazing view), its plan from the points at that height (:data:`TOP_PCT`), and its legs
stand at the inset whose legs fill the least seen free space (:func:`fit_leg_inset`). On the 11
tables and desks of the real, plain-SUN, Total3D-demo and COCO photos the prior's free-space
share fell from 47-99 % to 10-47 % on seven of them (BENCHMARKS.md, 2026-11-29 sixth session).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

__all__ = ["SIDES", "TABLE_LABELS", "Proportions", "fit_leg_inset", "measure_proportions", "seen_proportions", "turned_box"]

#: The sides of the box a back may stand on, by the outward axis of that side.
SIDES = ("-x", "+x", "-y", "+y")
#: Categories read as a top on legs (:func:`seen_proportions`, :func:`fit_leg_inset`).
TABLE_LABELS = ("table", "desk")
#: Grid cell (m) of the top height map: fine enough for a 6 cm headboard strip, coarse enough
#: that most cells hold a few points of a sensor's depth at 2-5 m.
CELL_M = 0.05
#: A side's strip is this share of the box across it (at least one cell, at most 0.3 m).
STRIP_SHARE = 0.15
#: A back rises at least this far (m) above the seat or mattress top; lower, there is none seen.
MIN_BACK_RISE_M = 0.1
#: A bed's plan this many times longer than wide shows which axis is its length (a queen bed's is
#: 1.33, a twin's about 2, a king's 1.05; a plan measured from estimated depth is off by 10-20 %):
#: its headboard is then at one end of it; a squarer plan leaves all four sides to the points.
LONG_PLAN_RATIO = 1.3
#: The seat or mattress top lies between these shares of the box's height.
TOP_SHARE = (0.2, 0.85)
#: A table's or desk's top lies between these shares of its box's height (what stands on it
#: raises the box).
TABLE_TOP_SHARE = (0.5, 1.0)
#: A table's top as seen: the TOP_PCT-th to (100 - TOP_PCT)-th percentiles of the plan of its
#: points within TOP_BAND_M of its top's height, inside the box and at least TOP_KEEP_SHARE of it
#: each way. A box fitted to every point takes in the flying pixels along a depth edge:
#: emsanet_sample's coffee table's box is 0.73 x 0.69 m, its top 0.54 x 0.58 m. (Widened as for
#: points spread evenly over the top, the percentiles gave 0.56 x 0.61 m and its prior filled
#: 18 % seen free space instead of 13 %, esanet_sample's 15 % instead of 10 %, and the procedural
#: rooms' F-Score-O fell from 76.0 to 72.9 %: the edge of a top seen at a grazing angle is mixed
#: pixels more than top.)
TOP_BAND_M = 0.05
TOP_PCT = 2.0
TOP_KEEP_SHARE = 0.6


@dataclass(frozen=True)
class Proportions:
    """What the observed points say of a seat's or bed's shape, in its box frame.

    top_m: height of the seat's or mattress's top; back_side: the side (:data:`SIDES`) whose
    strip rises highest, where the back or headboard stands, or None where no side rises
    :data:`MIN_BACK_RISE_M` above the top; back_top_m: that strip's height (90th percentile of
    its cells); leg_inset_m: how far a table's legs stand in from the edges of its top
    (:func:`fit_leg_inset`), None where not fitted; top_lo_m, top_hi_m: a table's top as seen,
    the plan rectangle (x, y corners in the box frame) of the points at its top's height, None
    for the whole box."""

    top_m: float
    back_side: str | None
    back_top_m: float | None
    leg_inset_m: float | None = None
    top_lo_m: tuple[float, float] | None = None
    top_hi_m: tuple[float, float] | None = None

    def top_plan(self, size_m) -> tuple[np.ndarray, np.ndarray]:
        """(lo (2,), hi (2,)): the plan rectangle of a table's top in the box frame, the one seen
        (``top_lo_m``, ``top_hi_m``) or the whole box of ``size_m``."""
        if self.top_lo_m is not None:
            return np.asarray(self.top_lo_m, dtype=np.float64), np.asarray(self.top_hi_m, dtype=np.float64)
        half = 0.5 * np.asarray(size_m, dtype=np.float64)[:2]
        return -half, half

    def describe(self, label: str) -> str:
        """What was read, for the asset's description ("... as seen")."""
        if label in TABLE_LABELS:
            legs = "" if self.leg_inset_m is None else f" and legs {self.leg_inset_m * 100:.0f} cm in from its edges"
            plan = "" if self.top_lo_m is None else f", {self.top_hi_m[0] - self.top_lo_m[0]:.2f} x {self.top_hi_m[1] - self.top_lo_m[1]:.2f} m"
            return f"top at {self.top_m:.2f} m{plan}{legs}"
        head = f" and headboard on its {self.back_side} side, seen up to {self.back_top_m:.2f} m" if self.back_side else ", no headboard"
        return f"mattress top at {self.top_m:.2f} m{head}"


def measure_proportions(points_box_m: np.ndarray, size_m, sides: tuple[str, ...] = SIDES, top_share: tuple[float, float] = TOP_SHARE) -> Proportions | None:
    """The :class:`Proportions` of the (N, 3) observed points in the box frame of ``size_m``
    (D, W, H); ``sides``: where a back may stand (a bed's headboard: its short sides). None
    when fewer than 8 cells of the footprint hold points (too little seen to say)."""
    d, w, h = (float(v) for v in size_m)
    p = np.asarray(points_box_m, dtype=np.float64)
    inside = (np.abs(p[:, 0]) <= d / 2) & (np.abs(p[:, 1]) <= w / 2) & (p[:, 2] >= 0.0) & (p[:, 2] <= h)
    p = p[inside]
    nx, ny = max(1, int(np.ceil(d / CELL_M))), max(1, int(np.ceil(w / CELL_M)))
    ix = np.clip(((p[:, 0] + d / 2) / d * nx).astype(np.int64), 0, nx - 1)
    iy = np.clip(((p[:, 1] + w / 2) / w * ny).astype(np.int64), 0, ny - 1)
    top = np.full((nx, ny), -np.inf)
    np.maximum.at(top, (ix, iy), p[:, 2])
    seen = np.isfinite(top)
    if np.count_nonzero(seen) < 8:
        return None
    seat = float(np.clip(np.median(top[seen]), top_share[0] * h, top_share[1] * h))
    sx = max(1, min(int(round(STRIP_SHARE * nx)), int(np.ceil(0.3 / CELL_M))))
    sy = max(1, min(int(round(STRIP_SHARE * ny)), int(np.ceil(0.3 / CELL_M))))
    strips = {"-x": top[:sx, :], "+x": top[-sx:, :], "-y": top[:, :sy], "+y": top[:, -sy:]}
    best, best_top = None, -np.inf
    for side in sides:
        cells = strips[side][np.isfinite(strips[side])]
        if len(cells) < 2:
            continue
        rise = float(np.percentile(cells, 90))
        if rise > best_top:
            best, best_top = side, rise
    if best is None or best_top < seat + MIN_BACK_RISE_M:
        return Proportions(seat, None, None)
    return Proportions(seat, best, best_top)


def turned_box(side: str, lo_m, hi_m) -> tuple[np.ndarray, np.ndarray]:
    """Corners (lo, hi) of the axis-aligned box given in a frame whose back is on ``-x``, turned
    about the vertical so that the back is on ``side`` (:data:`SIDES`). A box built for a back
    on ``-y`` or ``+y`` takes the box's W as its depth and D as its width."""
    lo, hi = np.asarray(lo_m, dtype=np.float64), np.asarray(hi_m, dtype=np.float64)
    turn = {"-x": ((1, 0), (0, 1)), "+x": ((-1, 0), (0, -1)), "-y": ((0, -1), (1, 0)), "+y": ((0, 1), (-1, 0))}[side]
    r = np.array(turn, dtype=np.float64)
    a, b = r @ lo[:2], r @ hi[:2]
    return np.r_[np.minimum(a, b), lo[2]], np.r_[np.maximum(a, b), hi[2]]


def seen_proportions(label: str, points_box_m: np.ndarray, size_m) -> Proportions | None:
    """:func:`measure_proportions` of a bed, its headboard on one of its short sides (any side
    where its plan is not :data:`LONG_PLAN_RATIO` times longer than wide); None for other
    labels. (Sofas and chairs keep their constants: read this way, a sofa's back on a long side
    and a chair's on any side, on the real, plain-SUN, Total3D-demo and COCO photos 6 of 7 sofas
    and 20 of 22 chairs whose prior changed filled more seen free space than with the
    constants, and none came under 10 %.)"""
    if label in TABLE_LABELS:
        m = measure_proportions(points_box_m, size_m, (), TABLE_TOP_SHARE)
        if m is None:
            return None
        p = np.asarray(points_box_m, dtype=np.float64)
        half = 0.5 * np.asarray(size_m, dtype=np.float64)[:2]
        near = (np.abs(p[:, 2] - m.top_m) <= TOP_BAND_M) & np.all(np.abs(p[:, :2]) <= half, axis=1)
        if np.count_nonzero(near) < 30:
            return m
        lo = np.maximum(np.percentile(p[near, :2], TOP_PCT, axis=0), -half)
        hi = np.minimum(np.percentile(p[near, :2], 100.0 - TOP_PCT, axis=0), half)
        grow = np.maximum(0.0, TOP_KEEP_SHARE * 2 * half - (hi - lo)) / 2  # (not below TOP_KEEP_SHARE of the box)
        lo, hi = np.maximum(lo - grow, -half), np.minimum(hi + grow, half)
        return replace(m, top_lo_m=(float(lo[0]), float(lo[1])), top_hi_m=(float(hi[0]), float(hi[1])))
    if label != "bed":
        return None
    d, w = float(size_m[0]), float(size_m[1])
    sides = SIDES
    if max(d, w) > LONG_PLAN_RATIO * min(d, w):
        sides = ("-y", "+y") if d < w else ("-x", "+x")  # the ends of its long axis
    return measure_proportions(points_box_m, size_m, sides)


#: Candidate insets of a table's legs from the edges of its top, as shares of its shorter side
#: (a top overhangs its legs by 0-20 % of its depth: a dining table's apron, a coffee table's rim).
LEG_INSET_SHARES = (0.0, 0.04, 0.08, 0.12, 0.16, 0.2)
#: Surface samples per candidate.
LEG_SAMPLES = 600


def fit_leg_inset(proportions: Proportions, space, world_from_box: np.ndarray, size_m, legs, seed: int = 0) -> Proportions:
    """``proportions`` with the leg inset (:data:`LEG_INSET_SHARES`) whose legs fill the least
    seen free space: the legs the camera saw stand where it saw them (a thin leg a few
    centimetres off shows the floor behind it), the first (outermost) on ties. ``space`` is the
    object's ``generation.visibility.FreeSpace``, ``world_from_box`` and ``size_m`` its box,
    ``legs(lo_xy, hi_xy, top_m, inset_m)`` the leg meshes in the box frame under the top's plan
    (``generation.priors.table_legs``). Fitted by search, not by clustering leg points: a leg is
    a few dozen points or none, and the free space seen around it says as much."""
    from scene_builder.frames import transform_points

    from generation.visibility import surface_samples

    lo, hi = proportions.top_plan(size_m)
    best, best_share = None, np.inf
    for share in LEG_INSET_SHARES:
        inset = share * float(np.min(hi - lo))
        pts = transform_points(world_from_box, surface_samples(legs(lo, hi, proportions.top_m, inset), LEG_SAMPLES, seed))
        v = space.violation(pts)
        if v < best_share - 1e-9:
            best, best_share = inset, v
    return replace(proportions, leg_inset_m=best)
