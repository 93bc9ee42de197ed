"""The static background: every pixel that no movable object explains, as one textured mesh.

What was observed but is not a movable object (floor, walls, ceiling, counters, shelves,
built-ins, clutter too small or unclear to be an object) stays in the twin as static geometry,
so that the twin rendered from the photo's camera looks like the photo and objects can rest on
what was seen under them.

Method:

1. **A grid over the image.** Nodes at the pixel corners of every ``stride``-th pixel (so the
   mesh covers the whole image: the outer nodes lie on the image border), ``stride`` chosen so
   that the grid has at most about :data:`MAX_NODES` nodes. A node's depth is its pixel's depth.
2. **Holes filled.** Nodes on a movable object (its mask dilated by one node: edge pixels mix
   object and background) and nodes with no depth are filled with what lies behind: the first of
   the floor and wall planes that the node's ray meets beyond the object's observed depth;
   otherwise the depth inpainted from the surrounding background (Navier-Stokes inpainting,
   OpenCV), never in front of the object. A node without depth next to what was measured
   behind the plane its ray meets (a doorway, a window: the sensor's border or range cut it off)
   lies on the surface seen through that opening instead (:func:`_through_openings`). No node,
   filled or observed, lies under the floor:
   one whose depth puts it there (a depth error: the camera cannot see through the floor)
   moves along its ray onto the floor plane.
3. **Triangles** between neighbouring nodes, counter-clockwise seen from the camera. A triangle
   spanning a depth jump larger than :data:`MAX_DEPTH_RATIO` (an occluding edge) would be a
   "rubber sheet" from the near surface to the far one; instead its near corners are copied to
   the far corner's depth, so the far surface continues under the near one's edge: seen from
   the camera there is no crack, seen from elsewhere no sheet (``keep_stretched`` keeps the
   sheets).
4. **Texture**: the photo at full resolution (``Observation.photo_rgb``), with the pixels of
   movable objects inpainted from
   their surroundings (so that what an object hides looks plausible when it is moved); a node's
   ``uv`` is its image position (see :mod:`scene_builder.model` for the convention).

Everything is in the world frame (``camera.world_from_camera``).
"""

from __future__ import annotations

import numpy as np

from scene_builder.frames import transform_points
from scene_builder.model import Background, Camera, Observation, PerceivedObject, Plane, Texture, TriangleMesh

__all__ = ["GRAZING_DEG", "GRAZING_DEPTH_RATIO", "MAX_NODES", "MAX_DEPTH_RATIO", "fill_depth_behind", "grid_stride", "observed_background", "plane_depths", "plane_labels", "stretched_faces"]

#: The grid has at most about this many nodes (one per ``stride`` x ``stride`` pixels).
MAX_NODES = 100_000
#: Triangles whose corner depths differ by more than this ratio span an occluding edge; so do
#: triangles whose depths differ by more than GRAZING_DEPTH_RATIO seen more than GRAZING_DEG
#: edge-on (a chair 10 % in front of the wall behind it).
MAX_DEPTH_RATIO = 1.15
GRAZING_DEPTH_RATIO = 1.04
GRAZING_DEG = 84.0
#: Background filled in behind an object lies at least this far behind the object's surface:
#: more than generation sets an object's faces back from its observed front (a refrigerator's
#: doors stand 4 cm behind the fronts of its handles, which the fit puts at the observed points;
#: at 2 cm the background hid the doors from the photo's camera, coco128_000000000338).
BEHIND_MARGIN_M = 0.05
#: Filled depth never exceeds this multiple of the farthest observed depth (rays that meet no
#: plane and no observation, e.g. through a window).
MAX_FILL_FACTOR = 1.5
#: Plane points this far outside the room's footprint still fill a node (m).
FOOTPRINT_MARGIN_M = 0.1
#: A node without depth continues an opening in the plane its ray meets (a doorway, a window)
#: when its nearest observed node, at most this share of the grid's long side away, was
#: measured more than OPENING_RATIO times the plane's depth along its own ray.
OPENING_REACH = 0.1
OPENING_RATIO = 1.1
#: The floor, z = 0 (world frame): nothing of the background lies under it.
FLOOR = Plane(np.array([0.0, 0.0, 1.0]), 0.0, "floor")
#: Colour inpainting runs on an image of at most this many pixels on its long side, and is
#: upsampled into the masked pixels of the full-resolution texture.
INPAINT_MAX_SIDE_PX = 1024


