"""Objects' unseen sides (generation.texture): textured from the object's own seen material, not
by the photo smeared along the viewing rays."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from generation.texture import MATERIAL, SEEN, face_sources, photo_textured
from scene_builder.bench.clutter import box_asset
from scene_builder.frames import pose, rot_z
from scene_builder.model import GeneratedAsset
from tests import twin_fixtures as tf

BLUE = (20, 40, 230)


@pytest.fixture(scope="module")
def textured():
    """The fixture's red board as the front of a 0.4 m deep box, its silhouette outlined in blue
    (piping, a dark frame: what an object's boundary pixels often are)."""
    import dataclasses

    obs, board = tf.observation()
    rgb = obs.rgb.copy()
    ring = board.mask & ~ndimage.binary_erosion(board.mask, iterations=2)
    rgb[ring] = BLUE
    obs = dataclasses.replace(obs, rgb=rgb)
    board = dataclasses.replace(board, colors_rgb=rgb[board.mask])
    cam = tf.camera()
    centre = board.points_world_m.mean(axis=0)
    # The board's size: 60 x 40 pixels at 2 m with a 120 px focal length (its plane leans 15 deg).
    asset = box_asset("board_1", (0.4, 1.0, 0.68))
    world_from_asset = pose(rot_z(0.0), [centre[0] + 0.2, centre[1], centre[2] - 0.34])
    generated = GeneratedAsset(asset, world_from_asset, board.points_world_m)
    return photo_textured(generated, board, obs, cam), generated, obs, board, cam


def _texels_on_faces(visual, faces, n=25):
    """Texture colours at n barycentric points of each given face."""
    tex = visual.texture.image_rgb
    rng = np.random.default_rng(0)
    w = rng.dirichlet(np.ones(3), size=n)  # (n, 3)
    uv = np.einsum("sk,fkc->fsc", w, visual.uv[visual.faces[faces]]).reshape(-1, 2)
    px = np.clip(np.floor(uv * [tex.shape[1], tex.shape[0]]).astype(int), 0, [tex.shape[1] - 1, tex.shape[0] - 1])
    return tex[px[:, 1], px[:, 0]].astype(int)


def test_hidden_sides_carry_the_seen_material_not_the_outline(textured):
    out, generated, obs, board, cam = textured
    part = generated.asset.parts[0]
    camera_from_asset = np.linalg.inv(cam.world_from_camera) @ generated.world_from_asset
    source = face_sources(part.visual.vertices_m, part.visual.faces, camera_from_asset, cam.intrinsics, board.mask, obs.depth_m.astype(np.float64))
    normals = np.cross(*(part.visual.vertices_m[part.visual.faces][:, k] - part.visual.vertices_m[part.visual.faces][:, 0] for k in (1, 2)))
    front = normals[:, 0] < -0.5 * np.linalg.norm(normals, axis=1)  # facing -X, the camera
    assert np.all(source[front] == SEEN) and np.all(source[~front] == MATERIAL)
    # The textured mesh: the same surface, faces re-indexed; find the hidden ones by their normals.
    vis = out.asset.parts[0].visual
    tri = vis.vertices_m[vis.faces]
    n2 = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    hidden = ~(n2[:, 0] < -0.5 * np.linalg.norm(n2, axis=1))
    colours = _texels_on_faces(vis, np.flatnonzero(hidden))
    blue = (colours[:, 2] > 150) & (colours[:, 0] < 100)
    red = (colours[:, 0] > 150) & (colours[:, 2] < 100)
    # The seen surface is red inside a blue outline; hidden sides are red like it, not streaks of
    # the outline (the sides seen edge-on project onto the outline).
    assert blue.mean() < 0.02 and red.mean() > 0.95
    # The front keeps the photo: outline and all.
    front_colours = _texels_on_faces(vis, np.flatnonzero(~hidden), n=200)
    assert ((front_colours[:, 2] > 150) & (front_colours[:, 0] < 100)).any()


def test_textured_mesh_keeps_the_geometry(textured):
    out, generated, *_ = textured
    a, b = generated.asset.parts[0].visual, out.asset.parts[0].visual
    np.testing.assert_allclose(np.sort(a.vertices_m[a.faces].reshape(-1, 9), axis=0), np.sort(b.vertices_m[b.faces].reshape(-1, 9), axis=0))
    assert b.uv.shape == (len(b.vertices_m), 2) and np.all((b.uv >= 0) & (b.uv <= 1))


def test_hidden_faces_take_the_colour_of_the_nearest_seen_face_turned_the_same_way():
    """A mattress's top seen only at its front: its hidden back half takes the seen top's colour,
    while the underside (turned away) and a face beyond DONOR_RADIUS_M keep the material swatch."""
    from generation.texture import DONOR_RADIUS_M, near_seen_donors

    def quad(x0, y0, size, z=0.0, up=True):
        a, b, c, d = (np.array(p, dtype=float) for p in ((x0, y0, z), (x0 + size, y0, z), (x0 + size, y0 + size, z), (x0, y0 + size, z)))
        return [(a, b, c), (a, c, d)] if up else [(a, c, b), (a, d, c)]

    top = [t for i in range(6) for t in quad(0.1 * i, 0.0, 0.1)]  # a strip 0.6 m long, facing +Z
    under = quad(0.0, 0.0, 0.1, z=-0.2, up=False)  # facing -Z, right under the seen faces
    far = quad(0.6 + DONOR_RADIUS_M + 0.1, 0.0, 0.1)  # facing +Z, past the radius
    corners = np.array(top + under + far)
    source = np.full(len(corners), MATERIAL)
    source[:4] = SEEN  # the first 0.2 m of the top
    donor = near_seen_donors(corners, source)
    assert np.all(donor[:4] == -1)  # the photo textures these
    # Every hidden top face takes a seen top face, the nearest one (faces 2-3 are at x 0.1-0.2).
    assert np.all(np.isin(donor[4:12], [2, 3]))
    assert np.all(donor[12:14] == -1) and np.all(donor[14:] == -1)


def test_hidden_faces_take_the_seen_colour_around_their_donor_not_one_speck():
    """The board's surface runs on 0.35 m past its mask (hidden: a finely triangulated plane, as
    a shell made from sensor depth is). The seen board is red and black in alternate pixels
    (a fine grain): each hidden face takes the colour around its donor's centre, the same dark
    red for all, not the one pixel under it (black or red, half and half)."""
    import dataclasses

    from generation.texture import MATERIAL, face_sources

    obs, board = tf.observation()
    rgb = obs.rgb.copy()
    rr, cc = np.nonzero(board.mask)
    speck = (rr + cc) % 2 == 0
    rgb[rr[speck], cc[speck]] = 0
    obs = dataclasses.replace(obs, rgb=rgb)
    board = dataclasses.replace(board, colors_rgb=rgb[board.mask])
    cam = tf.camera()
    # The plane z = 2 m of the camera frame (the board's), 2 cm triangles, from inside the mask
    # (x -0.45..0.49 m) to 0.35 m past its right edge; the asset frame is the camera's.
    xs, ys = np.arange(-0.45, 0.85, 0.02), np.arange(0.05, 0.65, 0.02)
    gx, gy = np.meshgrid(xs, ys)
    v = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, tf.BOARD_DEPTH_M)], axis=1)
    i = np.arange(gx.size).reshape(gx.shape)[:-1, :-1].ravel()
    nx = len(xs)
    faces = np.concatenate([np.stack([i, i + nx, i + 1], 1), np.stack([i + 1, i + nx, i + nx + 1], 1)])  # facing -z, the camera
    asset = box_asset("board_1", (0.1, 0.1, 0.1))
    part = asset.parts[0]
    part = dataclasses.replace(part, visual=dataclasses.replace(part.visual, vertices_m=v, faces=faces.astype(np.int64), uv=None, texture=None, vertex_colors_rgba=None))
    asset = dataclasses.replace(asset, parts=(part,))
    generated = GeneratedAsset(asset, cam.world_from_camera, board.points_world_m)
    source = face_sources(v, faces, np.eye(4), cam.intrinsics, board.mask, obs.depth_m.astype(np.float64))
    hidden_before = v[faces].mean(axis=1)[:, 0] > 0.55
    assert np.all(source[hidden_before] == MATERIAL) and (source == SEEN).sum() > 100
    out = photo_textured(generated, board, obs, cam).asset.parts[0].visual
    tri = out.vertices_m[out.faces]
    hidden = tri.mean(axis=1)[:, 0] > 0.55
    colours = _texels_on_faces(out, np.flatnonzero(hidden), n=5)
    seen_mean = rgb[board.mask].mean(axis=0)  # (105, 15, 15): red and black, half and half
    assert np.all(np.abs(colours - seen_mean).max(axis=1) < 25)


