"""Frame conversions: quaternions, and an OpenCV camera reproduced by MuJoCo to sub-pixel accuracy."""

from __future__ import annotations

import numpy as np
import pytest

from scene_builder import frames
from scene_builder.model import CameraIntrinsics


def test_quaternion_round_trip():
    rng = np.random.default_rng(1)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q = q if q[0] >= 0 else -q
        assert np.allclose(frames.quat_wxyz_from_matrix(frames.matrix_from_quat_wxyz(q)), q, atol=1e-9)


def test_mujoco_camera_reproduces_opencv_projection():
    import mujoco

    k = CameraIntrinsics(518.86, 519.47, 325.58, 253.74, 640, 480)
    # Camera 1.2 m up, looking along +X, pitched down 10 degrees.
    pitch = np.radians(10)
    r_w_cv0 = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], float)
    r_pitch = np.array([[np.cos(pitch), 0, np.sin(pitch)], [0, 1, 0], [-np.sin(pitch), 0, np.cos(pitch)]])
    world_from_camera = frames.pose(r_pitch @ r_w_cv0, (0, 0, 1.2))
    target = np.array([3.0, 0.5, 0.4])
    cam = frames.mujoco_camera(world_from_camera, k)
    fmt = lambda v: " ".join(f"{x:.9g}" for x in v)  # noqa: E731
    xml = f"""<mujoco><visual><global offwidth="640" offheight="480"/></visual>
      <asset><material name="e" emission="1" rgba="1 0 0 1"/></asset>
      <worldbody><geom type="sphere" size="0.02" pos="{fmt(target)}" material="e"/>
      <camera name="c" pos="{fmt(cam['pos'])}" quat="{fmt(cam['quat'])}" resolution="{fmt(cam['resolution'])}"
        focalpixel="{fmt(cam['focalpixel'])}" principalpixel="{fmt(cam['principalpixel'])}" sensorsize="{fmt(cam['sensorsize'])}"/>
      </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with mujoco.Renderer(model, 480, 640) as r:
        r.update_scene(data, camera="c")
        img = r.render()
    ys, xs = np.nonzero(img[..., 0] > 150)
    p_cam = frames.transform_points(np.linalg.inv(world_from_camera), target[None])
    u, v = k.project(p_cam)[0]
    assert abs(xs.mean() - u) < 0.5 and abs(ys.mean() - v) < 0.5


def test_a_mask_filling_the_photos_bottom_corner_is_cut_by_its_bottom_edge_a_chairs_legs_are_not():
    h, w = 480, 640
    sideboard = np.zeros((h, w), bool)
    sideboard[230:475, 25:190] = True  # a segmenter stops a few pixels short of the edge
    assert frames.cut_by_photo_bottom(sideboard)
    # slambook frame 5's sideboard ends at row 461; its sensor's depth ends at row 471 (a flat
    # frame below it), which is the edge.
    sideboard[462:] = False
    assert not frames.cut_by_photo_bottom(sideboard)
    valid = np.zeros((h, w), bool)
    valid[40:472] = True
    assert frames.cut_by_photo_bottom(sideboard, valid)
    chair = np.zeros((h, w), bool)
    chair[100:400, 200:400] = True  # seat and back well above the edge ...
    for x in (205, 390):
        chair[400:480, x : x + 8] = True  # ... two legs standing on it
    assert not frames.cut_by_photo_bottom(chair)
    floating = np.zeros((h, w), bool)
    floating[100:300, 100:300] = True
    assert not frames.cut_by_photo_bottom(floating) and not frames.cut_by_photo_bottom(np.zeros((h, w), bool))
    valid[:] = True  # measured down to the last row: 18 px short, over 3 % of the height
    assert not frames.cut_by_photo_bottom(sideboard, valid)


def test_edge_reach_share_counts_the_lines_across_each_edge():
    """The share of a mask's columns (top, bottom) or rows (left, right) with a pixel within the
    band of that edge: the one measure behind cut_by_photo_bottom and
    perception.seen_extent.cut_by_side_edge."""
    m = np.zeros((10, 20), dtype=bool)
    m[5:10, 0:4] = True  # a block in the bottom-left corner, 4 columns, 5 rows
    m[2:4, 8:16] = True  # a bar above it, 8 columns, 2 rows
    assert frames.edge_reach_share(m, "bottom", 2) == pytest.approx(4 / 12)
    assert frames.edge_reach_share(m, "top", 3) == pytest.approx(8 / 12)
    assert frames.edge_reach_share(m, "left", 1) == pytest.approx(5 / 7)
    assert frames.edge_reach_share(m, "right", 4) == 0.0
    assert frames.edge_reach_share(m, "bottom", 2, edge_px=4) == pytest.approx(8 / 12)  # depth ends at row 4
    assert frames.edge_reach_share(np.zeros((4, 4), dtype=bool), "left", 2) == 0.0
    with pytest.raises(ValueError, match="edge"):
        frames.edge_reach_share(m, "middle", 2)
