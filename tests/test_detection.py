"""Offline detectors, the semantic map, GrabCut box masks, floor-contact placement and the
detection-driven segmenter's registry wiring, on real photos and rendered rooms."""

from __future__ import annotations

import json

import numpy as np
import pytest

from perception.detection import (
    COCO_CLASSES,
    COCO_TO_LABEL,
    CONFIDENT,
    OID_TO_LABEL,
    PASCAL_TO_LABEL,
    box_iou,
    box_is_slice,
    merge_detections,
    suppress,
)
from perception.protocols import Detections
from scene_builder.config import PerceptionConfig
from scene_builder.vocabulary import LABELS
from tests.conftest import MODELS, PHOTOS, require
from tests.test_learned_sam2 import tiny_sam  # noqa: F401  (fixture)


def _rgb(name: str) -> np.ndarray:
    from PIL import Image

    d = require(PHOTOS / name)
    path = next(p for p in (d / "rgb.jpg", d / "rgb.png") if p.exists())
    return np.asarray(Image.open(path).convert("RGB"))


def _demo_boxes(name: str, cls: tuple[str, ...]) -> np.ndarray:
    """The 2D boxes of the Total3D demo inputs (a second opinion on what is where, not used by
    the code under test)."""
    meta = json.loads((require(PHOTOS / name) / "meta.json").read_text())
    boxes = meta["extra_annotations_not_gt"]["detections_2d"]["boxes"]
    return np.array([b["bbox"] for b in boxes if b["class"] in cls], dtype=np.float64)


def _det(boxes, scores, labels) -> Detections:
    return Detections(np.asarray(boxes, dtype=np.float64), np.asarray(scores, dtype=np.float32), tuple(labels), tuple(labels))


def test_class_maps_target_the_vocabulary():
    assert len(COCO_CLASSES) == 80
    # The indices the models README gives for the CenterNet output.
    assert [COCO_CLASSES[i] for i in (0, 56, 57, 59, 60, 62)] == ["person", "chair", "couch", "bed", "dining table", "tv"]
    assert set(COCO_TO_LABEL) <= set(COCO_CLASSES)
    for table in (COCO_TO_LABEL, OID_TO_LABEL, PASCAL_TO_LABEL):
        assert set(table.values()) <= set(LABELS)
    if MODELS.exists():
        oid = [line.strip() for line in (MODELS / "object_detection_oidv4_labelmap.txt").read_text().splitlines()]
        pascal = [line.strip() for line in (MODELS / "pascal_voc_segmentation_labels.txt").read_text().splitlines()]
        assert set(OID_TO_LABEL) <= set(oid) and set(PASCAL_TO_LABEL) <= set(pascal)


def test_box_iou_suppress_and_merge():
    a = [[0, 0, 10, 10], [5, 0, 15, 10], [100, 100, 110, 110]]
    iou = box_iou(np.array(a), np.array(a))
    assert iou[0, 0] == pytest.approx(1.0) and iou[0, 1] == pytest.approx(50 / 150) and iou[0, 2] == 0.0
    # One family (table, desk) suppresses within itself; a chair on the same box survives unless
    # it is nearly the same box (IoU 0.8: one detector calling one thing two names).
    d = _det([[0, 0, 10, 10], [1, 0, 11, 10], [0, 0, 10, 10.5], [50, 50, 60, 60]], [0.9, 0.5, 0.4, 0.3], ["table", "desk", "chair", "chair"])
    s = suppress(d, 0.5)
    assert s.labels == ("table", "chair") and np.allclose(s.boxes_xyxy_px[1], [50, 50, 60, 60])
    # A class outside the vocabulary never suppresses one inside it.
    s = suppress(_det([[0, 0, 10, 10], [0, 0, 10, 10]], [0.9, 0.4], ["", "chair"]))
    assert "chair" in s.labels
    # Two detectors agreeing on one table: one box, noisy-or of the rescaled scores.
    one = _det([[0, 0, 100, 50]], [0.3], ["table"])
    two = _det([[5, 0, 100, 55], [200, 0, 250, 50]], [0.25, 0.5], ["desk", "chair"])
    m = merge_detections([(one, 0.3), (two, 0.5)])
    assert len(m) == 2
    fused = m.labels.index("table")
    assert m.scores[fused] == pytest.approx(1 - (1 - CONFIDENT) * (1 - 0.25), abs=1e-6)
    assert m.scores[m.labels.index("chair")] == pytest.approx(CONFIDENT)
    # One bed boxed as a couch by one detector and as a table by the other: kept once.
    couch = _det([[180, 149, 636, 518]], [0.26], ["sofa"])
    table = _det([[180, 160, 637, 510]], [0.3], ["table"])
    m = merge_detections([(couch, 0.3), (table, 0.5)])
    assert m.labels == ("sofa",)


