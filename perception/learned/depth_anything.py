"""Depth Anything V2 metric depth (``transformers`` ``DepthAnythingForDepthEstimation``).

The metric checkpoints end in ``sigmoid * max_depth`` (20 m for the indoor / Hypersim models), so
the network output is already metres; it is resized back to the input resolution here. Images go
through the DPT image processor's PIL backend (the torchvision one cannot be used on this
project's machines), resized so that the short side matches the checkpoint's size with the aspect
ratio kept and both sides multiples of the 14-pixel patch.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from perception.protocols import DepthEstimate
from scene_builder.errors import InputError, ModelUnavailableError
from scene_builder.model import CameraIntrinsics

__all__ = ["DepthAnythingV2Estimator", "default_processor_kwargs"]


def default_processor_kwargs() -> dict:
    """Preprocessing of the published Depth Anything V2 checkpoints, used when a weights folder has
    no ``preprocessor_config.json``: 518 px, aspect ratio kept, multiple of 14, ImageNet mean/std,
    bicubic."""
    return dict(
        size={"height": 518, "width": 518},
        keep_aspect_ratio=True,
        ensure_multiple_of=14,
        do_resize=True,
        do_rescale=True,
        rescale_factor=1 / 255,
        do_normalize=True,
        image_mean=[0.485, 0.456, 0.406],
        image_std=[0.229, 0.224, 0.225],
        do_pad=False,
        resample=3,  # PIL bicubic
    )


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
                pixels = self.processor([arrays[i] for i in chunk], return_tensors="pt")["pixel_values"]
                with torch.inference_mode():
                    pred = self.model(pixel_values=pixels.to(self.device, self.dtype)).predicted_depth
                    # (B, h, w) at the network resolution -> (B, H, W) at the input resolution.
                    pred = torch.nn.functional.interpolate(
                        pred.float().unsqueeze(1), size=shape, mode="bicubic", align_corners=False
                    )[:, 0]
                    # Bicubic overshoots at sharp edges: keep it inside the head's range (0, max].
                    pred = pred.clamp(min=1e-3, max=self.max_depth_m)
                depth = pred.cpu().numpy().astype(np.float32)
                for j, i in enumerate(chunk):
                    out[i] = DepthEstimate(depth_m=depth[j], focal_px=None)
        return [o for o in out if o is not None]


def _check_rgb(rgb: np.ndarray) -> np.ndarray:
    arr = np.asarray(rgb)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8:
        raise InputError(f"expected an (H, W, 3) uint8 RGB image, got {arr.shape} {arr.dtype}")
    return np.ascontiguousarray(arr)
