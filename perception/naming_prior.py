"""The ``"geometric-prior"`` naming backend: a label from gravity-aligned size alone.

Sizes are compared with the typical sizes of :mod:`scene_builder.vocabulary` in log space (a
chair twice too big is as wrong as one half too small). Only the categories whose size and shape
tell them apart from their neighbours are candidates (a dishwasher and a cabinet of the same size
cannot be told apart by size, so the more general "cabinet" stands for both); a few shape rules
add what size alone misses (a large flat top at table height, tall and narrow furniture).
Observed extents are partial (the back of an object is not seen), so the footprint may be
smaller than the object's. The confidence is honest and low: at most :data:`MAX_CONFIDENCE`.
"""

from __future__ import annotations

import numpy as np

from scene_builder.vocabulary import BY_NAME

__all__ = ["CANDIDATES", "GeometricPriorNamer", "MAX_CONFIDENCE"]

#: The namer never claims more than this: size is weak evidence of what an object is.
MAX_CONFIDENCE = 0.35
CANDIDATES: tuple[str, ...] = (
    "table",
    "chair",
    "sofa",
    "bed",
    "shelf",
    "cabinet",
    "wardrobe",
    "box",
    "bottle",
    "mug",
    "bowl",
    "book",
    "monitor",
    "lamp",
    "pillow",
)
#: Beyond this log-size distance nothing fits: the object is called "object".
_MAX_DISTANCE = 1.0


class GeometricPriorNamer:
    """Names an object from its gravity-aligned extents (see the module doc)."""

    def name(self, crop_rgb: np.ndarray, crop_mask: np.ndarray, size_m: tuple[float, float, float]) -> tuple[str, float]:
        """size_m: (length, width, height) with length >= width. Returns (label, confidence)."""
        length, width, height = (max(float(s), 0.01) for s in size_m)
        obs = np.log([length, width, height])
        thin = width < 0.15 and width < 0.3 * length
        best, best_d = "object", np.inf
        for label in CANDIDATES:
            x, y, z = BY_NAME[label].typical_size_m
            typ = np.log([max(x, y), min(x, y), z])
            diff = obs - typ
            # The unseen back makes the footprint look smaller than it is: forgive that more.
            diff[:2] = np.where(diff[:2] < 0, 0.6 * diff[:2], diff[:2])
            if thin:
                # Only one face was seen (a cabinet front): its depth says nothing.
                diff = diff[[0, 2]]
            d = float(np.sqrt(np.mean(diff * diff)))
            if d < best_d:
                best, best_d = label, d
        # Shape rules that size distance alone gets wrong.
        if height > 1.5 and width < 0.7 * height and best not in ("wardrobe", "shelf"):
            best, best_d = ("wardrobe" if length > 0.9 else "shelf"), min(best_d, 0.5)
        if 0.6 <= height <= 0.85 and length >= 0.9 and width >= 0.5 and best not in ("table", "bed", "sofa"):
            best, best_d = "table", min(best_d, 0.5)
        if best_d > _MAX_DISTANCE:
            return "object", 0.1
        return best, float(MAX_CONFIDENCE * np.exp(-2.0 * best_d))
