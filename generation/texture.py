"""Photo textures for generated assets: what the camera saw of an object carries the photo; what
it did not see carries the object's own material, never the photo stretched along the rays.

Each visual-mesh face, placed at the pose where the object was seen
(``GeneratedAsset.world_from_asset``), is one of:

* **seen**: it faces the camera (within :data:`MAX_VIEW_DEG`, or a grazing top one photo pixel
  spans at most :data:`MAX_TEXEL_M` of), its corners project onto the object's mask at the
  depth observed there, and the object's own surface does not hide them (a ray cast). Its
  texture coordinates are its corners' pixels in a crop of the photo around the mask (the photo
  projected from the input camera).
* **mirrored**: hidden, but its mirror image across the asset's left-right plane (asset frame
  ``y = 0``: the asset's front is +X, so this swaps its left and right sides; furniture is
  built symmetric about it) is seen: it takes the photo where its mirror image was seen (the
  hidden flank of a bed shows the seen flank).
* **near-seen**: hidden or seen edge-on (a grazing top, the jittered faces of a shell made from
  sensor depth), but a seen (or mirrored) face of the same part within :data:`DONOR_RADIUS_M`
  turns the same way (normals within :data:`DONOR_MAX_DEG`) on the same surface (its plane
  within :data:`DONOR_PLANE_M`; else the nearest turned its way within :data:`DONOR_NEAR_M`):
  it takes the photo's colour at the centre of the nearest such face, averaged over
  :data:`DONOR_SPOT_M` around it (a blurred copy of the crop), one texel for the whole face (no
  stretching), so the hidden half of a mattress's top stays the mattress's white instead of the
  swatch of the dark frame.
* **material**: the rest (backs, undersides, faces seen edge-on, whose projection would smear
  the silhouette's boundary pixels along them: the "streaked flank"). They carry a swatch of the
  object's own texture: the largest square seen inside the mask, scaled to its size in metres
  and mirror-tiled, mapped by the face's dominant axis (box mapping), so the grain keeps its
  scale on every side. The square is taken inside the object's most common colour (its dominant
  material: a bed's mattress, not the mattress's edge over its dark frame).

The texture is one image per object: the crop (pixels outside the mask filled from the nearest
mask pixel, for filtering at the silhouette) beside the swatch and the blurred crop. The
coordinates are fixed at the observed pose (the texture moves with the object). The crop keeps the photo's full resolution
(``Observation.photo_rgb``).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scene_builder.frames import transform_points
from scene_builder.model import Camera, GeneratedAsset, Observation, PerceivedObject, Texture

__all__ = ["CROP_MARGIN_PX", "MAX_VIEW_DEG", "SWATCH_PX", "donor_colours", "face_sources", "material_swatch", "near_seen_donors", "object_texture", "photo_textured", "self_visibility"]

#: The crop reaches this many pixels past the mask's bounding box (texture filtering reads a
#: little around each texel).
CROP_MARGIN_PX = 4
#: A face seen more edge-on than this (angle between its normal and the ray to the camera) is
#: not textured from the photo: its pixels would be smeared across it ...
MAX_VIEW_DEG = 75.0
#: ... unless it is seen within GRAZING_MAX_DEG and one photo pixel spans at most MAX_TEXEL_M
#: (metres) of it, along the rays: a bed's mattress seen from 1.3 m high and 2.5-4 m away is seen
#: 75-81 degrees from its normal, at 3-4.5 cm per pixel (sunrgbd_imvotenet_000003). It is what
#: the photo shows of that top, coarse along the rays; left to the material swatch, the top of
#: a white mattress was striped with its dark frame. A flank seen edge-on (88 degrees, 20 cm
#: per pixel at 3 m) still is not textured from the photo.
GRAZING_MAX_DEG = 84.0
MAX_TEXEL_M = 0.05
#: A face corner counts as seen where the depth observed at its pixel is within this of its own
#: (metres, plus DEPTH_TOL_REL of the depth): the shapes' seen surface lies on the observed depth.
DEPTH_TOL_M = 0.05
DEPTH_TOL_REL = 0.03
#: ... and where no other part of the object's own surface lies in front of it along the ray by
#: more than SELF_TOL_M plus SELF_TOL_REL of the distance.
SELF_TOL_M = 0.03
SELF_TOL_REL = 0.01
#: Side of the material swatch (texels) and the least size of the square it is taken from.
SWATCH_PX = 128
MIN_PATCH_PX = 4
#: The swatch comes from the object's dominant material: the largest of this many colour
#: clusters of its seen pixels, when it holds at least MIN_MATERIAL_SHARE of them.
MATERIAL_CLUSTERS = 2
MIN_MATERIAL_SHARE = 0.25
MATERIAL_GRID_PX = 160
#: ... unless its colours span less than this (CIELAB units: a just noticeable difference is
#: about 2): one material.
ONE_COLOUR_LAB = 3.0
#: A pixel of the dominant material's cluster whose colour is farther than this many times the
#: cluster's median distance (CIELAB, at least OUTLIER_MIN_LAB) from its median colour is a knob,
#: a handle or a highlight, not the material.
OUTLIER_SPREAD = 3.0
OUTLIER_MIN_LAB = 10.0
#: A swatch square smaller than this share of the object's extent would repeat many times over
#: it (a wallpaper of one knob): the material is its median colour instead.
MIN_TILE_SHARE = 0.1
#: ... and so does a square whose blurred lightness spreads more than this (CIELAB standard
#: deviation): it shows the object's structure, not its material, and mirror-tiled it became a
#: kaleidoscope of legs and floor (sunrgbd_total3d_demo_2's chair seen from behind: 15.3; the
#: other 31 objects of four photos measured 0.0-4.5).
MAX_SWATCH_SPREAD_LAB = 8.0
#: Texels between the crop and the swatch in the texture image.
GAP_PX = 2
SEEN, MIRRORED, MATERIAL = 0, 1, 2
#: Points on each face (barycentric weights: the centroid, and towards each corner) whose
#: visibility decides the face's texture source; a face is seen where SEEN_SHARE of them are.
SAMPLE_WEIGHTS = np.array([[1 / 3, 1 / 3, 1 / 3], [0.7, 0.15, 0.15], [0.15, 0.7, 0.15], [0.15, 0.15, 0.7]])
SEEN_SHARE = 0.75
#: A face the photo does not texture takes the colour of the nearest seen face within this
#: distance (asset frame, between face centres) whose normal is within DONOR_MAX_DEG of its own
#: (of its DONOR_NEIGHBOURS nearest seen faces). 1 m: the middle of a bed's top hidden behind its
#: footboard lies more than 0.5 m from the seen part of that top, and took the dark frame's swatch.
DONOR_RADIUS_M = 1.0
DONOR_MAX_DEG = 40.0
#: ... and whose plane passes within this (m) of its centre: the same surface, not a parallel one
#: nearby (sunrgbd_000017's mattress top hidden behind the footboard took the footboard's top
#: rail, 10-20 cm higher, in a patchwork of brown and white).
DONOR_PLANE_M = 0.06
#: ... or, where no seen face on its surface is within DONOR_RADIUS_M, the nearest one turned
#: its way within this distance (m).
DONOR_NEAR_M = 0.5
DONOR_NEIGHBOURS = 16
#: A near-seen face's colour is the photo averaged over about this much of the object (metres, the
#: sigma of a Gaussian) around its donor's centre: one photo pixel there is a speck of the grain,
#: a highlight or a seam, and faces taking single pixels made a patchwork of flat colours.
DONOR_SPOT_M = 0.03


def object_texture(rgb: np.ndarray, mask: np.ndarray, name: str) -> tuple[Texture, tuple[int, int]]:
    """The photo crop of one object: the (h, w, 3) crop of ``rgb`` around ``mask`` ((H, W) bool),
    pixels outside the mask (eroded by one pixel: edge pixels mix in the background) replaced by
    the nearest mask pixel's colour. Returns the crop as a texture and its top-left (row, column)."""
    from scipy import ndimage

    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if len(rows) == 0:
        raise ValueError(f"object {name}: empty mask, nothing to texture")
    h, w = mask.shape
    r0, r1 = max(0, rows[0] - CROP_MARGIN_PX), min(h, rows[-1] + 1 + CROP_MARGIN_PX)
    c0, c1 = max(0, cols[0] - CROP_MARGIN_PX), min(w, cols[-1] + 1 + CROP_MARGIN_PX)
    crop = np.array(rgb[r0:r1, c0:c1])
    m = mask[r0:r1, c0:c1]
    core = ndimage.binary_erosion(m)
    source = core if core.sum() >= max(4, 0.25 * m.sum()) else m
    # The nearest source pixel of every pixel (a Euclidean distance transform's indices).
    _, (ri, ci) = ndimage.distance_transform_edt(~source, return_indices=True)
    filled = crop[ri, ci]
    return Texture(name, filled), (int(r0), int(c0))


