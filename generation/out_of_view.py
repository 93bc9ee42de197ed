"""Furniture that a side edge of the photo cut continues out of view.

A dresser at the photo's right edge shows 40 cm of its front; the rest of it stands past the
edge, where the camera did not look. Built as seen, it is a 40 cm slab, and any other viewpoint
(a robot's, a simulator camera's, the rerun viewer's) shows a sliver of a dresser. The box of
floor furniture that exactly one side edge cut (:func:`scene_builder.frames.cut_side`, seen at
least :data:`~scene_builder.frames.SIDEWAYS_MIN_HEIGHT_M` tall) is widened along its width axis
toward that edge:

- **how far**: at least until the seen face's end is not wholly in view (the photo did not show
  it: one of its two corners, top or bottom, lies past the frustum's side plane, which a rolled
  or pitched camera leans; a sensor's depth often stops short of the photo's edge, so the seen
  points end inside the view where the object goes on), and to the
  category's typical width, scaled by the seen height against the typical height (the
  proportions :func:`generation.shape_prior.complete_box` completes the depth by), when less
  than :data:`GROW_BELOW_SHARE` of that was seen; never more than :data:`~scene_builder.frames.LENGTH_FACTOR` times
  the seen width (:data:`~scene_builder.frames.LENGTH_CAP_M` at most), the range naming weighed
  (``perception.seen_extent``);
- **which way**: the box's width axis whose direction points out of the view past the cut edge
  (its cosine with the frustum side plane's outward normal, in plan, at least
  :data:`MIN_OUTWARD`); a box whose width axis runs along the view (a dresser seen end-on)
  is left as it is: its depth completion already grows it away from the camera;
- **what stops it**: a wall (:meth:`scene_builder.planes.Plane.clearance_m`), what another
  object showed of itself beside it (within the box's depth and height), and the camera, which
  stands in the room, not in the furniture.

What the camera saw stays where it was seen: the seen front and side do not move; only the end
that the photo did not show does.
"""

from __future__ import annotations

import numpy as np

from scene_builder.frames import LENGTH_CAP_M, LENGTH_FACTOR, SIDEWAYS_MIN_HEIGHT_M, cut_side, transform_points

__all__ = ["CAMERA_CLEARANCE_M", "GROW_BELOW_SHARE", "MIN_OUTWARD", "OTHERS_CLEARANCE_M", "outward_normal", "width_out_of_view"]

#: The width axis points out of the view when its cosine with the side plane's outward normal is
#: at least this (60 degrees).
MIN_OUTWARD = 0.5
#: The box is widened to the category's width only when its seen width is less than this share of
#: it (else only until its end is out of view).
GROW_BELOW_SHARE = 0.8
#: It stops this far short of another object's seen points ...
OTHERS_CLEARANCE_M = 0.02
#: ... at least this many of them (a few stray points do not stop it) ...
MIN_BLOCKING_POINTS = 20
#: ... and this far from the camera's centre, in plan, when the camera is not above it.
CAMERA_CLEARANCE_M = 0.3


def outward_normal(camera, side: str) -> np.ndarray:
    """(3,) world unit normal of the frustum's ``side`` ("left" / "right") plane (through the
    camera centre and the photo's edge column), pointing out of the view."""
    k = camera.intrinsics
    if side == "left":
        a = (0.0 - k.cx_px) / k.fx_px
        n_cam = np.array([-1.0, 0.0, a])
    elif side == "right":
        b = (k.width_px - 1.0 - k.cx_px) / k.fx_px
        n_cam = np.array([1.0, 0.0, -b])
    else:
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    n = camera.world_from_camera[:3, :3] @ n_cam
    return n / np.linalg.norm(n)


def _limit_others(q_others, d: float, w: float, h: float, s: float) -> float:
    """How far the end at ``y = s w / 2`` (box frame) can move before it reaches what another
    object showed of itself beside it (``q_others``: each object's points in the box frame)."""
    limit = np.inf
    for q in q_others:
        beside = (np.abs(q[:, 0]) <= d / 2) & (q[:, 2] >= 0.0) & (q[:, 2] <= h) & (s * q[:, 1] > w / 2)
        if int(beside.sum()) < MIN_BLOCKING_POINTS:
            continue
        limit = min(limit, float(np.percentile(s * q[beside, 1] - w / 2, 2)) - OTHERS_CLEARANCE_M)
    return limit


def width_out_of_view(fit, label: str, mask: np.ndarray, camera, walls=(), others_world_m=()) -> tuple[object, float, str]:
    """(the box ``fit`` (a :class:`generation.pose.BoxFit`) widened out of view, metres it grew,
    the edge that cut it or "") for an object labelled ``label`` with photo ``mask`` (see the
    module docstring); ``fit`` itself and 0 when nothing is to grow."""
    from generation.pose import BoxFit, travel_to_walls
    from scene_builder.vocabulary import category

    cat = category(label)
    side = cut_side(mask)
    d, w, h = (float(v) for v in fit.size_m)
    if side is None or label == "object" or not cat.on_floor or h < SIDEWAYS_MIN_HEIGHT_M:
        return fit, 0.0, ""
    _, tw, th = cat.typical_size_m
    expected = tw * h / th
    rot = fit.world_from_box[:3, :3]
    n3 = outward_normal(camera, side)
    n_plan = np.array([n3[0], n3[1], 0.0])
    n_plan /= max(float(np.linalg.norm(n_plan)), 1e-9)
    s = 1.0 if float(rot[:, 1] @ n_plan) >= 0 else -1.0
    e = s * rot[:, 1]
    if float(e @ n_plan) < MIN_OUTWARD:
        return fit, 0.0, ""
    end = transform_points(fit.world_from_box, np.array([[x, s * w / 2, z] for x in (-d / 2, d / 2) for z in (0.0, h)]))
    # The seen face's end is not wholly in view: one of its two corners (top, bottom) lies past
    # the side plane. Not both: a camera looking down leans the plane, and a shelf whose top
    # corner the edge cut showed its bottom corner, its true end, 22 px inside the photo
    # (procedural room 3: grown 11 cm past it when both had to leave the view). Not the back's
    # corners: the depth behind the seen face is a completion.
    front_end = end[2:]
    c = camera.position_m
    rate = float(n3 @ e)
    out_of_view = max(0.0, float(np.min(-((front_end - c) @ n3) / rate)))
    grow = max(expected - w, out_of_view) if w < GROW_BELOW_SHARE * expected else out_of_view
    grow = min(grow, min(LENGTH_FACTOR * w, max(LENGTH_CAP_M, w)) - w)
    box_from_world = np.linalg.inv(fit.world_from_box)
    q_others = [transform_points(box_from_world, np.asarray(o, dtype=np.float64)) for o in others_world_m if len(o)]
    cam = transform_points(box_from_world, c[None])[0]
    limit = min(travel_to_walls(end, e, walls), _limit_others(q_others, d, w, h, s))
    if cam[2] < h + CAMERA_CLEARANCE_M and abs(cam[0]) < d / 2 + CAMERA_CLEARANCE_M and s * cam[1] > w / 2:
        limit = min(limit, s * cam[1] - w / 2 - CAMERA_CLEARANCE_M)
    grow = min(grow, limit)
    if grow <= 0.01:
        return fit, 0.0, ""
    world_from_box = fit.world_from_box.copy()
    world_from_box[:3, 3] = world_from_box[:3, 3] + e * grow / 2.0
    size = fit.size_m.copy()
    size[1] = w + grow
    return BoxFit(world_from_box, size, fit.on_floor, fit.observed_depth_m), float(grow), side
