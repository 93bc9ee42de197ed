"""What makes a detector box's object whole (used by :mod:`perception.segment_detect`): a box
segmenter cuts by colour; depth joins an object's parts, and a box-shaped thing is its box.
"""

from __future__ import annotations

import numpy as np

__all__ = ["BOXY", "BOXY_FILL", "WHOLE_CUT_SHARE", "WHOLE_INSIDE", "box_slices", "cuboid_faces", "fill_box", "whole_cluster"]

#: A depth cluster that an object's cut reaches into and that lies this much inside its box is
#: part of it (:func:`whole_cluster`) ...
WHOLE_INSIDE = 0.8
#: ... and that holds at least this share of its in-box pixels in the cut.
WHOLE_CUT_SHARE = 0.2
#: Things whose outline is their box (seen from the front): a confident detection's cut that fills
#: less than BOXY_FILL of its box is grown to the box on estimated depth (:func:`fill_box`).
BOXY = frozenset({"tv", "monitor", "microwave", "oven", "refrigerator", "dishwasher"})
BOXY_FILL = 0.6


def box_slices(box: np.ndarray, h: int, w: int) -> tuple[slice, slice]:
    """Row and column slices of an (x0, y0, x1, y1) pixel box in an (h, w) image, at least 1 px."""
    x0, y0 = int(np.clip(np.floor(box[0]), 0, w)), int(np.clip(np.floor(box[1]), 0, h))
    x1, y1 = int(np.clip(np.ceil(box[2]), 0, w)), int(np.clip(np.ceil(box[3]), 0, h))
    return slice(y0, max(y1, y0 + 1)), slice(x0, max(x1, x0 + 1))


def whole_cluster(box: np.ndarray, mask: np.ndarray, clusters: np.ndarray, claimed: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels of the depth clusters that make the object of ``box`` whole: each
    cluster that the cut ``mask`` reaches into and that lies mostly (:data:`WHOLE_INSIDE`) inside
    the box, less what other instances ``claimed``. A box segmenter cuts by colour: a bed's dark
    wooden footboard from its white mattress, a sofa's legs from its cushions; depth joins them (a
    cluster reaching far out of the box is another thing, or things, touching it)."""
    h, w = mask.shape
    rs, cs = box_slices(box, h, w)
    ids, inside = np.unique(clusters[rs, cs][mask[rs, cs]], return_counts=True)
    out = np.zeros_like(mask)
    for cl, n in zip(ids, inside):
        if cl == 0 or n < 0.05 * np.count_nonzero(mask):
            continue
        pix = clusters == cl
        in_box = np.count_nonzero(pix[rs, cs])
        # Mostly inside the box, and the cut holds a fair share of it (a cluster the cut only
        # grazes is something the object touches: a wall's pillar behind a wardrobe).
        if in_box >= WHOLE_INSIDE * np.count_nonzero(pix) and n >= WHOLE_CUT_SHARE * in_box:
            out[rs, cs] |= pix[rs, cs]
    return out & ~claimed


def cuboid_faces(own: np.ndarray, cl: np.ndarray, clusters: np.ndarray, mine: int) -> np.ndarray:
    """The pixels (a bool crop of the box, like ``own``) of the depth clusters of an *estimated*
    depth map that lie mostly (:data:`WHOLE_INSIDE`) inside the box and join the object's own
    cluster ``mine`` (pixels ``own``), face by face. ``cl`` is the box's crop of ``clusters``.

    Single-view depth stands a detected bed or sofa as a cuboid whose front, top and headboard
    meet at creases, and the depth segmenter splits at creases: without this the cut kept a bed's
    front panel and gave up its mattress and headboard (3D box IoU 0.24 on
    sunrgbd_imvotenet_000003 as a plain photo). Sensor depth is not asked: there a cluster
    inside the box is as likely another thing (a coffee table before a sofa)."""
    from scipy.ndimage import binary_dilation

    total = np.bincount(clusters.ravel())
    ids, n_in = np.unique(cl, return_counts=True)
    inside = [i for i, n in zip(ids, n_in) if i not in (0, mine) and n >= WHOLE_INSIDE * total[i]]
    out = own.copy()
    grown = True
    while grown and inside:  # face by face: a headboard touches the top, not the front
        near = binary_dilation(out, iterations=2)
        grown = False
        for i in list(inside):
            face = cl == i
            if (face & near).any():
                out |= face
                inside.remove(i)
                grown = True
    return out & ~own


def fill_box(box: np.ndarray, mask: np.ndarray, claimed: np.ndarray, others: list[np.ndarray]) -> np.ndarray:
    """``mask`` of a box-shaped thing, grown to its whole box (less what ``claimed`` and the
    ``others`` hold) when it fills less than :data:`BOXY_FILL` of it: a colour cut keeps a CRT
    television's bright screen and gives up its dark case (perceived mask IoU 0.50 with the
    annotated set on coco128_000000000643; a confident detector's box is the set's outline)."""
    h, w = mask.shape
    rs, cs = box_slices(box, h, w)
    if mask[rs, cs].mean() >= BOXY_FILL:
        return mask
    free = ~claimed[rs, cs]
    for m in others:
        free &= ~np.asarray(m, dtype=bool)[rs, cs]
    out = mask.copy()
    out[rs, cs] |= free
    return out
