"""SAM 2: upstream's generator constants pinned, the mask filters and box NMS on hand-made masks
with known answers, and the automatic / box-prompted generator through the exact loading path
with a tiny randomly initialised Sam2Model."""

from __future__ import annotations

import numpy as np
import pytest

from scene_builder.errors import InputError

from perception.learned.sam2 import (
    assign_instances,
    box_iou_matrix,
    box_nms,
    mask_iou_matrix,
    mask_nms,
    masks_to_boxes,
    point_grid,
    preprocess,
    remove_small_regions,
    stability_score,
)
from scene_builder.config import PerceptionConfig, Sam2Settings


def _rect(h, w, r0, r1, c0, c1):
    m = np.zeros((h, w), dtype=bool)
    m[r0:r1, c0:c1] = True
    return m


def test_automatic_mask_defaults_are_upstreams():
    """SAM2AutomaticMaskGenerator.__init__ defaults (facebookresearch/sam2 @ 2b90b9f5), and
    Grounded-SAM-2's single mask per box prompt."""
    s = PerceptionConfig().sam2
    assert s == Sam2Settings()
    assert (s.points_per_side, s.points_per_batch) == (32, 64)
    assert s.pred_iou_thresh == 0.8  # transformers' mask-generation pipeline: 0.88
    assert (s.stability_score_thresh, s.stability_score_offset, s.mask_threshold) == (0.95, 1.0, 0.0)
    assert s.box_nms_thresh == 0.7 and s.min_mask_region_area_px == 0
    assert s.multimask_output is True and s.box_prompt_multimask is False


def test_point_grid_is_upstreams_build_point_grid_times_the_image_size():
    g = point_grid(2, 100, 50)  # upstream: [[.25, .25], [.75, .25], [.25, .75], [.75, .75]] * (100, 50)
    np.testing.assert_allclose(g, [[25, 12.5], [75, 12.5], [25, 37.5], [75, 37.5]])
    assert len(point_grid(32, 640, 480)) == 1024


def test_masks_to_boxes_is_inclusive_and_zero_for_empty_masks():
    m = np.zeros((3, 10, 12), dtype=bool)
    m[0, 2:5, 3:9] = True
    m[2, 9, 11] = True
    np.testing.assert_array_equal(masks_to_boxes(m), [[3, 2, 8, 4], [0, 0, 0, 0], [11, 9, 11, 9]])


def test_box_nms_matches_torchvision_semantics():
    boxes = np.array([[0, 0, 10, 10], [0, 0, 10, 9], [20, 20, 30, 30], [1, 0, 10, 10]], dtype=float)
    assert box_iou_matrix(boxes[:1], boxes[1:2])[0, 0] == pytest.approx(0.9)
    # 0 beats 1 and 3 (IoU 0.9 > 0.7); the distant box survives; order is by score
    assert box_nms(boxes, np.array([0.9, 0.95, 0.5, 0.1]), 0.7).tolist() == [1, 2]
    # strict ">": IoU exactly 0.9 at threshold 0.9 is kept
    assert box_nms(boxes[:2], np.array([0.9, 0.8]), 0.9).tolist() == [0, 1]
    assert box_nms(np.zeros((0, 4)), np.zeros(0), 0.7).tolist() == []


def test_stability_score_is_iou_of_shifted_thresholds():
    logits = np.zeros((2, 4, 4))
    logits[0] = 5.0  # crisp: the same mask at +1 and -1
    logits[1, :2] = 0.5  # soft: 8 pixels above -1 ... none above +1
    logits[1, 2:] = -3.0
    s = stability_score(logits, 0.0, 1.0)
    assert s[0] == pytest.approx(1.0)
    assert s[1] == pytest.approx(0.0)
    logits[1, 0] = 2.0  # 4 of 8 above +1
    assert stability_score(logits, 0.0, 1.0)[1] == pytest.approx(0.5)


