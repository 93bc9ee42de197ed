"""The static background (perception.background, perception.room_surfaces): the observed depth as
a textured grid cut at occluding edges, the floor and walls completed behind the objects and
beyond the photo's frame, the photo as texture with the objects inpainted."""

from __future__ import annotations

import numpy as np
import pytest

from perception.background import observed_background
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


def _cast(mesh, origins, dirs):
    """Distance along each (N, 3) unit ray to the first front-facing hit of the mesh (inf: none),
    by open3d's RaycastingScene. Back faces are passed through, as MuJoCo's renderer, USD
    (``doubleSided`` false) and glTF (``doubleSided`` false) viewers cull them: a room's closing
    wall seen from outside the room is not drawn."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices_m.astype(np.float32)), o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    start = np.broadcast_to(np.asarray(origins, dtype=np.float64), dirs.shape).copy()
    travelled = np.zeros(len(dirs))
    out = np.full(len(dirs), np.inf)
    todo = np.arange(len(dirs))
    for _ in range(8):
        rays = np.hstack([start[todo], dirs[todo]]).astype(np.float32)
        ans = scene.cast_rays(o3d.core.Tensor(rays))
        t = ans["t_hit"].numpy().astype(np.float64)
        normal = ans["primitive_normals"].numpy().astype(np.float64)
        hit = np.isfinite(t)
        front = hit & (np.einsum("ij,ij->i", normal, dirs[todo]) < 0.0)
        out[todo[front]] = travelled[todo[front]] + t[front]
        back = hit & ~front
        step = t[back] + 1e-4
        start[todo[back]] += dirs[todo[back]] * step[:, None]
        travelled[todo[back]] += step
        todo = todo[back]
        if len(todo) == 0:
            break
    return out


def _pixel_rays(cam, world_from_camera=None):
    """Unit world-frame rays through every pixel centre of the fixture's camera (optionally put
    at another pose), and the camera centre."""
    t = cam.world_from_camera if world_from_camera is None else world_from_camera
    d = tf.rays_cam().reshape(-1, 3) @ t[:3, :3].T
    return t[:3, 3], d / np.linalg.norm(d, axis=1, keepdims=True)


def _true_surface_distance(points):
    """(N,) distance of world points to the nearest true surface of the fixture (floor, wall)."""
    return np.minimum(np.abs(points[:, 2]), np.abs(points[:, 0] - tf.WALL_X_M))


def _closing_walls(obs, cam):
    """The walls the completion closes the fixture's room with (it has one wall; its other
    sides end where what was seen ends)."""
    from perception import room_surfaces

    seen = transform_points(cam.world_from_camera, cam.intrinsics.unproject(obs.depth_m)[obs.depth_m > 0])
    fwd = cam.world_from_camera[:2, 2]
    footprint = room_surfaces.room_footprint(seen, cam.world_from_camera[:2, 3], (tf.wall(),), fwd, enclose=True)
    return room_surfaces.closing_walls(footprint, (tf.wall(),), fwd)


def _room_distance(points, closing):
    """(N,) distance to the nearest of the fixture's true surfaces and the closing walls (the
    completed planes lie BEHIND_M behind their planes)."""
    from perception.room_surfaces import BEHIND_M

    d = _true_surface_distance(points)
    for w in closing:
        d = np.minimum(d, np.abs(w.signed_distance_m(points) + BEHIND_M))
    return d


def test_the_room_is_closed_where_what_was_seen_ends(built):
    """The fixture's room has its wall ahead; its sides to the left and right are closed by walls
    just past the farthest point seen there, and nothing closes it behind the camera. The photo's camera
    sees none of them in front of what it saw (the cells its rays cross are left out)."""
    obs, board, cam, bg = built
    closing = _closing_walls(obs, cam)
    normals = np.array([w.normal for w in closing])
    assert len(closing) == 2 and np.allclose(np.sort(normals[:, 1]), [-1.0, 1.0]) and np.allclose(normals[:, [0, 2]], 0.0)
    assert bg.closed_sides == 2  # (perceive reports them: task "room-closure")
    seen = transform_points(cam.world_from_camera, cam.intrinsics.unproject(obs.depth_m)[obs.depth_m > 0])
    for w in closing:
        s = w.signed_distance_m(seen)
        assert 0.0 < s.min() < 0.1  # just past the farthest point seen
    origin, dirs = _pixel_rays(cam)
    t = _cast(bg.surface, origin, dirs)
    hit = origin + dirs * t[:, None]
    on_closing = np.zeros(len(hit), dtype=bool)
    for w in closing:
        on_closing |= np.abs(w.signed_distance_m(hit) + 0.003) < 1e-3
    on_closing &= _true_surface_distance(hit) > 1e-3  # (not the floor at a closing wall's foot)
    assert on_closing.sum() == 0 and np.isfinite(t[(obs.depth_m > 0).ravel()]).all()


def test_observed_nodes_keep_the_observed_depth(built):
    obs, board, cam, bg = built
    mesh = bg.surface
    seen = bg.surface_observed
    assert seen.sum() > 0.5 * tf.W * tf.H
    p, u, v = _camera_coords(cam, mesh.vertices_m[seen])
    # A node sits on a pixel corner and takes one of its pixels' depth (or the plane it shows,
    # exact in this fixture).
    d = obs.depth_m.astype(np.float64)
    lo, hi = np.full(len(p), np.inf), np.full(len(p), -np.inf)
    for du in (-0.5, 0.5):
        for dv in (-0.5, 0.5):
            ui = np.clip(np.round(u + du).astype(int), 0, tf.W - 1)
            vi = np.clip(np.round(v + dv).astype(int), 0, tf.H - 1)
            lo, hi = np.minimum(lo, d[vi, ui]), np.maximum(hi, d[vi, ui])
    within = (p[:, 2] <= hi * (1 + 1e-4)) & (p[:, 2] >= lo * (1 - 1e-4))
    # Nodes on a room plane are put on the plane (exact here): at the image border a corner's ray
    # leaves its pixels' span.
    assert np.all(within | (_true_surface_distance(mesh.vertices_m[seen]) < 1e-6))
    assert within.mean() > 0.95
    assert np.all(mesh.vertices_m[:, 2] >= -0.01)  # nothing under the floor (completed planes 3 mm under it)


def test_render_from_the_camera_sees_the_room_where_it_was_seen(built):
    """Rays from the camera through the pixels that show the room hit the mesh at the observed
    depth (the grid draws them; the completed planes lie just behind)."""
    obs, board, cam, bg = built
    origin, dirs = _pixel_rays(cam)
    t = _cast(bg.surface, origin, dirs)
    room = ~board.mask.ravel()
    z_ray = (tf.rays_cam().reshape(-1, 3) / np.linalg.norm(tf.rays_cam().reshape(-1, 3), axis=1, keepdims=True))[:, 2]
    depth = (t * z_ray)[room]
    rel = np.abs(depth / obs.depth_m.ravel()[room] - 1.0)
    # (Within a pixel of the floor-wall corner a triangle cuts the corner.)
    assert np.quantile(rel, 0.99) < 2e-3 and rel.max() < 0.01


def test_completed_room_covers_the_pixels_behind_an_object(built):
    """A ray from the camera through an object's pixels hits a room plane behind the object."""
    obs, board, cam, bg = built
    origin, dirs = _pixel_rays(cam)
    inner = np.zeros_like(board.mask)
    inner[tf.BOARD_ROWS, tf.BOARD_COLS] = True
    sel = inner.ravel()
    t = _cast(bg.surface, origin, dirs[sel])
    assert np.all(np.isfinite(t))
    hit = origin + dirs[sel] * t[:, None]
    z_ray = transform_points(np.linalg.inv(cam.world_from_camera), hit)[:, 2]
    assert np.all(z_ray > tf.BOARD_DEPTH_M + 0.02)  # behind the board, never in front
    assert np.all(_true_surface_distance(hit) < 0.005)
    assert (np.abs(hit[:, 2]) < 0.005).any() and (np.abs(hit[:, 0] - tf.WALL_X_M) < 0.005).any()