def test_a_slice_box_spans_its_outer_box_one_way_and_shares_three_sides():
    night_stand = np.array([604.0, 299.0, 729.0, 530.0])
    assert box_is_slice(np.array([599.0, 365.0, 729.0, 530.0]), night_stand)  # its lower drawers (5 px past the left side)
    assert box_is_slice(np.array([604.0, 299.0, 729.0, 420.0]), night_stand)  # its upper part
    assert not box_is_slice(np.array([630.0, 250.0, 700.0, 300.0]), night_stand)  # a lamp on it: not inside
    assert not box_is_slice(np.array([640.0, 380.0, 700.0, 450.0]), night_stand)  # a handle on its face: no shared side
    assert not box_is_slice(np.array([604.0, 480.0, 729.0, 530.0]), night_stand)  # its plinth: too small a share
    assert not box_is_slice(night_stand, np.array([599.0, 365.0, 729.0, 530.0]))  # the whole is no slice of its part


def test_family_refinement_follows_a_size_aware_posterior():
    from perception.detection import refine_in_family

    class Posterior:
        """The size-aware namer's answer for two objects (a bed and a real sofa)."""

        def label_scores_many(self, crops, masks, sizes):
            return [{"bed": 0.6, "sofa": 0.2, "chair": 0.2}, {"bed": 0.3, "sofa": 0.4, "chair": 0.3}][: len(crops)]

    crop = (np.zeros((4, 4, 3), np.uint8), np.ones((4, 4), bool))
    names = [("sofa", 0.4), ("sofa", 0.7), ("chair", 0.9)]
    out = refine_in_family(Posterior(), names, [crop] * 3, [(2.0, 1.5, 0.6)] * 3)
    # The first is a bed (three times the posterior), the second stays a sofa (not twice as
    # likely a bed), the chair's family has one member: it is not asked about.
    assert out == [("bed", 0.4), ("sofa", 0.7), ("chair", 0.9)]
    assert refine_in_family(object(), names, [crop] * 3, [(1.0, 1.0, 1.0)] * 3) == names
    # A surer detection needs surer evidence: three times the posterior renames a sofa boxed at
    # 0.5 (odds 1), not one boxed at 0.8 (odds 4: eight times would be needed).
    assert refine_in_family(Posterior(), [("sofa", 0.5)], [crop], [(2.0, 1.5, 0.6)]) == [("bed", 0.5)]
    assert refine_in_family(Posterior(), [("sofa", 0.8)], [crop], [(2.0, 1.5, 0.6)]) == [("sofa", 0.8)]


def test_ssd_anchors_follow_the_object_detection_api_layout():
    from perception.learned.detectors import ssd_anchors

    a = ssd_anchors()
    assert a.shape == (1917, 4)
    # First cell of the 19 x 19 map: (0.1, 1), (0.2, 2), (0.2, 1/2) as (scale, aspect ratio).
    assert np.allclose(a[0], [0.5 / 19, 0.5 / 19, 0.1, 0.1])
    assert np.allclose(a[1], [0.5 / 19, 0.5 / 19, 0.2 / np.sqrt(2), 0.2 * np.sqrt(2)])
    # The last anchor: the 1 x 1 map, interpolated scale sqrt(0.95 * 1.0) at ratio 1.
    assert np.allclose(a[-1], [0.5, 0.5, np.sqrt(0.95), np.sqrt(0.95)])


@pytest.fixture(scope="module")
def detectors():
    require(MODELS)
    from perception.learned.detectors import CenterNetCocoDetector, DeepLabPascalSegmenter, SsdOidDetector

    return (
        CenterNetCocoDetector(MODELS / "centernet_mbv3_coco.onnx"),
        SsdOidDetector(MODELS / "object_detection_ssd_mobilenetv2_oidv4_fp16.tflite"),
        DeepLabPascalSegmenter(MODELS / "deeplabv3_mnv2_pascal_quant.tflite"),
    )


