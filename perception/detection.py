"""Object detector classes mapped to the project vocabulary, and the box arithmetic shared by the
detector backends (:mod:`perception.learned.detectors`) and the detection-driven segmenter
(:mod:`perception.segment_detect`).

Detectors name far more than furniture (people, animals, vehicles, food); only the classes that
are things of a room map to a label of :mod:`scene_builder.vocabulary`; the rest are dropped.
Scores of different detectors are not on one scale (the Open Images SSD gives its sigmoid scores
of 0.4 to plain wall; CenterNet's best room detections score 0.35-0.65; Grounding DINO's demo
trusts its token similarities from 0.35): each detector states the
score at which one of its detections is trusted alone (``accept_score``) and
:func:`merge_detections` rescales every detector so that this score becomes
:data:`CONFIDENT`.
"""

from __future__ import annotations

import numpy as np

from perception.protocols import Detections, keywords_taken

__all__ = [
    "COCO_CLASSES",
    "COCO_TO_LABEL",
    "CONFIDENT",
    "FAMILIES",
    "OID_TO_LABEL",
    "PASCAL_TO_LABEL",
    "box_inside",
    "box_iou",
    "box_is_slice",
    "empty_detections",
    "family",
    "merge_detections",
    "refine_in_family",
    "suppress",
]

#: The standard 80-class COCO order (index = the detector's class index).
COCO_CLASSES: tuple[str, ...] = (
    "person", "bicycle", "car", "motorcycle", "airplane", "bus", "train", "truck", "boat", "traffic light",
    "fire hydrant", "stop sign", "parking meter", "bench", "bird", "cat", "dog", "horse", "sheep", "cow",
    "elephant", "bear", "zebra", "giraffe", "backpack", "umbrella", "handbag", "tie", "suitcase", "frisbee",
    "skis", "snowboard", "sports ball", "kite", "baseball bat", "baseball glove", "skateboard", "surfboard",
    "tennis racket", "bottle", "wine glass", "cup", "fork", "knife", "spoon", "bowl", "banana", "apple",
    "sandwich", "orange", "broccoli", "carrot", "hot dog", "pizza", "donut", "cake", "chair", "couch",
    "potted plant", "bed", "dining table", "toilet", "tv", "laptop", "mouse", "remote", "keyboard",
    "cell phone", "microwave", "oven", "toaster", "sink", "refrigerator", "book", "clock", "vase",
    "scissors", "teddy bear", "hair drier", "toothbrush",
)  # fmt: skip

#: COCO class -> vocabulary label. Left out: people, animals, vehicles, food, cutlery and things
#: smaller than a few centimetres (mouse, remote, phone, scissors, toothbrush): not worth an
#: asset of their own, and the static background keeps their look.
COCO_TO_LABEL: dict[str, str] = {
    "bench": "bench",
    "backpack": "bag",
    "handbag": "bag",
    "suitcase": "suitcase",
    "bottle": "bottle",
    "wine glass": "mug",
    "cup": "mug",
    "bowl": "bowl",
    "chair": "chair",
    "couch": "sofa",
    "potted plant": "plant",
    "bed": "bed",
    "dining table": "table",
    "toilet": "toilet",
    "tv": "tv",
    "laptop": "laptop",
    "keyboard": "keyboard",
    "microwave": "microwave",
    "oven": "oven",
    "sink": "sink",
    "refrigerator": "refrigerator",
    "book": "book",
    "clock": "clock",
    "vase": "vase",
    "teddy bear": "soft_toy",
}

#: Open Images (the SSD's 23 classes) -> vocabulary label.
OID_TO_LABEL: dict[str, str] = {
    "Chair": "chair",
    "Desk": "desk",
    "Table": "table",
    "Laptop": "laptop",
    "Computer monitor": "monitor",
    "Box": "box",
    "Mug": "mug",
    "Coffee cup": "mug",
    "Bottle": "bottle",
    "Book": "book",
}

#: PASCAL VOC (the DeepLab map's 21 classes) -> vocabulary label.
PASCAL_TO_LABEL: dict[str, str] = {
    "chair": "chair",
    "diningtable": "table",
    "sofa": "sofa",
    "tvmonitor": "tv",
    "pottedplant": "plant",
    "bottle": "bottle",
}

#: Labels one object is often given by different detectors (or by one detector twice): boxes of
#: one family suppress each other. A label not listed is its own family.
FAMILIES: tuple[frozenset[str], ...] = (
    frozenset({"table", "desk"}),
    frozenset({"tv", "monitor"}),
    frozenset({"mug", "bowl", "vase"}),
    frozenset({"sofa", "bench", "bed"}),
    frozenset({"bag", "suitcase"}),
    frozenset({"cabinet", "drawer_unit", "wardrobe"}),
)

