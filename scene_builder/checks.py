"""Results of checking a scene (part of the data model; re-exported by :mod:`scene_builder.model`):
the physics verdict measured in MuJoCo and the render-and-compare against the photo. Units and
frames as written down in :mod:`scene_builder.model`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scene_builder.arrays import _freeze

__all__ = ["Fidelity", "ObjectVerdict", "PhysicsVerdict", "Trajectory"]


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Simulated motion of one free body.

    times_s: (T,) float64; positions_m: (T, 3) body origin in the world; quats_wxyz: (T, 4).
    """

    name: str
    times_s: np.ndarray
    positions_m: np.ndarray
    quats_wxyz: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self, "times_s", np.float64, (None,))
        n = len(self.times_s)
        _freeze(self, "positions_m", np.float64, (n, 3))
        _freeze(self, "quats_wxyz", np.float64, (n, 4))


@dataclass(frozen=True)
class ObjectVerdict:
    """Physics check of one object after layout.

    start_penetration_m / end_penetration_m: its deepest overlap with any other body or static
    geometry at t = 0 and after settling. fixed: welded to the world (built-in furniture): it
    cannot move, so it is never counted as "at rest".
    """

    name: str
    start_penetration_m: float
    drift_m: float
    rotation_deg: float
    toppled: bool
    fixed: bool = False
    end_penetration_m: float = 0.0


@dataclass(frozen=True)
class PhysicsVerdict:
    """Physics check of the whole exported scene (measured in MuJoCo from the exported MJCF).

    max_penetration_m: deepest overlap at t = 0 over every pair of collision geometry of
      different bodies: objects, fixed furniture, floor, walls and the static background
      (``mj_geomDistance``; soft bodies by their contacts). max_penetration_settled_m: the same
      after ``simulated_s`` of simulation.
    settle_max_drift_m / settle_max_rotation_deg: largest motion of any movable object.
    stable: every movable object stays within the drift and rotation bounds (fixed furniture is
      not counted: it cannot move). movable_count / fixed_count: how many of each were checked.
    """

    max_penetration_m: float
    settle_max_drift_m: float
    settle_max_rotation_deg: float
    simulated_s: float
    stable: bool
    objects: tuple[ObjectVerdict, ...] = ()
    trajectories: tuple[Trajectory, ...] = ()
    contact_points_m: tuple[tuple[float, float, float], ...] = ()
    max_penetration_settled_m: float = 0.0
    movable_count: int = 0
    fixed_count: int = 0


@dataclass(frozen=True, eq=False)
class Fidelity:
    """Render-and-compare of the scene against the observation, rendered from ``input_camera``
    with the scene's own lights, at t = 0 and after the settle simulation.

    psnr_db, ssim (unitless, -1..1): the RGB render against the photo (t = 0);
      psnr_settled_db, ssim_settled: after settling.
    depth_absrel (unitless): mean |d_render - d_obs| / d_obs over every pixel with valid observed
      depth (not an isolated outlier: within 10 % of its 5x5 median), t = 0 (a pixel where the
      render hits nothing counts as relative error 1);
      depth_absrel_settled: the same after settling; object_depth_absrel: over the movable
      objects' perceived pixels only.
    mask_iou_mean: mean over movable objects of the IoU of their rendered (visible) silhouette
      and their perceived mask; mask_iou: per object name.
    render_rgb, render_settled_rgb: (H, W, 3) uint8 renders, or None.
    """

    depth_absrel: float
    mask_iou_mean: float
    mask_iou: tuple[tuple[str, float], ...] = field(default_factory=tuple)
    depth_absrel_settled: float = float("nan")
    object_depth_absrel: float = float("nan")
    psnr_db: float = float("nan")
    ssim: float = float("nan")
    psnr_settled_db: float = float("nan")
    ssim_settled: float = float("nan")
    render_rgb: np.ndarray | None = None
    render_settled_rgb: np.ndarray | None = None