def test_centernet_finds_the_three_chairs_of_the_cafe_photo(detectors):
    cn = detectors[0]
    d = cn.detect(_rgb("sunrgbd_total3d_demo_2"))
    chairs = d.boxes_xyxy_px[[i for i, (lab, s) in enumerate(zip(d.labels, d.scores)) if lab == "chair" and s >= cn.accept_score]]
    truth = _demo_boxes("sunrgbd_total3d_demo_2", ("chair",))
    assert len(truth) == 3 and len(chairs) >= 3
    assert (box_iou(truth, chairs).max(axis=1) >= 0.6).all()
    again = cn.detect(_rgb("sunrgbd_total3d_demo_2"))
    assert np.array_equal(again.boxes_xyxy_px, d.boxes_xyxy_px)  # deterministic


def test_ssd_finds_the_classroom_desks_that_coco_lacks(detectors):
    ssd = detectors[1]
    d = ssd.detect(_rgb("sunrgbd_total3d_demo_4"))
    desks = d.boxes_xyxy_px[[i for i, (lab, s) in enumerate(zip(d.labels, d.scores)) if lab in ("table", "desk") and s >= 0.4]]
    truth = _demo_boxes("sunrgbd_total3d_demo_4", ("desk",))
    assert len(desks) >= 3
    assert int((box_iou(truth, desks).max(axis=1) >= 0.4).sum()) >= 3


def test_deeplab_labels_the_chairs_and_the_table(detectors):
    sem = detectors[2].segment_classes(_rgb("sunrgbd_total3d_demo_2"))
    labels = np.asarray(sem.labels, dtype=object)[sem.classes]
    assert sem.classes.shape == (530, 730)
    for x0, y0, x1, y1 in _demo_boxes("sunrgbd_total3d_demo_2", ("chair",)).astype(int):
        assert (labels[y0:y1, x0:x1] == "chair").mean() > 0.25
    x0, y0, x1, y1 = _demo_boxes("sunrgbd_total3d_demo_2", ("table",))[0].astype(int)
    assert (labels[y0:y1, x0:x1] == "table").mean() > 0.2


@pytest.mark.slow
def test_grabcut_outlines_rendered_objects_from_their_boxes():
    from perception.box_segment import GrabCutBoxSegmenter
    from scene_builder.bench.procedural import make_room
    from scene_builder.bench.render import render_arrays

    ious = []
    seg = GrabCutBoxSegmenter()
    for seed in (0, 1):
        r = render_arrays(make_room(seed, n_objects=5))
        ids = [i for i in np.unique(r.instances) if i > 0 and (r.instances == i).sum() >= 3000]
        boxes, truth = [], []
        for i in ids:
            rr, cc = np.nonzero(r.instances == i)
            boxes.append([cc.min(), rr.min(), cc.max() + 1, rr.max() + 1])
            truth.append(r.instances == i)
        masks = seg.segment_boxes(r.rgb, np.array(boxes, dtype=np.float64))
        assert masks.shape == (len(ids),) + r.rgb.shape[:2]
        assert np.array_equal(masks, seg.segment_boxes(r.rgb, np.array(boxes, dtype=np.float64)))  # deterministic
        ious += [float((m & t).sum() / (m | t).sum()) for m, t in zip(masks, truth)]
    assert len(ious) >= 6
    # GrabCut on colour alone: most rendered objects come out well, a few lose to a floor or
    # wall of similar colour; the box itself scores far lower on thin furniture.
    assert float(np.median(ious)) >= 0.7


