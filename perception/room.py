"""Gravity, floor, walls and ceiling from a depth map: the world frame of the scene.

Planes are peeled off a seeded subsample of the point cloud by RANSAC (:func:`ransac_plane`).
The ones whose normal lies within :data:`FLOOR_MAX_TILT_DEG` of the camera's image-up direction
(-y of the OpenCV camera) propose an up direction; the one most other planes are parallel or
perpendicular to wins (rooms are Manhattan), so a sloppy patch of floor cannot tilt the world.
The floor is the lowest horizontal layer of points that spreads in two directions; it is refined
by a tight RANSAC and least squares on all of its inliers, and up is its normal. Vertical planes
at least a metre wide that reach past head height and have little seen behind them are walls (a
doorway's view of the next room does not count); a horizontal plane above the camera is the
ceiling.

The world frame (see :mod:`scene_builder.model`): Z up, floor ``z = 0``, the camera above the
origin, X the horizontal projection of the optical axis, snapped to the nearest dominant wall
direction when walls were found (Manhattan frame).

Without a visible floor (a close-up of a cabinet), gravity comes from the photo's vertical
vanishing point (estimated depth), two non-parallel vertical planes when there are, else from the
camera's -y axis tilted by a typical :data:`TYPICAL_PITCH_DEG` downward pitch; the floor then goes
under everything seen and at least a typical camera height :data:`CAMERA_HEIGHT_PRIOR_M` under the
camera (:func:`place_floor_under` lowers it further under an object point below it). The choices
are recorded in ``RoomFrame.gravity`` and ``RoomFrame.floor``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from scene_builder.frames import pose
from scene_builder.model import BackendUse, Plane, Room

__all__ = [
    "CAMERA_HEIGHT_PRIOR_M",
    "FLOOR_MAX_TILT_DEG",
    "TYPICAL_PITCH_DEG",
    "CameraPlane",
    "RoomFrame",
    "ceiling_plane",
    "completion_planes",
    "estimate_room",
    "grid_normals",
    "open3d_normals",
    "vertical_plane_candidates",
    "inlier_threshold_m",
    "place_floor_under",
    "world_from_camera_for",
]

#: A floor candidate's normal lies within this angle of the camera's image-up direction.
FLOOR_MAX_TILT_DEG = 30.0
#: A wall's normal is perpendicular to up within this angle.
WALL_MAX_TILT_DEG = 6.0
#: A wall's inliers span at least this wide and reach at least this high above the floor.
WALL_MIN_WIDTH_M = 1.0
WALL_MIN_TOP_M = 1.5
#: Downward pitch assumed when nothing in the image tells where gravity points.
TYPICAL_PITCH_DEG = 10.0
#: Height of the camera above a floor it does not see, unless something seen lies lower: the
#: median of the 17 RGB-D frames with a floor in ../shared/data (0.99-1.67 m, median 1.27 m).
CAMERA_HEIGHT_PRIOR_M = 1.3
#: Surface normals for wall candidates (open3d's, what builds use: voxel size, neighbourhood
#: radius; grid_normals, the measured alternative: window and stride in pixels); a wall point's
#: normal lies within WALL_NORMAL_TILT_DEG of horizontal and of its wall's normal.
NORMAL_VOXEL_M = 0.03
NORMAL_RADIUS_M = 0.1
NORMAL_WINDOW_PX = 7
NORMAL_STRIDE_PX = 2
WALL_NORMAL_TILT_DEG = 12.0
CANDIDATE_SHARE = 0.2
#: A vertical plane parallel to a wall found and this close to it is the same wall (a curtain
#: hung in front of it, the wall's skirting) and is not added again.
WALL_MERGE_M = 0.5
#: A wall seen in part (narrower than WALL_MIN_WIDTH_M, or fewer than _MIN_PLANE_FRACTION of the
#: points: the side wall beside the camera, seen edge-on) that passes the other wall tests is a
#: "partial-wall": it completes the room's surface (perception.background) but is no collision
#: wall, does not leave objects out behind it and its pixels stay open to the segmenter.
PARTIAL_WALL_MIN_WIDTH_M = 0.5
PARTIAL_WALL_MIN_FRACTION = 0.01
#: Rooms are Manhattan: a wall whose normal lies within this angle of the room's axes (the X
#: axis is the best-supported wall's normal) is turned onto that axis about its inliers.
MANHATTAN_SNAP_DEG = 12.0
#: Points sampled for RANSAC (seeded); planes are refined on all points afterwards.
RANSAC_SAMPLES = 10_000
_RANSAC_THRESHOLD_M = 0.025
_MAX_PLANES = 8
#: A plane must hold this fraction of the sampled points to count (floor, wall, ceiling).
_MIN_PLANE_FRACTION = 0.03
#: Wall candidates take the offsets of points up to this depth as uncertain by their depth noise
#: (:func:`_offset_support`); farther ones count in their 2 cm bin only (sigma 5 cm at 6 m).
FAR_WALL_MAX_M = 6.0


def inlier_threshold_m(depth_m: np.ndarray) -> np.ndarray:
    """Distance within which a point at planar depth ``depth_m`` counts as on a plane.

    1 cm plus 2.5 sigma of the structured-light depth noise model sigma = 1.425e-3 z^2 m
    (Khoshelham and Elberink 2012): 2 cm at 1.5 m, 4.2 cm at 3 m, 9.9 cm at 5 m.
    """
    z = np.asarray(depth_m, dtype=np.float64)
    return 0.01 + 2.5 * 1.425e-3 * z * z


@dataclass(frozen=True, eq=False)
class CameraPlane:
    """A plane ``normal . p + offset_m = 0`` in the camera frame, normal towards the camera
    (so ``offset_m`` > 0 is the camera's distance to it). inliers: (H, W) bool. span_m: for a
    wall, its known ends along up x normal (``Plane.span_m``; the same in the world frame, whose
    origin is under the camera), set by :func:`_with_span`."""

    normal: np.ndarray
    offset_m: float
    kind: str
    inliers: np.ndarray
    span_m: tuple[float | None, float | None] | None = None


@dataclass(frozen=True, eq=False)
class RoomFrame:
    """The gravity-aligned world frame and the room's planes.

    world_from_camera: (4, 4) float64 rigid transform; the camera is at (0, 0, height).
    up_cam: (3,) unit up vector in the camera frame.
    room: walls in the world frame, normals into the room.
    background: (H, W) bool, pixels explained by the floor, walls or ceiling (or below the floor).
    floor_found: False when gravity and the floor height come from a fallback.
    gravity: how up was found (recorded in ``Perception.backends``).
    planes: the floor, walls, partial walls and ceiling in the camera frame.
    floor: how the floor's height was found (recorded in ``Perception.backends``).
    """

    world_from_camera: np.ndarray
    up_cam: np.ndarray
    room: Room
    background: np.ndarray
    floor_found: bool
    gravity: BackendUse
    planes: tuple[CameraPlane, ...] = ()
    floor: BackendUse | None = None

    @property
    def camera_height_m(self) -> float:
        return float(self.world_from_camera[2, 3])

    @property
    def tilt_deg(self) -> float:
        """Angle between the camera's image-up direction (-y) and true up, degrees."""
        return float(np.degrees(np.arccos(np.clip(-self.up_cam[1], -1.0, 1.0))))

    @property
    def floor_mask(self) -> np.ndarray:
        """(H, W) bool inliers of the floor plane (all False without a floor)."""
        for p in self.planes:
            if p.kind == "floor":
                return p.inliers
        return np.zeros_like(self.background)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _fit_plane(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane through (N, 3) points: unit normal and offset (n . p + d = 0)."""
    c = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - c, full_matrices=False)
    n = vt[2]
    return n, float(-n @ c)


def _towards_camera(n: np.ndarray, d: float) -> tuple[np.ndarray, float]:
    return (n, d) if d >= 0 else (-n, -d)


def ransac_plane(points: np.ndarray, threshold_m: float, iterations: int, rng: np.random.Generator) -> tuple[np.ndarray, float, np.ndarray]:
    """Best plane through (N, 3) points by RANSAC, refit by least squares on its inliers.

    Returns the unit normal, the offset (n . p + d = 0) and the (N,) bool inlier mask.
    Written here rather than open3d's ``segment_plane``: that one draws its samples from one
    generator shared by its OpenMP threads, and gave different planes for the same input and
    seed on this 2-core machine under load (the project needs deterministic output); this
    vectorised version is also about 3x faster at these sizes.
    """
    n = len(points)
    triples = rng.integers(0, n, size=(iterations, 3))
    a, b, c = points[triples[:, 0]], points[triples[:, 1]], points[triples[:, 2]]
    normals = np.cross(b - a, c - a)
    norms = np.linalg.norm(normals, axis=1)
    ok = norms > 1e-12
    if not ok.any():  # every sampled triple collinear (points along a line): least squares
        nrm, off = _fit_plane(points)
        return nrm, off, np.abs(points @ nrm + off) < threshold_m
    normals, offsets = normals[ok] / norms[ok, None], -np.einsum("ij,ij->i", normals[ok] / norms[ok, None], a[ok])
    # Hypotheses are scored on a fixed subset of at most 2000 points (the inlier fraction is
    # estimated to about 1 %, plenty to rank planes), the winner on all points.
    probe = points[:: max(1, n // 2000)]
    counts = (np.abs(probe @ normals.T + offsets) < threshold_m).sum(axis=0)
    best = int(np.argmax(counts))
    inliers = np.abs(points @ normals[best] + offsets[best]) < threshold_m
    nrm, off = _fit_plane(points[inliers])
    return nrm, off, np.abs(points @ nrm + off) < threshold_m


def _ransac_planes(points: np.ndarray, seed: int) -> list[tuple[np.ndarray, float, int]]:
    """Peel planes off (N, 3) points with RANSAC; returns (normal, offset, inlier count), normals
    towards the camera."""
    rng = np.random.default_rng(seed)
    remaining = points
    min_inliers = max(200, int(_MIN_PLANE_FRACTION * len(points)))
    planes = []
    for _ in range(_MAX_PLANES):
        if len(remaining) < min_inliers:
            break
        n, d, inliers = ransac_plane(remaining, _RANSAC_THRESHOLD_M, 300, rng)
        if inliers.sum() < min_inliers:
            break
        n, d = _towards_camera(n, d)
        planes.append((n, d, int(inliers.sum())))
        remaining = remaining[~inliers]
    return planes


def _refine(
    points: np.ndarray, thr: np.ndarray, n: np.ndarray, d: float, seed: int, iterations: int = 3
) -> tuple[np.ndarray, float, np.ndarray]:
    """Refit a RANSAC plane on all (N, 3) points; returns normal, offset and the inlier mask
    (within ``thr``, (N,) metres).

    A RANSAC plane from a subsample at a loose threshold can be a few degrees off on a small
    patch (a strip of carpet at the bottom of the photo), so first a tight RANSAC runs on the
    points within 8 cm of it, then least squares on its inliers (capped at 3 cm so that far,
    noisy points and the feet of furniture do not tilt the fit).
    """
    near = np.flatnonzero(np.abs(points @ n + d) < 0.08)
    if len(near) >= 3:
        rng = np.random.default_rng(seed)
        if len(near) > 8_000:
            near = near[np.sort(rng.choice(len(near), 8_000, replace=False))]
        n_new, d_new, _ = ransac_plane(points[near], 0.012, 200, rng)
        if n_new @ n < 0:
            n_new, d_new = -n_new, -d_new
        n, d = n_new, d_new
    fit_thr = np.minimum(thr, 0.03)
    for _ in range(iterations):
        inl = np.abs(points @ n + d) < fit_thr
        if inl.sum() < 3:
            break
        n_new, d_new = _fit_plane(points[inl])
        if n_new @ n < 0:
            n_new, d_new = -n_new, -d_new
        n, d = n_new, d_new
    return n, d, np.abs(points @ n + d) < thr


def grid_normals(points_cam: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Surface normals of an organised point cloud: ((N, 3) points, (N, 3) unit normals towards
    the camera) on every NORMAL_STRIDE_PX-th pixel, from the points averaged over
    NORMAL_WINDOW_PX windows (depth noise) and differenced across the window.

    The alternative to open3d's ``estimate_normals`` (the depth map is a grid, so the neighbours
    are known without a KD-tree), measured against it by ``python -m scene_builder.bench.room_planes``
    on the 17 RGB-D frames of ../shared/data (2 loaded cores): median 0.12 s against 0.58 s, and
    no open3d import (2.7 s); but the same walls on only 11 of 17 frames, and it misses the far
    right walls of multiview frames 3 and 5 that open3d's normals find (a 7-pixel window is a few
    cm on a far wall: too noisy). So builds use open3d's (:func:`open3d_normals`)."""
    import cv2

    p = np.where(valid[..., None], points_cam, 0.0).astype(np.float32)
    wgt = valid.astype(np.float32)
    k = NORMAL_WINDOW_PX
    cnt = cv2.boxFilter(wgt, -1, (k, k), normalize=False)
    mean = np.stack([cv2.boxFilter(p[..., i], -1, (k, k), normalize=False) for i in range(3)], axis=-1) / np.maximum(cnt[..., None], 1e-6)
    full = cnt >= 0.8 * k * k
    r = k // 2
    s = NORMAL_STRIDE_PX
    h, w = valid.shape
    rows, cols = np.arange(r, h - r, s), np.arange(r, w - r, s)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    up_, dn = np.clip(rr - r, 0, h - 1), np.clip(rr + r, 0, h - 1)
    lf, rt = np.clip(cc - r, 0, w - 1), np.clip(cc + r, 0, w - 1)
    ok = full[rr, cc] & full[up_, cc] & full[dn, cc] & full[rr, lf] & full[rr, rt] & valid[rr, cc]
    n = np.cross(mean[rr, rt] - mean[rr, lf], mean[dn, cc] - mean[up_, cc]).astype(np.float64)
    norm = np.linalg.norm(n, axis=-1)
    ok &= norm > 1e-12
    pts, n = mean[rr, cc][ok].astype(np.float64), n[ok] / norm[ok, None]
    n = np.where(((n * pts).sum(axis=1) > 0)[:, None], -n, n)  # towards the camera
    return pts, n


def open3d_normals(points_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((N, 3) points, (N, 3) normals towards the camera) by open3d on a NORMAL_VOXEL_M voxel
    grid (``estimate_normals``, NORMAL_RADIUS_M): what builds use for the wall candidates."""
    import open3d as o3d

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)))
    pc = pc.voxel_down_sample(NORMAL_VOXEL_M)
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=NORMAL_RADIUS_M, max_nn=30))
    pc.orient_normals_towards_camera_location(np.zeros(3))
    return np.asarray(pc.points), np.asarray(pc.normals)


def vertical_plane_candidates(q: np.ndarray, nrm: np.ndarray, up: np.ndarray, min_points: int, scale: float) -> list[tuple[np.ndarray, float, int]]:
    """Vertical planes (normal, offset, support) in the camera frame, normals towards the camera,
    from (N, 3) points ``q`` and their surface normals ``nrm`` (each standing for ``scale``
    points of the cloud): the directions where many horizontal normals agree (peaks of their
    azimuths), then, along each, the offsets where many of those points lie (peaks of a 2 cm
    histogram). RANSAC on a random subsample misses a wall seen edge-on or far away (few points,
    spread by depth noise); the normals of its points still agree."""
    if len(q) == 0:
        return []
    horizontal = np.abs(nrm @ up) < np.sin(np.radians(WALL_NORMAL_TILT_DEG))
    if horizontal.sum() < 3:
        return []
    a = _unit(np.cross(up, [1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.cross(up, [0.0, 0.0, 1.0]))
    b = np.cross(up, a)
    az = np.degrees(np.arctan2(nrm[horizontal] @ b, nrm[horizontal] @ a)) % 360.0
    hist = np.bincount(np.floor(az).astype(np.int64) % 360, minlength=360).astype(np.float64)
    smooth = np.convolve(np.concatenate([hist[-4:], hist, hist[:4]]), np.ones(9), mode="valid")
    out = []
    # Candidates only: the caller counts the plane's inliers among all points (within the depth
    # noise, which spreads a far wall over many 2 cm bins) and decides.
    min_voxels = CANDIDATE_SHARE * min_points / scale
    for k in np.argsort(-smooth):
        if smooth[k] < min_voxels:
            break
        if smooth[k] < smooth[(k - 1) % 360] or smooth[k] < smooth[(k + 1) % 360]:
            continue
        ang = np.radians(k + 0.5)
        d = np.cos(ang) * a + np.sin(ang) * b
        sel = horizontal & (nrm @ d > np.cos(np.radians(WALL_NORMAL_TILT_DEG)))
        if sel.sum() < min_voxels:
            continue
        d = _unit(nrm[sel].sum(axis=0) - (nrm[sel].sum(axis=0) @ up) * up)
        off = -(q[sel] @ d)  # plane d . p + off = 0; off > 0: the camera is on the normal's side
        bins = np.arange(off.min() - 0.02, off.max() + 0.04, 0.02)
        hs, edges = _offset_support(off, q[sel, 2], bins)
        for i in np.argsort(-hs):
            if hs[i] < min_voxels:
                break
            if (i > 0 and hs[i - 1] > hs[i]) or (i + 1 < len(hs) and hs[i + 1] > hs[i]):
                continue
            o = float(0.5 * (edges[i] + edges[i + 1]))
            if o > 0:
                out.append((d, o, int(hs[i] * scale)))
    return out


def _offset_support(off: np.ndarray, z_m: np.ndarray, bins: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Support of each 2 cm offset bin: how many of the points with offsets ``off`` ((N,) m, at
    depths ``z_m``) may lie in it, and the bin edges.

    A near point counts in its bin and half in each neighbour. A far point's offset is uncertain
    by its depth noise (sigma = 1.425e-3 z^2, as :func:`inlier_threshold_m`): it counts in every
    bin within 2 sigma. Kinect depth at 5.5 m comes in 9 cm steps, so a far wall's points fill
    ten bins and no single 2 cm bin held enough of them (the dining room of
    ../shared/data/multiview, frame 5: the wall behind the dresser was never a candidate, and the
    detector's "wardrobe" box took it).
    """
    reach = np.floor(2.0 * 1.425e-3 * z_m * z_m / float(bins[1] - bins[0])).astype(np.int64)  # bins either side
    # (Beyond FAR_WALL_MAX_M the noise is so wide that a plane at any angle through a far patch
    # gathers inliers: frame 1 of the dining room, 8 m from its back wall, found three "walls"
    # there at 30 deg to each other.)
    far = (reach > 1) & (z_m <= FAR_WALL_MAX_M)
    h, edges = np.histogram(off[~far], bins=bins)
    hs = np.convolve(h, [1, 2, 1], mode="same") / 2.0
    if far.any():
        n = len(hs)
        i = np.clip(np.searchsorted(bins, off[far], side="right") - 1, 0, n - 1)
        diff = np.zeros(n + 1)
        np.add.at(diff, np.clip(i - reach[far], 0, n), 1.0)
        np.add.at(diff, np.clip(i + reach[far] + 1, 0, n), -1.0)
        hs = hs + np.cumsum(diff)[:-1]
    return hs, edges


def _manhattan_up(planes: list[tuple[np.ndarray, float, int]], image_up: np.ndarray, cos_max: float) -> np.ndarray | None:
    """Up from the near-horizontal RANSAC plane that most of the other planes agree with.

    Each near-horizontal plane's normal is a hypothesis; it scores the inliers of every plane
    parallel or perpendicular to it within 6 degrees (rooms are Manhattan: floors, table tops,
    beds and the ceiling are parallel, walls and cabinet fronts perpendicular). A small, sloppy
    floor patch that disagrees with the walls then loses to a bed top that agrees.
    """
    hyps = []
    for n, _, count in planes:
        c = float(n @ image_up)
        if abs(c) > cos_max:
            hyps.append((n if c > 0 else -n, count))
    if not hyps:
        return None
    tol = np.sin(np.radians(6.0))

    def score(u: np.ndarray) -> int:
        return sum(cnt for m, _, cnt in planes if abs(m @ u) < tol or np.linalg.norm(np.cross(m, u)) < tol)

    best = max(hyps, key=lambda h: (score(h[0]), h[1]))[0]
    # Average the agreeing horizontal normals (weighted by support) for a steadier estimate.
    agree = [(h if h @ best > 0 else -h) * cnt for h, cnt in hyps if np.linalg.norm(np.cross(h, best)) < tol]
    return _unit(np.sum(agree, axis=0))


def _lowest_surface(points: np.ndarray, up: np.ndarray, min_count: int) -> float | None:
    """Offset (distance below the camera along ``up``) of the lowest horizontal layer of (N, 3)
    points holding at least ``min_count`` of them within +-3 cm, or None."""
    depth_below = -(points @ up)
    bins = np.arange(np.floor(depth_below.min() / 0.02) * 0.02, depth_below.max() + 0.04, 0.02)
    if len(bins) < 2:
        return None
    hist, edges = np.histogram(depth_below, bins=bins)
    # "full" trimmed to len(hist): mode "same" returns 3 values for a 2-bin histogram (a perfectly
    # flat floor), which does not line up with the bins.
    window = np.convolve(hist, np.ones(3, dtype=np.int64), mode="full")[1:-1]
    ok = np.flatnonzero((window >= min_count) & (edges[:-1] > 0.2))  # at least 20 cm below the camera
    a = np.cross(up, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    horiz = np.stack([a, np.cross(up, a)])
    for k in ok[::-1]:
        # The local maximum of the layer that starts at this bin.
        while k > 0 and window[k - 1] > window[k]:
            k -= 1
        sel = np.abs(depth_below - (edges[k] + 0.01)) < 0.03
        # A floor spreads in two horizontal directions; a band cut through a wall or a cabinet
        # front is a thin line seen from above.
        xy = points[sel] @ horiz.T
        if np.sqrt(np.linalg.eigvalsh(np.cov(xy.T))[0]) > 0.15:
            return float(np.median(depth_below[sel]))
    return None


def _is_wall(
    lateral_m: np.ndarray, dist: np.ndarray, thr: np.ndarray, inl: np.ndarray, rows: np.ndarray, cols: np.ndarray, height_px: int, width_px: int
) -> bool:
    """Is a vertical plane a wall of the room rather than the face of a piece of furniture?

    lateral_m: (N,) coordinate of the points along the plane's horizontal direction;
    dist: (N,) signed distance of the points to the plane (positive towards the camera); thr:
    (N,) inlier thresholds; inl: (N,) bool inliers; rows, cols: (N,) pixel of each point.

    A wall has little seen behind it. A wall with a doorway or a window has the next room behind
    it, but seen through a hole: in the same image column the wall shows above it. A wardrobe's
    front has the wall behind it seen over its top. So when the plane runs up out of the top of
    the depth image (walls do, furniture shorter than the ceiling shows its top), what lies
    behind it under its own pixels, or beyond its ends (a passage beside it, the room turning a
    corner), does not count.
    """
    behind = dist < -3.0 * thr
    if behind.sum() <= 0.5 * inl.sum():
        return True
    # Sensors leave the image border without depth: "the top" is the first rows with depth.
    top_rows = rows[inl] < rows.min() + max(2, int(0.03 * height_px))
    if top_rows.sum() < 0.02 * inl.sum():
        return False
    highest = np.full(width_px, np.iinfo(np.int64).max)
    np.minimum.at(highest, cols[inl], rows[inl])
    through_hole = rows > highest[cols]
    lo, hi = np.percentile(lateral_m[inl], [2, 98])
    beyond_ends = (lateral_m < lo) | (lateral_m > hi)
    return bool((behind & ~through_hole & ~beyond_ends).sum() <= 0.5 * inl.sum())


def _wall_behind(p: CameraPlane, planes: list[CameraPlane]) -> bool:
    """Is there a wall parallel to ``p`` (within 5 deg) more than WALL_MERGE_M behind it, with more
    inliers than ``p``? (Offsets are the planes' distances from the camera.)"""
    cos = np.cos(np.radians(5.0))
    return any(
        q.kind == "wall" and q is not p and float(q.normal @ p.normal) > cos and q.offset_m > p.offset_m + WALL_MERGE_M
        and int(q.inliers.sum()) > int(p.inliers.sum())
        for q in planes
    )


def _manhattan(p: CameraPlane, world_from_camera: np.ndarray, points_cam: np.ndarray) -> CameraPlane:
    """A wall (or partial wall) within MANHATTAN_SNAP_DEG of the room's horizontal axes turned
    onto the nearest one, its offset the median over its inliers (so it stays where it was seen);
    others unchanged. A wall fitted on a curtain's folds or seen edge-on at the image's side is a
    few degrees off (the dining room of ../shared/data/multiview, frame 3: its curtained window
    wall 7.5 deg off the wall it faces, 0.7 m too near where frame 1 sees it)."""
    if p.kind not in ("wall", "partial-wall"):
        return p
    axes = world_from_camera[:2, :3]  # world X and Y in camera coordinates (rows of the rotation)
    cands = np.concatenate([axes, -axes])
    best = cands[int(np.argmax(cands @ p.normal))]
    cos = float(best @ p.normal)
    if cos < np.cos(np.radians(MANHATTAN_SNAP_DEG)) or cos > 1.0 - 1e-9:  # (the wall the axes were taken from stays as fitted)
        return p
    pts = points_cam[p.inliers]
    return replace(p, normal=best.copy(), offset_m=float(np.median(-(pts @ best))))


def _merge_parallel(planes: list[CameraPlane]) -> list[CameraPlane]:
    """Walls (and partial walls) that the Manhattan turn made parallel (within 5 deg) and within
    WALL_MERGE_M of one of the same kind with more inliers are that wall: their inliers join it
    (nyuv2_metric3d_00100: two walls 1 cm apart after the turn)."""
    cos = np.cos(np.radians(5.0))
    order = sorted(range(len(planes)), key=lambda i: -int(planes[i].inliers.sum()))
    kept: list[int] = []
    joined: dict[int, np.ndarray] = {}
    for i in order:
        p = planes[i]
        host = None
        if p.kind in ("wall", "partial-wall"):
            host = next((j for j in kept if planes[j].kind == p.kind and float(planes[j].normal @ p.normal) > cos
                         and abs(planes[j].offset_m - p.offset_m) < WALL_MERGE_M), None)
        if host is None:
            kept.append(i)
        else:
            joined[host] = joined.get(host, planes[host].inliers) | p.inliers
    return [replace(planes[i], inliers=joined[i]) if i in joined else planes[i] for i in sorted(kept)]


def world_from_camera_for(up_cam: np.ndarray, height_m: float, wall_normals_cam: list[np.ndarray] = ()) -> np.ndarray:
    """(4, 4) world_from_camera for a camera whose up vector is ``up_cam`` at ``height_m`` above
    the floor; X is the horizontal optical axis snapped to the nearest wall direction.

    wall_normals_cam: horizontal wall normals in the camera frame, most supported first.
    """
    up = _unit(np.asarray(up_cam, dtype=np.float64))
    fwd = np.array([0.0, 0.0, 1.0]) - up[2] * up
    if np.linalg.norm(fwd) < 1e-6:  # looking straight down: image-up is forward
        fwd = np.array([0.0, -1.0, 0.0]) - (-up[1]) * up
    x = _unit(fwd)
    if len(wall_normals_cam):
        w = _unit(np.asarray(wall_normals_cam[0]) - (wall_normals_cam[0] @ up) * up)
        candidates = [w, -w, np.cross(up, w), -np.cross(up, w)]
        x = max(candidates, key=lambda c: float(c @ x))
    y = np.cross(up, x)
    rot = np.stack([x, y, up])  # rows: world axes in camera coordinates
    return pose(rot, [0.0, 0.0, float(height_m)])


def _world_walls(world_from_camera: np.ndarray, planes: list[CameraPlane]) -> tuple[Plane, ...]:
    rot = world_from_camera[:3, :3]
    walls = []
    for p in planes:
        if p.kind != "wall":
            continue
        n_w = rot @ p.normal
        n_w[2] = 0.0
        n_w = _unit(n_w)
        # Vertical planes: the camera's height does not change the offset (n_w . t = 0).
        walls.append(Plane(n_w, float(p.offset_m - n_w @ world_from_camera[:3, 3]), "wall", int(p.inliers.sum()), p.span_m))
    return tuple(walls)


#: A wall's inliers are taken to reach between these percentiles of their positions along it (a
#: few stray inliers where a surface of the next room lines up with it do not stretch it).
SPAN_PERCENTILES = (0.5, 99.5)
#: A point seen this far behind a wall's plane: its ray passed through the plane, where the wall
#: is not (the crossing counts between SEEN_THROUGH_Z_M above the floor, where things stand).
SEEN_THROUGH_M = 0.3
SEEN_THROUGH_Z_M = (0.05, 2.0)
#: At least this many rays through the plane beyond the wall's inliers end it there.
MIN_SEEN_THROUGH = 200


def _with_span(p: CameraPlane, points_cam: np.ndarray, pts: np.ndarray, up_cam: np.ndarray, height_m: float) -> CameraPlane:
    """A wall or partial wall with its known ends (``Plane.span_m``): beyond the extent of its
    inliers (points_cam: (H, W, 3)) along it, the first place where rays of the seen points
    (pts: (N, 3)) pass through its plane between SEEN_THROUGH_Z_M, by MIN_SEEN_THROUGH rays or
    more. Between its inliers and there, whatever stands in front hides the wall, which goes on
    behind it (a sofa against the wall's last metre); with nothing seen through the plane beyond
    a side, the wall goes on past the photo there (None). Rays through the plane between its
    inliers are doorways and windows: the wall stands around them. The world frame's origin lies
    under the camera and turns about up only, so the position along the wall, ``p . (up x n)``,
    is the same in the camera frame and in the world frame."""
    if p.kind not in ("wall", "partial-wall") or not p.inliers.any():
        return p
    along = np.cross(up_cam, p.normal)
    a, b = (float(v) for v in np.percentile(points_cam[p.inliers] @ along, SPAN_PERCENTILES))
    dist = pts @ p.normal + p.offset_m
    through = pts[dist < -SEEN_THROUGH_M]
    # Where the ray from the camera (the origin) to each such point crosses the plane.
    cross = through * (p.offset_m / -(through @ p.normal))[:, None]
    z = cross @ up_cam + height_m
    s = (cross @ along)[(z > SEEN_THROUGH_Z_M[0]) & (z < SEEN_THROUGH_Z_M[1])]
    beyond_lo, beyond_hi = s[s < a], s[s > b]
    lo = float(np.percentile(beyond_lo, 98)) if len(beyond_lo) >= MIN_SEEN_THROUGH else None
    hi = float(np.percentile(beyond_hi, 2)) if len(beyond_hi) >= MIN_SEEN_THROUGH else None
    return replace(p, span_m=(lo, hi)) if (lo, hi) != (None, None) else p


def estimate_room(points_cam: np.ndarray, valid: np.ndarray, seed: int = 0, up_hint: np.ndarray | None = None, normals: str = "open3d") -> RoomFrame:
    """Find gravity, floor, walls and ceiling.

    points_cam: (H, W, 3) float64 camera-frame points (from ``CameraIntrinsics.unproject``).
    valid: (H, W) bool, pixels with usable depth.
    up_hint: (3,) up in the camera frame measured by the depth estimator (vanishing points), used
    when no floor is visible (before the vertical-planes and camera-prior fallbacks).
    normals: "open3d" (:func:`open3d_normals`, the default) or "grid" (:func:`grid_normals`, the
    measured alternative) for the wall candidates.
    """
    h, w = valid.shape
    idx = np.flatnonzero(valid.reshape(-1))
    pts = points_cam.reshape(-1, 3)[idx]
    rng = np.random.default_rng(seed)
    sample = pts if len(pts) <= RANSAC_SAMPLES else pts[np.sort(rng.choice(len(pts), RANSAC_SAMPLES, replace=False))]
    planes = _ransac_planes(sample, seed)
    thr = inlier_threshold_m(pts[:, 2])
    image_up = np.array([0.0, -1.0, 0.0])
    cos_floor = np.cos(np.radians(FLOOR_MAX_TILT_DEG))

    def to_image(mask_flat: np.ndarray) -> np.ndarray:
        out = np.zeros(h * w, dtype=bool)
        out[idx[mask_flat]] = True
        return out.reshape(h, w)

    cam_planes: list[CameraPlane] = []
    up0 = _manhattan_up(planes, image_up, cos_floor)
    floor_d = None if up0 is None else _lowest_surface(sample, up0, max(200, int(_MIN_PLANE_FRACTION * len(sample))))
    floor_found = floor_d is not None
    if floor_found:
        n, d, inl = _refine(pts, thr, up0, floor_d, seed)
        n, d = _towards_camera(n, d)
        if n @ up0 < np.cos(np.radians(8.0)):  # the patch was too small to tilt the consensus
            n, d = up0, float(np.median(-(pts[inl] @ up0)))
            inl = np.abs(pts @ n + d) < thr
        up = n
        height = d
        below = (pts @ n + d) < -thr  # under the floor: reflections and noise, never objects
        cam_planes.append(CameraPlane(n, d, "floor", to_image(inl | below)))
        tilt = np.degrees(np.arccos(np.clip(up @ image_up, -1, 1)))
        gravity = BackendUse("gravity", "floor-plane", f"floor plane from RANSAC, {int(inl.sum())} inliers, camera {tilt:.1f} deg from upright, {height:.2f} m high")
        floor = BackendUse("floor", "floor-plane", f"the floor seen, {height:.2f} m under the camera")
    else:
        verticals = [p for p in planes if abs(p[0] @ image_up) < np.sin(np.radians(FLOOR_MAX_TILT_DEG))]
        pair = next(
            ((a, b) for i, a in enumerate(verticals) for b in verticals[i + 1 :] if np.linalg.norm(np.cross(a[0], b[0])) > np.sin(np.radians(30.0))),
            None,
        )
        if up_hint is not None:
            up = _unit(np.asarray(up_hint, dtype=np.float64))
            gravity = BackendUse("gravity", "vanishing-points", "no floor visible; up from the photo's vertical vanishing point")
        elif pair is not None:
            up = _unit(np.cross(pair[0][0], pair[1][0]))
            up = up if up @ image_up > 0 else -up
            gravity = BackendUse("gravity", "vertical-planes", "no floor visible; up from the intersection of two vertical planes")
        else:
            t = np.radians(TYPICAL_PITCH_DEG)
            up = np.array([0.0, -np.cos(t), -np.sin(t)])
            gravity = BackendUse(
                "gravity", "camera-prior", f"no floor or vertical structure found; assumed the camera upright with a {TYPICAL_PITCH_DEG:.0f} deg downward pitch"
            )
        height, floor = _floor_without_plane(float(-np.quantile(pts @ up, 0.005)))

    # Walls (vertical, little seen behind them) and the ceiling (horizontal, above the camera).
    # Without a floor in view a large vertical plane is as likely a cabinet front as a wall, and
    # the room's planes stay unknown.
    sin_wall = np.sin(np.radians(WALL_MAX_TILT_DEG))
    on_floor = (pts @ up + height) < thr  # on or under the floor
    rows, cols = idx // w, idx % w
    min_wall = max(200, int(_MIN_PLANE_FRACTION * len(pts)))
    min_partial = max(200, int(PARTIAL_WALL_MIN_FRACTION * len(pts)))
    candidates = sorted(planes, key=lambda p: -p[2])
    walls_flat = np.zeros(len(pts), dtype=bool)  # inliers of the walls and partial walls found
    if floor_found:
        gq, gn = grid_normals(points_cam, valid) if normals == "grid" else open3d_normals(pts)
        candidates += vertical_plane_candidates(gq, gn, up, min_wall, len(pts) / max(len(gq), 1))
    for n0, d0, _ in candidates if floor_found else ():
        if abs(n0 @ up) < sin_wall:
            n = _unit(n0 - (n0 @ up) * up)
            _, _, inl = _refine(pts, thr, n, d0, seed, iterations=1)
            if inl.sum() < 3:
                continue
            d = float(np.median(-(pts[inl] @ n)))
            n, d = _towards_camera(n, d)
            dist = pts @ n + d
            inl = (np.abs(dist) < thr) & ~on_floor
            if inl.sum() < min_partial:
                continue
            # Walls are big and run up past head height; a chair's back or a drawer front is not.
            lateral = pts[inl] @ np.cross(up, n)
            top_m = float(np.percentile(pts[inl] @ up + height, 98))
            width_m = float(np.subtract(*np.percentile(lateral, [98, 2])))
            if width_m < PARTIAL_WALL_MIN_WIDTH_M or top_m < WALL_MIN_TOP_M:
                continue
            if not _is_wall(pts @ np.cross(up, n), dist, thr, inl, rows, cols, h, w):
                continue
            kind = "wall" if inl.sum() >= min_wall and width_m >= WALL_MIN_WIDTH_M else "partial-wall"
            if any(p.kind == kind and abs(p.normal @ n) > np.cos(np.radians(5.0)) and abs(p.offset_m - d) < WALL_MERGE_M for p in cam_planes):
                continue
            # A plane through a wall already found (most of its inliers are that wall's) is that
            # wall seen at a slant: far away the inlier band is 20 cm thick, and a plane 15 deg
            # off still gathers thousands of its points.
            if inl.sum() and (inl & walls_flat).sum() > 0.5 * inl.sum():
                continue
            walls_flat |= inl
            cam_planes.append(CameraPlane(n, d, kind, to_image(inl)))
        elif -(n0 @ up) > cos_floor:
            # A horizontal plane whose normal (towards the camera) points down: the ceiling.
            n, d, inl = _refine(pts, thr, n0, d0, seed, iterations=1)
            above = (pts @ n + d) < -thr
            cam_planes.append(CameraPlane(n, d, "ceiling", to_image(inl | above)))

    # What lies behind a wall along its span is left out of the room: a vertical plane
    # with a wall parallel to it behind it that shows more of itself is no wall. Single-view
    # depth stands a bed as a cuboid whose headboard is such a plane; with the ceiling band it
    # crosses it passed `_is_wall`, and it left a dresser out of sunrgbd_imvotenet_000003 and cut
    # the bed's headboard off.
    cam_planes = [p for p in cam_planes if p.kind != "wall" or not _wall_behind(p, cam_planes)]
    # A partial wall that is a wall found in full is that wall.
    cam_planes = [
        p for p in cam_planes
        if p.kind != "partial-wall" or not any(q.kind == "wall" and abs(q.normal @ p.normal) > np.cos(np.radians(5.0)) and abs(q.offset_m - p.offset_m) < WALL_MERGE_M for q in cam_planes)
    ]
    walls_cam = [p.normal for p in sorted((p for p in cam_planes if p.kind == "wall"), key=lambda p: -int(p.inliers.sum()))]
    world_from_camera = world_from_camera_for(up, height, walls_cam)
    cam_planes = [_with_span(p, points_cam, pts, up, height) for p in _merge_parallel([_manhattan(p, world_from_camera, points_cam) for p in cam_planes])]
    background = np.zeros((h, w), dtype=bool)
    for p in cam_planes:
        if p.kind != "partial-wall":  # (a partial wall may be a tall cabinet's front: left to the segmenter)
            background |= p.inliers
    return RoomFrame(
        world_from_camera=world_from_camera,
        up_cam=up,
        room=Room(walls=_world_walls(world_from_camera, cam_planes)),
        background=background,
        floor_found=floor_found,
        gravity=gravity,
        planes=tuple(cam_planes),
        floor=floor,
    )


def _world_plane(frame: RoomFrame, p: CameraPlane) -> tuple[np.ndarray, float]:
    rot, t = frame.world_from_camera[:3, :3], frame.world_from_camera[:3, 3]
    n = rot @ p.normal
    return n, float(p.offset_m - n @ t)


def ceiling_plane(frame: RoomFrame) -> Plane | None:
    """The ceiling found (if any) as a horizontal world plane, normal down (into the room), at the
    height where the fitted plane passes over the camera."""
    for p in frame.planes:
        if p.kind != "ceiling":
            continue
        t = frame.world_from_camera[:3, 3]
        n, off = _world_plane(frame, p)
        if abs(n[2]) < 1e-6:
            return None
        z = -(off + n[0] * t[0] + n[1] * t[1]) / n[2]
        if z <= t[2]:
            return None
        return Plane(np.array([0.0, 0.0, -1.0]), float(z), "ceiling", int(p.inliers.sum()))
    return None


def completion_planes(frame: RoomFrame) -> tuple[Plane, ...]:
    """The room's planes beyond the floor and the walls, for completing its surface
    (perception.background): the ceiling, and the partial walls (world frame, kind "wall",
    normals horizontal, into the room)."""
    out = _world_walls(frame.world_from_camera, [replace(p, kind="wall") for p in frame.planes if p.kind == "partial-wall"])
    ceiling = ceiling_plane(frame)
    return tuple(out) + ((ceiling,) if ceiling is not None else ())


def _floor_without_plane(lowest_m: float) -> tuple[float, BackendUse]:
    """The camera's height above a floor not seen, and how it was chosen: under everything seen
    (``lowest_m``: the lowest observed point's depth below the camera) and at least
    :data:`CAMERA_HEIGHT_PRIOR_M` under the camera. Measured on the 17 RGB-D frames with a floor
    here, with everything seen below a given height removed (``python -m
    scene_builder.bench.room_planes``): the lowest point alone misses the camera height by the
    height of what is unseen (median 0.51 m with nothing seen below 0.5 m), the prior by a median
    0.12 m whatever is unseen."""
    if lowest_m >= CAMERA_HEIGHT_PRIOR_M:
        return lowest_m, BackendUse("floor", "lowest-point", f"no floor visible; the floor put under the lowest point seen, {lowest_m:.2f} m under the camera")
    return CAMERA_HEIGHT_PRIOR_M, BackendUse(
        "floor", "camera-height-prior", f"no floor visible; the floor put {CAMERA_HEIGHT_PRIOR_M:.2f} m under the camera (a typical camera height; everything seen lies above it, the lowest point {lowest_m:.2f} m under the camera)"
    )


def place_floor_under(frame: RoomFrame, lowest_z_m: float) -> RoomFrame:
    """The same frame with the floor lowered to ``lowest_z_m`` (world z of the lowest object
    point) if that lies under it (the floor found without a plane is already under everything
    seen and at least CAMERA_HEIGHT_PRIOR_M under the camera: it is never raised to an object)."""
    if lowest_z_m >= 0.0:
        return frame
    t = frame.world_from_camera.copy()
    t[2, 3] -= lowest_z_m
    floor = BackendUse("floor", "lowest-point", f"no floor visible; the floor put under the lowest object point, {t[2, 3]:.2f} m under the camera")
    return replace(frame, world_from_camera=t, room=Room(walls=_world_walls(t, list(frame.planes))), floor=floor)
