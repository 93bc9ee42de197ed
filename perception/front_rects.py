"""Fronts inside a face frame, the fallbacks of ``perception.front_parse`` for case goods:
outlined rectangles, and a column of drawer pulls.

The XY-cut of ``front_parse`` splits a face along lines that run from one end of what is left to
the other. A night stand's or a dresser's drawers are inset in a face frame (stiles down the
sides, a top moulding, a plinth): their outlines stop at the stiles, no line crosses the face,
and the cut finds one big panel (the SUN RGB-D bedrooms: 0 of 48 hand-counted fronts). Here the
face's horizontal and vertical edge lines are paired instead: every rectangle whose four sides
lie on edges along most of their length (:data:`RECT_MIN_COVER`), front-sized, with a handle
inside, is a candidate; the best-outlined ones that do not overlap and repeat (a column of drawers
of one width with their handles at one place, a row of doors of one height) are the fronts. (No library
finds axis-aligned rectangles from two edge maps: OpenCV's contour approximation needs closed
contours, which the gaps between a drawer and its frame rarely give.) Where no outline shows (a
dark face under JPEG noise), a column of evenly spaced pulls of one size is a stack of drawers
(:func:`handle_column`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["RECT_MIN_COVER", "handle_column", "handle_grid", "inside_stiles", "outlined_rectangles"]

#: Each side of a front's rectangle lies on edges along at least this share of its length.
RECT_MIN_COVER = 0.6
#: Fronts' sizes (m): at least RECT_MIN_M on each side, at most RECT_MAX_M.
RECT_MIN_M = 0.07
RECT_MAX_M = 1.2
#: Candidate lines: rows (columns) where edges run along at least this share of the searched
#: box's width (height), local maxima, the LINES strongest.
LINE_MIN_SHARE = 0.1
LINES = 40
#: Two rectangles overlapping by more than this share of the smaller are one front.
MAX_OVERLAP = 0.2
#: An outlined rectangle inside another and under this share of its area makes the other a frame.
MIN_NESTED = 0.6
#: Fronts repeat: sizes and edges within this share, handles within HANDLE_ALIGN of the size.
ALIGN_SHARE = 0.1
HANDLE_ALIGN = 0.1


def _lines(emap: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """Indices (along axis 0) of candidate lines of ``emap`` ((n, m) bool, lines along axis 1)
    over its columns lo..hi."""
    prof = emap[:, lo:hi].mean(axis=1)
    peak = (prof >= LINE_MIN_SHARE) & (prof >= np.roll(prof, 1)) & (prof >= np.roll(prof, -1))
    idx = np.flatnonzero(peak)
    return np.sort(idx[np.argsort(-prof[idx], kind="stable")[:LINES]])


def _cover(cum: np.ndarray, line: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Share of [a, b) on edges along each ``line`` (prefix sums ``cum`` (n, m + 1) along the
    line direction); line, a, b broadcast together."""
    return (cum[line, b] - cum[line, a]) / np.maximum(b - a, 1)


