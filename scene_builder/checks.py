"""Results of checking a scene (part of the data model; re-exported by :mod:`scene_builder.model`):
the physics verdict measured in MuJoCo and the render-and-compare against the photo. Units and
frames as written down in :mod:`scene_builder.model`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scene_builder.arrays import _freeze

__all__ = ["Fidelity", "JointProbe", "ObjectVerdict", "PhysicsVerdict", "PushPlan", "PushResult", "Trajectory"]


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


@dataclass(frozen=True)
class PushResult:
    """A scripted push of one movable object (``layout.push.push_object``): a force-limited
    pusher (a paddle on slide joints driven by position servos, colliding with everything) driven
    horizontally into its side, then pulled back, then a settle.

    name: the pushed object; direction_xy: (2,) unit horizontal push direction in the world;
    clearance_m: free space ahead of it along that direction (its collision geometry slid there, up to
      ``CLEARANCE_CAP_M``); height_m: world z of the pusher's centre (nan when it never started);
      speed_m_s: pusher speed; force_limit_n: the pusher's force limit;
    pusher_travel_m: how far the pusher advanced past first contact (0 when it never touched);
      touched: whether it touched the object at all;
    displacement_m: horizontal displacement of the pushed object's root body after the settle;
      along_m: its component along the push direction; tilt_deg: change of its up axis;
      toppled: tilt above ``layout.verify.TOPPLE_DEG``.
    carried: (name, displacement_m) of the objects resting on it (directly or on each other):
      they may ride along and are not counted as others; carried_slip: (name, m) how far each
      moved horizontally relative to the pushed object; carried_drop: (name, m) how far each
      sank; carried_tilt: (name, deg) how far each tilted.
    others: (name, max displacement_m over the push and settle) of every other free object;
      max_other_m: their largest (0 with none).
    mass_kg: the pushed object's mass with what rides on it; slide_force_n: that weight times the
      friction coefficient of its resting contacts (nan with none): what sliding it takes.
    max_force_n: the largest force the pusher exerted along the push; stalled: it touched the
      object but stopped short of its travel (held back at its force limit).
    resisted_by: (what, peak N) the pushed object and its riders pressed against the push
      through side contacts (objects, fixed furniture, ``wall_i``, ``background``), largest first;
      pusher_hit: (what, peak N) the pusher touched besides the pushed object, largest first.
    not_started: why the push could not start ("" when it did): no room for the pusher behind
      it, no collision geometry.
    """

    name: str
    direction_xy: tuple[float, float]
    clearance_m: float
    height_m: float
    speed_m_s: float
    pusher_travel_m: float
    displacement_m: float
    along_m: float
    tilt_deg: float
    toppled: bool
    carried: tuple[tuple[str, float], ...] = ()
    others: tuple[tuple[str, float], ...] = ()
    max_other_m: float = 0.0
    force_limit_n: float = float("nan")
    mass_kg: float = float("nan")
    slide_force_n: float = float("nan")
    touched: bool = False
    max_force_n: float = 0.0
    stalled: bool = False
    resisted_by: tuple[tuple[str, float], ...] = ()
    pusher_hit: tuple[tuple[str, float], ...] = ()
    carried_slip: tuple[tuple[str, float], ...] = ()
    carried_drop: tuple[tuple[str, float], ...] = ()
    carried_tilt: tuple[tuple[str, float], ...] = ()
    not_started: str = ""


@dataclass(frozen=True)
class PushPlan:
    """Which way a movable object is pushed (``layout.push.plan_push``); every movable object
    is pushed, this is the planner's forecast.

    name: the object; pushable: a direction with at least ``min_clearance_m`` free space ahead,
    support under its centre of mass after the push, no neighbour beside it to drag and room for
    the pusher behind it was found; direction_xy / clearance_m: that direction, else the best of
    the tried ones (room for the pusher, then most clearance; (0, 0) and 0 with no collision
    geometry); reason: why no side has all of these ("" when one has).
    """

    name: str
    pushable: bool
    direction_xy: tuple[float, float]
    clearance_m: float
    reason: str = ""


@dataclass(frozen=True, eq=False)
class JointProbe:
    """One articulation joint pulled open (``layout.interaction.open_joint``): a force at the
    handle (a hinge: tangential to the swing at the handle or the part's edge farthest from the
    axis; a slide: along the axis), held ``pull_s`` seconds, then released.

    joint: MJCF joint name (``NAME/PART/joint``); object: NAME; kind: "hinge" (rad) or "slide" (m);
    range: (lower, upper) joint limits in joint units; start: position before the pull;
    open_sign: +1 when opening increases the position (toward the farther limit), else -1;
    force_n: the pull; travel: signed-open travel at the end of the pull (joint units);
    open_fraction: travel over the distance from start to the far limit;
    backtrack: the largest step back against the opening direction while pulled (joint units);
    limit_violation: the largest excursion beyond the range at any time (joint units);
    final: position after release and settle;
    body_displacement_m: largest displacement of the object's root body (the carcass);
    times_s / positions: (T,) samples of the joint position over the probe.
    """

    joint: str
    object: str
    kind: str
    range: tuple[float, float]
    start: float
    open_sign: float
    force_n: float
    travel: float
    open_fraction: float
    backtrack: float
    limit_violation: float
    final: float
    body_displacement_m: float
    times_s: np.ndarray
    positions: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self, "times_s", np.float64, (None,))
        _freeze(self, "positions", np.float64, (len(self.times_s),))