def test_mask_nms_keeps_best_of_duplicates_and_distinct_masks():
    a = _rect(20, 20, 0, 10, 0, 10)
    a2 = _rect(20, 20, 0, 10, 0, 9)  # IoU 0.9 with a
    b = _rect(20, 20, 10, 20, 10, 20)
    masks = np.stack([a2, a, b])
    keep = mask_nms(masks, np.array([0.8, 0.9, 0.5]), iou_threshold=0.7)
    assert keep.tolist() == [1, 2]
    assert mask_iou_matrix(masks[:1], masks[1:2])[0, 0] == pytest.approx(0.9)
    # A higher threshold keeps the near-duplicate too.
    assert sorted(mask_nms(masks, np.array([0.8, 0.9, 0.5]), 0.95).tolist()) == [0, 1, 2]


def test_remove_small_regions_fills_holes_and_drops_islands():
    m = _rect(30, 30, 5, 25, 5, 25)
    m[10:12, 10:12] = False  # 4-pixel hole
    m[0, 0] = True  # 1-pixel island
    out = remove_small_regions(m, 10)
    assert out[10:12, 10:12].all() and not out[0, 0]
    assert out.sum() == 400


def test_assign_instances_gives_pixels_to_the_best_mask_without_overlap():
    big = _rect(20, 20, 0, 20, 0, 20)
    small = _rect(20, 20, 5, 10, 5, 10)
    tiny = _rect(20, 20, 0, 2, 0, 1)  # loses 2 pixels to nothing; survives only without min area
    inst = assign_instances(np.stack([big, small, tiny]), np.array([0.5, 0.9, 0.95]), min_area_px=3)
    labels = inst.labels
    # small outranks big, so it keeps its 25 pixels; tiny (2 px) is dropped, its pixels go to big.
    assert (labels == 1).sum() == 25 and (labels[5:10, 5:10] == 1).all()
    assert (labels == 2).sum() == 400 - 25
    np.testing.assert_allclose(inst.scores, [0.9, 0.5])
    assert labels.dtype == np.int32


def test_preprocess_square_and_letterbox():
    rgb = np.full((50, 100, 3), 255, dtype=np.uint8)
    px, inner = preprocess(rgb, 64)
    assert px.shape == (3, 64, 64) and inner == (64, 64)
    np.testing.assert_allclose(px[:, 10, 10], (1.0 - np.array([0.485, 0.456, 0.406])) / np.array([0.229, 0.224, 0.225]), rtol=1e-5)
    px, inner = preprocess(rgb, 64, letterbox=True)
    assert inner == (32, 64) and np.all(px[:, 40:, :] == 0)


def save_tiny_sam2(folder):
    """A randomly initialised tiny Sam2Model saved as a transformers folder; returns the folder."""
    import torch
    from transformers import Sam2Config, Sam2Model
    from transformers.models.sam2.configuration_sam2 import (
        Sam2HieraDetConfig,
        Sam2MaskDecoderConfig,
        Sam2PromptEncoderConfig,
        Sam2VisionConfig,
    )

    backbone = Sam2HieraDetConfig(
        hidden_size=8, num_attention_heads=1, embed_dim_per_stage=[8, 16, 32, 64],
        num_attention_heads_per_stage=[1, 1, 2, 2], blocks_per_stage=[1, 1, 2, 1],
        window_size_per_stage=[8, 4, 14, 7], global_attention_blocks=[3], image_size=[256, 256],
    )
    config = Sam2Config(
        vision_config=Sam2VisionConfig(
            backbone_config=backbone, backbone_channel_list=[64, 32, 16, 8], fpn_hidden_size=32,
            backbone_feature_sizes=[[64, 64], [32, 32], [16, 16]],
        ),
        prompt_encoder_config=Sam2PromptEncoderConfig(hidden_size=32, image_size=256),
        mask_decoder_config=Sam2MaskDecoderConfig(hidden_size=32, mlp_dim=64, num_attention_heads=2, iou_head_hidden_dim=16),
    )
    torch.manual_seed(0)
    Sam2Model(config).save_pretrained(folder)
    return folder


@pytest.fixture(scope="module")
def tiny_sam(tmp_path_factory):
    return save_tiny_sam2(tmp_path_factory.mktemp("sam2"))


