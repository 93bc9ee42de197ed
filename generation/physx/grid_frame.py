"""PhysX grid frame -> asset frame: :class:`GridFrame` maps voxel coordinates to metres and
:func:`group_joint` turns a description's group into an asset-frame joint (metres, radians).

Frames: the PhysX grid frame is z up with the object's front towards -y (the PartNet-Mobility
canonical front +z of the Y-up source becomes -y after the +90 degree turn about x, README G5; in the
real cabinet the door is the part at the lowest y). Our asset frame has the front towards +x, so
``asset_from_physx`` is a +90 degree turn about z. Upstream scales by the largest dimension only;
:meth:`GridFrame.from_dimension` uses all three (the origin at the bottom centre of the box they
define, and, when the voxels are known, one scale per axis fitted to them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from generation.physx.description import MovementType, PhysxGroup
from scene_builder.model import Joint, JointType

__all__ = ["ASSET_FROM_PHYSX", "GridFrame", "group_joint"]

#: (3, 3) rotation taking PhysX grid axes (front -y) to the asset frame (front +x): +90 deg about z.
ASSET_FROM_PHYSX = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
ASSET_FROM_PHYSX.setflags(write=False)


# --------------------------------------------------------------------------------------------
# Grid frame -> asset frame
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class GridFrame:
    """Maps continuous PhysX grid coordinates (voxel units; voxel i covers [i, i+1)) to the asset
    frame in metres: ``p_asset = ASSET_FROM_PHYSX @ (metres_per_voxel * (p_vox - origin_vox))``.

    metres_per_voxel: (3,) along the grid's x, y, z. origin_vox: (3,) the grid point that becomes
    the asset origin (bottom centre of the object's box).
    """

    grid: int
    metres_per_voxel: np.ndarray
    origin_vox: np.ndarray

    def __post_init__(self) -> None:
        for name in ("metres_per_voxel", "origin_vox"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            if arr.shape != (3,):
                raise ValueError(f"GridFrame.{name} must have shape (3,)")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @classmethod
    def from_dimension(
        cls,
        dimension_cm: tuple[float, float, float],
        grid: int,
        occupied_lo_hi_vox: tuple[np.ndarray, np.ndarray] | None = None,
        max_anisotropy: float = 0.25,
    ) -> tuple["GridFrame", tuple[str, ...]]:
        """Frame from the stated size along x, y, z (all three used). Without voxels: the object
        box is centred in the grid with extents ``G * D / max(D)`` (README G5) and the scale is
        ``max(D) / G``. With ``occupied_lo_hi_vox`` (inclusive min / max occupied voxel indices of
        all parts): the origin is that box's bottom centre and each axis gets its own scale
        ``D_i / n_i``, unless it differs from ``max(D) / G`` by more than ``max_anisotropy``
        (then the model's size and voxels disagree on that axis: the isotropic scale is kept)."""
        d_m = np.asarray(dimension_cm, dtype=np.float64) / 100.0
        iso = float(d_m.max()) / grid
        warnings: list[str] = []
        if occupied_lo_hi_vox is None:
            half = grid * d_m / d_m.max() / 2.0
            origin = np.array([grid / 2.0, grid / 2.0, grid / 2.0 - half[2]])
            return cls(grid, np.full(3, iso), origin), ()
        lo, hi = (np.asarray(a, dtype=np.float64) for a in occupied_lo_hi_vox)
        n = hi - lo + 1.0
        scale = d_m / n
        for i in range(3):
            if abs(scale[i] / iso - 1.0) > max_anisotropy:
                warnings.append(
                    f"axis {'xyz'[i]}: stated size {d_m[i] * 100:g} cm over {n[i]:g} voxels disagrees with "
                    f"the largest size's scale by {abs(scale[i] / iso - 1) * 100:.0f}%; isotropic scale kept"
                )
                scale[i] = iso
        origin = np.array([(lo[0] + hi[0] + 1.0) / 2.0, (lo[1] + hi[1] + 1.0) / 2.0, lo[2]])
        return cls(grid, scale, origin), tuple(warnings)

    def to_asset(self, points_vox: np.ndarray) -> np.ndarray:
        """(N, 3) grid coordinates -> (N, 3) asset-frame metres."""
        p = np.atleast_2d(np.asarray(points_vox, dtype=np.float64))
        return ((p - self.origin_vox) * self.metres_per_voxel) @ ASSET_FROM_PHYSX.T

    def direction_to_asset(self, direction: np.ndarray) -> tuple[np.ndarray, float]:
        """Unit asset-frame direction of a grid direction and the metres per voxel along it
        (a line stays a line under the per-axis scale)."""
        d = np.asarray(direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        v = d * self.metres_per_voxel
        length = float(np.linalg.norm(v))
        return ASSET_FROM_PHYSX @ (v / length), length


def _axis_position(g: PhysxGroup, direction, centre_vox: np.ndarray) -> np.ndarray:
    """Hinge point in grid coordinates; for an axis-aligned direction the text writes 0 along the
    axis (no information): we put the child's centre there instead of the grid's corner."""
    p = np.array(g.axis_position_vox, dtype=np.float64)
    if direction is not None:
        d = np.asarray(direction, dtype=np.float64)
        ones = np.flatnonzero(np.isclose(d, 1.0))
        if len(ones) == 1 and np.allclose(np.delete(d, ones[0]), 0.0):
            p[ones[0]] = centre_vox[ones[0]]
    return p


def group_joint(g: PhysxGroup, frame: GridFrame, child_centre_vox: np.ndarray) -> tuple[Joint, tuple[str, ...]]:
    """The asset-frame joint (metres, radians) of a non-base group relative to its parent group.

    child_centre_vox: (3,) centre of the group's voxels in grid coordinates (anchor for joints
    without a position, and the value along the axis of axis-aligned hinges)."""
    warnings: list[str] = []
    centre = np.asarray(child_centre_vox, dtype=np.float64)
    anchor_centre = frame.to_asset(centre)[0]
    z_axis = np.array([0.0, 0.0, 1.0])
    mt = g.movement
    if mt is MovementType.FIXED:
        return Joint(JointType.FIXED, z_axis, anchor_centre), ()
    if mt is MovementType.FREE:
        return Joint(JointType.FREE, z_axis, anchor_centre), ()
    if mt is MovementType.BALL:
        anchor = frame.to_asset(np.array(g.axis_position_vox))[0]
        return Joint(JointType.BALL, z_axis, anchor), ()
    if mt is MovementType.SLIDE:
        axis, m_per_vox = frame.direction_to_asset(np.array(g.slide_direction))
        lo, hi = (v * m_per_vox for v in g.slide_range_vox)
        return Joint(JointType.PRISMATIC, axis, anchor_centre, lower=lo, upper=hi), ()
    axis, _ = frame.direction_to_asset(np.array(g.axis_direction))
    anchor = frame.to_asset(_axis_position(g, g.axis_direction, centre))[0]
    lo, hi = (math.radians(v) for v in g.revolute_range_deg)
    if hi - lo >= 2.0 * math.pi - 1e-9:
        warnings.append(f"group_{g.group_id}: unlimited revolute range kept as [-pi, pi]")
        lo, hi = -math.pi, math.pi
    if mt is MovementType.REVOLUTE:
        return Joint(JointType.REVOLUTE, axis, anchor, lower=lo, upper=hi), tuple(warnings)
    slide_axis, m_per_vox = frame.direction_to_asset(np.array(g.slide_direction))
    cos = float(axis @ slide_axis)
    if abs(cos) < 0.99:
        warnings.append(f"group_{g.group_id}: slide direction is not along the hinge axis; only its component along the axis kept")
    lo2, hi2 = sorted(v * m_per_vox * cos for v in g.slide_range_vox)
    return Joint(JointType.REVOLUTE_PRISMATIC, axis, anchor, lower=lo, upper=hi, lower2=lo2, upper2=hi2), tuple(warnings)
