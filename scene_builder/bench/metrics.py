"""Metrics of a reconstructed scene against ground truth (pure numpy; scipy for the assignment,
shapely for exact rotated-rectangle overlap).

Conventions
-----------
* A :class:`Box3D` is gravity-aligned: ``center_m`` is the box centre, ``size_m`` its full extents
  along its own x (the heading ``(cos yaw, sin yaw, 0)``), y and z, ``yaw_rad`` the rotation about
  +Z. It is the ground-truth convention of :mod:`scene_builder.bench.procedural` and of the SUN RGB-D
  boxes in ``../shared/data`` (there ``size_m`` = [l, w, h] with l along the heading).
* Matching: Hungarian assignment (``scipy.optimize.linear_sum_assignment``) on mask IoU when masks
  exist (the procedural suite: perceived masks against the rendered instance ids; a pair needs
  IoU >= 0.25), else on 3D centre distance with a per-object gate
  (``max(0.3 m, 0.5 * diagonal of the true box)``; the SUN RGB-D boxes).
* Yaw error is taken modulo the box's symmetry: 180 degrees for a rectangle footprint, 90 for a
  square one (sides within 10 %).
* Size error is relative, per axis, after matching the predicted box's horizontal axes to the true
  ones (a box predicted 90 degrees off has its x and y swapped first).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "Box3D",
    "Match",
    "ObjectBox",
    "ObjectScores",
    "box_from_pose",
    "box_iou_3d",
    "category_accuracy",
    "depth_absrel",
    "mask_iou",
    "mask_iou_matrix",
    "match_by_center",
    "match_by_mask_iou",
    "median_or_none",
    "p90_or_none",
    "recall_precision",
    "relative_error",
    "scene_boxes",
    "score_objects",
    "size_error_rel",
    "yaw_error_deg",
    "yaw_period_deg",
]

SQUARE_TOLERANCE = 0.1  # footprint sides within 10 % count as a square (90 degree symmetry)
MIN_MASK_IOU = 0.25


@dataclass(frozen=True, eq=False)
class Box3D:
    """A gravity-aligned box: center_m (3,), size_m (3,) full extents in the box frame, yaw_rad."""

    center_m: np.ndarray
    size_m: np.ndarray
    yaw_rad: float

    def __post_init__(self) -> None:
        for name in ("center_m", "size_m"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            if arr.shape != (3,) or not np.all(np.isfinite(arr)):
                raise ValueError(f"Box3D.{name} must be 3 finite numbers, got {arr}")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if np.any(self.size_m < 0):
            raise ValueError("Box3D.size_m must be non-negative")
        object.__setattr__(self, "yaw_rad", float(self.yaw_rad))

    def footprint_xy(self) -> np.ndarray:
        """(4, 2) footprint corners, counter-clockwise."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        hx, hy = self.size_m[0] / 2, self.size_m[1] / 2
        local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
        return local @ np.array([[c, -s], [s, c]]).T + self.center_m[:2]

    @property
    def volume_m3(self) -> float:
        return float(np.prod(self.size_m))


def box_iou_3d(a: Box3D, b: Box3D) -> float:
    """Exact IoU of two gravity-aligned yawed boxes: footprint polygon overlap (shapely) times the
    overlap of the z intervals, over the union of the volumes."""
    from shapely.geometry import Polygon

    za = (a.center_m[2] - a.size_m[2] / 2, a.center_m[2] + a.size_m[2] / 2)
    zb = (b.center_m[2] - b.size_m[2] / 2, b.center_m[2] + b.size_m[2] / 2)
    dz = max(0.0, min(za[1], zb[1]) - max(za[0], zb[0]))
    if dz == 0.0:
        return 0.0
    area = Polygon(a.footprint_xy()).intersection(Polygon(b.footprint_xy())).area
    inter = area * dz
    union = a.volume_m3 + b.volume_m3 - inter
    return float(inter / union) if union > 0 else 0.0


def yaw_period_deg(size_m) -> float:
    """180 for a rectangular footprint, 90 for a square one (sides within 10 %)."""
    sx, sy = float(size_m[0]), float(size_m[1])
    return 90.0 if abs(sx - sy) <= SQUARE_TOLERANCE * max(sx, sy, 1e-9) else 180.0


def yaw_error_deg(pred_yaw_rad: float, true_yaw_rad: float, true_size_m) -> float:
    """Smallest angle (degrees, in [0, period / 2]) between the yaws modulo the true box's symmetry."""
    period = yaw_period_deg(true_size_m)
    d = np.degrees(pred_yaw_rad - true_yaw_rad) % period
    return float(min(d, period - d))


