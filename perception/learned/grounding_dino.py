"""Open-vocabulary object detection with Grounding DINO, prompted with the room vocabulary
(transformers ``GroundingDinoForObjectDetection``; ``IDEA-Research/grounding-dino-tiny``,
Apache-2.0), the detector Grounded-SAM-2 prompts SAM 2 with and PhysX-Omni's scene app runs on its
object list.

**Prompt.** Every label of :mod:`scene_builder.vocabulary` but ``"object"`` (the name of what is
not recognised) becomes one phrase: the label in plain words, or the common English name where the
label is a code (:data:`PROMPT_NAMES`: ``drawer_unit`` is prompted as "chest of drawers"). The
text goes to the model as Grounding DINO's captions do, ``"table . desk . chair ."``: ``[CLS]``,
each phrase's tokens followed by the token of ".", ``[SEP]`` (the model splits phrases at the ids of
``[CLS]``, ``[SEP]``, "." and "?", so that no phrase's tokens attend to another's). The text
encoder takes at most ``config.max_text_len`` tokens (256 for the published checkpoints): the
phrases are packed, in vocabulary order, into as few prompts as fit (:func:`chunk_phrases`), each
prompt is run on the image, and their detections are merged (pooled, then non-maximum
suppression). With the published tokenizer the whole vocabulary fits one prompt (about 110
tokens), so one forward pass; a longer vocabulary, or a checkpoint with a shorter text budget, is
split.

**Scores.** The model gives each of its queries (900 in the published checkpoints) a box and a
sigmoid similarity to every prompt token. A phrase's score is the maximum over its tokens and the
query takes its best phrase: its score is then the query's maximum over all tokens, the box score
that transformers' ``post_process_grounded_object_detection`` and Grounding DINO's own demo
threshold. ``accept_score`` (the score at which one of its detections is trusted alone, which
:func:`perception.detection.merge_detections` maps to :data:`perception.detection.CONFIDENT`) is
0.35: the box threshold of Grounding DINO's README demo (``BOX_TRESHOLD = 0.35``, text threshold
0.25); Grounded-SAM-2's transformers demo uses 0.4. Detections are returned down to ``min_score``
0.14, which the rescaling puts at the ``"detections"`` segmenter's floor
(:data:`perception.segment_detect.FLOOR_SCORE` = 0.2 = 0.14 x 0.5 / 0.35): weaker ones would be
dropped there anyway, and between the floor and ``accept_score`` a box needs a witness (a depth
cluster, the semantic map).

**Preprocessing.** transformers' default ``GroundingDinoImageProcessor`` needs torchvision, which
is not installed on this project's machines (importing it breaks transformers' image processors);
its PIL backend ``GroundingDinoImageProcessorPil`` does the same work and is used as is, from the
checkpoint's ``preprocessor_config.json`` (shortest side 800 px, longest at most 1333, ImageNet
mean and std), with the published values when the file is absent. Boxes come back normalised to
the image and are scaled to its pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from perception.detection import empty_detections, suppress
from perception.protocols import Detections
from scene_builder.errors import InputError, ModelUnavailableError
from scene_builder.vocabulary import LABELS

__all__ = [
    "PROMPT_NAMES",
    "GroundingDinoDetector",
    "Prompt",
    "build_prompts",
    "chunk_phrases",
    "phrase_scores",
    "prompt_phrases",
]

#: Prompt words for the vocabulary labels that are codes rather than what a person calls the
#: thing (the names COCO and LVIS use for these categories); every other label is prompted as
#: itself with "_" read as a space.
PROMPT_NAMES: dict[str, str] = {
    "drawer_unit": "chest of drawers",
    "box_with_lid": "storage box with lid",
    "tv": "television",
    "monitor": "computer monitor",
    "plant": "potted plant",
    "bin": "trash can",
    "soft_toy": "stuffed toy",
    "counter": "kitchen counter",
}

#: The label of things not recognised: never prompted.
_UNKNOWN = "object"


def prompt_phrases(labels: Sequence[str] = LABELS) -> tuple[tuple[str, str], ...]:
    """(phrase, vocabulary label) for every label of ``labels`` but ``"object"``, in order.
    Phrases are lower case without "." or "?" (those split the prompt into phrases)."""
    out = []
    for label in labels:
        if label == _UNKNOWN:
            continue
        phrase = PROMPT_NAMES.get(label, label.replace("_", " ")).strip().lower()
        if not phrase or "." in phrase or "?" in phrase:
            raise InputError(f"prompt phrase '{phrase}' for label '{label}' is empty or contains '.' or '?'")
        out.append((phrase, label))
    return tuple(out)


def chunk_phrases(token_counts: Sequence[int], max_tokens: int) -> list[list[int]]:
    """Phrase indices packed in order into prompts of at most ``max_tokens`` tokens, each prompt
    ``[CLS] p1 . p2 . ... pk . [SEP]``: 2 + sum(n_i + 1) tokens. Greedy in order (the vocabulary's
    order groups related labels; no prompt is split mid-phrase). InputError when one phrase alone
    does not fit."""
    chunks: list[list[int]] = []
    current: list[int] = []
    used = 2
    for i, n in enumerate(token_counts):
        need = int(n) + 1
        if 2 + need > max_tokens:
            raise InputError(f"prompt phrase {i} needs {need} tokens with its '.'; the model takes {max_tokens} in all")
        if current and used + need > max_tokens:
            chunks.append(current)
            current, used = [], 2
        current.append(i)
        used += need
    if current:
        chunks.append(current)
    return chunks


@dataclass(frozen=True)
class Prompt:
    """One text prompt: its token ids (``[CLS]`` ... ``[SEP]``), and for each of its phrases the
    index into the detector's phrase list and the token positions [start, end) it occupies."""

    input_ids: tuple[int, ...]
    phrases: tuple[int, ...]
    spans: tuple[tuple[int, int], ...]


