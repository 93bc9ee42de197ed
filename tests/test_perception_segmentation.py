"""Colour-aware splitting of depth clusters (a thin thing lying on a surface in another colour)
and silhouette filling of object masks, on ray-cast RGB-D scenes."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from perception import perceive
from perception.perceive import _cut_above_tops, _cut_seen_through, _fill_silhouettes, _merge_fragments
from scene_builder.config import InputSpec, PerceptionConfig
from scene_builder.frames import transform_points
from tests.test_perception_synthetic import F, H, W, _camera, _render

CFG = PerceptionConfig(naming_backend="geometric-prior", segmentation_backend="depth-clusters")
CABINET = ((2.6, -0.4, 0.0), (3.2, 0.4, 0.8))
LAPTOP = ((2.75, -0.15, 0.8), (3.05, 0.2, 0.825))  # 2.5 cm thin: below the support split's 4 cm


def _scene(tmp_path, name, with_laptop):
    cam = _camera(1.5, 30.0, 0.0, 0.0)
    plain = _render(cam, [CABINET])
    laptop_px = _render(cam, [CABINET, LAPTOP]) < plain - 1e-4  # where the laptop would be seen
    depth = _render(cam, [CABINET, LAPTOP]) if with_laptop else plain
    rgb = np.empty((H, W, 3), dtype=np.uint8)
    rng = np.random.default_rng(0)
    rgb[:] = (150, 110, 70)  # brown floor and cabinet, mild sensor noise
    rgb[laptop_px] = (215, 215, 225)  # a light grey lid
    rgb = np.clip(rgb + rng.normal(0, 3, rgb.shape), 0, 255).astype(np.uint8)
    Image.fromarray(rgb).save(tmp_path / f"{name}.png")
    np.save(tmp_path / f"{name}.npy", depth)
    spec = InputSpec(tmp_path / f"{name}.png", tmp_path / f"{name}.npy", intrinsics=(F, F, (W - 1) / 2, (H - 1) / 2))
    return spec, laptop_px


def test_a_thin_thing_of_another_colour_is_split_from_its_support(tmp_path):
    spec, laptop_px = _scene(tmp_path, "laptop", with_laptop=True)
    p = perceive(spec, CFG)
    assert len(p.objects) == 2
    ious = [float((o.mask & laptop_px).sum() / (o.mask | laptop_px).sum()) for o in p.objects]
    assert max(ious) > 0.7
    laptop = p.objects[int(np.argmax(ious))]
    z = laptop.points_world_m[:, 2]
    assert np.median(z) > 0.79 and np.percentile(z, 98) < 0.86
    # Deterministic: the same masks again.
    again = perceive(spec, CFG)
    assert all(np.array_equal(a.mask, b.mask) for a, b in zip(p.objects, again.objects))


def test_a_colour_patch_in_a_surface_is_not_split(tmp_path):
    # The same light patch painted on the cabinet top, with no height step: one object.
    spec, _ = _scene(tmp_path, "patch", with_laptop=False)
    assert len(perceive(spec, CFG).objects) == 1


def test_silhouettes_take_enclosed_room_pixels_but_not_other_objects():
    ring = np.zeros((20, 20), dtype=bool)
    ring[2:18, 2:18] = True
    ring[5:15, 5:15] = False  # a bookcase's back panel taken for wall
    inner = np.zeros_like(ring)
    inner[8:11, 8:11] = True  # a bowl on a shelf board, its own instance
    labels = ring.astype(np.int32) + 2 * inner
    free = ~(ring | inner)
    [(mask, pix), (mask2, _)] = _fill_silhouettes([(ring, ring), (inner, inner)], labels, free)
    assert mask[5:15, 5:15].sum() == 100 - 9 and not (mask & inner).any()
    assert np.array_equal(pix, ring)  # observed points are unchanged
    assert np.array_equal(mask2, inner)


def _ball_query_reference(points: np.ndarray, samples: np.ndarray, radius_m: float) -> np.ndarray:
    """The colour split's neighbour search as it was: one ball query per sample over all points
    (about 8e8 indices on a large flat cluster); the reference for :func:`_near_points`."""
    from scipy.spatial import cKDTree

    near = cKDTree(points).query_ball_point(samples, radius_m)
    return np.unique(np.concatenate([np.asarray(n, dtype=np.int64) for n in near]))


def test_near_points_is_the_union_of_ball_queries():
    from perception.segment_depth import _near_points

    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 1, (20000, 2))
    samples = rng.uniform(0.3, 0.6, (300, 2))
    assert np.array_equal(_near_points(pts, samples, 0.03), _ball_query_reference(pts, samples, 0.03))
    # Points exactly at the radius count (a ball query is inclusive).
    grid = np.array([[0.0, 0.0], [0.03, 0.0], [0.0, 0.0300001]])
    assert np.array_equal(_near_points(grid, np.zeros((1, 2)), 0.03), [0, 1])
    assert len(_near_points(pts, np.zeros((0, 2)), 0.03)) == 0


@pytest.mark.slow
def test_colour_split_labels_are_unchanged_on_a_real_sample(monkeypatch):
    """The one-shot nearness query gives the depth-cluster segmenter the same labels as the
    per-sample ball queries it replaced, on a real RGB-D photo where the colour split runs."""
    import perception.segment_depth as sd
    from perception.backends import build_registries
    from perception.inputs import load_input
    from perception.perceive import _resolve_depth
    from perception.room import estimate_room
    from tests.conftest import REAL_DATA, require

    d = require(REAL_DATA / "nyuv2_metric3d_00050")
    cfg = PerceptionConfig()
    loaded = load_input(InputSpec(d / "rgb.jpg", d / "depth.png"), cfg)
    depth, k, *_ = _resolve_depth(loaded, build_registries(cfg), cfg)
    frame = estimate_room(k.unproject(depth), depth > 0, 0)
    # The floor alone is taken as background (not the walls found): what is compared is the split,
    # on many clusters, whatever walls the room finds (a wall found over the furnace here left it 3).
    floor = next(p.inliers for p in frame.planes if p.kind == "floor")
    new = sd.DepthClusterSegmenter().segment(loaded.rgb, depth, k, floor, up_cam=frame.up_cam)
    calls = []

    def reference(points, samples, radius_m):
        calls.append(len(points))
        return _ball_query_reference(points, samples, radius_m)

    monkeypatch.setattr(sd, "_near_points", reference)
    old = sd.DepthClusterSegmenter().segment(loaded.rgb, depth, k, floor, up_cam=frame.up_cam)
    assert len(calls) >= 5  # the split's neighbour search really ran on this photo
    assert new.labels.max() >= 10
    assert np.array_equal(new.labels, old.labels)


def _slab(x0, x1, y0, y1, z0, z1, step=0.05):
    g = np.mgrid[x0:x1 + 1e-9:step, y0:y1 + 1e-9:step, z0:z1 + 1e-9:step].reshape(3, -1).T
    return g


def test_a_fragment_of_one_family_lying_in_an_objects_footprint_joins_it():
    """A sleigh bed's frame (head- and footboard and a side rail around a 2 x 1.5 m footprint)
    named sofa, its mattress inside named bed with more confidence: one object, named bed, with
    both masks and pixels. A bench against the footboard (outside the footprint) and a pillow
    on the mattress (another family) stay objects; so does a second bed standing apart."""
    frame = np.vstack([_slab(0, 2, 0, 0.05, 0, 1.0), _slab(0, 2, 1.45, 1.5, 0, 1.0), _slab(0, 0.05, 0, 1.5, 0, 0.6), _slab(1.95, 2.0, 0, 1.5, 0, 0.6)])
    mattress = _slab(0.1, 1.9, 0.1, 1.4, 0.45, 0.55)
    bench = _slab(0.5, 1.5, -0.55, -0.05, 0, 0.45)
    pillow = _slab(0.2, 0.6, 0.3, 0.8, 0.6, 0.7)
    other_bed = mattress + [4.0, 0.0, 0.0]
    clouds = [frame, mattress, bench, pillow, other_bed]
    names = [("sofa", 0.57), ("bed", 0.6), ("bench", 0.7), ("pillow", 0.8), ("bed", 0.5)]
    kept = []
    for i in range(len(clouds)):
        m = np.zeros((10, 10), dtype=bool)
        m[i, :] = True
        kept.append((m, m.copy()))
    out, points, out_names, merged = _merge_fragments(kept, clouds, names)
    assert merged == 1 and len(out) == 4
    assert out_names == [("bed", 0.6), ("bench", 0.7), ("pillow", 0.8), ("bed", 0.5)]
    assert out[0][0][:2].all() and out[0][1][:2].all() and out[0][0].sum() == 20
    assert len(points[0]) == len(frame) + len(mattress)
    # The same mattress 30 cm above the frame touches nothing: not merged.
    floating = [frame, mattress + [0.0, 0.0, 0.6]]
    assert _merge_fragments(kept[:2], floating, names[:2])[3] == 0
    # Small things of one family are not merged: a vase standing in a bowl's footprint.
    bowl, vase = _slab(0, 0.3, 0, 0.3, 0.7, 0.8), _slab(0.1, 0.2, 0.1, 0.2, 0.8, 1.0)
    assert _merge_fragments(kept[:2], [bowl, vase], [("bowl", 0.5), ("vase", 0.6)])[3] == 0


def test_a_desk_ends_at_its_top_and_what_rises_behind_it_is_background():
    """An office desk (top at 0.72 m) whose cut took the partition panel behind it (up to 1.45
    m): the points and pixels more than 4 cm above the top leave the desk; a table seen with
    nothing above its top, a table seen edge-on (no dense band of heights) and a cabinet with the
    same points are unchanged."""
    rng = np.random.default_rng(0)
    top = np.column_stack([rng.uniform(0, 1.5, 4000), rng.uniform(0, 0.7, 4000), rng.normal(0.72, 0.005, 4000)])
    panel = np.column_stack([rng.uniform(0, 1.5, 6000), np.full(6000, 0.72), rng.uniform(0.72, 1.45, 6000)])
    desk = np.vstack([top, panel])
    edge_on = np.column_stack([rng.uniform(0, 1.5, 3000), np.zeros(3000), rng.uniform(0.0, 0.75, 3000)])

    def kept_for(points):
        pix = np.zeros((100, 200), dtype=bool)
        pix.ravel()[: len(points)] = True
        return (pix.copy(), pix)

    clouds = [desk, top, edge_on, desk]
    kept = [kept_for(p) for p in clouds]
    out, points, cut = _cut_above_tops(kept, clouds, ["desk", "table", "table", "cabinet"])
    assert cut == 1
    # The kept points are the desk's at and just above its top: every top point, none of the
    # panel more than 5 cm over it.
    kept_z = {tuple(p) for p in points[0]}
    gone = np.array([tuple(p) not in kept_z for p in desk])
    assert not gone[:4000].any() and gone[4000:].mean() > 0.9
    assert points[0][:, 2].max() < 0.77
    assert out[0][1].sum() == len(points[0]) and out[0][0].sum() == len(points[0])
    assert not out[0][1].ravel()[np.flatnonzero(gone)].any()  # the dropped points' pixels leave the mask
    for i in (1, 2, 3):
        assert points[i] is clouds[i] and out[i] is kept[i]


def _through_fixture(far_z_m):
    """A 60 x 80 px mask whose left part sees a chair-sized surface 2.4 m away and whose right
    part sees something ``far_z_m`` away (camera level, 1.4 m high, f = 100 px)."""
    h, w, f = 60, 80, 100.0
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    z = np.where(u < 50, 2.4, far_z_m)
    points_cam = np.dstack([(u - w / 2) / f * z, (v - h / 2) / f * z, z])
    mask = np.zeros((h, w), dtype=bool)
    mask[10:50, 20:60] = True
    world_from_camera = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 1.4], [0.0, 0.0, 0.0, 1.0]])
    return [(mask, mask.copy())], transform_points(world_from_camera, points_cam[mask]), points_cam, f


def test_what_was_seen_past_an_object_far_larger_than_its_kind_is_cut_off():
    """A "chair" whose mask took in a sofa 2.6 m behind it (through its open back) is 3 m deep:
    the far cluster leaves its points and its mask. The same mask named bed (2 m long) keeps it
    all; so does a chair whose far part is only 30 cm behind (one object's depth)."""

    kept, pts, points_cam, f = _through_fixture(5.0)
    (mask, pix), = kept
    out_kept, out_points, cut = _cut_seen_through(list(kept), [pts], ["chair"], points_cam, f)
    assert cut == 1
    new_mask, _ = out_kept[0]
    assert new_mask[:, :50].sum() == mask[:, :50].sum() and not new_mask[:, 50:].any()
    assert len(out_points[0]) == mask[:, :50].sum() and np.ptp(out_points[0][:, 0]) < 0.01
    assert _cut_seen_through(list(kept), [pts], ["bed"], points_cam, f)[2] == 0
    near = _through_fixture(2.7)
    assert _cut_seen_through(list(near[0]), [near[1]], ["chair"], near[2], near[3])[2] == 0