def size_error_rel(pred: Box3D, true: Box3D) -> np.ndarray:
    """(3,) |pred - true| / true per axis of the true box, after matching the horizontal axes
    (swap the predicted x and y when the yaws are closer to 90 degrees apart than to 0)."""
    d = np.degrees(pred.yaw_rad - true.yaw_rad) % 180.0
    p = pred.size_m.copy()
    if 45.0 < d < 135.0:
        p[[0, 1]] = p[[1, 0]]
    return np.abs(p - true.size_m) / np.maximum(true.size_m, 1e-9)


def relative_error(pred: float, true: float) -> float:
    """|pred - true| / true."""
    return float(abs(pred - true) / true)


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """IoU of two (H, W) bool masks (0 when both are empty)."""
    inter = np.logical_and(a, b).sum()
    union = np.logical_or(a, b).sum()
    return float(inter / union) if union else 0.0


def mask_iou_matrix(pred_masks: list[np.ndarray] | tuple[np.ndarray, ...], true_ids: np.ndarray, true_id_list) -> np.ndarray:
    """(N, M) IoU between N predicted (H, W) bool masks and the M instances ``true_id_list`` of the
    (H, W) integer instance image ``true_ids`` (one bincount per predicted mask)."""
    ids = np.asarray(true_id_list, dtype=np.int64)
    n_lab = int(max(true_ids.max(initial=0), ids.max(initial=0))) + 1
    true_area = np.bincount(true_ids.ravel().astype(np.int64), minlength=n_lab)[ids]
    out = np.zeros((len(pred_masks), len(ids)))
    for i, m in enumerate(pred_masks):
        inter = np.bincount(true_ids[m].astype(np.int64), minlength=n_lab)[ids]
        union = m.sum() + true_area - inter
        out[i] = np.where(union > 0, inter / np.maximum(union, 1), 0.0)
    return out


@dataclass(frozen=True)
class Match:
    """pairs: (pred index, true index) matched; scores: the IoU or the distance (m) of each pair."""

    pairs: tuple[tuple[int, int], ...]
    scores: tuple[float, ...]


def _assign(cost: np.ndarray, allowed: np.ndarray) -> list[tuple[int, int]]:
    from scipy.optimize import linear_sum_assignment

    if cost.size == 0:
        return []
    big = 1e6
    rows, cols = linear_sum_assignment(np.where(allowed, cost, big))
    return sorted((int(r), int(c)) for r, c in zip(rows, cols) if allowed[r, c])


def match_by_mask_iou(iou: np.ndarray, min_iou: float = MIN_MASK_IOU) -> Match:
    """Hungarian assignment maximising the summed IoU of an (N pred, M true) IoU matrix; pairs below
    ``min_iou`` are not matches."""
    pairs = _assign(-iou, iou >= min_iou)
    return Match(tuple(pairs), tuple(float(iou[i, j]) for i, j in pairs))


def match_by_center(pred_centers_m: np.ndarray, true_boxes: list[Box3D] | tuple[Box3D, ...], min_gate_m: float = 0.3) -> Match:
    """Hungarian assignment minimising the summed centre distance; a pair is allowed when the
    distance is below ``max(min_gate_m, 0.5 * diagonal of the true box)``.

    pred_centers_m: (N, 3)."""
    p = np.asarray(pred_centers_m, dtype=np.float64).reshape(-1, 3)
    t = np.array([b.center_m for b in true_boxes]).reshape(-1, 3)
    gate = np.array([max(min_gate_m, 0.5 * float(np.linalg.norm(b.size_m))) for b in true_boxes])
    dist = np.linalg.norm(p[:, None, :] - t[None, :, :], axis=-1)
    pairs = _assign(dist, dist <= gate[None, :])
    return Match(tuple(pairs), tuple(float(dist[i, j]) for i, j in pairs))


def recall_precision(n_matched_true: int, n_true: int, n_matched_pred: int, n_pred: int) -> tuple[float | None, float | None]:
    """(recall, precision); None where the denominator is 0."""
    recall = n_matched_true / n_true if n_true else None
    precision = n_matched_pred / n_pred if n_pred else None
    return recall, precision


def category_accuracy(pred_labels, true_labels, synonyms: dict[str, tuple[str, ...]] | None = None) -> float | None:
    """Fraction of matched pairs whose predicted label equals the true one (or one of its synonyms)."""
    if len(pred_labels) == 0:
        return None
    syn = synonyms or {}
    ok = [p == t or p in syn.get(t, ()) for p, t in zip(pred_labels, true_labels)]
    return float(np.mean(ok))


def depth_absrel(pred_m: np.ndarray, true_m: np.ndarray, mask: np.ndarray | None = None) -> float | None:
    """Mean |pred - true| / true over pixels where both are valid (> 0) and ``mask`` holds; None if
    there are none. pred_m, true_m: (H, W)."""
    valid = (pred_m > 0) & (true_m > 0)
    if mask is not None:
        valid &= mask
    if not valid.any():
        return None
    t = true_m[valid].astype(np.float64)
    return float(np.mean(np.abs(pred_m[valid].astype(np.float64) - t) / t))