def outlined_rectangles(horiz: np.ndarray, vert: np.ndarray, box: tuple[int, int, int, int], m_per_px: float, handle_in) -> list[tuple[tuple[int, int, int, int], float, object]]:
    """Fronts outlined by edges inside ``box`` (x0, y0, x1, y1) of a face: [(rectangle (x0, y0,
    x1, y1), the least cover of its sides, its handle)], best outlined first, none overlapping
    (:data:`MAX_OVERLAP`). horiz, vert: (h, w) bool edge maps; handle_in(box) -> the handle
    inside a rectangle or None (rectangles without one are left out)."""
    x0, y0, x1, y1 = box
    rows = _lines(horiz, x0, x1)
    cols = _lines(vert.T, y0, y1)
    rows = rows[(rows >= y0) & (rows < y1)]
    cols = cols[(cols >= x0) & (cols < x1)]
    if len(rows) < 2 or len(cols) < 2:
        return []
    ch = np.concatenate([np.zeros((horiz.shape[0], 1)), np.cumsum(horiz, axis=1)], axis=1)
    cv = np.concatenate([np.zeros((vert.shape[1], 1)), np.cumsum(vert.T, axis=1)], axis=1)
    lo_px, hi_px = RECT_MIN_M / m_per_px, RECT_MAX_M / m_per_px
    ri, rj = np.triu_indices(len(rows), 1)
    ci, cj = np.triu_indices(len(cols), 1)
    r0, r1 = rows[ri], rows[rj]
    c0, c1 = cols[ci], cols[cj]
    okr = (r1 - r0 >= lo_px) & (r1 - r0 <= hi_px)
    okc = (c1 - c0 >= lo_px) & (c1 - c0 <= hi_px)
    r0, r1, c0, c1 = r0[okr], r1[okr], c0[okc], c1[okc]
    if len(r0) == 0 or len(c0) == 0:
        return []
    top = _cover(ch, r0[:, None], c0[None, :], c1[None, :])
    bottom = _cover(ch, r1[:, None], c0[None, :], c1[None, :])
    left = _cover(cv, c0[None, :], r0[:, None], r1[:, None])
    right = _cover(cv, c1[None, :], r0[:, None], r1[:, None])
    score = np.minimum(np.minimum(top, bottom), np.minimum(left, right))
    a, b = np.nonzero(score >= RECT_MIN_COVER)
    rects = np.stack([c0[b], r0[a], c1[b], r1[a]], axis=1)
    handles = [handle_in(tuple(int(v) for v in r)) for r in rects]
    keep = np.array([h is not None for h in handles], dtype=bool)
    rects, cover, handles = rects[keep], score[a, b][keep], [h for h in handles if h is not None]
    # A rectangle holding a smaller outlined one with a handle (under MIN_NESTED of its area) is
    # the frame around fronts, not a front: two drawers and the rails between them.
    area = (rects[:, 2] - rects[:, 0]) * (rects[:, 3] - rects[:, 1])
    tol = 2
    inside = ((rects[None, :, 0] >= rects[:, None, 0] - tol) & (rects[None, :, 1] >= rects[:, None, 1] - tol)
              & (rects[None, :, 2] <= rects[:, None, 2] + tol) & (rects[None, :, 3] <= rects[:, None, 3] + tol)
              & (area[None, :] < MIN_NESTED * area[:, None]))
    minimal = ~inside.any(axis=1)
    order = [k for k in np.lexsort((-area, -cover)) if minimal[k]]  # best outlined, then larger
    out: list[tuple[tuple[int, int, int, int], float, object]] = []
    for k in order:
        rect = tuple(int(v) for v in rects[k])
        hd = handles[k]
        if any(h is hd for _, _, h in out):
            continue
        clash = False
        for (q0, p0, q1, p1), _, _ in out:
            inter = max(0, min(rect[2], q1) - max(rect[0], q0)) * max(0, min(rect[3], p1) - max(rect[1], p0))
            if inter > MAX_OVERLAP * min(int(area[k]), (q1 - q0) * (p1 - p0)):
                clash = True
                break
        if not clash:
            out.append((rect, float(cover[k]), hd))
    return _repeated(out)


def _repeated(rects: list[tuple[tuple[int, int, int, int], float, object]]) -> list[tuple[tuple[int, int, int, int], float, object]]:
    """The rectangles that repeat: stacked in a column with another (widths and left edges
    within ALIGN_SHARE of the width, handles at the same place across them, within HANDLE_ALIGN
    of the width: a chest's drawers) or side by side in a row (heights and tops within
    ALIGN_SHARE of the height, handles at the same height: a pair of doors). A lone outlined
    rectangle with a handle-like blob in it is as often a cane panel, a picture or a moulding."""
    keep = set()
    for i, ((a0, b0, a1, b1), _, hi) in enumerate(rects):
        for j in range(i + 1, len(rects)):
            (c0, d0, c1, d1), _, hj = rects[j]
            w, h = max(a1 - a0, c1 - c0), max(b1 - b0, d1 - d0)
            column = (abs((a1 - a0) - (c1 - c0)) <= ALIGN_SHARE * w and abs(a0 - c0) <= ALIGN_SHARE * w
                      and abs((hi.centre[0] - a0) / (a1 - a0) - (hj.centre[0] - c0) / (c1 - c0)) <= HANDLE_ALIGN)
            row = (abs((b1 - b0) - (d1 - d0)) <= ALIGN_SHARE * h and abs(b0 - d0) <= ALIGN_SHARE * h
                   and abs((hi.centre[1] - b0) / (b1 - b0) - (hj.centre[1] - d0) / (d1 - d0)) <= HANDLE_ALIGN)
            if column or row:
                keep.update((i, j))
    return [r for i, r in enumerate(rects) if i in keep]


