"""Objects a side edge of the photo cut (perception.seen_extent), named over the lengths they may have."""

import numpy as np
import pytest

from perception.seen_extent import cut_by_side_edge


def test_cut_by_one_side_edge_of_the_photo():
    """A dresser at the right edge is cut (its mask reaches the edge on most of its rows, or within
    3 % of the width of it: segmenters stop a few pixels short); a chair standing free is not, nor
    one whose leg alone touches the edge."""
    dresser = np.zeros((100, 200), dtype=bool)
    dresser[30:90, 150:196] = True
    assert cut_by_side_edge(dresser) and cut_by_side_edge(dresser[:, ::-1])
    chair = np.zeros((100, 200), dtype=bool)
    chair[40:80, 130:150] = True
    assert not cut_by_side_edge(chair) and not cut_by_side_edge(np.zeros((100, 200), dtype=bool))
    chair[75:80, 150:200] = True  # a leg reaching the edge on 5 of its 40 rows
    assert not cut_by_side_edge(chair)


def test_a_close_up_filling_the_photos_width_is_not_cut():
    """urdformer_label31: the cabinet's mask spans the whole photo; weighed as longer than seen it
    became a table."""
    whole = np.zeros((50, 80), dtype=bool)
    whole[5:45, :] = True
    assert not cut_by_side_edge(whole)


def test_an_object_a_side_edge_cut_is_named_over_its_possible_lengths():
    """SUN RGB-D 000005's dresser at the photo's right edge: 0.38 x 0.12 x 0.96 m seen, the
    classifier's drawer_unit at 0.5 (a file cabinet). Named from the seen extents it was a chair
    (a 0.4 m wide, 1 m tall thing); up to twice as long, furniture with drawers wins."""
    from perception.learned.naming import combined_label_posterior
    from perception.naming_prior import GeometricPriorNamer, size_hypotheses

    seen = (0.38, 0.12, 0.96)
    lengths = [s[0] for s in size_hypotheses(seen, None, 0.76)]
    assert lengths[0] == pytest.approx(0.38) and lengths[-1] == pytest.approx(0.76) and lengths == sorted(lengths)
    assert len(size_hypotheses(seen, 1.5, 0.76)) == len(lengths) ** 2  # every pair of the two
    lp = {"drawer_unit": 0.496, "monitor": 0.02, "desk": 0.018, "cabinet": 0.009}
    flat = combined_label_posterior(lp, seen)
    cut = combined_label_posterior(lp, seen, None, 0.76)
    assert max(flat, key=flat.get) == "chair"
    storage = ("cabinet", "drawer_unit")
    assert max(cut, key=cut.get) in storage
    assert sum(cut[k] for k in storage) > 1.5 * sum(flat[k] for k in storage)
    assert combined_label_posterior(lp, seen, None, 0.38) == pytest.approx(flat)  # no room to be longer
    crop, mask = np.zeros((4, 4, 3), np.uint8), np.ones((4, 4), bool)
    assert GeometricPriorNamer().name(crop, mask, seen, length_max_m=0.38) == GeometricPriorNamer().name(crop, mask, seen)


def test_a_plug_in_namer_of_the_older_protocol_is_called_without_the_bounds():
    """A namer written before ``height_max_m`` / ``length_max_m`` (name(crop, mask, size)) is
    called without them on a photo where an object is cut, rather than failing; one that takes
    them, or **kwargs, gets them."""
    from perception.protocols import keywords_taken

    class Old:
        def name(self, crop_rgb, crop_mask, size_m):
            return "object", 0.1

    class New:
        def name(self, crop_rgb, crop_mask, size_m, height_max_m=None, length_max_m=None):
            return "object", 0.1

        def label_scores_many(self, crops, masks, sizes, **bounds):
            return [{}]

    bounds = {"height_max_m": 0.98, "length_max_m": 0.76}
    assert keywords_taken(Old().name, **bounds) == {}
    assert keywords_taken(New().name, **bounds) == bounds
    assert keywords_taken(New().label_scores_many, **bounds) == bounds
    crop = np.zeros((4, 4, 3), np.uint8)
    assert Old().name(crop, np.ones((4, 4), bool), (0.4, 0.1, 1.0), **keywords_taken(Old().name, **bounds)) == ("object", 0.1)


def test_the_length_bound_is_twice_the_seen_length_for_furniture_an_edge_cut():
    from perception.seen_extent import length_max_m

    dresser = np.zeros((100, 200), dtype=bool)
    dresser[30:90, 150:200] = True
    assert length_max_m(dresser, (0.38, 0.12, 0.96)) == pytest.approx(0.76)
    assert length_max_m(dresser, (1.6, 0.5, 0.9)) == pytest.approx(2.5)  # capped
    assert length_max_m(dresser, (0.1, 0.05, 0.2)) is None  # a mug: named by what it looks like
    free = np.zeros((100, 200), dtype=bool)
    free[30:90, 80:120] = True
    assert length_max_m(free, (0.38, 0.12, 0.96)) is None  # in full view
