"""The scoring of ``scene_builder.bench.detectors`` (box matching, AP at IoU 0.5, the COCO-by-max
merge it measures) on hand-made detections."""

from __future__ import annotations

import numpy as np
import pytest

from perception.protocols import Detections
from scene_builder.bench.detectors import merge_coco_by_max, score_boxes
from scene_builder.bench.nanodet_decoding import ap50


def _det(boxes, scores, labels, classes=None) -> Detections:
    return Detections(np.asarray(boxes, dtype=np.float64), np.asarray(scores, dtype=np.float32), tuple(labels), tuple(classes or labels))


def test_boxes_match_within_a_label_family_at_iou_half():
    truth = [([0, 0, 100, 100], "chair"), ([200, 0, 400, 100], "table")]
    boxes = np.array([[10, 0, 100, 100], [200, 0, 380, 100], [0, 0, 100, 100], [500, 500, 600, 600], [0, 0, 100, 100]], dtype=np.float64)
    scores = np.array([0.9, 0.8, 0.7, 0.6, 0.05])
    labels = ("chair", "desk", "chair", "sofa", "chair")
    s = score_boxes(boxes, scores, labels, truth, 0.1)
    # The desk matches the table (one family); the second chair finds its box taken; the sofa
    # matches nothing; the last chair is under the threshold.
    assert (s.matched, s.found, s.truth) == (2, 4, 2)
    s = score_boxes(boxes, scores, labels, truth, 0.1, keep=frozenset({"chair"}))
    assert (s.matched, s.found, s.truth) == (1, 2, 1)
    # Under IoU 0.5 no match: a box half as wide.
    assert score_boxes(np.array([[0, 0, 40, 100.0]]), np.array([0.9]), ("chair",), truth, 0.1).matched == 0


def test_ap50_ranks_the_detections():
    truth = np.array([[0, 0, 10, 10, 1], [20, 0, 30, 10, 2]], dtype=np.float64)
    perfect = np.array([[0, 0, 10, 10, 0.9, 1], [20, 0, 30, 10, 0.8, 2]], dtype=np.float64)
    assert ap50([(truth, perfect)]) == pytest.approx(1.0)
    # A wrong class ranked first: precision 1/2 then 2/3 at recall 1/2 and 1 -> AP 2/3.
    wrong_first = np.array([[0, 0, 10, 10, 0.95, 7], [0, 0, 10, 10, 0.9, 1], [20, 0, 30, 10, 0.8, 2]], dtype=np.float64)
    assert ap50([(truth, wrong_first)]) == pytest.approx(2 / 3)
    assert ap50([(truth, np.zeros((0, 6)))]) == 0.0


def test_coco_detectors_pool_by_max_and_fuse_with_the_others():
    box = [[0, 0, 100, 100]]
    centernet = _det(box, [0.3], ["chair"])  # accept 0.3 -> 0.5
    nanodet = _det(box, [0.4], ["chair"])  # accept 0.5 -> 0.4
    ssd = _det(box, [0.5], ["chair"], ["Chair"])  # Open Images class: not pooled
    merged = merge_coco_by_max([(centernet, 0.3), (nanodet, 0.5), (ssd, 0.5)])
    # The COCO pair gives max(0.5, 0.4) = 0.5 (not the noisy-or 0.7); the SSD's 0.5 then fuses.
    assert len(merged) == 1 and merged.scores[0] == pytest.approx(1 - 0.5 * 0.5, abs=1e-6)
    # With one COCO detector it is the product's merge.
    from perception.detection import merge_detections

    alone = merge_coco_by_max([(centernet, 0.3), (ssd, 0.5)])
    ref = merge_detections([(centernet, 0.3), (ssd, 0.5)])
    assert np.allclose(alone.scores, ref.scores) and alone.labels == ref.labels
