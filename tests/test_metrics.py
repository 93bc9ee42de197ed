"""Metrics on hand-made cases with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from scene_builder.bench import metrics as M


def box(c, s, yaw=0.0):
    return M.Box3D(np.array(c, float), np.array(s, float), yaw)


def test_box_iou_identical_shifted_disjoint_and_rotated():
    a = box((0, 0, 0.5), (2, 1, 1), 0.3)
    assert M.box_iou_3d(a, a) == pytest.approx(1.0)
    # Shifted by half its length along its own x: overlap 1/2, union 3/2 -> 1/3.
    shift = 1.0 * np.array([np.cos(0.3), np.sin(0.3), 0.0])
    assert M.box_iou_3d(a, box(a.center_m + shift, (2, 1, 1), 0.3)) == pytest.approx(1 / 3)
    # Shifted by half its height: also 1/3; shifted beyond: 0.
    assert M.box_iou_3d(a, box((0, 0, 1.0), (2, 1, 1), 0.3)) == pytest.approx(1 / 3)
    assert M.box_iou_3d(a, box((0, 0, 2.0), (2, 1, 1), 0.3)) == 0.0
    # A unit square footprint rotated 45 degrees about the same centre: the overlap is the regular
    # octagon of area 2 (sqrt 2 - 1), so IoU = 2 (sqrt2 - 1) / (2 - 2 (sqrt2 - 1)).
    sq = box((0, 0, 0), (1, 1, 1))
    inter = 2 * (np.sqrt(2) - 1)
    assert M.box_iou_3d(sq, box((0, 0, 0), (1, 1, 1), np.pi / 4)) == pytest.approx(inter / (2 - inter))
    # A box rotated by 180 degrees is the same box.
    assert M.box_iou_3d(a, box((0, 0, 0.5), (2, 1, 1), 0.3 + np.pi)) == pytest.approx(1.0)


def test_yaw_error_respects_box_symmetry():
    rect, square = (2.0, 1.0, 1.0), (1.0, 1.02, 0.5)
    assert M.yaw_error_deg(np.radians(10), np.radians(190), rect) == pytest.approx(0.0, abs=1e-9)
    assert M.yaw_error_deg(np.radians(100), 0.0, rect) == pytest.approx(80.0)
    assert M.yaw_error_deg(np.radians(-30), np.radians(30), rect) == pytest.approx(60.0)
    assert M.yaw_error_deg(np.radians(95), 0.0, square) == pytest.approx(5.0)
    assert M.yaw_error_deg(np.radians(60), 0.0, square) == pytest.approx(30.0)
    assert M.yaw_period_deg(rect) == 180.0 and M.yaw_period_deg(square) == 90.0


def test_size_error_matches_axes_before_comparing():
    true = box((0, 0, 0), (2.0, 1.0, 0.5), 0.0)
    swapped = box((0, 0, 0), (1.0, 2.0, 0.5), np.pi / 2)  # the same box described 90 degrees off
    assert np.allclose(M.size_error_rel(swapped, true), 0.0)
    bigger = box((0, 0, 0), (2.2, 0.9, 0.75), 0.0)
    assert np.allclose(M.size_error_rel(bigger, true), [0.1, 0.1, 0.5])


def test_mask_iou_and_matrix():
    a = np.zeros((10, 10), bool)
    a[:5] = True
    b = np.zeros((10, 10), bool)
    b[:, :5] = True
    assert M.mask_iou(a, b) == pytest.approx(25 / 75)
    assert M.mask_iou(a, a) == 1.0
    assert M.mask_iou(np.zeros_like(a), np.zeros_like(a)) == 0.0
    ids = np.zeros((10, 10), np.uint16)
    ids[:5] = 3
    ids[5:, 5:] = 7
    iou = M.mask_iou_matrix([a, b], ids, [3, 7])
    assert iou[0, 0] == pytest.approx(1.0) and iou[0, 1] == 0.0
    assert iou[1, 0] == pytest.approx(25 / 75) and iou[1, 1] == pytest.approx(0.0)


def test_hungarian_mask_matching_prefers_the_global_optimum():
    # Greedy would give pred 0 -> true 0 (0.6) and leave pred 1 with 0.3; the optimum is 0.55 + 0.5.
    iou = np.array([[0.6, 0.55], [0.5, 0.3]])
    m = M.match_by_mask_iou(iou)
    assert m.pairs == ((0, 1), (1, 0))
    # Below the IoU floor nothing matches.
    assert M.match_by_mask_iou(np.array([[0.1]])).pairs == ()


def test_centre_matching_gates_by_true_size():
    true = [box((0, 0, 0.5), (1, 1, 1)), box((3, 0, 0.1), (0.1, 0.1, 0.1))]
    pred = np.array([[0.4, 0.3, 0.5], [3.5, 0.0, 0.1], [10, 0, 0]])
    m = M.match_by_center(pred, true)
    # Pred 0 is 0.5 m from a box of diagonal 1.73 m (gate 0.87): matched; pred 1 is 0.5 m from a
    # 0.17 m box (gate 0.3): not matched; pred 2 is far from everything.
    assert m.pairs == ((0, 0),) and m.scores[0] == pytest.approx(0.5)
    r, p = M.recall_precision(len(m.pairs), len(true), len(m.pairs), len(pred))
    assert r == pytest.approx(0.5) and p == pytest.approx(1 / 3)
    assert M.recall_precision(0, 0, 0, 0) == (None, None)


def test_depth_absrel_category_and_summaries():
    true = np.full((4, 4), 2.0)
    pred = true * 1.1
    pred[0, 0] = 0.0  # invalid prediction pixel is ignored
    assert M.depth_absrel(pred, true) == pytest.approx(0.1)
    mask = np.zeros((4, 4), bool)
    assert M.depth_absrel(pred, true, mask) is None
    assert M.category_accuracy(["chair", "cabinet"], ["chair", "drawer_unit"]) == 0.5
    assert M.category_accuracy(["cabinet"], ["drawer_unit"], {"drawer_unit": ("cabinet",)}) == 1.0
    assert M.median_or_none([1.0, None, 3.0]) == 2.0 and M.median_or_none([]) is None
    assert M.p90_or_none(list(range(11))) == pytest.approx(9.0)
    assert M.relative_error(11.0, 10.0) == pytest.approx(0.1)