def build_prompts(tokenizer, phrases: Sequence[str], max_tokens: int) -> tuple[Prompt, ...]:
    """The prompts for ``phrases`` under a text budget of ``max_tokens``: each phrase tokenised
    alone (BERT's WordPiece splits at spaces and punctuation, so a phrase's tokens are the same
    alone as inside the caption), joined by the "." token, packed by :func:`chunk_phrases`."""
    dot = tokenizer.convert_tokens_to_ids(".")
    cls, sep = tokenizer.cls_token_id, tokenizer.sep_token_id
    if dot is None or dot == tokenizer.unk_token_id or cls is None or sep is None:
        raise ModelUnavailableError("the Grounding DINO tokenizer lacks [CLS], [SEP] or '.'; is it the checkpoint's BERT tokenizer?")
    ids = [list(tokenizer(p, add_special_tokens=False)["input_ids"]) for p in phrases]
    out = []
    for chunk in chunk_phrases([len(t) for t in ids], max_tokens):
        seq, spans = [int(cls)], []
        for i in chunk:
            spans.append((len(seq), len(seq) + len(ids[i])))
            seq.extend(int(t) for t in ids[i])
            seq.append(int(dot))
        seq.append(int(sep))
        out.append(Prompt(tuple(seq), tuple(chunk), tuple(spans)))
    return tuple(out)


def phrase_scores(token_probs: np.ndarray, spans: Sequence[tuple[int, int]]) -> np.ndarray:
    """(Q, P) score of each of P phrases for each of Q queries: the maximum of the queries' token
    probabilities (Q, T) over the phrase's token positions."""
    token_probs = np.asarray(token_probs, dtype=np.float64)
    if not len(spans):
        return np.zeros((len(token_probs), 0))
    return np.stack([token_probs[:, a:b].max(axis=1) for a, b in spans], axis=1)


def _check_rgb(rgb: np.ndarray) -> np.ndarray:
    arr = np.asarray(rgb)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8:
        raise InputError(f"detector input must be an (H, W, 3) uint8 image, got {arr.shape} {arr.dtype}")
    return np.ascontiguousarray(arr)


