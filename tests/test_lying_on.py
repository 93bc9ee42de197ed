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
    the two are pillows lying on the bed's top, and the bed is what is under them."""
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
    assert np.percentile(bed.points_world_m[:, 2], 99) < top + 0.1  # the bed no longer holds them
    assert any(b.task == "lying-on" for b in p.backends)


def _bed_with_foot(bench: bool, headboard: bool = True, footboard_top_m: float = 0.6):
    """Points of a 2 m bed along x (its mattress top 0.6 m high over x in [0, 2], y in [-0.8,
    0.8]), a headboard at x = 2.05 rising to 1.2 m, a foot panel at x = -0.02 up to
    ``footboard_top_m``, and with ``bench`` a 0.5 m bench at its foot (x in [-0.6, -0.1], its
    seat 0.45 m high, its front face toward -x): (N, 3) points, (N,) True on the bench's."""
    g = np.linspace(0.0, 1.0, 41)
    a, b = np.meshgrid(g, g)
    a, b = a.ravel(), b.ravel()
    parts = [np.column_stack([2.0 * a, -0.8 + 1.6 * b, np.full(a.size, 0.6)])]
    if headboard:
        parts.append(np.column_stack([np.full(a.size, 2.05), -0.8 + 1.6 * b, 0.6 + 0.6 * a]))
    parts.append(np.column_stack([np.full(a.size, -0.02), -0.8 + 1.6 * b, 0.2 + (footboard_top_m - 0.2) * a]))
    on = [np.zeros(len(p), dtype=bool) for p in parts]
    if bench:
        seat = np.column_stack([-0.6 + 0.5 * a, -0.75 + 1.5 * b, np.full(a.size, 0.45)])
        front = np.column_stack([np.full(a.size, -0.6), -0.75 + 1.5 * b, 0.45 * a])
        parts += [seat, front]
        on += [np.ones(len(seat), dtype=bool), np.ones(len(front), dtype=bool)]
    return np.concatenate(parts), np.concatenate(on)


def test_a_bench_at_a_beds_foot_is_cut_out_of_it():
    """The bed's height profile, away from its headboard, steps down 15 cm past the mattress's
    end and stays down for 0.5 m: that is a bench, the bed is what is left (its foot panel
    included). No bench, a sleigh bed's footboard higher than its top, or no headboard to tell the
    foot by: nothing is cut."""
    from perception.lying_on import foot_part

    pts, truth = _bed_with_foot(bench=True)
    sel = foot_part(pts)
    assert sel is not None and np.array_equal(sel, truth)
    assert foot_part(_bed_with_foot(bench=False)[0]) is None
    assert foot_part(_bed_with_foot(bench=False, footboard_top_m=0.9)[0]) is None
    assert foot_part(_bed_with_foot(bench=True, headboard=False)[0]) is None


def test_split_lying_makes_the_bench_at_a_beds_foot_an_object():
    from perception.lying_on import split_lying

    pts, truth = _bed_with_foot(bench=True)
    pix = np.zeros((len(pts) // 100 + 1, 100), dtype=bool)
    pix.ravel()[: len(pts)] = True
    out_kept, out_points, names, added = split_lying([(pix.copy(), pix.copy())], [pts], [("bed", 0.9)])
    assert added == 1 and [n for n, _ in names] == ["bed", "bench"]
    assert len(out_points[1]) == np.count_nonzero(truth) and len(out_points[0]) == len(pts) - np.count_nonzero(truth)
    assert not (out_kept[0][0] & out_kept[1][0]).any()


@pytest.mark.slow
def test_the_bench_at_a_real_beds_foot_is_an_object_of_its_own():
    """sunrgbd_imvotenet_000004: a storage bench against the footboard was part of a 2.8 m "bed".
    Now it is a bench of its own, lower than the mattress, and the bed is a bed's length."""
    from perception import perceive
    from perception.perceive import gravity_aligned_size
    from scene_builder.config import InputSpec, PerceptionConfig
    from tests.conftest import require

    d = require(REAL_DATA / "sunrgbd_imvotenet_000004")
    import json

    cam = json.loads((d / "camera.json").read_text())
    p = perceive(InputSpec(d / "rgb.jpg", d / "depth.png", 0.001, (cam["fx"], cam["fy"], cam["cx"], cam["cy"])), PerceptionConfig(), seed=0)
    (bed,) = [o for o in p.objects if o.label == "bed"]
    (bench,) = [o for o in p.objects if o.label == "bench"]
    assert max(gravity_aligned_size(bed.points_world_m)[:2]) < 2.4
    assert np.percentile(bench.points_world_m[:, 2], 98) < top_height(bed.points_world_m[:, 2]) - 0.1
    assert not (bed.mask & bench.mask).any()
