"""The ``"geometric-prior"`` naming backend: a label from gravity-aligned size alone.

Sizes are compared with the typical sizes of :mod:`scene_builder.vocabulary` in log space (a
chair twice too big is as wrong as one half too small). Only the categories whose size and shape
tell them apart from their neighbours are candidates (a dishwasher and a cabinet of the same size
cannot be told apart by size, so the more general "cabinet" stands for both); a few shape rules
add what size alone misses (a large flat top at table height, tall and narrow furniture).
Observed extents are partial (the back of an object is not seen), so the footprint may be
smaller than the object's. A thing of furniture height standing on the floor is unlikely to be
one of the things that stand on furniture (:data:`OFF_FLOOR_WEIGHT`). The confidence is honest
and low: at most :data:`MAX_CONFIDENCE`.
"""

from __future__ import annotations

import numpy as np

from scene_builder.vocabulary import BY_NAME

__all__ = [
    "CANDIDATES", "EXTENT_STEPS", "FLOOR_LAMP_MIN_M", "GeometricPriorNamer", "MAX_CONFIDENCE", "OFF_FLOOR_WEIGHT",
    "SIZE_SIGMA_LOG", "off_floor_labels", "shape_rule", "size_distance", "size_hypotheses", "size_log_likelihoods",
]

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
#: Prior weight, for a thing of furniture height standing on the floor, of the labels of things
#: that stand on furniture (``Category.on_floor`` False: a monitor, a microwave, a vase). Size
#: alone named sunrgbd_imvotenet_000002's tufted ottoman, 0.5 m high on the floor, a monitor
#: (posterior 0.26, the classifier seeing nothing), and its monitor prior built a thin screen.
#: Not a lamp FLOOR_LAMP_MIN_M tall or more: a floor lamp.
OFF_FLOOR_WEIGHT = 0.25
FLOOR_LAMP_MIN_M = 1.0


def off_floor_labels(labels, height_m: float) -> np.ndarray:
    """(L,) bool: the labels weighed down by OFF_FLOOR_WEIGHT on a thing ``height_m`` high
    standing on the floor."""
    return np.array([not BY_NAME[lab].on_floor and not (lab == "lamp" and height_m >= FLOOR_LAMP_MIN_M) for lab in labels], dtype=bool)


def size_distance(label: str, size_m: tuple[float, float, float]) -> float:
    """RMS log-size distance of the observed extents (length >= width, height) from ``label``'s
    typical size. The unseen back makes a footprint look smaller than it is, so undershoot counts
    0.6 of overshoot; a thin seen face (a cabinet front) is compared on width and height only."""
    length, width, height = (max(float(s), 0.01) for s in size_m)
    obs = np.log([length, width, height])
    x, y, z = BY_NAME[label].typical_size_m
    diff = obs - np.log([max(x, y), min(x, y), z])
    diff[:2] = np.where(diff[:2] < 0, 0.6 * diff[:2], diff[:2])
    if width < 0.15 and width < 0.3 * length:
        diff = diff[[0, 2]]
    return float(np.sqrt(np.mean(diff * diff)))


def shape_rule(size_m: tuple[float, float, float]) -> str | None:
    """What size distance alone gets wrong: tall narrow furniture is a wardrobe (long) or a shelf;
    a large flat top at table height is a table. None when no rule applies."""
    length, width, height = (float(s) for s in size_m)
    if height > 1.5 and width < 0.7 * height:
        return "wardrobe" if length > 0.9 else "shelf"
    if 0.6 <= height <= 0.85 and length >= 0.9 and width >= 0.5:
        return "table"
    return None


#: Log-size distance that costs half a nat (a factor of about 1.3 off on every axis).
SIZE_SIGMA_LOG = 0.25


#: Heights (lengths) tried between an object's seen height (length) and its upper bound when an
#: edge of the photo cut it (:func:`size_hypotheses`).
EXTENT_STEPS = 6


