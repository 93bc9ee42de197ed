"""The sweep of ``scene_builder.bench.sweep``: its perturbed copies carry depth and intrinsics that
still fit the photo, its outcome classes are what the CLI's exit statuses say, it covers every
shared image with >= 200 copies, and a small deterministic sample of it builds without a traceback
(the whole sweep is a bench command: BENCHMARKS.md)."""

from __future__ import annotations

import numpy as np
import pytest

from scene_builder.bench import sweep
from tests.conftest import SHARED, require

K = {"fx": 100.0, "fy": 110.0, "cx": 37.3, "cy": 24.6}
GEOMETRIC = ["crop-centre-60", "crop-top-left-50", "crop-bottom-right-40", "crop-strip-15", "rotate-90", "rotate-180",
             "rotate-270", "mirror", "downscale-50", "downscale-160px", "downscale-64px"]


@pytest.mark.parametrize("name", GEOMETRIC)
def test_geometric_perturbations_move_depth_and_intrinsics_with_the_photo(name):
    """Every pixel carries its own id as depth: wherever it lands, its viewing ray under the new
    intrinsics keeps its angle to the optical axis (crops, quarter turns, a mirror and downscales
    keep it; nearest-neighbour downscaling picks a source pixel within half a pixel)."""
    h, w = 60, 80
    rgb = np.zeros((h, w, 3), np.uint8)
    depth = (1 + np.arange(h * w)).reshape(h, w).astype(np.uint16)
    transform, _ = sweep.PERTURBATIONS[name]
    rgb2, depth2, k2 = transform(rgb, depth, dict(K))
    assert rgb2.shape[:2] == depth2.shape and depth2.size > 0
    v2, u2 = np.indices(depth2.shape)
    ids = depth2.astype(np.int64) - 1
    v, u = ids // w, ids % w
    before = np.hypot((u - K["cx"]) / K["fx"], (v - K["cy"]) / K["fy"])
    after = np.hypot((u2 - k2["cx"]) / k2["fx"], (v2 - k2["cy"]) / k2["fy"])
    tolerance = 1.0 / min(K["fx"], K["fy"]) if name.startswith("downscale") else 1e-9
    assert np.max(np.abs(after - before)) <= tolerance


def test_photometric_perturbations_keep_depth_and_intrinsics():
    rgb = np.random.default_rng(0).integers(0, 256, (30, 40, 3)).astype(np.uint8)
    depth = np.arange(1200, dtype=np.uint16).reshape(30, 40)
    for name in ("dark", "very-dark", "overexposed", "low-contrast", "noise-25", "blur-4", "jpeg-10", "grey"):
        transform, _ = sweep.PERTURBATIONS[name]
        rgb2, depth2, k2 = transform(rgb, depth, dict(K))
        assert rgb2.shape == rgb.shape and rgb2.dtype == np.uint8
        assert np.array_equal(depth2, depth) and k2 == K
    assert sweep.PERTURBATIONS["very-dark"][0](rgb, None, None)[0].max() <= 8


def test_outcomes_follow_the_exit_status_and_the_one_error_line():
    tb = "warning: x\nTraceback (most recent call last):\n  File \"a.py\", line 1\nValueError: boom\n"
    assert sweep._classify(1, tb) == ("traceback", tb[tb.index("Traceback"):].strip())
    assert sweep._classify(0, "warning: intrinsics assumed\n") == ("scene", "")
    assert sweep._classify(3, "warning: w\nerror: depth map is 8-bit; pass --depth-scale\n") == ("refusal", "depth map is 8-bit; pass --depth-scale")
    assert sweep._classify(-9, "")[0] == "traceback"  # killed (out of memory, a segfault)
    assert sweep._classify(1, "something else\n")[0] == "traceback"  # no documented error line


def test_the_sweep_covers_every_shared_image_and_200_perturbed_copies():
    data = require(SHARED / "data")
    srcs = sweep.sources(data)
    folders = {f"{d.parent.name}/{d.name}" for d in data.glob("*/*") if (d / "rgb.jpg").is_file() or (d / "rgb.png").is_file()}
    assert {s.name for s in srcs} == folders and len(folders) >= 30
    items = sweep.items(srcs, per_image=6)
    as_is = [i for i in items if i.perturbation == "none"]
    assert {i.source.name for i in as_is if not i.with_depth} == folders
    assert {i.source.name for i in as_is if i.with_depth} == {s.name for s in srcs if s.depth is not None}
    copies = [i for i in items if i.perturbation != "none"]
    assert len(copies) >= 200 and set(i.perturbation for i in copies) == set(sweep.PERTURBATIONS)
    assert sum(i.with_depth for i in copies) >= 40 and sum(i.full_exports for i in items) >= 40
    assert len({i.name for i in items}) == len(items)


SAMPLE = ["photos/urdformer_label3+downscale-64px", "real/nyuv2_metric3d_00050+rotate-90+depth",
          "photos_gt/coco128_000000000241+jpeg-10", "multiview/slambook_ch5_diningroom_frame3+very-dark+depth"]


@pytest.mark.slow
@pytest.mark.parametrize("name", SAMPLE)
def test_a_sample_of_the_sweep_builds_without_a_traceback(tmp_path, name):
    """Four perturbed copies (thumbnail, rotated RGB-D, JPEG 10, very dark RGB-D) at 160 px wide,
    each through its own `scene-builder build` process: a scene or a one-line refusal."""
    data = require(SHARED / "data")
    source, perturbation, *depth = name.split("+")
    (src,) = [s for s in sweep.sources(data) if s.name == source]
    item = sweep.Item(name, src, perturbation, bool(depth), full_exports=name == SAMPLE[1])
    record = sweep.run_item(item, tmp_path, max_width=160, timeout_s=600)
    assert record["outcome"] in ("scene", "refusal"), record["traceback"]
    if record["outcome"] == "refusal":
        assert record["message"] and "\n" not in record["message"]
