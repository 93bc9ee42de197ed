"""Per-object asset generation: perceived objects -> simulation-ready assets.

Entry point: :func:`generate_assets`. :func:`assemble_asset` builds an asset from part
specifications (voxel grids, convex solids or meshes) and is shared with the PhysX backend.
Importing this package is cheap: heavy libraries (trimesh, skimage, coacd, manifold3d) are
imported inside the functions that use them.

Backends (registry task ``"generation"``):

* ``"shape-prior"`` (priority 0, always available): category shape priors, articulation
  templates and observed-shell completion on the CPU (``generation.shape_prior``);
* ``"physx-anything-vlm"`` (priority 100, registered by ``generation.physx``): available when
  its weights are found locally.
"""

from __future__ import annotations

import importlib.util
from typing import TYPE_CHECKING, Callable, Protocol

from scene_builder.config import GenerationConfig
from scene_builder.model import BackendUse, GeneratedAsset, PerceivedObject, Perception
from scene_builder.registry import Registry

if TYPE_CHECKING:
    from generation.assembly import ConvexSolids, JointSpec, PartSpec, VoxelGeometry  # noqa: F401

__all__ = [
    "AssetGenerator",
    "assemble_asset",
    "generate_assets",
    "generator_registry",
    "resolve_generator",
]


class AssetGenerator(Protocol):
    """A per-object generator: one :class:`GeneratedAsset` (asset named ``obj.name``, initial
    gravity-aligned pose, observed points) per perceived object."""

    name: str

    def generate(self, obj: PerceivedObject, perception: Perception, config: GenerationConfig, seed: int = 0) -> GeneratedAsset: ...


def _shape_prior() -> AssetGenerator:
    from generation.shape_prior import ShapePriorGenerator

    return ShapePriorGenerator()


def generator_registry() -> Registry[AssetGenerator]:
    """A fresh registry of the generation backends (the PhysX VLM backend when its package is
    present in this checkout)."""
    registry: Registry[AssetGenerator] = Registry("generation")
    registry.register("shape-prior", _shape_prior, priority=0,
                      description="category shape priors, articulation templates and observed-shell completion (CPU)")
    if importlib.util.find_spec("generation.physx") is not None:
        from generation.physx import register_backends

        register_backends(registry)
    return registry


class _PhysxAdapter:
    """Runs the PhysX VLM backend (which answers an ``ObjectAsset`` from an image crop) as an
    :class:`AssetGenerator`: crop from the object's mask, pose from the observed points."""

    name = "physx-anything-vlm"

    def __init__(self, backend) -> None:
        self.backend = backend

    def generate(self, obj: PerceivedObject, perception: Perception, config: GenerationConfig, seed: int = 0) -> GeneratedAsset:
        import numpy as np

        from generation.pose import fit_box
        from generation.shape_prior import complete_box

        rows, cols = np.nonzero(obj.mask)
        if len(rows) == 0:
            raise ValueError(f"object {obj.name}: empty mask, nothing to crop for the PhysX model")
        crop = perception.observation.rgb[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
        asset, _warnings = self.backend.generate_object(np.ascontiguousarray(crop), obj.name, obj.label, config=config, seed=seed)
        fit = complete_box(fit_box(obj.points_world_m, perception.camera.position_m), obj.label)
        return GeneratedAsset(asset, fit.world_from_box, obj.points_world_m)


def resolve_generator(config: GenerationConfig) -> tuple[AssetGenerator, BackendUse]:
    """The generator ``config.backend`` names (or the best available for ``"auto"``) and why."""
    backend, use = generator_registry().resolve(config.backend)
    if not hasattr(backend, "generate") and hasattr(backend, "generate_object"):
        backend = _PhysxAdapter(backend)
    return backend, use


def generate_assets(
    perception: Perception,
    config: GenerationConfig,
    seed: int = 0,
    on_object: Callable[[str], None] | None = None,
) -> tuple[GeneratedAsset, ...]:
    """One :class:`GeneratedAsset` per ``perception.objects`` (same order, asset name = object
    name), its visual meshes textured with the photo projected from the input camera
    (``generation.texture``) when ``config.photo_textures``. ``on_object(name)`` is called after
    each object. Deterministic for a given seed."""
    generator, _use = resolve_generator(config)
    out = []
    for obj in perception.objects:
        generated = generator.generate(obj, perception, config, seed)
        if config.photo_textures:
            from generation.texture import photo_textured

            generated = photo_textured(generated, obj, perception.observation, perception.camera)
        out.append(generated)
        if on_object is not None:
            on_object(obj.name)
    return tuple(out)


def assemble_asset(*args, **kwargs):
    """See :func:`generation.assembly.assemble_asset` (re-exported lazily to keep import cheap)."""
    from generation.assembly import assemble_asset as _assemble

    return _assemble(*args, **kwargs)