class GroundingDinoDetector:
    """Vocabulary detections from a Grounding DINO checkpoint (see the module docstring).

    weights_dir: a folder with ``config.json``, ``model.safetensors``, the tokenizer files
    (``tokenizer.json``, ``tokenizer_config.json``) and optionally ``preprocessor_config.json``, as
    resolved by :func:`perception.models.resolve_weights`. labels: the vocabulary labels to prompt
    (all of them by default). min_score: the weakest detection returned. max_boxes: at most this
    many detections, best first, after non-maximum suppression. device: ``"cpu"``, ``"cuda"``;
    None picks cuda when available.
    """

    accept_score = 0.35

    def __init__(
        self,
        weights_dir: Path | str,
        labels: Sequence[str] = LABELS,
        min_score: float = 0.14,
        max_boxes: int = 100,
        device: str | None = None,
    ) -> None:
        import torch
        from transformers import AutoTokenizer, GroundingDinoForObjectDetection
        from transformers.models.grounding_dino import GroundingDinoImageProcessorPil

        weights_dir = Path(weights_dir)
        if not (weights_dir / "config.json").is_file():
            raise ModelUnavailableError(f"no config.json in {weights_dir}; run: scene-builder models fetch grounding-dino-tiny")
        self.device = device or ("cuda" if torch.cuda.is_available() else "cpu")
        self.model = GroundingDinoForObjectDetection.from_pretrained(weights_dir, use_safetensors=True).to(self.device).eval()
        self.tokenizer = AutoTokenizer.from_pretrained(weights_dir)
        if (weights_dir / "preprocessor_config.json").is_file():
            self.processor = GroundingDinoImageProcessorPil.from_pretrained(weights_dir)
        else:
            self.processor = GroundingDinoImageProcessorPil()  # its defaults are the published preprocessor_config.json
        delimiters = {int(t) for t in self.model.model.special_tokens.tolist()}
        dot = self.tokenizer.convert_tokens_to_ids(".")
        if not {self.tokenizer.cls_token_id, self.tokenizer.sep_token_id, dot} <= delimiters:
            raise ModelUnavailableError(
                f"the tokenizer in {weights_dir} gives [CLS], [SEP], '.' the ids {self.tokenizer.cls_token_id}, "
                f"{self.tokenizer.sep_token_id}, {dot}; the model splits phrases at {sorted(delimiters)}: use the checkpoint's own tokenizer"
            )
        pairs = prompt_phrases(labels)
        self.phrases = tuple(p for p, _ in pairs)
        self.labels = tuple(lab for _, lab in pairs)
        self.max_text_len = int(self.model.config.max_text_len)
        self.prompts = build_prompts(self.tokenizer, self.phrases, self.max_text_len)
        self.min_score = float(min_score)
        self.max_boxes = int(max_boxes)

    def _pixels(self, rgb: np.ndarray):
        enc = self.processor(images=rgb, return_tensors="pt")
        return enc["pixel_values"].to(self.device), enc["pixel_mask"].to(self.device)

    def run_prompt(self, pixels, prompt: Prompt, size_hw: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One prompt on preprocessed ``pixels`` = (pixel_values, pixel_mask): per query its box
        (Q, 4) xyxy in pixels of an image of ``size_hw``, its best phrase's score (Q,) and that
        phrase's index into :attr:`phrases` (Q,)."""
        import torch

        pixel_values, pixel_mask = pixels
        ids = torch.tensor([prompt.input_ids], dtype=torch.long, device=self.device)
        with torch.inference_mode():
            out = self.model(
                pixel_values=pixel_values,
                input_ids=ids,
                token_type_ids=torch.zeros_like(ids),
                attention_mask=torch.ones_like(ids),
                pixel_mask=pixel_mask,
            )
        probs = out.logits[0].float().sigmoid().cpu().numpy()
        cxcywh = out.pred_boxes[0].float().cpu().numpy().astype(np.float64)
        scores = phrase_scores(probs, prompt.spans)
        best = np.argmax(scores, axis=1)
        h, w = size_hw
        cx, cy, bw, bh = cxcywh.T
        boxes = np.stack([(cx - bw / 2) * w, (cy - bh / 2) * h, (cx + bw / 2) * w, (cy + bh / 2) * h], axis=1)
        boxes[:, [0, 2]] = np.clip(boxes[:, [0, 2]], 0, w)
        boxes[:, [1, 3]] = np.clip(boxes[:, [1, 3]], 0, h)
        return boxes, scores[np.arange(len(best)), best], np.asarray(prompt.phrases, dtype=np.int64)[best]

    def detect(self, rgb: np.ndarray) -> Detections:
        """Vocabulary detections of ``rgb`` ((H, W, 3) uint8): every prompt's queries down to
        ``min_score``, pooled, suppressed within label families (and across them for nearly the
        same box, :func:`perception.detection.suppress`), at most ``max_boxes``, best first.
        ``classes`` holds the prompt phrase of each detection, ``labels`` its vocabulary label."""
        rgb = _check_rgb(rgb)
        size_hw = rgb.shape[:2]
        pixels = self._pixels(rgb)
        boxes, scores, phrase_idx = [], [], []
        for prompt in self.prompts:
            b, s, p = self.run_prompt(pixels, prompt, size_hw)
            keep = (s >= self.min_score) & (b[:, 2] > b[:, 0]) & (b[:, 3] > b[:, 1])
            boxes.append(b[keep])
            scores.append(s[keep])
            phrase_idx.append(p[keep])
        idx = np.concatenate(phrase_idx)
        if not len(idx):
            return empty_detections()
        pooled = Detections(
            np.concatenate(boxes),
            np.concatenate(scores).astype(np.float32),
            tuple(self.labels[i] for i in idx),
            tuple(self.phrases[i] for i in idx),
        )
        kept = suppress(pooled)
        if len(kept) <= self.max_boxes:
            return kept
        n = self.max_boxes
        return Detections(kept.boxes_xyxy_px[:n], kept.scores[:n], kept.labels[:n], kept.classes[:n])
