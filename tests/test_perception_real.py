"""perceive() on the real RGB-D samples (NYU Depth v2, SUN RGB-D) in ../shared/data/real."""

from __future__ import annotations

import json

import numpy as np
import pytest

from perception import perceive
from perception.room import estimate_room
from scene_builder.config import InputSpec, PerceptionConfig
from scene_builder.frames import transform_points
from tests.conftest import REAL_DATA, real_samples

pytestmark = pytest.mark.slow

CFG = PerceptionConfig(naming_backend="geometric-prior", segmentation_backend="depth-clusters", depth_backend="auto")
SAMPLES = real_samples()


def _spec(d):
    return InputSpec(next(d.glob("rgb.*")), d / "depth.png")


_CACHE: dict[str, tuple] = {}


def _run(d):
    if d.name not in _CACHE:
        p = perceive(_spec(d), CFG, seed=0)
        obs = p.observation
        frame = estimate_room(obs.intrinsics.unproject(obs.depth_m), obs.valid_depth & (obs.depth_m < CFG.max_depth_m), seed=0)
        _CACHE[d.name] = (p, frame)
    return _CACHE[d.name]


def _gt_up_cam(d):
    """Ground-truth up in the OpenCV camera frame from SUN RGB-D's Rtilt, or None."""
    rt = json.loads((d / "meta.json").read_text())["ground_truth"].get("Rtilt")
    if rt is None:
        return None
    r = np.asarray(rt)
    up = np.array([r[2, 0], -r[2, 2], r[2, 1]])  # Rtilt^T e_z in depth axes -> OpenCV axes
    return up / np.linalg.norm(up)


@pytest.mark.skipif(not SAMPLES, reason=f"no real RGB-D samples under {REAL_DATA}")
@pytest.mark.parametrize("sample", SAMPLES, ids=lambda d: d.name)
def test_room_frame(sample):
    p, frame = _run(sample)
    assert frame.floor_found and [b.backend for b in p.backends if b.task == "gravity"] == ["floor-plane"]
    # perceive's camera is the room frame (deterministic for the seed).
    np.testing.assert_allclose(p.camera.world_from_camera, frame.world_from_camera, atol=1e-12)
    obs = p.observation
    pts = obs.intrinsics.unproject(obs.depth_m)
    on_floor = frame.floor_mask & (obs.depth_m > 0) & (obs.depth_m < 4.0)
    z = np.abs(transform_points(p.camera.world_from_camera, pts[on_floor])[:, 2])
    # Structured-light noise grows as z^2 (sigma 2.3 cm at 4 m): most floor inliers within 2 cm.
    assert np.median(z) < 0.01 and np.quantile(z, 0.8) < 0.02
    assert 5.0 < frame.tilt_deg < 20.0
    assert 0.5 < p.camera.position_m[2] < 2.5
    up_gt = _gt_up_cam(sample)
    if up_gt is not None:
        # SUN RGB-D's own Rtilt leaves these floors 1 to 3.3 degrees off level (measured), so
        # agreement is bounded by that, not by the floor fit (floor inliers 1 cm off z = 0).
        assert np.degrees(np.arccos(np.clip(up_gt @ frame.up_cam, -1, 1))) < 5.0


@pytest.mark.skipif(not SAMPLES, reason=f"no real RGB-D samples under {REAL_DATA}")
@pytest.mark.parametrize("sample", SAMPLES, ids=lambda d: d.name)
def test_objects(sample):
    p, _ = _run(sample)
    assert len(p.objects) >= 3
    masks = np.stack([o.mask for o in p.objects])
    assert masks.sum(axis=0).max() == 1
    assert len({o.name for o in p.objects}) == len(p.objects)
    assert [o.object_id for o in p.objects] == list(range(1, len(p.objects) + 1))
    for o in p.objects:
        assert len(o.points_world_m) >= CFG.min_object_points
        assert np.quantile(o.points_world_m[:, 2], 0.05) > -0.03, o.name
        assert o.mask.shape == p.observation.depth_m.shape
        for w in p.room.walls:  # the room is the space in front of its walls where they stand
            assert w.clearance_m(o.points_world_m).min() > -0.1, o.name


def test_sunrgbd_ground_truth_boxes():
    d = REAL_DATA / "sunrgbd_000017_mmdet3d"
    if not d.exists():
        pytest.skip(f"shared data not present: {d}")
    meta = json.loads((d / "meta.json").read_text())
    rtilt = np.asarray(meta["ground_truth"]["Rtilt"])
    p, _ = _run(d)
    camera_from_world = np.linalg.inv(p.camera.world_from_camera)
    hits = {}
    for box in meta["ground_truth"]["boxes_3d"]:
        c, s = np.cos(box["yaw_rad"]), np.sin(box["yaw_rad"])
        half = np.asarray(box["size_m"]) / 2 + 0.15  # 15 cm neighbourhood
        for o in p.objects:
            pc = transform_points(camera_from_world, o.points_world_m)
            x = (rtilt @ np.stack([pc[:, 0], pc[:, 2], -pc[:, 1]])).T  # SUN upright depth frame
            centroid = np.median(x, axis=0) - np.asarray(box["center_m"])
            local = np.array([c * centroid[0] + s * centroid[1], -s * centroid[0] + c * centroid[1], centroid[2]])
            if np.all(np.abs(local) <= half):
                hits.setdefault(box["label"], []).append(o.name)
    # Both annotated objects (a bed and a night stand) have a perceived object inside their box.
    assert set(hits) == {"bed", "night_stand"}


