"""Pillows lying on a bed are cut out of its mask as objects of their own (perception.lying_on)."""

from __future__ import annotations

import numpy as np
import pytest

from perception.lying_on import lying_parts, split_lying, top_height
from tests.conftest import REAL_DATA


def _bed(pillow_heights_m):
    """A (120, 160) pixel grid whose pixels carry the points of a bed seen from its foot: rows 0-7
    a headboard rising from 1.0 to 1.2 m behind the mattress, rows 10-19 what lies at the back of
    the mattress (``pillow_heights_m(y)``: height over the top at plan position y, 0 for bare
    mattress), rows 20-119 the bare mattress top at 0.6 m; 2 m deep, 1.6 m wide."""
    rows, cols = np.mgrid[0:120, 0:160]
    y = (cols - 80) / 100.0
    x = np.where(rows < 10, 2.05, 1.95 - (rows - 10) * 0.02)
    z = np.full(rows.shape, 0.6)
    z[rows < 8] = 1.0 + (7 - rows[rows < 8]) * 0.03
    pillow = (rows >= 10) & (rows < 20)
    z[pillow] += pillow_heights_m(y[pillow])
    pix = np.ones(rows.shape, dtype=bool)
    pix[8:10] = False  # the headboard's foot, hidden
    pts = np.stack([x[pix], y[pix], z[pix]], axis=1)
    return pix, pts


def _two(y):
    """Two 0.7 m pillows side by side, 15 cm high, touching at y = 0 (a dip of 10 cm there)."""
    return np.where(np.abs(y) < 0.72, 0.05 + 0.10 * np.minimum(1.0, np.abs(y) / 0.1) * np.minimum(1.0, (0.72 - np.abs(y)) / 0.1), 0.0)


def _bolster(y):
    """One 1.4 m bolster, 15 cm high all along."""
    return np.where(np.abs(y) < 0.7, 0.15, 0.0)


def test_top_height_is_the_mattress_not_the_headboard():
    pix, pts = _bed(_two)
    assert top_height(pts[:, 2]) == pytest.approx(0.6, abs=0.01)


def test_two_pillows_side_by_side_are_two_objects_and_the_headboard_is_neither():
    pix, pts = _bed(_two)
    parts = lying_parts(pix, pts)
    assert len(parts) == 2
    for sel in parts:
        p = pts[sel]
        assert p[:, 2].min() > 0.64 and p[:, 2].max() < 0.95  # above the top, below the headboard
        assert np.ptp(p[:, 1]) == pytest.approx(0.6, abs=0.15)  # one pillow wide
    assert not (parts[0] & parts[1]).any()
    assert np.sign(pts[parts[0], 1].mean()) != np.sign(pts[parts[1], 1].mean())  # one each side of the dip


def test_a_bolster_with_no_dip_stays_one_object_and_a_bare_bed_has_none():
    pix, pts = _bed(_bolster)
    (sel,) = lying_parts(pix, pts)
    assert np.ptp(pts[sel, 1]) == pytest.approx(1.4, abs=0.1)
    pix, pts = _bed(lambda y: np.zeros_like(y))
    assert lying_parts(pix, pts) == []


def test_split_lying_moves_the_pillows_out_of_a_bed_and_leaves_a_table_alone():
    pix, pts = _bed(_two)
    kept = [(pix.copy(), pix.copy()), (pix.copy(), pix.copy())]
    out_kept, out_points, names, added = split_lying(kept, [pts, pts], [("bed", 0.9), ("table", 0.8)])
    assert added == 2 and [n for n, _ in names] == ["bed", "table", "pillow", "pillow"]
    bed_mask, bed_pix = out_kept[0]
    assert len(out_points[0]) == np.count_nonzero(bed_pix) == len(pts) - len(out_points[2]) - len(out_points[3])
    assert not (bed_mask & out_kept[2][0]).any() and not (bed_mask & out_kept[3][0]).any()
    assert out_points[1] is pts and out_kept[1] is kept[1]


@pytest.mark.slow
def test_the_pillows_of_a_real_bed_are_objects_on_it():
    """sunrgbd_imvotenet_000005: a bed with two blue pillows against its headboard. The detector's
    box of the bed took both pillows (no pillow was an object; the bed stood to their tops). Now
    the two are pillows lying on the bed's top, and the bed is what is under them and its
    headboard against the wall behind them."""
    from perception import perceive
    from scene_builder.config import InputSpec, PerceptionConfig
    from tests.conftest import require

    d = require(REAL_DATA / "sunrgbd_imvotenet_000005")
    p = perceive(InputSpec(d / "rgb.jpg", d / "depth.png"), PerceptionConfig(), seed=0)
    (bed,) = [o for o in p.objects if o.label == "bed"]
    top = top_height(bed.points_world_m[:, 2])
    on_bed = []
    for o in p.objects:
        if o.label != "pillow":
            continue
        z = o.points_world_m[:, 2]
        if np.percentile(z, 5) > top and np.percentile(z, 95) < top + 0.35 and not (o.mask & bed.mask).any():
            on_bed.append(o.name)
    assert len(on_bed) == 2, [(o.name, o.label) for o in p.objects]
    # The bed no longer holds them (no pixel of theirs is the bed's, above); what of it rises
    # 20 cm over its top, above the pillows, is its headboard against the wall
    # (perception.headboard): 95 % of those points within 10 cm of the wall (median 5 cm).
    high = bed.points_world_m[bed.points_world_m[:, 2] > top + 0.2]
    assert len(high) > 0
    off_wall = np.min([high @ w.normal + w.offset_m for w in p.room.walls], axis=0)
    assert np.percentile(off_wall, 95) < 0.1
    assert any(b.task == "lying-on" for b in p.backends)