def _top_seen(height_below_camera_m: float, near_m: float, far_m: float, size_m: float = 0.8):
    """A horizontal top (camera frame = asset frame, OpenCV: +y down) ``height_below_camera_m``
    under a 500 px camera, from ``near_m`` to ``far_m`` ahead, ``size_m`` wide, as two faces
    facing up; its mask and exact depth. Returns (face sources, faces' corners)."""
    from scene_builder.model import CameraIntrinsics

    w, h = 640, 480
    k = CameraIntrinsics(500.0, 500.0, (w - 1) / 2.0, (h - 1) / 2.0, w, h, "flag")
    y = height_below_camera_m
    v = np.array([[-size_m / 2, y, near_m], [size_m / 2, y, near_m], [size_m / 2, y, far_m], [-size_m / 2, y, far_m]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])  # counter-clockwise seen from above (-y)
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    ry = (vv - k.cy_px) / k.fy_px
    rx = (uu - k.cx_px) / k.fx_px
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(ry > 0, y / ry, np.inf)
    mask = (z >= near_m) & (z <= far_m) & (np.abs(rx * z) <= size_m / 2)
    depth = np.where(mask, z, 0.0)
    return face_sources(v, faces, np.eye(4), k, mask, depth), v[faces]


def test_a_top_seen_at_a_grazing_angle_keeps_the_photo_an_edge_on_one_does_not():
    """A mattress 0.7 m under the camera, 2.5-4 m ahead, is seen 74-80 degrees from its normal,
    at most 4 cm per pixel: the photo shows it, it is textured from the photo (it was left to the
    material swatch at more than 75 degrees). The same top 0.1 m under the camera (86-88
    degrees, 15-20 cm per pixel) is a sliver of pixels: not textured from them."""
    seen, _ = _top_seen(0.7, 2.5, 4.0)
    assert np.all(seen == SEEN)
    edge_on, _ = _top_seen(0.1, 2.5, 4.0)
    assert np.all(edge_on == MATERIAL)


