"""People and animals are removed from the room (perception.people): no object takes their pixels,
and the background fills what they hid, on a real COCO photo with its ground-truth masks."""

from __future__ import annotations

import json

import numpy as np
import pytest

from perception.detection import CONFIDENT
from perception.people import people_boxes, people_pixels, removal_mask
from perception.protocols import Detections, SemanticMap
from tests.conftest import SHARED, require

PHOTOS_GT = SHARED / "data" / "photos_gt"


def _gt_people(sample, h: int, w: int) -> np.ndarray:
    from skimage.draw import polygon as draw_polygon

    out = np.zeros((h, w), dtype=bool)
    for g in json.loads((sample / "gt_instances.json").read_text()):
        if g["label"] != "person" or str(g.get("iscrowd", 0)) == "1":
            continue
        for p in g["polygon"]:
            p = np.asarray(p, dtype=np.float64).reshape(-1, 2)
            rr, cc = draw_polygon(p[:, 1], p[:, 0], (h, w))
            out[rr, cc] = True
    return out


def test_people_boxes_need_confidence_or_a_second_witness():
    boxes = np.array([[0, 0, 10, 20], [20, 0, 30, 20], [40, 0, 50, 20], [60, 0, 70, 20]], dtype=np.float64)
    dets = Detections(boxes, np.array([CONFIDENT, 0.6 * CONFIDENT, 0.6 * CONFIDENT, 0.9], dtype=np.float32), ("", "", "", "chair"), ("person", "Person", "dog", "chair"))
    assert people_boxes(dets).tolist() == [boxes[0].tolist()]
    seen = np.zeros((20, 80), dtype=bool)
    seen[:, 40:50] = True  # the semantic map sees the dog, not the second person
    assert sorted(map(tuple, people_boxes(dets, seen).tolist())) == sorted([tuple(boxes[0]), tuple(boxes[2])])
    sem = SemanticMap(np.array([[0, 1], [2, 3]], dtype=np.int32), ("", "", "chair", ""), ("background", "person", "chair", "dog"))
    assert people_pixels(sem).tolist() == [[False, True], [False, True]]
    assert people_pixels(SemanticMap(sem.classes, sem.labels)) is None
    grown = removal_mask([np.pad(np.ones((1, 1), bool), 10)], (21, 21))
    assert grown[10, 10] and grown[10, 13] and not grown[10, 14]


@pytest.mark.slow
def test_people_are_removed_from_a_real_living_room():
    """COCO 241: four people around two sofas. Their pixels belong to no object, the removal
    covers most of every true person, and the background's colour there is inpainted."""
    from perception import perceive
    from scene_builder.config import InputSpec, PerceptionConfig

    sample = require(PHOTOS_GT / "coco128_000000000241")
    p = perceive(InputSpec(sample / "rgb.jpg"), PerceptionConfig())
    assert p.removed_mask is not None
    h, w = p.removed_mask.shape
    truth = _gt_people(sample, h, w)
    assert truth.sum() > 0.2 * h * w
    assert (p.removed_mask & truth).sum() >= 0.85 * truth.sum()
    objects = np.zeros((h, w), dtype=bool)
    for o in p.objects:
        objects |= o.mask
        assert o.label != "object"
    assert not (objects & p.removed_mask).any()
    assert (objects & truth).sum() <= 0.02 * truth.sum()
    assert any(b.task == "people" and "removed" in b.reason for b in p.backends)
    # The background's texture holds the photo with the people inpainted (at the atlas's top left,
    # beside the completed room planes, after pack_atlas's 2-texel border): it differs where they were.
    photo = p.observation.photo_rgb
    tex = p.room.background.surface.texture.image_rgb[2 : 2 + photo.shape[0], 2 : 2 + photo.shape[1]]
    inner = truth & ~np.pad(~truth, 6, constant_values=True)[6:-6, 6:-6]  # away from the edges
    diff = np.abs(tex.astype(int) - photo.astype(int)).sum(axis=2)
    assert np.median(diff[inner]) > 30
    assert np.median(diff[~p.removed_mask]) == 0