def size_hypotheses(size_m: tuple[float, float, float], height_max_m: float | None, length_max_m: float | None = None) -> list[tuple[float, float, float]]:
    """The extents to weigh for an object: ``size_m`` itself, or, when the photo's bottom edge cut
    the object (its seen height a lower bound, its top's height above the floor ``height_max_m``
    an upper bound), :data:`EXTENT_STEPS` heights spaced evenly in log between the two; likewise,
    when a side edge of the photo cut it (its seen length a lower bound, ``length_max_m`` an
    upper one), :data:`EXTENT_STEPS` lengths (every pair of a height and a length)."""
    length, width, height = (float(s) for s in size_m)
    heights = [height] if height_max_m is None or height_max_m <= 1.05 * height else list(np.geomspace(max(height, 0.01), height_max_m, EXTENT_STEPS))
    lengths = [length] if length_max_m is None or length_max_m <= 1.05 * length else list(np.geomspace(max(length, 0.01), length_max_m, EXTENT_STEPS))
    return [(float(ln), width, float(h)) for ln in lengths for h in heights]


def size_log_likelihoods(labels: tuple[str, ...], size_m: tuple[float, float, float], height_max_m: float | None = None, length_max_m: float | None = None) -> np.ndarray:
    """(L,) log-likelihood of the observed extents under each label's typical size:
    -d^2 / (2 SIZE_SIGMA_LOG^2) with d = :func:`size_distance`; the label a shape rule picks is
    scored as if it were at distance <= 0.5 (:class:`GeometricPriorNamer` does the same). With
    ``height_max_m`` (the photo's bottom edge cut the object: its height is somewhere between the
    seen one and its top's height above the floor) or ``length_max_m`` (a side edge of the photo cut it), the
    likelihood is averaged over the extents of :func:`size_hypotheses` (interval-censored
    extents, uniform in log)."""
    from scipy.special import logsumexp

    per = []
    for size in size_hypotheses(size_m, height_max_m, length_max_m):
        rule = shape_rule(size)
        d = np.array([min(size_distance(lab, size), 0.5) if lab == rule else size_distance(lab, size) for lab in labels])
        per.append(-0.5 * (d / SIZE_SIGMA_LOG) ** 2)
    return logsumexp(np.array(per), axis=0) - np.log(len(per))


class GeometricPriorNamer:
    """Names an object from its gravity-aligned extents (see the module doc)."""

    def name(
        self, crop_rgb: np.ndarray, crop_mask: np.ndarray, size_m: tuple[float, float, float], height_max_m: float | None = None, length_max_m: float | None = None,
        on_floor: bool = False,
    ) -> tuple[str, float]:
        """size_m: (length, width, height) with length >= width; height_max_m, length_max_m: see
        :func:`size_log_likelihoods` (the extents that fit a label best within the ranges are
        used); on_floor: a thing of furniture height standing on the floor (the labels of things
        standing on furniture weigh OFF_FLOOR_WEIGHT: as a distance, their log-likelihood
        lowered by log OFF_FLOOR_WEIGHT). Returns (label, confidence)."""
        sizes = size_hypotheses(size_m, height_max_m, length_max_m)
        dist = {label: min(size_distance(label, s) for s in sizes) for label in CANDIDATES}
        if on_floor:
            penalty = -2.0 * SIZE_SIGMA_LOG**2 * float(np.log(OFF_FLOOR_WEIGHT))
            off = off_floor_labels(list(dist), float(size_m[2]))
            dist = {label: float(np.sqrt(d * d + penalty)) if o else d for (label, d), o in zip(dist.items(), off)}
        best = min(CANDIDATES, key=lambda lab: dist[lab])
        best_d = dist[best]
        size_m = min(sizes, key=lambda s: size_distance(best, s))
        rule = shape_rule(size_m)
        # The rule stands unless the size already picked a label of the same family.
        family = ("table", "bed", "sofa") if rule == "table" else ("wardrobe", "shelf")
        if rule is not None and best not in family:
            best, best_d = rule, min(best_d, 0.5)
        if best_d > _MAX_DISTANCE:
            return "object", 0.1
        return best, float(MAX_CONFIDENCE * np.exp(-2.0 * best_d))