def test_the_swatch_comes_from_the_objects_dominant_material_not_across_two():
    """A white mattress (the top 45 rows) over a dark frame (35 rows): the largest square of the
    whole silhouette straddles both, and tiled it stripes every hidden side; the swatch is taken
    from the white, which holds most of the object."""
    from generation.texture import material_swatch

    rgb = np.zeros((90, 90, 3), dtype=np.uint8)
    rgb[5:50, 5:85] = (235, 235, 240)
    rgb[50:85, 5:85] = (40, 30, 30)
    rng = np.random.default_rng(0)
    rgb = np.clip(rgb.astype(int) + rng.integers(-6, 7, rgb.shape), 0, 255).astype(np.uint8)  # a little grain
    mask = np.zeros((90, 90), dtype=bool)
    mask[5:85, 5:85] = True
    swatch = material_swatch(rgb, mask, 0.01, 0.8)
    assert swatch.shape == (128, 128, 3)
    assert swatch.min() > 180  # all white: no row of the dark frame in it


def test_hidden_faces_take_a_donor_on_their_own_surface_not_a_parallel_one_nearer():
    """A mattress top (z = 0) seen only at its far end (x 0-0.2 m), hidden behind a footboard
    whose top rail (z = 0.15 m, seen) lies nearer to the hidden part: the hidden top takes the
    seen mattress, not the rail; a sliver on neither surface takes the nearest seen face turned
    its way."""
    from generation.texture import near_seen_donors

    def quad(x0, y0, size, z=0.0):
        a, b, c, d = (np.array(p, dtype=float) for p in ((x0, y0, z), (x0 + size, y0, z), (x0 + size, y0 + size, z), (x0, y0 + size, z)))
        return [(a, b, c), (a, c, d)]

    mattress = [t for i in range(6) for t in quad(0.1 * i, 0.0, 0.1)]  # x 0-0.6 m at z = 0
    rail = [t for i in range(2) for t in quad(0.6 + 0.05 * i, 0.0, 0.05, z=0.15)]  # x 0.6-0.7 m, 15 cm higher
    between = quad(0.6, 0.0, 0.02, z=0.075)  # a sliver of the rounded edge between the two
    corners = np.array(mattress + rail + between)
    source = np.full(len(corners), MATERIAL)
    source[:4] = SEEN  # the mattress's far 0.2 m
    source[12:16] = SEEN  # the rail
    donor = near_seen_donors(corners, source)
    # faces 4-11: the hidden mattress x 0.2-0.6 m; the rail is nearer to those at x 0.4-0.6 m.
    assert np.all(np.isin(donor[4:12], [0, 1, 2, 3]))
    # On neither surface (7.5 cm off both): the nearest seen face turned its way, the rail.
    assert np.all(np.isin(donor[16:], [12, 13, 14, 15]))


