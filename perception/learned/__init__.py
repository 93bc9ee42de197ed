"""Learned perception backends (Depth Anything V2, SAM 2, EfficientNet-Lite0 naming, the SSD
detector) and the weight-free single-photo depth chain, registered into the perception registries.

Everything heavy is imported inside the factories: registering costs a few file-system checks.
"""

from __future__ import annotations

from pathlib import Path

from scene_builder.config import PerceptionConfig
from scene_builder.registry import Registry

__all__ = ["register_backends"]


def register_backends(depth: Registry, segmentation: Registry, naming: Registry, config: PerceptionConfig) -> None:
    """Register this package's backends (lazy factories; availability says why not, in one line).

    depth: ``"depth-anything-v2"`` (priority 100, when its weights resolve locally) and
    ``"single-view-geometry"`` (priority 0, always available, no weights).
    segmentation: ``"sam2"`` (priority 100, when its weights resolve locally).
    naming: ``"efficientnet-lite0"`` (priority 50, when its package and weights file exist).
    """
    from perception import models

    models_dir = config.models_dir

    def weights(name: str) -> Path:
        path = models.resolve_weights(name, models_dir)
        if path is None:
            from scene_builder.errors import ModelUnavailableError

            raise ModelUnavailableError(models.unavailable_reason(name, models_dir) or f"{name} is not available")
        return path

    da_name = models.default_model("depth").name
    sam_name = models.default_model("segmentation").name
    eff_name = models.default_model("naming").name

    def make_depth_anything():
        from perception.learned.depth_anything import DepthAnythingV2Estimator

        return DepthAnythingV2Estimator(weights(da_name))

    def make_single_view():
        from perception.single_view import SingleViewDepth

        # A COCO detector, when its weights are here, stands beds, sofas and chairs on the floor
        # as cuboids of their typical size (and their heights refine the metric scale).
        det_path = models.resolve_weights("centernet-mbv3-coco", models_dir)
        if det_path is None:
            return SingleViewDepth()
        from perception.learned.centernet import CenterNetDetector

        return SingleViewDepth(detector=CenterNetDetector(det_path))

    def make_sam2():
        from perception.learned.sam2 import Sam2Segmenter

        return Sam2Segmenter(weights(sam_name))

    def make_efficientnet():
        from perception.learned.naming import EfficientNetNamer

        return EfficientNetNamer(weights(eff_name))

    def _eff_ok() -> str | None:
        return models.unavailable_reason(eff_name, models_dir)

    depth.register(
        "depth-anything-v2",
        make_depth_anything,
        priority=100,
        available=lambda: models.unavailable_reason(da_name, models_dir),
        description=f"Depth Anything V2 metric indoor ({da_name}, transformers)",
    )
    depth.register(
        "single-view-geometry",
        make_single_view,
        priority=0,
        description="vanishing points, floor and room box from a 1.3 m camera-height prior (plus COCO boxes of known size when centernet-mbv3-coco is present)",
    )
    segmentation.register(
        "sam2",
        make_sam2,
        priority=100,
        available=lambda: models.unavailable_reason(sam_name, models_dir),
        description=f"SAM 2 automatic masks ({sam_name}, transformers)",
    )
    naming.register(
        "efficientnet-lite0",
        make_efficientnet,
        priority=50,
        available=_eff_ok,
        description="EfficientNet-Lite0 ImageNet classifier mapped to the project vocabulary",
    )
