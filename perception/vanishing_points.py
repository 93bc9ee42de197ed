"""Gravity, camera pitch and roll and the focal length of one photo from its vanishing points:
steps 1-3 of the single-view chain of :mod:`perception.single_view` (line segments, the Manhattan
frame, the camera), which that module's ``SingleViewDepth`` turns into metric depth. No learned
weights; scikit-image for edges and the Hough transform."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scene_builder.model import CameraIntrinsics

__all__ = [
    "SingleViewGeometry",
    "analysis_image",
    "detect_segments",
    "estimate_geometry",
    "focal_from_orthogonal_vps",
    "gravity_pitch_roll_deg",
    "manhattan_frame",
    "vanishing_point_ransac",
]


@dataclass(frozen=True, eq=False)
class SingleViewGeometry:
    """What the vanishing-point analysis found.

    gravity_cam: (3,) unit vector, the direction of gravity (down) in the OpenCV camera frame.
    pitch_deg: angle of the optical axis below the horizon (positive = looking down).
    roll_deg: rotation of the image about the optical axis (positive = clockwise horizon).
    focal_px: focal length used (estimated when ``focal_source == "vanishing-points"``).
    vertical_vp: (3,) homogeneous pixel coordinates of the vertical vanishing point, or None.
    horizontal_vp: (3,) homogeneous pixel coordinates of the strongest horizontal one, or None.
    horizon_v_px: row of the horizon at the principal point's column.
    segments: (N, 4) float64 line segments (u0, v0, u1, v1).
    """

    gravity_cam: np.ndarray
    pitch_deg: float
    roll_deg: float
    focal_px: float
    focal_source: str
    vertical_vp: np.ndarray | None
    horizontal_vp: np.ndarray | None
    horizon_v_px: float
    segments: np.ndarray


# --------------------------------------------------------------------------------------------
# Segments and vanishing points
# --------------------------------------------------------------------------------------------


def analysis_image(rgb: np.ndarray, max_side_px: int = 640) -> np.ndarray:
    """The (h, w, 3) uint8 image single-view analysis runs on: ``rgb`` downscaled (bilinear) so
    that its long side is at most ``max_side_px`` (unchanged when it already is)."""
    h, w = rgb.shape[:2]
    scale = min(1.0, max_side_px / max(h, w))
    if scale >= 1.0:
        return rgb
    from PIL import Image

    sw, sh = max(1, int(round(w * scale))), max(1, int(round(h * scale)))
    return np.asarray(Image.fromarray(rgb).resize((sw, sh), Image.Resampling.BILINEAR))


def detect_segments(rgb: np.ndarray, seed: int = 0, min_length_frac: float = 0.04) -> np.ndarray:
    """(N, 4) float64 line segments (u0, v0, u1, v1) of an (H, W, 3) uint8 image.

    Canny (sigma 2 px on a 480-px-high scale) then scikit-image's probabilistic Hough transform,
    seeded so the result is deterministic. Segments shorter than ``min_length_frac`` of the image
    diagonal are dropped.
    """
    from skimage.color import rgb2gray
    from skimage.feature import canny
    from skimage.transform import probabilistic_hough_line

    gray = rgb2gray(np.asarray(rgb))
    h, w = gray.shape
    scale = max(h, w) / 640.0
    edges = canny(gray, sigma=2.0 * scale)
    min_len = max(8, int(min_length_frac * np.hypot(h, w)))
    lines = probabilistic_hough_line(edges, threshold=10, line_length=min_len, line_gap=max(2, int(3 * scale)), rng=seed)
    if not lines:
        return np.zeros((0, 4), dtype=np.float64)
    segs = np.array([[p0[0], p0[1], p1[0], p1[1]] for p0, p1 in lines], dtype=np.float64)
    # Sort for determinism independent of the Hough transform's internal order.
    return segs[np.lexsort(segs.T[::-1])]


def _consistency_deg(segs: np.ndarray, vp: np.ndarray) -> np.ndarray:
    """(N,) angle in degrees between each segment and the line from its midpoint to the
    homogeneous point ``vp`` (finite or at infinity)."""
    mid = 0.5 * (segs[:, :2] + segs[:, 2:])
    d_seg = segs[:, 2:] - segs[:, :2]
    d_vp = vp[:2][None, :] - vp[2] * mid
    cross = np.abs(d_seg[:, 0] * d_vp[:, 1] - d_seg[:, 1] * d_vp[:, 0])
    dot = np.abs(np.sum(d_seg * d_vp, axis=1))
    return np.degrees(np.arctan2(cross, dot))


def _lines(segs: np.ndarray, norm: float) -> np.ndarray:
    """Homogeneous lines (N, 3) through the segments, in coordinates scaled by 1 / norm."""
    p0 = np.column_stack([segs[:, :2] / norm, np.ones(len(segs))])
    p1 = np.column_stack([segs[:, 2:] / norm, np.ones(len(segs))])
    ln = np.cross(p0, p1)
    return ln / np.linalg.norm(ln[:, :2], axis=1, keepdims=True)


def vanishing_point_ransac(
    segs: np.ndarray,
    norm: float,
    iterations: int = 400,
    inlier_deg: float = 2.0,
    seed: int = 0,
    accept=None,
) -> tuple[np.ndarray | None, np.ndarray]:
    """The vanishing point best supported by ``segs`` (N, 4), by length-weighted RANSAC.

    norm: coordinate scale (e.g. the image size) for numerically stable intersections.
    accept: optional callable(vp (3,) homogeneous pixel coords) -> bool to reject candidates.
    Returns (vp (3,) homogeneous in pixels, unit norm, or None; (N,) bool inliers). The winner is
    refined by least squares over its inliers (the null vector of their stacked lines).
    """
    n = len(segs)
    if n < 2:
        return None, np.zeros(n, dtype=np.bool_)
    rng = np.random.default_rng(seed)
    lengths = np.hypot(*(segs[:, 2:] - segs[:, :2]).T)
    lines = _lines(segs, norm)
    prob = lengths / lengths.sum()
    best_score, best_vp = -1.0, None
    to_px = np.diag([norm, norm, 1.0])
    for _ in range(iterations):
        i, j = rng.choice(n, size=2, replace=False, p=prob)
        vp = np.cross(lines[i], lines[j])
        if not np.any(vp):
            continue
        vp = to_px @ vp
        vp /= np.linalg.norm(vp)
        if accept is not None and not accept(vp):
            continue
        inl = _consistency_deg(segs, vp) < inlier_deg
        score = float(lengths[inl].sum())
        if score > best_score:
            best_score, best_vp = score, vp
    if best_vp is None:
        return None, np.zeros(n, dtype=np.bool_)
    inl = _consistency_deg(segs, best_vp) < inlier_deg
    if inl.sum() >= 2:
        a = lines[inl] * lengths[inl, None]
        _, _, vt = np.linalg.svd(a)
        refined = to_px @ vt[-1]
        refined /= np.linalg.norm(refined)
        if accept is None or accept(refined):
            r_inl = _consistency_deg(segs, refined) < inlier_deg
            if lengths[r_inl].sum() >= lengths[inl].sum():
                best_vp, inl = refined, r_inl
    return best_vp, inl


def _angles_to_vps(segs: np.ndarray, vps: np.ndarray) -> np.ndarray:
    """(M, N) angle in degrees between each of N segments (N, 4) and the line from its midpoint to
    each of M homogeneous points ``vps`` (M, 3) (finite or at infinity)."""
    mid = 0.5 * (segs[:, :2] + segs[:, 2:])
    d_seg = segs[:, 2:] - segs[:, :2]
    d_vp = vps[:, None, :2] - vps[:, None, 2:3] * mid[None]  # (M, N, 2)
    cross = np.abs(d_seg[None, :, 0] * d_vp[..., 1] - d_seg[None, :, 1] * d_vp[..., 0])
    dot = np.abs(d_seg[None, :, 0] * d_vp[..., 0] + d_seg[None, :, 1] * d_vp[..., 1])
    return np.degrees(np.arctan2(cross, dot))


def manhattan_frame(
    segs: np.ndarray, k: np.ndarray, g_hyps: np.ndarray, inlier_deg: float = 2.0, step_deg: float = 1.0
) -> tuple[np.ndarray, np.ndarray, float]:
    """The Manhattan frame (gravity and two horizontal directions) best supported by the segments.

    segs: (N, 4); k: (3, 3) intrinsics; g_hyps: (G, 3) unit gravity hypotheses in the camera frame.
    Each hypothesis is completed by every horizontal direction pair (d, g x d) at ``step_deg``
    steps, and scored by the length of the segments pointing at one of the three vanishing points
    (soft: weight 1 - angle / inlier_deg). Searching the three directions jointly (orthogonal by
    construction) keeps a few stray near-vertical lines from tilting gravity, which a vertical
    vanishing point found alone does. Returns (g (3,), d1 (3,), score).
    """
    lengths = np.hypot(*(segs[:, 2:] - segs[:, :2]).T)
    thetas = np.radians(np.arange(0.0, 90.0, step_deg))
    best = (g_hyps[0], np.array([1.0, 0.0, 0.0]), -1.0)
    for g in g_hyps:
        a = np.cross(g, [0.0, 0.0, 1.0]) if abs(g[2]) < 0.9 else np.cross(g, [1.0, 0.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(g, a)
        d1 = np.cos(thetas)[:, None] * a + np.sin(thetas)[:, None] * b  # (T, 3)
        d2 = np.cross(g, d1)
        ang_v = _angles_to_vps(segs, (k @ g)[None])[0]  # (N,)
        ang = np.minimum(_angles_to_vps(segs, d1 @ k.T), _angles_to_vps(segs, d2 @ k.T))  # (T, N)
        ang = np.minimum(ang, ang_v[None])
        score = (np.clip(1.0 - ang / inlier_deg, 0.0, None) * lengths[None]).sum(axis=1)
        t = int(np.argmax(score))
        if score[t] > best[2]:
            best = (g, d1[t], float(score[t]))
    return best

def focal_from_orthogonal_vps(v1: np.ndarray, v2: np.ndarray, cx: float, cy: float) -> float | None:
    """Focal length (px) from two vanishing points of orthogonal directions, both finite:
    f^2 = -(v1 - c) . (v2 - c). None when either is (near) infinite or the product is not negative."""
    if abs(v1[2]) < 1e-9 or abs(v2[2]) < 1e-9:
        return None
    p1 = v1[:2] / v1[2] - (cx, cy)
    p2 = v2[:2] / v2[2] - (cx, cy)
    f2 = -float(p1 @ p2)
    return float(np.sqrt(f2)) if f2 > 0 else None


def gravity_pitch_roll_deg(gravity_cam: np.ndarray) -> tuple[float, float]:
    """(pitch, roll) in degrees of a camera whose frame sees gravity along ``gravity_cam``.

    pitch > 0: looking down (the optical axis points below the horizon, so gravity has a positive
    z component in the camera frame). roll > 0: gravity leans towards -x in the image, i.e. the
    camera is rotated clockwise about its optical axis.
    """
    g = np.asarray(gravity_cam, dtype=np.float64)
    g = g / np.linalg.norm(g)
    pitch = float(np.degrees(np.arcsin(np.clip(g[2], -1.0, 1.0))))
    roll = float(np.degrees(np.arctan2(-g[0], g[1])))
    return pitch, roll


def _gravity_from_vp(vp: np.ndarray, fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """(3,) unit gravity (down, +y-ish) in the camera frame for a vertical vanishing point."""
    g = np.array([(vp[0] - cx * vp[2]) / fx, (vp[1] - cy * vp[2]) / fy, vp[2]])
    g /= np.linalg.norm(g)
    return -g if g[1] < 0 else g


def _joint_manhattan(segs, vert_vp, fx, fy, cx, cy, w, focal_source, estimate_focal, seed):
    """Gravity (and the focal length when ``estimate_focal``) from a joint search over Manhattan
    frames (:func:`manhattan_frame`).

    Vertical hypotheses: the RANSAC vertical vanishing point, the intersections of up to 120
    length-weighted pairs of near-vertical segments and a level camera; the 10 best supported by
    the near-vertical segments alone (in the image, so for any focal length) are searched jointly
    and the winner refined on a 0.5 deg pitch/roll grid. The focal length, when unknown: the
    field of view among 40-100 deg (5 deg steps) whose best frame scores highest after smoothing
    over neighbouring steps, when that beats the default field of view by 3 % (measured on the
    real samples with known intrinsics: within 5-10 deg of the truth). Returns (g, fx, fy, focal_source, vertical_vp, horizontal_vp).
    """
    d = segs[:, 2:] - segs[:, :2]
    lengths = np.hypot(d[:, 0], d[:, 1])
    near_vertical = np.degrees(np.arctan2(np.abs(d[:, 0]), np.abs(d[:, 1]))) < 20.0
    vps = [] if vert_vp is None else [np.asarray(vert_vp, dtype=np.float64)]
    idx = np.flatnonzero(near_vertical)
    if len(idx) >= 2:
        rng = np.random.default_rng(seed)
        lines = _lines(segs[idx], float(w))
        p = lengths[idx] / lengths[idx].sum()
        for _ in range(120):
            i, j = rng.choice(len(idx), size=2, replace=False, p=p)
            vp = np.diag([w, w, 1.0]) @ np.cross(lines[i], lines[j])
            if np.any(vp):
                vps.append(vp / np.linalg.norm(vp))
    vps_arr = np.array(vps) if vps else np.zeros((0, 3))
    if len(idx) and len(vps_arr):
        support = (np.clip(1.0 - _angles_to_vps(segs[idx], vps_arr) / 2.0, 0.0, None) * lengths[idx][None]).sum(axis=1)
        vps_arr = vps_arr[np.argsort(-support, kind="stable")[:10]]
    vps_arr = np.concatenate([vps_arr, [[0.0, 1.0, 0.0]]])  # a level camera

    def kmat(f: float) -> np.ndarray:
        return np.array([[f, 0.0, cx], [0.0, f * fy / fx, cy], [0.0, 0.0, 1.0]])

    def hyps(f: float) -> np.ndarray:
        gs = np.array([_gravity_from_vp(vp, f, f * fy / fx, cx, cy) for vp in vps_arr])
        return gs[gs[:, 1] > np.cos(np.radians(35.0))]

    if estimate_focal:
        fovs = np.arange(40.0, 101.0, 5.0)
        focals = (w / 2.0) / np.tan(np.radians(fovs) / 2.0)
        scores = np.array([manhattan_frame(segs, kmat(f), hyps(f), step_deg=2.0)[2] for f in focals])
        smooth = np.convolve(np.pad(scores, 1, mode="edge"), [0.25, 0.5, 0.25], mode="valid")
        default = float(np.interp(fx, focals[::-1], smooth[::-1]))
        if smooth.max() > 1.03 * default:  # a flat curve (no perspective: a close-up) keeps the default
            f_best = float(focals[int(np.argmax(smooth))])
            fy, fx, focal_source = f_best, f_best, "vanishing-points"
    g, _, _ = manhattan_frame(segs, kmat(fx), hyps(fx), step_deg=2.0)
    # refine: a 0.5 deg grid of pitch and roll around the winner
    pitch, roll = np.radians(gravity_pitch_roll_deg(g))
    grid = np.radians(np.arange(-2.0, 2.01, 0.5))
    fine = [[-np.sin(roll + dr) * np.cos(pitch + dp), np.cos(roll + dr) * np.cos(pitch + dp), np.sin(pitch + dp)] for dp in grid for dr in grid]
    g, d1, _ = manhattan_frame(segs, kmat(fx), np.array(fine), step_deg=1.0)
    k = kmat(fx)
    return g, fx, fy, focal_source, k @ g, k @ d1

def estimate_geometry(
    rgb: np.ndarray,
    intrinsics: CameraIntrinsics | None,
    default_fov_deg: float = 60.0,
    seed: int = 0,
) -> SingleViewGeometry:
    """Gravity, pitch/roll and focal length of one photo from its vanishing points.

    intrinsics: used as given when not None; else the focal length comes from two orthogonal
    finite vanishing points when they exist (and give a horizontal field of view in 30..110 deg),
    else from ``default_fov_deg``. Falls back to a level camera when no vertical vanishing point
    is found.
    """
    h, w = rgb.shape[:2]
    if intrinsics is not None:
        fx, fy, cx, cy = intrinsics.fx_px, intrinsics.fy_px, intrinsics.cx_px, intrinsics.cy_px
        focal_source = intrinsics.source
    else:
        fx = fy = (w / 2.0) / np.tan(np.radians(default_fov_deg) / 2.0)
        cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
        focal_source = "default-fov"
    segs = detect_segments(rgb, seed=seed)
    norm = float(max(h, w))
    vert_vp = horiz_vp = None
    if len(segs):
        d = segs[:, 2:] - segs[:, :2]
        ang_from_vertical = np.degrees(np.arctan2(np.abs(d[:, 0]), np.abs(d[:, 1])))
        near_vertical = ang_from_vertical < 20.0

        def is_vertical(vp: np.ndarray) -> bool:
            # Direction within 35 deg of the image's vertical axis (camera roughly upright).
            ray = np.array([(vp[0] - cx * vp[2]) / fx, (vp[1] - cy * vp[2]) / fy, vp[2]])
            return abs(ray[1]) / max(np.linalg.norm(ray), 1e-12) > np.cos(np.radians(35.0))

        if near_vertical.sum() >= 2:
            vert_vp, _ = vanishing_point_ransac(segs[near_vertical], norm, seed=seed, accept=is_vertical)
        if vert_vp is not None:
            rest = ~near_vertical & (_consistency_deg(segs, vert_vp) > 4.0)
        else:
            rest = ~near_vertical

        def is_horizontal(vp: np.ndarray) -> bool:
            ray = np.array([(vp[0] - cx * vp[2]) / fx, (vp[1] - cy * vp[2]) / fy, vp[2]])
            return abs(ray[1]) / max(np.linalg.norm(ray), 1e-12) < np.sin(np.radians(30.0))

        if rest.sum() >= 2:
            horiz_vp, _ = vanishing_point_ransac(segs[rest], norm, seed=seed + 1, accept=is_horizontal)
    g = None
    if len(segs) >= 4:
        g, fx, fy, focal_source, vert_vp, horiz_vp = _joint_manhattan(segs, vert_vp, fx, fy, cx, cy, w, focal_source, intrinsics is None, seed)
    if g is None:
        g = np.array([0.0, 1.0, 0.0])
    pitch, roll = gravity_pitch_roll_deg(g)
    # Horizon: image points whose ray is orthogonal to gravity; row at column cx.
    # g . [(u - cx)/fx, (v - cy)/fy, 1] = 0 at u = cx  ->  v = cy - fy * g_z / g_y.
    horizon_v = float(cy - fy * g[2] / g[1])
    return SingleViewGeometry(
        gravity_cam=g,
        pitch_deg=pitch,
        roll_deg=roll,
        focal_px=float(fx),
        focal_source=focal_source,
        vertical_vp=vert_vp,
        horizontal_vp=horiz_vp,
        horizon_v_px=horizon_v,
        segments=segs,
    )
