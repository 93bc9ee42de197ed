"""Door and drawer fronts on one rectified face: the face image split into panels along its
gaps and panel edges, each panel's handle found, and each panel told door, drawer or frame.

Input is a *rectified* face: an image in which the face of a box-like piece of furniture is seen
head-on, rows horizontal and columns vertical in the world (``perception.fronts`` warps the photo
there with the face plane's homography), with its scale in metres per pixel (approximate: the
rules below use it only for sizes that tolerate a factor of about 1.5).

1. **Edges** (scikit-image Canny) split by orientation (Sobel): horizontal and vertical.
2. **Recursive cuts** (an XY-cut, as document layout analysis splits a page): in the current
   rectangle, each row (column), at each slope of ``SLOPES``, is scored by the share of the
   rectangle's width (height) along which a horizontal (vertical) edge lies within a pixel of it.
   The best row or column scoring at least ``CUT_MIN_SCORE`` that leaves both pieces at least
   ``MIN_PANEL_M`` wide and that reaches both ends of the rectangle splits it; the pieces are cut
   again until no such line is left. Inner panel frames of a door stop short of its edges and do
   not cut it. Dense texture does cut: wood grain's long edges strip a drawer into rows too thin
   to hold its pull (urdformer_label40's top drawers); thresholds on the edges' strength, global
   or against their neighbourhood, and lines barred through strong handles were each measured
   worse on the cabinet photos (BENCHMARKS.md, 2026-11-28).
3. **Handles**: small dark or bright features (morphological black / white top-hat with a 5 cm
   square) that are compact (a knob) or a bar (a pull), 1-35 cm long and at most 5 cm thick, not
   touching the panel's border: the strongest one in the panel.
   A bar pull that a cut runs through (grain along it) starts its front from the smallest piece
   holding it whole, when that piece is only strips (:func:`_fronts`).
4. **Kind**: a panel is a front when it has a handle, or when it is at least 12 cm in both
   directions and every side of it is a cut (not the face's border: the face's top, plinth and
   side strips are carcass). A front whose handle is near its left or right edge is a door hinged
   on the far side, unless it is wide and low (``WIDE_FRONT_RATIO``) with the handle more than
   ``EDGE_HANDLE_SHARE`` of its width in from the edge (a drawer's pull found off its middle);
   one with a centred handle that is at least as wide as 0.8 of its height is a drawer; without
   a handle, a panel wider than 1.3 x its height and under 40 cm high is a drawer,
   else a door hinged on the side nearer to the face's border (the outer sides of a pair).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CUT_MIN_SCORE", "MIN_PANEL_M", "Panel", "parse_face"]

#: A line cuts when its edge share minus the share beside it is at least this.
CUT_MIN_SCORE = 0.75
#: A cut leaves both pieces at least this wide (m): thin strips (a gap, a frame rail) are cut
#: off as pieces of their own, so that the lines beside them reach the ends of what is left.
MIN_PANEL_M = 0.015
#: A line must have edges within this share of each end of the rectangle (it reaches both ends),
#: or cover at least LONG_LINE_SHARE of it (a front column ending above the plinth or the legs).
END_SHARE = 0.12
LONG_LINE_SHARE = 0.8
#: Shears (pixels per pixel) tried when deskewing the face.
MAX_SKEW = 0.04
#: Handle sizes (m), contrast (grey levels in [0, 1]) and shape.
HANDLE_MAX_LONG_M = 0.35
HANDLE_MAX_SHORT_M = 0.05
HANDLE_MIN_LONG_M = 0.012
HANDLE_MAX_ASPECT = 15.0
HANDLE_CONTRAST = 0.12
HANDLE_LEVELS = (HANDLE_CONTRAST, 0.2, 0.3, 0.45)
#: At most this many handle candidates (the strongest) are kept.
MAX_HANDLES = 400
#: Handle pieces closer than this (m) are one handle.
HANDLE_MERGE_M = 0.005
#: A panel without a handle is a front only when at least this big (m) in both directions.
FRONT_MIN_M = 0.12
#: A front grows over the strips around its handle up to this size (m).
FRONT_MAX_M = 2.5
#: Handles at least this share of the strongest one's score are credible.
HANDLE_MIN_SHARE = 0.2
#: A handle that no leaf of the cut tree holds whole starts a front of its own only when it is a
#: bar at least this many times as long as thick (a pull that grain runs along; a knob split by a
#: cut is more often two knobs, or a knob and a gap).
CUT_PULL_ASPECT = 3.0
#: A door's handle lies within this share of its width from its edge; a front at least
#: WIDE_FRONT_RATIO times as wide as high with its handle farther in is a drawer.
EDGE_HANDLE_SHARE = 0.15
WIDE_FRONT_RATIO = 1.5


@dataclass(frozen=True, eq=False)
class Panel:
    """One front found on the face, in face pixels (x right, y down).

    corners: (4, 2) float64 corners (x, y) bottom-left, bottom-right, top-right, top-left.
    kind: ``"door"`` or ``"drawer"``. hinge: ``"left"`` / ``"right"`` (seen from the front) for a
    door, ``""`` for a drawer. handle: (x, y) centre of its handle or None. support: the share of
    its sides that are cuts rather than the face's border (0..1)."""

    corners: np.ndarray
    kind: str
    hinge: str
    handle: tuple[float, float] | None
    support: float

    @property
    def box(self) -> tuple[float, float, float, float]:
        lo, hi = self.corners.min(axis=0), self.corners.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def _edges(gray: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """(horizontal, vertical) edge maps, each (h, w) bool, thickened by one pixel across."""
    from scipy import ndimage
    from skimage.feature import canny

    e = canny(gray, sigma=sigma, low_threshold=0.03, high_threshold=0.08)
    smooth = ndimage.gaussian_filter(gray, sigma)
    gx = ndimage.sobel(smooth, axis=1)
    gy = ndimage.sobel(smooth, axis=0)
    horiz = e & (np.abs(gy) >= np.abs(gx))
    vert = e & (np.abs(gx) > np.abs(gy))
    horiz = ndimage.binary_dilation(horiz, structure=np.ones((3, 1), dtype=bool))
    vert = ndimage.binary_dilation(vert, structure=np.ones((1, 3), dtype=bool))
    return horiz, vert


#: Slopes (rows per column) a line may have in the rectified face: a face rectified from an
#: estimated plane is off by a degree or two.
SLOPES = np.linspace(-0.035, 0.035, 9)


class _Lines:
    """Prefix sums of an edge map (lines along axis 1) sheared by each slope of SLOPES, so that
    the share of any row segment lying on edges is O(1) for every slope at once."""

    def __init__(self, emap: np.ndarray) -> None:
        h, w = emap.shape
        cols = np.arange(w)
        self.shifts = np.round(SLOPES[:, None] * (cols[None, :] - 0.5 * (w - 1))).astype(np.int64)  # (S, w)
        r = np.clip(np.arange(h)[None, :, None] + self.shifts[:, None, :], 0, h - 1)  # (S, h, w)
        sheared = emap[r, cols[None, None, :]].astype(np.float32)
        self.cum = np.concatenate([np.zeros((len(SLOPES), h, 1), np.float32), np.cumsum(sheared, axis=2)], axis=2)
        self.h = h

    def best(self, lo: int, hi: int, a0: int, a1: int, min_piece: int) -> tuple[float, int]:
        """Best cut line over rows lo..hi (exclusive) and columns a0..a1: (score, row where it
        crosses the middle column). score: the share of the columns with an edge on the line,
        when the line has edges near both ends or covers LONG_LINE_SHARE of them (else -1)."""
        n = a1 - a0
        if hi - lo < 2 * min_piece or n < 4:
            return -1.0, -1
        end = max(2, int(round(END_SHARE * n)))
        mid = (a0 + a1) // 2
        rows = np.arange(lo, hi)
        idx = np.clip(rows[None, :] - self.shifts[:, mid][:, None], 0, self.h - 1)  # (S, R): sheared index of each row at mid
        c = self.cum[np.arange(len(SLOPES))[:, None], idx]  # (S, R, w + 1)
        share = (c[..., a1] - c[..., a0]) / n
        reach = np.minimum(c[..., a0 + end] - c[..., a0], c[..., a1] - c[..., a1 - end]) / end
        score = np.where((reach >= 0.5) | (share >= LONG_LINE_SHARE), share, -1.0).max(axis=0)
        ok = (rows - lo >= min_piece) & (hi - rows >= min_piece)
        if not ok.any():
            return -1.0, -1
        score = np.where(ok, score, -1.0)
        i = int(np.argmax(score))
        return float(score[i]), int(rows[i])


@dataclass(eq=False)
class _Node:
    """A rectangle of the cut tree: (x0, y0, x1, y1) pixel bounds, which sides are cuts (left,
    top, right, bottom) rather than the face's border, its parent and its two pieces (none for a
    leaf)."""

    box: tuple[int, int, int, int]
    sides: tuple[bool, bool, bool, bool]
    parent: "_Node | None" = None
    children: tuple = ()

    def leaves(self) -> list["_Node"]:
        return [self] if not self.children else [leaf for c in self.children for leaf in c.leaves()]


def _cut(horiz: _Lines, vert: _Lines, node: _Node, min_piece: int, depth: int = 0) -> None:
    """Split ``node`` recursively along its best cut line (see the module docstring)."""
    x0, y0, x1, y1 = node.box
    sh, r = horiz.best(y0, y1, x0, x1, min_piece)
    sv, c = vert.best(x0, x1, y0, y1, min_piece)
    if max(sh, sv) < CUT_MIN_SCORE or depth > 24:
        return
    left, top, right, bottom = node.sides
    if sh >= sv:
        node.children = (_Node((x0, y0, x1, r), (left, top, right, True), node), _Node((x0, r, x1, y1), (left, True, right, bottom), node))
    else:
        node.children = (_Node((x0, y0, c, y1), (left, top, True, bottom), node), _Node((c, y0, x1, y1), (True, top, right, bottom), node))
    for child in node.children:
        _cut(horiz, vert, child, min_piece, depth + 1)


@dataclass(frozen=True)
class _Handle:
    box: tuple[int, int, int, int]  # x0, y0, x1, y1 in face pixels
    centre: tuple[float, float]
    score: float


def _handles(gray: np.ndarray, m_per_px: float, opened: bool = True) -> list[_Handle]:
    """Handle-like features of the whole face, strongest first. Candidates: components of the
    black and white top-hats (a 5 cm square) above each of HANDLE_LEVELS (highest first: a dark
    knob joined to dark gaps at a low level stands alone at a higher one), as they are and opened by
    a 3 x 3 square (a knob touching a thin gap line), of a handle's size,
    filling their box (a knob or a bar, not a curved moulding), not a gap (HANDLE_MAX_ASPECT)
    and not one of a repeated pattern (beads, a lattice, carving: four or more components of
    about the same size and contrast within three times their size (square root of the area) of
    each other; handles repeat too, but a front's size apart). Pieces of one handle are merged
    (:func:`_merge_handles`)."""
    from scipy import ndimage

    size = int(np.clip(round(0.05 / m_per_px), 5, 25))
    boxes, scores = [], []
    cores = np.zeros((0, 2))
    black = ndimage.grey_closing(gray, size=(size, size)) - gray  # dark features smaller than the square
    white = gray - ndimage.grey_opening(gray, size=(size, size))  # bright ones
    rows_grid, cols_grid = np.indices(gray.shape)
    # Each level's mask as it is and opened by a 3 x 3 square: a knob touching a gap or a panel's
    # shadow line (the knobs beside the meeting stiles of a pair of doors,
    # urdformer_label31) is one component with the line, too long for a handle, until the line
    # (1-2 px wide) is opened away; the opened pass adds only components whose core is new.
    modes = (False, True) if opened else (False,)
    passes = [(th, level, o) for th in (black, white) for level in sorted(HANDLE_LEVELS, reverse=True) for o in modes]
    square = np.ones((3, 3), dtype=bool)
    for th, level, open_ in passes:
        above = th > level
        lab, n = ndimage.label(ndimage.binary_opening(above, structure=square) if open_ else above)
        if n == 0:
            continue
        sl = ndimage.find_objects(lab)
        r0 = np.array([s_[0].start for s_ in sl], dtype=np.float64)
        r1 = np.array([s_[0].stop for s_ in sl], dtype=np.float64)
        c0 = np.array([s_[1].start for s_ in sl], dtype=np.float64)
        c1 = np.array([s_[1].stop for s_ in sl], dtype=np.float64)
        area = np.bincount(lab.ravel(), minlength=n + 1)[1:].astype(np.float64)
        peak = np.zeros(n + 1)
        on = lab.ravel() > 0
        np.maximum.at(peak, lab.ravel()[on], th.ravel()[on])
        peak = peak[1:]
        cy = np.bincount(lab.ravel(), weights=rows_grid.ravel(), minlength=n + 1)[1:] / area
        cx = np.bincount(lab.ravel(), weights=cols_grid.ravel(), minlength=n + 1)[1:] / area
        long_, short = np.maximum(r1 - r0, c1 - c0), np.minimum(r1 - r0, c1 - c0)
        ok = (long_ * m_per_px <= HANDLE_MAX_LONG_M) & (short * m_per_px <= HANDLE_MAX_SHORT_M) & (long_ * m_per_px >= HANDLE_MIN_LONG_M)
        ok &= area >= 0.4 * (r1 - r0) * (c1 - c0)  # a handle fills its box (not a curved line)
        ok &= long_ <= HANDLE_MAX_ASPECT * np.maximum(short, 1)  # a gap or a groove is longer
        # the pattern test compares with components of at least half the smallest candidate's size
        cand = np.flatnonzero(ok)
        if len(cand) == 0:
            continue
        big = area >= 0.5 * area[cand].min()
        cy_b, cx_b, area_b, peak_b = cy[big], cx[big], area[big], peak[big]
        for i in cand:
            near = np.hypot(cy_b - cy[i], cx_b - cx[i]) < 3.0 * np.sqrt(area[i])
            similar = near & (area_b > 0.5 * area[i]) & (area_b < 2.0 * area[i]) & (peak_b > peak[i] / 1.5) & (peak_b < 1.5 * peak[i])
            if similar.sum() >= 4:  # one of a pattern (itself and three more close by)
                continue
            if len(cores) and np.any((cores[:, 0] >= c0[i]) & (cores[:, 0] <= c1[i]) & (cores[:, 1] >= r0[i]) & (cores[:, 1] <= r1[i])):
                continue  # its core was found at a higher level
            boxes.append((c0[i], r0[i], c1[i], r1[i]))
            scores.append(float(peak[i] * np.sqrt(area[i])))
            cores = np.vstack([cores, [[cx[i], cy[i]]]])
    order = np.argsort(-np.array(scores), kind="stable")[:MAX_HANDLES]
    out = _merge_handles(np.array(boxes, dtype=np.float64).reshape(-1, 4)[order], np.array(scores)[order],
                         max(1, int(round(HANDLE_MERGE_M / m_per_px))), HANDLE_MAX_LONG_M / m_per_px, HANDLE_MAX_SHORT_M / m_per_px)
    out.sort(key=lambda hd: -hd.score)
    return out


def _credible_handles(gray: np.ndarray, m_per_px: float, opened: bool = True) -> list[_Handle]:
    """:func:`_handles` of ``gray`` that are credible: a fifth (HANDLE_MIN_SHARE) of the strongest's
    score at least, strongest first."""
    handles = _handles(gray, m_per_px, opened)
    return [hd for hd in handles if hd.score >= HANDLE_MIN_SHARE * handles[0].score] if handles else []


def _merge_handles(boxes: np.ndarray, scores: np.ndarray, gap: int, long_max: float, short_max: float) -> list[_Handle]:
    """Handles ((N, 4) boxes x0, y0, x1, y1 and (N,) scores) whose boxes lie within ``gap`` pixels
    of each other, chained, merged into one (a knob split by its highlight, a bar by its
    reflection) when the union is still of a handle's size (``long_max`` x ``short_max``
    pixels): the union box, the strongest's score. A group too big for a handle stays apart."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(boxes)
    if n == 0:
        return []
    b = boxes
    close = ((b[:, None, 0] - gap <= b[None, :, 2]) & (b[None, :, 0] - gap <= b[:, None, 2])
             & (b[:, None, 1] - gap <= b[None, :, 3]) & (b[None, :, 1] - gap <= b[:, None, 3]))
    _, comp = connected_components(csr_matrix(close), directed=False)
    out = []
    for c in np.unique(comp):
        idx = np.flatnonzero(comp == c)
        u = np.array([b[idx, 0].min(), b[idx, 1].min(), b[idx, 2].max(), b[idx, 3].max()])
        dims = (u[2] - u[0], u[3] - u[1])
        groups = [idx] if (max(dims) <= long_max and min(dims) <= short_max) else [[i] for i in idx]
        for g in groups:
            g = np.asarray(g)
            box = (int(b[g, 0].min()), int(b[g, 1].min()), int(b[g, 2].max()), int(b[g, 3].max()))
            out.append(_Handle(box, (0.5 * (box[0] + box[2]), 0.5 * (box[1] + box[3])), float(scores[g].max())))
    return out


def _handle_in(handles: list[_Handle], box, m_per_px: float) -> _Handle | None:
    """The strongest handle inside ``box`` and off its border (1 cm), no longer than 0.7 of it."""
    x0, y0, x1, y1 = box
    margin = max(2, int(round(0.01 / m_per_px)))
    for hd in handles:
        a0, b0, a1, b1 = hd.box
        if a0 >= x0 + margin and b0 >= y0 + margin and a1 <= x1 - margin and b1 <= y1 - margin:
            if max(a1 - a0, b1 - b0) <= 0.7 * max(x1 - x0, y1 - y0):
                return hd
    return None


def _fronts(root: _Node, handles: list[_Handle], m_per_px: float, cut_handles: bool = True) -> list[tuple]:
    """The fronts of a cut tree: [(box, sides, handle or None)].

    A leaf holding a handle grows into its ancestors as long as what it takes in holds no handle
    and no leaf that could be a front itself (FRONT_MIN_M in both directions, cut on every side):
    the strips that plank seams, wood grain or a raised panel's mouldings cut a front into, and
    the rails around it, are the front's. A bar pull (:data:`CUT_PULL_ASPECT`) that a cut runs
    through (wood grain along it) lies in no leaf: it grows the same way from the smallest node
    holding it whole, when that node is all strips (no front-sized leaf), and fronts growing from
    other handles stop short of it (``cut_handles`` False: leaves only). Leaves without a handle,
    FRONT_MIN_M in both directions and cut on every side, are fronts as they are."""
    min_px = FRONT_MIN_M / m_per_px

    def has_handle(node: _Node) -> _Handle | None:
        return _handle_in(handles, node.box, m_per_px)

    def big(leaf: _Node) -> bool:
        x0, y0, x1, y1 = leaf.box
        return min(x1 - x0, y1 - y0) >= min_px and all(leaf.sides)

    def holding(node: _Node, hd: _Handle) -> _Node | None:
        """The smallest node under ``node`` that holds ``hd`` off its border."""
        if _handle_in([hd], node.box, m_per_px) is None:
            return None
        for c in node.children:
            inner = holding(c, hd)
            if inner is not None:
                return inner
        return node

    starts = [(leaf, hd) for leaf in root.leaves() if (hd := has_handle(leaf)) is not None]
    # A handle a cut runs through (wood grain across a drawer's pull) lies in no leaf: its front
    # grows from the smallest piece holding it whole, when that piece is strips (no front-sized
    # leaf: two doors' knobs either side of their meeting gap are one blob across it).
    used = {id(hd) for _, hd in starts}
    cut: list[tuple[_Node, _Handle]] = []
    for hd in handles if cut_handles else ():
        if id(hd) not in used:
            bw, bh = hd.box[2] - hd.box[0], hd.box[3] - hd.box[1]
            if max(bw, bh) < CUT_PULL_ASPECT * max(min(bw, bh), 1):
                continue
            node = holding(root, hd)
            if node is not None and node.children and not any(big(x) for x in node.leaves()):
                cut.append((node, hd))
                used.add(id(hd))
    starts += cut
    out, taken = [], set()
    for leaf, hd in starts:
        if leaf.children and any(id(x) in taken for x in leaf.leaves()):
            continue  # a cut handle inside a front found already
        node = leaf
        while node.parent is not None:
            sibling = next(c for c in node.parent.children if c is not node)
            if any(_handle_in(handles, sl.box, m_per_px) is not None or big(sl) for sl in sibling.leaves()):
                break
            if any(_overlaps(hd2, sibling.box) for hd2 in handles) or any(_touches(hc.box, sibling.box) for _, hc in cut):
                break
            px0, py0, px1, py1 = node.parent.box
            if max(px1 - px0, py1 - py0) * m_per_px > FRONT_MAX_M:
                break
            node = node.parent
        if id(node) in taken:
            continue
        taken.add(id(node))
        taken.update(id(x) for x in node.leaves())
        out.append((node.box, node.sides, hd))
    for leaf in root.leaves():
        if id(leaf) not in taken and big(leaf) and has_handle(leaf) is None:
            out.append((leaf.box, leaf.sides, None))
    return out


def _touches(a, b) -> bool:
    """Whether boxes ``a`` and ``b`` (x0, y0, x1, y1) share pixels."""
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _overlaps(hd: _Handle, box) -> bool:
    """Whether handle ``hd``'s centre lies in ``box``."""
    x0, y0, x1, y1 = box
    return x0 <= hd.centre[0] < x1 and y0 <= hd.centre[1] < y1


def _skew(emap: np.ndarray) -> float:
    """The shear s (rows per column) within MAX_SKEW whose sheared row profile of ``emap`` is
    most peaked (sum of squared row counts)."""
    ys, xs = np.nonzero(emap)
    if len(ys) == 0:
        return 0.0
    cols = xs - 0.5 * (emap.shape[1] - 1)
    best, best_s = -1.0, 0.0
    for s in np.linspace(-MAX_SKEW, MAX_SKEW, 17):
        r = np.round(ys - s * cols).astype(np.int64)
        score = float(np.sum(np.bincount(r - r.min()).astype(np.float64) ** 2))
        if score > best * 1.0001:
            best, best_s = score, float(s)
    return best_s


def parse_face(face_rgb: np.ndarray, m_per_px: float, inside: np.ndarray | None = None, opened: bool = True) -> list[Panel]:
    """The door and drawer fronts of a rectified face image ((h, w, 3) uint8) at ``m_per_px``
    metres per pixel (see the module docstring). ``inside``: (h, w) bool, where the face shows
    the object (its mask), given for case goods: where the cuts find fewer than two fronts,
    fronts outlined by edges within the object's box, or a column of drawer pulls, are looked for
    (``perception.front_rects``) and taken when they are more. ``opened``: handle candidates
    also from the top-hats opened by a 3 x 3 square (:func:`_handles`)."""
    import cv2
    from skimage.color import rgb2gray

    gray = rgb2gray(np.asarray(face_rgb)).astype(np.float64)
    raw = gray
    lo, hi = np.percentile(gray, [1.0, 99.0])
    gray = np.clip((gray - lo) / max(hi - lo, 0.05), 0.0, 1.0)  # dark furniture: stretch its contrast
    h, w = gray.shape
    horiz, vert = _edges(gray, sigma=1.2)
    sh, sv = _skew(horiz), _skew(vert.T)  # rows drift sh per column, columns sv per row
    fwd = np.array([[1.0, -sv, sv * 0.5 * (h - 1)], [-sh, 1.0, sh * 0.5 * (w - 1)]])
    if sh or sv:  # deskew: x' = x - sv (y - cy), y' = y - sh (x - cx)
        gray = cv2.warpAffine(gray, fwd, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        horiz, vert = _edges(gray, sigma=1.2)
    back = cv2.invertAffineTransform(fwd)
    handles = _credible_handles(gray, m_per_px, opened)
    min_piece = max(3, int(round(MIN_PANEL_M / m_per_px)))
    root = _Node((0, 0, w, h), (False, False, False, False))
    _cut(_Lines(horiz), _Lines(vert.T), root, min_piece)
    fronts = _fronts(root, handles, m_per_px)
    # (the fallbacks are looked for as before the cut pulls were taken: where the leaves' handles
    # alone give fewer than two fronts)
    if len(_fronts(root, handles, m_per_px, cut_handles=False)) < 2 and inside is not None and inside.any():
        from perception.front_rects import handle_column, handle_grid, inside_stiles, outlined_rectangles

        ins = cv2.warpAffine(inside.astype(np.uint8), fwd, (w, h), flags=cv2.INTER_NEAREST) > 0 if (sh or sv) else inside
        cols, rows = np.flatnonzero(ins.mean(axis=0) >= 0.5), np.flatnonzero(ins.mean(axis=1) >= 0.5)
        box = (int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1) if len(cols) and len(rows) else (0, 0, w, h)
        rects = outlined_rectangles(horiz, vert, box, m_per_px, lambda b: _handle_in(handles, b, m_per_px))
        if len(rects) < 2:
            rects = handle_column(handles, box, m_per_px, ins)
        own_handles = None
        if len(rects) < 2 and ins.sum() >= 0.25 * ins.size:
            # The face's contrast stretched over the object's own pixels, to its brightest
            # handful: a bright bed beside a dark night stand left the stand's pulls too faint
            # (sunrgbd_imvotenet_000004). Only here: stretched so for every face, the cuts and
            # handles changed on the cabinet photos (fronts matched 34 -> 32 of 52).
            own = cv2.warpAffine(raw, fwd, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE) if (sh or sv) else raw
            lo, hi = np.percentile(own[ins], [1.0, 99.9])
            own_gray = np.clip((own - lo) / max(hi - lo, 0.05), 0.0, 1.0)
            own_handles = _credible_handles(own_gray, m_per_px, opened)  # found once, for both fallbacks
        stiles = vert  # the edges the fronts were told on: their sides move in to the stiles there
        if len(rects) < 2 and own_handles is not None:
            rects = handle_column(own_handles, box, m_per_px, ins)
            if len(rects) >= 2:
                stiles = _edges(own_gray, sigma=1.2)[1]
        if len(rects) < 2:
            # rows of handles: a dresser's row of small drawers over wide ones
            rects = handle_grid(handles, horiz, vert, box, m_per_px, ins)
        if len(rects) < 2 and own_handles is not None:
            o_horiz, o_vert = _edges(own_gray, sigma=1.2)
            rects = handle_grid(own_handles, o_horiz, o_vert, box, m_per_px, ins)
            stiles = o_vert
        if len(rects) >= 2 and len(rects) > len(fronts):
            fronts = [(rect, (True, True, True, True), hd) for rect, _, hd in inside_stiles(rects, stiles, box)]
    panels = []
    for (x0, y0, x1, y1), sides, hd in fronts:
        pw, ph = (x1 - x0) * m_per_px, (y1 - y0) * m_per_px
        kind, hinge = "", ""
        if hd is not None:
            rel = (hd.centre[0] - x0) / max(1, x1 - x0)
            if 0.3 <= rel <= 0.7:
                kind = "drawer" if pw >= 0.8 * ph else "door"
            elif min(rel, 1.0 - rel) >= EDGE_HANDLE_SHARE and pw >= WIDE_FRONT_RATIO * ph:
                # A wide, low front pulled a fifth of the way in: a drawer whose pull was found
                # off its middle (one of two knobs, or an ornament beside the knob), not a door
                # (a door's knob sits at its edge; urdformer_label62's drawers, 53's top drawer).
                kind = "drawer"
            else:
                kind = "door"
                hinge = "right" if rel < 0.3 else "left"
        elif min(pw, ph) >= FRONT_MIN_M and all(sides):
            kind = "drawer" if (pw > 1.3 * ph and ph < 0.4) else "door"
        if not kind:
            continue
        if kind == "door" and not hinge:
            hinge = "left" if (x0 + x1) / 2 < w / 2 else "right"
        corners = np.array([[x0, y1], [x1, y1], [x1, y0], [x0, y0]], dtype=np.float64) @ back[:, :2].T + back[:, 2]
        handle = None if hd is None else tuple(float(v) for v in back[:, :2] @ np.array(hd.centre) + back[:, 2])
        panels.append(Panel(corners, kind, hinge, handle, float(np.mean(sides))))
    return panels