def test_grabcut_follows_hints_and_gives_no_mask_for_a_flat_box():
    from perception.box_segment import HINT_BACKGROUND, GrabCutBoxSegmenter

    rng = np.random.default_rng(0)
    rgb = np.full((120, 160, 3), 200, dtype=np.uint8)
    rgb += rng.integers(0, 6, rgb.shape, dtype=np.uint8)
    rgb[40:80, 50:110] = (30, 60, 200)  # a blue object on a grey wall
    seg = GrabCutBoxSegmenter()
    m = seg.segment_boxes(rgb, np.array([[40.0, 30.0, 120.0, 90.0]]))[0]
    truth = np.zeros(m.shape, bool)
    truth[40:80, 50:110] = True
    assert (m & truth).sum() / (m | truth).sum() > 0.9
    # A red thing beside it in the same box: colour alone takes both; a hint that the red one
    # is something else (depth, the semantic map) leaves the blue one.
    rgb[40:80, 80:110] = (200, 40, 30)
    both = seg.segment_boxes(rgb, np.array([[40.0, 30.0, 120.0, 90.0]]))[0]
    assert both[40:80, 50:110].mean() > 0.9
    hint = np.zeros((1,) + m.shape, dtype=np.int8)
    hint[0, :, 80:] = HINT_BACKGROUND
    m2 = seg.segment_boxes(rgb, np.array([[40.0, 30.0, 120.0, 90.0]]), hints=hint)[0]
    assert not m2[:, 80:].any() and m2[40:80, 50:80].mean() > 0.9
    flat = np.full((120, 160, 3), 128, dtype=np.uint8)
    assert not seg.segment_boxes(flat, np.array([[40.0, 30.0, 120.0, 90.0]]))[0].any()