@pytest.mark.parametrize("board_depth_m", [2.0, 2.75])
def test_no_rubber_sheets_across_occluding_edges(board_depth_m):
    """Built with the board as background (so its edge is an occluding edge in the grid), the
    mesh seen from a camera 0.6 m to the side has nothing between the board and the room behind
    it: every hit lies on the board, the floor or the wall. The 2.75 m board stands about 10 %
    in front of the wall behind it (a jump the depth ratio alone does not flag)."""
    obs, board = tf.observation()
    depth = obs.depth_m.copy()
    # (Where the floor is nearer than the board, the floor hides it: the board stands on it.)
    depth[board.mask] = np.minimum(board_depth_m, tf.room_depth()[board.mask])
    import dataclasses

    obs = dataclasses.replace(obs, depth_m=depth)
    cam = tf.camera()
    bg = observed_background(obs, cam, (tf.wall(),), (), max_nodes=tf.W * tf.H)
    moved = cam.world_from_camera.copy()
    moved[:3, 3] += moved[:3, 0] * 0.6  # 0.6 m to the camera's right
    origin, dirs = _pixel_rays(cam, moved)
    t = _cast(bg.surface, origin, dirs)
    ok = np.isfinite(t)
    hit = origin + dirs[ok] * t[ok, None]
    cam_z = transform_points(np.linalg.inv(cam.world_from_camera), hit)[:, 2]
    r = transform_points(np.linalg.inv(cam.world_from_camera), hit)
    k = cam.intrinsics
    col, row = k.fx_px * r[:, 0] / r[:, 2] + k.cx_px, k.fy_px * r[:, 1] / r[:, 2] + k.cy_px
    in_board = (row > tf.BOARD_ROWS.start - 1.5) & (row < tf.BOARD_ROWS.stop + 0.5) & (col > tf.BOARD_COLS.start - 1.5) & (col < tf.BOARD_COLS.stop + 0.5)
    to_board = np.where(in_board, np.abs(cam_z - board_depth_m), np.inf)
    on_board = to_board < 0.01
    # A sheet spanning the jump (20 or 35 cm) has points far from both sides; steps under
    # GRAZING_DEPTH_RATIO (4 %, 11 cm here: where the board stands on the floor) are surface.
    room = _room_distance(hit, _closing_walls(obs, cam))
    stray = np.minimum(to_board, room) > 0.06
    on_room = room < 0.01
    assert not stray.any(), f"{stray.sum()} of {len(hit)} hits between the board and the room"
    # The board's edge was near the floor and the wall in the photo: the side view sees both.
    assert on_board.sum() > 1000 and on_room.sum() > 5000


