"""Shape-prior box completion: a face seen against a wall is completed to the category's depth
only as far as the wall behind it."""

from __future__ import annotations

import numpy as np
import pytest

from generation.pose import fit_box
from generation.shape_prior import complete_box, depth_to_walls
from scene_builder.model import Plane


def _face_points(x_m: float, rng: np.random.Generator) -> np.ndarray:
    """(400, 3) points of a 1.0 m wide, 0.8 m high vertical face at x = x_m, 0.6..1.4 m up."""
    y = rng.uniform(-0.5, 0.5, 400)
    z = rng.uniform(0.6, 1.4, 400)
    return np.column_stack([np.full(400, x_m) + rng.normal(0.0, 0.002, 400), y, z])


@pytest.mark.parametrize("wall_gap_m", [0.05, 0.2])
def test_completed_depth_stops_at_the_wall_behind(wall_gap_m: float):
    rng = np.random.default_rng(0)
    camera = np.array([3.0, 0.0, 1.3])  # looking along -x at the face; the wall at x = -wall_gap_m
    wall = Plane(np.array([1.0, 0.0, 0.0]), wall_gap_m, "wall", 1000)
    fit = fit_box(_face_points(0.0, rng), camera)
    free = complete_box(fit, "table")
    assert free.size_m[0] > 0.5  # a table's depth without the wall
    near = complete_box(fit, "table", (wall,))
    corners = np.array([[sx * near.size_m[0] / 2, sy * near.size_m[1] / 2, 0.0] for sx in (-1, 1) for sy in (-1, 1)])
    world = corners @ near.world_from_box[:3, :3].T + near.world_from_box[:3, 3]
    assert wall.signed_distance_m(world).min() == pytest.approx(0.0, abs=2e-3)  # back face on the wall
    assert near.size_m[0] < wall_gap_m + 0.02
    # the observed front face stays where it was
    front = lambda f: f.world_from_box[0, 3] + f.size_m[0] / 2  # noqa: E731
    assert front(near) == pytest.approx(front(fit), abs=1e-6)


def test_wall_in_front_or_beside_does_not_limit_depth():
    rng = np.random.default_rng(1)
    camera = np.array([3.0, 0.0, 1.3])
    fit = fit_box(_face_points(0.0, rng), camera)
    behind_camera = Plane(np.array([-1.0, 0.0, 0.0]), 4.0, "wall", 10)  # x = 4, normal towards -x
    side = Plane(np.array([0.0, 1.0, 0.0]), 2.0, "wall", 10)  # y = -2, parallel to the depth axis
    assert depth_to_walls(fit, (behind_camera, side)) == np.inf
    np.testing.assert_allclose(complete_box(fit, "table", (behind_camera, side)).size_m, complete_box(fit, "table").size_m)


def _slab(lo, hi, n, rng):
    return rng.uniform(lo, hi, size=(n, 3))


def test_unseen_legs_extend_the_box_to_the_floor_unless_something_is_under_it():
    from generation.pose import floor_snap_height_m

    rng = np.random.default_rng(0)
    camera = np.array([-3.0, 0.0, 1.6])
    # a chair seen from above: seat and backrest, the legs hidden (lowest point 0.12 m up)
    chair = np.vstack([_slab([0.0, 0.0, 0.12], [0.5, 0.5, 0.45], 400, rng), _slab([0.45, 0.0, 0.45], [0.5, 0.5, 0.85], 400, rng)])
    snap = floor_snap_height_m(chair, [])
    fit = fit_box(chair, camera, floor_snap_m=snap)
    assert fit.on_floor
    assert abs(fit.world_from_box[2, 3]) < 1e-9
    assert abs(fit.size_m[2] - chair[:, 2].max()) < 1e-9
    # a low box under it (top at 0.12 m): the chair's points rest on it, its bottom stays seen
    low_box = _slab([0.1, 0.1, 0.0], [0.4, 0.4, 0.12], 300, rng)
    snap = floor_snap_height_m(chair, [low_box])
    fit = fit_box(chair, camera, floor_snap_m=snap)
    assert not fit.on_floor
    assert abs(fit.world_from_box[2, 3] - chair[:, 2].min()) < 0.01
    # the same box beside the chair supports nothing
    assert floor_snap_height_m(chair, [low_box + np.array([2.0, 0.0, 0.0])]) >= chair[:, 2].min()
    # a laptop on a table 0.75 m up is never dropped to the floor by the box fit
    laptop = _slab([0.0, 0.0, 0.75], [0.3, 0.3, 0.77], 200, rng)
    assert floor_snap_height_m(laptop, []) < 0.75
