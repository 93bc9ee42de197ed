"""A small analytic RGB-D observation for the twin tests: a camera 1.5 m up, pitched 15 degrees
down, looking at a floor (z = 0) and a wall (x = 3 m), with a red board 2 m in front of the
camera and (optionally) a table top seen as background. Depth and colours are exact, so the
tests can check the background mesh against them to float precision."""

from __future__ import annotations

import numpy as np

from scene_builder.frames import transform_points
from scene_builder.model import Camera, CameraIntrinsics, Observation, PerceivedObject, Plane

W, H, F = 160, 120, 120.0
CAMERA_HEIGHT_M = 1.5
PITCH_DEG = 15.0
WALL_X_M = 3.0
BOARD_DEPTH_M = 2.0
BOARD_ROWS, BOARD_COLS = slice(60, 100), slice(50, 110)


def camera() -> Camera:
    p = np.radians(PITCH_DEG)
    forward = np.array([np.cos(p), 0.0, -np.sin(p)])
    right = np.array([0.0, -1.0, 0.0])
    down = np.cross(forward, right)
    t = np.eye(4)
    t[:3, :3] = np.stack([right, down, forward], axis=1)
    t[:3, 3] = [0.0, 0.0, CAMERA_HEIGHT_M]
    return Camera(CameraIntrinsics(F, F, (W - 1) / 2.0, (H - 1) / 2.0, W, H, "flag"), t)


def wall() -> Plane:
    return Plane(np.array([-1.0, 0.0, 0.0]), WALL_X_M, "wall", 1000)


def rays_cam() -> np.ndarray:
    k = camera().intrinsics
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    return np.stack([(u - k.cx_px) / k.fx_px, (v - k.cy_px) / k.fy_px, np.ones_like(u)], axis=-1)


def room_depth() -> np.ndarray:
    """(H, W) planar depth of the floor and the wall alone."""
    cam = camera()
    d = rays_cam() @ cam.world_from_camera[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = np.where(d[..., 2] < 0, -CAMERA_HEIGHT_M / d[..., 2], np.inf)
        t_wall = np.where(d[..., 0] > 0, WALL_X_M / d[..., 0], np.inf)
    return np.minimum(t_floor, t_wall)


def observation() -> tuple[Observation, PerceivedObject]:
    """The photo (floor grey with a gradient, wall beige, board red) and its depth, and the
    board as the one perceived object."""
    cam = camera()
    depth = room_depth()
    rgb = np.zeros((H, W, 3), dtype=np.uint8)
    world = transform_points(cam.world_from_camera, (rays_cam() * depth[..., None]).reshape(-1, 3)).reshape(H, W, 3)
    on_wall = world[..., 0] > WALL_X_M - 1e-6
    rgb[on_wall] = (200, 190, 160)
    floor_shade = (90 + 60 * np.clip(world[..., 1] + 1.5, 0, 3) / 3).astype(np.uint8)
    rgb[~on_wall] = np.stack([floor_shade, floor_shade, floor_shade], axis=-1)[~on_wall]
    mask = np.zeros((H, W), dtype=bool)
    mask[BOARD_ROWS, BOARD_COLS] = True
    depth[mask] = BOARD_DEPTH_M
    rgb[mask] = (210, 30, 30)
    obs = Observation("synthetic.png", rgb, depth.astype(np.float32), cam.intrinsics, "sensor")
    pts = transform_points(cam.world_from_camera, (rays_cam() * depth[..., None])[mask])
    board = PerceivedObject(1, "board_1", "object", 0.5, mask, pts, rgb[mask])
    return obs, board