#: Handles of one column of drawers: centres within COLUMN_SHARE of the searched box's width of
#: each other across, sizes within a factor HANDLE_SIZE_RATIO, spacings within SPACING_SHARE of
#: their mean and at least RECT_MIN_M.
COLUMN_SHARE = 0.06
HANDLE_SIZE_RATIO = 1.5
SPACING_SHARE = 0.25
#: ... and at least this share of the strongest handle's score, and no taller than KNOB_ASPECT
#: times their width.
HANDLE_STRONG = 0.5
KNOB_ASPECT = 1.2


def _pulls_in(handles: list, box: tuple[int, int, int, int], mask: np.ndarray | None) -> list:
    """The handles centred in ``box`` (and on ``mask``, when given) that lie or are knobs: drawer
    pulls (a standing bar is a door's, beside the gap of a pair)."""
    x0, y0, x1, y1 = box
    return [hd for hd in handles if x0 <= hd.centre[0] < x1 and y0 <= hd.centre[1] < y1
            and (mask is None or mask[int(hd.centre[1]), int(hd.centre[0])])
            and hd.box[3] - hd.box[1] <= KNOB_ASPECT * (hd.box[2] - hd.box[0])]


def _strong(handles: list) -> list:
    """The handles of at least HANDLE_STRONG of the strongest's score (JPEG blocks and grain give
    many weak blobs)."""
    strongest = max(hd.score for hd in handles)
    return [hd for hd in handles if hd.score >= HANDLE_STRONG * strongest]


def handle_column(handles: list, box: tuple[int, int, int, int], m_per_px: float, mask: np.ndarray | None = None) -> list[tuple[tuple[int, int, int, int], float, object]]:
    """Drawers told by their handles alone, for a face too dark or too blurred to show its
    fronts' outlines (sunrgbd_imvotenet_000004's night stand: its two pulls stand out, its
    drawers' edges are under the JPEG noise): two or more handles ``handles`` (the parser's, each
    with .box and .centre) one above the other at one place across ``box``, of one size and evenly
    spaced, are that many drawers as wide as the box, each centred on its handle and as tall as
    the spacing. ``mask``: (h, w) bool, the object on the face; handles off it do not count (a
    bed's edge beside a night stand). [(rectangle, 0.0, handle)], top to bottom; [] when no such
    column stands out (or two do)."""
    x0, y0, x1, y1 = box
    w = x1 - x0
    inside = _pulls_in(handles, box, mask)
    if not inside:
        return []
    # The strong ones only, and of blobs one above the other closer than the smallest front, the
    # stronger (a pull's bar and its backplate).
    inside = sorted(_strong(inside), key=lambda hd: -hd.score)
    near = RECT_MIN_M / m_per_px
    kept: list = []
    for hd in inside:
        if not any(abs(hd.centre[0] - k.centre[0]) <= COLUMN_SHARE * w and abs(hd.centre[1] - k.centre[1]) < near for k in kept):
            kept.append(hd)
    inside = kept
    columns: dict[frozenset, list] = {}
    for a in inside:
        size_a = max(a.box[2] - a.box[0], a.box[3] - a.box[1])
        col = [hd for hd in inside if abs(hd.centre[0] - a.centre[0]) <= COLUMN_SHARE * w
               and 1.0 / HANDLE_SIZE_RATIO <= max(hd.box[2] - hd.box[0], hd.box[3] - hd.box[1]) / max(size_a, 1) <= HANDLE_SIZE_RATIO]
        col.sort(key=lambda hd: hd.centre[1])
        if len(col) < 2:
            continue
        gaps = np.diff([hd.centre[1] for hd in col])
        if gaps.min() * m_per_px < RECT_MIN_M or np.max(np.abs(gaps - gaps.mean())) > SPACING_SHARE * gaps.mean():
            continue
        columns[frozenset(id(h) for h in col)] = col
    longest = max((len(c) for c in columns.values()), default=0)
    best = [c for c in columns.values() if len(c) == longest]
    if len(best) != 1:
        return []  # none, or two columns as good: no telling which
    best = best[0]
    step = float(np.mean(np.diff([hd.centre[1] for hd in best])))
    out = []
    for hd in best:
        top = max(float(y0), hd.centre[1] - 0.5 * step)
        bottom = min(float(y1), hd.centre[1] + 0.5 * step)
        out.append(((int(x0), int(round(top)), int(x1), int(round(bottom))), 0.0, hd))
    return out