def donor_colours(crop_rgb: np.ndarray, metres_per_px: float) -> tuple[np.ndarray, int]:
    """The crop blurred over :data:`DONOR_SPOT_M` (Gaussian sigma, at ``metres_per_px``, the
    photo's pixel size on the object) and shrunk by the returned factor (about a third of the
    sigma: the blur leaves nothing finer), as (h, w, 3) uint8."""
    import cv2

    sigma = max(1.0, DONOR_SPOT_M / max(metres_per_px, 1e-9))
    sigma = min(sigma, 0.25 * max(crop_rgb.shape[:2]))
    blurred = cv2.GaussianBlur(np.ascontiguousarray(crop_rgb), (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    factor = max(1, int(sigma / 3.0))
    h, w = crop_rgb.shape[:2]
    small = cv2.resize(blurred, (max(1, -(-w // factor)), max(1, -(-h // factor))), interpolation=cv2.INTER_AREA)
    return small, factor


def material_swatch(crop_rgb: np.ndarray, crop_mask: np.ndarray, metres_per_px: float, extent_m: float, size_px: int = SWATCH_PX) -> np.ndarray:
    """(size_px, size_px, 3) uint8: the object's own texture covering ``extent_m`` metres.

    The largest square inside the object's dominant material (:func:`dominant_region`: the mask,
    eroded by two pixels, where the silhouette's edge mixes in the background and outlines, less
    what is not of its most common colour), resampled from ``metres_per_px`` (the photo's pixel
    size on the object) to the swatch's scale, mirror-tiled; the median colour of that material
    where no square of MIN_PATCH_PX, or of MIN_TILE_SHARE of ``extent_m``, fits, or where the
    square shows structure rather than material (:data:`MAX_SWATCH_SPREAD_LAB`)."""
    import cv2
    from scipy import ndimage

    core = ndimage.binary_erosion(crop_mask, iterations=2)
    if not core.any():
        core = crop_mask
    region = dominant_region(crop_rgb, core, metres_per_px)
    r, cy, cx = _largest_square(region)
    if region is not core and 2 * r + 1 < MIN_PATCH_PX:  # no square of the material: the whole mask
        region = core
        r, cy, cx = _largest_square(region)
    median = np.median(crop_rgb[region], axis=0).astype(np.uint8)
    fits = 2 * r + 1 >= MIN_PATCH_PX and (2 * r + 1) * metres_per_px >= MIN_TILE_SHARE * extent_m
    patch = crop_rgb[cy - r : cy + r + 1, cx - r : cx + r + 1]
    if not fits or _structured(patch, metres_per_px):
        return np.broadcast_to(median, (size_px, size_px, 3)).copy()
    side = int(np.clip(round((2 * r + 1) * metres_per_px * size_px / max(extent_m, 1e-6)), MIN_PATCH_PX, size_px))
    patch = cv2.resize(np.ascontiguousarray(patch), (side, side), interpolation=cv2.INTER_AREA)
    tile = np.concatenate([patch, patch[:, ::-1]], axis=1)
    tile = np.concatenate([tile, tile[::-1]], axis=0)
    reps = int(np.ceil(size_px / tile.shape[0]))
    return np.tile(tile, (reps, reps, 1))[:size_px, :size_px].copy()


def _structured(patch_rgb: np.ndarray, metres_per_px: float) -> bool:
    """Whether a swatch square shows the object's structure rather than its material: its CIELAB
    lightness, blurred over DONOR_SPOT_M (a grain or a weave averages out), spreads more than
    MAX_SWATCH_SPREAD_LAB (standard deviation)."""
    import cv2
    from skimage.color import rgb2lab

    sigma = max(1.0, DONOR_SPOT_M / max(metres_per_px, 1e-9))
    blurred = cv2.GaussianBlur(np.ascontiguousarray(patch_rgb), (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    return float(rgb2lab(blurred)[..., 0].std()) > MAX_SWATCH_SPREAD_LAB


def dominant_region(crop_rgb: np.ndarray, core: np.ndarray, metres_per_px: float) -> np.ndarray:
    """(h, w) bool: the pixels of ``core`` of the object's most common material: its colours
    (CIELAB, blurred over DONOR_SPOT_M so that a grain or a pattern is one colour) split in
    MATERIAL_CLUSTERS by k-means, the largest cluster, opened by a pixel; ``core`` itself where
    that leaves less than MIN_MATERIAL_SHARE of it (:func:`material_swatch` goes back to ``core``
    where it leaves no square of MIN_PATCH_PX). Pixels of that
    cluster whose own colour lies more than OUTLIER_SPREAD times the cluster's median distance from
    its median colour are left out.

    A bed is a white mattress on a dark frame: the largest square of its whole mask straddled the
    two (sunrgbd_imvotenet_000003: the mattress's edge over the footboard), and tiled, it striped
    the bed's hidden back and flanks white and black."""
    import cv2
    from scipy import ndimage
    from scipy.cluster.vq import ClusterError, kmeans2
    from skimage.color import rgb2lab

    if core.sum() < 4 * MATERIAL_CLUSTERS:
        return core
    sigma = max(1.0, DONOR_SPOT_M / max(metres_per_px, 1e-9))
    blurred = cv2.GaussianBlur(np.ascontiguousarray(crop_rgb), (0, 0), min(sigma, 0.1 * max(crop_rgb.shape[:2])), borderType=cv2.BORDER_REFLECT)
    # The colours are told apart on every STEP-th pixel (at most MATERIAL_GRID_PX a side; the
    # blurred colours vary slowly), the region then drawn back at the crop's resolution.
    h, w = core.shape
    step = max(1, int(np.ceil(max(h, w) / MATERIAL_GRID_PX)))
    few = core[::step, ::step]
    if few.sum() < 4 * MATERIAL_CLUSTERS:
        return core
    lab = rgb2lab(blurred[::step, ::step][few]).astype(np.float64)
    if float(np.ptp(lab, axis=0).max()) < ONE_COLOUR_LAB:
        return core  # one colour: one material
    try:
        # (a fixed seed and k-means++ start: the same photo gives the same swatch)
        _, assign = kmeans2(lab, MATERIAL_CLUSTERS, minit="++", seed=np.random.default_rng(0), missing="raise")
    except ClusterError:  # a cluster came out empty: no second colour to tell apart
        return core
    main = assign == int(np.argmax(np.bincount(assign, minlength=MATERIAL_CLUSTERS)))
    # Its own pixels far from its usual colour (the blur hid them) are no part of it: knobs,
    # handles, highlights (a sideboard's swatch tiled its brass knobs into rows of dots).
    raw = rgb2lab(crop_rgb[::step, ::step][few]).astype(np.float64)
    off = np.linalg.norm(raw - np.median(raw[main], axis=0), axis=1)
    usual = max(OUTLIER_MIN_LAB, OUTLIER_SPREAD * float(np.median(off[main])))
    coarse = np.zeros_like(few)
    coarse[few] = main & (off <= usual)
    region = core & np.repeat(np.repeat(coarse, step, axis=0), step, axis=1)[:h, :w]
    region = ndimage.binary_opening(region)
    return core if region.sum() < MIN_MATERIAL_SHARE * core.sum() else region


def _largest_square(mask: np.ndarray) -> tuple[int, int, int]:
    """(r, row, column): the largest square of side 2 r + 1 inside ``mask``, by its centre (the
    chessboard distance to the nearest pixel outside it, the image's border counted outside)."""
    from scipy import ndimage

    dist = ndimage.distance_transform_cdt(np.pad(mask, 1), metric="chessboard")[1:-1, 1:-1]
    cy, cx = np.unravel_index(int(np.argmax(dist)), dist.shape)
    return int(dist.max()) - 1, int(cy), int(cx)


def _corner_seen(p_cam: np.ndarray, k, grown: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
    """(N,) bool: camera-frame points that project onto ``grown`` (the object's mask at analysis
    resolution, dilated by a pixel) where the observed depth matches theirs (or none was
    observed)."""
    h, w = grown.shape
    z = p_cam[:, 2]
    zs = np.where(z > 1e-3, z, 1.0)
    col = np.round(k.fx_px * p_cam[:, 0] / zs + k.cx_px).astype(np.int64)
    row = np.round(k.fy_px * p_cam[:, 1] / zs + k.cy_px).astype(np.int64)
    inside = (z > 1e-3) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
    out = np.zeros(len(p_cam), dtype=bool)
    ci, ri = col[inside], row[inside]
    d = depth_m[ri, ci]
    out[inside] = grown[ri, ci] & ((d <= 0) | (np.abs(d - z[inside]) < DEPTH_TOL_M + DEPTH_TOL_REL * z[inside]))
    return out


def _facing(tri_cam: np.ndarray, focal_px: float) -> np.ndarray:
    """(F,) bool: triangles ((F, 3, 3), camera frame, counter-clockwise seen from outside) facing
    the camera within MAX_VIEW_DEG, or within GRAZING_MAX_DEG where one photo pixel (at
    ``focal_px``) spans at most MAX_TEXEL_M of them."""
    n = np.cross(tri_cam[:, 1] - tri_cam[:, 0], tri_cam[:, 2] - tri_cam[:, 0])
    to_cam = -tri_cam.mean(axis=1)
    dist = np.linalg.norm(to_cam, axis=1)
    cos = np.einsum("ij,ij->i", n, to_cam) / np.maximum(np.linalg.norm(n, axis=1) * dist, 1e-12)
    texel_m = dist / max(focal_px, 1e-9) / np.maximum(cos, 1e-9)
    return (cos > np.cos(np.radians(MAX_VIEW_DEG))) | ((cos > np.cos(np.radians(GRAZING_MAX_DEG))) & (texel_m <= MAX_TEXEL_M))


def face_sources(vertices_asset: np.ndarray, faces: np.ndarray, camera_from_asset: np.ndarray, k, mask: np.ndarray, depth_m: np.ndarray,
                 visible=None) -> np.ndarray:
    """(F,) int per face: SEEN, MIRRORED or MATERIAL (see the module docstring). k: the
    intrinsics of ``mask`` and ``depth_m`` (analysis resolution). A face is seen where at least
    SEEN_SHARE of SAMPLE_WEIGHTS' points on it are (large faces reach past the silhouette).
    ``visible``: None or a callable mapping (N, 3) camera-frame points to (N,) bool, whether the
    object's own surface leaves them in view (:func:`self_visibility`)."""
    from scipy import ndimage

    grown = ndimage.binary_dilation(mask)
    mirror = np.array([1.0, -1.0, 1.0])
    out = np.full(len(faces), MATERIAL, dtype=np.int64)
    for kind, verts, order in ((MIRRORED, vertices_asset * mirror, [0, 2, 1]), (SEEN, vertices_asset, [0, 1, 2])):
        p = transform_points(camera_from_asset, verts)
        tri = p[faces[:, order]]
        samples = np.einsum("sk,fkc->fsc", SAMPLE_WEIGHTS, tri).reshape(-1, 3)  # (F * S, 3)
        seen_at = _corner_seen(samples, k, grown, depth_m)
        if visible is not None:
            seen_at &= visible(samples)
        seen = seen_at.reshape(len(faces), -1).mean(axis=1)
        out[(seen >= SEEN_SHARE) & _facing(tri, 0.5 * (k.fx_px + k.fy_px))] = kind
    return out


def self_visibility(meshes_asset, camera_from_asset: np.ndarray):
    """A callable: (N, 3) camera-frame points on the object's surface -> (N,) bool, true where the
    ray from the camera reaches the point before any other part of that surface (``meshes_asset``:
    (vertices, faces) pairs in the asset frame, all its parts), within SELF_TOL_M plus
    SELF_TOL_REL of the distance. Open3D's ``RaycastingScene``.

    The observed depth alone let a mattress's top hidden behind its bed's own footboard count as
    seen when it lay within the depth tolerance behind the footboard (17 cm at 4 m): it was
    textured with the footboard (sunrgbd_000017_mmdet3d)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    for v, f in meshes_asset:
        if len(f):
            vc = transform_points(camera_from_asset, np.asarray(v, dtype=np.float64)).astype(np.float32)
            scene.add_triangles(o3d.core.Tensor(vc), o3d.core.Tensor(np.asarray(f, dtype=np.uint32)))

    def visible(points_cam: np.ndarray) -> np.ndarray:
        p = np.asarray(points_cam, dtype=np.float64)
        dist = np.linalg.norm(p, axis=1)
        rays = np.concatenate([np.zeros_like(p), p / np.maximum(dist, 1e-12)[:, None]], axis=1).astype(np.float32)
        hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)
        return hit >= dist - (SELF_TOL_M + SELF_TOL_REL * dist)

    return visible


def _box_uv(tri_asset: np.ndarray, lo: np.ndarray, extent_m: float) -> np.ndarray:
    """(F, 3, 2) swatch coordinates in [0, 1] of triangles (F, 3, 3) in the asset frame: the two
    coordinates across each face's dominant normal axis, from the asset's low corner ``lo``."""
    n = np.cross(tri_asset[:, 1] - tri_asset[:, 0], tri_asset[:, 2] - tri_asset[:, 0])
    axis = np.argmax(np.abs(n), axis=1)
    other = np.array([[1, 2], [0, 2], [0, 1]])[axis]  # (F, 2): the two axes across the normal
    rel = (tri_asset - lo) / max(extent_m, 1e-6)
    uv = np.take_along_axis(rel, np.repeat(other[:, None, :], 3, axis=1), axis=2)
    uv[..., 1] = 1.0 - uv[..., 1]  # image rows run down, heights up
    return np.clip(uv, 0.0, 1.0)


def near_seen_donors(corners: np.ndarray, source: np.ndarray) -> np.ndarray:
    """(F,) index of the face whose photo colour each MATERIAL face of ``corners`` ((F, 3, 3),
    asset frame) takes (see the module docstring), -1 where none qualifies (and for faces the
    photo textures)."""
    from scipy.spatial import cKDTree

    out = np.full(len(corners), -1, dtype=np.int64)
    donors = np.flatnonzero(source != MATERIAL)
    takers = np.flatnonzero(source == MATERIAL)
    if len(donors) == 0 or len(takers) == 0:
        return out
    centre = corners.mean(axis=1)
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    k = min(DONOR_NEIGHBOURS, len(donors))
    dist, idx = cKDTree(centre[donors]).query(centre[takers], k=k, distance_upper_bound=DONOR_RADIUS_M)
    dist, idx = dist.reshape(len(takers), k), idx.reshape(len(takers), k)
    found = np.isfinite(dist)
    cand = donors[np.where(found, idx, 0)]  # (T, k) face indices (0 where no neighbour)
    turned = found & (np.einsum("tc,tkc->tk", n[takers], n[cand]) > np.cos(np.radians(DONOR_MAX_DEG)))
    # ... on the same surface: the taker lies near the donor's plane (a mattress's hidden top
    # takes the seen mattress, not the top rail of the footboard a few centimetres nearer); where
    # none is, a small face between two surfaces (a shell's rounded edge) takes the nearest one
    # turned its way within DONOR_NEAR_M.
    off_plane = np.abs(np.einsum("tkc,tkc->tk", n[cand], centre[takers][:, None, :] - centre[cand]))
    rows = np.arange(len(takers))
    for agree in (turned & (off_plane <= DONOR_PLANE_M), turned & (dist <= DONOR_NEAR_M)):
        first = np.argmax(agree, axis=1)  # neighbours come nearest first
        ok = agree[rows, first] & (out[takers] < 0)
        out[takers[ok]] = cand[rows, first][ok]
    return out


def photo_textured(generated: GeneratedAsset, obj: PerceivedObject, observation: Observation, camera: Camera) -> GeneratedAsset:
    """``generated`` with every visual mesh of its asset textured (see the module docstring).
    Deformables keep their colours (a MuJoCo flex carries no texture). Faces get their own
    corners where their texture sources differ (the geometry is unchanged)."""
    photo = observation.photo_rgb  # full resolution when the analysis ran downscaled
    mask = obj.mask
    scale = photo.shape[1] / observation.rgb.shape[1]
    if photo.shape[:2] != observation.rgb.shape[:2]:
        import cv2

        mask = cv2.resize(mask.astype(np.uint8), (photo.shape[1], photo.shape[0]), interpolation=cv2.INTER_NEAREST) > 0
    crop_tex, (r0, c0) = object_texture(photo, mask, generated.asset.name)
    crop = crop_tex.image_rgb
    th, tw = crop.shape[:2]
    k = camera.intrinsics.scaled(photo.shape[1], photo.shape[0]) if scale != 1.0 else camera.intrinsics
    camera_from_asset = np.linalg.inv(camera.world_from_camera) @ generated.world_from_asset
    all_v = np.concatenate([p.visual.vertices_m for p in generated.asset.parts])
    lo = all_v.min(axis=0)
    extent = float(np.max(all_v.max(axis=0) - lo))
    obs_depth = np.asarray(observation.depth_m, dtype=np.float64)
    z_obj = obs_depth[obj.mask & (obs_depth > 0)]
    z_med = float(np.median(z_obj)) if len(z_obj) else float(np.median(transform_points(camera_from_asset, all_v)[:, 2]))
    swatch = material_swatch(crop, mask[r0 : r0 + th, c0 : c0 + tw], z_med / k.fx_px, extent)
    spots, factor = donor_colours(crop, z_med / k.fx_px)
    s = swatch.shape[0]
    bx0 = tw + GAP_PX + s + GAP_PX  # the blurred crop's first column
    height, width = max(th, s), bx0 + spots.shape[1]
    image = np.zeros((height, width, 3), dtype=np.uint8)
    image[:th, :tw] = crop
    image[th:, :tw] = crop[-1:]
    image[:, tw : tw + GAP_PX] = image[:, tw - 1 : tw]
    image[:s, tw + GAP_PX : bx0 - GAP_PX] = swatch
    image[s:, tw + GAP_PX : bx0 - GAP_PX] = swatch[-1:]
    image[:, bx0 - GAP_PX : bx0] = image[:, bx0 - GAP_PX - 1 : bx0 - GAP_PX]
    image[: spots.shape[0], bx0:] = spots
    image[spots.shape[0] :, bx0:] = spots[-1:]
    texture = Texture(generated.asset.name, image)
    parts = []
    visible = self_visibility([(p.visual.vertices_m, p.visual.faces) for p in generated.asset.parts], camera_from_asset)
    for part in generated.asset.parts:
        v, f = part.visual.vertices_m, part.visual.faces
        source = face_sources(v, f, camera_from_asset, camera.intrinsics, obj.mask, obs_depth, visible)
        corners = v[f]  # (F, 3, 3)
        mirrored = np.where((source == MIRRORED)[:, None, None], corners * np.array([1.0, -1.0, 1.0]), corners)
        p = transform_points(camera_from_asset, mirrored.reshape(-1, 3))
        z = np.maximum(p[:, 2], 1e-3)
        x = k.fx_px * p[:, 0] / z + k.cx_px
        y = k.fy_px * p[:, 1] / z + k.cy_px
        uv_photo = np.stack([(x - c0 + 0.5) / width, (y - r0 + 0.5) / height], axis=1).reshape(-1, 3, 2)
        sw = _box_uv(corners, lo, extent)
        uv_swatch = np.stack([(tw + GAP_PX + sw[..., 0] * s) / width, (sw[..., 1] * s) / height], axis=-1)
        uv = np.where((source == MATERIAL)[:, None, None], uv_swatch, uv_photo)
        donor = near_seen_donors(corners, source)
        takes = donor >= 0
        # The donor's centre in the crop (texels from its left and top) -> the blurred crop.
        centre = uv_photo[donor[takes]].mean(axis=1) * [width, height] / factor
        centre = np.clip(centre, 0.5, [spots.shape[1] - 0.5, spots.shape[0] - 0.5])
        uv[takes] = ((centre + [bx0, 0.0]) / [width, height])[:, None, :]
        uv = uv.reshape(-1, 2)
        # One corner per (vertex, texture coordinate) pair.
        key = np.concatenate([f.reshape(-1, 1).astype(np.float64), np.round(uv * 1e7)], axis=1)
        _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
        inverse = inverse.reshape(-1)
        new_v = v[f.reshape(-1)[first]]
        new_uv = np.clip(uv[first], 0.0, 1.0)
        visual = dataclasses.replace(part.visual, vertices_m=new_v, faces=inverse.reshape(-1, 3).astype(np.int64), uv=new_uv, texture=texture,
                                     vertex_colors_rgba=None if part.visual.vertex_colors_rgba is None else part.visual.vertex_colors_rgba[f.reshape(-1)[first]])
        parts.append(dataclasses.replace(part, visual=visual))
    asset = dataclasses.replace(generated.asset, parts=tuple(parts))
    return dataclasses.replace(generated, asset=asset)