def test_detected_objects_the_sparse_scan_barely_measured_stand_at_their_floor_contact():
    """sunrgbd_000017's depth is a 13 % subsample, and the far dark chest of drawers at the back
    right holds 53 measured points on its 8343 pixels: detected (a drawer unit), it stands at its
    floor contact, its face square to the room (before, it was left out as unmeasured). What the
    scan barely measured and that stands on no floor (the lamp's base, a tag on the headboard)
    is still counted as left out, and the report says so, rather than losing it silently."""
    d = REAL_DATA / "sunrgbd_000017_mmdet3d"
    if not d.exists():
        pytest.skip(f"shared data not present: {d}")
    p = perceive(_spec(d), PerceptionConfig(), seed=0)
    chest = [o for o in p.objects if o.mask[200, 620]]
    assert len(chest) == 1 and chest[0].label in ("drawer_unit", "cabinet", "wardrobe"), [(o.name, o.label) for o in chest]
    pts = chest[0].points_world_m
    assert pts[:, 2].min() < 0.1 and np.quantile(pts[:, 2], 0.98) > 0.9  # from the floor up
    # its face: a vertical plane whose normal is a wall's or runs along a wall
    _, _, vt = np.linalg.svd(pts - pts.mean(axis=0), full_matrices=False)
    normal = vt[2]
    assert abs(normal[2]) < 0.02
    wall = p.room.walls[0].normal
    along = np.cross([0.0, 0.0, 1.0], wall)
    assert max(abs(normal @ wall), abs(normal @ along)) > 0.999
    placed = [b.reason for b in p.backends if b.task == "placement" and b.backend == "floor-contact"]
    assert placed and "sensor depth did not measure" in placed[0]
    assert p.left_out_unmeasured >= 1
    said = [b.reason for b in p.backends if b.task == "segmentation" and "left out" in b.reason]
    assert said and said[0].startswith(f"left out {p.left_out_unmeasured} segmented objects with fewer than")


def test_a_night_stand_boxed_whole_and_by_its_lower_drawers_is_one_object():
    """sunrgbd_imvotenet_000005's night stand at the right edge is boxed whole ("oven") and by its
    lower two drawers ("suitcase"): one object from its top drawer down (before, the slice's mask
    took the whole's lower part, the whole was dropped and the top drawer was in no object). The
    photo's edge cuts it (0.38 m of it seen): named over the lengths it may have, it is storage
    furniture with drawers seen on its face (named from what was seen, it was a chair)."""
    d = REAL_DATA / "sunrgbd_imvotenet_000005"
    if not d.exists():
        pytest.skip(f"shared data not present: {d}")
    p = perceive(_spec(d), PerceptionConfig(), seed=0)
    top_drawer, bottom_drawer = (330, 690), (470, 690)  # (row, column)
    owners = [o.name for o in p.objects if o.mask[top_drawer] or o.mask[bottom_drawer]]
    assert len(owners) == 1, owners
    stand = next(o for o in p.objects if o.name == owners[0])
    assert stand.mask[top_drawer] and stand.mask[bottom_drawer]
    assert stand.label in ("cabinet", "drawer_unit"), stand.label
    assert sum(f.kind == "drawer" for f in stand.fronts) >= 2


def test_plain_bedroom_photo_keeps_the_bed_whole_to_its_headboard():
    """sunrgbd_imvotenet_000003 as a plain photo (no depth): single-view depth stands the detected
    bed as a cuboid with a headboard. Its top and headboard are the bed's (the depth segmenter
    splits the cuboid at its creases; they were hinted background), the headboard's plane is no
    wall (a wall parallel to it behind it shows more of itself), and a bed boxed at 0.79 stays a
    bed. Before, its points stopped at 0.6 m, the headboard was a wall, and it was named sofa
    (3D box IoU 0.24 against the annotated bed; 0.65 now)."""
    from tests.conftest import require

    d = require(REAL_DATA / "sunrgbd_imvotenet_000003")
    p = perceive(InputSpec(d / "rgb.jpg"), PerceptionConfig(), seed=0)
    beds = [o for o in p.objects if o.label == "bed"]
    assert len(beds) == 1, [(o.name, o.label) for o in p.objects]
    z = beds[0].points_world_m[:, 2]
    assert np.percentile(z, 99) > 0.9  # the headboard (the typical bed's is 1.1 m high)
    walls = p.room.walls
    for a in walls:
        for b in walls:
            parallel = float(a.normal @ b.normal) > np.cos(np.radians(5.0))
            # (world walls: signed distance from the camera's position, normals into the room)
            assert not (a is not b and parallel and abs(a.offset_m - b.offset_m) > 0.5), walls


def test_a_kinect_photos_frame_is_not_textured_and_nothing_stands_behind_its_walls():
    """nyuv2_metric3d_00100 (white undistortion frame, 6-8 px): the observation's photo, which
    textures the twin, has no frame left, and the report says so. Without it the fronts found on
    the far side of the room's wall made a built-in "cabinet" 1.1 m behind the wall (welded there,
    1.6 m into it): every object, built-ins included, stands in front of every wall where the
    wall stands (its span); the laundry past the wall's end, through the opening on the right,
    is the room going on."""
    from perception.inputs import photo_frame
    from tests.conftest import require

    d = require(REAL_DATA / "nyuv2_metric3d_00100")
    p = perceive(_spec(d), PerceptionConfig(), seed=0)
    assert photo_frame(p.observation.rgb) == (0, 0, 0, 0)
    assert any(b.task == "photo-frame" for b in p.backends)
    assert p.room.walls
    for o in p.objects:
        for w in p.room.walls:
            assert np.median(w.clearance_m(o.points_world_m)) > -0.1, o.name