#: Handles of one row of fronts: centres within ROW_M of each other in height.
ROW_M = 0.03
#: A vertical line between two handles of a row splits them into two fronts when edges run along
#: at least this share of the row's height there (else they are one front's pair of pulls).
SPLIT_COVER = 0.5
#: A row's outer boundary (the top of the top row, the bottom of the bottom row) is the strongest
#: horizontal line this far from its handles' centre, in shares of the next row's half-spacing.
OUTER_SEARCH = (0.5, 1.6)


def _strongest(profile: np.ndarray, lo: float, hi: float) -> int | None:
    """Index of the largest value of ``profile`` in [lo, hi) (clipped), or None when the range is
    empty or holds no line (below LINE_MIN_SHARE)."""
    a, b = max(0, int(np.ceil(lo))), min(len(profile), int(np.floor(hi)))
    if b <= a:
        return None
    i = a + int(np.argmax(profile[a:b]))
    return i if profile[i] >= LINE_MIN_SHARE else None


#: A "handle" with horizontal edges running on along at least ON_LINE_SHARE of ON_LINE_REACH (its
#: own width twice, at least ON_LINE_MIN_M) on both sides is a piece of a lit edge (a drawer's
#: bevel catching the light), not a handle (a bail pull's post beside its bar is one).
ON_LINE_SHARE = 0.7
ON_LINE_REACH = 2.0
ON_LINE_MIN_M = 0.1


def _on_line(hd, horiz: np.ndarray, m_per_px: float) -> bool:
    """The handle ``hd`` lies on a horizontal edge line that runs on past both its ends."""
    a0, b0, a1, b1 = (int(v) for v in hd.box)
    reach = max(int(ON_LINE_REACH * max(a1 - a0, 1)), int(round(ON_LINE_MIN_M / m_per_px)))
    band = horiz[max(0, b0 - 1):b1 + 1].any(axis=0)
    left, right = band[max(0, a0 - reach):a0], band[a1:a1 + reach]
    return len(left) > 0 and len(right) > 0 and left.mean() >= ON_LINE_SHARE and right.mean() >= ON_LINE_SHARE


