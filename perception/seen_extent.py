"""Which objects a side edge of the photo cut: their seen length is a lower bound, and naming
weighs the lengths they may have (:func:`perception.naming_prior.size_hypotheses`); the photo's
bottom edge is :func:`scene_builder.frames.cut_by_photo_bottom`'s.

A side is cut when, on at least :data:`~scene_builder.frames.SIDE_CUT_SHARE` of the mask's
rows, the mask's outermost pixel on that side lies within
:data:`~scene_builder.frames.SIDE_EDGE_SHARE` of the photo's width of the edge
(:func:`scene_builder.frames.cut_side`; SUN RGB-D 000005: a dresser at the right edge, 0.38 m of
it seen, was named a chair). An object reaching both side
edges fills the photo's width: a close-up framed on it, not cut (urdformer_label31's cabinet,
weighed as longer, became a table). Only objects seen at least :data:`SIDEWAYS_MIN_HEIGHT_M` tall
are weighed so (:func:`length_max_m`): a mug at the edge of a close-up of a shelf, weighed
as up to twice as wide, became a box that crowded the shelf (promptda_arkit); small things are
named by what the classifier sees more than by their size.

Tried and left out (measured on the real samples): a side hidden by a nearer object (on half the
mask's rows, 10 cm nearer) named a bottle behind another a vase (open3d_TUM) and named nothing
better; a bottom hidden by a nearer object (weighed down to that object's bottom) made a mattress
behind its bed's footboard a sofa (sunrgbd_000017).
"""

from __future__ import annotations

import numpy as np

from scene_builder.frames import LENGTH_CAP_M, LENGTH_FACTOR, SIDEWAYS_MIN_HEIGHT_M, cut_side

__all__ = ["LENGTH_CAP_M", "LENGTH_FACTOR", "SIDEWAYS_MIN_HEIGHT_M", "cut_by_side_edge", "length_max_m"]


def cut_by_side_edge(mask: np.ndarray) -> bool:
    """Whether exactly one side edge of the photo cut the (H, W) bool ``mask`` (module doc)."""
    return cut_side(mask) is not None


def length_max_m(mask: np.ndarray, size_m: tuple[float, float, float]) -> float | None:
    """The most the length of an object with (H, W) bool ``mask`` and seen extents ``size_m``
    (length, width, height) can be, for naming (``ObjectNamer``'s ``length_max_m``): LENGTH_FACTOR
    times the seen length (LENGTH_CAP_M at most) when a side edge of the photo cut it and it was
    seen at least SIDEWAYS_MIN_HEIGHT_M tall; None otherwise."""
    length, _, height = (float(s) for s in size_m)
    if height < SIDEWAYS_MIN_HEIGHT_M or not cut_by_side_edge(mask):
        return None
    return min(LENGTH_FACTOR * length, max(LENGTH_CAP_M, length))
