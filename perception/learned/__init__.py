"""Learned perception backends (Depth Anything V2, SAM 2, EfficientNet-Lite0 naming, Grounding
DINO and the offline detectors) and the weight-free single-photo depth chain, registered into the
perception registries.

Everything heavy is imported inside the factories: registering costs a few file-system checks.
"""

from __future__ import annotations

from pathlib import Path

from scene_builder.config import PerceptionConfig
from scene_builder.registry import Registry

__all__ = ["OFF_BY_DEFAULT", "register_backends", "register_box_prompt_backends", "register_detection_backends"]

#: Detectors registered but not run by the ``"detections"`` segmenter (their entry says why).
#: NanoDet: on the 15 inventory photos (82 objects a person counts) the pipeline with it found
#: none more and 4 more wrong objects at its accept_score 0.5 (instance precision 0.889 -> 0.836),
#: 3 more and 8 more wrong at 0.4 (recall 0.683 -> 0.720, precision 0.797): its COCO names call
#: cabinet close-ups refrigerator, microwave or oven, and its mistakes agree with CenterNet's
#: (pictures as tv). BENCHMARKS.md, "Offline detectors in the pipeline". Benchmarks build it
#: through its registry factory.
OFF_BY_DEFAULT: frozenset[str] = frozenset({"nanodet-coco"})


def _weights(name: str, models_dir: Path | None) -> Path:
    """The local weights of model ``name``; ModelUnavailableError (one line) when absent."""
    from perception import models

    path = models.resolve_weights(name, models_dir)
    if path is None:
        from scene_builder.errors import ModelUnavailableError

        raise ModelUnavailableError(models.unavailable_reason(name, models_dir) or f"{name} is not available")
    return path


def register_backends(depth: Registry, segmentation: Registry, naming: Registry, config: PerceptionConfig) -> None:
    """Register this package's backends (lazy factories; availability says why not, in one line).

    depth: ``"depth-anything-v2"`` (priority 100, when its weights resolve locally) and
    ``"single-view-geometry"`` (priority 0, always available, no weights).
    segmentation: ``"sam2"`` (priority 100, when its weights resolve locally).
    naming: ``"efficientnet-lite0"`` (priority 50, when its ONNX file, shipped with the project,
    passes its SHA-256 check).
    """
    from perception import models

    models_dir = config.models_dir

    def weights(name: str) -> Path:
        return _weights(name, models_dir)

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
        from perception.learned.detectors import CenterNetCocoDetector

        return SingleViewDepth(detector=CenterNetCocoDetector(det_path))

    def make_sam2():
        from perception.learned.sam2 import Sam2Segmenter

        return Sam2Segmenter(weights(sam_name), config.sam2)

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
        description="EfficientNet-Lite0 ImageNet classifier (onnxruntime) mapped to the project vocabulary",
    )


def register_box_prompt_backends(registry: Registry, config: PerceptionConfig) -> None:
    """Register ``"sam2"`` (priority 100, when its weights resolve locally) into a registry of
    ``perception.protocols.BoxPromptSegmenter`` backends: detector boxes prompt SAM 2 as in
    Grounded-SAM-2. The caller registers its classical fallback (GrabCut) at a lower priority."""
    from perception import models

    sam_name = models.default_model("segmentation").name

    def make_sam2():
        from perception.learned.sam2 import Sam2Segmenter

        return Sam2Segmenter(_weights(sam_name, config.models_dir), config.sam2)

    registry.register(
        "sam2",
        make_sam2,
        priority=100,
        available=lambda: models.unavailable_reason(sam_name, config.models_dir),
        description=f"SAM 2 prompted with detector boxes, one mask per box ({sam_name}, transformers)",
    )


def _detector_reason(name: str, models_dir: Path | None) -> str | None:
    """Why detector ``name`` is not run: its file is missing, or it is off by default."""
    from perception import models

    if name in OFF_BY_DEFAULT:
        return f"{name} is off by default (more false objects than found ones on the inventory photos; BENCHMARKS.md, Offline detectors)"
    return models.unavailable_reason(name, models_dir)


def register_detection_backends(detection: Registry, semantic: Registry, box_prompt: Registry, config: PerceptionConfig) -> None:
    """Register the offline detectors, the semantic segmenter and SAM 2 box prompts (lazy
    factories; availability says why not, in one line).

    detection: ``"grounding-dino-tiny"`` (priority 200, when its weights resolve locally: the
    open-vocabulary detector prompted with the room vocabulary, downloaded on a networked
    machine), ``"centernet-mbv3-coco"`` (priority 100) and ``"ssd-mobilenet-oid"`` (priority 50),
    each when its file resolves through the model registry (the ``"detections"`` segmenter runs
    every available one, in this order); ``"nanodet-coco"`` (priority 75) is unavailable while
    it is in :data:`OFF_BY_DEFAULT`. semantic: ``"deeplabv3-mnv2-pascal"`` (priority 50).
    box_prompt: ``"sam2"`` (priority 100, when its weights resolve locally; GrabCut is the
    always-available fallback registered by ``perception.backends``).
    """
    from perception import models

    models_dir = config.models_dir

    def weights(name: str) -> Path:
        return _weights(name, models_dir)

    gd_name = models.default_model("detection").name

    def make_grounding_dino():
        from perception.learned.grounding_dino import GroundingDinoDetector

        return GroundingDinoDetector(weights(gd_name))

    def make_centernet():
        from perception.learned.detectors import CenterNetCocoDetector

        return CenterNetCocoDetector(weights("centernet-mbv3-coco"))

    def make_nanodet():
        from perception.learned.detectors import NanoDetCocoDetector

        return NanoDetCocoDetector(weights("nanodet-coco"))

    def make_ssd():
        from perception.learned.detectors import SsdOidDetector

        return SsdOidDetector(weights("ssd-mobilenet-oid"))

    def make_deeplab():
        from perception.learned.detectors import DeepLabPascalSegmenter

        return DeepLabPascalSegmenter(weights("deeplabv3-mnv2-pascal"))

    for name, factory, priority, what in (
        (gd_name, make_grounding_dino, 200, "Grounding DINO prompted with the room vocabulary, open-vocabulary boxes (transformers)"),
        ("centernet-mbv3-coco", make_centernet, 100, "CenterNet MobileNetV3, 80 COCO classes (onnxruntime)"),
        ("nanodet-coco", make_nanodet, 75, "NanoDet-m, 80 COCO classes (onnxruntime)"),
        ("ssd-mobilenet-oid", make_ssd, 50, "SSD MobileNetV2, Open Images indoor classes incl. desk and table (TFLite)"),
    ):
        detection.register(name, factory, priority=priority, available=lambda n=name: _detector_reason(n, models_dir), description=what)
    semantic.register(
        "deeplabv3-mnv2-pascal",
        make_deeplab,
        priority=50,
        available=lambda: models.unavailable_reason("deeplabv3-mnv2-pascal", models_dir),
        description="DeepLab v3 MobileNetV2, PASCAL VOC classes (TFLite)",
    )
    register_box_prompt_backends(box_prompt, config)