def test_a_face_behind_the_objects_own_front_is_not_seen_though_the_depth_is_near():
    """A bed's footboard (a panel 3.0 m away) in front of its mattress's face (3.1 m): the depth
    observed over the footboard is within the depth tolerance of the mattress's face (14 cm at
    3 m), but the footboard hides it; a ray cast against the object's own surface tells."""
    from generation.texture import self_visibility
    from scene_builder.model import CameraIntrinsics

    w, h = 320, 240
    k = CameraIntrinsics(300.0, 300.0, (w - 1) / 2.0, (h - 1) / 2.0, w, h, "flag")

    def panel(x0, x1, y0, y1, z):  # facing the camera (-z), counter-clockwise seen from it
        v = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], dtype=float)
        return v, np.array([[0, 2, 1], [0, 3, 2]])

    front_v, front_f = panel(-0.3, 0.3, -0.3, 0.3, 3.0)
    strips = [panel(a, b, -0.3, 0.3, 3.1) for a, b in ((-0.9, -0.3), (-0.3, 0.3), (0.3, 0.9))]
    back_v = np.concatenate([v for v, _ in strips])
    back_f = np.concatenate([f + 4 * i for i, (_, f) in enumerate(strips)])
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    x, y = (uu - k.cx_px) / k.fx_px, (vv - k.cy_px) / k.fy_px
    in_front = (np.abs(x * 3.0) <= 0.3) & (np.abs(y * 3.0) <= 0.3)
    in_back = (np.abs(x * 3.1) <= 0.9) & (np.abs(y * 3.1) <= 0.3)
    mask = in_front | in_back
    depth = np.where(in_front, 3.0, np.where(in_back, 3.1, 0.0))
    without = face_sources(back_v, back_f, np.eye(4), k, mask, depth)
    assert np.all(without == SEEN)  # the depth test alone takes the hidden middle strip as seen
    visible = self_visibility([(front_v, front_f), (back_v, back_f)], np.eye(4))
    with_rays = face_sources(back_v, back_f, np.eye(4), k, mask, depth, visible)
    assert np.all(with_rays[2:4] != SEEN)  # the middle strip, behind the footboard
    assert np.all(with_rays[[0, 1, 4, 5]] == SEEN)  # the strips beside it are in view
    assert np.all(face_sources(front_v, front_f, np.eye(4), k, mask, depth, visible) == SEEN)


def test_a_swatch_square_showing_structure_gives_a_flat_colour_a_grain_is_tiled():
    """A dark top (another material) over light bands 16 cm wide, two greys of one noisy
    material (a chair's frame before the floor seen through it): the square cut from the bands
    shows structure, and mirror-tiled it is a kaleidoscope: the material's median colour instead.
    The same two greys alternating every centimetre are a grain: kept as texture."""
    from generation.texture import material_swatch

    rng = np.random.default_rng(0)
    cols = np.arange(140)
    mask = np.ones((140, 140), dtype=bool)
    for period, flat in ((16, True), (1, False)):
        img = np.zeros((140, 140, 3))
        img[:40] = 20
        img[40:] = np.where((cols // period) % 2 == 0, 205, 140)[None, :, None] + rng.normal(0, 12, (100, 140, 1))
        sw = material_swatch(np.clip(img, 0, 255).astype(np.uint8), mask, 0.01, 1.4)
        assert (np.ptp(sw.reshape(-1, 3), axis=0).max() == 0) == flat
