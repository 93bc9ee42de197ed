"""Configuration of a build: one frozen dataclass per stage, gathered in :class:`BuildConfig`.

Every field has a default that a user of ``scene-builder build`` gets without flags.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class InputSpec:
    """What the user handed in.

    image_path: the photo. depth_path: optional aligned depth image (uint16 PNG, or any
    single-channel image readable by PIL, or a .npy of float metres). depth_scale: metres per depth
    unit (0.001 for millimetre PNGs). intrinsics: (fx, fy, cx, cy) in pixels, or None. fov_deg:
    horizontal field of view used when no intrinsics, EXIF focal length or camera.json is found.
    """

    image_path: Path
    depth_path: Path | None = None
    depth_scale: float = 0.001
    intrinsics: tuple[float, float, float, float] | None = None
    fov_deg: float | None = None


@dataclass(frozen=True)
class PerceptionConfig:
    """Perception settings.

    default_fov_deg: horizontal field of view assumed when nothing else gives intrinsics (60 deg
    is a typical phone / Kinect-class camera). max_depth_m: depth beyond this is ignored.
    min_object_points: clusters with fewer observed points are dropped. depth_backend,
    segmentation_backend, naming_backend: registry names or "auto". models_dir: where learned
    model weights are looked up first (also $SCENE_BUILDER_MODELS). background: build the static
    textured background from every pixel no movable object explains.
    """

    default_fov_deg: float = 60.0
    max_depth_m: float = 10.0
    min_object_points: int = 150
    max_objects: int = 40
    depth_backend: str = "auto"
    segmentation_backend: str = "auto"
    naming_backend: str = "auto"
    models_dir: Path | None = None
    background: bool = True


@dataclass(frozen=True)
class GenerationConfig:
    """Per-object asset generation settings.

    voxel_resolution: voxels along the longest side of an object's grid (PhysX-Omni uses 64).
    coacd_threshold: CoACD concavity threshold. max_collision_pieces: bound on convex pieces per part.
    max_voxel_pieces: the same bound for parts completed from observed voxels (irregular scanned
    shapes: with fewer, hulls bridge concavities where neighbours stand).
    cache_dir: where convex decompositions are cached (keyed by mesh hash); None disables it.
    backend: registry name or "auto". photo_textures: texture every asset with the photo,
    projected from the input camera.
    """

    voxel_resolution: int = 48
    coacd_threshold: float = 0.08
    max_collision_pieces: int = 12
    max_voxel_pieces: int = 32
    max_visual_faces: int = 4000
    cache_dir: Path | None = None
    backend: str = "auto"
    photo_textures: bool = True


@dataclass(frozen=True)
class LayoutConfig:
    """Layout solver and physics-check settings.

    settle_s: simulated seconds of the stability check. adopt_settled: replace solved poses with
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
    scene.usdz. viz: "save" (OUT/scene.rrd), "spawn" (open the viewer too) or "off"."""

    mjcf: bool = True
    usd: bool = True
    usdz: bool = False
    urdf: bool = True
    gltf: bool = True
    viz: str = "save"


@dataclass(frozen=True)
class BuildConfig:
    """Everything a build needs besides the input. ``seed`` makes the output deterministic."""

    seed: int = 0
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    generation: GenerationConfig = field(default_factory=GenerationConfig)
    layout: LayoutConfig = field(default_factory=LayoutConfig)
    export: ExportConfig = field(default_factory=ExportConfig)