def grid_stride(width_px: int, height_px: int, max_nodes: int = MAX_NODES) -> int:
    """Pixels per grid cell so that the grid has at most about ``max_nodes`` nodes."""
    return max(1, int(np.ceil(np.sqrt(width_px * height_px / float(max_nodes)))))


def plane_depths(rays_cam: np.ndarray, camera: Camera, planes: list[Plane]) -> np.ndarray:
    """(P, N) planar depth at which each of the (N, 3) camera rays (z = 1) meets each plane
    (inf when it does not, or behind the camera). Rays are scaled so planar depth = ray length
    factor."""
    r = camera.world_from_camera[:3, :3]
    c = camera.world_from_camera[:3, 3]
    d_world = rays_cam @ r.T  # (N, 3): world direction per unit planar depth
    out = np.full((len(planes), len(rays_cam)), np.inf)
    for k, plane in enumerate(planes):
        denom = d_world @ plane.normal
        dist = float(plane.normal @ c + plane.offset_m)  # camera's signed distance to the plane
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -dist / denom
        ok = (denom < -1e-9) & (t > 0)
        out[k, ok] = t[ok]
    return out


def fill_depth_behind(
    depth_m: np.ndarray,
    need: np.ndarray,
    lower_m: np.ndarray,
    rays_cam: np.ndarray,
    camera: Camera,
    walls: tuple[Plane, ...],
    footprint=None,
) -> np.ndarray:
    """Depth (h, w) with the ``need`` nodes filled.

    depth_m: (h, w) float observed depth (0 = none). need: (h, w) bool nodes to fill.
    lower_m: (h, w) float, the least depth a filled node may take (an object's depth + margin,
    or 0). rays_cam: (h, w, 3) camera-frame rays with z = 1. footprint: the room's floor polygon
    (shapely, world XY) or None: plane points outside it do not count. A node takes the nearest floor/wall
    plane intersection beyond ``lower_m`` when there is one within reach, else the inpainted
    depth of the surrounding background (clamped to ``lower_m``).
    """
    import cv2

    h, w = depth_m.shape
    out = depth_m.astype(np.float64).copy()
    known = (depth_m > 0) & ~need
    far = float(depth_m[known].max()) if np.any(known) else 10.0
    cap = MAX_FILL_FACTOR * far
    idx = np.flatnonzero(need)
    if len(idx) == 0:
        return out
    planes = [FLOOR, *walls]
    t = plane_depths(rays_cam.reshape(-1, 3)[idx], camera, planes)  # (P, n)
    t_floor = t[0].copy()
    low = lower_m.reshape(-1)[idx]
    t = np.where(t > low[None, :], t, np.inf)
    if footprint is not None:
        # Only where the room is: a plane met outside the room's footprint (the floor beyond a
        # wall that was not found) is not what lies behind.
        import shapely

        region = footprint.buffer(FOOTPRINT_MARGIN_M)
        r_world = rays_cam.reshape(-1, 3)[idx] @ camera.world_from_camera[:3, :3].T
        c = camera.world_from_camera[:3, 3]
        for p in range(len(planes)):
            fin = np.isfinite(t[p])
            if np.any(fin):
                hit = c + r_world[fin] * t[p, fin, None]
                row = t[p]
                row[np.flatnonzero(fin)[~shapely.contains_xy(region, hit[:, 0], hit[:, 1])]] = np.inf
    best = t.min(axis=0)
    hit = np.isfinite(best) & (best <= cap)
    best = _through_openings(best, hit, np.argmin(t, axis=0), idx, depth_m, known, rays_cam, camera, planes, cap)
    flat = out.reshape(-1)
    flat[idx[hit]] = best[hit]
    rest = np.zeros(h * w, dtype=bool)
    rest[idx[~hit]] = True
    rest = rest.reshape(h, w)
    if np.any(rest):
        source = np.where(known | (need & ~rest), out, 0.0)
        if np.any(source > 0):
            # OpenCV's inpainting wants the holes marked and a float32 single-channel image.
            holes = (rest | (source <= 0)).astype(np.uint8)
            filled = cv2.inpaint(source.astype(np.float32), holes, 5, cv2.INPAINT_NS).astype(np.float64)
        else:
            filled = np.full((h, w), 2.5)
        filled = np.where(np.isfinite(filled) & (filled > 0), filled, far)
        out[rest] = np.minimum(np.maximum(filled[rest], lower_m[rest]), cap)
    # Nothing filled lies below the floor: a node's depth stops where its ray meets the floor
    # (inpainting across a far, dark region can otherwise bend the surface metres under it).
    # (At an object's floor contact its lower bound can lie past the floor by the margin; the
    # floor still wins there: the object hides that node.)
    under = np.isfinite(t_floor) & (flat[idx] > t_floor)
    flat[idx[under]] = t_floor[under]
    return out


