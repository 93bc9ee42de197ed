"""The ground-truth bench's pooled figures carry the physics check of every build: the deepest
overlap over the set and the builds whose movable objects did not stay at rest (issue 23: every
interactive object at rest with < 1 mm penetration), and the README block shows them."""

from __future__ import annotations

from scene_builder.bench import readme
from scene_builder.bench.groundtruth import Item, ObjectFates, summarize


def test_summary_pools_penetration_and_rest_over_builds_and_the_readme_shows_them():
    items = [
        Item("real", "a", "built", 10.0, fates=ObjectFates(5, 4, 0, 1), max_penetration_m=0.0004, stable=True),
        Item("real", "b", "built", 12.0, fates=ObjectFates(3, 3, 0, 0), max_penetration_m=0.1035, stable=False),
        Item("real", "c", "refused", 0.1, "bad depth"),
    ]
    s = summarize(items)["real"]
    assert s["max_penetration_mm"] == 103.5
    assert s["builds_not_at_rest"] == 1
    assert (s["built"], s["refused"], s["perceived_objects"], s["interactive_objects"]) == (2, 1, 8, 7)
    block = readme.BLOCKS["objects"][1]({"summary": {"real": s}, "meta": {}})
    assert "max penetration mm (every build) | builds not at rest |" in block
    assert "| 103.50 | 1 |" in block
