"""Door and drawer fronts on the faces of furniture seen in the photo.

For each object that can have fronts (:data:`FRONT_LABELS`), its **face** is the vertical
rectangle of its observed points that looks most toward the camera: the gravity-aligned
smallest-area rectangle of its points in plan gives its axes (snapped to the room's walls when
within ``SNAP_DEG``), the side whose normal points most toward the camera is the face, set at the
front-most observed points, as wide and as high as the points. The photo is resampled onto that
plane (``rectify``: every face pixel is a world point on the plane projected into the photo), so
that the face is seen head-on with rows horizontal and columns vertical; ``perception.front_parse``
splits it into panels and tells doors, drawers and frame apart. Each front goes back into the
photo and the world through the same plane (:class:`scene_builder.model.Front`).

An object of a category that may hold drawers without being made of them (a table that is a
night stand, a desk) keeps its fronts only when at least ``MIN_HANDLED_FRONTS`` of them show a
handle; a face the photo shows coarser than ``MAX_PHOTO_M_PER_PX`` gets none (too coarse to
see a pull or a gap: the object is built rigid); ovens and dishwashers get their largest front
as a flap hinged at the bottom, microwaves as a door hinged on the left, and an appliance keeps
no other front but an oven's drawer under that door (its controls, vents and cooktop are no
fronts), and on a floor-standing oven or dishwasher that door reaches down near the floor
(``FLAP_MAX_RISE_M``: else it was the cooktop, and the template stands in); a "drawer" taller
than ``DRAWER_MAX_HEIGHT_M`` is a door. On sensor
depth, a panel whose middle lies ``OPENING_RECESS_M`` (``HANDLED_RECESS_M`` for a case good's panel with a
handle) or more behind the face is an opening, not a front (the cubbies of an open bookcase).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from scene_builder.config import usable_cores
from scene_builder.frames import transform_points
from scene_builder.model import Camera, Front, Observation, PerceivedObject, Plane

__all__ = ["FRONT_LABELS", "MAYBE_FRONT_LABELS", "Face", "face_of", "fronts_on_face", "rectify", "with_fronts"]

#: Categories made of fronts: every front found counts.
FRONT_LABELS = frozenset({"cabinet", "wardrobe", "drawer_unit", "refrigerator", "oven", "dishwasher", "microwave"})
#: Categories that may hold drawers (a night stand named a table, a desk, a low shelf unit):
#: their fronts count when at least MIN_HANDLED_FRONTS of them show a handle.
MAYBE_FRONT_LABELS = frozenset({"table", "desk", "shelf", "box"})
#: Furniture whose drawers may sit in a face frame (``perception.front_rects``).
CASE_GOODS = frozenset({"cabinet", "wardrobe", "drawer_unit"})
MIN_HANDLED_FRONTS = 2
#: A face's axes snap to the walls' directions within this angle.
SNAP_DEG = 12.0
#: The face image: at most this many pixels on its long side, and no finer than MIN_M_PER_PX.
FACE_MAX_PX = 360
MIN_M_PER_PX = 0.002
#: The face's yaw is searched this far (deg) either way, in steps of YAW_STEP_DEG, on a
#: resampling YAW_PX pixels long.
YAW_SEARCH_DEG = 20.0
YAW_STEP_DEG = 2.5
YAW_PX = 160
#: ... unless the face's long horizontal lines (its gaps, rails and top) fan out: on a face turned
#: away from the real one they converge toward a vanishing point, so that their slope changes
#: with their height; on the real face they are parallel. The fan (:func:`_fan`: the change of
#: slope, rows per column, over the face's height, a Theil-Sen fit to the Hough segments of its
#: horizontal edges at least LINE_SHARE of the face image's width and within MAX_LINE_SLOPE of
#: level, at least MIN_LINES of them over MIN_LINE_SPAN of its height) is measured at each yaw of
#: the search on a resampling FAN_PX long within the object's mask. Where it rises or falls
#: steadily with the yaw (Spearman's rank correlation FAN_RHO or more in size, over at least
#: MIN_FAN_YAWS yaws), the face turns to where it crosses zero (a Theil-Sen line through the
#: yaws, refitted within FAN_NEAR_DEG of its zero), when that is MIN_TURN_DEG or more from the
#: face's own yaw (the zero's error on a drawn chest with wood grain, up to 3.5 degrees, turned
#: a face on the right plane; and a smaller turn is nearly within the parse's SLOPES).
#: Estimated depth can put a cabinet seen at an angle head-on (urdformer_label53: the fan
#: crosses zero 12.6 degrees off; turned there, its two lower drawers come apart and all three
#: built fronts match the hand count, one of two before); the edge count's peak (above) does not
#: see a fan. urdformer_label3 turns 5.1 degrees, and its parse then loses two of its three
#: matched drawers to cuts along the wood grain (front_parse's known failure). Rank correlations
#: on the faces of the bench's photos: 0.998-1.0 (label53, label3, label42), 0.76 and 0.82 on a
#: kitchen's white cabinet and microwave (coco 164: noise); a drawn chest turned 5-15 degrees,
#: wood grain or not, 0.96-0.99, its turn found within 4.1 degrees.
LINE_SHARE = 0.4
MAX_LINE_SLOPE = 0.3
MIN_LINES = 6
MIN_LINE_SPAN = 0.2
FAN_PX = 200
FAN_RHO = 0.9
MIN_FAN_YAWS = 5
FAN_NEAR_DEG = 7.5
MIN_TURN_DEG = 5.0
#: Fronts smaller than this (m) in either direction are not kept (a sliver of a cut face).
MIN_FRONT_M = 0.07
#: A "front" less than PLINTH_MAX_M high whose bottom edge lies within FLOOR_CLEARANCE_M of the
#: floor is the plinth or the floor under the piece, not a door or a drawer (a front must clear
#: the floor to move): the 13 cm strip of carpet and feet under sunrgbd_total3d_demo_5's night
#: stand, from z = 0.00 m, was built as a door.
PLINTH_MAX_M = 0.15
FLOOR_CLEARANCE_M = 0.02
#: An appliance's largest front, whatever the parse read from its window or panel: (kind,
#: hinge). An oven's or a dishwasher's is a flap hinged at its bottom; a microwave's a door
#: hinged on its left (its keypad and latch are on the right).
APPLIANCE_DOORS = {"oven": ("flap", "bottom"), "dishwasher": ("flap", "bottom"), "microwave": ("door", "left")}
#: A floor-standing appliance whose door is hinged at its bottom (a range's oven, a dishwasher)
#: has that door, or a drawer under it, reaching within this height (m) of the floor (a range's
#: kick plate and storage drawer are 5-15 cm). A "door" the parse found higher with nothing under
#: it is the cooktop or the control panel seen from above (coco128_000000000089: the glass cooktop
#: was built as the oven's door, 0.40-0.70 m up, and opened as one): the appliance keeps no parsed
#: front and takes its category's articulation template.
FLAP_MAX_RISE_M = 0.3
#: An appliance keeps its largest front (its door) and, an oven, of the other fronts the parse
#: found on its face only drawers under that door at least this share of its width.
APPLIANCE_DRAWER_WIDTH = 0.8
#: A drawer front is at most this high (m; a kitchen's deep pan drawer is about 0.4 m): a taller
#: "drawer" is a door (a refrigerator's, which the parse reads as a drawer by its centred handle).
DRAWER_MAX_HEIGHT_M = 0.45
#: On sensor depth, a "front" whose middle was measured this far (median, m) behind the face is
#: an opening (an open shelf's cubby, 7-33 cm deep on promptda_arkit's bookcase), not a door or a
#: drawer. Not on estimated depth, whose relief inside a face is not measured well enough.
OPENING_RECESS_M = 0.05
#: ... and one of a case good (:data:`CASE_GOODS`, not an open shelf's cubby with a thing in it
#: that looks like a handle: promptda_arkit) with a handle this far: a sensor's depth at 4 m
#: leaks from a top seen from above onto the face below it (the top drawer of
#: sunrgbd_imvotenet_000003's night stand read 12 cm behind its face, its bottom drawer 2 cm).
HANDLED_RECESS_M = 0.15
#: Fronts are read off a face the photo shows at this many metres per pixel or finer: coarser, a
#: pull (2-3 cm) is a pixel or two and the gaps between fronts are lost (a chest of drawers 6.5 m
#: away at 1.2 cm per pixel, sunrgbd_000017_mmdet3d, gave two doors where it has seven drawers):
#: the object is built without fronts, rigid (the faces of the bench's photos: 0.3-0.9 cm per pixel).
MAX_PHOTO_M_PER_PX = 0.01


@dataclass(frozen=True, eq=False)
class Face:
    """A vertical rectangle in the world: ``origin_m`` its bottom-left corner seen from the front,
    ``right`` (3,) the horizontal unit vector to the viewer's right along it, ``normal`` (3,) the
    horizontal unit vector out of it (toward the camera); ``width_m`` along ``right``,
    ``height_m`` up (+Z)."""

    origin_m: np.ndarray
    right: np.ndarray
    normal: np.ndarray
    width_m: float
    height_m: float

    def points(self, a_m: np.ndarray, b_m: np.ndarray) -> np.ndarray:
        """(..., 3) world points at ``a_m`` along ``right`` and ``b_m`` up from the origin."""
        a, b = np.asarray(a_m, dtype=np.float64), np.asarray(b_m, dtype=np.float64)
        return self.origin_m + a[..., None] * self.right + b[..., None] * np.array([0.0, 0.0, 1.0])


def _plan_axes(xy: np.ndarray, walls: tuple[Plane, ...]) -> np.ndarray:
    """(2, 2) rows: the two horizontal axes of the smallest-area rectangle around ``xy`` (N, 2)
    (1 deg steps), snapped to the walls' directions within SNAP_DEG."""
    c = xy - np.median(xy, axis=0)
    if len(c) > 3000:
        c = c[:: len(c) // 3000 + 1]
    best = (np.inf, 0.0)
    for a in np.radians(np.arange(0.0, 90.0, 1.0)):
        u = c @ [np.cos(a), np.sin(a)]
        v = c @ [-np.sin(a), np.cos(a)]
        area = float(np.subtract(*np.percentile(u, [98, 2])) * np.subtract(*np.percentile(v, [98, 2])))
        if area < best[0]:
            best = (area, float(a))
    angle = best[1]
    for wall in walls:
        wa = float(np.arctan2(wall.normal[1], wall.normal[0])) % (np.pi / 2)
        diff = (angle - wa + np.pi / 4) % (np.pi / 2) - np.pi / 4
        if abs(diff) < np.radians(SNAP_DEG):
            angle = wa
            break
    return np.array([[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]])


def face_of(points_world_m: np.ndarray, camera_position_m: np.ndarray, walls: tuple[Plane, ...] = ()) -> Face:
    """The face of an object's observed points (N, 3) that looks most toward the camera (see the
    module docstring). Its plane lies at the 95th percentile of the points along its normal (the
    front-most, robust to stray depth); its extent is the 1st-99th percentile of the points."""
    p = np.asarray(points_world_m, dtype=np.float64)
    axes = _plan_axes(p[:, :2], walls)
    centre = np.median(p[:, :2], axis=0)
    to_cam = np.asarray(camera_position_m, dtype=np.float64)[:2] - centre
    normals = np.vstack([axes, -axes])
    n2 = normals[int(np.argmax(normals @ to_cam))]
    normal = np.array([n2[0], n2[1], 0.0])
    right = np.cross(np.array([0.0, 0.0, 1.0]), normal)  # the viewer's right, looking along -normal: (-normal) x up
    a = p @ right
    d = p @ normal
    a0, a1 = np.percentile(a, [1, 99])
    z0, z1 = np.percentile(p[:, 2], [1, 99])
    z0 = 0.0 if z0 < 0.05 else float(z0)
    offset = float(np.percentile(d, 95))
    origin = normal * offset + right * a0 + np.array([0.0, 0.0, z0])
    return Face(origin, right, normal, float(a1 - a0), float(z1 - z0))


def _rotated(face: Face, points_world_m: np.ndarray, yaw_rad: float) -> Face:
    """``face`` turned by ``yaw_rad`` about the vertical through its centre, its extent taken
    again from the points (as :func:`face_of` does)."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    normal = rot @ face.normal
    right = np.cross(np.array([0.0, 0.0, 1.0]), normal)
    p = np.asarray(points_world_m, dtype=np.float64)
    a = p @ right
    a0, a1 = np.percentile(a, [1, 99])
    offset = float(np.percentile(p @ normal, 95))
    origin = normal * offset + right * a0 + np.array([0.0, 0.0, face.origin_m[2]])
    return Face(origin, right, normal, float(a1 - a0), face.height_m)


# Theil-Sen and Spearman written with numpy, not taken from scipy.stats: importing scipy.stats
# costs 0.7 s (measured in a build of sunrgbd_imvotenet_000005, of a 15 s budget), for two
# statistics of a few dozen values each. Same definitions as scipy.stats.theilslopes (its default
# "separate" intercept) and spearmanr (average ranks for ties); tests compare them with scipy's.
def theil_sen(y: np.ndarray, x: np.ndarray) -> tuple[float, float]:
    """(slope, intercept) of the Theil-Sen line of ``y`` on ``x``: the median of the slopes of every
    pair with different x, and median(y) - slope * median(x); NaNs when every x is the same."""
    y, x = np.asarray(y, dtype=np.float64), np.asarray(x, dtype=np.float64)
    dx, dy = x[:, None] - x[None, :], y[:, None] - y[None, :]
    pair = dx > 0
    if not np.any(pair):
        return float("nan"), float("nan")
    slope = float(np.median(dy[pair] / dx[pair]))
    return slope, float(np.median(y) - slope * np.median(x))


def _ranks(a: np.ndarray) -> np.ndarray:
    """Ranks 1..n of ``a``, tied values taking the mean of their ranks."""
    _, inverse, counts = np.unique(a, return_inverse=True, return_counts=True)
    last = np.cumsum(counts)
    return (last - (counts - 1) / 2.0)[inverse]


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman's rank correlation of ``a`` and ``b``; NaN when either is constant."""
    ra, rb = _ranks(np.asarray(a, dtype=np.float64)), _ranks(np.asarray(b, dtype=np.float64))
    if np.ptp(ra) == 0 or np.ptp(rb) == 0:
        return float("nan")
    return float(np.corrcoef(ra, rb)[0, 1])


def _fan(img: np.ndarray, inside: np.ndarray) -> float | None:
    """How much the long near-level lines of a face image fan out: the slope (rows per column) of
    its Hough segments (OpenCV's probabilistic transform of its horizontal edges) fitted as a
    line in their height, the fitted slope's change from the image's top to its bottom; None
    when too few lines are found (see :data:`MIN_LINES`)."""
    import cv2
    from skimage.color import rgb2gray

    from perception.front_parse import _edges

    horiz, _ = _edges(rgb2gray(img), sigma=1.2)
    horiz &= inside
    h, w = horiz.shape
    lines = cv2.HoughLinesP(horiz.astype(np.uint8) * 255, 1, np.pi / 360, threshold=max(4, int(LINE_SHARE * w)),
                            minLineLength=max(4, int(LINE_SHARE * w)), maxLineGap=5)
    if lines is None:
        return None
    x0, y0, x1, y1 = lines.reshape(-1, 4).astype(np.float64).T
    ok = x1 != x0
    slope = (y1[ok] - y0[ok]) / (x1[ok] - x0[ok])
    row = 0.5 * (y0[ok] + y1[ok]) / h
    level = np.abs(slope) < MAX_LINE_SLOPE
    slope, row = slope[level], row[level]
    if len(slope) < MIN_LINES or np.ptp(row) < MIN_LINE_SPAN:
        return None
    return theil_sen(slope, row)[0]


def _fan_zero(fans: list[tuple[float, float]]) -> float | None:
    """The yaw (deg) where the fan of (yaw deg, fan) pairs crosses zero, or None when it does not
    change steadily with the yaw (:data:`FAN_RHO`)."""
    if len(fans) < MIN_FAN_YAWS:
        return None
    deg, fan = np.array(fans).T
    if np.ptp(fan) == 0 or not abs(spearman(deg, fan)) >= FAN_RHO:  # (a NaN correlation fails too)
        return None
    a, b = theil_sen(fan, deg)
    if a == 0:
        return None
    near = np.abs(deg - (-b / a)) <= FAN_NEAR_DEG
    if near.sum() >= 3:
        a_near, b_near = theil_sen(fan[near], deg[near])
        if a_near * a > 0:
            a, b = a_near, b_near
    return float(-b / a)


def refine_yaw(rgb: np.ndarray, camera: Camera, face: Face, points_world_m: np.ndarray, mask: np.ndarray | None = None) -> Face:
    """``face`` turned about the vertical (within YAW_SEARCH_DEG) so that the horizontal edges of
    the photo resampled onto it run most nearly along its rows: a face plane turned away from the
    real face shows that face's horizontal edges (drawer gaps, rails, tops) sloping. Score: the
    sum of squared counts of horizontal edge pixels per row over the squared total (peakedness),
    on a coarse resampling (YAW_PX on the long side). Where the face's long horizontal lines
    (within ``mask``, the object's pixels, when given) fan out, steadily less toward one yaw,
    the face turns to that yaw instead (:data:`FAN_RHO`)."""
    from skimage.color import rgb2gray

    from perception.front_parse import _edges

    best, best_face = -1.0, face
    fans: list[tuple[float, float]] = []
    for deg in np.arange(-YAW_SEARCH_DEG, YAW_SEARCH_DEG + 1e-9, YAW_STEP_DEG):
        f = _rotated(face, points_world_m, float(np.radians(deg))) if deg else face
        if f.width_m <= 0.05:
            continue
        fan = _fan(*rectify(rgb, camera, f, mask, max_px=FAN_PX)[:2])
        if fan is not None:
            fans.append((float(deg), fan))
        img, inside, m = rectify(rgb, camera, f, max_px=YAW_PX)
        horiz, _ = _edges(rgb2gray(img), sigma=1.0)
        horiz &= inside
        total = float(horiz.sum())
        if total < 20:
            continue
        score = float(np.sum(horiz.sum(axis=1).astype(np.float64) ** 2)) / total ** 2 * horiz.shape[0]
        if score > best * 1.1 or (deg == 0 and score >= best / 1.1):
            best, best_face = score, f
    turn = _fan_zero(fans)
    if turn is not None and MIN_TURN_DEG <= abs(turn) <= YAW_SEARCH_DEG:
        return _rotated(face, points_world_m, float(np.radians(turn)))
    return best_face


def rectify(rgb: np.ndarray, camera: Camera, face: Face, mask: np.ndarray | None = None, max_px: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """The photo seen head-on on ``face``: ((h, w, 3) uint8 face image, (h, w) bool where the
    face pixel projects into the photo (and into ``mask``, when given), metres per pixel). Row 0
    is the face's top; column 0 its left edge seen from the front. Bilinear resampling (OpenCV's
    remap). ``max_px``: the long side in pixels (default FACE_MAX_PX)."""
    import cv2

    m_per_px = max(MIN_M_PER_PX, max(face.width_m, face.height_m) / (max_px or FACE_MAX_PX))
    w = max(4, int(round(face.width_m / m_per_px)))
    h = max(4, int(round(face.height_m / m_per_px)))
    a = (np.arange(w) + 0.5) * m_per_px
    b = face.height_m - (np.arange(h) + 0.5) * m_per_px
    world = face.points(a[None, :].repeat(h, 0), b[:, None].repeat(w, 1))
    cam = transform_points(np.linalg.inv(camera.world_from_camera), world.reshape(-1, 3))
    k = camera.intrinsics
    z = np.maximum(cam[:, 2], 1e-6)
    u = (k.fx_px * cam[:, 0] / z + k.cx_px).reshape(h, w).astype(np.float32)
    v = (k.fy_px * cam[:, 1] / z + k.cy_px).reshape(h, w).astype(np.float32)
    img = cv2.remap(np.ascontiguousarray(rgb), u, v, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    H, W = rgb.shape[:2]
    inside = (cam[:, 2].reshape(h, w) > 0) & (u >= 0) & (u <= W - 1) & (v >= 0) & (v <= H - 1)
    if mask is not None:
        ui = np.clip(np.round(u).astype(np.int64), 0, W - 1)
        vi = np.clip(np.round(v).astype(np.int64), 0, H - 1)
        inside &= mask[vi, ui]
    return img, inside, m_per_px


def fronts_on_face(rgb: np.ndarray, camera: Camera, face: Face, label: str = "", mask: np.ndarray | None = None,
                   depth: np.ndarray | None = None) -> tuple[Front, ...]:
    """The door and drawer fronts on ``face`` of the photo ``rgb`` (the analysis image), left to
    right then top to bottom. ``label``: the object's category (ovens and dishwashers: the largest
    front is a flap hinged at its bottom; microwaves: a door hinged on its left). ``depth``:
    measured (sensor) depth of the analysis image, to tell openings from fronts
    (:data:`OPENING_RECESS_M`)."""
    from perception.front_parse import parse_face

    img, inside, m = rectify(rgb, camera, face, mask)
    # (the fallbacks for fronts in a face frame, for case goods only: on a shelf two boxes one
    # above the other, on a microwave its keypad's buttons, are no column of drawers)
    panels = parse_face(img, m, inside if mask is not None and label in CASE_GOODS else None)
    h = img.shape[0]
    k = camera.intrinsics
    camera_from_world = np.linalg.inv(camera.world_from_camera)
    out = []
    for p in panels:
        x0, y0, x1, y1 = p.box
        # (measured on the face: a panel refitted past the face's border, a strip of plinth
        # under urdformer_label62's bottom drawer, 6 cm on the face, 7.5 cm refitted, is no front)
        if min(min(x1, img.shape[1]) - max(x0, 0.0), min(y1, h) - max(y0, 0.0)) * m < MIN_FRONT_M:
            continue
        # (a panel may reach a pixel past the rectified image: an empty window's mean was NaN,
        # which kept a front lying off the photo)
        window = inside[max(0, int(y0)):int(np.ceil(y1)), max(0, int(x0)):int(np.ceil(x1))]
        if window.size == 0 or window.mean() < 0.5:  # mostly off the photo or hidden by something else
            continue
        a = p.corners[:, 0] * m
        b = (h - p.corners[:, 1]) * m
        world = face.points(a, b)
        if float(np.min(world[:, 2])) < FLOOR_CLEARANCE_M and float(np.ptp(world[:, 2])) < PLINTH_MAX_M:
            continue
        px = k.project(transform_points(camera_from_world, world))
        handle = None
        if p.handle is not None:
            hw = face.points(np.array(p.handle[0] * m), np.array((h - p.handle[1]) * m))
            handle = k.project(transform_points(camera_from_world, hw[None]))[0]
        deep = HANDLED_RECESS_M if p.handle is not None and label in CASE_GOODS else OPENING_RECESS_M
        if depth is not None and _recess_m(px, world, depth, camera) >= deep:
            continue
        score = 0.5 * float(p.handle is not None) + 0.5 * p.support
        kind, hinge = p.kind, p.hinge
        if kind == "drawer" and float(np.ptp(world[:, 2])) > DRAWER_MAX_HEIGHT_M:
            # A door, hinged on the side away from its handle (off the middle), else on the
            # face's outer side (the pair rule of front_parse).
            lo, hi = float(np.min(a)), float(np.max(a))
            mid = 0.5 * (lo + hi)
            if p.handle is not None and abs(p.handle[0] * m - mid) > 0.05 * (hi - lo):
                hinge = "right" if p.handle[0] * m < mid else "left"
            else:
                hinge = "left" if mid < 0.5 * face.width_m else "right"
            kind = "door"
        out.append(Front(kind, hinge, px, world, handle, float(np.clip(score, 0.0, 1.0))))
    if label in APPLIANCE_DOORS and out:
        big = max(range(len(out)), key=lambda i: _area(out[i]))
        kind, hinge = APPLIANCE_DOORS[label]
        door = replace(out[big], kind=kind, hinge=hinge)
        out = [door if i == big else f for i, f in enumerate(out) if i == big or (label == "oven" and _drawer_under(f, door))]
        lowest = min(float(np.min(f.corners_world_m[:, 2])) for f in out)
        if hinge == "bottom" and float(face.origin_m[2]) <= 0.0 and lowest > FLAP_MAX_RISE_M:
            return ()
    return tuple(out)


def _drawer_under(f: Front, door: Front) -> bool:
    """Whether ``f`` is an oven's drawer under its door: a drawer wholly below the door
    (world z) and at least APPLIANCE_DRAWER_WIDTH of its width (a range's warming drawer). The
    other panels the parse reads on an appliance's face are its controls, vents and cooktop, no
    fronts (coco 089's range: a knob panel and the glass cooktop were built as a door and a drawer)."""
    below = float(np.max(f.corners_world_m[:, 2])) <= float(np.min(door.corners_world_m[:, 2])) + 0.02
    wide = _width_m(f) >= APPLIANCE_DRAWER_WIDTH * _width_m(door)
    return f.kind == "drawer" and below and wide


def _width_m(f: Front) -> float:
    c = f.corners_world_m  # bottom-left, bottom-right, top-right, top-left
    return float(np.linalg.norm(c[1] - c[0]))


def _recess_m(px: np.ndarray, world: np.ndarray, depth_m: np.ndarray, camera: Camera) -> float:
    """Median distance (m, along the optical axis) by which the depth measured in the middle of
    a panel (its corners ``px`` in the image, ``world`` on the face plane, shrunk to 60 % about
    its centre, away from the frame around it) lies behind the face plane; 0 without valid depth."""
    from skimage.draw import polygon

    from perception.background import plane_depths

    c = px.mean(axis=0)
    inner = c + 0.6 * (px - c)
    rr, cc = polygon(inner[:, 1], inner[:, 0], depth_m.shape)
    d = depth_m[rr, cc]
    ok = d > 0
    if np.count_nonzero(ok) < 10:
        return 0.0
    rr, cc, d = rr[ok], cc[ok], d[ok]
    normal = np.cross(world[1] - world[0], world[3] - world[0])
    normal /= np.linalg.norm(normal)
    if normal @ (camera.position_m - world[0]) < 0:
        normal = -normal  # toward the camera, as plane_depths wants a wall's
    k = camera.intrinsics
    rays_cam = np.column_stack([(cc - k.cx_px) / k.fx_px, (rr - k.cy_px) / k.fy_px, np.ones(len(rr))])
    plane_z = plane_depths(rays_cam, camera, [Plane(normal, -float(normal @ world[0]), "wall")])[0]
    seen = np.isfinite(plane_z)
    return float(np.median(d[seen] - plane_z[seen])) if np.any(seen) else 0.0


def _area(f: Front) -> float:
    c = f.corners_world_m
    return _width_m(f) * float(np.linalg.norm(c[3] - c[0]))


def _photo_m_per_px(face: Face, camera: Camera) -> float:
    """Metres of ``face`` (at its centre) one photo pixel spans."""
    centre = face.points(np.array(0.5 * face.width_m), np.array(0.5 * face.height_m))
    return float(np.linalg.norm(centre - camera.position_m)) / camera.intrinsics.fx_px


def with_fronts(objects: tuple[PerceivedObject, ...], observation: Observation, camera: Camera, walls: tuple[Plane, ...] = ()) -> tuple[PerceivedObject, ...]:
    """``objects`` with the fronts seen on the face of each that can have them (see the module
    docstring); the others unchanged. Objects are read on threads (one per usable core): most of
    the time is OpenCV and scipy, which free the interpreter; the result does not depend on it."""
    from concurrent.futures import ThreadPoolExecutor

    def one(obj: PerceivedObject) -> PerceivedObject:
        if obj.label not in FRONT_LABELS and obj.label not in MAYBE_FRONT_LABELS:
            return obj
        face = face_of(obj.points_world_m, camera.position_m, walls)
        if face.width_m <= 0.1 or face.height_m <= 0.1 or _photo_m_per_px(face, camera) > MAX_PHOTO_M_PER_PX:
            return obj
        face = refine_yaw(observation.rgb, camera, face, obj.points_world_m, obj.mask)
        depth = observation.depth_m if observation.depth_source == "sensor" else None
        fronts = fronts_on_face(observation.rgb, camera, face, obj.label, obj.mask, depth)
        if obj.label not in FRONT_LABELS and sum(f.handle_px is not None for f in fronts) < MIN_HANDLED_FRONTS:
            fronts = ()
        return replace(obj, fronts=fronts) if fronts else obj

    threads = min(usable_cores(), sum(o.label in FRONT_LABELS or o.label in MAYBE_FRONT_LABELS for o in objects))
    if threads <= 1:
        return tuple(map(one, objects))
    with ThreadPoolExecutor(threads, thread_name_prefix="fronts") as pool:
        return tuple(pool.map(one, objects))
