"""The room completed behind what hides it: the floor, the walls and the ceiling as textured
polygons, for the parts of them the photo does not show.

The photo shows the room's planes only between the objects and inside its frame. A twin seen
from elsewhere needs the rest: the floor under a table, the wall behind a wardrobe, the floor and
walls beside and behind the camera. :func:`plane_surfaces` builds, for each room plane, the part
of it inside the room box seen (:func:`room_footprint`) that the photo-textured background grid
(:mod:`perception.background`) does not already draw:

1. **Extent.** The floor (and the ceiling, when one was found) is the box of the observed points
   and the camera's surroundings, cut by every wall's inner half-plane; each wall runs along the
   edge of that floor from the floor up to the ceiling (or the top of what was seen, at least
   :data:`MIN_WALL_TOP_M`). The box encloses everything seen (:func:`room_footprint` with
   ``enclose``); its sides that no wall was found on are closed by walls (:func:`closing_walls`)
   just past the farthest point seen, except behind the camera.
2. **Cells.** The plane is cut into :data:`CELL_M` squares. A cell is left out where the grid
   draws the plane already (all four corners project onto pixels that show this plane) and where
   the camera saw through the plane (a corner's pixel has depth beyond it: a doorway, a window
   with depth): closing those would hide what the photo shows. The cells kept are merged into
   row runs (two triangles each), :data:`BEHIND_M` behind the plane so that where they overlap
   the grid at the edges of what it draws, the grid's photo wins.
3. **Texture, rectified.** Each plane gets its own texture on a regular grid of the plane (so it
   is not stretched by perspective), :data:`TEXEL_M` per texel (coarser for large planes, at
   most :data:`MAX_TEXTURE_SIDE_PX` per side). Texels whose pixel shows this plane take the
   photo's colour there; the rest are filled by :func:`fill_unseen`: the smooth colour inpainted
   from what was seen (lighting continues), plus the high frequencies of the largest square of
   the plane seen whole, mirror-tiled (the carpet's or the wallpaper's grain continues): the
   material's own texture, never boundary pixels stretched into the unseen.

:func:`pack_atlas` puts the photo and the plane textures side by side in one image, so the
background stays one mesh with one texture for every exporter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scene_builder.frames import transform_points
from scene_builder.model import Camera, CameraIntrinsics, Plane

__all__ = [
    "BEHIND_CAMERA_M",
    "BEHIND_M",
    "CELL_M",
    "MAX_TEXTURE_SIDE_PX",
    "MIN_WALL_TOP_M",
    "TEXEL_M",
    "closing_walls",
    "PlaneSurface",
    "fill_unseen",
    "pack_atlas",
    "plane_surfaces",
    "room_footprint",
]

#: Geometry cells of a completed plane (m).
CELL_M = 0.10
#: Texture resolution of a completed plane (m per texel), coarser where a plane's texture would
#: exceed MAX_TEXTURE_SIDE_PX on a side.
TEXEL_M = 0.01
MAX_TEXTURE_SIDE_PX = 1024
#: Completed planes lie this far behind the plane, under the grid where both draw it.
BEHIND_M = 0.003
#: The room holds the camera: the floor reaches at least this far around it (m), and at least
#: BEHIND_CAMERA_M behind it (photos of rooms are taken from inside them, rarely with the back
#: against a wall; a second camera beside the first is usually a step or two behind it).
CAMERA_MARGIN_M = 0.5
BEHIND_CAMERA_M = 1.5
#: A side of the room box with no wall found is closed by a wall there unless it lies behind the
#: camera: its outward normal more than this angle from the camera's horizontal forward.
CLOSE_MAX_ANGLE_DEG = 120.0
#: Walls without a ceiling found run at least this high (a room's height; m).
MIN_WALL_TOP_M = 2.4
#: Quantiles of the observed points that bound the room box where it limits what the room's
#: planes fill in behind objects (robust to stray far points).
BOX_QUANTILE = 0.005
#: The enclosing room box (the completed surfaces, closed by walls on its sides without one)
#: reaches this far past the farthest point seen along each axis: nothing seen, object or room,
#: may stand outside it.
BOX_CLEARANCE_M = 0.05
#: A corner is "seen through" the plane when its pixel's depth lies this far beyond it, plus
#: the depth noise (perception.room.inlier_threshold_m).
THROUGH_MARGIN_M = 0.05
#: Texels of the low-frequency fill: the inpainting runs on an image of at most this many texels
#: per side; the tile of the plane's own texture is at least this many texels wide.
LOWFREQ_SIDE_PX = 64
#: Pixels this close to the photo's border (share of its long side, at least 2) do not colour
#: the completed planes.
BORDER_SHARE = 0.005
MIN_TILE_PX = 8
#: The tile comes from texels the photo resolves: at least this many pixels per texel.
SHARP_PX_PER_TEXEL = 0.5


@dataclass(frozen=True, eq=False)
class PlaneSurface:
    """One completed plane: a mesh in the world frame with coordinates into its own texture
    (``uv`` in [0, 1], the project's convention: ``u`` right, ``v`` down the image)."""

    kind: str
    vertices_m: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    texture_rgb: np.ndarray
    seen_texels: int


def room_footprint(points_world_m: np.ndarray, camera_xy_m: np.ndarray, walls: tuple[Plane, ...], forward_xy: np.ndarray | None = None,
                   enclose: bool = False):
    """The room's floor polygon (a shapely Polygon in world XY): the box of the observed points
    (their :data:`BOX_QUANTILE` quantiles; with ``enclose``, :data:`BOX_CLEARANCE_M` past the
    farthest) and of the camera's surroundings (:data:`CAMERA_MARGIN_M` around it,
    :data:`BEHIND_CAMERA_M` behind it along the room axis nearest ``forward_xy``, the camera's
    horizontal viewing direction, when given), cut by every wall's inner half-plane (walls'
    normals point into the room)."""
    import shapely

    xy = np.asarray(points_world_m, dtype=np.float64)[:, :2]
    cam = np.asarray(camera_xy_m, dtype=np.float64)
    around = [cam - CAMERA_MARGIN_M, cam + CAMERA_MARGIN_M]
    if forward_xy is not None and np.linalg.norm(forward_xy) > 1e-9:
        # Along the room axis nearest the view direction (the box is the room's, axis-aligned:
        # a camera looking into a corner does not push the side walls out).
        f = np.asarray(forward_xy, dtype=np.float64)
        axis = np.zeros(2)
        axis[int(np.argmax(np.abs(f)))] = np.sign(f[int(np.argmax(np.abs(f)))])
        around.append(cam - BEHIND_CAMERA_M * axis)
    around = np.array(around)
    lo, hi = around.min(axis=0), around.max(axis=0)
    if len(xy):
        if enclose:
            lo = np.minimum(xy.min(axis=0) - BOX_CLEARANCE_M, lo)
            hi = np.maximum(xy.max(axis=0) + BOX_CLEARANCE_M, hi)
        else:
            lo = np.minimum(np.quantile(xy, BOX_QUANTILE, axis=0), lo)
            hi = np.maximum(np.quantile(xy, 1.0 - BOX_QUANTILE, axis=0), hi)
    poly = shapely.box(lo[0], lo[1], hi[0], hi[1])
    far = 4.0 * float(np.max(hi - lo)) + 10.0
    for w in walls:
        n = w.normal[:2] / max(np.linalg.norm(w.normal[:2]), 1e-12)
        on = -w.offset_m * n  # the point of the wall's line nearest the origin
        t = np.array([-n[1], n[0]])
        half = shapely.Polygon([on + far * t, on + far * t + far * n, on - far * t + far * n, on - far * t])
        cut = poly.intersection(half)
        if not cut.is_empty and cut.area > 0.25:  # a wall that would leave less than 0.5 m x 0.5 m is not this room's
            poly = cut
    if poly.geom_type != "Polygon":  # a cut into pieces: the piece holding the camera, else the largest
        parts = list(poly.geoms)
        inside = [p for p in parts if p.contains(shapely.Point(*cam))]
        poly = inside[0] if inside else max(parts, key=lambda p: p.area)
    return poly


def closing_walls(footprint, walls: tuple[Plane, ...], forward_xy: np.ndarray) -> tuple[Plane, ...]:
    """Walls (world frame, normals into the room) along the sides of ``footprint`` that lie on no
    wall found, except the sides behind the camera (outward normal more than
    :data:`CLOSE_MAX_ANGLE_DEG` from ``forward_xy``): the room seen ends about where what was
    seen ends, and a twin looked at from beside the photo's camera shows a wall there, not the
    void. Only completed surfaces (no collision): nothing seen says where the wall stands."""
    ring = np.asarray(footprint.exterior.coords)[:-1]
    if footprint.exterior.is_ccw is False:
        ring = ring[::-1]
    fwd = np.asarray(forward_xy, dtype=np.float64)
    fwd = fwd / max(float(np.linalg.norm(fwd)), 1e-12)
    cos_max = np.cos(np.radians(CLOSE_MAX_ANGLE_DEG))
    out = []
    for a, b in zip(ring, np.roll(ring, -1, axis=0)):
        edge = b - a
        length = float(np.linalg.norm(edge))
        if length < CELL_M:
            continue
        inward = np.array([-edge[1], edge[0]]) / length  # left of a counter-clockwise edge
        n3 = np.array([inward[0], inward[1], 0.0])
        offset = -float(inward @ a)
        on_wall = any(
            abs(float(w.normal[:2] @ a) + w.offset_m) < 1e-3 and abs(float(w.normal[:2] @ b) + w.offset_m) < 1e-3 for w in walls
        )
        if on_wall or float(-inward @ fwd) < cos_max:
            continue
        out.append(Plane(n3, offset, "wall", 0))
    return tuple(out)


def _plane_axes(plane: Plane) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(origin, e1, e2) of a plane's 2D coordinates, e1 x e2 = normal (faces built
    counter-clockwise in (e1, e2) face the room). Floor: X, Y; ceiling: X, -Y; wall: along the
    wall (horizontal), Z."""
    n = plane.normal
    origin = -plane.offset_m * n
    if plane.kind == "floor":
        return origin, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    if plane.kind == "ceiling":
        return origin, np.array([1.0, 0.0, 0.0]), np.array([0.0, -1.0, 0.0])
    e2 = np.array([0.0, 0.0, 1.0])
    e1 = np.cross(e2, n)
    e1 /= np.linalg.norm(e1)
    return origin, e1, e2


def _region(plane: Plane, footprint, top_m: float):
    """The plane's extent in its own 2D coordinates (shapely geometry; empty when none)."""
    import shapely

    if plane.kind == "floor":
        return footprint
    if plane.kind == "ceiling":
        return shapely.affinity.scale(footprint, 1.0, -1.0, origin=(0.0, 0.0))
    origin, e1, _ = _plane_axes(plane)
    far = 1e3
    line = shapely.LineString([origin[:2] - far * e1[:2], origin[:2] + far * e1[:2]])
    seg = line.intersection(footprint.buffer(1e-3))
    if seg.is_empty or seg.length < CELL_M:
        return shapely.Polygon()
    s = [float((np.asarray(c) - origin[:2]) @ e1[:2]) for c in seg.coords] if seg.geom_type == "LineString" else [
        float((np.asarray(c) - origin[:2]) @ e1[:2]) for g in seg.geoms for c in g.coords
    ]
    return shapely.box(min(s), 0.0, max(s), top_m)


