"""A bed's headboard against the wall grown into the bed (perception.headboard).

A 100 x 100 pixel view of a bed seen from its foot: rows 60-94 its mattress (z = 0.6 m, y from
-1.0 to 1.0 m; rows 95-99 its end's face, down to 0.3 m), x from -0.75 to 0.75 m over columns 10-89), rows 0-59 the wall behind it at
y = -1.1 m (1 cm of sensor noise), rising from 0.6 m (row 59) to 1.2 m (row 20) and on to 2.0 m
(row 0); a headboard 3 cm off the wall over columns 10-89, rows 20-59 (0.6 to 1.2 m), measured
only at its edges and at a few studs, as a dark leather headboard is (sunrgbd_imvotenet_000005).
"""

from __future__ import annotations

import numpy as np

from perception.headboard import grow_headboards, headboard_pixels
from scene_builder.planes import Plane

WALL = Plane(np.array([0.0, 1.0, 0.0]), 1.1, "wall")  # y = -1.1, normal into the room


def _view(headboard: bool = True, to_ceiling: bool = False, dark_left: bool = False, seed: int = 0):
    """(points (100, 100, 3), measured, bed mask, headboard mask) of the module's view.
    ``to_ceiling``: the panel behind the bed runs up the whole wall (a wardrobe, a wall the
    room's planes missed). ``dark_left``: the headboard's left 12 columns measured nowhere."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0:100, 0:100].astype(np.float64)
    x = -0.75 + (cols - 10) / 79 * 1.5
    p = np.zeros((100, 100, 3))
    p[..., 0] = x
    p[..., 1] = -1.1 + rng.normal(0.0, 0.01, (100, 100))
    p[..., 2] = np.where(rows < 20, 2.0 - rows / 19 * 0.78, 1.2 - (rows - 20) / 39 * 0.6)
    p[rows >= 60, 2] = 0.0  # the floor beside the bed
    bed = (rows >= 60) & (cols >= 10) & (cols < 90)
    p[bed, 1] = (-1.0 + (rows - 60) / 39 * 2.0)[bed]
    p[bed, 2] = 0.6 + rng.normal(0.0, 0.005, int(bed.sum()))
    foot = rows >= 95  # the mattress's end face toward the camera, down to 0.3 m
    p[foot, 1] = 1.0
    p[foot, 2] = (0.6 - (rows - 94) * 0.06)[foot]
    head = (rows >= 20) & (rows < 60) & (cols >= 10) & (cols < 90)
    measured = np.ones((100, 100), dtype=bool)
    if headboard:
        p[head, 1] = -1.07 + rng.normal(0.0, 0.003, int(head.sum()))
        inner = (rows >= 24) & (rows < 57) & (cols >= 14) & (cols < 86)
        studs = ((rows - 30) % 12 < 4) & ((cols - 20) % 20 < 4)
        measured &= ~(inner & ~studs)  # the dark leather: its edges and studs measured only
        if dark_left:
            measured &= ~(head & (cols < 22))
    if to_ceiling:
        panel = (rows < 60) & (cols >= 10) & (cols < 90)
        p[panel, 1] = -0.8
    return p, measured, bed, head


def test_a_headboard_off_the_wall_is_the_beds_with_its_unmeasured_middle():
    p, measured, bed, head = _view()
    found = headboard_pixels(bed, p[bed], p, measured, bed, (WALL,))
    assert found is not None
    region, seen = found
    assert (region & head).sum() >= 0.9 * head.sum()  # the headboard, its unmeasured middle too
    # none of the wall around and above it, but for pixels on its border (the 7 x 7 median of the
    # distances to the wall there reads half the headboard)
    from scipy import ndimage

    assert not (region & ~ndimage.binary_dilation(head)).any()
    assert (region & ~head).sum() <= 0.05 * head.sum()
    assert (seen == (region & measured)).all()


def test_a_bare_wall_behind_a_bed_is_no_headboard():
    p, measured, bed, _ = _view(headboard=False)
    assert headboard_pixels(bed, p[bed], p, measured, bed, (WALL,)) is None


def test_what_rises_on_up_behind_a_bed_is_no_headboard():
    # 30 cm off the wall from the mattress up past the search's ceiling: a wardrobe, or a wall
    # the room's planes missed
    p, measured, bed, _ = _view(headboard=False, to_ceiling=True)
    assert headboard_pixels(bed, p[bed], p, measured, bed, (WALL,)) is None
    p, measured, bed, _ = _view(headboard=False)
    assert headboard_pixels(bed, p[bed], p, measured, bed, ()) is None


CAMERA = np.array([0.0, 3.0, 1.0])  # before the bed's foot


def test_grow_headboards_grows_beds_only_and_keeps_other_objects_pixels():
    # (the headboard's left 12 columns measured nowhere: they join it where their rays meet its
    # panel, past the hull of its measured pieces)
    p, measured, bed, head = _view(dark_left=True)
    rays = p - CAMERA  # each pixel's ray through the point it shows
    lamp = np.zeros_like(bed)
    lamp[30:40, 40:50] = True  # an object standing before the headboard keeps its pixels
    kept = [(bed, bed & measured), (lamp, lamp & measured)]
    points = [p[bed & measured], p[lamp & measured]]
    seen = np.where(measured[..., None], p, 0.0)  # what a sensor gives: nothing where unmeasured
    out_kept, out_points, grown = grow_headboards(kept, points, [("bed", 0.9), ("lamp", 0.8)], seen, measured, (WALL,), rays, CAMERA)
    assert grown == 1
    (bed_mask, bed_pix), (lamp_mask, _) = out_kept
    assert (bed_mask & head & ~lamp).sum() >= 0.9 * (head & ~lamp).sum() and not (bed_mask & lamp).any()
    assert lamp_mask is lamp and out_points[1] is points[1]
    # every pixel of the bed has its point: the measured ones as measured, the headboard's
    # unmeasured middle on the plane of its measured edges and studs (3 cm off the wall)
    assert (bed_pix == bed_mask).all()
    np.testing.assert_allclose(out_points[0], p[bed_pix], atol=0.015)  # (3 mm of noise on the panel)
    assert out_points[0][:, 2].max() > 1.15  # the bed now rises to its headboard's top
    # a sofa (or anything but a bed) is not grown
    _, _, grown = grow_headboards(kept, points, [("sofa", 0.9), ("lamp", 0.8)], seen, measured, (WALL,), rays, CAMERA)
    assert grown == 0
