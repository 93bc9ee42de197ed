"""The PhysX-Anything / PhysX-Omni vision-language model (a fine-tuned Qwen2.5-VL) as a backend.

Conversation protocol (README of ``shared/data/physx_protocol``): one chat per object.

1. user: image + overall prompt -> assistant: the overall description.
2. for each part ``l_k`` (k = 0, 1, ... while the substring ``l_k`` occurs in the description): a
   new request whose history is [user: image + overall prompt, assistant: description,
   user: geometry question for ``l_k``] -> the part's voxel tokens. Other parts' geometry is not
   kept in the history.

Greedy decoding, at most ``max_total_tokens`` (32768 upstream) for prompt plus answer, special
tokens stripped. The prompts are the models' own (S-Lab licensed, not shipped here): they are read
from the model directory (``overall_prompt.txt``, ``geometry_question.txt``), and the grid (32 or
64) is read from the overall prompt's ``grid=N``.

transformers' ``Qwen2_5_VLProcessor`` insists on a video processor, which needs torchvision (it
cannot be installed beside transformers here), so :class:`TransformersQwenVL` does the processor's
two steps itself: the PIL image processor, and expanding ``<|image_pad|>`` to one token per merged
patch.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, Sequence

import numpy as np

from scene_builder.errors import InputError, ModelUnavailableError

from generation.physx.convert import PhysxObject, decode_part_tokens, physx_object
from generation.physx.protocol import ParseReport, parse_description

__all__ = [
    "ChatModel",
    "PhysxConversation",
    "PhysxPrompts",
    "TransformersQwenVL",
    "count_parts",
    "model_dir_problem",
    "physx_from_conversation",
    "resolve_model_dir",
    "run_conversation",
]

IMAGE_PAD = "<|image_pad|>"
MODEL_SUBDIR = "physx-anything"


class ChatModel(Protocol):
    """A chat VLM: one image (with the first user turn) and alternating user / assistant turns.

    image_rgb: (H, W, 3) uint8. turns: ((role, text), ...) with role "user" or "assistant", ending
    with a user turn. Returns the assistant's answer (special tokens stripped)."""

    def generate(self, image_rgb: np.ndarray, turns: Sequence[tuple[str, str]], max_new_tokens: int) -> str: ...


@dataclass(frozen=True)
class PhysxPrompts:
    """The model's prompts. geometry: the question for part ``l_0`` (or with a ``{part}`` field)."""

    overall: str
    geometry: str

    @property
    def grid(self) -> int:
        """Voxels per side, from the overall prompt's ``grid=N`` (32: PhysX-Anything, 64: Omni)."""
        m = re.search(r"grid\s*=\s*(\d+)", self.overall)
        if m is None:
            raise InputError("the overall prompt does not say its voxel grid ('grid=32' or 'grid=64'); use the model's own prompt file")
        return int(m.group(1))

    def geometry_question(self, k: int) -> str:
        if "{part}" in self.geometry:
            return self.geometry.replace("{part}", f"l_{k}")
        return re.sub(r"\bl_0\b", f"l_{k}", self.geometry)

    @classmethod
    def from_dir(cls, directory: Path) -> "PhysxPrompts":
        """Read ``overall_prompt.txt`` and ``geometry_question.txt`` from ``directory``."""
        files = [directory / "overall_prompt.txt", directory / "geometry_question.txt"]
        missing = [f.name for f in files if not f.is_file()]
        if missing:
            raise ModelUnavailableError(f"{directory} lacks {', '.join(missing)}: copy the model's prompts there")
        return cls(files[0].read_text(encoding="utf-8"), files[1].read_text(encoding="utf-8"))


def count_parts(description_text: str, limit: int = 256) -> int:
    """Upstream rule: count k = 0, 1, ... while the substring ``l_k`` occurs in the description."""
    k = 0
    while k < limit and f"l_{k}" in description_text:
        k += 1
    return k


@dataclass(frozen=True)
class PhysxConversation:
    """The model's raw answers: the overall description and one geometry text per part."""

    description_text: str
    part_texts: tuple[str, ...]
    grid: int


def run_conversation(
    chat: ChatModel,
    image_rgb: np.ndarray,
    prompts: PhysxPrompts,
    max_new_tokens: int = 8192,
    max_parts: int = 64,
) -> PhysxConversation:
    """Run the multi-turn protocol: the description, then one fresh request per part."""
    image = np.asarray(image_rgb)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise InputError(f"the PhysX model needs an (H, W, 3) uint8 image, got {image.shape} {image.dtype}")
    first = ("user", prompts.overall)
    description = chat.generate(image, (first,), max_new_tokens)
    n_parts = min(count_parts(description), max_parts)
    parts = tuple(
        chat.generate(image, (first, ("assistant", description), ("user", prompts.geometry_question(k))), max_new_tokens)
        for k in range(n_parts)
    )
    return PhysxConversation(description, parts, prompts.grid)


def physx_from_conversation(conv: PhysxConversation) -> tuple[PhysxObject, ParseReport]:
    """Parse the description and decode every part (tolerantly); all repairs in the report.

    Raises ProtocolError when the description has no part at all or no part has voxels."""
    desc, report = parse_description(conv.description_text, grid=conv.grid)
    warnings = list(report.warnings)
    grids = {}
    for k, text in enumerate(conv.part_texts):
        occ, w = decode_part_tokens(text, conv.grid, strict=False)
        warnings += [f"l_{k} geometry: {x}" for x in w]
        grids[k] = occ
    obj = physx_object(desc, grids)
    return obj, ParseReport(tuple(warnings) + obj.warnings)


