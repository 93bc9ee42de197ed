"""Depth Anything V2 through the exact user code path: a randomly initialised tiny model saved with
save_pretrained and loaded back by DepthAnythingV2Estimator (no download). The metric head's
max_depth, the preprocessing and the output resize are pinned against transformers' own DPT
processor on the real photos of ../shared/data/real."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scene_builder.errors import InputError, ModelUnavailableError

MAX_DEPTH_M = 20


def _tiny(tmp_path, depth_type: str = "metric", with_processor: bool = True, max_depth: float = MAX_DEPTH_M, name: str = "da"):
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
        fusion_hidden_size=16, head_hidden_size=8, depth_estimation_type=depth_type, max_depth=max_depth,
    )
    torch.manual_seed(0)
    model = DepthAnythingForDepthEstimation(config)
    # Break the symmetry of the random head so the output varies across the image.
    with torch.no_grad():
        for p in model.head.parameters():
            p.add_(0.2 * torch.randn_like(p))
    folder = tmp_path / name
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


# The published preprocessor_config.json of depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf
# (and the other -hf checkpoints), written down here independently of the code under test.
PUBLISHED = {
    "do_normalize": True, "do_pad": False, "do_rescale": True, "do_resize": True, "ensure_multiple_of": 14,
    "image_mean": [0.485, 0.456, 0.406], "image_processor_type": "DPTImageProcessor",
    "image_std": [0.229, 0.224, 0.225], "keep_aspect_ratio": True, "resample": 3,
    "rescale_factor": 0.00392156862745098, "size": {"height": 518, "width": 518}, "size_divisor": None,
}


def _expected_input_hw(h: int, w: int) -> tuple[int, int]:
    """DPT's keep-aspect-ratio rule: the side scale closest to 1, then each side rounded to a
    multiple of 14."""
    sh, sw = 518 / h, 518 / w
    s = sw if abs(1 - sw) < abs(1 - sh) else sh
    return int(round(h * s / 14) * 14), int(round(w * s / 14) * 14)


def _real_photos() -> list[np.ndarray]:
    from PIL import Image

    from tests.conftest import REAL_DATA, require

    require(REAL_DATA)
    files = [f for d in sorted(REAL_DATA.iterdir()) for f in (d / "rgb.png", d / "rgb.jpg") if f.is_file()]
    return [np.asarray(Image.open(f).convert("RGB")) for f in files]


def _one_photo_per_size() -> list[np.ndarray]:
    by_size: dict[tuple[int, int], np.ndarray] = {}
    for rgb in _real_photos():
        by_size.setdefault(rgb.shape[:2], rgb)
    return [by_size[k] for k in sorted(by_size)]


def test_defaults_are_the_published_preprocessor_config():
    from perception.learned.depth_anything import INDOOR_MAX_DEPTH_M, PUBLISHED_PREPROCESSOR_CONFIG, default_processor_kwargs

    assert PUBLISHED_PREPROCESSOR_CONFIG == PUBLISHED
    kw = default_processor_kwargs()
    for key, value in PUBLISHED.items():
        if key not in ("image_processor_type", "size_divisor"):
            assert kw[key] == value, key
    assert INDOOR_MAX_DEPTH_M == 20.0
    assert _expected_input_hw(480, 640) == (518, 686) and _expected_input_hw(1080, 1920) == (518, 924)


@pytest.fixture(scope="module")
def published_estimator(tmp_path_factory):
    """The tiny model without a preprocessor_config.json: the estimator's built-in defaults apply."""
    from perception.learned.depth_anything import DepthAnythingV2Estimator

    return DepthAnythingV2Estimator(_tiny(tmp_path_factory.mktemp("pub"), with_processor=False), device="cpu")


@pytest.mark.slow
def test_preprocessing_and_output_resize_equal_transformers_processor_on_real_photos(published_estimator, tmp_path):
    import torch
    from transformers.models.dpt import DPTImageProcessorPil

    (tmp_path / "preprocessor_config.json").write_text(json.dumps(PUBLISHED))
    reference = DPTImageProcessorPil.from_pretrained(tmp_path)  # transformers' own, from the published file
    est = published_estimator
    for rgb in _real_photos():  # preprocessing: every photo (cheap)
        torch.testing.assert_close(est.preprocess([rgb]), reference([rgb], return_tensors="pt")["pixel_values"], rtol=0, atol=0)
    photos = _one_photo_per_size()
    assert len(photos) >= 4  # 512x424 up to 1920x1440
    for rgb in photos:
        h, w = rgb.shape[:2]
        ours = est.preprocess([rgb])
        theirs = reference([rgb], return_tensors="pt")["pixel_values"]
        assert tuple(ours.shape[-2:]) == _expected_input_hw(h, w)
        torch.testing.assert_close(ours, theirs, rtol=0, atol=0)
        # the output: transformers' post-processing of the raw head output, inside (0, max_depth]
        with torch.inference_mode():
            raw = est.model(pixel_values=theirs)
        expected = reference.post_process_depth_estimation(raw, target_sizes=[(h, w)])[0]["predicted_depth"]
        expected = expected.clamp(1e-3, MAX_DEPTH_M).numpy()
        depth = est.estimate(rgb).depth_m
        assert depth.shape == (h, w)
        np.testing.assert_allclose(depth, expected, rtol=1e-5, atol=1e-5)
        # and that post-processing is a bicubic, align_corners=False resize (not bilinear)
        bicubic = torch.nn.functional.interpolate(raw.predicted_depth[:, None], size=(h, w), mode="bicubic", align_corners=False)[0, 0]
        np.testing.assert_allclose(depth, bicubic.clamp(1e-3, MAX_DEPTH_M).numpy(), rtol=1e-5, atol=1e-5)


def test_metric_head_is_sigmoid_times_max_depth_from_the_checkpoint(tmp_path):
    from perception.learned.depth_anything import DepthAnythingV2Estimator

    rgb = _image(40, 52, 4)
    d20 = DepthAnythingV2Estimator(_tiny(tmp_path, name="in"), device="cpu")
    d80 = DepthAnythingV2Estimator(_tiny(tmp_path, max_depth=80, name="out"), device="cpu")  # same seed, same weights
    assert d20.max_depth_m == 20 and d80.max_depth_m == 80
    a, b = d20.estimate(rgb).depth_m, d80.estimate(rgb).depth_m
    inside = (a > 1e-3) & (a < 20)
    assert inside.mean() > 0.9
    np.testing.assert_allclose(b[inside], 4.0 * a[inside], rtol=1e-4)
    # transformers' default max_depth (1 m) is no room: refused, not read as 0..1 m
    with pytest.raises(ModelUnavailableError, match="max_depth"):
        DepthAnythingV2Estimator(_tiny(tmp_path, max_depth=1, name="one"), device="cpu")
