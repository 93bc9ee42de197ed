"""perceive() on procedural rooms with exact ground truth (scene_builder.bench.procedural: MuJoCo
renders with Kinect-like depth noise): camera frame and instance masks against the truth."""

from __future__ import annotations

import numpy as np
import pytest

from perception import perceive
from scene_builder.config import InputSpec, PerceptionConfig

pytestmark = pytest.mark.slow

# Default naming (EfficientNet-Lite0 x size prior where its package is installed).
CFG = PerceptionConfig(segmentation_backend="depth-clusters")
SEEDS = (0, 2, 8)


@pytest.fixture(scope="module")
def rooms(tmp_path_factory):
    from scene_builder.bench.procedural import make_room
    from scene_builder.bench.render import render_room
    from scene_builder.bench.truth import load_truth

    out = []
    for seed in SEEDS:
        d = render_room(make_room(seed, n_objects=6, noise=True), tmp_path_factory.mktemp(f"room{seed}"))
        out.append((perceive(InputSpec(d / "rgb.png", d / "depth.png"), CFG, seed=0), load_truth(d)))
    return out


def test_camera_frame_matches_the_truth(rooms):
    for p, truth in rooms:
        up_true = truth.world_from_camera[2, :3]  # world Z in camera coordinates
        up_found = p.camera.world_from_camera[2, :3]
        assert np.degrees(np.arccos(np.clip(up_true @ up_found, -1, 1))) < 0.5
        assert p.camera.position_m[2] == pytest.approx(truth.world_from_camera[2, 3], abs=0.01)


def test_instances_match_the_truth(rooms):
    matched = total = 0
    for p, truth in rooms:
        for k in np.unique(truth.instances):
            gt = truth.instances == k
            if k == 0 or gt.sum() < 300:
                continue
            total += 1
            best = max((float((gt & o.mask).sum() / (gt | o.mask).sum()) for o in p.objects), default=0.0)
            matched += best >= 0.5
    # Measured: 16 of 17 visible objects (the miss: a 2 cm laptop lying on a cabinet).
    assert total >= 15 and matched / total >= 0.75


def test_matched_objects_are_named_by_category(rooms):
    from scene_builder.bench.perception import score_room

    scores = [score_room(p, truth) for p, truth in rooms]
    matched = sum(s.matched for s in scores)
    named = sum(s.named for s in scores)
    print([s.labels for s in scores])
    # Measured: 12 of 16 with EfficientNet-Lite0 x size prior; size alone names ~65% of 65 objects
    # of 16 rooms and chance over the 9 categories here is ~11%.
    assert matched >= 14 and named / matched >= 0.6
