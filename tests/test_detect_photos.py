"""Plain photos with the offline detectors: every SUN RGB-D demo photo yields at least three
movable objects named as what is in the photo, and the objects found over all photos of
../shared/data/photos match the hand-made inventory (tests/data/photo_inventory.json) with recall
and precision of at least 0.5."""

from __future__ import annotations

import pytest

from scene_builder.bench.detect import DEFAULT_INVENTORY, canonical, load_inventory, pooled, score_inventory
from scene_builder.config import InputSpec, PerceptionConfig
from scene_builder.vocabulary import category
from tests.conftest import MODELS, PHOTOS, require


def test_inventory_score_counts_categories_and_instances():
    seen = {"chair": 4, "table": 1, "lamp": 1}
    groups = (("table", "desk"),)
    s = score_inventory(["chair", "chair", "desk", "tv", "object"], seen, groups)
    assert (s.matched, s.found, s.seen) == (3, 5, 6)  # two chairs and the desk-as-table
    assert (s.cats_matched, s.cats_found, s.cats_seen) == (2, 4, 3)
    s2 = score_inventory(["chair"] * 6, seen, groups)
    assert (s2.matched, s2.found) == (4, 6)  # extra chairs are wrong
    p = pooled([s, s2])
    assert p["instance_recall"] == pytest.approx(7 / 12) and p["instance_precision"] == pytest.approx(7 / 11)
    assert p["category_recall"] == pytest.approx(3 / 6) and p["category_precision"] == pytest.approx(3 / 5)
    assert canonical("desk", groups) == "table" and canonical("bed", groups) == "bed"


def test_inventory_covers_every_photo_in_vocabulary_labels():
    from scene_builder.vocabulary import LABELS

    seen, groups = load_inventory(DEFAULT_INVENTORY)
    names = {d.name for d in require(PHOTOS).iterdir() if d.is_dir()}
    assert set(seen) == names
    for objects in seen.values():
        assert objects and set(objects) <= set(LABELS) and all(n >= 1 for n in objects.values())
    assert all(set(g) <= set(LABELS) for g in groups)


@pytest.fixture(scope="session")
def perceptions():
    """The perception of every photo of ../shared/data/photos (no depth map), by folder name.
    Session-scoped: a module-scoped one is torn down whenever the worker runs another module's
    test in between, and was computed twice (95 s each) in one CI run."""
    from perception import perceive

    require(MODELS)
    cfg = PerceptionConfig(models_dir=MODELS)
    out = {}
    for d in sorted(require(PHOTOS).iterdir()):
        image = next(p for p in (d / "rgb.jpg", d / "rgb.png") if p.exists())
        p = perceive(InputSpec(image), cfg)
        seg = next(b for b in p.backends if b.task == "segmentation")
        assert seg.backend == "detections"
        assert any(b.task == "detection" and b.backend.startswith("centernet-mbv3-coco") for b in p.backends)
        out[d.name] = p
    return out


@pytest.fixture(scope="session")
def perceived(perceptions):
    """Labels of the objects perceived in every photo of ../shared/data/photos."""
    return {name: [o.label for o in p.objects] for name, p in perceptions.items()}


@pytest.mark.slow
@pytest.mark.xdist_group("photos")  # one worker perceives the photos once for the three
def test_demo_photos_yield_three_movable_objects_named_as_in_the_photo(perceived):
    seen, groups = load_inventory(DEFAULT_INVENTORY)
    for name in sorted(n for n in perceived if n.startswith("sunrgbd_total3d_demo_")):
        there = {canonical(lab, groups) for lab in seen[name]}
        right = [lab for lab in perceived[name] if not category(lab).fixed and canonical(lab, groups) in there]
        assert len(right) >= 3, f"{name}: {perceived[name]}"


@pytest.mark.slow
@pytest.mark.xdist_group("photos")  # one worker perceives the photos once for the three
def test_photos_match_the_inventory(perceived):
    seen, groups = load_inventory(DEFAULT_INVENTORY)
    scores = pooled([score_inventory(perceived[n], seen[n], groups) for n in sorted(perceived)])
    assert scores["category_recall"] >= 0.5 and scores["category_precision"] >= 0.5, scores
    assert scores["instance_recall"] >= 0.5 and scores["instance_precision"] >= 0.5, scores


@pytest.mark.slow
@pytest.mark.xdist_group("photos")  # one worker perceives the photos once for the three
def test_detection_driven_perception_is_deterministic(perceptions):
    """The photo perceived again (in the same process, after 14 others) gives the same objects."""
    import numpy as np

    from perception import perceive

    require(MODELS)
    spec, cfg = InputSpec(require(PHOTOS / "sunrgbd_total3d_demo_3") / "rgb.jpg"), PerceptionConfig(models_dir=MODELS)
    a, b = perceptions["sunrgbd_total3d_demo_3"], perceive(spec, cfg)
    assert [o.name for o in a.objects] == [o.name for o in b.objects] and len(a.objects) >= 3
    for x, y in zip(a.objects, b.objects):
        assert np.array_equal(x.mask, y.mask) and np.array_equal(x.points_world_m, y.points_world_m)