def median_or_none(values) -> float | None:
    v = [float(x) for x in values if x is not None and np.isfinite(x)]
    return float(np.median(v)) if v else None


def p90_or_none(values) -> float | None:
    v = [float(x) for x in values if x is not None and np.isfinite(x)]
    return float(np.percentile(v, 90)) if v else None


# --------------------------------------------------------------------------------------------
# Object-level scoring of one scene
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ObjectBox:
    """An object reduced to what is scored: name, label, gravity-aligned box (in the ground-truth
    world frame), mass_kg (None when unknown) and visible (ground truth: enough pixels to count in
    recall; predictions: always True)."""

    name: str
    label: str
    box: Box3D
    mass_kg: float | None = None
    visible: bool = True


@dataclass(frozen=True)
class ObjectScores:
    """Scores of matched predictions against ground truth in one scene.

    recall: matched visible true objects / visible true objects. precision: matched predictions /
    predictions. Per matched pair (same order as ``pairs`` of (pred name, true name)):
    position_error_m (centre distance), yaw_error_deg, size_error_rel (mean over the 3 axes),
    mass_error_rel (None when either mass is unknown), box_iou.
    """

    n_true: int
    n_true_visible: int
    n_matched_visible: int
    n_pred: int
    recall: float | None
    precision: float | None
    category_accuracy: float | None
    pairs: tuple[tuple[str, str], ...]
    position_error_m: tuple[float, ...]
    yaw_error_deg: tuple[float, ...]
    size_error_rel: tuple[float, ...]
    mass_error_rel: tuple[float | None, ...]
    box_iou: tuple[float, ...]


def score_objects(
    pred: list[ObjectBox] | tuple[ObjectBox, ...],
    true: list[ObjectBox] | tuple[ObjectBox, ...],
    match: Match,
    synonyms: dict[str, tuple[str, ...]] | None = None,
) -> ObjectScores:
    """Score ``pred`` against ``true`` given a matching (indices into the two sequences)."""
    pairs = [(i, j) for i, j in match.pairs]
    n_vis = sum(1 for t in true if t.visible)
    matched_vis = sum(1 for _, j in pairs if true[j].visible)
    recall, precision = recall_precision(matched_vis, n_vis, len(pairs), len(pred))
    pos, yaw, size, mass, iou = [], [], [], [], []
    for i, j in pairs:
        p, t = pred[i].box, true[j].box
        pos.append(float(np.linalg.norm(p.center_m - t.center_m)))
        yaw.append(yaw_error_deg(p.yaw_rad, t.yaw_rad, t.size_m))
        size.append(float(np.mean(size_error_rel(p, t))))
        pm, tm = pred[i].mass_kg, true[j].mass_kg
        mass.append(relative_error(pm, tm) if pm is not None and tm else None)
        iou.append(box_iou_3d(p, t))
    return ObjectScores(
        n_true=len(true),
        n_true_visible=n_vis,
        n_matched_visible=matched_vis,
        n_pred=len(pred),
        recall=recall,
        precision=precision,
        category_accuracy=category_accuracy([pred[i].label for i, _ in pairs], [true[j].label for _, j in pairs], synonyms),
        pairs=tuple((pred[i].name, true[j].name) for i, j in pairs),
        position_error_m=tuple(pos),
        yaw_error_deg=tuple(yaw),
        size_error_rel=tuple(size),
        mass_error_rel=tuple(mass),
        box_iou=tuple(iou),
    )


def box_from_pose(world_from_object: np.ndarray, size_m, origin: str = "bottom") -> Box3D:
    """The gravity-aligned box of an object of extents ``size_m`` at a (4, 4) pose.

    origin: ``"bottom"`` when the pose's origin is the centre of the box's bottom face (the asset
    frame of :mod:`scene_builder.model`), ``"center"`` when it is the box centre. Yaw is the angle
    of the pose's x axis projected on the floor (the pose is assumed near gravity-aligned)."""
    size = np.asarray(size_m, dtype=np.float64)
    offset = np.array([0.0, 0.0, size[2] / 2.0]) if origin == "bottom" else np.zeros(3)
    center = world_from_object[:3, :3] @ offset + world_from_object[:3, 3]
    yaw = float(np.arctan2(world_from_object[1, 0], world_from_object[0, 0]))
    return Box3D(center, size, yaw)


def scene_boxes(scene, gt_from_world: np.ndarray) -> list[ObjectBox]:
    """Every placed object of a :class:`scene_builder.model.Scene` as an :class:`ObjectBox` in the
    ground-truth frame (``gt_from_world``: (4, 4) from the scene's world to the truth's)."""
    out = []
    for o in scene.objects:
        out.append(ObjectBox(o.name, o.asset.label, box_from_pose(gt_from_world @ o.world_from_asset, o.asset.size_m), o.asset.mass_kg))
    return out
