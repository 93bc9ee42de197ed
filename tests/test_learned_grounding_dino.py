"""Grounding DINO prompted with the room vocabulary: the prompts (phrases, chunks under the text
budget, token spans), the phrase scores on hand-made token probabilities, and the detector
through its exact loading path with a tiny randomly initialised GroundingDinoForObjectDetection
and a tiny BERT tokenizer made from a local vocab file (no hub), on a real photo, alone and as the
first detector of the "detections" segmenter, whose boxes prompt SAM 2 (random weights too)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from perception.detection import CONFIDENT, box_iou, family, merge_detections
from perception.learned.grounding_dino import (
    PROMPT_NAMES,
    GroundingDinoDetector,
    build_prompts,
    chunk_phrases,
    phrase_scores,
    prompt_phrases,
)
from scene_builder.config import PerceptionConfig
from scene_builder.errors import InputError
from scene_builder.vocabulary import LABELS
from tests.conftest import MODELS, SHARED, require

GD = "grounding-dino-tiny"
PHOTOS_GT = SHARED / "data" / "photos_gt"
#: A kitchen and a living room of COCO (chairs, a table, a tv, plants, a refrigerator).
PHOTO = PHOTOS_GT / "coco128_000000000089"


def _bert_vocab(words: list[str]) -> list[str]:
    """A WordPiece vocabulary with bert-base-uncased's ids for [PAD] 0, [UNK] 100, [CLS] 101,
    [SEP] 102, [MASK] 103, "." 1012 and "?" 1029 (the ids Grounding DINO splits phrases at), then
    ``words``."""
    vocab = ["[PAD]"] + [f"[unused{i}]" for i in range(99)] + ["[UNK]", "[CLS]", "[SEP]", "[MASK]"]
    vocab += [f"[unused{i}]" for i in range(99, 99 + 1012 - len(vocab))] + ["."]
    vocab += [f"[unused{i}]" for i in range(1000, 1000 + 1029 - len(vocab))] + ["?"]
    return vocab + words


def save_tiny_grounding_dino(folder: Path, max_text_len: int = 32, num_queries: int = 20) -> Path:
    """A randomly initialised tiny GroundingDinoForObjectDetection with its tokenizer (BERT, from
    a local vocab of the prompt words) and a small preprocessor config, saved as a transformers
    folder; returns the folder."""
    import torch
    from transformers import BertConfig, BertTokenizer, GroundingDinoConfig, GroundingDinoForObjectDetection, SwinConfig
    from transformers.models.grounding_dino import GroundingDinoImageProcessorPil

    folder.mkdir(parents=True, exist_ok=True)
    words = sorted({w for p, _ in prompt_phrases() for w in p.split()})
    vocab = _bert_vocab(words)
    vocab_file = folder.parent / f"{folder.name}_vocab.txt"
    vocab_file.write_text("\n".join(vocab) + "\n")
    BertTokenizer(vocab=str(vocab_file)).save_pretrained(folder)
    backbone = SwinConfig(image_size=224, patch_size=4, embed_dim=8, depths=[1, 1, 1, 1], num_heads=[1, 1, 1, 1], window_size=7,
                          out_indices=[2, 3, 4], out_features=["stage2", "stage3", "stage4"])
    text = BertConfig(vocab_size=len(vocab), hidden_size=16, num_hidden_layers=1, num_attention_heads=2, intermediate_size=32,
                      max_position_embeddings=64)
    config = GroundingDinoConfig(
        backbone_config=backbone, text_config=text, d_model=32, encoder_layers=1, decoder_layers=2, encoder_ffn_dim=32,
        decoder_ffn_dim=32, encoder_attention_heads=2, decoder_attention_heads=2, num_queries=num_queries,
        max_text_len=max_text_len, encoder_n_points=2, decoder_n_points=2,
    )
    torch.manual_seed(0)
    GroundingDinoForObjectDetection(config).save_pretrained(folder)
    GroundingDinoImageProcessorPil(size={"shortest_edge": 160, "longest_edge": 256}).save_pretrained(folder)
    return folder


@pytest.fixture(scope="module")
def tiny_gd(tmp_path_factory) -> Path:
    return save_tiny_grounding_dino(tmp_path_factory.mktemp("gd") / GD)


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(require(PHOTO) / "rgb.jpg").convert("RGB"))


def test_every_vocabulary_label_but_object_is_one_phrase():
    pairs = prompt_phrases()
    assert [lab for _, lab in pairs] == [lab for lab in LABELS if lab != "object"]
    phrases = [p for p, _ in pairs]
    assert len(set(phrases)) == len(phrases)
    assert all(p == p.lower().strip() and "." not in p and "?" not in p and "_" not in p for p in phrases)
    assert dict(pairs)["chest of drawers"] == "drawer_unit" and dict(pairs)["television"] == "tv"
    assert set(PROMPT_NAMES) <= set(LABELS)
    with pytest.raises(InputError, match="contains"):
        prompt_phrases(("table", "bad.label"))


def test_chunks_pack_phrases_in_order_within_the_budget():
    # [CLS] + (n + 1 for each phrase and its ".") + [SEP] <= budget
    assert chunk_phrases([3, 1, 2, 5], 8) == [[0, 1], [2], [3]]
    assert chunk_phrases([3, 1, 2, 5], 100) == [[0, 1, 2, 3]]
    assert chunk_phrases([1] * 6, 6) == [[0, 1], [2, 3], [4, 5]]
    assert chunk_phrases([], 10) == []
    with pytest.raises(InputError, match="needs 6 tokens"):
        chunk_phrases([1, 5], 7)


def test_phrase_scores_are_the_max_over_each_phrases_tokens():
    probs = np.array([[0.0, 0.9, 0.1, 0.0, 0.2, 0.3, 0.0], [0.0, 0.1, 0.2, 0.0, 0.8, 0.05, 0.0]])
    np.testing.assert_allclose(phrase_scores(probs, [(1, 3), (4, 6)]), [[0.9, 0.3], [0.2, 0.8]])
    assert phrase_scores(probs, []).shape == (2, 0)


def test_prompts_cover_the_vocabulary_in_chunks_under_the_text_budget(tiny_gd):
    from transformers import AutoTokenizer

    tok = AutoTokenizer.from_pretrained(tiny_gd)
    phrases = [p for p, _ in prompt_phrases()]
    dot = tok.convert_tokens_to_ids(".")
    for budget, n_chunks in ((32, None), (256, 1)):
        prompts = build_prompts(tok, phrases, budget)
        assert n_chunks is None or len(prompts) == n_chunks
        assert [i for p in prompts for i in p.phrases] == list(range(len(phrases)))  # every phrase once, in order
        for p in prompts:
            assert len(p.input_ids) <= budget
            assert p.input_ids[0] == tok.cls_token_id and p.input_ids[-1] == tok.sep_token_id
            for i, (a, b) in zip(p.phrases, p.spans):
                assert tok.decode(p.input_ids[a:b]) == phrases[i]
                assert p.input_ids[b] == dot
            # the prompt is the caption Grounding DINO is given, tokenised as a whole
            caption = " . ".join(phrases[i] for i in p.phrases) + " ."
            assert tuple(tok(caption)["input_ids"]) == p.input_ids
    assert len(build_prompts(tok, phrases, 32)) >= 3


def test_detector_finds_vocabulary_boxes_in_a_real_photo(tiny_gd, photo):
    det = GroundingDinoDetector(tiny_gd, device="cpu")
    assert det.max_text_len == 32 and len(det.prompts) >= 3
    assert sorted(i for p in det.prompts for i in p.phrases) == list(range(len(det.phrases)))
    d = det.detect(photo)
    h, w = photo.shape[:2]
    assert len(d) > 0
    b = d.boxes_xyxy_px
    assert np.all(b[:, 0] >= 0) and np.all(b[:, 2] <= w) and np.all(b[:, 1] >= 0) and np.all(b[:, 3] <= h)
    assert np.all(b[:, 2] > b[:, 0]) and np.all(b[:, 3] > b[:, 1])
    assert set(d.labels) <= set(LABELS) - {"object"}
    phrase_of = {lab: p for p, lab in prompt_phrases()}
    assert all(phrase_of[lab] == cls for lab, cls in zip(d.labels, d.classes))
    assert np.all(d.scores >= det.min_score) and np.all(d.scores <= 1.0)
    assert np.all(np.diff(d.scores) <= 0)  # best first
    # non-maximum suppression: no two boxes of one family overlap by IoU 0.5
    iou = box_iou(b, b)
    for i in range(len(d)):
        for j in range(i + 1, len(d)):
            assert not (d.labels[j] in family(d.labels[i]) and iou[i, j] >= 0.5), (i, j, iou[i, j])
    # the prompts' queries before suppression: more than survive it, from more than one prompt
    pixels = det._pixels(photo)
    raw = [det.run_prompt(pixels, p, (h, w)) for p in det.prompts]
    above = [int((s >= det.min_score).sum()) for _, s, _ in raw]
    assert sum(above) > len(d) and sum(n > 0 for n in above) >= 2
    # deterministic, and on the merge scale of the other detectors: accept_score -> CONFIDENT
    again = det.detect(photo)
    np.testing.assert_array_equal(again.boxes_xyxy_px, b)
    assert again.labels == d.labels
    merged = merge_detections([(d, det.accept_score)])
    top = int(np.argmax(d.scores))
    assert merged.scores[0] == pytest.approx(min(1.0, CONFIDENT * float(d.scores[top]) / det.accept_score), rel=1e-5)
    with pytest.raises(InputError):
        det.detect(photo[..., 0])


def test_a_tokenizer_whose_ids_are_not_the_models_delimiters_is_refused(tiny_gd, tmp_path):
    from transformers import BertTokenizer

    from scene_builder.errors import ModelUnavailableError

    bad = tmp_path / "bad"
    shutil.copytree(tiny_gd, bad)
    for f in ("tokenizer.json", "tokenizer_config.json"):
        (bad / f).unlink()
    vocab = tmp_path / "small_vocab.txt"
    vocab.write_text("\n".join(["[PAD]", "[UNK]", "[CLS]", "[SEP]", "[MASK]", ".", "table"]) + "\n")
    BertTokenizer(vocab=str(vocab)).save_pretrained(bad)
    with pytest.raises(ModelUnavailableError, match="own tokenizer"):
        GroundingDinoDetector(bad, device="cpu")


def _models_dir(tmp_path: Path, tiny_gd: Path | None, tiny_sam: Path | None = None) -> Path:
    """A models dir with the shared offline detector files (links) and the given tiny models."""
    root = tmp_path / "models"
    root.mkdir(parents=True)
    for f in sorted(require(MODELS).iterdir()):
        if f.is_file() and f.suffix != ".md":
            (root / f.name).symlink_to(f)
    if tiny_gd is not None:
        shutil.copytree(tiny_gd, root / GD)
    if tiny_sam is not None:
        shutil.copytree(tiny_sam, root / "sam2-hiera-tiny")
    return root


def test_registered_first_among_the_detectors_only_when_its_weights_are_here(tiny_gd, tmp_path, monkeypatch):
    from perception import models
    from perception.backends import build_registries

    reg = build_registries(PerceptionConfig(models_dir=tmp_path / "nothing"))
    entry = next(e for e in reg.detection.entries() if e.name == GD)
    why = entry.available()
    assert why is not None and f"scene-builder models fetch {GD}" in why and "\n" not in why
    assert entry.priority > max(e.priority for e in reg.detection.entries() if e.name != GD)

    # Beside the bundled offline detectors it runs first.
    alone = tmp_path / "alone"
    shutil.copytree(tiny_gd, alone / GD)
    seg, use = build_registries(PerceptionConfig(models_dir=alone)).segmentation.resolve()
    assert use.backend == "detections" and [d.name for d in seg.detectors] == [GD, "centernet-mbv3-coco", "ssd-mobilenet-oid"]
    # Grounding DINO alone (an install without the bundled files) is enough for the detection-driven segmenter.
    monkeypatch.setattr(models, "BUNDLED_DIR", tmp_path / "no-bundled-files")
    seg, use = build_registries(PerceptionConfig(models_dir=alone)).segmentation.resolve()
    assert use.backend == "detections" and [d.name for d in seg.detectors] == [GD]
    monkeypatch.undo()

    root = _models_dir(tmp_path, tiny_gd)
    seg, use = build_registries(PerceptionConfig(models_dir=root)).segmentation.resolve()
    assert use.backend == "detections"
    assert [d.name for d in seg.detectors] == [GD, "centernet-mbv3-coco", "ssd-mobilenet-oid"]
    assert isinstance(seg.detectors[0].backend, GroundingDinoDetector)


def _perceive(photo_dir: Path, models_dir: Path):
    from perception import perceive
    from scene_builder.config import InputSpec

    return perceive(InputSpec(photo_dir / "rgb.jpg"), PerceptionConfig(models_dir=models_dir))


@pytest.mark.slow
def test_detections_segmenter_runs_grounding_dino_with_sam2_and_falls_back_without_it(tiny_gd, tiny_sam, tmp_path):
    """What a networked user runs (Grounding DINO's boxes prompting SAM 2, beside the offline
    detectors), then the same photo with the Grounding DINO weights absent."""
    from scene_builder.vocabulary import LABELS as VOCAB

    photo_dir = require(PHOTO)
    with_gd = _perceive(photo_dir, _models_dir(tmp_path / "a", tiny_gd, tiny_sam))
    uses = {b.task: b for b in with_gd.backends}
    assert uses["segmentation"].backend == "detections"
    assert uses["detection"].backend == f"{GD}+centernet-mbv3-coco+ssd-mobilenet-oid"
    assert f"{GD} " in uses["detection"].reason
    assert uses["box-segmentation"].backend == "sam2"
    assert with_gd.objects and all(o.label in VOCAB for o in with_gd.objects)

    without = _perceive(photo_dir, _models_dir(tmp_path / "b", None, tiny_sam))
    uses = {b.task: b for b in without.backends}
    assert uses["segmentation"].backend == "detections"
    assert uses["detection"].backend == "centernet-mbv3-coco+ssd-mobilenet-oid" and GD not in uses["detection"].reason
    assert without.objects


@pytest.fixture(scope="module")
def tiny_sam(tmp_path_factory) -> Path:
    from tests.test_learned_sam2 import save_tiny_sam2

    return save_tiny_sam2(tmp_path_factory.mktemp("sam") / "sam2")

