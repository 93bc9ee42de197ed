"""The PhysX-Anything / PhysX-Omni representation: geometry token encodings (``tokens``), the
overall-description text protocol (``protocol``), conversion to asset-frame parts (``convert``)
and the vision-language model backend (``vlm``). Importing this package is cheap: heavy
libraries are imported inside the functions that use them."""

from __future__ import annotations

from pathlib import Path

__all__ = ["BACKEND_NAME", "PhysxVlmGenerator", "register_backends"]

BACKEND_NAME = "physx-anything-vlm"


class PhysxVlmGenerator:
    """Generates one object from its image crop with the PhysX model found in ``model_dir``.

    The model is loaded on first use."""

    def __init__(self, model_dir: Path) -> None:
        self.model_dir = model_dir
        self._chat = None

    def generate_object(self, image_rgb, name: str, label: str, config=None, seed: int = 0):
        """(ObjectAsset, warnings): run the conversation on ``image_rgb`` ((H, W, 3) uint8 crop of
        the object), parse, decode and assemble. Raises ProtocolError when the answer is unusable."""
        from generation.physx.convert import to_object_asset
        from generation.physx.vlm import PhysxPrompts, TransformersQwenVL, physx_from_conversation, run_conversation

        if self._chat is None:
            self._chat = TransformersQwenVL.from_pretrained(self.model_dir)
        conv = run_conversation(self._chat, image_rgb, PhysxPrompts.from_dir(self.model_dir))
        obj, report = physx_from_conversation(conv)
        return to_object_asset(obj, name, label, config=config, seed=seed, backend=BACKEND_NAME), report.warnings


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