#: A detection at its detector's ``accept_score`` gets this confidence after
#: :func:`merge_detections`.
CONFIDENT = 0.5


def family(label: str) -> frozenset[str]:
    """The family of ``label`` (see :data:`FAMILIES`)."""
    for f in FAMILIES:
        if label in f:
            return f
    return frozenset({label})


def empty_detections() -> Detections:
    return Detections(np.zeros((0, 4)), np.zeros(0, dtype=np.float32), (), ())


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(len(a), len(b)) intersection over union of (N, 4) and (M, 4) xyxy boxes."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.prod(np.clip(rb - lt, 0.0, None), axis=2)
    area_a = np.prod(np.clip(a[:, 2:] - a[:, :2], 0.0, None), axis=1)
    area_b = np.prod(np.clip(b[:, 2:] - b[:, :2], 0.0, None), axis=1)
    union = area_a[:, None] + area_b[None, :] - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)


#: A box is a slice of another when it lies inside it (0.9 of its area), shares three of its
#: four sides (each within SLICE_TOL of the other's side length, at least SLICE_TOL_PX) and
#: covers at least SLICE_MIN_SHARE of its area.
SLICE_TOL = 0.05
SLICE_TOL_PX = 4.0
SLICE_MIN_SHARE = 0.3


def box_inside(box: np.ndarray, other: np.ndarray, share: float = 0.7) -> bool:
    """Whether ``share`` of xyxy box ``box`` (4,) lies inside xyxy box ``other`` (4,)."""
    ix = max(0.0, min(box[2], other[2]) - max(box[0], other[0])) * max(0.0, min(box[3], other[3]) - max(box[1], other[1]))
    return ix >= share * max((box[2] - box[0]) * (box[3] - box[1]), 1e-9)


def box_is_slice(inner: np.ndarray, outer: np.ndarray) -> bool:
    """Whether xyxy box ``inner`` (4,) is a slice of xyxy box ``outer`` (4,): its full width or
    its full height (a cabinet's lower drawers, a bed's foot). A thing on or in front of another
    (a lamp on a dresser, a book on a bed) shares at most two of its sides."""
    inner, outer = np.asarray(inner, dtype=np.float64), np.asarray(outer, dtype=np.float64)
    ow, oh = outer[2] - outer[0], outer[3] - outer[1]
    iw, ih = inner[2] - inner[0], inner[3] - inner[1]
    if ow <= 0 or oh <= 0 or iw <= 0 or ih <= 0:
        return False
    if not box_inside(inner, outer, 0.9) or iw * ih < SLICE_MIN_SHARE * ow * oh:
        return False
    tol = np.maximum(SLICE_TOL * np.array([ow, oh, ow, oh]), SLICE_TOL_PX)
    return int(np.sum(np.abs(inner - outer) <= tol)) >= 3


def _take(d: Detections, idx: np.ndarray, scores: np.ndarray | None = None) -> Detections:
    idx = np.asarray(idx, dtype=np.int64)
    s = d.scores[idx] if scores is None else scores
    return Detections(d.boxes_xyxy_px[idx], np.asarray(s, dtype=np.float32), tuple(d.labels[i] for i in idx), tuple(d.classes[i] for i in idx))


def suppress(d: Detections, iou_threshold: float = 0.5, across_families: float = 0.8) -> Detections:
    """Non-maximum suppression within each label family (OpenCV's ``NMSBoxes``), then across
    families for nearly the same box (IoU ``across_families``: one detector calling one thing a
    table and a chair); best first."""
    import cv2

    keep: list[int] = []
    for fam in sorted({tuple(sorted(family(lab))) for lab in d.labels}):
        idx = np.flatnonzero([lab in fam for lab in d.labels])
        b = d.boxes_xyxy_px[idx]
        rects = [[float(x0), float(y0), float(x1 - x0), float(y1 - y0)] for x0, y0, x1, y1 in b]
        hit = cv2.dnn.NMSBoxes(rects, [float(s) for s in d.scores[idx]], 0.0, float(iou_threshold))
        keep.extend(int(idx[i]) for i in np.asarray(hit, dtype=np.int64).reshape(-1))
    order = sorted(keep, key=lambda i: (-float(d.scores[i]), i))
    iou = box_iou(d.boxes_xyxy_px[order], d.boxes_xyxy_px[order])
    named = [bool(d.labels[i]) for i in order]
    # A box of a class outside the vocabulary never suppresses one inside it (a person on a chair).
    # (A box suppressed across families still suppresses the weaker ones: they are the same box.)
    alive = [k for k in range(len(order)) if not any(iou[j, k] >= across_families and (named[j] or not named[k]) for j in range(k))]
    return _take(d, np.asarray([order[k] for k in alive], dtype=np.int64))


