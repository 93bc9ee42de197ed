"""The perception registries: one per task (depth, segmentation, naming; and the detection,
semantic-segmentation and box-segmentation backends the ``"detections"`` segmenter combines).

The geometric fallbacks of this package are registered at priority 0; the learned backends
(Depth Anything V2, single-view geometry, SAM2, EfficientNet-Lite0 naming, ...) are registered by
``perception.learned.register_backends`` with their own availability checks, the detectors and
the semantic segmenter by ``perception.learned.register_detection_backends``.
"""

from __future__ import annotations

import importlib
import importlib.util
from dataclasses import dataclass, field

from perception.protocols import BoxPromptSegmenter, DepthEstimator, InstanceSegmenter, ObjectDetector, ObjectNamer, SemanticSegmenter
from scene_builder.config import PerceptionConfig
from scene_builder.errors import ModelUnavailableError
from scene_builder.registry import Registry

__all__ = ["PerceptionRegistries", "build_registries"]


@dataclass(frozen=True)
class PerceptionRegistries:
    """The registries ``perceive`` resolves a backend from (depth, segmentation, naming), and
    those the ``"detections"`` segmenter draws on."""

    depth: Registry[DepthEstimator]
    segmentation: Registry[InstanceSegmenter]
    naming: Registry[ObjectNamer]
    detection: Registry[ObjectDetector] = field(default_factory=lambda: Registry("detection"))
    semantic: Registry[SemanticSegmenter] = field(default_factory=lambda: Registry("semantic-segmentation"))
    box_prompt: Registry[BoxPromptSegmenter] = field(default_factory=lambda: Registry("box-segmentation"))


def build_registries(config: PerceptionConfig) -> PerceptionRegistries:
    """Registries for ``config``: this package's geometric fallbacks plus the learned backends
    when ``perception.learned`` provides ``register_backends`` (and the detectors when it
    provides ``register_detection_backends``)."""
    from perception.box_segment import GrabCutBoxSegmenter
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
    detection: Registry[ObjectDetector] = Registry("detection")
    semantic: Registry[SemanticSegmenter] = Registry("semantic-segmentation")
    box_prompt: Registry[BoxPromptSegmenter] = Registry("box-segmentation")
    box_prompt.register(
        "grabcut",
        GrabCutBoxSegmenter,
        priority=0,
        description="OpenCV GrabCut in each box, seeded with depth and semantic hints",
    )
    # The learned backends live in a sibling package that may not be there yet; look before
    # importing rather than catching ImportError (which would also hide its real import errors).
    if importlib.util.find_spec("perception.learned") is not None:
        learned = importlib.import_module("perception.learned")
        if hasattr(learned, "register_backends"):
            learned.register_backends(depth, segmentation, naming, config)
        if hasattr(learned, "register_detection_backends"):
            learned.register_detection_backends(detection, semantic, box_prompt, config)
    registries = PerceptionRegistries(depth, segmentation, naming, detection, semantic, box_prompt)

    def detectors_missing() -> str | None:
        reasons = [f"{e.name}: {why}" for e in detection.entries() if (why := e.available()) is not None]
        if len(reasons) < len(detection.entries()):
            return None
        return "no object detector available" + (f" ({'; '.join(reasons)})" if reasons else "")

    segmentation.register(
        "detections",
        lambda: _detection_segmenter(registries, config),
        priority=150,
        available=detectors_missing,
        description="detector boxes (Grounding DINO prompted with the room vocabulary, COCO CenterNet, Open Images SSD) "
        "confirmed by depth clusters and the semantic map, outlined by SAM 2 or GrabCut; clear unexplained depth clusters "
        "as extra objects",
    )
    return registries