@pytest.mark.slow
def test_tiny_sam2_automatic_and_prompted_masks(tiny_sam):
    from perception.learned.sam2 import Sam2Segmenter

    # Random weights: switch the quality filters off so that masks get through.
    settings = Sam2Settings(points_per_side=4, pred_iou_thresh=0.0, stability_score_thresh=0.0, min_instance_frac=0.0)
    seg = Sam2Segmenter(tiny_sam, settings, device="cpu")
    rgb = np.random.default_rng(0).integers(0, 255, (61, 87, 3), dtype=np.uint8)
    props = seg.generate(rgb)
    assert props.masks.shape[1:] == (61, 87) and len(props.predicted_iou) == len(props.masks)
    assert 0 < len(props.masks) <= 4 * 4 * 3
    assert np.all(np.diff(props.predicted_iou) <= 0)  # best first, as upstream's NMS returns them
    # no two surviving masks have boxes overlapping above the NMS threshold (at full resolution
    # up to the low-res rounding)
    iou = box_iou_matrix(masks_to_boxes(props.masks), masks_to_boxes(props.masks))
    np.fill_diagonal(iou, 0.0)
    assert iou.max(initial=0.0) <= 0.7 + 0.1
    # a stricter predicted-IoU filter keeps a subset
    strict = Sam2Segmenter(tiny_sam, Sam2Settings(points_per_side=4, pred_iou_thresh=float(np.median(props.predicted_iou)), stability_score_thresh=0.0), device="cpu")
    assert len(strict.generate(rgb).masks) < len(props.masks)

    background = np.zeros((61, 87), dtype=bool)
    background[50:] = True
    a = seg.segment(rgb, np.ones((61, 87), np.float32), None, background)
    b = seg.segment(rgb, np.ones((61, 87), np.float32), None, background)
    np.testing.assert_array_equal(a.labels, b.labels)  # deterministic
    assert a.labels.shape == (61, 87) and a.labels.dtype == np.int32
    assert not np.any(a.labels[background])
    assert len(a.scores) == a.labels.max() and set(np.unique(a.labels)) <= set(range(len(a.scores) + 1))

    # box prompts: one mask per box, in order, deterministic, empty input -> empty output
    det_boxes = np.array([[5.0, 5.0, 40.0, 30.0], [0.0, 0.0, 87.0, 61.0], [50.0, 10.0, 80.0, 55.0]])
    per_box = seg.segment_boxes(rgb, det_boxes)
    assert per_box.shape == (3, 61, 87) and per_box.dtype == np.bool_
    np.testing.assert_array_equal(per_box, seg.segment_boxes(rgb, det_boxes))
    np.testing.assert_array_equal(per_box[1:2], seg.segment_boxes(rgb, det_boxes[1:2]))  # boxes do not interact
    assert seg.segment_boxes(rgb, np.zeros((0, 4))).shape == (0, 61, 87)
    with pytest.raises(InputError):
        seg.segment_boxes(rgb, np.array([[10.0, 10.0, 5.0, 20.0]]))
    boxes = seg.segment_with_prompts(rgb, boxes_xyxy=np.array([[5, 5, 40, 30], [0, 0, 86, 60]]))
    assert boxes.masks.shape == (2, 61, 87) and np.all(np.isnan(boxes.points_px))
    pts = seg.segment_with_prompts(rgb, points=np.array([[10.0, 10.0], [70.0, 50.0]]))
    assert pts.masks.shape == (2, 61, 87)
    np.testing.assert_allclose(pts.points_px, [[10, 10], [70, 50]])


@pytest.mark.slow
def test_box_prompt_registry_gives_sam2_when_its_weights_are_in_the_models_dir(tiny_sam, tmp_path, monkeypatch):
    import shutil

    from perception.learned import register_box_prompt_backends
    from perception.protocols import BoxPromptSegmenter
    from scene_builder.registry import Registry

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty_cache"))
    reg: Registry[BoxPromptSegmenter] = Registry("box-prompt")
    register_box_prompt_backends(reg, PerceptionConfig(models_dir=tmp_path))
    assert reg.names() == ["sam2"]
    reason = reg.entries()[0].available()
    assert reason is not None and "models fetch sam2-hiera-tiny" in reason
    shutil.copytree(tiny_sam, tmp_path / "sam2-hiera-tiny")
    seg, use = reg.resolve()
    assert use.backend == "sam2"
    rgb = np.random.default_rng(1).integers(0, 255, (40, 50, 3), dtype=np.uint8)
    assert seg.segment_boxes(rgb, np.array([[2.0, 3.0, 30.0, 35.0]])).shape == (1, 40, 50)
