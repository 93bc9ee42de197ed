"""Frame conversions shared by every stage (part of the data model; see scene_builder.model for
the frames themselves). Pure numpy, no heavy imports."""

from __future__ import annotations

import numpy as np

from scene_builder.model import CameraIntrinsics

# OpenCV camera axes (x right, y down, z forward) -> MuJoCo / OpenGL camera axes (x right, y up,
# looking along -z): flip y and z.
CV_FROM_GL = np.diag([1.0, -1.0, -1.0])


def pose(rotation: np.ndarray, translation_m) -> np.ndarray:
    """(4, 4) rigid transform from a (3, 3) rotation and a (3,) translation."""
    t = np.eye(4)
    t[:3, :3] = rotation
    t[:3, 3] = np.asarray(translation_m, dtype=np.float64)
    return t


def rot_z(yaw_rad: float) -> np.ndarray:
    """(3, 3) rotation about +Z by ``yaw_rad`` (counter-clockwise seen from above)."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def yaw_of(rotation: np.ndarray) -> float:
    """Yaw (rad) of a rotation's X axis projected on the floor plane."""
    return float(np.arctan2(rotation[1, 0], rotation[0, 0]))


def transform_points(a_from_b: np.ndarray, points_b: np.ndarray) -> np.ndarray:
    """Apply a (4, 4) transform to (N, 3) points."""
    p = np.asarray(points_b, dtype=np.float64)
    return p @ a_from_b[:3, :3].T + a_from_b[:3, 3]


def quat_wxyz_from_matrix(rotation: np.ndarray) -> np.ndarray:
    """(4,) unit quaternion (w, x, y, z), w >= 0, of a (3, 3) rotation matrix."""
    r = np.asarray(rotation, dtype=np.float64)
    tr = np.trace(r)
    if tr > 0:
        s = np.sqrt(tr + 1.0) * 2
        q = np.array([0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s])
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
        q = np.array([(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s])
    elif r[1, 1] > r[2, 2]:
        s = np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
        q = np.array([(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s])
    else:
        s = np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
        q = np.array([(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s])
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def matrix_from_quat_wxyz(q) -> np.ndarray:
    """(3, 3) rotation of a (w, x, y, z) quaternion (normalised first)."""
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def mujoco_camera(world_from_camera: np.ndarray, k: CameraIntrinsics) -> dict[str, object]:
    """Attributes of an MJCF ``<camera>`` that reproduces an OpenCV pinhole camera.

    Returns pos (3,), quat (w, x, y, z), resolution (W, H), focalpixel (fx, fy),
    principalpixel and sensorsize. Measured on MuJoCo 4.0: with these, a rendered point lands
    within 0.2 px of ``k.project``; MuJoCo's principalpixel is the offset of the image centre from
    the principal point, ((W - 1) / 2 - cx, (H - 1) / 2 - cy), the opposite sign of OpenCV's.
    """
    r_world_gl = world_from_camera[:3, :3] @ CV_FROM_GL
    return {
        "pos": world_from_camera[:3, 3].copy(),
        "quat": quat_wxyz_from_matrix(r_world_gl),
        "resolution": (k.width_px, k.height_px),
        "focalpixel": (k.fx_px, k.fy_px),
        "principalpixel": ((k.width_px - 1) / 2.0 - k.cx_px, (k.height_px - 1) / 2.0 - k.cy_px),
        "sensorsize": (float(k.width_px), float(k.height_px)),
    }


#: A mask reaching within this share of the photo's height of its last measured row on at least
#: :data:`BOTTOM_CUT_SHARE` of its columns was cut by the photo's bottom edge: what lies below it
#: was out of view (a sideboard whose top and upper front fill the photo's bottom corner). A
#: chair's legs standing on the edge are a small share of its columns. (Segmenters stop a few
#: pixels short of a photo's edge: slambook frame 5's sideboard mask ends 9 px above it.)
BOTTOM_CUT_ROWS_SHARE = 0.03
BOTTOM_CUT_SHARE = 0.3


def edge_reach_share(mask: np.ndarray, edge: str, band_px: int, edge_px: int | None = None) -> float:
    """The share of the (H, W) bool ``mask``'s lines across ``edge`` (its columns for "top" and
    "bottom", its rows for "left" and "right") that hold a pixel within ``band_px`` pixels of that
    edge of the photo (0 for an empty mask). edge_px: the edge's row or column where it is not the
    image's last or first (a sensor's depth that ends short of the photo's bottom)."""
    if edge not in ("top", "bottom", "left", "right"):
        raise ValueError(f"edge must be top, bottom, left or right, got {edge!r}")
    mask = np.asarray(mask, dtype=np.bool_)
    m = mask if edge in ("top", "bottom") else mask.T  # lines are columns of m
    lines = m.any(axis=0)
    if not lines.any():
        return 0.0
    far = edge in ("bottom", "right")
    at = (m.shape[0] - 1 if far else 0) if edge_px is None else int(edge_px)
    band = m[max(0, at - band_px + 1) : at + 1] if far else m[at : at + band_px]
    return float(band.any(axis=0).sum() / lines.sum())


def cut_by_photo_bottom(mask: np.ndarray, valid_depth: np.ndarray | None = None) -> bool:
    """Whether the (H, W) bool ``mask`` was cut by the photo's bottom edge (see
    :data:`BOTTOM_CUT_SHARE`). valid_depth: (H, W) bool pixels with measured depth; the bottom edge
    is its last row with any (a sensor's depth often ends short of the photo's), else row H - 1."""
    mask = np.asarray(mask, dtype=np.bool_)
    last = None
    if valid_depth is not None:
        rows_valid = np.flatnonzero(np.asarray(valid_depth, dtype=np.bool_).any(axis=1))
        last = int(rows_valid[-1]) if len(rows_valid) else None
    rows = max(2, int(round(BOTTOM_CUT_ROWS_SHARE * mask.shape[0])))
    return edge_reach_share(mask, "bottom", rows, last) >= BOTTOM_CUT_SHARE


#: A mask reaching within this share of the photo's width of its left or right edge on at least
#: :data:`SIDE_CUT_SHARE` of its rows was cut by that edge (a dresser at the photo's edge); one
#: reaching both edges fills the photo's width (a close-up framed on it), which is no cut.
SIDE_EDGE_SHARE = 0.03
SIDE_CUT_SHARE = 0.3
#: Only objects seen at least this tall are weighed as longer than seen when a side edge cut them
#: (perception.seen_extent); an object a side edge cut is taken to be at most LENGTH_FACTOR times
#: as long as seen, LENGTH_CAP_M at most (a bed's or a sofa's length): what is out of view is
#: taken to be no more than what is in it.
SIDEWAYS_MIN_HEIGHT_M = 0.3
LENGTH_FACTOR = 2.0
LENGTH_CAP_M = 2.5


def cut_side(mask: np.ndarray) -> str | None:
    """``"left"`` or ``"right"``: the one side edge of the photo that cut the (H, W) bool
    ``mask`` (see :data:`SIDE_CUT_SHARE`); None when neither or both did."""
    mask = np.asarray(mask, dtype=np.bool_)
    near = max(2, int(round(SIDE_EDGE_SHARE * mask.shape[1])))
    at_left = edge_reach_share(mask, "left", near) >= SIDE_CUT_SHARE
    at_right = edge_reach_share(mask, "right", near) >= SIDE_CUT_SHARE
    if at_left == at_right:
        return None
    return "left" if at_left else "right"