def test_the_room_continues_beyond_the_photo(built):
    """Turned 30 degrees, the camera still sees floor and wall where the photo showed none."""
    obs, board, cam, bg = built
    c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    turn = np.eye(4)
    turn[:3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    moved = cam.world_from_camera.copy()
    moved[:3, :3] = turn[:3, :3] @ moved[:3, :3]
    origin, dirs = _pixel_rays(cam, moved)
    t = _cast(bg.surface, origin, dirs)
    ok = np.isfinite(t)
    hit = origin + dirs[ok] * t[ok, None]
    # Without completion (the grid alone) much of this view is empty.
    bare = observed_background(obs, cam, (tf.wall(),), (board,), max_nodes=tf.W * tf.H, complete_room=False)
    t_bare = _cast(bare.surface, origin, dirs)
    assert ok.mean() > np.isfinite(t_bare).mean() + 0.08
    room = _room_distance(hit, _closing_walls(obs, cam))
    assert np.all(room < 0.015)  # (the floor-wall corner is cut by a triangle)
    assert np.mean(_true_surface_distance(hit) < 0.015) > 0.5  # mostly the floor and the wall seen


def test_texture_atlas_holds_the_photo_with_objects_inpainted(built):
    obs, board, cam, bg = built
    tex = bg.surface.texture.image_rgb
    seen = bg.surface_observed
    # The grid's texture coordinates are the nodes' image positions inside the atlas's photo.
    p, u, v = _camera_coords(cam, bg.surface.vertices_m[seen])
    uv = bg.surface.uv[seen]
    col, row = uv[:, 0] * tex.shape[1] - 0.5, uv[:, 1] * tex.shape[0] - 0.5
    c0, r0 = np.round(col - u).astype(int), np.round(row - v).astype(int)
    assert len(set(c0)) == 1 and len(set(r0)) == 1
    photo = tex[r0[0] : r0[0] + tf.H, c0[0] : c0[0] + tf.W]
    np.testing.assert_array_equal(photo[~board.mask], obs.rgb[~board.mask])
    inside = photo[tf.BOARD_ROWS, tf.BOARD_COLS].reshape(-1, 3).astype(int)
    assert np.mean(inside[:, 0] - inside[:, 1]) < 40  # no red board left: the room's colours


def test_texture_keeps_the_full_resolution_photo():
    """A photo analysed downscaled (Observation.rgb_full) is textured at its stored resolution."""
    import dataclasses

    obs, board = tf.observation()
    full = np.repeat(np.repeat(obs.rgb, 3, axis=0), 3, axis=1)
    big = dataclasses.replace(obs, rgb_full=full)
    bg = observed_background(big, tf.camera(), (tf.wall(),), (board,), complete_room=False)
    tex = bg.surface.texture.image_rgb
    assert tex.shape == full.shape
    mask_full = np.repeat(np.repeat(board.mask, 3, axis=0), 3, axis=1)
    np.testing.assert_array_equal(tex[~mask_full], full[~mask_full])


def test_pack_atlas_keeps_the_photo_at_the_top_left_and_every_image_whole():
    """The photo (first image) starts at (pad, pad) even beside a taller plane texture, and every
    image is found unchanged at the position returned."""
    from perception.room_surfaces import pack_atlas

    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (s, t, 3), dtype=np.uint8) for s, t in ((20, 30), (50, 10), (5, 40), (20, 20))]
    atlas, pos = pack_atlas(images)
    assert pos[0] == (2, 2)
    for im, (r, c) in zip(images, pos):
        assert np.array_equal(atlas[r : r + im.shape[0], c : c + im.shape[1]], im)