def _through_openings(best: np.ndarray, hit: np.ndarray, first: np.ndarray, idx: np.ndarray, depth_m: np.ndarray, known: np.ndarray,
                      rays_cam: np.ndarray, camera: Camera, planes: list[Plane], cap: float) -> np.ndarray:
    """``best`` (the plane depth of each filled node ``idx``) where a node without depth continues
    an opening: its nearest observed node (within OPENING_REACH of the grid's long side) was
    measured more than OPENING_RATIO behind the plane the node's ray meets (``first``), so the
    plane has a doorway or a window there and the node lies on the surface seen through it,
    taken parallel to that plane through the observed point.

    The case: a depth sensor's frame has no depth along its border and past its range. On
    slambook_ch5_diningroom_frame5 the top rows over a doorway, where the next room's wall was
    measured 7 m away, took the room's back wall 1.2 m nearer, and a view from another pose saw
    that wall across the doorway."""
    from scipy import ndimage

    h, w = depth_m.shape
    hole = (depth_m.reshape(-1)[idx] <= 0) & hit
    if not np.any(hole) or not np.any(known):
        return best
    dist, (ni, nj) = ndimage.distance_transform_edt(~known, return_indices=True)
    near = (ni * w + nj).reshape(-1)[idx]
    close = hole & (dist.reshape(-1)[idx] <= OPENING_REACH * max(h, w))
    if not np.any(close):
        return best
    r = camera.world_from_camera[:3, :3]
    c = camera.world_from_camera[:3, 3]
    rays = rays_cam.reshape(-1, 3)
    out = best.copy()
    for p, plane in enumerate(planes):
        sel = np.flatnonzero(close & (first == p))
        if len(sel) == 0 or plane.kind == "floor":  # (nothing is seen through the floor)
            continue
        k = near[sel]
        t_k = plane_depths(rays[k], camera, [plane])[0]
        d_k = depth_m.reshape(-1)[k]
        through = np.isfinite(t_k) & (d_k > OPENING_RATIO * t_k)
        if not np.any(through):
            continue
        sel, k, d_k = sel[through], k[through], d_k[through]
        x_k = c + (rays[k] * d_k[:, None]) @ r.T  # the observed points seen through the opening
        d_i = rays[idx[sel]] @ r.T
        denom = d_i @ plane.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t_i = ((x_k - c) @ plane.normal) / denom
        ok = np.isfinite(t_i) & (t_i > out[sel]) & (t_i <= cap)
        out[sel[ok]] = t_i[ok]
    return out