class TransformersQwenVL:
    """A Qwen2.5-VL model run with transformers: greedy decoding, one image per conversation.

    model: ``Qwen2_5_VLForConditionalGeneration``; tokenizer: its tokenizer with a chat template;
    image_processor: ``Qwen2VLImageProcessorPil``. image_size_px: the image is resized to a square
    of this side first (512 upstream). max_total_tokens: prompt plus answer."""

    def __init__(self, model, tokenizer, image_processor, image_size_px: int = 512, max_total_tokens: int = 32768, chat_template: str | None = None):
        self.model = model
        self.tokenizer = tokenizer
        self.image_processor = image_processor
        self.image_size_px = image_size_px
        self.max_total_tokens = max_total_tokens
        self.chat_template = chat_template

    @classmethod
    def from_pretrained(cls, model_dir: Path, dtype: str = "auto", device: str = "cpu") -> "TransformersQwenVL":
        """Load weights, tokenizer and image processor from a local directory (no download)."""
        problem = model_dir_problem(model_dir, need_prompts=False)
        if problem is not None:
            raise ModelUnavailableError(problem)
        from transformers import AutoTokenizer, Qwen2_5_VLForConditionalGeneration
        from transformers.models.qwen2_vl.image_processing_pil_qwen2_vl import Qwen2VLImageProcessorPil

        tokenizer = AutoTokenizer.from_pretrained(model_dir, local_files_only=True)
        image_processor = Qwen2VLImageProcessorPil.from_pretrained(model_dir, local_files_only=True)
        model = Qwen2_5_VLForConditionalGeneration.from_pretrained(
            model_dir, local_files_only=True, dtype=dtype, use_safetensors=True
        ).to(device).eval()
        template = tokenizer.chat_template
        tpl_file = model_dir / "chat_template.json"
        if template is None and tpl_file.is_file():
            template = json.loads(tpl_file.read_text())["chat_template"]
        return cls(model, tokenizer, image_processor, chat_template=template)

    def _messages(self, turns: Sequence[tuple[str, str]]) -> list[dict]:
        messages = []
        for i, (role, text) in enumerate(turns):
            if i == 0:
                messages.append({"role": role, "content": [{"type": "image"}, {"type": "text", "text": text}]})
            else:
                messages.append({"role": role, "content": [{"type": "text", "text": text}]})
        return messages

    def generate(self, image_rgb: np.ndarray, turns: Sequence[tuple[str, str]], max_new_tokens: int) -> str:
        import torch
        from PIL import Image

        text = self.tokenizer.apply_chat_template(
            self._messages(turns), tokenize=False, add_generation_prompt=True, chat_template=self.chat_template
        )
        if text.count(IMAGE_PAD) != 1:
            raise InputError(f"the chat template produced {text.count(IMAGE_PAD)} image slots, expected 1")
        pil = Image.fromarray(np.asarray(image_rgb, dtype=np.uint8)).convert("RGB")
        pil = pil.resize((self.image_size_px, self.image_size_px), Image.Resampling.BICUBIC)
        vision = self.image_processor(images=[pil], return_tensors="pt")
        merge = int(getattr(self.image_processor, "merge_size", 2))
        n_image_tokens = int(vision["image_grid_thw"][0].prod()) // (merge * merge)
        text = text.replace(IMAGE_PAD, IMAGE_PAD * n_image_tokens)
        enc = self.tokenizer([text], return_tensors="pt", add_special_tokens=False)
        n_prompt = int(enc["input_ids"].shape[1])
        budget = min(max_new_tokens, self.max_total_tokens - n_prompt)
        if budget <= 0:
            raise InputError(f"the prompt has {n_prompt} tokens, over the {self.max_total_tokens}-token limit")
        with torch.inference_mode():
            out = self.model.generate(
                input_ids=enc["input_ids"],
                attention_mask=enc["attention_mask"],
                pixel_values=vision["pixel_values"],
                image_grid_thw=vision["image_grid_thw"],
                max_new_tokens=budget,
                do_sample=False,
            )
        return self.tokenizer.decode(out[0, n_prompt:], skip_special_tokens=True)


def resolve_model_dir(models_dir: Path | None = None) -> Path:
    """``<models_dir or $SCENE_BUILDER_MODELS>/physx-anything``."""
    root = models_dir if models_dir is not None else os.environ.get("SCENE_BUILDER_MODELS")
    if not root:
        return Path("~/.cache/scene-builder/models").expanduser() / MODEL_SUBDIR
    return Path(root) / MODEL_SUBDIR


def model_dir_problem(model_dir: Path, need_prompts: bool = True) -> str | None:
    """None when ``model_dir`` holds a loadable model (config, weights, tokenizer, image
    processor and, with need_prompts, the two prompt files); else a one-line reason."""
    if not model_dir.is_dir():
        return f"no model directory {model_dir} (put the PhysX-Anything / PhysX-Omni weights there)"
    missing = [f for f in ("config.json", "preprocessor_config.json") if not (model_dir / f).is_file()]
    if not list(model_dir.glob("*.safetensors")):
        missing.append("*.safetensors (only safetensors weights are loaded: pickled .bin files can run code)")
    if not (model_dir / "tokenizer.json").is_file() and not (model_dir / "tokenizer_config.json").is_file():
        missing.append("tokenizer.json")
    if need_prompts:
        missing += [f for f in ("overall_prompt.txt", "geometry_question.txt") if not (model_dir / f).is_file()]
    if missing:
        return f"{model_dir} lacks {', '.join(missing)}"
    return None
