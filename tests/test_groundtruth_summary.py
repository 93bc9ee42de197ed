"""The ground-truth bench's pooled figures carry the physics check of every build: the deepest
overlap over the set and the builds whose movable objects did not stay at rest (issue 23: every
interactive object at rest with < 1 mm penetration), and the README block shows them."""

from __future__ import annotations

from scene_builder.bench import readme
from scene_builder.bench.groundtruth import Item, ObjectFates, summarize


def test_summary_pools_penetration_and_rest_over_builds_and_the_readme_shows_them():
    items = [
        Item("real", "a", "built", 10.0, fates=ObjectFates(5, 4, 0, 1, (), 2, 3), max_penetration_m=0.0004, stable=True),
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
    # Instances left out behind walls are no perceived object, but they are counted and shown.
    assert s["left_out_behind_walls"] == 2
    # ... and so are those left out for too little measured depth on them.
    assert s["left_out_unmeasured"] == 3
    assert "left out with too little depth (not perceived) |" in block
    assert block.splitlines()[-1].endswith("| 103.50 | 1 | 2 | 3 |")


def test_mask_precision_leaves_out_what_the_annotation_is_too_small_to_judge():
    """As COCO's own evaluation does with its area ranges: an object matching no scored instance
    is left out of the precision when it is under the smallest scored size or matches an
    annotated instance that small; a large object matching nothing is a false positive."""
    import numpy as np

    from scene_builder.bench.groundtruth import score_masks

    h, w = 100, 100

    def box(x0, y0, x1, y1):
        m = np.zeros((h, w), dtype=bool)
        m[y0:y1, x0:x1] = True
        return m

    true = [("couch", box(0, 0, 40, 40))]
    small = [box(90, 90, 94, 94)]  # a 16 px mug: 0.16 % of the photo, under MIN_INSTANCE_SHARE
    pred = {
        "sofa_1": ("sofa", box(0, 0, 40, 38)),  # the couch
        "mug_1": ("mug", box(90, 90, 95, 95)),  # 25 px, over the size, but the small mug: not judged
        "speck_1": ("box", box(60, 10, 63, 13)),  # 9 px matching nothing: not judged
        "table_1": ("table", box(50, 50, 80, 80)),  # large, matching nothing: a false positive
    }
    s = score_masks(pred, true, small)
    assert (s.matched, s.matched_loose, s.n_pred, s.n_ignored) == (1, 1, 2, 2)
    # Without the small annotation the mug is judged (and matches nothing).
    assert score_masks(pred, true).n_pred == 3
    # A large unmatched object stays counted however many small annotations there are.
    assert score_masks({"table_1": pred["table_1"]}, true, small).n_pred == 1


def test_mask_scores_leave_out_the_pixels_of_the_people_the_twin_removed():
    """A person sits on a sofa: the photo's annotation holds the sofa's visible pixels, the twin
    (people removed) the whole sofa. Scored on the pixels no person covers, the sofa matches;
    with the person's pixels scored it does not (IoU 0.4)."""
    import numpy as np

    from scene_builder.bench.groundtruth import score_masks

    sofa = np.zeros((100, 100), dtype=bool)
    sofa[40:80, 0:100] = True
    person = np.zeros_like(sofa)
    person[20:80, 20:80] = True
    visible = sofa & ~person
    pred = {"sofa_1": ("sofa", sofa)}
    assert score_masks(pred, [("couch", visible)]).matched == 0
    s = score_masks(pred, [("couch", visible)], removed=person)
    assert (s.matched, s.matched_large, s.n_pred) == (1, 1, 1)


def test_the_builds_fates_line_says_how_many_instances_were_left_out_behind_walls():
    """The CLI's one-line summary of report.json's object fates names the instances perception
    left out behind walls (the next room, or past a wall's end), and says nothing when none were."""
    from scene_builder.report import fates_line

    f = {"perceived": 9, "movable": 5, "fixed_with_joints": 0, "fixed": 0, "background": 4,
         "background_by_reason": {"hangs": 1}, "left_out_behind_walls": 2}
    assert fates_line(f) == "9 perceived: 5 movable, 0 fixed with joints, 0 fixed, 4 background (hangs 1); 2 left out behind walls"
    assert fates_line({**f, "left_out_behind_walls": 0}).endswith("4 background (hangs 1)")
    assert fates_line({**f, "left_out_unmeasured": 3}).endswith("; 2 left out behind walls; 3 left out with too little depth on them")