def test_a_hole_in_the_depth_over_a_doorway_continues_what_was_seen_through_it():
    """A sensor frame without depth in its top rows (its border) over a doorway in the wall,
    through which the next room's wall was measured 1.5 m further: the hole over the doorway
    lies on that far wall, not on the room's wall across the doorway; the hole over the rest of
    the wall lies on the wall (slambook_ch5_diningroom_frame5's top rows over its doorway)."""
    import dataclasses

    obs, _ = tf.observation()
    cam = tf.camera()
    d = tf.rays_cam() @ cam.world_from_camera[:3, :3].T
    depth = tf.room_depth()
    doorway = (slice(10, 60), slice(10, 45))
    beyond_m = tf.WALL_X_M + 1.5
    depth[doorway] = beyond_m / d[doorway][..., 0]
    depth[:10] = 0.0  # the sensor's border: no depth
    obs = dataclasses.replace(obs, depth_m=depth.astype(np.float32))
    bg = observed_background(obs, cam, (tf.wall(),), (), max_nodes=tf.W * tf.H)
    origin, dirs = _pixel_rays(cam)
    t = _cast(bg.surface, origin, dirs).reshape(tf.H, tf.W)
    x_hit = origin[0] + dirs.reshape(tf.H, tf.W, 3)[..., 0] * t
    top = slice(1, 9)
    over_doorway = x_hit[top, 14:41]
    over_wall = x_hit[top, 60:150]
    assert np.all(np.abs(over_doorway - beyond_m) < 0.05), np.round(over_doorway.min(), 2)
    assert np.all(np.abs(over_wall - tf.WALL_X_M) < 0.05), np.round(over_wall.max(), 2)
