"""People and animals are not part of a room.

A twin is the room a robot will act in: the person standing in front of the sofa, the cat on the
bed are not furniture. Painted onto the background they would stand as flat cut-outs on the wall
and the bed (seen from anywhere but the photo's camera, a person's silhouette stretched over the
room); turned into objects they would be nonsense. Their pixels are removed: no object takes them,
no depth cluster becomes an object from them, and the background fills what they hid (the room's
planes behind them, the colour inpainted from around them; :mod:`perception.background`).

Their outlines come from the same box segmenter as the objects' (SAM 2 or GrabCut), prompted with
the detectors' boxes of people and animals at a confident score.
"""

from __future__ import annotations

import numpy as np

from perception.detection import CONFIDENT
from perception.protocols import Detections, SemanticMap

__all__ = ["PEOPLE_CLASSES", "people_boxes", "people_pixels", "removal_mask"]

#: Detector classes (COCO, Open Images) of people and animals.
PEOPLE_CLASSES = frozenset(
    {
        "person", "cat", "dog", "bird", "horse", "sheep", "cow", "elephant", "bear", "zebra", "giraffe",
        "Person", "Cat", "Dog", "Cattle",
    }
)
#: A box of a person needs this (rescaled, :func:`perception.detection.merge_detections`) score:
#: the Open Images SSD scores pictures of people on a wall at 0.2-0.3 of its own scale.
PEOPLE_MIN_SCORE = CONFIDENT
#: Pixels this far around a person's cut are removed too (hair, motion blur, GrabCut's edge).
MARGIN_PX = 3
#: A weaker box of a person (down to this score) counts when the semantic map's people pixels
#: fill this share of it (two witnesses: a seated person the detector is unsure of).
WITNESSED_MIN_SCORE = 0.5 * CONFIDENT
WITNESSED_SHARE = 0.3
#: Semantic classes (PASCAL VOC) of people and animals.
_SEMANTIC_PEOPLE = frozenset({"person", "cat", "dog", "bird", "horse", "sheep", "cow"})


def people_pixels(sem: SemanticMap | None) -> np.ndarray | None:
    """(H, W) bool pixels a semantic map gives to people and animals, or None without a map
    that names its classes."""
    if sem is None or not sem.names:
        return None
    ids = [i for i, n in enumerate(sem.names) if n.lower() in _SEMANTIC_PEOPLE]
    return np.isin(np.asarray(sem.classes), ids)


def people_boxes(dets: Detections, seen: np.ndarray | None = None, min_score: float = PEOPLE_MIN_SCORE) -> np.ndarray:
    """(K, 4) xyxy boxes of the detections of people and animals, best first: confident ones
    (``min_score``), and weaker ones (down to :data:`WITNESSED_MIN_SCORE`) whose box the semantic
    map's people pixels ``seen`` ((H, W) bool or None) fill by :data:`WITNESSED_SHARE`."""
    keep = []
    for i, (c, s) in enumerate(zip(dets.classes, dets.scores)):
        if c not in PEOPLE_CLASSES or float(s) < WITNESSED_MIN_SCORE:
            continue
        if float(s) < min_score:
            if seen is None:
                continue
            h, w = seen.shape
            x0, y0, x1, y1 = np.clip(np.round(dets.boxes_xyxy_px[i]).astype(int), 0, [w, h, w, h])
            if x1 <= x0 or y1 <= y0 or seen[y0:y1, x0:x1].mean() < WITNESSED_SHARE:
                continue
        keep.append(i)
    keep.sort(key=lambda i: (-float(dets.scores[i]), i))
    return np.asarray([dets.boxes_xyxy_px[i] for i in keep], dtype=np.float64).reshape(-1, 4)


def removal_mask(masks: list[np.ndarray], shape: tuple[int, int]) -> np.ndarray:
    """(H, W) bool: the union of the people's (H, W) masks grown by :data:`MARGIN_PX`."""
    import cv2

    out = np.zeros(shape, dtype=bool)
    for m in masks:
        out |= np.asarray(m, dtype=bool)
    if out.any() and MARGIN_PX > 0:
        k = np.ones((2 * MARGIN_PX + 1, 2 * MARGIN_PX + 1), np.uint8)
        out = cv2.dilate(out.astype(np.uint8), k) > 0
    return out
