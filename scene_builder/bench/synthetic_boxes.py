"""Synthetic perceptions for tests and the generation benchmark: boxes on the floor seen by a
camera, observed only on their faces that point toward it (the half an object a photo shows).

Points are sampled uniformly (seeded) on each visible face of each box, with optional Gaussian
depth noise; the image is a small blank placeholder (generation uses points, not pixels).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scene_builder.frames import pose, rot_z, transform_points
from scene_builder.model import Camera, CameraIntrinsics, Observation, PerceivedObject, Perception, Room

__all__ = ["SyntheticBox", "look_at", "visible_box_points", "synthetic_perception"]


@dataclass(frozen=True)
class SyntheticBox:
    """A box object: label, size (x depth, y width, z height) in its own frame, yaw (rad) and the
    world position of its bottom centre, colour."""

    label: str
    size_m: tuple[float, float, float]
    yaw_rad: float
    position_m: tuple[float, float, float]
    rgb: tuple[int, int, int] = (180, 120, 60)

    @property
    def world_from_box(self) -> np.ndarray:
        return pose(rot_z(self.yaw_rad), self.position_m)


def look_at(eye_m, target_m) -> np.ndarray:
    """(4, 4) world_from_camera of an OpenCV camera at ``eye_m`` looking at ``target_m`` (Z up)."""
    eye = np.asarray(eye_m, dtype=np.float64)
    z = np.asarray(target_m, dtype=np.float64) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return pose(np.stack([x, y, z], axis=1), eye)


def visible_box_points(box: SyntheticBox, camera_m, density_per_m2: float, rng: np.random.Generator,
                       noise_m: float = 0.0) -> np.ndarray:
    """(N, 3) world points on the faces of ``box`` whose outward normal points toward the camera
    (the bottom face is never seen)."""
    size = np.asarray(box.size_m, dtype=np.float64)
    t = box.world_from_box
    cam_box = transform_points(np.linalg.inv(t), np.asarray(camera_m, dtype=np.float64)[None])[0]
    centre = np.array([0.0, 0.0, size[2] / 2])
    out = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            if axis == 2 and sign < 0:
                continue
            face_c = centre.copy()
            face_c[axis] += sign * size[axis] / 2
            normal = np.zeros(3)
            normal[axis] = sign
            if float(normal @ (cam_box - face_c)) <= 0:
                continue
            others = [a for a in range(3) if a != axis]
            area = size[others[0]] * size[others[1]]
            n = max(int(density_per_m2 * area), 20)
            p = np.tile(face_c, (n, 1))
            for a in others:
                p[:, a] += rng.uniform(-size[a] / 2, size[a] / 2, n)
            p[:, axis] += rng.normal(0.0, noise_m, n) if noise_m > 0 else 0.0
            out.append(p)
    return transform_points(t, np.vstack(out))


def synthetic_perception(boxes: list[SyntheticBox], camera_m=(3.0, 1.0, 1.5), target_m=(0.0, 0.0, 0.4),
                         density_per_m2: float = 4000.0, noise_m: float = 0.0, seed: int = 0) -> Perception:
    """A :class:`Perception` of ``boxes`` seen from ``camera_m``: one object per box named
    ``<label>_<i>``, points on its visible faces."""
    rng = np.random.default_rng(seed)
    k = CameraIntrinsics.from_fov(64, 48, 60.0)
    rgb = np.zeros((48, 64, 3), dtype=np.uint8)
    obs = Observation("synthetic.png", rgb, np.zeros((48, 64), dtype=np.float32), k, "synthetic")
    camera = Camera(k, look_at(camera_m, target_m))
    camera_from_world = np.linalg.inv(camera.world_from_camera)
    objects = []
    for i, b in enumerate(boxes):
        pts = visible_box_points(b, camera_m, density_per_m2, rng, noise_m)
        # the mask: the pixels its points project to (what a segmenter would have outlined)
        cam = transform_points(camera_from_world, pts)
        px = np.round(k.project(cam[cam[:, 2] > 1e-6])).astype(np.int64)
        px = px[(px[:, 0] >= 0) & (px[:, 0] < 64) & (px[:, 1] >= 0) & (px[:, 1] < 48)]
        mask = np.zeros((48, 64), dtype=bool)
        mask[px[:, 1], px[:, 0]] = True
        cols = np.tile(np.array(b.rgb, dtype=np.uint8), (len(pts), 1))
        objects.append(PerceivedObject(i + 1, f"{b.label}_{i}", b.label, 0.9, mask, pts, cols))
    return Perception(obs, camera, Room(), tuple(objects))
