"""Small protocols behind which every perception backend sits (learned or geometric).

Registries of these live in :mod:`perception.backends`; ``perceive`` resolves one backend per task
and records the choice in ``Perception.backends``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from scene_builder.model import CameraIntrinsics


@dataclass(frozen=True, eq=False)
class DepthEstimate:
    """depth_m: (H, W) float32 planar metric depth, 0 where unknown, at the input resolution.
    focal_px: the focal length the model estimated (None if it does not estimate one).
    note: a one-line remark for the depth BackendUse reason (e.g. how the metric scale was set).
    up_cam: (3,) unit up direction in the OpenCV camera frame when the estimator measured one and
    the depth relies on it (perception uses it when no floor is visible)."""

    depth_m: np.ndarray
    focal_px: float | None = None
    note: str | None = None
    up_cam: np.ndarray | None = None


class DepthEstimator(Protocol):
    """Metric depth from one RGB image."""

    def estimate(self, rgb: np.ndarray, intrinsics: CameraIntrinsics | None) -> DepthEstimate:
        """rgb: (H, W, 3) uint8. intrinsics: known intrinsics, or None when only a default exists."""
        ...


@dataclass(frozen=True, eq=False)
class InstanceMasks:
    """labels: (H, W) int32, 0 = no instance, k > 0 = instance k (no pixel in two instances).
    scores: (K,) float32 confidence of instances 1..K.
    names: None, or K labels of ``scene_builder.vocabulary`` for instances 1..K given by the
    backend itself (a detector's class); ``""`` where the backend does not know (the naming
    backend names those).
    boxes_xyxy_px: None, or (K, 4) float64 the detector's box of each instance (NaN rows for
    instances without one); a detector's box reaches the floor contact that a mask may miss
    (thin legs, an occluded foot).
    removed: None, or (H, W) bool pixels of people and animals (in no instance): not part of the
    room; removed_count: how many of them (:mod:`perception.people`)."""

    labels: np.ndarray
    scores: np.ndarray
    names: tuple[str, ...] | None = None
    boxes_xyxy_px: np.ndarray | None = None
    removed: np.ndarray | None = None
    removed_count: int = 0


class InstanceSegmenter(Protocol):
    """Instance masks from an RGB image (and depth/geometry when the backend uses it)."""

    def segment(
        self,
        rgb: np.ndarray,
        depth_m: np.ndarray,
        intrinsics: CameraIntrinsics,
        background: np.ndarray,
    ) -> InstanceMasks:
        """rgb: (H, W, 3) uint8; depth_m: (H, W) float32 (0 = invalid); background: (H, W) bool,
        True on pixels already explained by the floor, walls or ceiling."""
        ...


@dataclass(frozen=True, eq=False)
class Detections:
    """Named boxes from an object detector, in the input image's pixels.

    boxes_xyxy_px: (K, 4) float64 (x1, y1, x2, y2). scores: (K,) float32 in [0, 1].
    labels: K labels of ``scene_builder.vocabulary`` (the detector's classes mapped to it), ``""``
    for a class outside it (a person, a car, an oven box around a night stand): such a box is
    still evidence that something is there (an object proposal).
    classes: K class names as the detector names them (for the report)."""

    boxes_xyxy_px: np.ndarray
    scores: np.ndarray
    labels: tuple[str, ...]
    classes: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.labels)


class ObjectDetector(Protocol):
    """Named boxes of the objects in one RGB image."""

    def detect(self, rgb: np.ndarray) -> Detections:
        """rgb: (H, W, 3) uint8. Returns every detection down to the detector's own floor score
        (low: the caller weighs low scores against geometry and a classifier), overlaps already
        suppressed; classes outside the vocabulary with the label ``""``."""
        ...


@dataclass(frozen=True, eq=False)
class SemanticMap:
    """A per-pixel class map. classes: (H, W) int32 index into ``labels``, at the input size.
    labels: vocabulary label of each class index, ``""`` for background and for classes that
    are not objects of the vocabulary (person, animals, vehicles). names: the model's own name of
    each class index (empty when unknown)."""

    classes: np.ndarray
    labels: tuple[str, ...]
    names: tuple[str, ...] = ()


class SemanticSegmenter(Protocol):
    """Semantic classes of every pixel of one RGB image."""

    def segment_classes(self, rgb: np.ndarray) -> SemanticMap:
        """rgb: (H, W, 3) uint8."""
        ...


class BoxPromptSegmenter(Protocol):
    """One instance mask per box prompt (Grounded-SAM style: a detector's boxes prompt a
    segmenter). A learned backend (SAM2) or a classical one (GrabCut) answers."""

    def segment_boxes(self, rgb: np.ndarray, boxes_xyxy_px: np.ndarray) -> np.ndarray:
        """rgb: (H, W, 3) uint8; boxes_xyxy_px: (K, 4) float (x1, y1, x2, y2) in pixels.
        Returns (K, H, W) bool, mask k for box k (may overlap; the caller resolves overlaps)."""
        ...


def keywords_taken(fn, **kwargs) -> dict:
    """The items of ``kwargs`` that the callable ``fn`` takes by keyword: a plug-in written to an
    older protocol (an ``ObjectNamer.name`` without ``height_max_m`` / ``length_max_m``) is called
    without the bounds it does not know, rather than failing on the photos that need them."""
    import inspect

    try:
        params = inspect.signature(fn).parameters
    except (TypeError, ValueError):  # a builtin or C callable without a signature: keep them all
        return dict(kwargs)
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return dict(kwargs)
    return {k: v for k, v in kwargs.items() if k in params and params[k].kind is not inspect.Parameter.POSITIONAL_ONLY}


class ObjectNamer(Protocol):
    """Names an object crop with a label of ``scene_builder.vocabulary``."""

    def name(
        self, crop_rgb: np.ndarray, crop_mask: np.ndarray, size_m: tuple[float, float, float], height_max_m: float | None = None, length_max_m: float | None = None,
        on_floor: bool = False,
    ) -> tuple[str, float]:
        """crop_rgb: (h, w, 3) uint8; crop_mask: (h, w) bool; size_m: gravity-aligned extents
        (length, width, height) sorted so that length >= width; height_max_m: None, or, for an
        object the photo's bottom edge cut, its top's height above the floor (its height lies
        between the seen one and this); length_max_m: None, or, for an object a side edge of the
        photo cut, the most its length can be; on_floor: the object is a thing of furniture
        height standing on the floor (not a monitor or a vase:
        :data:`perception.naming_prior.OFF_FLOOR_WEIGHT`). All three are optional: a namer that
        takes none is called without them (:func:`keywords_taken`). Returns (label, confidence
        in [0, 1]); ``("object", c)`` when unknown."""
        ...
