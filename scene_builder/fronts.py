"""Door and drawer fronts seen in the photo (part of the data model; re-exported by
:mod:`scene_builder.model`).

Perception (``perception.fronts``) finds them on the face of a piece of furniture, free-standing
or built in; generation turns each into a moving part (``generation.front_parts``): a door on a
revolute joint at its hinge side, a drawer on a prismatic joint as deep as the carcass, a flap
(oven, dishwasher) on a revolute joint at its bottom edge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scene_builder.arrays import _freeze

__all__ = ["FRONT_KINDS", "Front"]

#: ``door``: hinged at its left or right edge; ``drawer``: slides out; ``flap``: hinged at its
#: bottom edge (an oven or dishwasher door).
FRONT_KINDS = ("door", "drawer", "flap")
_HINGES = {"door": ("left", "right"), "drawer": ("",), "flap": ("bottom",)}


@dataclass(frozen=True, eq=False)
class Front:
    """One door or drawer front seen on an object's face.

    kind: one of :data:`FRONT_KINDS`. hinge: ``"left"`` or ``"right"`` (as seen from the front,
      the viewer's left or right) for a door, ``"bottom"`` for a flap, ``""`` for a drawer.
    corners_px: (4, 2) float64 pixel corners (u, v) in the analysis image (``Observation.rgb``):
      bottom-left, bottom-right, top-right, top-left as seen from the front.
    corners_world_m: (4, 3) float64 the same corners in the world frame, on the face's plane.
    handle_px: (2,) float64 pixel of its handle's centre, or None when none was seen.
    score: unitless confidence in [0, 1] (1: a handle and cut lines on all four sides).
    """

    kind: str
    hinge: str
    corners_px: np.ndarray
    corners_world_m: np.ndarray
    handle_px: np.ndarray | None = None
    score: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in FRONT_KINDS:
            raise ValueError(f"Front.kind must be one of {FRONT_KINDS}, got {self.kind!r}")
        if self.hinge not in _HINGES[self.kind]:
            raise ValueError(f"Front: a {self.kind}'s hinge is one of {_HINGES[self.kind]}, got {self.hinge!r}")
        _freeze(self, "corners_px", np.float64, (4, 2))
        _freeze(self, "corners_world_m", np.float64, (4, 3))
        if self.handle_px is not None:
            _freeze(self, "handle_px", np.float64, (2,))
        if not 0.0 <= self.score <= 1.0:
            raise ValueError("Front.score must be in [0, 1]")

    @property
    def box_xyxy_px(self) -> tuple[float, float, float, float]:
        """(u0, v0, u1, v1): the pixel bounding box of its corners."""
        lo, hi = self.corners_px.min(axis=0), self.corners_px.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])
