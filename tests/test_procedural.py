"""Procedural rooms: deterministic, physically valid ground truth, renders that match the geometry."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scene_builder import frames
from scene_builder.bench import procedural, render, truth
from scene_builder.model import CameraIntrinsics


def _gt(spec):
    return json.dumps(render.ground_truth(spec), sort_keys=True)


def test_rooms_are_deterministic_for_a_seed():
    a, b = procedural.make_room(11, n_objects=7), procedural.make_room(11, n_objects=7)
    assert _gt(a) == _gt(b)
    assert a.objects == b.objects
    assert _gt(procedural.make_room(12, n_objects=7)) != _gt(a)


def test_rooms_have_the_requested_objects_categories_and_supports():
    spec = procedural.make_room(5, n_objects=8)
    assert len(spec.objects) == 8
    names = [o.name for o in spec.objects]
    assert len(set(names)) == len(names)
    assert [o.object_id for o in spec.objects] == list(range(1, 9))
    for o in spec.objects:
        assert o.support == "floor" or o.support in names
        if o.support == "floor":
            assert o.position_m[2] == pytest.approx(o.size_m[2] / 2)
        else:  # resting exactly on a surface of its host, below the host's top
            host = spec.object(o.support)
            assert o.position_m[2] - o.size_m[2] / 2 <= host.top_z_m + 1e-9
        assert o.mass_kg > 0
    only = procedural.make_room(3, n_objects=4, categories=("table",))
    assert {o.category for o in only.objects if o.support == "floor"} == {"table"}
    with pytest.raises(ValueError):
        procedural.make_room(0, categories=("spaceship",))


def test_camera_is_kinect_like_and_pitched_down():
    for seed in range(6):
        cam = procedural.make_room(seed, n_objects=3).camera
        k = cam.intrinsics
        assert (k.width_px, k.height_px) == (640, 480) and 500 < k.fx_px < 540
        assert 1.2 <= cam.position_m[2] <= 1.7
        optical_axis = cam.world_from_camera[:3, 2]
        pitch_down = np.degrees(np.arcsin(-optical_axis[2]))
        assert 8.0 <= pitch_down <= 20.0
        # The camera's x axis is horizontal (no roll).
        assert abs(cam.world_from_camera[2, 0]) < 1e-9


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_ground_truth_objects_do_not_interpenetrate(seed):
    import mujoco

    spec = procedural.make_room(seed, n_objects=9)
    model = render.build_mjspec(spec, free_bodies=True).compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert model.nbody == 1 + len(spec.objects) + sum(len(o.joints) for o in spec.objects)
    dists = [data.contact[i].dist for i in range(data.ncon)]
    # Contacts exist (objects touch the floor and their hosts) but none goes 1 mm deep.
    assert data.ncon > 0
    assert min(dists) > -1e-3


def test_joints_in_ground_truth_are_on_their_parts():
    spec = next(s for s in (procedural.make_room(i, n_objects=8) for i in range(30)) if any(o.joints for o in s.objects))
    for o in spec.objects:
        for j in o.joints:
            prims = [p for p in o.primitives if p.body == j.part]
            assert prims, f"joint {j.part} of {o.name} has no geometry"
            assert np.isclose(np.linalg.norm(j.axis), 1.0) and j.upper > j.lower
            # The anchor lies within the object's bounding box (object frame: bottom centre origin).
            half = np.array(o.size_m) / 2
            a = np.array(j.anchor_m) - [0, 0, half[2]]
            assert np.all(np.abs(a) <= half + 1e-9)


def _analytic_background_depth(spec, shape):
    """(H, W) planar depth of the nearest of floor, walls and ceiling along each pixel's ray."""
    k, t_wc = spec.camera.intrinsics, spec.camera.world_from_camera
    h, w = shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    dirs = np.stack([(u - k.cx_px) / k.fx_px, (v - k.cy_px) / k.fy_px, np.ones_like(u)], -1) @ t_wc[:3, :3].T
    o = t_wc[:3, 3]
    planes = [(np.array([0.0, 0.0, 1.0]), 0.0), (np.array([0.0, 0.0, -1.0]), spec.room_size_m[2])]
    planes += [(np.array(wl.normal), wl.offset_m) for wl in spec.walls]
    ts = []
    for n, off in planes:
        with np.errstate(divide="ignore"):
            t = -(n @ o + off) / (dirs @ n)  # rays have unit z in the camera: t is planar depth
        ts.append(np.where(t > 0, t, np.inf))
    return np.min(np.stack(ts), axis=0), ts[0]


