"""The room's planes: the floor, the ceiling and the walls (re-exported by :mod:`scene_builder.model`).

A wall is the plane of the wall's inliers. ``span_m`` is how far along it (horizontally, along
:attr:`Plane.tangent`) it stands: an end is known where the camera saw past the plane beside the
wall (an opening, an L-shaped room, the partition's end where the next room starts); where
nothing was seen through it, the wall goes on (None). What stands past a known end, behind the
wall's plane, is still in the room, and the wall does not push it or cut it
(:meth:`Plane.clearance_m`). Exporters build a bounded wall as a slab over its span.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scene_builder.arrays import _freeze

__all__ = ["WALL_END_MARGIN_M", "WALL_OPEN_LENGTH_M", "WALL_SLAB_HEIGHT_M", "WALL_SLAB_THICKNESS_M", "Plane"]

#: A point lies past a bounded wall's end when its position along the wall is this far beyond
#: the span seen (depth noise at the wall's end, a corner's rounding).
WALL_END_MARGIN_M = 0.1
#: A bounded wall's collision slab (:meth:`Plane.slab`): this thick behind its face and this
#: tall from the floor (above any room's ceiling; nothing rests on a wall's top).
WALL_SLAB_THICKNESS_M = 0.2
WALL_SLAB_HEIGHT_M = 4.0
#: A slab runs this far from its known end towards an open one (past any room a photo shows).
WALL_OPEN_LENGTH_M = 30.0


@dataclass(frozen=True, eq=False)
class Plane:
    """A plane ``normal . x + offset_m = 0`` in the world frame.

    normal: (3,) float64 unit vector; for floors it is +Z, for walls it is horizontal and points
      into the room (towards the camera).
    kind: ``"floor"``, ``"wall"`` or ``"ceiling"``.
    inlier_count: number of observed depth points that support the plane.
    span_m: (lo, hi) metres along :attr:`tangent` between the wall's known ends, either None
      where it goes on (nothing seen past it there); None: an infinite plane (the floor, the
      ceiling, a wall with no end seen).
    """

    normal: np.ndarray
    offset_m: float
    kind: str
    inlier_count: int = 0
    span_m: tuple[float | None, float | None] | None = None

    def __post_init__(self) -> None:
        _freeze(self, "normal", np.float64, (3,))
        n = float(np.linalg.norm(self.normal))
        if not np.isclose(n, 1.0, atol=1e-6):
            raise ValueError(f"Plane.normal must be a unit vector, got norm {n}")
        if self.span_m is None or self.span_m == (None, None):
            object.__setattr__(self, "span_m", None)
            return
        lo, hi = (None if v is None else float(v) for v in self.span_m)
        if any(v is not None and not math.isfinite(v) for v in (lo, hi)) or (lo is not None and hi is not None and not lo < hi):
            raise ValueError(f"Plane.span_m must be (lo, hi) of finite values or None with lo < hi, got {self.span_m}")
        if abs(float(self.normal[2])) > 1e-6:
            raise ValueError("Plane.span_m bounds walls only: a bounded plane's normal must be horizontal")
        object.__setattr__(self, "span_m", (lo, hi))

    @property
    def bounded(self) -> bool:
        """True when a wall end is known (the camera saw past the plane beside the wall)."""
        return self.span_m is not None

    def _ends(self) -> tuple[float, float]:
        if self.span_m is None:
            return -math.inf, math.inf
        lo, hi = self.span_m
        return (-math.inf if lo is None else lo), (math.inf if hi is None else hi)

    @property
    def tangent(self) -> np.ndarray:
        """(3,) horizontal unit vector along the plane, up x normal (world X for a horizontal
        plane): the axis of ``span_m``."""
        t = np.cross([0.0, 0.0, 1.0], self.normal)
        norm = float(np.linalg.norm(t))
        return t / norm if norm > 1e-9 else np.array([1.0, 0.0, 0.0])

    def signed_distance_m(self, points_m: np.ndarray) -> np.ndarray:
        """(N,) signed distance of (N, 3) points to the infinite plane; positive on the side the
        normal points to."""
        return np.asarray(points_m, dtype=np.float64) @ self.normal + self.offset_m

    def clearance_m(self, points_m: np.ndarray) -> np.ndarray:
        """(N,) how far (N, 3) points stand in front of the wall where it stands: the signed
        distance for points along its span (within :data:`WALL_END_MARGIN_M`), ``inf`` for those
        past its ends (the wall is not between them and the room). The same as
        :meth:`signed_distance_m` for an unbounded plane."""
        pts = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
        d = pts @ self.normal + self.offset_m
        if not self.bounded:
            return d
        s = pts @ self.tangent
        lo, hi = self._ends()
        along = (s >= lo - WALL_END_MARGIN_M) & (s <= hi + WALL_END_MARGIN_M)
        return np.where(along, d, np.inf)

    def slab(self) -> tuple[np.ndarray, float, np.ndarray]:
        """A bounded wall as the box exporters collide with: centre (3,) m, yaw (rad) of its
        frame (x along the wall, :attr:`tangent`; y out of the room, ``-normal``; z up) and half
        extents (3,) m: its span widened by WALL_END_MARGIN_M at each known end (an open end
        WALL_OPEN_LENGTH_M from the known one), WALL_SLAB_THICKNESS_M behind its face,
        WALL_SLAB_HEIGHT_M from the floor up."""
        if not self.bounded:
            raise ValueError("Plane.slab: an unbounded plane has no slab (export it as a plane)")
        t = self.tangent
        a, b = self.span_m
        lo = a - WALL_END_MARGIN_M if a is not None else b + WALL_END_MARGIN_M - WALL_OPEN_LENGTH_M
        hi = b + WALL_END_MARGIN_M if b is not None else a - WALL_END_MARGIN_M + WALL_OPEN_LENGTH_M
        centre = -self.offset_m * self.normal + 0.5 * (lo + hi) * t - 0.5 * WALL_SLAB_THICKNESS_M * self.normal
        centre[2] = 0.5 * WALL_SLAB_HEIGHT_M
        half = np.array([0.5 * (hi - lo), 0.5 * WALL_SLAB_THICKNESS_M, 0.5 * WALL_SLAB_HEIGHT_M])
        return centre, float(np.arctan2(t[1], t[0])), half