def _detection_segmenter(registries: PerceptionRegistries, config: PerceptionConfig):
    """The ``"detections"`` segmenter over every available detector, the best box segmenter and
    semantic segmenter, and the depth-cluster segmenter."""
    from perception.segment_depth import DepthClusterSegmenter
    from perception.segment_detect import DetectionSegmenter, NamedBackend

    detectors = [NamedBackend(e.name, e.factory()) for e in registries.detection.entries() if e.available() is None]
    box, box_use = registries.box_prompt.resolve()
    semantic = None
    if any(e.available() is None for e in registries.semantic.entries()):
        sem, sem_use = registries.semantic.resolve()
        semantic = NamedBackend(sem_use.backend, sem)
    geometry = DepthClusterSegmenter(min_points=config.min_object_points, max_depth_m=config.max_depth_m)
    namer, name_use = registries.naming.resolve(config.naming_backend)
    classifier = NamedBackend(name_use.backend, namer) if hasattr(namer, "label_scores_many") else None
    return DetectionSegmenter(
        detectors, NamedBackend(box_use.backend, box), semantic, geometry, config.min_object_points, config.max_depth_m, classifier
    )


def prepare_learned_weights(
    config: PerceptionConfig,
    need_depth: bool,
    offline: bool = False,
    timeout_s: float = 2.0,
    progress: bool = True,
) -> tuple[str, ...]:
    """Make the default learned perception models usable for a build, the first time downloading
    them (Depth Anything V2 when ``need_depth``, SAM 2, Grounding DINO) with progress bars, unless
    ``offline``, ``HF_HUB_OFFLINE`` or no network (``perception.models.offline_reason``, decided in
    about ``timeout_s``). Only the models of tasks whose backend is "auto" or that model's backend
    are considered (SAM 2 and Grounding DINO also for the ``"detections"`` segmenter, whose
    detector and box prompts they are). Returns one-line notes for the user: what was downloaded,
    or which fallback each task will use and why (empty when every weight was already here)."""
    from perception import models

    wanted: list[tuple[str, str, str]] = []  # (task, backend, model)
    if need_depth and config.depth_backend in ("auto", "depth-anything-v2"):
        wanted.append(("depth", "depth-anything-v2", models.default_model("depth").name))
    if config.segmentation_backend in ("auto", "sam2", "detections"):
        wanted.append(("segmentation", "sam2", models.default_model("segmentation").name))
    if config.segmentation_backend in ("auto", "detections"):
        detector = models.default_model("detection").name
        wanted.append(("detection", detector, detector))
    missing = [w for w in wanted if models.resolve_weights(w[2], config.models_dir) is None]
    if not missing:
        return ()
    names = [m for _, _, m in missing]
    size_mb = sum(models.model_spec(m).download_mb for m in names)
    why = models.offline_reason(offline, timeout_s)
    if why is None:
        from huggingface_hub import errors as hf_errors

        # What a failed download raises: fetch_models' ModelUnavailableError (the hub went away
        # since the check above); what snapshot_download documents (OSError, which its HTTP errors
        # RepositoryNotFoundError, RevisionNotFoundError... are, and ValueError); and its HTTP
        # client's transport errors (a connection dropped mid-file), whose base HTTPError is not an
        # OSError (huggingface_hub.errors subclasses it). The build goes on with its fallbacks; the
        # note says why.
        download_errors = (ModelUnavailableError, OSError, ValueError, hf_errors.HTTPError)
        try:
            paths = models.fetch_models(names, config.models_dir, endpoint_timeout_s=max(timeout_s, 5.0), progress=progress)
        except download_errors as err:
            why = f"download failed: {type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}".rstrip(": ")
        else:
            where = ", ".join(str(p) for p in paths)
            return (f"downloaded {', '.join(names)} (about {size_mb:.0f} MB) to {where}",)
    registries = build_registries(config)
    uses = []
    for task, backend, _ in missing:
        others = [e.name for e in getattr(registries, task).entries() if e.name != backend and e.available() is None]
        if task == "detection":  # the "detections" segmenter runs every available detector
            fallback = "+".join(others) if others else "no detector"
        else:
            fallback = others[0] if others else "none"
        uses.append(f"{task}: {fallback} instead of {backend}")
    return (
        f"no {' or '.join(names)} weights here and no download ({why}): {'; '.join(uses)}. "
        f"`scene-builder models fetch` on a networked machine gets them (about {size_mb:.0f} MB)",
    )
