"""The perception registries: one per task (depth, segmentation, naming).

The geometric fallbacks of this package are registered at priority 0; the learned backends
(Depth Anything V2, single-view geometry, SAM2, EfficientNet-Lite0 naming, ...) are registered by
``perception.learned.register_backends`` with their own availability checks.
"""

from __future__ import annotations

import importlib
import importlib.util
from dataclasses import dataclass

from perception.protocols import DepthEstimator, InstanceSegmenter, ObjectNamer
from scene_builder.config import PerceptionConfig
from scene_builder.registry import Registry

__all__ = ["PerceptionRegistries", "build_registries"]


@dataclass(frozen=True)
class PerceptionRegistries:
    """The three registries ``perceive`` resolves a backend from."""

    depth: Registry[DepthEstimator]
    segmentation: Registry[InstanceSegmenter]
    naming: Registry[ObjectNamer]


def build_registries(config: PerceptionConfig) -> PerceptionRegistries:
    """Registries for ``config``: this package's geometric fallbacks plus the learned backends
    when ``perception.learned`` provides ``register_backends``."""
    from perception.naming_prior import GeometricPriorNamer
    from perception.segment_depth import DepthClusterSegmenter

    depth: Registry[DepthEstimator] = Registry("depth")
    segmentation: Registry[InstanceSegmenter] = Registry("segmentation")
    naming: Registry[ObjectNamer] = Registry("naming")
    segmentation.register(
        "depth-clusters",
        lambda: DepthClusterSegmenter(min_points=config.min_object_points, max_depth_m=config.max_depth_m),
        priority=0,
        description="Euclidean clusters of the depth points left after removing floor, walls and ceiling",
    )
    naming.register(
        "geometric-prior",
        GeometricPriorNamer,
        priority=0,
        description="label from gravity-aligned size against the vocabulary's typical sizes (low confidence)",
    )
    # The learned backends live in a sibling package that may not be there yet; look before
    # importing rather than catching ImportError (which would also hide its real import errors).
    if importlib.util.find_spec("perception.learned") is not None:
        learned = importlib.import_module("perception.learned")
        if hasattr(learned, "register_backends"):
            learned.register_backends(depth, segmentation, naming, config)
    return PerceptionRegistries(depth, segmentation, naming)
