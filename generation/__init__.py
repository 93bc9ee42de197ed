"""Per-object asset generation: perceived objects -> simulation-ready assets.

Entry point: :func:`generate_assets`. :func:`assemble_asset` builds an asset from part
specifications (voxel grids, convex solids or meshes) and is shared with the PhysX backend.
Importing this package is cheap: heavy libraries (trimesh, skimage, coacd, manifold3d) are
imported inside the functions that use them.

Backends (registry task ``"generation"``):

* ``"shape-prior"`` (priority 0, always available): category shape priors, articulation
  templates and observed-shell completion on the CPU (``generation.shape_prior``);
* ``"physx-anything-vlm"`` (priority 100, registered by ``generation.physx``): available when
  its weights are found locally. An object it fails on gets the shape prior instead, and the
  asset's ``fallback_reason`` (report.json: ``generation_failures``) says why.
"""

from __future__ import annotations

import importlib.util
from typing import TYPE_CHECKING, Callable, Protocol

from scene_builder.config import GenerationConfig, usable_cores
from scene_builder.model import BackendUse, GeneratedAsset, PerceivedObject, Perception
from scene_builder.registry import Registry

if TYPE_CHECKING:
    from generation.assembly import ConvexSolids, JointSpec, PartSpec, VoxelGeometry  # noqa: F401

__all__ = [
    "AssetGenerator",
    "ShapePriorFallback",
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


class ShapePriorFallback:
    """The preferred (learned) generator, and the shape prior for every object it fails on: a
    VLM answer that cannot be read, is truncated even after its retries, disagrees with the
    observed box, or a model that fails to load or run. The asset then records why in
    ``ObjectAsset.fallback_reason`` (and so in report.json); the other objects are unaffected."""

    def __init__(self, primary: AssetGenerator, fallback: AssetGenerator | None = None) -> None:
        self.primary = primary
        self.fallback = fallback if fallback is not None else _shape_prior()
        self.name = primary.name

    def generate(self, obj: PerceivedObject, perception: Perception, config: GenerationConfig, seed: int = 0) -> GeneratedAsset:
        from dataclasses import replace

        from scene_builder.errors import SceneBuilderError

        try:
            return self.primary.generate(obj, perception, config, seed)
        except (SceneBuilderError, ValueError) as err:  # recorded in the asset, not swallowed
            reason = str(err).splitlines()[0] if str(err) else type(err).__name__
            generated = self.fallback.generate(obj, perception, config, seed)
            note = f"{self.primary.name} failed: {type(err).__name__}: {reason}"
            return replace(generated, asset=replace(generated.asset, fallback_reason=note))


def resolve_generator(config: GenerationConfig) -> tuple[AssetGenerator, BackendUse]:
    """The generator ``config.backend`` names (or the best available for ``"auto"``) and why. A
    learned generator is wrapped so that an object it fails on gets the shape prior instead."""
    backend, use = generator_registry().resolve(config.backend)
    if use.backend != "shape-prior":
        backend = ShapePriorFallback(backend, _shape_prior())
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
    each object. Deterministic for a given seed. An object the learned generator fails on gets a
    shape-prior asset whose ``fallback_reason`` says why."""
    generator, use = resolve_generator(config)

    def one(obj: PerceivedObject) -> GeneratedAsset:
        generated = generator.generate(obj, perception, config, seed)
        if config.photo_textures:
            from generation.texture import photo_textured

            generated = photo_textured(generated, obj, perception.observation, perception.camera)
        return generated

    # The shape prior makes each object from the perception alone, in numpy, SciPy and trimesh
    # calls that release the GIL for much of their time: objects are made on threads, collected
    # in their order (the same assets as one at a time, byte for byte). A learned generator keeps
    # its one model call at a time.
    import contextlib
    from concurrent.futures import ThreadPoolExecutor

    threads = min(usable_cores(), len(perception.objects)) if use.backend == "shape-prior" else 1
    out = []
    with ThreadPoolExecutor(threads, thread_name_prefix="generate") if threads > 1 else contextlib.nullcontext() as pool:
        made = map(one, perception.objects) if pool is None else pool.map(one, perception.objects)
        for obj, generated in zip(perception.objects, made):
            out.append(generated)
            if on_object is not None:
                on_object(obj.name)
    return tuple(out)


def assemble_asset(*args, **kwargs):
    """See :func:`generation.assembly.assemble_asset` (re-exported lazily to keep import cheap)."""
    from generation.assembly import assemble_asset as _assemble

    return _assemble(*args, **kwargs)
