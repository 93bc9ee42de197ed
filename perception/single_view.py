"""Metric depth from one photo (backend ``"single-view-geometry"``): classical single-view room
layout, with no learned weights, optionally helped by a box detector's objects of known size.

The chain, each step a classical single-view-metrology result (all of it on the photo downscaled
to at most ``work_px`` = 640 px on the long side, so that any photo costs what a VGA one does):

1. **Line segments**: Canny edges and the probabilistic Hough transform (scikit-image).
2. **Manhattan frame** (:func:`manhattan_frame`): gravity and two horizontal room directions found
   jointly. Vertical hypotheses come from a RANSAC vertical vanishing point and from intersections
   of pairs of near-vertical segments; each is completed by every horizontal direction pair at
   2 deg steps and scored by the length of the segments pointing at one of the three vanishing
   points; the winner is refined on a 0.5 deg pitch/roll grid. (Consistency is the angle between
   a segment and the line from its midpoint to the point, for finite and infinite points alike.)
   On the 12 real RGB-D samples gravity is 0.4-5 deg from the floor plane fitted to their depth.
3. **Camera**: pitch and roll from gravity. Without known intrinsics the focal length is the field
   of view (40-100 deg) whose best Manhattan frame scores highest, kept when it beats the default
   60 deg by 3 % (a close-up, with no perspective, keeps the default).
4. **Floor plane and scale**: the camera-height prior puts the floor 1.3 m below the camera (chest
   to eye level of a standing photographer; the capture rigs of the real samples are at
   1.1-1.7 m). Every pixel below the horizon then has a floor depth ``z = h / (g . K^-1 [u, v, 1])``.
   With a detector, each detected chair, sofa, toilet or refrigerator whose whole height is in view
   gives the camera height by single-view metrology (its foot on the floor, its typical height
   from ``vocabulary``); the estimate is a score-weighted geometric mean with the prior.
5. **Floor region**: Felzenszwalb superpixels connected to the bottom of the image, below the
   horizon, and of the floor's colour (seeded from the bottom rows, detected objects left out) are
   grown into the floor; per column, the top of the floor run that starts at the bottom is the
   floor-wall / floor-object boundary (median-filtered across columns).
6. **Room box** (Manhattan prior, Hedau et al. 2009 / Lee et al. 2009 style, with the box's faces
   placed from the floor's extent rather than from learned surface labels): the back wall faces
   the camera at the 60th percentile of the floor contacts' forward distances (2-5 m) and behind
   the largest detected object, the side walls stand just beyond the widest floor contact on each
   side (at least 1.2 m out), the ceiling at ``ceiling_height_m``. Occluders hide the floor contact
   of what stands behind them, so a column's boundary is *not* taken as its wall's foot.
7. **Objects stand at their floor contact**: superpixels right above the boundary that are bounded
   above (they end below the image top and are narrower than 3/4 of it) stand as vertical
   billboards on their column's floor contact, when that is in front of the room box. Detected
   floor-standing objects (beds, sofas, chairs, tables, ...: :data:`BOX_CATEGORIES`) become
   cuboids of their category's typical size whose front face stands on the floor where the box's
   bottom edge meets it (a bed's top face and headboard recede as the real ones do).
8. **Close-ups** (``closeup_box_px``): a head-on photo of one large object (>= 30 segments,
   >= 60 % of the line length frame-aligned, >= 25 % horizontal and >= 25 % vertical, the lines'
   box covering >= 40 % of the image; true on all 10 URDFormer cabinet photos, false on all 19
   room photos) has no floor to scale by: its front face becomes a plane at the distance that
   gives it the typical width and height of the floor-standing articulated category whose
   proportions match best (``vocabulary``), the depth around it stays unknown, and the estimate
   carries the vertical vanishing point's up direction and a note saying how the scale was set
   (into the depth BackendUse reason).

Measured with ``python -m scene_builder.bench.single_photo --skip-time`` (12 real RGB-D samples
used as plain photos, their depth only for scoring; BENCHMARKS.md): median AbsRel 0.269 with no
weights and 0.195 with the COCO detector (``centernet-mbv3-coco``), against 0.281 for a constant
2.5 m (and 0.278 for this module before the Manhattan search and the objects of known size).
It is coarse (a room made of floor, ceiling, walls, billboards and cuboids) but metric,
deterministic and real.

Steps 1-3 (segments, vanishing points, the Manhattan frame and the camera) are
:mod:`perception.vanishing_points`; this module holds steps 4-8 (floor, room box, scale, objects).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from perception.protocols import DepthEstimate, Detections
from perception.vanishing_points import SingleViewGeometry, analysis_image, estimate_geometry
from scene_builder.errors import InputError
from scene_builder.model import CameraIntrinsics

__all__ = [
    "BOX_CATEGORIES",
    "CAMERA_HEIGHT_M",
    "BoxDetector",
    "CloseUp",
    "Detections",
    "PlacedBox",
    "closeup_box_px",
    "SingleViewDepth",
]

CAMERA_HEIGHT_M = 1.3
"""Prior height of the camera above the floor (a standing photographer); sets the metric scale."""


# --------------------------------------------------------------------------------------------
# Detected objects of known size (optional: a box detector's output)
# --------------------------------------------------------------------------------------------

#: Detector class names (COCO) of floor-standing things -> the vocabulary category whose typical
#: size (``scene_builder.vocabulary``) they get.
BOX_CATEGORIES = {
    "bed": "bed", "couch": "sofa", "sofa": "sofa", "chair": "chair", "dining table": "table", "table": "table",
    "desk": "desk", "toilet": "toilet", "refrigerator": "refrigerator", "oven": "oven", "potted plant": "plant",
}
#: Categories whose box top stands about above their front foot, so that their typical height can
#: set the scale (a table's or bed's box top is its far edge or headboard, so they are left out).
HEIGHT_CATEGORIES = frozenset({"chair", "sofa", "toilet", "refrigerator"})


#: Height of the back of objects whose back rises above their top (a bed's headboard, a sofa's back).
BACK_HEIGHT_M = {"bed": 1.1, "sofa": 0.85}


class BoxDetector(Protocol):
    """Named boxes in a photo (a learned detector; optional for single-view depth)."""

    def detect(self, rgb: np.ndarray) -> Detections:
        """rgb: (H, W, 3) uint8."""
        ...


@dataclass(frozen=True)
class PlacedBox:
    """A detected object stood on the floor as a cuboid: category (vocabulary label), box_px
    (u0, v0, u1, v1) in the analysis image, score, front_m (forward distance of its front face
    from the camera, horizontal), depth_m and height_m (its category's typical size), whether
    the box runs out of the image at the bottom or the top, and back_height_m (its back face's
    height: a headboard)."""

    category: str
    box_px: tuple[float, float, float, float]
    score: float
    front_m: float
    depth_m: float
    height_m: float
    cut_bottom: bool
    cut_top: bool
    back_height_m: float = 0.0

    @property
    def back_m(self) -> float:
        return self.front_m + self.depth_m


# --------------------------------------------------------------------------------------------
# Close-ups of one object (product photos)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CloseUp:
    """A photo showing one large object head-on. category: the vocabulary label whose typical size
    set the scale; box_px: (u0, v0, u1, v1) of the object; distance_m: its front face's depth;
    camera_height_m: implied height of the camera above the floor; note: a one-line reason."""

    category: str
    box_px: tuple[float, float, float, float]
    distance_m: float
    camera_height_m: float
    note: str


def closeup_box_px(segs: np.ndarray, h: int, w: int, min_segments: int = 30) -> tuple[float, float, float, float] | None:
    """(u0, v0, u1, v1) of the object when the segments (N, 4) say the photo is a head-on close-up of
    one object, else None.

    Cue (measured on the 10 URDFormer cabinet photos and 29 room photos of the shared data, at
    the <= 640 px analysis size): in a head-on product photo >= 60 % of the line length is within
    3 deg of the image axes, >= 25 % horizontal (drawer fronts, top, plinth) AND >= 25 % vertical
    (the carcass sides and door edges run the object's full height): on the cabinets 48-264
    segments, 28-66 % horizontal, 32-46 % vertical. Room photos have converging lines: at most 45 %
    horizontal with 10 % vertical (a bedroom), or 49 % vertical with 17 % horizontal (a corridor).
    A head-on kitchen wall of 23 mostly horizontal segments (issue 11) is no close-up: too few
    segments, too little vertical. The object is the 1st-99th percentile box of the segment end
    points, and it must cover at least 40 % of the image.
    """
    if len(segs) < min_segments:
        return None
    d = segs[:, 2:] - segs[:, :2]
    length = np.hypot(d[:, 0], d[:, 1])
    ang = np.degrees(np.arctan2(np.abs(d[:, 1]), np.abs(d[:, 0])))  # 0 = horizontal
    total = length.sum()
    horizontal, vertical = length[ang < 3.0].sum(), length[ang > 87.0].sum()
    if horizontal + vertical < 0.6 * total or horizontal < 0.25 * total or vertical < 0.25 * total:
        return None
    pts = np.concatenate([segs[:, :2], segs[:, 2:]])
    u0, u1 = np.percentile(pts[:, 0], [1, 99])
    v0, v1 = np.percentile(pts[:, 1], [1, 99])
    if (u1 - u0) * (v1 - v0) < 0.4 * h * w:
        return None
    return float(u0), float(v0), float(u1), float(v1)


# --------------------------------------------------------------------------------------------
# Depth from the geometry
# --------------------------------------------------------------------------------------------


class SingleViewDepth:
    """A ``DepthEstimator`` that needs no weights (see the module docstring for the chain).

    camera_height_m: the height prior that fixes the metric scale. ceiling_height_m: where the
    ceiling plane takes over from vertical surfaces. max_depth_m: depth cap (the far wall).
    """

    def __init__(
        self,
        camera_height_m: float = CAMERA_HEIGHT_M,
        ceiling_height_m: float = 2.6,
        max_depth_m: float = 10.0,
        default_fov_deg: float = 60.0,
        seed: int = 0,
        detector: "BoxDetector | None" = None,
    ) -> None:
        if not (camera_height_m > 0 and ceiling_height_m > camera_height_m and max_depth_m > 0):
            raise InputError("single-view depth: need 0 < camera height < ceiling height and a positive max depth")
        self.camera_height_m = camera_height_m
        self.ceiling_height_m = ceiling_height_m
        self.max_depth_m = max_depth_m
        self.default_fov_deg = default_fov_deg
        self.seed = seed
        self.work_px = 640  # long side of the image the floor and superpixels are computed on
        self.floor_colour_dist = 20.0  # CIE Lab distance to the floor seed colour
        self.max_floor_depth_m = 7.0  # farthest floor point a room is expected to show
        self.min_room_depth_m = 2.0  # nearest back wall of a room photo
        self.default_room_depth_m = 3.5  # back wall when no floor is seen
        self.min_half_width_m = 1.2  # side walls at least this far either side of the camera
        self.max_room_depth_m = 5.0  # farthest back wall
        self.back_wall_quantile = 0.6  # of the floor contacts' forward distances
        self.max_object_width_frac = 0.75  # wider superpixels are room surfaces
        self.last_geometry: SingleViewGeometry | None = None
        self.last_closeup: CloseUp | None = None
        self.closeup_surroundings = False  # close-ups: depth only on the object (0 = unknown around it)
        self.detector = detector
        self.min_box_score = 0.25  # detections below are ignored
        self.height_prior_weight = 1.0  # of the camera-height prior against each object (weight = its score)
        self.last_objects: tuple[PlacedBox, ...] = ()
        self.last_camera_height_m = camera_height_m
        self.last_scale_note: str | None = None

    def estimate(self, rgb: np.ndarray, intrinsics: CameraIntrinsics | None = None) -> DepthEstimate:
        """rgb: (H, W, 3) uint8. Returns (H, W) float32 metric depth; focal_px is set when the
        focal length was estimated from vanishing points.

        Everything is analysed at most ``work_px`` on the long side (the result is a piecewise
        planar room, so nothing is lost, and a 12 MP photo costs what a VGA one does); the depth
        is resized back to the input's size. ``last_geometry`` is in the analysis image's pixels.
        """
        from PIL import Image

        arr = np.asarray(rgb)
        if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8:
            raise InputError(f"expected an (H, W, 3) uint8 RGB image, got {arr.shape} {arr.dtype}")
        h, w = arr.shape[:2]
        small = analysis_image(arr, self.work_px)
        sh, sw = small.shape[:2]
        sx, sy = sw / w, sh / h
        k_small = None if intrinsics is None else intrinsics.scaled(sw, sh)
        geo = estimate_geometry(small, k_small, self.default_fov_deg, self.seed)
        self.last_geometry = geo
        if k_small is not None:
            fx, fy, cx, cy = k_small.fx_px, k_small.fy_px, k_small.cx_px, k_small.cy_px
        else:
            fx = fy = geo.focal_px
            cx, cy = (sw - 1) / 2.0, (sh - 1) / 2.0
        boxes = self.detector.detect(small) if self.detector is not None else None
        self.last_closeup = None
        self.last_objects, self.last_scale_note, self.last_camera_height_m = (), None, self.camera_height_m
        closeup = closeup_box_px(geo.segments, sh, sw)
        if closeup is not None:
            d_small, cu = self._closeup_depth(closeup, fx, fy, cx, cy, sh, sw)
            u0, v0, u1, v1 = cu.box_px
            self.last_closeup = replace(cu, box_px=(u0 / sx, v0 / sy, u1 / sx, v1 / sy))  # input pixels
        else:
            d_small = self._depth(small, geo.gravity_cam, fx, fy, cx, cy, boxes)
        if (sh, sw) != (h, w):
            resample = Image.Resampling.NEAREST if closeup is not None else Image.Resampling.BILINEAR
            depth = np.asarray(Image.fromarray(d_small.astype(np.float32)).resize((w, h), resample))
        else:
            depth = d_small
        focal = geo.focal_px / sx if geo.focal_source == "vanishing-points" else None
        note = up = None
        if self.last_closeup is not None:
            # the close-up has no floor to fit; its gravity is the vertical vanishing point's
            note, up = self.last_closeup.note, -geo.gravity_cam
        else:
            parts = []
            if self.detector is not None:
                cats = sorted({b.category for b in self.last_objects})
                parts.append(f"{len(self.last_objects)} detected objects of known size stood on the floor as cuboids ({', '.join(cats)})"
                             if cats else "the detector found no floor-standing object of known size")
            if self.last_scale_note:
                parts.append(self.last_scale_note)
            note = "; ".join(parts) or None
        return DepthEstimate(depth_m=depth.astype(np.float32), focal_px=focal, note=note, up_cam=up)

    def _closeup_depth(self, box_px: tuple[float, float, float, float], fx: float, fy: float, cx: float, cy: float,
                       h: int, w: int) -> tuple[np.ndarray, "CloseUp"]:
        """(H, W) depth of a close-up of one object: its front face a plane facing the camera at the
        distance that gives it the typical size of the floor-standing furniture category whose
        width/height ratio matches its box best. Around it the depth is unknown (0) unless
        ``closeup_surroundings``: then the floor under its bottom edge and a backdrop 1 m behind its
        typical depth (off by default: the sliver of floor such a photo shows is too thin for a
        floor fit, and the fitted plane then tilts the world). Assumes a level, frontal camera."""
        from scene_builder.vocabulary import CATEGORIES

        u0, v0, u1, v1 = box_px
        w_px, h_px = max(u1 - u0, 1.0), max(v1 - v0, 1.0)
        aspect = (w_px / fx) / (h_px / fy)
        cands = [c for c in CATEGORIES if c.kind.value == "articulated" and c.on_floor and not c.fixed]
        cat = min(cands, key=lambda c: abs(np.log(aspect * c.typical_size_m[2] / c.typical_size_m[1])))
        depth_x, width_y, height_z = cat.typical_size_m
        # distance from the geometric mean of the two size ratios: D * w_px / fx = width, ...
        dist_m = float(np.sqrt((fx * width_y / w_px) * (fy * height_z / h_px)))
        # the camera height that puts the floor under the object's bottom edge at that distance
        cam_h = max(dist_m * (v1 - cy) / fy, 0.1)
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        inside = (u >= u0) & (u <= u1) & (v >= v0) & (v <= v1)
        slope = (v - cy) / fy
        floor_z = np.where(slope > 1e-6, cam_h / np.maximum(slope, 1e-6), np.inf)
        backdrop = dist_m + depth_x + 1.0
        depth = np.where(inside, dist_m, np.minimum(floor_z, backdrop)) if self.closeup_surroundings else np.where(inside, dist_m, 0.0)
        note = (f"close-up of one object (frame-aligned lines filling the image): scaled to a typical {cat.name} "
                f"({width_y:.2f} m wide, {height_z:.2f} m high) at {dist_m:.2f} m")
        return depth, CloseUp(cat.name, box_px, dist_m, cam_h, note)

    # -- internals ---------------------------------------------------------------------------

    def _depth(self, rgb: np.ndarray, g: np.ndarray, fx: float, fy: float, cx: float, cy: float,
               boxes: "Detections | None" = None) -> np.ndarray:
        """(H, W) float64 depth of a box room (floor, ceiling, back and side walls) with the
        objects that stand on the floor in front of it.

        Occluders hide the floor contact of whatever stands behind them, so the floor-wall
        boundary of a column says where the *occluder* stands, not the wall: only superpixels
        that touch the boundary and are bounded above (they end below the top of the image and
        are narrower than half of it) stand at their contact; everything else above the floor
        is the room, whose walls are placed at the farthest plausible floor contacts. Detected
        floor-standing objects (``boxes``) become cuboids of their category's typical size
        standing on the floor at their box's bottom edge, and their heights refine the camera
        height (:meth:`_camera_height`).
        """
        h, w = rgb.shape[:2]
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        rays = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], axis=-1)  # (H, W, 3), z = 1
        down = rays @ g  # (H, W): height drop per unit depth along each ray
        # Horizontal camera axes: forward f (optical axis with gravity removed), right r.
        fwd = np.array([0.0, 0.0, 1.0]) - g[2] * g
        fwd /= np.linalg.norm(fwd)
        right = np.cross(g, fwd)  # x right in a level camera (g = +y, f = +z -> r = +x)
        placed = self._place_boxes(boxes, rays, down, fwd, h, w)
        cam_h = self._camera_height(placed, rays, down, g)
        placed = [replace(b, front_m=b.front_m * cam_h) for b in placed]  # metres, now the height is known
        floor_z = np.where(down > 1e-6, cam_h / np.maximum(down, 1e-6), np.inf)
        up = max(self.ceiling_height_m - cam_h, 0.3)
        ceil_z = np.where(down < -1e-6, up / np.maximum(-down, 1e-6), np.inf)

        in_box = np.zeros((h, w), dtype=np.bool_)
        for b in placed:
            u0, v0, u1, v1 = b.box_px
            in_box[int(v0) : int(np.ceil(v1)) + 1, int(u0) : int(np.ceil(u1)) + 1] = True
        labels = self._superpixels(rgb)
        floor = self._floor_mask(rgb, labels, down, cam_h, exclude=in_box) & ~in_box
        boundary = self._boundary_rows(floor)  # (W,) float: top row of the bottom floor run
        cols = np.arange(w)
        b_rows = np.clip(boundary.astype(np.int64), 0, h - 1)
        has_floor = floor[np.clip(b_rows + 1, 0, h - 1), cols] | floor[b_rows, cols]

        contact = rays[b_rows, cols] * np.minimum(floor_z[b_rows, cols], self.max_floor_depth_m)[:, None]  # (W, 3)
        c_fwd, c_right = contact @ fwd, contact @ right

        # Back wall: a Manhattan plane facing the camera at the farthest plausible floor contact
        # (upper quantile over the columns that see floor), within the room's expected extent,
        # and behind every detected object.
        if has_floor.sum() >= max(3, w // 20):
            back_m = float(np.quantile(c_fwd[has_floor], self.back_wall_quantile))
        else:
            back_m = self.default_room_depth_m
        if placed:  # the wall stands behind the largest detected object (far ones may be in the next room)
            largest = max(placed, key=lambda b: (b.box_px[2] - b.box_px[0]) * (b.box_px[3] - b.box_px[1]))
            back_m = max(back_m, min(largest.back_m + 0.2, self.max_room_depth_m))
        back_m = float(np.clip(back_m, self.min_room_depth_m, self.max_room_depth_m))
        # Side walls: just beyond the widest floor contact on each side, at least half a room
        # width out (a photo rarely shows the side walls' floor line).
        left_m = max(self.min_half_width_m, float(-c_right[has_floor].min()) if has_floor.any() else 0.0)
        right_m = max(self.min_half_width_m, float(c_right[has_floor].max()) if has_floor.any() else 0.0)
        r_fwd, r_right = rays @ fwd, rays @ right
        with np.errstate(divide="ignore", invalid="ignore"):
            back_z = np.where(r_fwd > 1e-6, back_m / r_fwd, np.inf)
            side_z = np.where(r_right > 1e-6, right_m / r_right, np.where(r_right < -1e-6, left_m / -r_right, np.inf))
        room = np.minimum.reduce([floor_z, ceil_z, back_z, side_z])

        # Floor-standing objects: superpixels just above the floor boundary, bounded above.
        n_lab = labels.max() + 1
        flat = labels.ravel()
        top_row = np.full(n_lab, h, dtype=np.int64)
        np.minimum.at(top_row, flat, v.astype(np.int64).ravel())
        umin = np.full(n_lab, w, dtype=np.int64)
        umax = np.full(n_lab, -1, dtype=np.int64)
        np.minimum.at(umin, flat, u.astype(np.int64).ravel())
        np.maximum.at(umax, flat, u.astype(np.int64).ravel())
        above = np.clip(b_rows - 1, 0, h - 1)
        foot = np.zeros(n_lab, dtype=np.bool_)
        foot[labels[above[has_floor], cols[has_floor]]] = True
        obj_lab = foot & (top_row > 0.02 * h) & ((umax - umin + 1) < self.max_object_width_frac * w)
        obj_lab[np.unique(labels[floor])] = False
        obj = obj_lab[labels] & ~floor & (v < b_rows[None, :]) & ~in_box

        # Vertical billboard through each column's contact: the point of each ray closest to the
        # vertical line through the contact (solve s * r = X_c + t * g in least squares).
        col_contact = np.broadcast_to(contact[None], (h, w, 3))
        rr = np.sum(rays * rays, axis=-1)
        rc = np.sum(rays * col_contact, axis=-1)
        gc = col_contact @ g
        s = (rc - down * gc) / np.maximum(rr - down * down, 1e-9)
        obj_z = np.where(cam_h - s * down > self.ceiling_height_m, ceil_z, s)
        obj &= obj_z < room  # an object stands inside the room

        depth = np.where(floor, np.minimum(floor_z, room), np.where(obj, obj_z, room))
        for b in placed:  # detected objects: where a ray meets the cuboid before the room
            hit = self._cuboid_depth(b, rays, down, r_fwd, r_right, cam_h, h, w)
            depth = np.where(np.isfinite(hit) & (hit < depth), hit, depth)
        self.last_objects = tuple(placed)
        depth = np.where(np.isfinite(depth) & (depth > 0), depth, self.max_depth_m)
        return np.clip(depth, 0.1, self.max_depth_m)

    def _place_boxes(self, boxes: "Detections | None", rays: np.ndarray, down: np.ndarray, fwd: np.ndarray,
                     h: int, w: int) -> list["PlacedBox"]:
        """The detections of floor-standing categories of known size (:data:`BOX_CATEGORIES`) whose
        bottom edge lies below the horizon, as PlacedBox with their front and back distances for a
        camera 1 m above the floor (scaled by the camera height later)."""
        from scene_builder.vocabulary import category

        out: list[PlacedBox] = []
        if boxes is None:
            return out
        # The detector's own class names (COCO's "couch", "potted plant"), vocabulary labels otherwise.
        names = getattr(boxes, "classes", None) or boxes.labels
        for (x0, y0, x1, y1), lab, score in zip(np.asarray(boxes.boxes_xyxy_px, dtype=np.float64), names, boxes.scores):
            name = BOX_CATEGORIES.get(str(lab))
            if name is None or score < self.min_box_score:
                continue
            u0, u1 = float(np.clip(x0, 0, w - 1)), float(np.clip(x1, 0, w - 1))
            v0, v1 = float(np.clip(y0, 0, h - 1)), float(np.clip(y1, 0, h - 1))
            if (u1 - u0) * (v1 - v0) < 0.002 * h * w or (u1 - u0) > 0.95 * w:
                continue
            uc = int(round(0.5 * (u0 + u1)))
            vb = int(round(v1))
            if down[vb, uc] <= 0.02:  # its foot is at or above the horizon: not on this floor
                continue
            cut = vb >= h - 2  # runs out of the image at the bottom: its front is nearer still
            front = float(rays[vb, uc] @ fwd / down[vb, uc]) * (0.9 if cut else 1.0)
            depth_x, _, height_z = category(name).typical_size_m
            back_h = max(height_z, BACK_HEIGHT_M.get(name, 0.0))
            out.append(PlacedBox(name, (u0, v0, u1, v1), float(score), front, depth_x, height_z, cut, v0 <= 1.0, back_h))
        return out

    def _camera_height(self, placed: list["PlacedBox"], rays: np.ndarray, down: np.ndarray, g: np.ndarray) -> float:
        """Camera height above the floor: the prior, refined by the detected objects whose full
        height is in view and whose top stands above their front foot (chairs, sofas, toilets,
        refrigerators; single-view metrology: with the foot on the floor, the ratio of the
        object's height to the camera's follows from the two image rows alone). A weighted
        geometric mean of the prior (weight ``height_prior_weight``) and each estimate (weight
        its detection score), clipped to 0.9-1.9 m. Records ``last_camera_height_m`` and
        ``last_scale_note``."""
        logs, weights, used = [np.log(self.camera_height_m)], [self.height_prior_weight], []
        for b in placed:
            if b.cut_bottom or b.cut_top or b.category not in HEIGHT_CATEGORIES:
                continue
            u0, v0, u1, v1 = b.box_px
            uc, vb, vt = int(round(0.5 * (u0 + u1))), int(round(v1)), int(round(v0))
            contact = rays[vb, uc] / down[vb, uc]  # the foot, for a camera 1 m above the floor
            r = rays[vt, uc]
            # the point of the top row's ray closest to the vertical through the foot
            s = (r @ contact - (r @ g) * (contact @ g)) / max(r @ r - (r @ g) ** 2, 1e-9)
            ratio = 1.0 - s * float(r @ g)  # object height / camera height
            if not 0.15 < ratio < 2.5:
                continue
            logs.append(np.log(b.height_m / ratio))
            weights.append(b.score)
            used.append(b.category)
        cam_h = float(np.clip(np.exp(np.average(logs, weights=weights)), 0.9, 1.9))
        self.last_camera_height_m = cam_h
        if used:
            self.last_scale_note = (f"metric scale from a {self.camera_height_m:.1f} m camera-height prior and the typical height of "
                                    f"{len(used)} detected object(s) ({', '.join(sorted(set(used)))}): camera {cam_h:.2f} m above the floor")
        else:
            self.last_scale_note = None
        return cam_h

    @staticmethod
    def _cuboid_depth(b: "PlacedBox", rays: np.ndarray, down: np.ndarray, r_fwd: np.ndarray, r_right: np.ndarray,
                      cam_h: float, h: int, w: int) -> np.ndarray:
        """(H, W) depth where the rays inside the object's box meet its cuboid (front face at
        ``front_m``, ``depth_m`` deep, ``height_m`` high, standing on the floor), inf elsewhere.
        The cuboid is as wide as its front face (the box's bottom corners at the front distance,
        unbounded on a side where the box runs out of the image): the image box of a cuboid is
        its front's width all the way up, but its top and back recede and narrow in the image,
        so a ray through the box's upper corners passes beside it (a bed 1.6 m wide otherwise
        grew to 2.4 m at its back)."""
        out = np.full((h, w), np.inf)
        u0, v0, u1, v1 = b.box_px
        sl = (slice(int(v0), int(np.ceil(v1)) + 1), slice(int(u0), int(np.ceil(u1)) + 1))
        f, d, r = r_fwd[sl], down[sl], r_right[sl]
        front, back = b.front_m, b.back_m
        vb = min(int(round(v1)), h - 1)
        ua, ub = int(np.clip(round(u0), 0, w - 1)), int(np.clip(round(u1), 0, w - 1))
        left = -np.inf if u0 <= 1.0 else front * r_right[vb, ua] / r_fwd[vb, ua]
        right = np.inf if u1 >= w - 2.0 else front * r_right[vb, ub] / r_fwd[vb, ub]
        with np.errstate(divide="ignore", invalid="ignore"):
            t_front = front / f
            hgt = cam_h - t_front * d
            t_top = np.where(d > 1e-6, (cam_h - b.height_m) / d, np.inf)
            beside_top = (t_top * r < left) | (t_top * r > right)
            on_top = (hgt > b.height_m) & (t_top * f >= front) & (t_top * f <= back) & ~beside_top
            t_back = back / f
            hgt_back = cam_h - t_back * d
            beside_back = (t_back * r < left) | (t_back * r > right)
            on_back = (hgt > b.height_m) & ~on_top & (hgt_back >= 0) & (hgt_back <= b.back_height_m) & ~beside_back
        z = np.where((hgt >= 0) & (hgt <= b.height_m), t_front, np.where(on_top, t_top, np.where(on_back, t_back, np.inf)))
        out[sl] = z
        return out

    def _superpixels(self, rgb: np.ndarray) -> np.ndarray:
        """(H, W) int64 Felzenszwalb superpixel labels 0..K-1 (scale grows with image size)."""
        from skimage.segmentation import felzenszwalb

        h, w = rgb.shape[:2]
        scale = 200.0 * (h * w) / (640 * 480)
        return felzenszwalb(rgb, scale=scale, sigma=0.8, min_size=int(max(50, 0.0005 * h * w))).astype(np.int64)

    def _floor_mask(self, rgb: np.ndarray, labels: np.ndarray, down: np.ndarray, cam_h: float,
                    exclude: np.ndarray | None = None) -> np.ndarray:
        """(H, W) bool floor pixels: superpixels grown from the bottom rows, below the horizon,
        close in colour (Lab) to the bottom-centre seed. exclude: (H, W) bool pixels kept out of
        the seed (detected objects), unless they cover more than 90 % of the seed band."""
        from skimage.color import rgb2lab

        h, w = labels.shape
        n_lab = labels.max() + 1
        lab_img = rgb2lab(rgb).reshape(-1, 3)
        counts = np.bincount(labels.ravel(), minlength=n_lab).astype(np.float64)
        mean_lab = np.stack([np.bincount(labels.ravel(), weights=lab_img[:, k], minlength=n_lab) for k in range(3)], 1)
        mean_lab /= np.maximum(counts, 1)[:, None]
        below = np.bincount(labels.ravel(), weights=(down > 0.02).ravel().astype(np.float64), minlength=n_lab)
        below_frac = below / np.maximum(counts, 1)
        # The seed band skips the outermost 3% (NYU-style frames have a constant border).
        rows, cols = slice(int(h * 0.85), int(h * 0.97)), slice(int(w * 0.05), int(w * 0.95))
        band = labels[rows, cols]
        if exclude is not None and (~exclude[rows, cols]).sum() >= 0.1 * band.size:
            band = band[~exclude[rows, cols]]
        seed_labels, seed_counts = np.unique(band, return_counts=True)
        # Seed: the superpixels covering the bottom band, weighted by their share of it.
        seed_colour = (mean_lab[seed_labels] * seed_counts[:, None]).sum(0) / seed_counts.sum()
        dist = np.linalg.norm(mean_lab - seed_colour, axis=1)
        # A floor superpixel lies below the horizon, has the floor's colour, and its farthest
        # floor point (its top row) is within the room (walls near the horizon would otherwise
        # read as floor kilometres away).
        top_row = np.full(n_lab, h, dtype=np.int64)
        np.minimum.at(top_row, labels.ravel(), np.repeat(np.arange(h), w))
        far_floor = np.array([cam_h / max(float(down[r, :].max()), 1e-6) for r in range(h)])
        candidate = (below_frac > 0.95) & (dist < self.floor_colour_dist) & (far_floor[np.minimum(top_row, h - 1)] < self.max_floor_depth_m)
        # Grow through 4-neighbour adjacency from the bottom-touching candidates.
        adj_a = np.concatenate([labels[:, :-1].ravel(), labels[:-1, :].ravel()])
        adj_b = np.concatenate([labels[:, 1:].ravel(), labels[1:, :].ravel()])
        diff = adj_a != adj_b
        pairs = np.unique(np.stack([adj_a[diff], adj_b[diff]], 1), axis=0)
        in_floor = np.zeros(n_lab, dtype=np.bool_)
        in_floor[seed_labels[seed_counts >= 0.02 * band.size]] = True
        in_floor &= candidate
        changed = True
        while changed:
            grow = (in_floor[pairs[:, 0]] & candidate[pairs[:, 1]] & ~in_floor[pairs[:, 1]]) | (
                in_floor[pairs[:, 1]] & candidate[pairs[:, 0]] & ~in_floor[pairs[:, 0]]
            )
            new = np.unique(np.concatenate([pairs[grow, 0], pairs[grow, 1]]))
            new = new[candidate[new] & ~in_floor[new]]
            changed = len(new) > 0
            in_floor[new] = True
        return in_floor[labels] & (down > 1e-3)

    def _boundary_rows(self, floor: np.ndarray) -> np.ndarray:
        """(W,) float64: per column, the top row of the floor run that starts at the bottom edge
        (the bottom row itself when the column has no floor), median-filtered across columns."""
        from scipy.ndimage import median_filter

        h, w = floor.shape
        # Row index of the first non-floor pixel scanning upwards from the bottom.
        rev = ~floor[::-1, :]
        first_non = np.where(rev.any(axis=0), np.argmax(rev, axis=0), h)
        top = (h - first_non).astype(np.float64)  # top row of the bottom run (h when no floor)
        top = np.clip(top, 0, h - 1)
        k = max(3, (w // 40) | 1)
        return median_filter(top, size=k, mode="nearest")
