"""Furniture a side edge of the photo cut continues out of view (generation.out_of_view): a
dresser whose front the photo's right edge cut at 42 cm is widened past the edge, its seen end
where it was, its new end outside the view, stopped by a wall or a neighbour beside it."""

from __future__ import annotations

import numpy as np
import pytest

from generation.out_of_view import outward_normal, width_out_of_view
from generation.pose import BoxFit
from scene_builder.frames import pose, transform_points
from scene_builder.model import Camera, CameraIntrinsics, Plane

# A camera 1.2 m up looking along world +x (OpenCV axes: x right = world -y, y down = world -z).
K = CameraIntrinsics(500.0, 500.0, 320.0, 240.0, 640, 480, "file")
CAMERA = Camera(K, pose(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]), [0.0, 0.0, 1.2]))
EDGE_Y = -319.0 / 500.0  # the right frustum plane's world y per metre of x


def _dresser(seen_width_m: float = 0.42, depth_m: float = 0.45, height_m: float = 0.9, short_m: float = 0.0) -> BoxFit:
    """The seen part of a dresser 3 m in front of the camera, its front facing it, its right
    end the right frustum plane at its front (y = 3 EDGE_Y), or ``short_m`` inside the view."""
    y_cut = 3.0 * EDGE_Y + short_m
    centre = np.array([3.0 + depth_m / 2, y_cut + seen_width_m / 2, 0.0])
    rot = np.array([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])  # box +x toward the camera, +y = world -y
    return BoxFit(pose(rot, centre), np.array([depth_m, seen_width_m, height_m]), True, depth_m)


def _mask(fit: BoxFit, camera: Camera = CAMERA) -> np.ndarray:
    """The box's front face's pixels in the photo."""
    d, w, h = fit.size_m
    ys, zs = np.meshgrid(np.linspace(-w / 2, w / 2, 60), np.linspace(0.0, h, 60))
    front = np.column_stack([np.full(ys.size, d / 2), ys.ravel(), zs.ravel()])
    world = transform_points(fit.world_from_box, front)
    px = K.project(transform_points(np.linalg.inv(camera.world_from_camera), world))
    mask = np.zeros((K.height_px, K.width_px), dtype=bool)
    u = np.clip(np.round(px[:, 0]).astype(int), 0, K.width_px - 1)
    v = np.clip(np.round(px[:, 1]).astype(int), 0, K.height_px - 1)
    mask[v, u] = True
    from scipy import ndimage

    return ndimage.binary_closing(mask, iterations=3) | mask


def _ends_y(fit: BoxFit) -> tuple[float, float]:
    y = transform_points(fit.world_from_box, np.array([[0.0, -fit.size_m[1] / 2, 0.0], [0.0, fit.size_m[1] / 2, 0.0]]))[:, 1]
    return float(y.min()), float(y.max())


def test_the_outward_normal_points_out_of_the_view():
    n = outward_normal(CAMERA, "right")
    assert n[1] < 0 and n[0] < 0  # right of the view is world -y; the plane leans forward
    assert outward_normal(CAMERA, "left")[1] > 0
    with pytest.raises(ValueError):
        outward_normal(CAMERA, "top")


def test_a_dresser_the_right_edge_cut_continues_past_it():
    fit = _dresser()
    mask = _mask(fit)
    assert mask[:, -3:].any() and not mask[:, :20].any()
    grown_fit, grown, side = width_out_of_view(fit, "cabinet", mask, CAMERA)
    assert side == "right"
    # to a cabinet's width at its height (0.8 m at 0.9 m), no more than twice what was seen
    assert grown_fit.size_m[1] == pytest.approx(0.8, abs=1e-6)
    assert grown == pytest.approx(0.8 - 0.42, abs=1e-6)
    # the seen end (world y max) stays; the new end lies outside the view
    _, seen_hi = _ends_y(fit)
    lo, hi = _ends_y(grown_fit)
    assert hi == pytest.approx(seen_hi, abs=1e-9)
    assert lo < 3.0 * EDGE_Y
    # depth and height unchanged
    assert grown_fit.size_m[0] == fit.size_m[0] and grown_fit.size_m[2] == fit.size_m[2]


