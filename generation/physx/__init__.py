"""The PhysX-Anything / PhysX-Omni representation: geometry token encodings (``tokens``), the
overall-description text protocol (``description``: its grammar, dataclasses and writer;
``protocol``: its parser; ``grid_frame``: its joints in the asset frame), conversion to
asset-frame parts (``convert``)
and the vision-language model backend (``vlm``). Importing this package is cheap: heavy
libraries are imported inside the functions that use them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["BACKEND_NAME", "PhysxVlmGenerator", "register_backends", "turn_to_match"]

BACKEND_NAME = "physx-anything-vlm"


def model_load_errors() -> tuple[type[BaseException], ...]:
    """What loading a transformers model from a folder raises when the folder is wrong: OSError
    (files missing or unreadable: what ``from_pretrained`` documents), ValueError (a config,
    tokenizer or JSON file it cannot use), KeyError (transformers' tokenizer loader on a
    ``tokenizer.json`` without the keys it reads, e.g. ``'added_tokens'``: found with a malformed
    file), RuntimeError (torch: weights of the wrong shape, CUDA, out of GPU memory), MemoryError,
    and safetensors' ``SafetensorError`` (a corrupt weights file; not an OSError)."""
    from safetensors import SafetensorError

    return (OSError, ValueError, KeyError, RuntimeError, MemoryError, SafetensorError)


class PhysxVlmGenerator:
    """An ``AssetGenerator``: each object from a single-object image of it, answered by the
    PhysX model found in ``model_dir`` (or by ``chat``, any :class:`~generation.physx.vlm.ChatModel`,
    with ``prompts``), scaled to the box observed in the photo.

    The model is loaded on first use; a failure to load is raised again for every later object
    without trying again. Failures raise ``SceneBuilderError`` subclasses (ProtocolError,
    TruncatedAnswerError, VlmCallError, ModelUnavailableError): ``generation.generate_assets``
    falls back to the shape prior for that object."""

    name = BACKEND_NAME

    def __init__(self, model_dir: Path | None = None, chat=None, prompts=None) -> None:
        if model_dir is None and (chat is None or prompts is None):
            raise ValueError("PhysxVlmGenerator needs a model_dir, or a chat model and its prompts")
        self.model_dir = model_dir
        self._chat = chat
        self._prompts = prompts
        self._load_error: Exception | None = None

    def _model(self):
        from generation.physx.vlm import PhysxPrompts, TransformersQwenVL, VlmCallError

        from scene_builder.errors import SceneBuilderError

        if self._load_error is not None:
            raise self._load_error
        if self._chat is None or self._prompts is None:
            try:
                self._prompts = PhysxPrompts.from_dir(self.model_dir)
                self._chat = TransformersQwenVL.from_pretrained(self.model_dir)
            except SceneBuilderError as err:
                self._load_error = err
                raise
            except model_load_errors() as err:  # transformers / torch failing to load the folder
                self._load_error = VlmCallError(f"cannot load the PhysX model from {self.model_dir} ({type(err).__name__}: {err})".splitlines()[0])
                raise self._load_error from err
        return self._chat, self._prompts

    def converse(self, image_rgb: np.ndarray, config=None):
        """The model's raw answers for ``image_rgb`` ((H, W, 3) uint8 single-object image), the
        answer budget and retries from ``config``."""
        from generation.physx.vlm import run_conversation

        from scene_builder.config import GenerationConfig

        cfg = config if config is not None else GenerationConfig()
        chat, prompts = self._model()
        return run_conversation(chat, image_rgb, prompts, max_new_tokens=cfg.vlm_max_new_tokens or None, retries=cfg.vlm_retries)

    def generate_object(self, image_rgb, name: str, label: str, config=None, seed: int = 0, target_size_m=None):
        """(ObjectAsset, warnings) from a single-object image: the conversation, parsed and
        decoded, the parts scaled to ``target_size_m`` ((3,) asset-frame extents) when given,
        meshed, weighed and decomposed."""
        from generation.physx.convert import to_object_asset
        from generation.physx.vlm import physx_from_conversation

        conv = self.converse(image_rgb, config)
        obj, report = physx_from_conversation(conv, target_size_m=target_size_m)
        return to_object_asset(obj, name, label, config=config, seed=seed, backend=BACKEND_NAME), conv.notes + report.warnings

    def generate(self, obj, perception, config, seed: int = 0):
        """One ``GeneratedAsset`` for perceived object ``obj``: the single-object crop of the photo
        (:func:`~generation.physx.vlm.object_crop`), the model's articulated object with every part
        scaled per axis to the observed box (the shape prior's,
        :func:`generation.shape_prior.observed_box`: gravity-aligned, front towards the camera,
        down to the floor, completed to the category's depth short of the walls and of what other
        objects showed behind it), posed on that box. When the model's
        footprint proportions match the box turned by 90 degrees clearly better, the asset is
        turned (its front then faces the box's side)."""
        from generation.physx.convert import model_size_m, physx_object, to_object_asset
        from generation.physx.vlm import decode_conversation, object_crop
        from generation.shape_prior import observed_box

        from scene_builder.frames import pose, rot_z, transform_points
        from scene_builder.model import GeneratedAsset

        crop = object_crop(perception.observation.rgb, obj.mask, config.vlm_crop_px, config.vlm_crop_fill)
        fit = observed_box(obj, perception).fit  # the shape prior's box, so both backends pose alike
        conv = self.converse(crop, config)
        description, grids, _ = decode_conversation(conv)
        observed = np.asarray(fit.size_m, dtype=np.float64)
        turn = turn_to_match(model_size_m(description, grids), observed)
        physx = physx_object(description, grids, target_size_m=observed[[1, 0, 2]] if turn else observed)
        world_from_asset = fit.world_from_box @ pose(rot_z(np.pi / 2), np.zeros(3)) if turn else fit.world_from_box
        seen = transform_points(np.linalg.inv(world_from_asset), obj.points_world_m)
        asset = to_object_asset(physx, obj.name, obj.label, config=config, seed=seed, backend=BACKEND_NAME,
                                observed_points_m=seen, observed_colors_rgb=obj.colors_rgb)
        return GeneratedAsset(asset, world_from_asset, obj.points_world_m)


def turn_to_match(model_size_m: np.ndarray, observed_size_m: np.ndarray, margin: float = 1.25) -> bool:
    """True when the model's footprint (asset x front-back, y width) matches the observed box
    (x towards the camera, y across) turned by 90 degrees better than as seen, by more than a
    factor ``margin`` in aspect ratio."""
    own = float(np.log(model_size_m[0] / model_size_m[1]))
    seen = float(np.log(observed_size_m[0] / observed_size_m[1]))
    return abs(own + seen) + float(np.log(margin)) < abs(own - seen)


def register_backends(registry, models_dir: Path | None = None) -> None:
    """Register generation backend ``physx-anything-vlm`` (priority 100), available when the
    weights, tokenizer, image processor and prompts are in ``<models dir>/physx-anything``
    (``models_dir`` or ``$SCENE_BUILDER_MODELS``), resolved when asked, not at registration."""
    from generation.physx.vlm import model_dir_problem, resolve_model_dir

    registry.register(
        BACKEND_NAME,
        lambda: PhysxVlmGenerator(resolve_model_dir(models_dir)),
        priority=100,
        available=lambda: model_dir_problem(resolve_model_dir(models_dir)),
        description="PhysX-Anything / PhysX-Omni vision-language model (Qwen2.5-VL) via transformers",
    )