def _project(camera: Camera, k: CameraIntrinsics, world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N,) column, row (analysis pixels, may lie outside) and planar depth of (N, 3) points."""
    p = transform_points(np.linalg.inv(camera.world_from_camera), world)
    z = p[:, 2]
    zs = np.where(z > 1e-6, z, 1.0)
    return k.fx_px * p[:, 0] / zs + k.cx_px, k.fy_px * p[:, 1] / zs + k.cy_px, z


def _lookup(img: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray, fill):
    """img[round(y), round(x)] where the point is in front of the camera and inside, else fill."""
    h, w = img.shape[:2]
    xi, yi = np.round(x).astype(np.int64), np.round(y).astype(np.int64)
    ok = (z > 1e-3) & (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
    out = np.full(x.shape, fill, dtype=img.dtype)
    out[ok] = img[yi[ok], xi[ok]]
    return out


def fill_unseen(image: np.ndarray, seen: np.ndarray, fallback_rgb, sharp: np.ndarray | None = None) -> np.ndarray:
    """``image`` (h, w, 3) uint8 with the texels not ``seen`` ((h, w) bool) filled from the seen
    ones: the smooth colour spread from what was seen plus the detail (the high-pass) of the
    largest seen square, mirror-tiled. sharp: (h, w) bool, the texels where the photo resolves
    the texture (at least about a pixel per texel; the square is taken there, so that the far
    floor's pixels, each smeared over many texels, do not become the tile); default ``seen``.
    ``fallback_rgb`` where nothing was seen."""
    import cv2
    from scipy import ndimage

    h, w = seen.shape
    if seen.all():
        return image
    if not seen.any():
        return np.broadcast_to(np.asarray(fallback_rgb, dtype=np.uint8), image.shape).copy()
    img = image.astype(np.float32)
    # Low frequencies: the seen texels' colour averaged onto a coarse grid, then spread by
    # normalised convolution at doubling widths (each unseen cell takes the narrowest average
    # that reaches it): lighting continues smoothly and tends to the plane's mean far from what
    # was seen, where inpainting from the border would draw its colours out in streaks.
    f = max(1, int(np.ceil(max(h, w) / LOWFREQ_SIDE_PX)))
    sh, sw = int(np.ceil(h / f)), int(np.ceil(w / f))
    pad = ((0, sh * f - h), (0, sw * f - w))
    wsum = np.pad(seen.astype(np.float32), pad).reshape(sh, f, sw, f).sum(axis=(1, 3))
    csum = np.stack([np.pad(img[..., c] * seen, pad).reshape(sh, f, sw, f).sum(axis=(1, 3)) for c in range(3)], axis=-1)
    small = csum / np.maximum(wsum[..., None], 1e-6)
    done = wsum >= 0.5 * f * f
    if not done.any():
        done = wsum > 0
    sigma = 1.0
    while not done.all():
        wb = cv2.GaussianBlur(np.where(done, wsum, 0.0).astype(np.float32), (0, 0), sigma, borderType=cv2.BORDER_CONSTANT)
        cb = cv2.GaussianBlur(np.where(done[..., None], csum, 0.0).astype(np.float32), (0, 0), sigma, borderType=cv2.BORDER_CONSTANT)
        reach = ~done & (wb > 1e-3 * f * f)
        small[reach] = cb[reach] / wb[reach, None]
        done = done | reach
        sigma *= 2.0
        if sigma > 4 * max(sh, sw):
            small[~done] = np.average(small[done], axis=0, weights=wsum[done])
            break
    low = cv2.resize(small.astype(np.float32), (sw * f, sh * f), interpolation=cv2.INTER_LINEAR)[:h, :w]
    # Detail: the high-pass of the largest square of the plane seen whole, mirror-tiled.
    synth = low
    source = seen if sharp is None else (seen & sharp)
    dist = ndimage.distance_transform_cdt(np.pad(source, 1), metric="chessboard")[1:-1, 1:-1]
    r = int(dist.max()) - 1
    if 2 * r + 1 >= MIN_TILE_PX:
        cy, cx = np.unravel_index(int(np.argmax(dist)), dist.shape)
        patch = img[cy - r : cy + r + 1, cx - r : cx + r + 1]
        detail = patch - cv2.GaussianBlur(patch, (0, 0), max(1.0, patch.shape[0] / 8.0))
        tile = np.concatenate([detail, detail[:, ::-1]], axis=1)
        tile = np.concatenate([tile, tile[::-1]], axis=0)
        reps = (int(np.ceil(h / tile.shape[0])), int(np.ceil(w / tile.shape[1])), 1)
        synth = low + np.tile(tile, reps)[:h, :w]
    out = np.where(seen[..., None], img, synth)
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


def _runs(keep: np.ndarray) -> list[tuple[int, int, int]]:
    """(row, first column, end column) of each run of True cells in a (R, C) mask."""
    runs = []
    for i in range(keep.shape[0]):
        row = np.concatenate([[False], keep[i], [False]])
        d = np.diff(row.astype(np.int8))
        starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
        runs += [(i, int(a), int(b)) for a, b in zip(starts, ends)]
    return runs


def plane_surfaces(
    planes: tuple[Plane, ...],
    camera: Camera,
    shown: np.ndarray,
    depth_m: np.ndarray,
    photo_rgb: np.ndarray,
    footprint,
    top_m: float,
    colour_from: np.ndarray | None = None,
) -> list[PlaneSurface]:
    """The completed room planes (see the module docstring).

    planes: the floor, walls and ceiling (world frame). camera: the input camera (intrinsics of
    the analysis resolution of ``shown`` and ``depth_m``). shown: (h, w) int, per pixel the index
    into ``planes`` of the plane it shows (-1: none, an object or something else). depth_m: (h, w)
    observed depth (0 = none). photo_rgb: (H, W, 3) the photo at its stored resolution (colour).
    footprint: the floor polygon (:func:`room_footprint`). top_m: the walls' top. colour_from:
    like ``shown``, the pixels whose colour the planes' textures take (default ``shown``; pixels
    without depth may show a plane to the grid, but photos often have a blank frame there).
    """
    import cv2
    import shapely

    from perception.room import inlier_threshold_m

    k = camera.intrinsics
    sx, sy = photo_rgb.shape[1] / k.width_px, photo_rgb.shape[0] / k.height_px
    seen_any = shown >= 0
    fallback = np.median(photo_rgb[cv2.resize(seen_any.astype(np.uint8), (photo_rgb.shape[1], photo_rgb.shape[0]), interpolation=cv2.INTER_NEAREST) > 0], axis=0) if seen_any.any() else np.array([128, 128, 128])
    out = []
    for idx, plane in enumerate(planes):
        region = _region(plane, footprint, top_m)
        if region.is_empty or region.area <= 0:
            continue
        origin, e1, e2 = _plane_axes(plane)
        u0, w0, u1, w1 = region.bounds
        i0, j0 = int(np.floor(u0 / CELL_M)), int(np.floor(w0 / CELL_M))
        i1, j1 = int(np.ceil(u1 / CELL_M)), int(np.ceil(w1 / CELL_M))
        nu, nw = i1 - i0, j1 - j0
        if nu <= 0 or nw <= 0:
            continue
        # Corners (nw + 1, nu + 1) of the cells, in plane coordinates and in the image.
        cu = (i0 + np.arange(nu + 1)) * CELL_M
        cw = (j0 + np.arange(nw + 1)) * CELL_M
        gu, gw = np.meshgrid(cu, cw)
        world = origin + gu.reshape(-1, 1) * e1 + gw.reshape(-1, 1) * e2
        x, y, z = _project(camera, k, world)
        covered = (_lookup(shown, x, y, z, -1) == idx).reshape(gu.shape)
        d_obs = _lookup(depth_m.astype(np.float64), x, y, z, 0.0)
        through = ((d_obs > 0) & (d_obs > z + THROUGH_MARGIN_M + inlier_threshold_m(np.maximum(z, 0.0)))).reshape(gu.shape)
        cells = shapely.box(gu[:-1, :-1].ravel(), gw[:-1, :-1].ravel(), gu[1:, 1:].ravel(), gw[1:, 1:].ravel())
        inside = shapely.intersects(cells, region).reshape(nw, nu)
        all_cov = covered[:-1, :-1] & covered[:-1, 1:] & covered[1:, :-1] & covered[1:, 1:]
        any_thr = through[:-1, :-1] | through[:-1, 1:] | through[1:, :-1] | through[1:, 1:]
        keep = inside & ~all_cov & ~any_thr
        if not keep.any():
            continue
        # Texture over the cells' bounding rectangle, rows running down e2.
        texel = max(TEXEL_M, nu * CELL_M / MAX_TEXTURE_SIDE_PX, nw * CELL_M / MAX_TEXTURE_SIDE_PX)
        tw, th = max(1, int(round(nu * CELL_M / texel))), max(1, int(round(nw * CELL_M / texel)))
        tu = cu[0] + (np.arange(tw) + 0.5) * (nu * CELL_M / tw)
        tv = cw[-1] - (np.arange(th) + 0.5) * (nw * CELL_M / th)
        gtu, gtv = np.meshgrid(tu, tv)
        tworld = origin + gtu.reshape(-1, 1) * e1 + gtv.reshape(-1, 1) * e2
        x, y, z = _project(camera, k, tworld)
        seen = (_lookup(shown if colour_from is None else colour_from, x, y, z, -1) == idx).reshape(th, tw)
        # (A texel is seen where its pixel shows the plane away from the photo's border: photos
        # often have a frame line or vignetting there.)
        border = max(2.0, BORDER_SHARE * max(k.width_px, k.height_px))
        seen &= ((x >= border) & (x <= k.width_px - 1 - border) & (y >= border) & (y <= k.height_px - 1 - border)).reshape(th, tw)
        mx = ((x + 0.5) * sx - 0.5).reshape(th, tw).astype(np.float32)
        my = ((y + 0.5) * sy - 0.5).reshape(th, tw).astype(np.float32)
        sampled = cv2.remap(np.ascontiguousarray(photo_rgb), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        # Pixels per texel along both texture axes: where the photo resolves the texels.
        gx, gy = x.reshape(th, tw), y.reshape(th, tw)
        step_c = np.hypot(np.gradient(gx, axis=1), np.gradient(gy, axis=1)) if tw > 1 else np.ones((th, tw))
        step_r = np.hypot(np.gradient(gx, axis=0), np.gradient(gy, axis=0)) if th > 1 else np.ones((th, tw))
        sharp = (np.minimum(step_c, step_r) >= SHARP_PX_PER_TEXEL).reshape(th, tw)
        texture = fill_unseen(sampled, seen, fallback, sharp)
        # The kept cells as row runs: 4 corners each, two triangles counter-clockwise in (e1, e2).
        runs = _runs(keep)
        verts, uvs, faces = [], [], []
        for n, (j, a, b) in enumerate(runs):
            quad = np.array([[cu[a], cw[j]], [cu[b], cw[j]], [cu[b], cw[j + 1]], [cu[a], cw[j + 1]]])
            verts.append(quad)
            uvs.append(np.column_stack([(quad[:, 0] - cu[0]) / (nu * CELL_M), (cw[-1] - quad[:, 1]) / (nw * CELL_M)]))
            faces += [[4 * n, 4 * n + 1, 4 * n + 2], [4 * n, 4 * n + 2, 4 * n + 3]]
        q = np.concatenate(verts)
        v3 = origin + q[:, :1] * e1 + q[:, 1:] * e2 - BEHIND_M * plane.normal
        out.append(PlaneSurface(plane.kind, v3, np.asarray(faces, dtype=np.int64), np.concatenate(uvs), texture, int(seen.sum())))
    return out


def pack_atlas(images: list[np.ndarray], pad_px: int = 2) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Shelf-pack (h, w, 3) images into one (the first, the photo, at the top left: its texels
    start at (pad_px, pad_px) whatever the others' sizes; the rest tallest first, rows left to
    right); each keeps a border of ``pad_px`` edge-replicated texels so that filtering does not
    bleed between them. Returns the atlas and each image's (row, column) of its top-left texel."""
    order = [0] + sorted(range(1, len(images)), key=lambda i: (-images[i].shape[0], i)) if images else []
    width = max(max(im.shape[1] for im in images) + 2 * pad_px, 1)
    width = max(width, int(np.ceil(np.sqrt(sum((im.shape[0] + 2 * pad_px) * (im.shape[1] + 2 * pad_px) for im in images)))))
    pos: list[tuple[int, int]] = [(0, 0)] * len(images)
    x = y = shelf = 0
    for i in order:
        h, w = images[i].shape[0] + 2 * pad_px, images[i].shape[1] + 2 * pad_px
        if x + w > width:
            x, y, shelf = 0, y + shelf, 0
        pos[i] = (y + pad_px, x + pad_px)
        x, shelf = x + w, max(shelf, h)
    atlas = np.zeros((y + shelf, width, 3), dtype=np.uint8)
    for i, im in enumerate(images):
        r, c = pos[i]
        atlas[r - pad_px : r + im.shape[0] + pad_px, c - pad_px : c + im.shape[1] + pad_px] = np.pad(im, ((pad_px, pad_px), (pad_px, pad_px), (0, 0)), mode="edge")
    return atlas, pos