def _inpaint_colour(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The photo with ``mask`` pixels (H, W) inpainted (Telea) from their surroundings; the
    inpainting runs at most INPAINT_MAX_SIDE_PX on the long side and is upsampled into the
    masked pixels only (the rest keeps the photo's full resolution)."""
    import cv2

    if not np.any(mask):
        return rgb
    h, w = mask.shape
    scale = min(1.0, INPAINT_MAX_SIDE_PX / float(max(h, w)))
    if scale < 1.0:
        size = (max(1, int(round(w * scale))), max(1, int(round(h * scale))))
        small = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
        small_mask = cv2.resize(mask.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST)
        small_mask = cv2.dilate(small_mask, np.ones((3, 3), np.uint8))
        painted = cv2.inpaint(small, small_mask, 5, cv2.INPAINT_TELEA)
        painted = cv2.resize(painted, (w, h), interpolation=cv2.INTER_LINEAR)
    else:
        painted = cv2.inpaint(np.ascontiguousarray(rgb), mask.astype(np.uint8), 5, cv2.INPAINT_TELEA)
    out = rgb.copy()
    out[mask] = painted[mask]
    return out


def plane_labels(points_world_m: np.ndarray, depth_m: np.ndarray, rays_cam: np.ndarray, camera: Camera, planes: list[Plane], hidden: np.ndarray, cap_m: float) -> np.ndarray:
    """(h, w) int: per pixel the index into ``planes`` of the room plane it shows, -1 for none.

    points_world_m: (h, w, 3) observed points; depth_m: (h, w) (0 = none); rays_cam: (h, w, 3)
    camera rays with z = 1; hidden: (h, w) bool pixels of objects and removed people (they show
    no plane). A pixel with depth shows the plane it lies on within the depth noise
    (:func:`perception.room.inlier_threshold_m`; the floor also takes what lies under it, a depth
    error); one without depth shows the first plane its ray meets within ``cap_m``.
    """
    from perception.room import inlier_threshold_m

    h, w = depth_m.shape
    out = np.full((h, w), -1, dtype=np.int64)
    if not planes:
        return out
    has = (depth_m > 0) & ~hidden
    thr = inlier_threshold_m(depth_m)
    dist = np.stack([points_world_m @ p.normal + p.offset_m for p in planes])  # (P, h, w)
    near = np.abs(dist) < thr[None]
    near[0] |= (dist[0] < 0) & (planes[0].kind == "floor")
    best = np.argmin(np.where(near, np.abs(dist), np.inf), axis=0)
    on = has & near.any(axis=0)
    out[on] = best[on]
    none = (depth_m <= 0) & ~hidden
    if np.any(none):
        t = plane_depths(rays_cam[none], camera, planes)
        first = np.argmin(t, axis=0)
        ok = np.isfinite(t.min(axis=0)) & (t.min(axis=0) <= cap_m)
        idx = np.full(first.shape, -1)
        idx[ok] = first[ok]
        out[none] = idx
    return out


def observed_background(
    observation: Observation,
    camera: Camera,
    walls: tuple[Plane, ...],
    objects: tuple[PerceivedObject, ...],
    max_depth_m: float = 10.0,
    keep_stretched: bool = False,
    max_nodes: int = MAX_NODES,
    removed: np.ndarray | None = None,
    extra_planes: tuple[Plane, ...] = (),
    complete_room: bool = True,
) -> Background:
    """The static background of an observation (see the module docstring).

    removed: None, or (H, W) bool pixels of people and animals: like an object's, they are filled
    with what lies behind them and their colour is inpainted (:mod:`perception.people`).
    extra_planes: more of the room's planes (world frame) for its completion: the ceiling (normal
    down) and walls seen only in part (``perception.room.completion_planes``).
    complete_room: add the room's planes where the photo does not show them
    (:mod:`perception.room_surfaces`); False keeps the grid alone (grid faces hidden behind
    objects included).

    Returns a :class:`Background` with the textured surface mesh in the world frame and no
    collision geometry yet (the layout adds it once the objects are placed).
    """
    from scipy import ndimage

    from perception import room_surfaces

    rgb = observation.rgb
    h, w = rgb.shape[:2]
    k = observation.intrinsics
    s = grid_stride(w, h, max_nodes)
    nu, nv = int(np.ceil(w / s)) + 1, int(np.ceil(h / s)) + 1
    u = np.linspace(-0.5, w - 0.5, nu)
    v = np.linspace(-0.5, h - 0.5, nv)
    ui = np.clip(np.round(u).astype(int), 0, w - 1)
    vi = np.clip(np.round(v).astype(int), 0, h - 1)
    planes = [FLOOR, *walls, *extra_planes]
    side = tuple(walls) + tuple(p for p in extra_planes if p.kind == "wall")
    ceiling = next((p for p in extra_planes if p.kind == "ceiling"), None)

    depth = np.asarray(observation.depth_m, dtype=np.float64)
    depth = np.where((depth > 0) & (depth < max_depth_m), depth, 0.0)
    obj_px = np.zeros((h, w), dtype=bool) if removed is None else np.asarray(removed, dtype=bool).copy()
    for o in objects:
        obj_px |= o.mask
    # Which room plane each pixel shows (the grid snaps those nodes onto it; the completed planes
    # leave out what the grid draws of them).
    pu, pv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    px_rays = np.stack([(pu - k.cx_px) / k.fx_px, (pv - k.cy_px) / k.fy_px, np.ones_like(pu)], axis=-1)
    px_world = (px_rays * depth[..., None]) @ camera.world_from_camera[:3, :3].T + camera.world_from_camera[:3, 3]
    far = float(depth.max()) if np.any(depth > 0) else 10.0
    shown = plane_labels(px_world, depth, px_rays, camera, planes, obj_px, MAX_FILL_FACTOR * far)
    seen_pts = px_world[depth > 0]
    footprint = room_surfaces.room_footprint(seen_pts, camera.world_from_camera[:2, 3], side) if complete_room else None
    # Object depth at each node (for the "behind" bound): the nearest object pixel of the cell.
    node_depth = depth[np.ix_(vi, ui)]
    valid = node_depth > 0
    on_obj = obj_px[np.ix_(vi, ui)]
    node_obj = ndimage.binary_dilation(on_obj, iterations=1)
    need = node_obj | ~valid
    # Behind the object on its own nodes; around it (edge pixels mix object and background)
    # anywhere from a little in front of the node's own depth.
    lower = np.where(on_obj & valid, node_depth + BEHIND_MARGIN_M, np.where(valid, 0.9 * node_depth, 0.2))
    if np.any(node_obj & ~valid):
        # Object nodes without depth: behind the object's median depth at least.
        obj_depth = depth[obj_px & (depth > 0)]
        med = float(np.median(obj_depth)) if len(obj_depth) else 0.2
        lower = np.where(node_obj & ~valid, med + BEHIND_MARGIN_M, lower)
    uu, vv = np.meshgrid(u, v)
    rays = np.stack([(uu - k.cx_px) / k.fx_px, (vv - k.cy_px) / k.fy_px, np.ones_like(uu)], axis=-1)
    filled = fill_depth_behind(np.where(valid, node_depth, 0.0), need, lower, rays, camera, tuple(planes[1:]), footprint)
    t_planes = plane_depths(rays.reshape(-1, 3), camera, planes).reshape(len(planes), nv, nu)
    # Observed nodes on a room plane lie on it exactly (the plane is the fit of many noisy points).
    node_shown = shown[np.ix_(vi, ui)]
    snap = valid & ~node_obj & (node_shown >= 0)
    if np.any(snap):
        t_snap = np.take_along_axis(t_planes, np.maximum(node_shown, 0)[None], axis=0)[0]
        filled = np.where(snap & np.isfinite(t_snap), t_snap, filled)
    # Nothing observed lies under the floor either: the camera cannot see through it, so such a
    # node is a depth error (a Kinect v2 frame of a dark carpet, emsanet_sample: a fifth of its
    # floor nodes 5-25 cm under the fitted floor, where the drawn floor showed through as dark
    # patches). It moves along its own ray onto the floor: its pixel is unchanged.
    t_floor = t_planes[0]
    filled = np.where(np.isfinite(t_floor) & (filled > t_floor), t_floor, filled)
    # Hidden nodes filled by a room plane: the completed planes draw those.
    on_plane = np.isclose(t_planes, filled[None], rtol=1e-9, atol=1e-9).any(axis=0)
    hidden_plane = (node_obj & on_plane).ravel()

    pts_cam = rays * filled[..., None]
    verts = transform_points(camera.world_from_camera, pts_cam.reshape(-1, 3))
    ids = np.arange(nu * nv).reshape(nv, nu)
    a, b = ids[:-1, :-1].ravel(), ids[:-1, 1:].ravel()
    c, d = ids[1:, :-1].ravel(), ids[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, c, b], axis=1), np.stack([b, c, d], axis=1)])
    uv = np.stack([(uu.ravel() + 0.5) / w, (vv.ravel() + 0.5) / h], axis=1)
    observed = (valid & ~node_obj).ravel()
    if complete_room:
        faces = faces[~hidden_plane[faces].all(axis=1)]
    if not keep_stretched:
        same_plane = snap.ravel() & (node_shown.ravel() >= 0)
        plane_of = np.where(same_plane, node_shown.ravel(), -1)
        flat = (plane_of[faces] >= 0).all(axis=1) & (plane_of[faces] == plane_of[faces][:, :1]).all(axis=1)
        # A hidden node filled by a plane lies on it too (the far side of an object's edge).
        fill_of = np.where(on_plane, np.argmin(np.abs(t_planes - filled[None]), axis=0), -1).ravel()
        plane_of = np.where(plane_of >= 0, plane_of, fill_of)
        verts, faces, uv, observed = _tuck_stretched(verts, faces, uv, observed, rays.reshape(-1, 3), filled.ravel(), camera, flat, plane_of, planes)
    verts, faces, uv, observed = _drop_unused(verts, faces, uv, observed)
    photo = observation.photo_rgb  # full resolution when the analysis ran downscaled
    if photo.shape[:2] != (h, w):
        import cv2

        obj_full = cv2.resize(obj_px.astype(np.uint8), (photo.shape[1], photo.shape[0]), interpolation=cv2.INTER_NEAREST) > 0
    else:
        obj_full = obj_px
    painted = _inpaint_colour(photo, obj_full)
    if not complete_room:
        surface = TriangleMesh(verts, faces, uv=np.clip(uv, 0.0, 1.0), texture=Texture("background", painted))
        return Background(surface=surface, surface_observed=observed)
    top = float(-ceiling.offset_m / ceiling.normal[2]) if ceiling is not None else max(room_surfaces.MIN_WALL_TOP_M, float(np.quantile(seen_pts[:, 2], 0.995)) if len(seen_pts) else 0.0)
    # What the grid draws of the planes: not the pixels next to objects (their nodes are filled
    # behind and their faces dropped; edge pixels mix colours too).
    near_obj = ndimage.binary_dilation(obj_px, iterations=2 * s + 1) if np.any(obj_px) else obj_px
    drawn = np.where(near_obj, -1, shown)
    # The sides of the room where no wall was found are closed just past what was seen (their
    # planes come after the observed ones: no pixel is labelled with them).
    forward_xy = camera.world_from_camera[:2, 2]
    enclosing = room_surfaces.room_footprint(seen_pts, camera.world_from_camera[:2, 3], side, forward_xy, enclose=True)
    closing = room_surfaces.closing_walls(enclosing, side, forward_xy)
    extra = room_surfaces.plane_surfaces((*planes, *closing), camera, drawn, depth, photo, enclosing, top, np.where(depth > 0, drawn, -1))
    atlas, pos = room_surfaces.pack_atlas([painted] + [e.texture_rgb for e in extra])
    ah, aw = atlas.shape[:2]

    def to_atlas(uv_img: np.ndarray, i: int, size: tuple[int, ...]) -> np.ndarray:
        r0, c0 = pos[i]
        return np.column_stack([(c0 + np.clip(uv_img[:, 0], 0.0, 1.0) * size[1]) / aw, (r0 + np.clip(uv_img[:, 1], 0.0, 1.0) * size[0]) / ah])

    all_v, all_f, all_uv, all_obs = [verts], [faces], [to_atlas(uv, 0, painted.shape)], [observed]
    n = len(verts)
    for i, e in enumerate(extra, start=1):
        all_v.append(e.vertices_m)
        all_f.append(e.faces + n)
        all_uv.append(to_atlas(e.uv, i, e.texture_rgb.shape))
        all_obs.append(np.zeros(len(e.vertices_m), dtype=bool))
        n += len(e.vertices_m)
    surface = TriangleMesh(np.concatenate(all_v), np.concatenate(all_f), uv=np.concatenate(all_uv), texture=Texture("background", atlas))
    return Background(surface=surface, surface_observed=np.concatenate(all_obs), closed_sides=len(closing))