def test_detected_object_stands_at_its_floor_contact():
    """A camera 1.5 m above the floor looking level; a detected chair whose mask (estimated depth
    put on the floor plane) ends at a known row stands where that row's ray meets the floor."""
    from perception.contact import stand_on_contacts
    from scene_builder.model import CameraIntrinsics

    h, w, f = 240, 320, 200.0
    k = CameraIntrinsics(f, f, w / 2, h / 2, w, h, "flag")
    # OpenCV camera (x right, y down, z forward) to world (z up), camera at z = 1.5.
    world_from_camera = np.eye(4)
    world_from_camera[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
    world_from_camera[2, 3] = 1.5
    depth = np.full((h, w), 3.0, dtype=np.float32)
    background = np.ones((h, w), dtype=bool)  # the estimate saw only the room
    labels = np.zeros((h, w), dtype=np.int32)
    labels[150:200, 140:180] = 1  # bottom row 199: the ray v = 199.5 meets the floor at z = 1.5 f / (199.5 - 120)
    out, valid, bg, _, lifted = stand_on_contacts(depth, np.ones((h, w), bool), background, labels, ("chair",), world_from_camera, k)
    assert lifted == (1,)
    expect = 1.5 * f / (199.5 - 120)
    assert np.allclose(out[labels == 1], expect, rtol=1e-3)
    assert not bg[labels == 1].any() and bg[labels == 0].all()
    assert np.array_equal(out[labels == 0], depth[labels == 0])
    # An undetected instance ("") and one the estimate sees are left alone.
    out2, _, _, _, lifted2 = stand_on_contacts(depth, np.ones((h, w), bool), background, labels, ("",), world_from_camera, k)
    assert lifted2 == () and np.array_equal(out2, depth)
    out3, _, _, _, lifted3 = stand_on_contacts(depth, np.ones((h, w), bool), np.zeros((h, w), bool), labels, ("chair",), world_from_camera, k)
    assert lifted3 == ()
    # The cut kept only the top of a cabinet (rows 150..179); the detector's box reaches the floor
    # at row 199: the cabinet stands there and its mask grows down to it through free pixels.
    seat = np.where(labels == 1, 1, 0)
    seat[180:] = 0
    seat[185:200, 100:140] = 2  # another object beside, not under it
    box = np.array([[140.0, 150.0, 180.0, 200.0], [np.nan] * 4])
    out4, _, _, grown, lifted4 = stand_on_contacts(depth, np.ones((h, w), bool), background, seat, ("cabinet", ""), world_from_camera, k, boxes_xyxy_px=box)
    assert lifted4 == (1,)
    assert (grown == 1).sum() == (labels == 1).sum() and (grown == 2).sum() == 15 * 40
    assert np.allclose(out4[grown == 1], expect, rtol=1e-3)


def test_an_object_painted_on_a_side_wall_of_the_estimate_stands_at_its_floor_contact():
    """The estimate put a detected desk on a plane 1.2 m left of a level camera, 0.8 m and more
    above the floor, running straight ahead (sunrgbd_total3d_demo_4's back-left desk): every
    pixel is off the room's planes, yet it stands at its floor contact like an unseen object. The
    same pixels on a plane facing the camera, or reaching down to the floor, stay as estimated."""
    from perception.contact import _painted_edge_on, stand_on_contacts
    from scene_builder.model import CameraIntrinsics

    h, w, f = 240, 320, 200.0
    k = CameraIntrinsics(f, f, w / 2, h / 2, w, h, "flag")
    world_from_camera = np.eye(4)
    world_from_camera[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]  # level, looking along +y
    world_from_camera[2, 3] = 1.5
    labels = np.zeros((h, w), dtype=np.int32)
    labels[150:200, 20:60] = 1  # left of the centre: u - cx < 0
    v, u = np.mgrid[0:h, 0:w]
    side = np.where(labels == 1, 1.2 / np.maximum((k.cx_px - u) / f, 1e-6), 3.0)  # x = -1.2 m (CameraIntrinsics.unproject's pixels)
    depth = np.clip(side, 0.2, 10.0).astype(np.float32)
    pts = np.column_stack([((u - k.cx_px) / f * depth)[labels == 1], depth[labels == 1], 1.5 - ((v - k.cy_px) / f * depth)[labels == 1]])
    assert np.allclose(pts[:, 0], -1.2) and pts[:, 2].min() > 0.3
    heading = np.array([0.0, 1.0])
    assert _painted_edge_on(pts, heading)
    assert not _painted_edge_on(pts[:, [1, 0, 2]], heading)  # the same points on a plane facing the camera
    assert not _painted_edge_on(pts - [0.0, 0.0, pts[:, 2].min()], heading)  # down on the floor
    seen = np.zeros((h, w), dtype=bool)  # every pixel of it off the room's planes
    out, _, _, _, lifted = stand_on_contacts(depth, np.ones((h, w), bool), seen, labels, ("desk",), world_from_camera, k)
    assert lifted == (1,)
    assert np.allclose(out[labels == 1], 1.5 * f / (199.5 - 120), rtol=0.05)  # its bottom row's floor contact
    _, _, _, _, lifted_cup = stand_on_contacts(depth, np.ones((h, w), bool), seen, labels, ("mug",), world_from_camera, k)
    assert lifted_cup == ()  # a thing that does not stand on the floor keeps the estimate


def test_only_the_instances_asked_stand_at_their_contact_and_their_face_is_square_to_the_room():
    """With sensor depth, perceive lifts only the detected objects the sensor measured too little
    of (``only``); a lifted face turned less than FACE_WALL_DEG from facing the camera is square
    to the room's walls (its normal a wall's, or along a wall), else it faces the camera."""
    from perception.contact import FACE_WALL_DEG, stand_on_contacts
    from perception.perceive import _unmeasured_instances
    from scene_builder.model import CameraIntrinsics, Plane

    h, w, f = 240, 320, 200.0
    k = CameraIntrinsics(f, f, w / 2, h / 2, w, h, "flag")
    world_from_camera = np.eye(4)
    world_from_camera[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]  # looking along world +y
    world_from_camera[2, 3] = 1.5
    depth = np.full((h, w), 3.0, dtype=np.float32)
    labels = np.zeros((h, w), dtype=np.int32)
    labels[150:200, 100:140] = 1
    labels[150:200, 200:240] = 2
    valid = np.ones((h, w), bool)
    valid[labels == 2] = False  # the sensor measured nothing on instance 2
    background = np.zeros((h, w), bool)
    assert _unmeasured_instances(labels, valid, background, 150) == [2]
    out, _, _, _, lifted = stand_on_contacts(depth, valid, background, labels, ("cabinet", "cabinet"), world_from_camera, k, only=frozenset({2}))
    assert lifted == (2,)
    assert np.array_equal(out[labels != 2], depth[labels != 2])

    def face_normal(walls, square=True):
        z, _, _, _, _ = stand_on_contacts(depth, valid, background, labels, ("cabinet", "cabinet"), world_from_camera, k, walls=walls, only=frozenset({2}),
                                          square_to_walls=square)
        rr, cc = np.nonzero(labels == 2)
        cam = np.column_stack([(cc - k.cx_px) / f * z[rr, cc], (rr - k.cy_px) / f * z[rr, cc], z[rr, cc]])
        pts = cam @ world_from_camera[:3, :3].T
        _, _, vt = np.linalg.svd(pts - pts.mean(axis=0), full_matrices=False)
        return vt[2] * np.sign(vt[2][1] or 1.0)

    # the contact is 16.7 degrees right of the camera's axis; the face turns to the camera
    centre = np.array([(220 - w / 2) / f, 1.0])
    facing = np.array([centre[0], centre[1], 0.0]) / np.linalg.norm(centre)
    assert np.allclose(face_normal(()), facing, atol=0.02)
    # a wall turned 10 degrees: its axes lie 26.7 and 63.3 degrees off facing, the face is square
    # to it; turned 28.3 degrees, both lie 45 degrees off (more than FACE_WALL_DEG): it faces
    assert FACE_WALL_DEG < 45.0
    for turn_deg, square in ((10.0, True), (28.3, False)):
        a = np.radians(turn_deg)
        wall = Plane(np.array([np.sin(a), -np.cos(a), 0.0]), 20.0, "wall")  # far away: no wall in the way
        n = face_normal((wall,))
        if square:
            assert abs(n @ wall.normal) > 0.999
        else:
            assert np.allclose(n, facing, atol=0.02)
    # walls a single-view estimate guessed are not squared to
    assert np.allclose(face_normal((Plane(np.array([np.sin(0.17), -np.cos(0.17), 0.0]), 20.0, "wall"),), square=False), facing, atol=0.02)


def test_registries_offer_detections_only_with_a_detector(tmp_path, monkeypatch):
    from perception import models
    from perception.backends import build_registries

    # A fresh clone detects: with an empty models dir the bundled detector files answer.
    reg = build_registries(PerceptionConfig(models_dir=tmp_path))
    seg, use = reg.segmentation.resolve()
    assert use.backend == "detections"
    assert [d.name for d in seg.detectors] == ["centernet-mbv3-coco", "ssd-mobilenet-oid"]
    assert all(str(models.BUNDLED_DIR) in str(models.resolve_weights(d.name, tmp_path)) for d in seg.detectors)

    # Without them (an install that lost its package data) the geometric chain answers and says why.
    monkeypatch.setattr(models, "BUNDLED_DIR", tmp_path / "none")
    reg = build_registries(PerceptionConfig(models_dir=tmp_path))
    entries = {e.name: e for e in reg.segmentation.entries()}
    assert "detections" in entries and entries["detections"].priority > entries["sam2"].priority
    why = entries["detections"].available()
    assert why is not None and "centernet_mbv3_coco.onnx" in why and "\n" not in why
    _, use = reg.segmentation.resolve()
    assert use.backend == "depth-clusters" and "detections" in use.reason
    box, box_use = reg.box_prompt.resolve()
    assert box_use.backend == "grabcut" and "sam2" in box_use.reason
    assert hasattr(box, "segment_boxes")

    require(MODELS)
    reg = build_registries(PerceptionConfig(models_dir=MODELS))
    assert {"centernet-mbv3-coco", "ssd-mobilenet-oid"} <= {e.name for e in reg.detection.entries() if e.available() is None}
    seg, use = reg.segmentation.resolve()
    assert use.backend == "detections" and seg.accepts_gravity
    assert [d.name for d in seg.detectors] == ["centernet-mbv3-coco", "ssd-mobilenet-oid"]
    # NanoDet is registered, its file is there, and it is off by default (BENCHMARKS.md).
    nanodet = next(e for e in reg.detection.entries() if e.name == "nanodet-coco")
    assert (MODELS / "nanodet_coco.onnx").is_file() and "off by default" in (nanodet.available() or "")
    assert seg.semantic is not None and seg.semantic.name == "deeplabv3-mnv2-pascal"


@pytest.mark.slow
def test_sam2_answers_box_prompts_when_its_weights_are_there(tiny_sam, tmp_path):
    """Grounded-SAM: with SAM 2 weights in the models dir, detector boxes prompt SAM 2 (a
    randomly initialised tiny model exercises the loading and prompting code)."""
    import shutil

    from perception.backends import build_registries

    shutil.copytree(tiny_sam, tmp_path / "sam2-hiera-tiny")
    reg = build_registries(PerceptionConfig(models_dir=tmp_path))
    seg, use = reg.box_prompt.resolve()
    assert use.backend == "sam2"
    rgb = np.random.default_rng(0).integers(0, 255, (61, 87, 3), dtype=np.uint8)
    masks = seg.segment_boxes(rgb, np.array([[5.0, 5.0, 40.0, 30.0], [0.0, 0.0, 86.0, 60.0]]))
    assert masks.shape == (2, 61, 87) and masks.dtype == bool
    assert seg.segment_boxes(rgb, np.zeros((0, 4))).shape == (0, 61, 87)


def test_a_confident_box_whose_hinted_cut_is_empty_is_cut_again_without_the_hints():
    """The semantic map (or estimated depth laying the object flat on the wall) calls every pixel
    of a confident bowl's box something else: the hinted cut is empty, and the box would
    vanish. On estimated depth a box at the detector's trust score is cut again with only other
    instances' pixels as probable background; a weak box is not (its witnesses were the hints),
    nor a box on a sensor's depth."""
    from perception.box_segment import GrabCutBoxSegmenter
    from perception.segment_detect import DetectionSegmenter, NamedBackend, _Candidate

    rng = np.random.default_rng(0)
    h, w = 120, 160
    rgb = np.full((h, w, 3), 200, dtype=np.uint8)
    rgb += rng.integers(0, 6, rgb.shape, dtype=np.uint8)
    rgb[40:80, 50:110] = (30, 60, 200)
    truth = np.zeros((h, w), bool)
    truth[40:80, 50:110] = True
    seg = DetectionSegmenter([], NamedBackend("grabcut", GrabCutBoxSegmenter()), None, None)
    sem = np.full((h, w), "sofa", dtype=object)  # wrong everywhere: another class in the box
    depth = np.full((h, w), 2.0, np.float32)
    valid = np.ones((h, w), bool)
    background = np.ones((h, w), bool)
    box = np.array([40.0, 30.0, 120.0, 90.0])
    def outline(score, measured):
        # (a bowl: the cut of a box-shaped thing, a microwave, would then be grown to its box)
        c = _Candidate(box.copy(), score, "bowl", "score" if score >= 0.5 else "semantic")
        seg._depth_measured = measured
        seg._outline(rgb, [c], depth, valid, background, np.zeros((h, w), np.int64), sem, np.zeros((h, w, 3)), 100.0, np.zeros((h, w), bool))
        return c

    strong = outline(0.8, False)
    assert (strong.mask & truth).sum() / (strong.mask | truth).sum() > 0.9
    assert strong.meta["outline"] == "cut without depth hints"
    assert not outline(0.3, False).mask.any()
    # A sensor's depth that calls the box's pixels room is believed (a picture on the wall).
    assert not outline(0.8, True).mask.any()


def test_a_cluster_filling_a_weak_box_witnesses_it_only_with_measured_depth():
    """Depth joined a wardrobe, the cabinet beside it and the wall behind into one cluster that
    reaches far out of the wardrobe's weak box (nyuv2_metric3d_00000): the cluster filling the
    box witnesses it where the depth is a sensor's, not where it was estimated (one photo's
    estimated depth joins whole rooms); a cluster lying inside the box witnesses it either way."""
    from types import SimpleNamespace

    from perception.protocols import Detections
    from perception.segment_detect import DetectionSegmenter

    h, w = 100, 200
    clusters = np.zeros((h, w), dtype=np.int64)
    clusters[10:90, 20:180] = 1  # one cluster, three times the box's width
    box = np.array([[70.0, 10.0, 130.0, 90.0]])
    dets = Detections(box, np.array([0.3], np.float32), ("wardrobe",), ("refrigerator",))
    me = SimpleNamespace(min_points=50)
    claimed = np.zeros((h, w), dtype=bool)

    def confirm(measured):
        return DetectionSegmenter._confirm(me, dets, False, clusters, None, claimed, h, w, measured)

    (c,) = confirm(True)
    assert c.witness == "depth" and c.cluster == 1
    assert confirm(False) == []
    clusters[:] = 0
    clusters[20:80, 80:120] = 2  # inside the box
    assert [c.cluster for c in confirm(False)] == [2]