def merge_detections(parts: list[tuple[Detections, float]], iou_threshold: float = 0.5) -> Detections:
    """One set of detections from several detectors.

    parts: (detections, accept_score) per detector. Scores are first rescaled so that each
    detector's ``accept_score`` becomes :data:`CONFIDENT` (clipped to [0, 1]). Boxes of one label
    family from different detectors that overlap by ``iou_threshold`` are one object seen twice:
    the best box stays, with the label of the best score and the noisy-or of the scores
    (agreement of independent detectors is evidence). Boxes of different families that overlap by
    IoU 0.8 are one object named twice: the better-scored stays. The result is sorted by score.
    """
    boxes, scores, labels, classes, source = [], [], [], [], []
    for k, (d, accept) in enumerate(parts):
        if len(d) == 0:
            continue
        boxes.append(d.boxes_xyxy_px)
        scores.append(np.clip(CONFIDENT * np.asarray(d.scores, dtype=np.float64) / float(accept), 0.0, 1.0))
        labels.extend(d.labels)
        classes.extend(d.classes)
        source.extend([k] * len(d))
    if not labels:
        return empty_detections()
    b, s, src = np.concatenate(boxes), np.concatenate(scores), np.asarray(source)
    order = np.lexsort((np.arange(len(s)), -s))
    iou = box_iou(b, b)
    taken = np.zeros(len(s), dtype=bool)
    keep, fused = [], []
    for i in order:
        if taken[i]:
            continue
        taken[i] = True
        fam = family(labels[i])
        p_not = 1.0 - s[i]
        seen = {int(src[i])}
        for j in order:
            if taken[j] or int(src[j]) in seen or labels[j] not in fam or iou[i, j] < iou_threshold:
                continue
            taken[j] = True
            seen.add(int(src[j]))
            p_not *= 1.0 - s[j]
        keep.append(int(i))
        fused.append(1.0 - p_not)
    merged = Detections(b[keep], np.asarray(fused, dtype=np.float32), tuple(labels[i] for i in keep), tuple(classes[i] for i in keep))
    order2 = sorted(range(len(keep)), key=lambda i: (-float(merged.scores[i]), i))
    # Nearly the same box named differently by two detectors (a bed as "couch" and "Table"):
    # one object, the better-scored name.
    return suppress(_take(merged, np.asarray(order2, dtype=np.int64)), iou_threshold=1.01, across_families=0.8)


#: Within a detector's family, another member replaces its label when the size-aware namer's
#: posterior for it is this many times the label's (for a detection at its detector's accept
#: score, :data:`CONFIDENT`; times the detection's odds above it, see :func:`refine_in_family`).
REFINE_RATIO = 2.0


def refine_in_family(
    namer,
    names: list[tuple[str, float]],
    crops: list[tuple[np.ndarray, np.ndarray]],
    sizes: list[tuple[float, float, float]],
    heights_max_m: list[float | None] | None = None,
    lengths_max_m: list[float | None] | None = None,
) -> list[tuple[str, float]]:
    """Detector names refined within their family by a namer that weighs size and appearance
    (``label_scores_many``: EfficientNet-Lite0 with the size prior): a member of the family whose
    posterior is :data:`REFINE_RATIO` times the detector label's replaces it. names: (label,
    score) per object; crops: (crop_rgb, crop_mask) per object; sizes: gravity-aligned extents;
    heights_max_m: per object, None or its top's height when the photo's bottom edge cut it;
    lengths_max_m: per object, None or the most its length can be when a side edge of the photo cut it.
    Names of single-member families, and all names when the namer has no posterior, stay."""
    idx = [i for i, (lab, _) in enumerate(names) if len(family(lab)) > 1]
    if not idx or not hasattr(namer, "label_scores_many"):
        return list(names)
    # (a namer is asked without the bounds no object has, or that it does not take: a plug-in)
    bounds = {key: [vals[i] for i in idx] for key, vals in (("heights_max_m", heights_max_m), ("lengths_max_m", lengths_max_m))
              if vals is not None and any(vals[i] is not None for i in idx)}
    post = namer.label_scores_many([crops[i][0] for i in idx], [crops[i][1] for i in idx], [sizes[i] for i in idx],
                                   **keywords_taken(namer.label_scores_many, **bounds))
    out = list(names)
    for i, p in zip(idx, post):
        lab, score = names[i]
        best = max(sorted(family(lab)), key=lambda m: p.get(m, 0.0))
        # A surer detection takes surer evidence to rename: the ratio grows with its odds (a bed
        # boxed at 0.79 whose headboard the classifier took for a sofa's back stays a bed).
        odds = max(1.0, float(score) / max(1.0 - float(score), 1e-6))
        if best != lab and p.get(best, 0.0) >= REFINE_RATIO * odds * max(p.get(lab, 0.0), 1e-9):
            out[i] = (best, score)
    return out
