"""The twin's layout and its honest checks: objects rest on the background seen under them, the
background's collision boxes stay clear of objects, overlaps of fixed bodies are measured, and
render-and-compare scores the twin against the photo."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from exporters import write_mjcf
from layout import verify_scene
from layout.background import PAD_THICKNESS_M, BackgroundSupport, carve, column_boxes
from layout.solver import solve_layout_with_stats
from perception.background import observed_background
from scene_builder.bench.clutter import box_asset, empty_perception
from scene_builder.config import LayoutConfig
from scene_builder.frames import pose, transform_points
from scene_builder.model import Background, GeneratedAsset, Perception, Room, Scene, TriangleMesh
from tests import twin_fixtures as tf

CFG = LayoutConfig()


def _grid(x0, x1, y0, y1, z, n=41):
    """An observed horizontal patch as a triangle grid (vertices (n*n, 3), faces)."""
    xs, ys = np.linspace(x0, x1, n), np.linspace(y0, y1, n)
    x, y = np.meshgrid(xs, ys)
    v = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1)
    ids = np.arange(n * n).reshape(n, n)
    a, b, c, d = ids[:-1, :-1].ravel(), ids[:-1, 1:].ravel(), ids[1:, :-1].ravel(), ids[1:, 1:].ravel()
    return v, np.concatenate([np.stack([a, b, c], 1), np.stack([b, d, c], 1)])


def _counter_background() -> Background:
    """A counter seen as background: its top at 0.75 m (x 1..2, y -0.5..0.5) and its front face
    (x = 1) from the floor up to the top."""
    top_v, top_f = _grid(1.0, 2.0, -0.5, 0.5, 0.75)
    zs, ys = np.meshgrid(np.linspace(0.0, 0.75, 31), np.linspace(-0.5, 0.5, 41))
    front_v = np.stack([np.full(zs.size, 1.0), ys.ravel(), zs.ravel()], axis=1)
    v = np.concatenate([top_v, front_v])
    return Background(TriangleMesh(v, top_f), np.ones(len(v), dtype=bool))


def _perception_with(background: Background, depth_m: float = 20.0) -> Perception:
    p = empty_perception(depth_m=depth_m)
    return dataclasses.replace(p, room=Room(p.room.walls, background))


def test_support_height_is_the_top_seen_around_the_footprint():
    support = BackgroundSupport(_counter_background())
    foot = np.array([[1.4, -0.1], [1.6, -0.1], [1.6, 0.1], [1.4, 0.1]])
    assert support.height_under(foot, 0.6, 0.8) == pytest.approx(0.75, abs=1e-9)
    # A band that does not reach the top finds nothing (the front face goes on up).
    assert support.height_under(foot, 0.3, 0.6) is None
    # Far from the counter there is nothing.
    assert support.height_under(foot + [3.0, 0.0], 0.6, 0.8) is None


def test_object_rests_on_the_background_seen_under_it(tmp_path):
    box = box_asset("box", (0.2, 0.2, 0.2))
    seen = pose(np.eye(3), [1.5, 0.0, 0.76])  # 1 cm above the counter top (depth noise)
    high = pose(np.eye(3), [1.2, 0.3, 1.5])  # 75 cm above it: nothing within reach
    perception = _perception_with(_counter_background())
    gen = (GeneratedAsset(box, seen, np.zeros((0, 3))), GeneratedAsset(box_asset("high", (0.2, 0.2, 0.2)), high, np.zeros((0, 3))))
    result, _ = solve_layout_with_stats(perception, gen, CFG)
    placements = {p.name: p for p in result.placements}
    assert placements["box"].support == "background" and placements["box"].lowered_m == pytest.approx(0.01)
    assert placements["high"].became_background
    placed = result.scene.object("box")
    np.testing.assert_allclose(placed.world_from_asset[:3, 3], [1.5, 0.0, 0.75], atol=1e-9)
    bg = result.scene.room.background
    # A pad under the box's footprint, its top exactly at the box's bottom.
    tops = bg.box_centers_m[:, 2] + bg.box_half_extents_m[:, 2]
    under = (np.abs(bg.box_centers_m[:, 0] - 1.5) < 1e-9) & (np.abs(bg.box_centers_m[:, 1]) < 1e-9)
    assert under.sum() == 1 and tops[under][0] == pytest.approx(0.75)
    assert bg.box_half_extents_m[under][0] == pytest.approx([0.1, 0.1, PAD_THICKNESS_M / 2])
    # The counter's own collision boxes keep clear of the box.
    lo, hi = bg.box_centers_m - bg.box_half_extents_m, bg.box_centers_m + bg.box_half_extents_m
    over = np.all(lo[:, :2] < [1.6, 0.1], axis=1) & np.all(hi[:, :2] > [1.4, -0.1], axis=1) & ~under
    assert np.all(hi[over, 2] <= 0.75 + 1e-9)
    # MuJoCo agrees: nothing interpenetrates (background boxes included), the box stays put.
    path = write_mjcf(result.scene, tmp_path)
    verdict, _ = verify_scene(path, result.scene, CFG)
    assert verdict.max_penetration_m < 1e-3 and verdict.max_penetration_settled_m < 1e-3
    assert verdict.stable and verdict.movable_count == 1 and verdict.fixed_count == 0
    assert verdict.settle_max_drift_m < 2e-3


def test_hidden_support_is_a_static_column_and_seen_through_space_hangs(tmp_path):
    """A box seen 75 cm above the counter with nothing within reach under it. Where the camera
    could not see under it (no depth there: hidden behind itself or something nearer), whatever
    holds it was hidden: it stays a movable object where it was seen, resting on a static column
    from the counter top up to its bottom, and stays put in MuJoCo. Where the camera saw through
    the space under it, it hangs: it becomes background."""
    high = pose(np.eye(3), [1.5, 0.0, 1.5])
    gen = (GeneratedAsset(box_asset("high", (0.2, 0.2, 0.2)), high, np.zeros((0, 3))),)
    result, _ = solve_layout_with_stats(_perception_with(_counter_background(), depth_m=0.0), gen, CFG)
    placement = {p.name: p for p in result.placements}["high"]
    assert not placement.became_background and placement.support == "background"
    assert placement.displacement_m == 0.0 and "column" in placement.reason
    np.testing.assert_allclose(result.scene.object("high").world_from_asset[:3, 3], [1.5, 0.0, 1.5], atol=1e-9)
    bg = result.scene.room.background
    lo, hi = bg.box_centers_m - bg.box_half_extents_m, bg.box_centers_m + bg.box_half_extents_m
    column = (np.abs(bg.box_centers_m[:, 0] - 1.5) < 1e-9) & (np.abs(bg.box_centers_m[:, 1]) < 1e-9)
    assert column.sum() == 1
    assert hi[column][0, 2] == pytest.approx(1.5) and lo[column][0, 2] == pytest.approx(0.75)
    path = write_mjcf(result.scene, tmp_path)
    verdict, _ = verify_scene(path, result.scene, CFG)
    assert verdict.stable and verdict.movable_count == 1 and verdict.max_penetration_m < 1e-3
    assert verdict.settle_max_drift_m < 2e-3
    # Seen through: it hangs, as background.
    result, _ = solve_layout_with_stats(_perception_with(_counter_background(), depth_m=20.0), gen, CFG)
    placement = {p.name: p for p in result.placements}["high"]
    assert placement.became_background and "camera saw empty space under it" in placement.reason


def test_column_boxes_follow_observed_heights_and_carving_cuts_under_objects():
    v, _ = _grid(0.0, 0.5, 0.0, 0.5, 0.7321, n=26)
    lo, hi = column_boxes(v)
    assert len(lo) >= 1 and np.allclose(hi[:, 2], 0.7321)  # tops at the observed height, not a voxel grid
    # An object sunk 2 mm into the slab: the boxes under it are cut down to its bottom (less the
    # clearance); one sunk 15 mm leaves too thin a slab, which is dropped.
    cut_lo, cut_hi = carve(lo, hi, np.array([[0.1, 0.1, 0.73]]), np.array([[0.2, 0.2, 0.9]]))
    hit = np.all(cut_lo[:, :2] < [0.2, 0.2], axis=1) & np.all(cut_hi[:, :2] > [0.1, 0.1], axis=1)
    assert hit.any() and np.allclose(cut_hi[hit, 2], 0.73 - 0.002) and len(cut_lo) == len(lo)
    cut_lo, cut_hi = carve(lo, hi, np.array([[0.1, 0.1, 0.7171]]), np.array([[0.2, 0.2, 0.9]]))
    hit = np.all(cut_lo[:, :2] < [0.2, 0.2], axis=1) & np.all(cut_hi[:, :2] > [0.1, 0.1], axis=1)
    assert not hit.any() and len(cut_lo) < len(lo)


def test_column_boxes_of_scattered_points_are_none():
    """Points too sparse for any column (fewer than MIN_RUN_POINTS per cell, as a plain photo's
    thin background can give: nyuv2 00050 without its depth map crashed here) give no boxes, as
    (0, 3) arrays, not an IndexError."""
    from layout.background import CELL_M, MIN_RUN_POINTS

    pts = np.array([[k * 3 * CELL_M, 0.02, 0.5] for k in range(MIN_RUN_POINTS + 2)])
    lo, hi = column_boxes(pts)
    assert lo.shape == (0, 3) and hi.shape == (0, 3)


def test_overlapping_fixed_bodies_are_measured(tmp_path):
    """MuJoCo makes no contacts between bodies welded to the world; the check measures every
    pair of collision geoms itself, so two fixed boxes 0.5 m into each other do not pass."""
    a = box_asset("cab_a", (1.0, 1.0, 1.0), label="counter", fixed=True)
    b = box_asset("cab_b", (1.0, 1.0, 1.0), label="counter", fixed=True)
    from scene_builder.model import PlacedObject

    p = empty_perception()
    scene = Scene(p.camera, p.room, (PlacedObject(a, pose(np.eye(3), [0.0, 0.0, 0.0])), PlacedObject(b, pose(np.eye(3), [0.5, 0.0, 0.0]))))
    verdict, _ = verify_scene(write_mjcf(scene, tmp_path), scene, CFG)
    assert verdict.max_penetration_m == pytest.approx(0.5, abs=1e-3)
    assert verdict.fixed_count == 2 and verdict.movable_count == 0
    assert all(o.fixed and o.start_penetration_m == pytest.approx(0.5, abs=1e-3) for o in verdict.objects)


def test_render_of_the_background_matches_the_photo(tmp_path):
    obs, board = tf.observation()
    cam = tf.camera()
    # The board as background too: the whole photo is the background's.
    bg = observed_background(obs, cam, (tf.wall(),), (), max_nodes=tf.W * tf.H)
    perception = Perception(obs, cam, Room((tf.wall(),), bg), ())
    scene = Scene(cam, perception.room, ())
    verdict, fidelity = verify_scene(write_mjcf(scene, tmp_path), scene, CFG, perception)
    assert fidelity.depth_absrel < 0.01 and fidelity.depth_absrel_settled == fidelity.depth_absrel
    assert fidelity.ssim > 0.8 and fidelity.psnr_db > 20.0
    assert fidelity.render_rgb.shape == obs.rgb.shape
    # Without the background (the floor and wall planes alone) the render is far from the photo.
    bare = Scene(cam, Room((tf.wall(),)), ())
    _, plain = verify_scene(write_mjcf(bare, tmp_path / "bare"), bare, CFG, perception)
    assert plain.psnr_db < fidelity.psnr_db - 5.0 and plain.ssim < fidelity.ssim
