"""Perception registries, the geometric-prior namer, cheap import, and the no-depth path."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from perception.backends import build_registries
from perception.naming_prior import MAX_CONFIDENCE, GeometricPriorNamer
from scene_builder.config import InputSpec, PerceptionConfig
from scene_builder.errors import InputError
from tests.conftest import PHOTOS, REPO


def test_import_is_cheap():
    code = "import sys, perception; print(sorted(m for m in ('open3d', 'torch', 'scipy', 'transformers', 'PIL') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_registries_have_the_geometric_fallbacks():
    reg = build_registries(PerceptionConfig())
    assert "depth-clusters" in reg.segmentation.names()
    assert "geometric-prior" in reg.naming.names()
    seg, use = reg.segmentation.resolve("depth-clusters")
    assert use.backend == "depth-clusters" and hasattr(seg, "segment")
    namer, use = reg.naming.resolve("geometric-prior")
    assert use.backend == "geometric-prior" and isinstance(namer, GeometricPriorNamer)
    with pytest.raises(InputError, match="unknown segmentation backend 'nope'"):
        reg.segmentation.resolve("nope")


@pytest.mark.parametrize(
    "size, label",
    [
        ((1.2, 0.8, 0.75), "table"),
        ((2.0, 1.4, 0.6), "bed"),
        ((0.5, 0.45, 0.9), "chair"),
        ((1.0, 0.6, 2.0), "wardrobe"),
        ((0.07, 0.07, 0.25), "bottle"),
        ((0.55, 0.18, 0.4), "monitor"),
        ((9.0, 7.0, 3.5), "object"),
        # Only the front of SUN RGB-D 000017's night stand is seen (7 cm deep): named by its face.
        ((0.62, 0.07, 0.65), "cabinet"),
    ],
)
def test_geometric_prior_names_typical_sizes(size, label):
    got, conf = GeometricPriorNamer().name(np.zeros((4, 4, 3), np.uint8), np.ones((4, 4), bool), size)
    assert got == label
    assert 0.0 < conf <= MAX_CONFIDENCE


def test_geometric_prior_is_less_sure_of_odd_sizes():
    namer = GeometricPriorNamer()
    crop, mask = np.zeros((4, 4, 3), np.uint8), np.ones((4, 4), bool)
    _, typical = namer.name(crop, mask, (0.5, 0.5, 0.9))
    _, odd = namer.name(crop, mask, (0.7, 0.35, 1.2))
    assert odd < typical


@pytest.mark.slow
def test_photo_without_depth_uses_the_depth_registry():
    photo_dir = PHOTOS / "sunrgbd_total3d_demo_2"
    if not photo_dir.exists():
        pytest.skip(f"shared data not present: {photo_dir}")
    from perception import perceive

    cfg = PerceptionConfig(naming_backend="geometric-prior", segmentation_backend="depth-clusters")
    p = perceive(InputSpec(next(photo_dir.glob("rgb.*"))), cfg)
    depth_uses = [b for b in p.backends if b.task == "depth"]
    assert len(depth_uses) == 1 and depth_uses[0].backend != "sensor"
    assert p.observation.depth_source == depth_uses[0].backend
    assert p.observation.intrinsics.source == "file"  # camera.json beside the photo
    assert [b.task for b in p.backends].count("gravity") == 1
    assert p.objects and all(np.quantile(o.points_world_m[:, 2], 0.05) > -0.03 for o in p.objects)
