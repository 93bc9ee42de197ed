"""The benchmark's own machinery: physics check, render-and-compare, the naive baseline, the truth
of the SUN RGB-D sample, and (once the pipeline runs) a small synthetic suite."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from scene_builder import bench, frames, metrics, procedural
from scene_builder.config import BuildConfig
from tests.conftest import REAL_DATA, require


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    spec = procedural.make_room(2, n_objects=7)
    return spec, procedural.render_room(spec, tmp_path_factory.mktemp("bench") / "room")


def test_physics_check_finds_ground_truth_at_rest_and_flags_overlaps(tmp_path):
    spec = procedural.make_room(6, n_objects=8)
    path = tmp_path / "gt.xml"
    path.write_text(procedural.build_mjspec(spec).to_xml())
    check = bench.physics_check(path)
    assert check.n_free == len(spec.objects)
    assert check.max_penetration_m < 1e-3
    assert check.n_stable == check.n_free and check.max_drift_m < 0.005

    # A second copy of a solid box, 10 cm beside the first (boxes are >= 25 cm): the check must
    # see the overlap, and the pair pushes apart.
    boxes = procedural.make_room(1, n_objects=2, categories=("box",))
    a = boxes.objects[0]
    twin = procedural.RoomObject(2, "box_twin", "box", (a.position_m[0] + 0.1, a.position_m[1], a.position_m[2]), a.size_m, a.yaw_rad, "floor", a.primitives)
    pushed = procedural.RoomSpec(boxes.seed, boxes.room_size_m, boxes.floor_look, boxes.walls, boxes.camera, (a, twin))
    path2 = tmp_path / "pushed.xml"
    path2.write_text(procedural.build_mjspec(pushed).to_xml())
    bad = bench.physics_check(path2)
    assert bad.max_penetration_m > 0.05
    assert bad.n_stable < bad.n_free


def test_render_of_ground_truth_mjcf_reproduces_instances_and_depth(room, tmp_path):
    spec, sample = room
    path = tmp_path / "gt.xml"
    path.write_text(procedural.build_mjspec(spec).to_xml())
    depth, ids, names = bench.render_ids_and_depth(path, 640, 480)
    truth = procedural.load_truth(sample)
    err = np.abs(depth - truth.depth_m)[truth.depth_m > 0]
    assert np.mean(err < 1.5e-3) > 0.999  # a few silhouette pixels may rasterise differently
    for o in spec.objects:
        true_mask = truth.instances == o.object_id
        if true_mask.sum() > 100:
            assert metrics.mask_iou(ids == names.index(o.name), true_mask) > 0.99


def test_naive_baseline_on_a_room_penetrates_and_drifts(room, tmp_path):
    spec, sample = room
    perception = bench.oracle_perception(sample)
    truth = procedural.load_truth(sample)
    scores = bench.evaluate_baseline(perception, truth, tmp_path, BuildConfig())
    o = scores.objects
    # With true masks every visible object is found, and boxes land near the true centres ...
    assert o.recall == 1.0 and o.precision == 1.0
    assert np.median(o.position_error_m) < 0.15
    # ... but the boxes are camera-aligned, so they sit inside the floor and each other and move.
    assert scores.max_penetration_m > 0.01
    assert scores.n_stable < scores.n_free
    assert 0.0 <= min(scores.mask_iou) and max(scores.mask_iou) <= 1.0
    assert scores.depth_absrel is not None and scores.depth_absrel > 0.0


def test_baseline_world_is_the_camera_with_gravity_along_y(room):
    _, sample = room
    perception = bench.oracle_perception(sample)
    base = bench.naive_baseline(perception)
    r = base.world_from_camera[:3, :3]
    assert np.allclose(r @ [0, 1, 0], [0, 0, -1])  # camera +y is world down
    # The floor (z = 0) passes through the lowest observed point.
    pts = perception.observation.intrinsics.unproject(perception.observation.depth_m.astype(np.float64))
    valid = perception.observation.depth_m > 0
    z = frames.transform_points(base.world_from_camera, pts[valid])[:, 2]
    assert z.min() == pytest.approx(0.0, abs=1e-9)
    assert len(base.boxes) == len(perception.objects)


def test_sun_rgbd_truth_projects_onto_its_2d_boxes():
    sample = require(REAL_DATA / "sunrgbd_000017_mmdet3d")
    truth = procedural.load_truth(sample)
    meta = json.loads((sample / "meta.json").read_text())
    cam = json.loads((sample / "camera.json").read_text())
    k = np.array([[cam["fx"], 0, cam["cx"]], [0, cam["fy"], cam["cy"]], [0, 0, 1.0]])
    assert len(truth.objects) == 2
    for obj, b in zip(truth.objects, meta["ground_truth"]["boxes_3d"]):
        c = frames.transform_points(np.linalg.inv(truth.world_from_camera), obj.box.center_m[None])[0]
        u, v = (k @ c)[:2] / c[2]
        x0, y0, x1, y1 = b["bbox2d_xyxy_px"]
        assert x0 <= u <= x1 and y0 <= v <= y1, obj.name


def test_summary_and_json_keys(room, tmp_path):
    _, sample = room
    perception = bench.oracle_perception(sample)
    scores = bench.evaluate_baseline(perception, procedural.load_truth(sample), tmp_path, BuildConfig())
    scene = bench.SceneResult("room", str(sample), 7, 7, False, scores, scores, (("perception", 1.0),), 100.0)
    s = bench.summarize([scene], "baseline")
    assert s.recall == 1.0 and s.stable_fraction == scores.n_stable / scores.n_free
    assert s.max_penetration_m == pytest.approx(scores.max_penetration_m)
    result = bench.BenchResult("synthetic", bench.summarize([scene], "pipeline"), s, (scene,), bench.machine_description(), "2026-01-01", "cmd", tmp_path / "b.json")
    d = json.loads(json.dumps(result.to_json()))
    for key in ("recall", "precision", "position_error_m_median", "yaw_error_deg_median", "size_error_rel_median", "max_penetration_m", "stable_fraction", "depth_absrel_median", "mask_iou_median", "seconds_per_scene_median"):
        assert key in d["summary"] and key in d["baseline"]
    assert d["scenes"][0]["name"] == "room" and d["machine"]["cores"] >= 1 and d["command"] == "cmd"


def _pipeline_ready() -> str | None:
    try:
        from exporters import write_mjcf  # noqa: F401
        from generation import generate_assets  # noqa: F401
        from layout import solve_layout, verify_scene  # noqa: F401
        from perception import perceive  # noqa: F401
        from scene_builder.pipeline import build  # noqa: F401
    except ImportError as err:
        return f"the pipeline is not complete yet ({err})"
    return None


@pytest.mark.slow
def test_small_synthetic_suite_scores_pipeline_and_baseline(tmp_path):
    why = _pipeline_ready()
    if why:
        pytest.skip(why)
    out = tmp_path / "bench.json"
    result = bench.run_bench("synthetic", 2, None, out, seed=0, n_objects=3)
    d = json.loads(out.read_text())
    assert d["summary"]["scenes"] == 2 and len(d["scenes"]) == 2
    assert result.summary.failed_scenes == 0, [s.error for s in result.scenes]
    s, b = result.summary, result.baseline
    # Perception finds most objects, and the built boxes land near the true ones.
    assert s.recall is not None and s.recall >= 0.5
    assert s.precision is not None and s.precision >= 0.3
    assert s.position_error_m_median < 0.3
    # Physics: the bench's own MuJoCo check agrees with the pipeline's verdict on the same MJCF,
    # and the pipeline does no worse than the naive boxes.
    for scene in result.scenes:
        assert scene.pipeline.max_penetration_m == pytest.approx(scene.pipeline.pipeline_verdict["max_penetration_m"], abs=1e-3)
    assert s.max_penetration_m <= b.max_penetration_m
    assert s.stable_fraction >= b.stable_fraction
