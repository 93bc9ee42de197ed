"""Geometry completion of a half-observed object on a voxel grid in the asset frame.

The camera sees one side of an object. The occupancy is completed by

1. **extrusion along the viewing rays**: a voxel of the object's box is solid when the ray from
   the camera through its centre meets an observed point (within the angular sampling
   spacing of the points) at or before the voxel: what is behind a visible surface, up to the
   far side of the box, is assumed solid; rays that pass beside every observed point are free
   space. Done per voxel (a nearest-direction query), so sparse or noisy sampling of the
   surface leaves no tunnels, unlike marching rays from the observed voxels;
2. **symmetry**: mirrored about the box's mid-plane y = 0 (left-right) and, for categories that
   are symmetric front-to-back, about x = 0;
3. **closing**: a one-voxel morphological closing and hole filling (depth noise leaves pinholes);
4. **support**: every column is filled down towards the bottom of the box (nothing floats),
   stopping at the first blocked voxel;
5. **blocked space**: voxels that the camera saw through, or that hold another object's observed
   surface (``blocked``, see ``generation.visibility``), are removed last: neither symmetry nor
   support may fill space where something else was seen.
"""

from __future__ import annotations

import numpy as np

from generation.assembly import VoxelGeometry

__all__ = ["complete_occupancy", "superellipsoid_occupancy", "grid_for_box"]


def grid_for_box(size_m, resolution: int) -> tuple[tuple[int, int, int], float, np.ndarray]:
    """Grid covering the box x in [-D/2, D/2], y in [-W/2, W/2], z in [0, H] with ``resolution``
    voxels along its longest side. Returns (dims, voxel_size_m, origin_m (3,)); the grid is
    centred on the box in x and y and starts at z = 0."""
    size = np.maximum(np.asarray(size_m, dtype=np.float64), 1e-6)
    s = float(size.max()) / int(resolution)
    dims = np.maximum(np.ceil(size / s - 1e-9).astype(int), 1)
    origin = np.array([-dims[0] * s / 2.0, -dims[1] * s / 2.0, 0.0])
    return (int(dims[0]), int(dims[1]), int(dims[2])), s, origin