def _drop_unused(verts, faces, uv, observed):
    """The mesh without the vertices no face uses (indices renumbered)."""
    used = np.zeros(len(verts), dtype=bool)
    used[faces.ravel()] = True
    if used.all():
        return verts, faces, uv, observed
    new = np.cumsum(used) - 1
    return verts[used], new[faces], uv[used], observed[used]


def stretched_faces(verts: np.ndarray, faces: np.ndarray, depth: np.ndarray, camera: Camera) -> np.ndarray:
    """(F,) bool: the triangles that span an occluding edge (rubber sheets): corner depths
    (``depth``, per vertex) differ by more than :data:`MAX_DEPTH_RATIO`, or by more than
    :data:`GRAZING_DEPTH_RATIO` on a triangle seen edge-on (its normal more than
    :data:`GRAZING_DEG` from the viewing ray). Neighbouring grid nodes are a few pixels apart: a
    real surface whose depth changes by 4 % over them is seen at more than 80 degrees, and one
    seen at more than GRAZING_DEG from the camera is a jump between two surfaces."""
    z = depth[faces]
    ratio = z.max(axis=1) / np.maximum(z.min(axis=1), 1e-9)
    tri = verts[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ray = tri.mean(axis=1) - camera.world_from_camera[:3, 3]
    cos = np.abs(np.einsum("ij,ij->i", n, ray)) / np.maximum(np.linalg.norm(n, axis=1) * np.linalg.norm(ray, axis=1), 1e-12)
    return (ratio > MAX_DEPTH_RATIO) | ((ratio > GRAZING_DEPTH_RATIO) & (cos < np.cos(np.radians(GRAZING_DEG))))


def _tuck_stretched(verts, faces, uv, observed, rays, depth, camera: Camera, flat: np.ndarray | None = None, plane_of: np.ndarray | None = None, planes: list[Plane] | None = None):
    """Replace each triangle spanning an occluding edge (:func:`stretched_faces`) by a copy on the
    far surface (new vertices on the same rays; see the module docstring): on the room plane its
    farthest corner lies on (``plane_of``: (V,) index into ``planes``, -1 none), else at that
    corner's depth. flat: (F,) bool faces on one room plane (never an edge). Returns the new
    vertices (V', 3), faces, uv (V', 2) and observed flags (V',)."""
    z = depth[faces]
    far = z.max(axis=1)
    stretched = stretched_faces(verts, faces, depth, camera)
    if flat is not None:
        stretched &= ~flat
    if not np.any(stretched):
        return verts, faces, uv, observed
    sf = faces[stretched]
    n0 = len(verts)
    new_ids = n0 + np.arange(sf.size).reshape(-1, 3)
    new_depth = np.repeat(far[stretched], 3)
    r = rays[sf.ravel()]
    if plane_of is not None and planes:
        far_node = sf[np.arange(len(sf)), np.argmax(z[stretched], axis=1)]
        on = np.repeat(plane_of[far_node], 3)
        for k in np.unique(on[on >= 0]):
            sel = on == k
            t = plane_depths(r[sel], camera, [planes[int(k)]])[0]
            new_depth[sel] = np.where(np.isfinite(t) & (t >= depth[sf.ravel()][sel]), t, new_depth[sel])
    # Not pushed under the floor: a near floor node tucked back to a far corner's depth stops
    # where its ray meets the floor.
    new_depth = np.minimum(new_depth, plane_depths(r, camera, [FLOOR])[0])
    new_cam = r * new_depth[:, None]
    new_verts = transform_points(camera.world_from_camera, new_cam)
    faces = faces.copy()
    faces[stretched] = new_ids
    return (
        np.concatenate([verts, new_verts]),
        faces,
        np.concatenate([uv, uv[sf.ravel()]]),
        np.concatenate([observed, np.zeros(sf.size, dtype=bool)]),
    )