def handle_grid(handles: list, horiz: np.ndarray, vert: np.ndarray, box: tuple[int, int, int, int], m_per_px: float,
                mask: np.ndarray | None = None) -> list[tuple[tuple[int, int, int, int], float, object]]:
    """Fronts told by rows of handles, for a dresser whose drawers sit in rows of different
    heights and counts (a row of small drawers with a knob each over wide ones with two-post
    pulls: sunrgbd_imvotenet_000003), too dark for the cuts to find their outlines reliably.

    The strong lying or knob-like handles on the object (as :func:`handle_column`) are grouped in
    rows (centres within ROW_M in height, rows at least RECT_MIN_M apart). Between two rows, the
    strongest horizontal edge line (share of ``box``'s width on ``horiz``) is their boundary (the
    middle when none shows); above the top row and below the bottom one, the strongest line at
    about the next row's half-spacing, else the box's edge. In a row, two neighbouring handles
    are two fronts when a vertical edge line runs along SPLIT_COVER of the row's height between
    them (split there), else one front's pair of pulls. Fronts span ``box`` across. Two fronts at
    least, else []. [(rectangle (x0, y0, x1, y1), 0.0, handle)], the handle of a front with
    several being their union, top to bottom, left to right."""
    from dataclasses import replace

    x0, y0, x1, y1 = box
    inside = [hd for hd in _pulls_in(handles, box, mask) if not _on_line(hd, horiz, m_per_px)]
    if len(inside) < 2:
        return []
    inside = sorted(_strong(inside), key=lambda hd: hd.centre[1])
    rows: list[list] = []
    for hd in inside:
        if rows and hd.centre[1] - np.mean([r.centre[1] for r in rows[-1]]) <= ROW_M / m_per_px:
            rows[-1].append(hd)
        else:
            rows.append([hd])
    # rows closer than the smallest front are one row (knobs read at heights a few cm apart)
    merged: list[list] = []
    for r in rows:
        if merged and np.mean([hd.centre[1] for hd in r]) - np.mean([hd.centre[1] for hd in merged[-1]]) < RECT_MIN_M / m_per_px:
            merged[-1] = merged[-1] + r
        else:
            merged.append(r)
    rows = merged
    centres = [float(np.mean([hd.centre[1] for hd in r])) for r in rows]
    prof_h = horiz[:, x0:x1].mean(axis=1)
    bounds = []
    for (ra, rb), (ca, cb) in zip(zip(rows, rows[1:]), zip(centres, centres[1:])):
        lo = max(hd.box[3] for hd in ra)
        hi = min(hd.box[1] for hd in rb)
        y = _strongest(prof_h, lo, hi)
        bounds.append(float(y) if y is not None else 0.5 * (ca + cb))
    top = bottom = None
    if bounds:
        h_top, h_bot = bounds[0] - centres[0], centres[-1] - bounds[-1]
        top = _strongest(prof_h, centres[0] - OUTER_SEARCH[1] * h_top,
                         min(centres[0] - OUTER_SEARCH[0] * h_top, min(hd.box[1] for hd in rows[0])))
        bottom = _strongest(prof_h, max(centres[-1] + OUTER_SEARCH[0] * h_bot, max(hd.box[3] for hd in rows[-1]) + 1),
                            centres[-1] + OUTER_SEARCH[1] * h_bot + 1)
    edges = [float(y0) if top is None else float(top)] + bounds + [float(y1) if bottom is None else float(bottom)]
    out = []
    for r, (t, b) in zip(rows, zip(edges, edges[1:])):
        t_i, b_i = int(round(t)), int(round(b))
        if (b_i - t_i) * m_per_px < RECT_MIN_M:
            return []
        r = sorted(r, key=lambda hd: hd.centre[0])
        prof_v = vert[t_i:b_i, :].mean(axis=0)
        cuts = [float(x0)]
        groups: list[list] = [[r[0]]]
        for a, c in zip(r, r[1:]):
            x = _strongest(prof_v, a.box[2], c.box[0])
            if x is not None and prof_v[x] >= SPLIT_COVER:
                cuts.append(float(x))
                groups.append([c])
            else:
                groups[-1].append(c)
        cuts.append(float(x1))
        for g, (a, c) in zip(groups, zip(cuts, cuts[1:])):
            if (c - a) * m_per_px < RECT_MIN_M or (c - a) * m_per_px > RECT_MAX_M:
                return []
            hd = g[0]
            if len(g) > 1:
                ub = (min(q.box[0] for q in g), min(q.box[1] for q in g), max(q.box[2] for q in g), max(q.box[3] for q in g))
                hd = replace(hd, box=ub, centre=(0.5 * (ub[0] + ub[2]), float(np.mean([q.centre[1] for q in g]))))
            out.append(((int(round(a)), t_i, int(round(c)), b_i), 0.0, hd))
    return out if len(out) >= 2 else []


#: A front told by handles spans the face's box across; its side moves in to the strongest vertical
#: edge line within STILE_SEARCH of the box's width from that side, when the line runs along at
#: least STILE_COVER of the fronts' height: the drawers' own edges inside a face frame's stiles
#: (sunrgbd_imvotenet_000005's dresser: its drawers start 4 cm in from the face).
STILE_SEARCH = 0.25
STILE_COVER = 0.5


def inside_stiles(rects: list, vert: np.ndarray, box: tuple[int, int, int, int]) -> list:
    """``rects`` ([(rectangle (x0, y0, x1, y1), score, handle)], from :func:`handle_column` or
    :func:`handle_grid`) with the sides that lie on ``box``'s sides moved in to the face frame's
    inner edges (:data:`STILE_SEARCH`, :data:`STILE_COVER`), never past a front's handle."""
    if not rects:
        return rects
    x0, _, x1, _ = box
    top, bottom = min(r[0][1] for r in rects), max(r[0][3] for r in rects)
    if bottom <= top:
        return rects
    prof = vert[top:bottom, :].mean(axis=0)
    reach = STILE_SEARCH * (x1 - x0)
    left = _strongest(prof, x0 + 1, x0 + reach)
    right = _strongest(prof, x1 - reach, x1 - 1)
    left = left if left is not None and prof[left] >= STILE_COVER else None
    right = right if right is not None and prof[right] >= STILE_COVER else None
    out = []
    for (a, t, c, b), score, hd in rects:
        if left is not None and a == x0 and (hd is None or left < hd.box[0]):
            a = int(left)
        if right is not None and c == x1 and (hd is None or right > hd.box[2]):
            c = int(right)
        out.append(((a, t, c, b), score, hd))
    return out
