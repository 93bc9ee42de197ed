"""The PhysX-Anything / PhysX-Omni vision-language model (a fine-tuned Qwen2.5-VL) as a backend.

Conversation protocol (README of ``shared/data/physx_protocol``): one chat per object.

1. user: image + overall prompt -> assistant: the overall description.
2. for each part ``l_k`` (k = 0, 1, ... while the substring ``l_k`` occurs in the description): a
   new request whose history is [user: image + overall prompt, assistant: description,
   user: geometry question for ``l_k``] -> the part's voxel tokens. Other parts' geometry is not
   kept in the history.

Greedy decoding, special tokens stripped. Upstream (``1_vlm_demo.py`` of PhysX-Anything and
``1vlm_demo.py`` of PhysX-Omni) caps prompt plus answer at ``max_length=32768`` tokens, which cuts a
long 32^3 part: range tokens are sorted x-major, so a cut-off answer silently loses the far side
of the part. Here the answer alone gets :func:`answer_token_budget` (1024 per voxel of grid side:
32768 for 32^3, 65536 for 64^3; ``GenerationConfig.vlm_max_new_tokens`` overrides it), bounded by
the model's context. An answer that stops at its budget, or whose text ends mid-token, mid-part or
mid-layer (:func:`truncation_problem`), is asked again with twice the budget
(``GenerationConfig.vlm_retries`` times); if it is still cut, :class:`TruncatedAnswerError`, and the
caller falls back to the shape prior for that object.

Images are prepared as upstream's examples: :func:`object_crop` makes a 512 x 512 single-object
image (background masked to black, as ``rembg`` cut-outs of the RGBA demo images become when
converted to RGB, the object centred with its longer side at 0.58 of the image, the median of the
17 demo images of PhysX-Anything), resized with Lanczos, and the Qwen2-VL image processor bounds
the pixels to [65536, 262144] as upstream sets them (a 512 x 512 image becomes 504 x 504, 324
visual tokens).

The prompts are the models' own (S-Lab licensed, not shipped here): they are read from the model
directory (``overall_prompt.txt``, ``geometry_question.txt``), and the grid (32 or 64) is read
from the overall prompt's ``grid=N``.

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

from scene_builder.errors import InputError, ModelUnavailableError, SceneBuilderError

from generation.physx.convert import PhysxObject, decode_part_tokens, physx_object
from generation.physx.description import ParseReport, PhysxDescription, ProtocolError
from generation.physx.protocol import parse_description

__all__ = [
    "UPSTREAM_CROP_FILL",
    "UPSTREAM_IMAGE_PX",
    "UPSTREAM_MAX_PIXELS",
    "UPSTREAM_MIN_PIXELS",
    "ChatAnswer",
    "ChatModel",
    "PhysxConversation",
    "PhysxPrompts",
    "TransformersQwenVL",
    "TruncatedAnswerError",
    "VlmCallError",
    "answer_token_budget",
    "count_parts",
    "decode_conversation",
    "model_dir_problem",
    "object_crop",
    "physx_from_conversation",
    "resolve_model_dir",
    "run_conversation",
    "truncation_problem",
]

IMAGE_PAD = "<|image_pad|>"
MODEL_SUBDIR = "physx-anything"
#: Upstream's image side (``im.resize((512, 512), Image.LANCZOS)`` in both demos).
UPSTREAM_IMAGE_PX = 512
#: Upstream's Qwen2-VL processor pixel bounds (``min_pixels = 65536``, ``max_pixels = 262144``).
UPSTREAM_MIN_PIXELS = 65536
UPSTREAM_MAX_PIXELS = 262144
#: Longer side of the object over the image side: the median over PhysX-Anything's 17 demo images
#: (0.43 to 0.76, measured on their alpha masks).
UPSTREAM_CROP_FILL = 0.58


class TruncatedAnswerError(ProtocolError):
    """The model's answer was cut off (budget reached, or the text ends mid-token / mid-part)
    even after the retries."""


class VlmCallError(SceneBuilderError):
    """The vision-language model itself failed (loading, out of memory, a runtime error)."""


@dataclass(frozen=True)
class ChatAnswer:
    """One answer. text: special tokens stripped. hit_limit: generation stopped because it reached
    its token budget (no end-of-turn token); None when the model cannot tell. budget: the number of
    new tokens it was allowed (after the context bound), None when unknown."""

    text: str
    hit_limit: bool | None = None
    budget: int | None = None


class ChatModel(Protocol):
    """A chat VLM: one image (with the first user turn) and alternating user / assistant turns.

    image_rgb: (H, W, 3) uint8. turns: ((role, text), ...) with role "user" or "assistant", ending
    with a user turn. Returns the assistant's answer: a :class:`ChatAnswer`, or a plain string when
    the model cannot say whether it stopped at its budget. A model that fails raises one of
    :data:`MODEL_RUN_ERRORS` (or a ``SceneBuilderError``)."""

    def generate(self, image_rgb: np.ndarray, turns: Sequence[tuple[str, str]], max_new_tokens: int) -> "ChatAnswer | str": ...


#: What running a torch / transformers model raises when it fails: RuntimeError (CUDA errors,
#: ``torch.OutOfMemoryError`` is one), MemoryError (out of host memory), ValueError (the tokenizer
#: or processor refusing an input). The object then falls back to the shape prior; anything else
#: is a bug and surfaces as itself.
MODEL_RUN_ERRORS: tuple[type[BaseException], ...] = (RuntimeError, MemoryError, ValueError)


def answer_token_budget(grid: int) -> int:
    """New tokens allowed for one answer: 1024 per voxel of grid side (32768 for 32^3, the whole
    upstream limit, above the 8.8k to 15.7k tokens measured for 32^3 furniture parts and the 15.7k
    of a random blob in BENCHMARKS.md; 65536 for 64^3)."""
    if grid < 1:
        raise InputError(f"grid must be positive, got {grid}")
    return 1024 * int(grid)


def object_crop(
    rgb: np.ndarray,
    mask: np.ndarray,
    size_px: int = UPSTREAM_IMAGE_PX,
    fill: float = UPSTREAM_CROP_FILL,
) -> np.ndarray:
    """A single-object image as upstream's examples: (size_px, size_px, 3) uint8, the object's
    pixels (``mask``) on black, the mask's box centred, its longer side ``fill * size_px``
    (Lanczos resampling, the mask's edge anti-aliased).

    rgb: (H, W, 3) uint8; mask: (H, W) bool. Raises InputError for an empty mask."""
    from PIL import Image

    image = np.asarray(rgb)
    m = np.asarray(mask, dtype=bool)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8 or m.shape != image.shape[:2]:
        raise InputError(f"object_crop needs an (H, W, 3) uint8 image and an (H, W) mask, got {image.shape} {image.dtype} and {m.shape}")
    if not 0.0 < fill <= 1.0:
        raise InputError(f"crop fill must be in (0, 1], got {fill}")
    rows, cols = np.nonzero(m)
    if len(rows) == 0:
        raise InputError("object_crop: empty mask, nothing to crop")
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    patch = image[r0:r1, c0:c1].astype(np.float32) * m[r0:r1, c0:c1, None]
    h, w = r1 - r0, c1 - c0
    scale = fill * size_px / max(h, w)
    nh, nw = max(1, int(round(h * scale))), max(1, int(round(w * scale)))
    rgb_small = np.asarray(Image.fromarray(patch.astype(np.uint8)).resize((nw, nh), Image.Resampling.LANCZOS), dtype=np.float32)
    alpha = np.asarray(Image.fromarray(m[r0:r1, c0:c1].astype(np.uint8) * 255).resize((nw, nh), Image.Resampling.BILINEAR), dtype=np.float32) / 255.0
    out = np.zeros((size_px, size_px, 3), dtype=np.float32)
    top, left = (size_px - nh) // 2, (size_px - nw) // 2
    out[top : top + nh, left : left + nw] = rgb_small * (alpha[..., None] > 0.0)
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


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
    """The model's raw answers: the overall description and one geometry text per part.
    notes: what the conversation had to do (retries of truncated answers), one line each."""

    description_text: str
    part_texts: tuple[str, ...]
    grid: int
    notes: tuple[str, ...] = ()


_GROUP_BRACKETS = {"E": 0, "A": 0, "B": 2, "C": 3, "D": 1, "CB": 5}
_RANGE_WORD = re.compile(r"^(\d+)(?:-(\d+))?$")


def _description_truncation(text: str) -> str | None:
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    if not lines:
        return "empty description"
    if not any(re.match(r"group_\d+\s*:", ln, flags=re.IGNORECASE) for ln in lines):
        last = lines[-1]
        if re.match(r"l_\d+\s*:", last) or re.match(r"(name|category|dimensions?|parts|group_info)\s*:", last, flags=re.IGNORECASE):
            return f"ends before the group lines (last line {last[:30]!r})"
        return None  # no group section at all and no sign of a cut: a format problem, not truncation
    last = lines[-1]
    if not re.match(r"group_\d+\s*:", last, flags=re.IGNORECASE):
        return None
    if last.count("[") != last.count("]"):
        return f"the last group line stops inside brackets ({last[-30:]!r})"
    m = re.search(r"Type\s*:\s*([A-Za-z]+)", last)
    if m is None or not re.search(r"Params?\s*:", last):
        return f"the last group line has no Type or Param ({last[-30:]!r})"
    kind = "CB" if m.group(1).upper().startswith("CB") else m.group(1).upper()[:1]
    need = _GROUP_BRACKETS.get(kind)
    if need is None:
        return None
    after = last[last.index(m.group(0)) :]
    have = after.count("]")
    if need == 0:
        return None if re.search(r"Params?\s*:\s*\S", after) else f"the last group line stops after 'Param:' ({last[-30:]!r})"
    if have < need:
        return f"the last group line (type {kind}) has {have} of its {need} bracketed values ({last[-30:]!r})"
    return None


def _ranges_truncation(text: str) -> str | None:
    words = text.split()
    if not words:
        return None
    last = words[-1]
    m = _RANGE_WORD.match(last)
    if m is None:
        return f"the last token {last[:20]!r} is cut (not N or A-B)"
    a = int(m.group(1))
    b = int(m.group(2)) if m.group(2) is not None else a
    if b < a:
        return f"the last run {last!r} ends before it starts (cut mid-number)"
    if len(words) > 1:
        pm = _RANGE_WORD.match(words[-2])
        if pm is not None and a <= int(pm.group(2) or pm.group(1)):
            return f"the last token {last!r} does not follow {words[-2]!r} (cut mid-number)"
    return None


def _rle_truncation(text: str, grid: int) -> str | None:
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    layers = [int(m.group(1)) for ln in lines if (m := re.match(r"^(\d+)\s*[:：]\s*(?:layer|l[ _-])", ln))]
    if lines and lines[-1].count("[") != lines[-1].count("]"):
        return f"the last line stops inside brackets ({lines[-1][-30:]!r})"
    if not layers:
        return "no layer line (cut in the templates)" if lines else None
    if len(set(layers)) < grid and max(layers) < grid - 1:
        return f"layers {max(layers) + 1}..{grid - 1} missing (cut after layer {max(layers)})"
    return None


def truncation_problem(text: str, kind: str, grid: int) -> str | None:
    """Why ``text`` looks cut off, or None. kind: ``"description"`` (the last group line must be
    complete: all bracketed values of its type) or ``"geometry"`` (grid 32: the last range token
    must be whole and follow the previous one; grid 64: every layer line up to ``grid - 1``)."""
    if kind == "description":
        return _description_truncation(text)
    if kind != "geometry":
        raise ValueError(f"kind must be 'description' or 'geometry', got {kind!r}")
    return _ranges_truncation(text) if grid == 32 else _rle_truncation(text, grid)


def _ask(
    chat: ChatModel,
    image: np.ndarray,
    turns: tuple[tuple[str, str], ...],
    what: str,
    kind: str,
    grid: int,
    budget: int,
    retries: int,
    notes: list[str],
) -> str:
    """One answer, asked again with twice the budget while it is truncated."""
    tried: list[int] = []
    while True:
        try:
            raw = chat.generate(image, turns, budget)
        except SceneBuilderError:
            raise
        except MODEL_RUN_ERRORS as err:  # the model's own failure (OOM, CUDA, tokenizer): this object falls back
            raise VlmCallError(f"{what}: the model failed ({type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''})") from err
        answer = raw if isinstance(raw, ChatAnswer) else ChatAnswer(str(raw))
        used = answer.budget if answer.budget is not None else budget
        problem = "stopped at its token budget" if answer.hit_limit else truncation_problem(answer.text, kind, grid)
        if problem is None:
            return answer.text
        tried.append(used)
        if len(tried) > retries or (len(tried) > 1 and used <= tried[-2]):
            raise TruncatedAnswerError(
                f"{what}: answer truncated ({problem}) with budgets {', '.join(map(str, tried))} tokens; "
                "raise GenerationConfig.vlm_max_new_tokens"
            )
        notes.append(f"{what}: answer truncated at {used} tokens ({problem}); asked again with {2 * used}")
        budget = 2 * used


def run_conversation(
    chat: ChatModel,
    image_rgb: np.ndarray,
    prompts: PhysxPrompts,
    max_new_tokens: int | None = None,
    max_parts: int = 64,
    retries: int = 1,
) -> PhysxConversation:
    """Run the multi-turn protocol: the description, then one fresh request per part.

    max_new_tokens: the answer budget (None: :func:`answer_token_budget` of the prompt's grid).
    retries: how many times a truncated answer is asked again with twice the budget. Raises
    TruncatedAnswerError when an answer is still cut, VlmCallError when the model fails."""
    image = np.asarray(image_rgb)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise InputError(f"the PhysX model needs an (H, W, 3) uint8 image, got {image.shape} {image.dtype}")
    grid = prompts.grid
    budget = int(max_new_tokens) if max_new_tokens else answer_token_budget(grid)
    notes: list[str] = []
    first = ("user", prompts.overall)
    description = _ask(chat, image, (first,), "description", "description", grid, budget, retries, notes)
    n_parts = min(count_parts(description), max_parts)
    parts = tuple(
        _ask(chat, image, (first, ("assistant", description), ("user", prompts.geometry_question(k))),
             f"l_{k} geometry", "geometry", grid, budget, retries, notes)
        for k in range(n_parts)
    )
    return PhysxConversation(description, parts, grid, tuple(notes))


def decode_conversation(conv: PhysxConversation) -> tuple[PhysxDescription, dict[int, np.ndarray], tuple[str, ...]]:
    """The parsed description, each part's (G, G, G) grid (decoded tolerantly) and every repair.

    Raises ProtocolError when the description has no part at all."""
    desc, report = parse_description(conv.description_text, grid=conv.grid)
    warnings = list(report.warnings)
    grids = {}
    for k, text in enumerate(conv.part_texts):
        occ, w = decode_part_tokens(text, conv.grid, strict=False)
        warnings += [f"l_{k} geometry: {x}" for x in w]
        grids[k] = occ
    return desc, grids, tuple(warnings)


def physx_from_conversation(conv: PhysxConversation, target_size_m: np.ndarray | None = None) -> tuple[PhysxObject, ParseReport]:
    """Parse the description and decode every part (tolerantly); all repairs in the report.
    target_size_m: (3,) asset-frame extents to scale the parts to (see ``physx_object``).

    Raises ProtocolError when the description has no part at all or no part has voxels."""
    desc, grids, warnings = decode_conversation(conv)
    obj = physx_object(desc, grids, target_size_m=target_size_m)
    return obj, ParseReport(warnings + obj.warnings)


class TransformersQwenVL:
    """A Qwen2.5-VL model run with transformers: greedy decoding, one image per conversation.

    model: ``Qwen2_5_VLForConditionalGeneration``; tokenizer: its tokenizer with a chat template;
    image_processor: ``Qwen2VLImageProcessorPil``. image_size_px: the image is resized to a square
    of this side first (512 upstream, Lanczos). max_total_tokens: prompt plus answer (None: the
    model's context, ``max_position_embeddings``)."""

    def __init__(self, model, tokenizer, image_processor, image_size_px: int = UPSTREAM_IMAGE_PX, max_total_tokens: int | None = None, chat_template: str | None = None):
        self.model = model
        self.tokenizer = tokenizer
        self.image_processor = image_processor
        self.image_size_px = image_size_px
        if max_total_tokens is None:
            cfg = getattr(model.config, "text_config", model.config)
            max_total_tokens = int(getattr(cfg, "max_position_embeddings", 32768))
        self.max_total_tokens = max_total_tokens
        self.chat_template = chat_template

    @classmethod
    def from_pretrained(cls, model_dir: Path, dtype: str = "auto", device: str | None = None) -> "TransformersQwenVL":
        """Load weights, tokenizer and image processor from a local directory (no download); the
        image processor's pixel bounds are upstream's. device: None picks cuda when available."""
        problem = model_dir_problem(model_dir, need_prompts=False)
        if problem is not None:
            raise ModelUnavailableError(problem)
        import torch
        from transformers import AutoTokenizer, Qwen2_5_VLForConditionalGeneration
        from transformers.models.qwen2_vl.image_processing_pil_qwen2_vl import Qwen2VLImageProcessorPil

        device = device or ("cuda" if torch.cuda.is_available() else "cpu")
        tokenizer = AutoTokenizer.from_pretrained(model_dir, local_files_only=True)
        image_processor = Qwen2VLImageProcessorPil.from_pretrained(
            model_dir, local_files_only=True, min_pixels=UPSTREAM_MIN_PIXELS, max_pixels=UPSTREAM_MAX_PIXELS
        )
        model = Qwen2_5_VLForConditionalGeneration.from_pretrained(
            model_dir, local_files_only=True, dtype=dtype, use_safetensors=True
        ).to(device).eval()
        template = tokenizer.chat_template
        tpl_file = model_dir / "chat_template.json"
        if template is None and tpl_file.is_file():
            doc = json.loads(tpl_file.read_text())
            if not (isinstance(doc, dict) and isinstance(doc.get("chat_template"), str)):
                raise ModelUnavailableError(f"{tpl_file} holds no 'chat_template' text; copy the model's own file there")
            template = doc["chat_template"]
        return cls(model, tokenizer, image_processor, chat_template=template)

    def _messages(self, turns: Sequence[tuple[str, str]]) -> list[dict]:
        messages = []
        for i, (role, text) in enumerate(turns):
            if i == 0:
                messages.append({"role": role, "content": [{"type": "image"}, {"type": "text", "text": text}]})
            else:
                messages.append({"role": role, "content": [{"type": "text", "text": text}]})
        return messages

    def generate(self, image_rgb: np.ndarray, turns: Sequence[tuple[str, str]], max_new_tokens: int) -> ChatAnswer:
        """Greedy answer; ``hit_limit`` when it used all of its budget without an end token."""
        import torch
        from PIL import Image

        text = self.tokenizer.apply_chat_template(
            self._messages(turns), tokenize=False, add_generation_prompt=True, chat_template=self.chat_template
        )
        if text.count(IMAGE_PAD) != 1:
            raise InputError(f"the chat template produced {text.count(IMAGE_PAD)} image slots, expected 1")
        pil = Image.fromarray(np.asarray(image_rgb, dtype=np.uint8)).convert("RGB")
        pil = pil.resize((self.image_size_px, self.image_size_px), Image.Resampling.LANCZOS)
        vision = self.image_processor(images=[pil], return_tensors="pt")
        merge = int(getattr(self.image_processor, "merge_size", 2))
        n_image_tokens = int(vision["image_grid_thw"][0].prod()) // (merge * merge)
        text = text.replace(IMAGE_PAD, IMAGE_PAD * n_image_tokens)
        enc = self.tokenizer([text], return_tensors="pt", add_special_tokens=False)
        n_prompt = int(enc["input_ids"].shape[1])
        budget = min(max_new_tokens, self.max_total_tokens - n_prompt)
        if budget <= 0:
            raise InputError(f"the prompt has {n_prompt} tokens, over the {self.max_total_tokens}-token limit")
        device = self.model.device
        with torch.inference_mode():
            out = self.model.generate(
                input_ids=enc["input_ids"].to(device),
                attention_mask=enc["attention_mask"].to(device),
                pixel_values=vision["pixel_values"].to(device),
                image_grid_thw=vision["image_grid_thw"].to(device),
                max_new_tokens=budget,
                do_sample=False,
            )
        new = out[0, n_prompt:]
        eos = self.model.generation_config.eos_token_id
        eos_ids = set(eos if isinstance(eos, (list, tuple)) else [eos]) | {self.tokenizer.eos_token_id}
        ended = len(new) > 0 and int(new[-1]) in eos_ids
        text = self.tokenizer.decode(new, skip_special_tokens=True)
        return ChatAnswer(text, hit_limit=bool(len(new) >= budget and not ended), budget=budget)


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
