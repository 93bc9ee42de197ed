"""The static background (perception.background): the observed depth as a textured mesh, holes
behind objects filled with the floor and wall planes, occluding edges tucked under instead of
stretched, the photo as texture with the objects inpainted."""

from __future__ import annotations

import numpy as np
import pytest

from perception.background import MAX_DEPTH_RATIO, observed_background
from scene_builder.frames import transform_points
from tests import twin_fixtures as tf


@pytest.fixture(scope="module")
def built():
    obs, board = tf.observation()
    cam = tf.camera()
    bg = observed_background(obs, cam, (tf.wall(),), (board,), max_nodes=tf.W * tf.H)  # stride 1
    return obs, board, cam, bg


def _camera_coords(cam, verts):
    p = transform_points(np.linalg.inv(cam.world_from_camera), verts)
    k = cam.intrinsics
    return p, k.fx_px * p[:, 0] / p[:, 2] + k.cx_px, k.fy_px * p[:, 1] / p[:, 2] + k.cy_px


def test_background_reproduces_the_observed_depth(built):
    obs, board, cam, bg = built
    mesh = bg.surface
    n_grid = (tf.W + 1) * (tf.H + 1)
    verts = mesh.vertices_m[:n_grid]
    p, u, v = _camera_coords(cam, verts)
    # Nodes sit on pixel corners; one with measured (not filled) depth takes the depth of one of
    # the pixels it touches, except where that depth along the corner's ray would put it under
    # the floor: there it lies on the floor, nearer than its pixels.
    seen = bg.surface_observed[:n_grid]
    assert seen.mean() > 0.6
    d = obs.depth_m.astype(np.float64)
    lo, hi = np.full(n_grid, np.inf), np.full(n_grid, -np.inf)
    for du in (-0.5, 0.5):
        for dv in (-0.5, 0.5):
            ui = np.clip(np.round(u + du).astype(int), 0, tf.W - 1)
            vi = np.clip(np.round(v + dv).astype(int), 0, tf.H - 1)
            lo, hi = np.minimum(lo, d[vi, ui]), np.maximum(hi, d[vi, ui])
    on_floor = np.abs(verts[:, 2]) < 1e-9
    assert np.all(p[seen, 2] <= hi[seen] * (1 + 1e-6))
    assert np.all((p[seen, 2] >= lo[seen] * (1 - 1e-6)) | on_floor[seen])
    assert np.all(verts[:, 2] >= -1e-9)  # nothing under the floor
    assert 0 < np.count_nonzero(on_floor[seen] & (p[:, 2] < lo * (1 - 1e-6))[seen]) < 0.2 * seen.sum()
    # The mesh covers the whole image: its outer nodes are on the image border.
    assert u.min() == pytest.approx(-0.5) and u.max() == pytest.approx(tf.W - 0.5)
    assert v.min() == pytest.approx(-0.5) and v.max() == pytest.approx(tf.H - 0.5)
    # Texture coordinates are the nodes' image positions.
    np.testing.assert_allclose(mesh.uv[:n_grid, 0], (u + 0.5) / tf.W, atol=1e-6)
    np.testing.assert_allclose(mesh.uv[:n_grid, 1], (v + 0.5) / tf.H, atol=1e-6)


def test_behind_the_object_the_room_planes_continue(built):
    obs, board, cam, bg = built
    n_grid = (tf.W + 1) * (tf.H + 1)
    verts = bg.surface.vertices_m[:n_grid]
    p, u, v = _camera_coords(cam, verts)
    inside = (u > 52) & (u < 107) & (v > 62) & (v < 97)  # well inside the board's pixels
    assert inside.sum() > 1000
    assert not bg.surface_observed[:n_grid][inside].any()
    # Filled behind the board, on the floor or the wall plane, never in front of the board.
    assert np.all(p[inside, 2] > tf.BOARD_DEPTH_M)
    on_floor = np.abs(verts[inside, 2]) < 1e-6
    on_wall = np.abs(verts[inside, 0] - tf.WALL_X_M) < 1e-6
    assert np.all(on_floor | on_wall) and on_floor.any() and on_wall.any()


def test_occluding_edges_are_tucked_under_not_stretched(built):
    obs, board, cam, bg = built
    # Put the board back into the depth the mesh is built from, as if it were background.
    from perception.background import observed_background

    bg2 = observed_background(obs, cam, (tf.wall(),), (), max_nodes=tf.W * tf.H)
    mesh = bg2.surface
    p = transform_points(np.linalg.inv(cam.world_from_camera), mesh.vertices_m)
    z = p[:, 2][mesh.faces]
    assert np.all(z.max(axis=1) <= MAX_DEPTH_RATIO * z.min(axis=1) + 1e-9)
    # The board's edge is an occluding edge: copies of its edge nodes at the far depth exist.
    assert len(mesh.vertices_m) > (tf.W + 1) * (tf.H + 1)


def test_texture_is_the_photo_with_objects_inpainted(built):
    obs, board, cam, bg = built
    tex = bg.surface.texture.image_rgb
    assert tex.shape == obs.rgb.shape
    np.testing.assert_array_equal(tex[~board.mask], obs.rgb[~board.mask])
    # No red board left in the texture: its pixels take the room's colours.
    inside = tex[tf.BOARD_ROWS, tf.BOARD_COLS].reshape(-1, 3).astype(int)
    assert np.mean(inside[:, 0] - inside[:, 1]) < 40


def test_texture_keeps_the_full_resolution_photo():
    """A photo analysed downscaled (Observation.rgb_full) is textured at its stored resolution."""
    import dataclasses

    obs, board = tf.observation()
    full = np.repeat(np.repeat(obs.rgb, 3, axis=0), 3, axis=1)
    big = dataclasses.replace(obs, rgb_full=full)
    bg = observed_background(big, tf.camera(), (tf.wall(),), (board,))
    tex = bg.surface.texture.image_rgb
    assert tex.shape == full.shape
    mask_full = np.repeat(np.repeat(board.mask, 3, axis=0), 3, axis=1)
    np.testing.assert_array_equal(tex[~mask_full], full[~mask_full])
