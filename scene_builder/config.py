"""Configuration of a build: one frozen dataclass per stage, gathered in :class:`BuildConfig`.

Every field has a default that a user of ``scene-builder build`` gets without flags.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path


def usable_cores() -> int:
    """The cores this process may use (its CPU affinity), at most ``OMP_NUM_THREADS`` where it is
    set (``scene-builder batch`` sets it to each worker's share of the cores): how many threads a
    stage runs side by side."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    cap = os.environ.get("OMP_NUM_THREADS", "").strip()
    return max(1, min(cores, int(cap)) if cap.isdigit() and int(cap) > 0 else cores)


@dataclass(frozen=True)
class InputSpec:
    """What the user handed in.

    image_path: the photo. depth_path: optional aligned depth image (uint16 PNG, or any
    single-channel image readable by PIL, or a .npy). depth_scale: metres per unit of the depth
    file, or None for the file's natural unit (millimetres for integer images and arrays, metres
    for float ones). intrinsics: (fx, fy, cx, cy) in pixels, or None. fov_deg: horizontal field of
    view in degrees, or None (``perception.inputs`` gives the order of the intrinsics sources).
    """

    image_path: Path
    depth_path: Path | None = None
    depth_scale: float | None = None
    intrinsics: tuple[float, float, float, float] | None = None
    fov_deg: float | None = None


@dataclass(frozen=True)
class Sam2Settings:
    """SAM 2 automatic-mask generator and box prompts (``perception.learned.sam2``).

    The defaults of the first group are upstream's, as the authors run SAM 2: the keyword defaults
    of ``SAM2AutomaticMaskGenerator.__init__`` in facebookresearch/sam2
    (``sam2/automatic_mask_generator.py``, commit 2b90b9f5): 32 x 32 points, 64 per batch,
    predicted IoU > 0.8, stability >= 0.95 at a logit offset of 1.0 around the 0.0 mask threshold,
    box NMS at IoU 0.7, no small-region clean-up (0 px), three masks per point. transformers'
    ``mask-generation`` pipeline (``pipelines/mask_generation.py`` and
    ``Sam2ImageProcessor.filter_masks``) uses the same values except predicted IoU > 0.88 (the
    SAM 1 value). Box prompts give one mask per box (``multimask_output=False``), as
    IDEA-Research/Grounded-SAM-2 does in ``grounded_sam2_local_demo.py``.

    The last two fields are this project's own steps after upstream's generator: masks lying
    mostly (``max_background_frac``) on floor / walls / ceiling are not objects, and instances
    smaller than ``min_instance_frac`` of the image are dropped.
    """

    points_per_side: int = 32
    points_per_batch: int = 64
    pred_iou_thresh: float = 0.8
    stability_score_thresh: float = 0.95
    stability_score_offset: float = 1.0
    mask_threshold: float = 0.0
    box_nms_thresh: float = 0.7
    min_mask_region_area_px: int = 0
    multimask_output: bool = True
    box_prompt_multimask: bool = False
    max_background_frac: float = 0.5
    min_instance_frac: float = 0.001


@dataclass(frozen=True)
class PerceptionConfig:
    """Perception settings.

    default_fov_deg: horizontal field of view assumed when nothing else gives intrinsics (60 deg
    is a typical phone / Kinect-class camera). max_depth_m: depth beyond this is ignored.
    min_object_points: clusters with fewer observed points are dropped. depth_backend,
    segmentation_backend, naming_backend: registry names or "auto". models_dir: where learned
    model weights are looked up first (also $SCENE_BUILDER_MODELS). sam2: SAM 2 settings.
    background: build the static textured background from every pixel no movable object explains.
    fronts: find door and drawer fronts on furniture faces and built-in runs from them
    (``perception.fronts``); off, articulated furniture gets its category template's layout.
    """

    default_fov_deg: float = 60.0
    max_depth_m: float = 10.0
    min_object_points: int = 150
    max_objects: int = 40
    depth_backend: str = "auto"
    segmentation_backend: str = "auto"
    naming_backend: str = "auto"
    models_dir: Path | None = None
    sam2: Sam2Settings = field(default_factory=Sam2Settings)
    background: bool = True
    fronts: bool = True


@dataclass(frozen=True)
class GenerationConfig:
    """Per-object asset generation settings.

    voxel_resolution: voxels along the longest side of an object's grid (PhysX-Omni uses 64).
    coacd_threshold: CoACD concavity threshold. max_collision_pieces: bound on convex pieces per part.
    max_voxel_pieces: the same bound for parts completed from observed voxels (irregular scanned
    shapes: with fewer, hulls bridge concavities where neighbours stand).
    cache_dir: where convex decompositions are cached (keyed by mesh hash); None disables it.
    backend: registry name or "auto".
    vlm_max_new_tokens: answer budget of the PhysX vision-language model, tokens per answer; 0
    follows the voxel grid (1024 per voxel of grid side: 32768 for 32^3, 65536 for 64^3).
    vlm_retries: a truncated answer is asked again with twice the budget this many times; still
    cut, the object falls back to the shape prior. vlm_crop_px, vlm_crop_fill: the single-object
    image given to the model (side in pixels; the object's longer side over the image side),
    upstream's 512 and the 0.58 median of its demo images. photo_textures: texture every asset with the photo,
    projected from the input camera.
    """

    voxel_resolution: int = 48
    coacd_threshold: float = 0.08
    max_collision_pieces: int = 12
    max_voxel_pieces: int = 32
    max_visual_faces: int = 4000
    cache_dir: Path | None = None
    backend: str = "auto"
    vlm_max_new_tokens: int = 0
    vlm_retries: int = 1
    vlm_crop_px: int = 512
    vlm_crop_fill: float = 0.58
    photo_textures: bool = True


@dataclass(frozen=True)
class LayoutConfig:
    """Layout solver and physics-check settings.

    settle_s: simulated seconds of the stability check (it ends sooner once every body has been
    at rest for half a second, after at least one second: layout.verify.REST_MOVE_M). adopt_settled: replace solved poses with
    the settled ones. max_wall_push_m: a movable object reaching further than this into a wall is
    wall (a door, a radiator, an off wall plane): it stays where seen as static background;
    shallower, it is pushed out. max_lower_m: an object seen at most this far above its support
    is set down on it; higher, it keeps its height and stands on collision legs. max_push_m: an
    overlap that a sideways push of more than this would clear leaves the lighter object where
    it was seen, as static background. clearance_m: gap kept between neighbouring objects by the solver.
    stable_drift_m, stable_rotation_deg: the per-object bounds for ``stable``.
    """

    settle_s: float = 3.0
    adopt_settled: bool = False
    max_wall_push_m: float = 0.05
    max_lower_m: float = 0.02
    max_push_m: float = 0.25
    clearance_m: float = 0.002
    max_iterations: int = 200
    stable_drift_m: float = 0.01
    stable_rotation_deg: float = 2.0


@dataclass(frozen=True)
class ExportConfig:
    """Which outputs to write. usdz: also package the USD stage and its textures as one
    scene.usdz. urdf: one URDF per object (OUT/urdf/); scene_urdf: also the whole scene as one
    URDF (OUT/scene.urdf, objects on floating joints). sdf: OUT/scene.sdf. viz: "save"
    (OUT/scene.rrd), "spawn" (open the viewer too) or "off"."""

    mjcf: bool = True
    usd: bool = True
    usdz: bool = False
    urdf: bool = True
    scene_urdf: bool = False
    sdf: bool = True
    gltf: bool = True
    viz: str = "save"


@dataclass(frozen=True)
class RobotConfig:
    """``--robot``: name (None: no robot; see ``generation.robot.ROBOTS``), source ("auto":
    MuJoCo Menagerie, else the built-in model; "menagerie"; "built-in") and offline (never
    download: the built-in model answers)."""

    name: str | None = None
    source: str = "auto"
    offline: bool = False


@dataclass(frozen=True)
class BuildConfig:
    """Everything a build needs besides the input. ``seed`` makes the output deterministic."""

    seed: int = 0
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    generation: GenerationConfig = field(default_factory=GenerationConfig)
    layout: LayoutConfig = field(default_factory=LayoutConfig)
    export: ExportConfig = field(default_factory=ExportConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
