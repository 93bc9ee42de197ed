"""Depth Anything V2 metric depth (``transformers`` ``DepthAnythingForDepthEstimation``), run as
transformers runs it.

- **Head.** The metric checkpoints end in ``sigmoid * max_depth``: 20 m for the indoor
  (Hypersim) models, 80 m for the outdoor (Virtual KITTI 2) ones (the authors' model card:
  ``max_depth = 20 # 20 for indoor model, 80 for outdoor model``). ``max_depth`` comes from the
  checkpoint's ``config.json``; transformers' own default is 1, which no room fits, so a metric
  checkpoint without a usable value is refused rather than read as 0..1 m.
- **Preprocessing.** The DPT image processor (its PIL backend: the torchvision one cannot be used
  on this project's machines) with the checkpoint's ``preprocessor_config.json``, else
  :data:`PUBLISHED_PREPROCESSOR_CONFIG`, the file published with the ``-hf`` checkpoints: size
  518, aspect ratio kept (the scale closest to 1 of the two sides' scales, so a 640 x 480 photo
  becomes 686 x 518 and 1920 x 1080 becomes 924 x 518), both sides rounded to multiples of the
  14-pixel patch, bicubic, ImageNet mean / std.
- **Output.** ``post_process_depth_estimation`` of the same processor: bicubic,
  ``align_corners=False``, to the input size; then kept inside the head's range (0, max_depth]
  because bicubic overshoots at sharp edges. (The authors' own ``infer_image`` resizes with
  bilinear ``align_corners=True``; transformers' pipeline, which this follows, uses bicubic.)
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from perception.protocols import DepthEstimate
from scene_builder.errors import InputError, ModelUnavailableError
from scene_builder.model import CameraIntrinsics

__all__ = [
    "INDOOR_MAX_DEPTH_M",
    "PUBLISHED_PREPROCESSOR_CONFIG",
    "DepthAnythingV2Estimator",
    "default_processor_kwargs",
]

#: ``max_depth`` of the metric indoor checkpoints (Hypersim fine-tunes), metres.
INDOOR_MAX_DEPTH_M = 20.0
#: Smallest ``max_depth`` accepted from a metric checkpoint (transformers' default is 1 m).
_MIN_MAX_DEPTH_M = 2.0

#: ``preprocessor_config.json`` of the ``depth-anything/Depth-Anything-V2-*-hf`` checkpoints
#: (the metric indoor ones included), as published.
PUBLISHED_PREPROCESSOR_CONFIG: dict = {
    "do_normalize": True,
    "do_pad": False,
    "do_rescale": True,
    "do_resize": True,
    "ensure_multiple_of": 14,
    "image_mean": [0.485, 0.456, 0.406],
    "image_processor_type": "DPTImageProcessor",
    "image_std": [0.229, 0.224, 0.225],
    "keep_aspect_ratio": True,
    "resample": 3,
    "rescale_factor": 0.00392156862745098,
    "size": {"height": 518, "width": 518},
    "size_divisor": None,
}


def default_processor_kwargs() -> dict:
    """Keyword arguments of ``DPTImageProcessorPil`` equal to :data:`PUBLISHED_PREPROCESSOR_CONFIG`,
    used when a weights folder has no ``preprocessor_config.json``."""
    skip = {"image_processor_type", "size_divisor"}
    return {k: (dict(v) if isinstance(v, dict) else list(v) if isinstance(v, list) else v)
            for k, v in PUBLISHED_PREPROCESSOR_CONFIG.items() if k not in skip}


def _pick_device(device: str | None) -> str:
    import torch

    if device is not None:
        return device
    return "cuda" if torch.cuda.is_available() else "cpu"


class DepthAnythingV2Estimator:
    """Metric depth from one RGB image with a Depth Anything V2 checkpoint.

    weights_dir: a folder with ``config.json`` and ``model.safetensors`` (and optionally
    ``preprocessor_config.json``), as resolved by :func:`perception.models.resolve_weights`.
    device: ``"cpu"``, ``"cuda"``, ...; None picks cuda when available. dtype: ``"float32"``,
    ``"float16"`` or ``"bfloat16"`` for the network (the output is always float32 metres).
    """

    def __init__(self, weights_dir: Path | str, device: str | None = None, dtype: str = "float32") -> None:
        import torch
        from transformers import DepthAnythingForDepthEstimation
        from transformers.models.dpt import DPTImageProcessorPil

        weights_dir = Path(weights_dir)
        if not (weights_dir / "config.json").is_file():
            raise ModelUnavailableError(f"no config.json in {weights_dir}; run: scene-builder models fetch depth-anything-v2-metric-indoor-small")
        torch_dtype = getattr(torch, dtype, None)
        if not isinstance(torch_dtype, torch.dtype):
            raise InputError(f"unknown dtype '{dtype}'; use float32, float16 or bfloat16")
        self.device = _pick_device(device)
        self.model = DepthAnythingForDepthEstimation.from_pretrained(weights_dir, dtype=torch_dtype, use_safetensors=True).to(self.device).eval()
        if self.model.config.depth_estimation_type != "metric":
            raise ModelUnavailableError(
                f"{weights_dir} is a relative-depth Depth Anything checkpoint; use a metric one "
                "(scene-builder models fetch depth-anything-v2-metric-indoor-small)"
            )
        max_depth = self.model.config.max_depth
        if max_depth is None or not float(max_depth) >= _MIN_MAX_DEPTH_M:
            raise ModelUnavailableError(
                f"{weights_dir}/config.json gives the metric head max_depth {max_depth} m; the published indoor "
                f"checkpoints use {INDOOR_MAX_DEPTH_M:g} (outdoor 80): set max_depth in config.json"
            )
        if (weights_dir / "preprocessor_config.json").is_file():
            self.processor = DPTImageProcessorPil.from_pretrained(weights_dir)
        else:
            self.processor = DPTImageProcessorPil(**default_processor_kwargs())
        self.dtype = torch_dtype
        self.max_depth_m = float(self.model.config.max_depth)

    def estimate(self, rgb: np.ndarray, intrinsics: CameraIntrinsics | None = None) -> DepthEstimate:
        """rgb: (H, W, 3) uint8. Returns (H, W) float32 metric depth (focal_px None: the model
        does not estimate it)."""
        return self.estimate_batch([rgb])[0]

    def estimate_batch(self, images: Sequence[np.ndarray], batch_size: int = 4) -> list[DepthEstimate]:
        """Depth of several images; images of equal size run together in batches of ``batch_size``.

        images: each (H_i, W_i, 3) uint8. Returns one DepthEstimate per image, in order.
        """
        import torch

        arrays = [_check_rgb(im) for im in images]
        out: list[DepthEstimate | None] = [None] * len(arrays)
        by_shape: dict[tuple[int, int], list[int]] = {}
        for i, im in enumerate(arrays):
            by_shape.setdefault(im.shape[:2], []).append(i)
        for shape in sorted(by_shape):
            idx = by_shape[shape]
            for start in range(0, len(idx), batch_size):
                chunk = idx[start : start + batch_size]
                pixels = self.preprocess([arrays[i] for i in chunk])
                with torch.inference_mode():
                    outputs = self.model(pixel_values=pixels.to(self.device, self.dtype))
                depth = self.postprocess(outputs, [shape] * len(chunk))
                for j, i in enumerate(chunk):
                    out[i] = DepthEstimate(depth_m=depth[j], focal_px=None)
        return [o for o in out if o is not None]

    def preprocess(self, images: Sequence[np.ndarray]):
        """(B, 3, h, w) float32 torch pixel values of equal-size (H, W, 3) uint8 images: the DPT
        processor's output, unchanged."""
        return self.processor([_check_rgb(im) for im in images], return_tensors="pt")["pixel_values"]

    def postprocess(self, outputs, sizes: Sequence[tuple[int, int]]) -> np.ndarray:
        """(B, H, W) float32 metres from the model's outputs: the processor's
        ``post_process_depth_estimation`` (bicubic, ``align_corners=False``) to each (H, W) of
        ``sizes``, kept inside the head's range (0, max_depth]."""
        import torch

        pred = outputs.predicted_depth.float()
        resized = self.processor.post_process_depth_estimation(type(outputs)(predicted_depth=pred), target_sizes=list(sizes))
        depth = torch.stack([r["predicted_depth"].reshape(size) for r, size in zip(resized, sizes)])
        # Bicubic overshoots at sharp edges: keep it inside the head's range (0, max].
        return depth.clamp(min=1e-3, max=self.max_depth_m).cpu().numpy().astype(np.float32)


def _check_rgb(rgb: np.ndarray) -> np.ndarray:
    arr = np.asarray(rgb)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8:
        raise InputError(f"expected an (H, W, 3) uint8 RGB image, got {arr.shape} {arr.dtype}")
    return np.ascontiguousarray(arr)