def test_rendered_depth_matches_the_geometry_and_instances_match_objects(tmp_path):
    from PIL import Image

    spec = procedural.make_room(4, n_objects=7)
    out = render.render_room(spec, tmp_path / "room")
    depth_m = np.asarray(Image.open(out / "depth.png")).astype(np.float64) / 1000.0
    inst = np.asarray(Image.open(out / "instances.png"))
    meta = json.loads((out / "meta.json").read_text())
    cam = json.loads((out / "camera.json").read_text())
    assert depth_m.shape == (480, 640) and inst.dtype == np.uint16
    assert cam["fx"] == spec.camera.intrinsics.fx_px

    analytic, floor_t = _analytic_background_depth(spec, depth_m.shape)
    floor_px = (inst == 0) & (floor_t == analytic) & np.isfinite(analytic)
    assert floor_px.sum() > 1000
    # Floor pixels: rendered depth = ray-plane distance, to the mm quantisation of the PNG.
    assert np.max(np.abs(depth_m[floor_px] - analytic[floor_px])) <= 1e-3
    bg = (inst == 0) & np.isfinite(analytic)
    assert np.max(np.abs(depth_m[bg] - analytic[bg])) <= 1e-3

    # Every object pixel back-projects into (or onto) that object's bounding box, and the ids
    # in the image are exactly the visible objects.
    k = CameraIntrinsics(cam["fx"], cam["fy"], cam["cx"], cam["cy"], cam["width"], cam["height"])
    pts_w = frames.transform_points(spec.camera.world_from_camera, k.unproject(depth_m).reshape(-1, 3)).reshape(480, 640, 3)
    gt = {o["object_id"]: o for o in meta["ground_truth"]["objects"]}
    assert set(np.unique(inst)) - {0} <= set(gt)
    for oid in np.unique(inst):
        if oid == 0:
            continue
        o = spec.objects[oid - 1]
        assert gt[oid]["visible_px"] == int((inst == oid).sum())
        local = frames.transform_points(np.linalg.inv(o.world_from_object), pts_w[inst == oid]) - [0, 0, o.size_m[2] / 2]
        inside = np.all(np.abs(local) <= np.array(o.size_m) / 2 + 0.004, axis=1)
        assert inside.mean() > 0.99, f"{o.name}: {inside.mean():.3f} of its pixels fall inside its box"


def test_depth_noise_is_proportional_with_holes():
    rng = np.random.default_rng(0)
    clean = rng.uniform(1.0, 5.0, size=(120, 160)).astype(np.float32)
    clean[:, :80] = 2.0  # a flat region and a depth edge at column 80
    clean[:, 80:] = 4.0
    noise = procedural.DepthNoise(rel_sigma=0.01, holes=3, edge_dropout=1.0)
    noisy = render.corrupt_depth(clean, noise, seed=3)
    valid = noisy > 0
    assert 0.5 < valid.mean() < 1.0
    assert not valid[:, 79:81].any()  # dropped at the discontinuity
    rel = (noisy[valid] - clean[valid]) / clean[valid]
    assert abs(rel.mean()) < 2e-3 and 0.008 < rel.std() < 0.012
    assert np.array_equal(noisy, render.corrupt_depth(clean, noise, seed=3))


def test_demo_input_is_a_loadable_sample(tmp_path):
    from PIL import Image

    out = render.write_demo_input(tmp_path / "demo", seed=0, n_objects=7)
    for name in ("rgb.png", "depth.png", "camera.json", "meta.json", "instances.png"):
        assert (out / name).exists()
    rgb = np.asarray(Image.open(out / "rgb.png").convert("RGB"))
    assert rgb.shape == (480, 640, 3) and rgb.std() > 10
    meta = json.loads((out / "meta.json").read_text())
    objs = meta["ground_truth"]["objects"]
    assert len(objs) == 7 and sum(o["visible_px"] > 0 for o in objs) >= 5
    assert meta["ground_truth"]["camera"]["world_from_camera"][3] == [0.0, 0.0, 0.0, 1.0]


def test_compare_to_ground_truth_aligns_worlds_through_the_camera(tmp_path):
    from scene_builder.bench.clutter import box_asset

    from scene_builder.model import Camera, PlacedObject, Room, Scene

    spec = procedural.make_room(8, n_objects=6)
    sample = render.render_room(spec, tmp_path / "room")
    # The same objects described in another world frame (yawed 40 degrees and shifted): only the
    # camera relates the two, as for a real build.
    other_from_gt = frames.pose(frames.rot_z(np.radians(40)), (1.0, -2.0, 0.0))
    placed = []
    for i, o in enumerate(spec.objects[:-1]):  # the last object is "missed"
        size = np.array(o.size_m) * (1.1 if i == 0 else 1.0)  # the first is built 10 % too big
        placed.append(PlacedObject(box_asset(o.name, size, o.category), other_from_gt @ o.world_from_object))
    scene = Scene(Camera(spec.camera.intrinsics, other_from_gt @ spec.camera.world_from_camera), Room(), tuple(placed))
    result = truth.compare_to_ground_truth(scene, sample)
    s = result["summary"]
    gt_objects = json.loads((sample / "meta.json").read_text())["ground_truth"]["objects"]
    visible = {o["name"] for o in gt_objects if o["visible_px"] >= truth.MIN_VISIBLE_PX}
    built = {o.name for o in spec.objects[:-1]}
    assert s["precision"] == 1.0 and s["category_accuracy"] == 1.0
    assert s["recall"] == pytest.approx(len(visible & built) / len(visible))
    assert s["position_error_m_median"] == pytest.approx(0.0, abs=1e-6)
    assert s["yaw_error_deg_median"] == pytest.approx(0.0, abs=1e-6)
    first = next(o for o in result["objects"] if o["true"] == spec.objects[0].name)
    assert first["size_error_rel"] == pytest.approx(0.1)
    assert first["box_iou_3d"] == pytest.approx(1 / 1.1**3)
    assert first["position_error_m"] == pytest.approx(0.05 * spec.objects[0].size_m[2])  # grown about its bottom