def complete_occupancy(
    points_m: np.ndarray,
    camera_m: np.ndarray,
    size_m,
    resolution: int,
    *,
    mirror_y: bool = True,
    mirror_x: bool = False,
    fill_down: bool = True,
    blocked=None,
    resting_m: np.ndarray | None = None,
    resting_bottom_m: np.ndarray | None = None,
    prior_boxes_m: tuple = (),
) -> VoxelGeometry:
    """Completed occupancy of an object from its observed surface points.

    points_m: (N, 3) observed points in the asset frame. camera_m: (3,) camera centre in the asset
    frame. size_m: (3,) box extents (the box spans x in [-D/2, D/2], y in [-W/2, W/2], z in
    [0, H]). resolution: voxels along the longest side. blocked: optional callable mapping (V, 3)
    asset-frame points to (V,) bool "cannot be this object" (seen free space, another object's
    surface): voxel centres it marks are never filled. resting_m: (M, 3) observed points (asset
    frame) of other objects resting on this one, with resting_bottom_m (M,) the bottom height of
    the object each belongs to: what they hide below their bottom is this object's (the back of a
    sideboard's top under the tea set standing on it), extruded along the rays like its own
    surface. prior_boxes_m: ((lo (3,), hi (3,)), ...) asset-frame boxes of a shape prior fitted
    to the object (a bed's mattress and headboard): filled too, then carved like the rest.
    Returns a :class:`VoxelGeometry`. Raises ValueError when no observed point lies in the box.
    """
    from scipy import ndimage
    from scipy.spatial import cKDTree

    dims, s, origin = grid_for_box(size_m, resolution)
    dims_a = np.array(dims)
    pts = np.asarray(points_m, dtype=np.float64)
    idx_f = (pts - origin) / s
    # points within one voxel outside the box are clamped onto it; farther ones are outliers
    near = np.all((idx_f >= -1.0) & (idx_f < dims_a + 1.0), axis=1)
    if not near.any():
        raise ValueError("complete_occupancy: no observed point lies inside the object's box")
    idx = np.clip(np.floor(idx_f[near]).astype(int), 0, dims_a - 1)
    occ = np.zeros(dims, dtype=bool)
    occ[idx[:, 0], idx[:, 1], idx[:, 2]] = True  # the observed surface itself

    cam = np.asarray(camera_m, dtype=np.float64)
    rel = pts[near] - cam
    rng_p = np.linalg.norm(rel, axis=1)  # (P,) range of each observed point
    dir_p = rel / np.maximum(rng_p[:, None], 1e-12)
    tree = cKDTree(dir_p)
    # angular spacing of the samples: the median distance to the 4th nearest neighbour direction
    k = min(5, len(dir_p))
    spacing = float(np.median(tree.query(dir_p, k=k)[0][:, -1])) if k > 1 else 0.0
    ii = [origin[a] + (np.arange(dims[a]) + 0.5) * s for a in range(3)]
    centres = np.stack(np.meshgrid(*ii, indexing="ij"), axis=-1).reshape(-1, 3)  # (V, 3)
    rel_v = centres - cam
    rng_v = np.linalg.norm(rel_v, axis=1)
    dir_v = rel_v / np.maximum(rng_v[:, None], 1e-12)
    dist, nn = tree.query(dir_v, k=1)
    # a ray hits the surface when a sample is within the sampling spacing or a voxel's angular size
    reach = np.maximum(1.5 * spacing, 0.75 * s / np.maximum(rng_v, 1e-9))
    behind = (dist <= reach) & (rng_v >= rng_p[nn] - 0.5 * s)
    occ |= behind.reshape(dims)
    if resting_m is not None and len(resting_m):
        rel_r = np.asarray(resting_m, dtype=np.float64) - cam
        rng_r = np.linalg.norm(rel_r, axis=1)
        tree_r = cKDTree(rel_r / np.maximum(rng_r[:, None], 1e-12))
        dist_r, nn_r = tree_r.query(dir_v, k=1)
        hidden = (dist_r <= reach) & (rng_v >= rng_r[nn_r] - 0.5 * s) & (centres[:, 2] < np.asarray(resting_bottom_m)[nn_r])
        occ |= hidden.reshape(dims)

    for lo, hi in prior_boxes_m:
        occ |= np.all((centres >= np.asarray(lo)) & (centres <= np.asarray(hi)), axis=1).reshape(dims)

    if mirror_y:
        occ |= occ[:, ::-1, :]
    if mirror_x:
        occ |= occ[::-1, :, :]
    occ = ndimage.binary_closing(np.pad(occ, 1), iterations=1)[1:-1, 1:-1, 1:-1] | occ
    occ = ndimage.binary_fill_holes(occ)
    stop = np.zeros(dims, dtype=bool)
    if blocked is not None:
        # Asked only where the occupancy can end up: in an occupied column, at or under its
        # highest occupied voxel (filling down and carving touch nothing else). The same answer
        # as asking everywhere, in a third to a half of the time.
        any_col = occ.any(axis=2)
        k_top = dims[2] - 1 - np.argmax(occ[:, :, ::-1], axis=2)
        ask = (any_col[:, :, None] & (np.arange(dims[2])[None, None, :] <= k_top[:, :, None])).ravel()
        stop.ravel()[ask] = np.asarray(blocked(centres[ask]), dtype=bool)
    if fill_down:
        # each occupied column is solid from its lowest occupied voxel down to the bottom of the
        # box, or to the first blocked voxel under it (another object's top, seen floor)
        any_col = occ.any(axis=2)
        k_min = np.argmax(occ, axis=2)  # first occupied index per column
        z = np.arange(dims[2])[None, None, :]
        below = z < k_min[:, :, None]
        # highest blocked voxel below the column's lowest occupied one (-1: none)
        k_stop = np.where(stop & below, z, -1).max(axis=2)
        occ |= below & (z > k_stop[:, :, None]) & any_col[:, :, None]
    if blocked is not None:
        carved = occ & ~stop
        if carved.any():
            occ = carved
    return VoxelGeometry(occ, s, origin)


def superellipsoid_occupancy(size_m, resolution: int, exponent: float = 4.0) -> VoxelGeometry:
    """Occupancy of the superellipsoid ``|x/a|^p + |y/b|^p + |z'/c|^p <= 1`` filling the box
    (a, b, c half-extents, z' from the box centre): a pillow or cushion shape."""
    dims, s, origin = grid_for_box(size_m, resolution)
    half = np.asarray(size_m, dtype=np.float64) / 2.0
    centre = np.array([0.0, 0.0, half[2]])
    ii = [origin[a] + (np.arange(dims[a]) + 0.5) * s - centre[a] for a in range(3)]
    x, y, z = np.meshgrid(*ii, indexing="ij")
    occ = np.abs(x / half[0]) ** exponent + np.abs(y / half[1]) ** exponent + np.abs(z / half[2]) ** exponent <= 1.0
    return VoxelGeometry(occ, s, origin)
