"""Repairs before an object is given up to the background: a pad cut back clear of a neighbour's
completion (layout.background.clip_pad), the floor under a rug (layout.support.FLOOR_LIKE_M)."""

from __future__ import annotations

import numpy as np
import pytest

from layout.background import clip_pad
from layout.background_policy import unsupport_blocked_pads
from layout.bodies import make_body
from layout.support import BACKGROUND, UNSUPPORTED
from scene_builder.bench.clutter import box_asset
from scene_builder.frames import pose


def _box_verts(lo, hi) -> np.ndarray:
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], dtype=np.float64)


def test_clip_pad_keeps_the_most_area_with_the_centre_of_mass_inside():
    rect = np.array([-1.0, -0.8, 1.0, 0.8])
    # A neighbour reaching 0.4 m in under the +x end, across the whole width.
    obstacle = _box_verts([0.6, -2.0, 0.0], [1.5, 2.0, 1.0])
    out = clip_pad(rect, 0.0, np.zeros(3), 0.0, 0.1, [obstacle], np.zeros(2), 0.1)
    assert out == pytest.approx([-1.0, -0.8, 0.6, 0.8])
    # Nothing in the pad's height band: the pad stays whole.
    high = _box_verts([0.6, -2.0, 0.2], [1.5, 2.0, 1.0])
    assert clip_pad(rect, 0.0, np.zeros(3), 0.0, 0.1, [high], np.zeros(2), 0.1) == pytest.approx(rect)
    # The centre of mass over the neighbour: no cut keeps it on the pad.
    assert clip_pad(rect, 0.0, np.zeros(3), 0.0, 0.1, [obstacle], np.array([0.8, 0.0]), 0.1) is None
    # The pad's axes turn with the object: yawed 90 degrees, the obstacle at +x cuts its -y side.
    out = clip_pad(rect, np.pi / 2, np.zeros(3), 0.0, 0.1, [_box_verts([0.6, -2.0, 0.0], [1.5, 2.0, 1.0])], np.zeros(2), 0.1)
    assert out == pytest.approx([-1.0, -0.6, 1.0, 0.8])
    # Two neighbours, both sides: cut twice.
    left = _box_verts([-1.5, 0.5, 0.0], [1.5, 1.0, 1.0])
    out = clip_pad(rect, 0.0, np.zeros(3), 0.0, 0.1, [obstacle, left], np.zeros(2), 0.1)
    assert out == pytest.approx([-1.0, -0.8, 0.6, 0.5])


def test_a_bed_keeps_its_pad_short_of_a_night_stand_reaching_under_it():
    bed = make_body(box_asset("bed", (2.0, 1.6, 0.5)), pose(np.eye(3), (0.0, 0.0, 0.1)))
    stand = make_body(box_asset("stand", (0.5, 0.5, 0.6)), pose(np.eye(3), (1.1, 0.0, 0.0)))  # reaches 15 cm under the bed's end
    bed.parent, stand.parent = BACKGROUND, -1
    unsupport_blocked_pads([bed, stand])
    assert bed.parent == BACKGROUND and bed.pad_rect_m is not None
    assert bed.pad_rect_m[2] == pytest.approx(1.1 - 0.25)
    # A neighbour filling the space under the bed's middle leaves it nothing to rest on.
    under = make_body(box_asset("chest", (0.6, 2.0, 0.6)), pose(np.eye(3), (0.0, 0.0, 0.0)))
    bed.parent, bed.pad_rect_m = BACKGROUND, None
    unsupport_blocked_pads([bed, under])
    assert bed.parent == UNSUPPORTED and "another object's" in bed.unsupported_reason


def test_swept_boxes_cover_an_open_door_and_a_pulled_drawer():
    """The room a door swings through and a drawer slides into (layout.geometry.swept_part_boxes),
    which the background's collision boxes are carved clear of: a cabinet photo's door was held
    at 2 % of its range by columns of the background seen 2 cm before it."""
    from layout.geometry import swept_part_boxes
    from tests.fixtures_scenes import CAB_D, CAB_W, DRAWER_RANGE_M, cabinet_asset

    asset = cabinet_asset()
    t = pose(np.eye(3), np.array([1.0, 2.0, 0.0]))
    lo, hi = swept_part_boxes(asset, t)
    assert len(lo) == 2  # the door and the drawer; the carcass does not move
    door, drawer = (0, 1) if hi[0, 2] > hi[1, 2] else (1, 0)
    # The door (hinged on its -y edge, opening 90 deg outwards) reaches a door width out in +x.
    assert hi[door, 0] == pytest.approx(1.0 + CAB_D / 2 + CAB_W, abs=0.01)
    assert lo[door, 1] == pytest.approx(2.0 - CAB_W / 2, abs=0.01)
    # The drawer slides out by its full travel.
    assert hi[drawer, 0] == pytest.approx(1.0 + CAB_D / 2 + DRAWER_RANGE_M[1], abs=1e-6)
    # A rigid box sweeps nothing.
    assert len(swept_part_boxes(box_asset("b", (1.0, 1.0, 1.0)), t)[0]) == 0


def test_a_pad_is_cut_again_when_the_pushes_moved_a_neighbour_into_it():
    """The background's pad under a bed was left out when the horizontal pushes had since moved a
    pillow under its edge (sunrgbd_imvotenet_000005: the bed fell onto its 13 cm of air and
    tipped everything on it off): it is cut back clear of the pillow instead."""
    from layout.background_policy import static_background
    from scene_builder.model import Background, TriangleMesh

    bed = make_body(box_asset("bed", (2.0, 1.6, 0.5)), pose(np.eye(3), (0.0, 0.0, 0.1)))
    pillow = make_body(box_asset("pillow", (0.5, 0.5, 0.3)), pose(np.eye(3), (1.1, 0.0, 0.0)))  # 15 cm under the bed's end
    bed.parent, pillow.parent = BACKGROUND, -1
    empty = Background(TriangleMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)), np.zeros(0, dtype=bool))
    out = static_background(empty, [bed, pillow], [], (), {})
    assert len(out.box_centers_m) == 1  # the bed's pad, and nothing else
    hi_x = out.box_centers_m[0, 0] + out.box_half_extents_m[0, 0]
    assert hi_x == pytest.approx(1.1 - 0.25)
    assert out.box_centers_m[0, 0] - out.box_half_extents_m[0, 0] == pytest.approx(-1.0)
