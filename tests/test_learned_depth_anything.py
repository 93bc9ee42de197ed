"""Depth Anything V2 through the exact user code path: a randomly initialised tiny model saved with
save_pretrained and loaded back by DepthAnythingV2Estimator (no download)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scene_builder.errors import InputError, ModelUnavailableError

MAX_DEPTH_M = 20


def _tiny(tmp_path, depth_type: str = "metric", with_processor: bool = True):
    import torch
    from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation, Dinov2Config
    from transformers.models.dpt import DPTImageProcessorPil

    from perception.learned.depth_anything import default_processor_kwargs

    backbone = Dinov2Config(
        hidden_size=32, num_hidden_layers=4, num_attention_heads=2, intermediate_size=64,
        patch_size=14, image_size=98, out_indices=[1, 2, 3, 4], reshape_hidden_states=False,
    )
    config = DepthAnythingConfig(
        backbone_config=backbone, reassemble_hidden_size=32, neck_hidden_sizes=[8, 16, 32, 32],
        fusion_hidden_size=16, head_hidden_size=8, depth_estimation_type=depth_type, max_depth=MAX_DEPTH_M,
    )
    torch.manual_seed(0)
    model = DepthAnythingForDepthEstimation(config)
    # Break the symmetry of the random head so the output varies across the image.
    with torch.no_grad():
        for p in model.head.parameters():
            p.add_(0.2 * torch.randn_like(p))
    folder = tmp_path / "da"
    model.save_pretrained(folder)
    if with_processor:
        kw = default_processor_kwargs()
        kw["size"] = {"height": 70, "width": 70}
        DPTImageProcessorPil(**kw).save_pretrained(folder)
    return folder


@pytest.fixture(scope="module")
def estimator(tmp_path_factory):
    from perception.learned.depth_anything import DepthAnythingV2Estimator

    return DepthAnythingV2Estimator(_tiny(tmp_path_factory.mktemp("w")), device="cpu")


def _image(h: int, w: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = np.linspace(0, 255, w)[None, :, None] * np.ones((h, 1, 3))
    return np.clip(base + rng.normal(0, 30, (h, w, 3)), 0, 255).astype(np.uint8)


def test_odd_sizes_come_back_at_input_resolution_in_positive_metres(estimator):
    for h, w in [(61, 83), (97, 40)]:
        out = estimator.estimate(_image(h, w, 1), None)
        assert out.depth_m.shape == (h, w) and out.depth_m.dtype == np.float32
        assert np.all(out.depth_m > 0) and np.all(out.depth_m <= MAX_DEPTH_M)
        assert out.focal_px is None
        assert float(out.depth_m.std()) > 0  # a real resized prediction, not a constant fill


def test_batch_matches_single_images_in_order(estimator):
    ims = [_image(61, 83, 1), _image(40, 30, 2), _image(61, 83, 3)]
    batch = estimator.estimate_batch(ims, batch_size=2)
    assert [b.depth_m.shape for b in batch] == [(61, 83), (40, 30), (61, 83)]
    for im, b in zip(ims, batch):
        np.testing.assert_allclose(b.depth_m, estimator.estimate(im).depth_m, rtol=1e-4, atol=1e-4)
    assert not np.allclose(batch[0].depth_m, batch[2].depth_m)


def test_processor_config_is_read_and_defaults_apply_without_it(tmp_path):
    from perception.learned.depth_anything import DepthAnythingV2Estimator

    folder = _tiny(tmp_path, with_processor=False)
    est = DepthAnythingV2Estimator(folder, device="cpu")
    assert est.processor.size["height"] == 518 and est.processor.keep_aspect_ratio
    (folder / "preprocessor_config.json").write_text(json.dumps({"size": {"height": 56, "width": 56}, "keep_aspect_ratio": True, "ensure_multiple_of": 14}))
    est2 = DepthAnythingV2Estimator(folder, device="cpu")
    px = est2.processor([_image(50, 100, 0)], return_tensors="pt")["pixel_values"]
    assert px.shape[-2] % 14 == 0 and px.shape[-1] % 14 == 0 and px.shape[-2] < px.shape[-1]


def test_half_precision_still_returns_float32_metres(tmp_path):
    from perception.learned.depth_anything import DepthAnythingV2Estimator

    est = DepthAnythingV2Estimator(_tiny(tmp_path), device="cpu", dtype="bfloat16")
    out = est.estimate(_image(33, 47, 0))
    assert out.depth_m.dtype == np.float32 and out.depth_m.shape == (33, 47) and np.all(out.depth_m > 0)


def test_relative_checkpoint_and_bad_input_are_rejected(tmp_path, estimator):
    from perception.learned.depth_anything import DepthAnythingV2Estimator

    with pytest.raises(ModelUnavailableError, match="relative"):
        DepthAnythingV2Estimator(_tiny(tmp_path, depth_type="relative"), device="cpu")
    with pytest.raises(ModelUnavailableError):
        DepthAnythingV2Estimator(tmp_path / "missing", device="cpu")
    with pytest.raises(InputError):
        estimator.estimate(np.zeros((10, 10), dtype=np.uint8))