def test_its_seen_end_leaves_the_view_and_it_grows_no_more_than_twice_what_was_seen():
    # seen as wide as a cabinet, its box ending 5 cm inside the view (the mask still reaches the
    # edge): it grows only until its front's end is out of view
    fit = _dresser(seen_width_m=0.75, short_m=0.05)
    assert width_out_of_view(fit, "cabinet", _mask(fit), CAMERA)[1] == pytest.approx(0.05, abs=1e-6)
    # 0.3 m seen of a cabinet 0.8 m wide: twice the seen width at most
    narrow = _dresser(seen_width_m=0.3)
    assert width_out_of_view(narrow, "cabinet", _mask(narrow), CAMERA)[0].size_m[1] == pytest.approx(0.6, abs=1e-6)


def test_an_end_the_photo_showed_at_its_bottom_does_not_grow():
    # A camera looking 25 degrees down leans the frustum's side plane: a shelf whose top corner
    # the right edge cut shows its bottom corner, its true end, inside the photo.
    tilt = np.radians(25.0)
    down = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(tilt), -np.sin(tilt)], [0.0, np.sin(tilt), np.cos(tilt)]])  # about camera x
    camera = Camera(K, pose(CAMERA.world_from_camera[:3, :3] @ down.T, [0.0, 0.0, 1.6]))
    n3 = outward_normal(camera, "right")
    c = camera.position_m
    h = 1.4
    # the end's top corner 2 cm past the side plane
    y_end = (0.02 - n3 @ (np.array([3.0, 0.0, h]) - c)) / n3[1]
    fit = BoxFit(pose(np.diag([-1.0, -1.0, 1.0]), [3.2, y_end + 0.4, 0.0]), np.array([0.4, 0.8, h]), True, 0.4)
    bottom = n3 @ (np.array([3.0, y_end, 0.0]) - c)
    assert bottom < -0.05  # the bottom corner in view
    mask = _mask(fit, camera)
    assert mask[:, -3:].any()
    assert width_out_of_view(fit, "shelf", mask, camera)[1] == 0.0


def test_a_wall_or_a_neighbour_beside_it_stops_it():
    fit = _dresser()
    wall = Plane(np.array([0.0, 1.0, 0.0]), 2.0, "wall", 1000)  # y = -2.0, facing the room
    walled, grown, _ = width_out_of_view(fit, "cabinet", _mask(fit), CAMERA, (wall,))
    assert _ends_y(walled)[0] == pytest.approx(-2.0, abs=1e-6)
    assert grown == pytest.approx(2.0 + 3.0 * EDGE_Y, abs=1e-6)
    rng = np.random.default_rng(0)
    neighbour = np.column_stack([rng.uniform(3.05, 3.4, 300), rng.uniform(-2.3, -2.1, 300), rng.uniform(0.1, 0.8, 300)])
    stopped, _, _ = width_out_of_view(fit, "cabinet", _mask(fit), CAMERA, (), [neighbour])
    assert -2.1 < _ends_y(stopped)[0] < -2.05


def test_what_no_edge_cut_small_things_and_whole_widths_stay_as_seen():
    fit = _dresser()
    mask = _mask(fit)
    whole = np.zeros_like(mask)
    whole[200:300, 300:400] = True
    assert width_out_of_view(fit, "cabinet", whole, CAMERA)[1] == 0.0
    assert width_out_of_view(fit, "mug", mask, CAMERA)[1] == 0.0  # not floor furniture
    assert width_out_of_view(fit, "object", mask, CAMERA)[1] == 0.0  # no category, no width to expect
    wide = _dresser(seen_width_m=0.75)  # already a cabinet's width, its end at the edge
    assert width_out_of_view(wide, "cabinet", _mask(wide), CAMERA)[1] == 0.0
