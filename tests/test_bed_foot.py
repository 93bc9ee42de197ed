"""A bench at the foot of a bed cut out of the bed's points (perception.bed_foot)."""

from __future__ import annotations

import numpy as np

from perception.bed_foot import foot_bench, split_foot_benches


def _grid(x0, x1, y0, y1, z0, z1, step=0.02):
    """Points on an axis-aligned rectangle (one of x, y, z constant: pass it as both bounds)."""
    xs = np.arange(x0, x1 + 1e-9, step) if x1 > x0 else np.array([x0])
    ys = np.arange(y0, y1 + 1e-9, step) if y1 > y0 else np.array([y0])
    zs = np.arange(z0, z1 + 1e-9, step) if z1 > z0 else np.array([z0])
    return np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1).reshape(-1, 3)


def _bed(rails: bool = False) -> np.ndarray:
    """A bed seen from its foot (the camera down -x): a mattress top at 0.65 m from x = 2 to 4 m,
    its end's face at x = 2, a headboard at x = 4 up to 1.3 m."""
    parts = [_grid(2.0, 4.0, -0.8, 0.8, 0.65, 0.65), _grid(2.0, 2.0, -0.8, 0.8, 0.3, 0.64), _grid(4.0, 4.0, -0.8, 0.8, 0.66, 1.3)]
    if rails:  # a frame's side rails, their tops at 0.45 m along the whole length
        parts += [_grid(2.0, 4.0, -0.86, -0.82, 0.45, 0.45), _grid(2.0, 4.0, 0.82, 0.86, 0.45, 0.45)]
    return np.vstack(parts)


def _bench() -> np.ndarray:
    """A storage bench before the bed's foot: its top at 0.47 m from x = 1.3 to 1.9 m, its front's face at x = 1.3."""
    return np.vstack([_grid(1.3, 1.9, -0.7, 0.7, 0.47, 0.47), _grid(1.3, 1.3, -0.7, 0.7, 0.04, 0.46)])


def test_the_bench_at_a_beds_foot_is_cut_out_and_the_bed_keeps_its_own_points():
    bed, bench = _bed(), _bench()
    pts = np.vstack([bed, bench])
    part = foot_bench(pts)
    assert part is not None
    assert part[len(bed):].all()  # every point of the bench
    assert not part[: len(bed)].any()  # none of the bed's (its end's face at x = 2 included)


def test_a_bed_alone_or_with_its_frames_rails_keeps_every_point():
    assert foot_bench(_bed()) is None
    # rails as low as a bench's top, but along the bed's length, under the mattress: no bench
    assert foot_bench(_bed(rails=True)) is None
    # a step too narrow to sit on (a platform's 10 cm lip at the foot) is the bed's
    lip = _grid(1.9, 1.98, -0.8, 0.8, 0.47, 0.47, step=0.01)
    assert foot_bench(np.vstack([_bed(), lip])) is None


def test_split_foot_benches_parts_the_mask_and_leaves_other_labels_alone():
    pts = np.vstack([_bed(), _bench()])
    n = len(pts)
    # one image row of pixels with points (raster order), and a row under it the mask holds without depth
    pix = np.zeros((2, n), dtype=bool)
    pix[0] = True
    mask = np.ones((2, n), dtype=bool)
    kept, points, names, added = split_foot_benches([(mask, pix)], [pts], [("bed", 0.8)])
    assert added == 1 and [n_ for n_, _ in names] == ["bed", "bench"]
    (bed_mask, bed_pix), (bench_mask, bench_pix) = kept
    assert not (bed_mask & bench_mask).any() and ((bed_mask | bench_mask) == mask).all()
    assert len(points[0]) + len(points[1]) == n and points[1][:, 0].max() < 2.0
    assert (bench_mask[1] == bench_pix[0]).all()  # the pixels without depth follow the point above them
    same = split_foot_benches([(mask, pix)], [pts], [("sofa", 0.8)])
    assert same[3] == 0 and same[0][0][0] is mask
