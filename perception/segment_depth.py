"""Instance segmentation from depth alone: the ``"depth-clusters"`` segmentation backend.

What is left after the floor, walls and ceiling are removed is split into objects by Euclidean
clustering: points are pooled into 2 cm voxels, voxels closer than their link radius
(:func:`link_radius_m`: :data:`LINK_RADIUS_M`, wider far away where pixels are sparse on the
surface) are linked and the connected components are the objects. scipy's KD-tree and
sparse-graph connected components rather than open3d's ``cluster_dbscan``, whose radius is one
constant. A depth discontinuity wider than the link radius separates objects.

Then:

* **support split**: when a cluster has a horizontal top layer (a desk top, a bed) with a
  separate group of points standing on it whose footprint lies inside the layer's (a monitor, a
  pillow), the group becomes its own object, unless it rises along the layer's edge or runs on
  below it (a chair's backrest, a headboard) (needs the up vector);
* **legs**: pieces standing under a cluster's top surface and reaching up to just below it
  join it (a table's legs, whose upper ends hide under the overhanging top);
* **colour**: a thing lying on a cluster's surface in another colour (a laptop, a bowl on a
  shelf board: too thin for the support split) becomes its own object (:func:`_split_by_colour`);
* **merge**: pieces too small to be objects join the nearest large cluster within
  :data:`MERGE_RADIUS_M` (a chair leg cut off by an occluder), or are dropped;
* **masks**: pixels without depth next to an object take the label of the nearest object pixel
  within a few pixels, so masks have no pin-holes; masks never overlap.

Deterministic: no random sampling.
"""

from __future__ import annotations

import numpy as np

from perception.protocols import InstanceMasks
from scene_builder.model import CameraIntrinsics

__all__ = ["DepthClusterSegmenter", "LINK_RADIUS_M", "MERGE_RADIUS_M", "VOXEL_M", "COLOUR_DELTA_E", "cluster_points", "link_radius_m"]

VOXEL_M = 0.02
LINK_RADIUS_M = 0.045
MERGE_RADIUS_M = 0.10
#: CIE Lab distance (Delta E 76) from a cluster's median colour that makes a pixel another object's
#: candidate (about 2.3 is a just-noticeable difference; 15 is a plainly different colour).
COLOUR_DELTA_E = 15.0
_LAB_WEIGHTS = np.array([1.0, 1.0, 1.0])
_LAYER_BIN_M = 0.01


def _voxelize(points: np.ndarray, voxel_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) voxel centroids and (N,) voxel index of each of the (N, 3) points."""
    keys = np.floor(points / voxel_m).astype(np.int64)
    keys -= keys.min(axis=0) if len(keys) else 0
    dims = keys.max(axis=0) + 1 if len(keys) else np.ones(3, dtype=np.int64)
    # One int64 per voxel, ordered as the rows are lexicographically: a 1-D sort, 5x faster than
    # np.unique(axis=0)'s row sort (0.8 s of a 23 s build of emsanet_sample), the same voxels.
    _, inverse = np.unique((keys[:, 0] * dims[1] + keys[:, 1]) * dims[2] + keys[:, 2], return_inverse=True)
    inverse = inverse.reshape(-1)
    counts = np.bincount(inverse)
    centroids = np.stack([np.bincount(inverse, weights=points[:, i]) for i in range(3)], axis=1) / counts[:, None]
    return centroids, inverse


def _components(centroids: np.ndarray, radius_m: np.ndarray | float) -> np.ndarray:
    """(M,) component label of each voxel centroid; two centroids are linked when closer than
    the larger of their radii (``radius_m``: scalar or (M,) metres)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    m = len(centroids)
    radius = np.broadcast_to(np.asarray(radius_m, dtype=np.float64), (m,))
    pairs = cKDTree(centroids).query_pairs(float(radius.max()), output_type="ndarray")
    if len(pairs):
        dist = np.linalg.norm(centroids[pairs[:, 0]] - centroids[pairs[:, 1]], axis=1)
        pairs = pairs[dist < np.maximum(radius[pairs[:, 0]], radius[pairs[:, 1]])]
    graph = coo_matrix((np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
    _, labels = connected_components(graph, directed=False)
    return labels


def link_radius_m(depth_m: np.ndarray, focal_px: float) -> np.ndarray:
    """Link radius for points at planar depth ``depth_m``: :data:`LINK_RADIUS_M`, or six pixel
    footprints (z / f) when larger, so that a surface seen at a grazing angle (rows of a table
    top 12 degrees below the line of sight are ~5 pixel footprints apart) stays in one piece.
    Capped at 12 cm."""
    return np.clip(6.0 * np.asarray(depth_m, dtype=np.float64) / focal_px, LINK_RADIUS_M, 0.12)


def cluster_points(points_cam: np.ndarray, focal_px: float) -> np.ndarray:
    """(N,) int64 cluster label (0..K-1) of each of the (N, 3) camera-frame points: Euclidean
    connected components over :data:`VOXEL_M` voxels with the radius of :func:`link_radius_m`."""
    if len(points_cam) == 0:
        return np.zeros(0, dtype=np.int64)
    centroids, inverse = _voxelize(points_cam, VOXEL_M)
    return _components(centroids, link_radius_m(centroids[:, 2], focal_px))[inverse].astype(np.int64)


def _split_on_support(points: np.ndarray, up: np.ndarray, horiz: np.ndarray, min_points: int, focal_px: float) -> np.ndarray | None:
    """Split what stands on a horizontal layer of one cluster.

    points: (N, 3) camera-frame points of the cluster; up: (3,) unit up; horiz: (2, 3) two
    horizontal unit axes; focal_px: focal length (for the link radius). Returns (N,) int labels
    (0 = the support, 1.. = objects on it) or None when there is nothing to split.
    """
    from scipy.spatial import ConvexHull, QhullError, cKDTree

    h = points @ up
    if h.max() - h.min() < 0.15:
        return None
    edges = np.arange(h.min(), h.max() + 2 * _LAYER_BIN_M, _LAYER_BIN_M)
    hist, _ = np.histogram(h, bins=edges)
    layer_counts = np.convolve(hist, np.ones(3, dtype=np.int64), mode="same")
    # A horizontal surface packs its points into one thin slab; vertical faces spread evenly.
    typical = float(np.median(layer_counts[layer_counts > 0]))
    # Candidate support layers, highest first: dense slabs (a horizontal surface seen from above
    # puts many points at one height) with enough points standing above them.
    dense = np.flatnonzero(layer_counts >= max(0.5 * min_points, 3.0 * typical))
    for k in dense[::-1]:
        layer_h = edges[k] + 0.5 * _LAYER_BIN_M
        above = h > layer_h + 0.04
        # The support (the layer and what is under it) must be a real object, not the rim of one.
        if above.sum() < min_points or (h <= layer_h + 1.5 * _LAYER_BIN_M).sum() < max(min_points, 0.3 * len(points)):
            continue
        layer = np.abs(h - layer_h) < 1.5 * _LAYER_BIN_M
        xy = points @ horiz.T
        # The support's footprint is the convex hull of its top layer: the part of the layer under
        # the object standing on it is hidden, so the layer's own cells would have a hole there.
        layer_xy = xy[layer][:: max(1, int(layer.sum()) // 2000)]
        try:
            facets = ConvexHull(layer_xy).equations  # (F, 3): inside where a . xy + b <= 0
        except QhullError:  # a degenerate (collinear) layer is no support surface
            continue
        above_idx = np.flatnonzero(above)
        pieces = cluster_points(points[above_idx], focal_px)
        labels = np.zeros(len(points), dtype=np.int64)
        next_label = 1
        # Points between the layer and the pieces: the pieces' lowest centimetres.
        skirt = np.flatnonzero((h > layer_h + 1.2 * _LAYER_BIN_M) & ~above)
        below_tree_idx = np.flatnonzero((h < layer_h - 0.02) & (h > layer_h - 0.15))
        below_tree = cKDTree(xy[below_tree_idx]) if len(below_tree_idx) else None
        order = np.argsort(pieces, kind="stable")
        bounds = np.searchsorted(pieces[order], np.arange(int(pieces.max()) + 2))
        for p in np.flatnonzero(np.bincount(pieces) >= min_points):
            sel = above_idx[order[bounds[p] : bounds[p + 1]]]
            inside = np.all(xy[sel] @ facets[:, :2].T + facets[:, 2] <= 0.01, axis=1)
            if inside.mean() < 0.8:
                continue
            # A chair's backrest, a sofa's back or a headboard rises along the seat's edge and
            # often runs on below it (into the legs, the base). A monitor stands inside the desk
            # top, with only the hidden desk top under its foot.
            foot = sel[h[sel] < layer_h + 0.07]
            if len(foot):
                to_edge = -np.max(xy[foot] @ facets[:, :2].T + facets[:, 2], axis=1)
                if np.mean(to_edge < 0.04) > 0.6:
                    continue
                if below_tree is not None:
                    d_below, _ = below_tree.query(xy[foot], distance_upper_bound=0.03)
                    if np.mean(d_below < np.inf) > 0.3:
                        continue
            if len(skirt):
                near = cKDTree(xy[sel]).query(xy[skirt], distance_upper_bound=0.02)[0] < np.inf
                free = labels[skirt] == 0
                labels[skirt[near & free]] = next_label
            labels[sel] = next_label
            next_label += 1
        return labels if next_label > 1 else None
    return None


def _top_layer(h: np.ndarray, min_points: int) -> float | None:
    """Height of the highest dense horizontal slab of a cluster's heights ``h`` (N,), or None."""
    if len(h) < min_points:
        return None
    if np.subtract(*np.percentile(h, [98, 2])) < 0.06:  # the cluster is one slab (a table top alone)
        return float(np.median(h))
    edges = np.arange(h.min(), h.max() + 2 * _LAYER_BIN_M, _LAYER_BIN_M)
    hist, _ = np.histogram(h, bins=edges)
    counts = np.convolve(hist, np.ones(3, dtype=np.int64), mode="same")
    dense = np.flatnonzero(counts >= max(0.5 * min_points, 3.0 * float(np.median(counts[counts > 0]))))
    return float(edges[dense[-1]] + 0.5 * _LAYER_BIN_M) if len(dense) else None


def _merge_legs(points: np.ndarray, labels: np.ndarray, up: np.ndarray, horiz: np.ndarray, min_points: int) -> None:
    """Join pieces standing under a cluster's top surface and reaching up to just below it (a
    table's legs, whose upper ends hide under the overhanging top) to that cluster, in place.

    points: (N, 3) camera-frame points; labels: (N,) cluster labels (modified); up: (3,);
    horiz: (2, 3) horizontal axes. A bin under a desk stops well below the desk top and stays.
    """
    from scipy.spatial import ConvexHull, QhullError

    h = points @ up
    xy = points @ horiz.T
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(int(labels.max()) + 2))
    members = {c: order[bounds[c] : bounds[c + 1]] for c in range(int(labels.max()) + 1) if bounds[c + 1] > bounds[c]}
    tops = {c: float(np.percentile(h[m], 98)) for c, m in members.items()}
    surfaces = []  # (cluster, layer height, hull equations) of clusters with a top surface
    for c, m in members.items():
        layer_h = _top_layer(h[m], min_points)
        if layer_h is None:
            continue
        # The footprint: the whole cluster seen from above (the top surface and its edge faces;
        # a near leg stands under the top's front edge).
        try:
            hull = ConvexHull(xy[m][:: max(1, len(m) // 3000)])
        except QhullError:
            continue
        if hull.volume >= 0.05:  # 2D hull: volume is the area, m^2
            surfaces.append((c, layer_h, hull.equations))
    # Each piece joins the surface right above it (the smallest gap), if any.
    target = {}
    for other, om in members.items():
        best = None
        for c, layer_h, eq in surfaces:
            gap = layer_h - tops[other]
            if c == other or not 0.01 <= gap <= 0.15 or (best is not None and gap >= best[1]):
                continue
            if np.mean(np.all(xy[om] @ eq[:, :2].T + eq[:, 2] <= 0.05, axis=1)) >= 0.8:
                best = (c, gap)
        if best is not None:
            target[other] = best[0]
    for other, c in sorted(target.items()):
        seen = {other}
        while c in target and c not in seen:  # a leg of a leg's table: follow to the top surface
            seen.add(c)
            c = target[c]
        labels[members[other]] = c


def _near_points(points: np.ndarray, samples: np.ndarray, radius_m: float) -> np.ndarray:
    """Sorted indices of the (N, 2) ``points`` within ``radius_m`` (inclusive) of any of the
    (M, 2) ``samples``.

    One nearest-neighbour query per point against a tree of the few samples, after a bounding-box
    cut, rather than a ball query per sample over all points: a ball query of every sample over a
    large flat cluster (a wall-sized cabinet front) returns each point hundreds of times (about
    8e8 indices on a 1000 x 667 kitchen photo, 167 s); this returns each once (same set).
    """
    from scipy.spatial import cKDTree

    if len(points) == 0 or len(samples) == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = samples.min(axis=0) - radius_m, samples.max(axis=0) + radius_m
    cand = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))
    if len(cand) == 0:
        return cand.astype(np.int64)
    # distance_upper_bound keeps distances strictly below it: the next float up keeps == radius.
    dist, _ = cKDTree(samples).query(points[cand], distance_upper_bound=float(np.nextafter(radius_m, np.inf)))
    return cand[np.isfinite(dist)].astype(np.int64)


def _split_by_colour(
    points: np.ndarray,
    pixels: np.ndarray,
    lab: np.ndarray,
    labels: np.ndarray,
    shape: tuple[int, int],
    up: np.ndarray,
    min_points: int,
) -> None:
    """Split off what lies on a surface of a cluster and differs from it in colour, in place.

    Depth alone cannot separate a thing lower than the support split's 4 cm (a laptop, a pillow
    sunk into a seat, a bowl on a shelf board) from the surface it lies on. Per cluster: pixels
    farther than :data:`COLOUR_DELTA_E` (CIE Lab, lightness at half weight: shading) from the
    cluster's median colour are "foreign";
    each 4-connected image region of foreign pixels with ``min_points`` points that is colour
    homogeneous (Lab spread under half the delta) and lies on the rest becomes its own cluster.
    "On the rest": among the rest's points within 3 cm horizontally (and from 10 cm below the
    piece to 5 cm over it), those under the piece's bottom form a thin layer (1.5 cm spread)
    within 2 cm of its bottom and at least 1 cm below its median height, and at most a tenth are
    over its top. The top face of a box over its (differently lit) front face fails the first test. A checker-textured seat or a two-coloured cabinet
    front fails: its colour regions lie in the surface, not on it.

    points: (N, 3) camera-frame points; pixels: (N,) flat pixel index of each; lab: (N, 3) Lab
    colour of each; labels: (N,) cluster labels (modified); shape: image (H, W); up: (3,) unit up.
    """
    from scipy.ndimage import binary_opening
    from scipy.ndimage import label as connected
    from scipy.spatial import cKDTree

    h_all = points @ up
    a = np.cross(up, [0.0, 0.0, 1.0]) if abs(up[2]) < 0.9 else np.cross(up, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    xy = points @ np.stack([a, np.cross(up, a)]).T
    next_label = int(labels.max()) + 1
    for c in np.flatnonzero(np.bincount(labels) >= 2 * min_points):
        sel = np.flatnonzero(labels == c)
        # Lightness counts half: faces of one object turned to or from the light differ in L.
        dist = np.linalg.norm((lab[sel] - np.median(lab[sel], axis=0)) * _LAB_WEIGHTS, axis=1)
        foreign = dist > COLOUR_DELTA_E
        if foreign.sum() < min_points:
            continue
        # Work in the foreign pixels' bounding box (a margin of 3 for the opening).
        rr, cc = np.divmod(pixels[sel], shape[1])
        r0, c0 = max(int(rr[foreign].min()) - 3, 0), max(int(cc[foreign].min()) - 3, 0)
        r1, c1 = min(int(rr[foreign].max()) + 4, shape[0]), min(int(cc[foreign].max()) + 4, shape[1])
        inside = (rr >= r0) & (rr < r1) & (cc >= c0) & (cc < c1)
        image = np.zeros((r1 - r0, c1 - c0), dtype=bool)
        image[rr[foreign] - r0, cc[foreign] - c0] = True
        # An opening drops the thin rims that shading and anti-aliasing leave along edges.
        regions, n = connected(binary_opening(image, iterations=2))
        if n == 0:
            continue
        region_of = np.zeros(len(sel), dtype=np.int32)
        region_of[inside] = regions[rr[inside] - r0, cc[inside] - c0]
        counts = np.bincount(region_of, minlength=n + 1)
        for r in np.flatnonzero(counts[1:] >= min_points) + 1:
            piece = sel[region_of == r]
            if np.linalg.norm(lab[piece].std(axis=0) * _LAB_WEIGHTS) > 0.5 * COLOUR_DELTA_E:
                continue
            rest = sel[(region_of != r) & (labels[sel] == c)]
            if len(rest) < min_points:
                continue
            lo, mid, hi = np.percentile(h_all[piece], [5, 50, 98])
            near_idx = _near_points(xy[rest], xy[piece][:: max(1, len(piece) // 400)], 0.03)
            near_h = h_all[rest[near_idx]]
            near_h = near_h[(near_h > lo - 0.10) & (near_h < hi + 0.05)]
            below = near_h[near_h < lo + 0.005]
            # On the rest: a horizontal surface around its foot (not a face running down from
            # it), lower than its middle, and nothing of the rest over it.
            if len(below) < 10 or float(np.median(below)) < lo - 0.02 or float(np.std(below)) > 0.015:
                continue
            if mid - float(np.median(below)) < 0.01 or float(np.mean(near_h > hi + 0.01)) > 0.1:
                continue
            labels[piece] = next_label
            next_label += 1


class DepthClusterSegmenter:
    """Objects as Euclidean clusters of the non-room depth points (see the module doc).

    min_points: clusters with fewer valid-depth pixels are merged into a neighbour or dropped.
    max_depth_m: farther depth is ignored. colour_split: split off what lies on a surface in
    another colour (:func:`_split_by_colour`; needs the up vector).
    """

    #: ``segment`` accepts the up vector (``perceive`` passes it to backends that say so).
    accepts_gravity = True

    def __init__(self, min_points: int = 150, max_depth_m: float = 10.0, colour_split: bool = True) -> None:
        self.min_points = int(min_points)
        self.max_depth_m = float(max_depth_m)
        self.colour_split = bool(colour_split)

    def segment(
        self,
        rgb: np.ndarray,
        depth_m: np.ndarray,
        intrinsics: CameraIntrinsics,
        background: np.ndarray,
        up_cam: np.ndarray | None = None,
    ) -> InstanceMasks:
        """rgb: (H, W, 3) uint8 (colour splits things lying on a surface); depth_m: (H, W) float32;
        background: (H, W) bool room pixels; up_cam: (3,) unit up in the camera frame or None.
        Returns instance labels (H, W) int32 numbered by decreasing size."""
        from scipy.ndimage import distance_transform_edt
        from scipy.spatial import cKDTree

        h, w = depth_m.shape
        valid = (depth_m > 0) & (depth_m < self.max_depth_m)
        fg = valid & ~background
        idx = np.flatnonzero(fg.reshape(-1))
        if len(idx) == 0:
            return InstanceMasks(np.zeros((h, w), dtype=np.int32), np.zeros(0, dtype=np.float32))
        points = intrinsics.unproject(depth_m).reshape(-1, 3)[idx]
        centroids, inverse = _voxelize(points, VOXEL_M)
        focal = 0.5 * (intrinsics.fx_px + intrinsics.fy_px)
        vox_labels = _components(centroids, link_radius_m(centroids[:, 2], focal))
        labels = vox_labels[inverse]

        if up_cam is not None:
            up = np.asarray(up_cam, dtype=np.float64)
            a = np.cross(up, [0.0, 0.0, 1.0]) if abs(up[2]) < 0.9 else np.cross(up, [1.0, 0.0, 0.0])
            a /= np.linalg.norm(a)
            horiz = np.stack([a, np.cross(up, a)])
            next_label = int(labels.max()) + 1
            for c in np.flatnonzero(np.bincount(labels) >= 2 * self.min_points):
                sel = np.flatnonzero(labels == c)
                split = _split_on_support(points[sel], up, horiz, self.min_points, focal)
                if split is None:
                    continue
                for s in range(1, int(split.max()) + 1):
                    labels[sel[split == s]] = next_label
                    next_label += 1
            _merge_legs(points, labels, up, horiz, self.min_points)
            if rgb is not None and self.colour_split:
                from skimage.color import rgb2lab

                lab = rgb2lab(np.asarray(rgb, dtype=np.uint8).reshape(-1, 1, 3)[idx]).reshape(-1, 3)
                _split_by_colour(points, idx, lab, labels, (h, w), up, self.min_points)

        # Merge small pieces into the nearest large cluster, or drop them.
        sizes = np.bincount(labels)
        big = sizes >= self.min_points
        if big.any() and (~big[labels]).any():
            big_pts = np.flatnonzero(big[labels])
            tree = cKDTree(points[big_pts])
            small_pts = np.flatnonzero(~big[labels])
            dist, nearest = tree.query(points[small_pts], distance_upper_bound=MERGE_RADIUS_M)
            # A whole small piece goes to the cluster its closest point touches: sort by piece,
            # then distance; the first row of each piece is its closest point.
            piece = labels[small_pts]
            order = np.lexsort((dist, piece))
            first = order[np.r_[True, piece[order][1:] != piece[order][:-1]]]
            target = np.full(int(labels.max()) + 1, -1, dtype=labels.dtype)
            hit = np.isfinite(dist[first])
            target[piece[first[hit]]] = labels[big_pts[nearest[first[hit]]]]
            labels[small_pts] = target[piece]
        elif not big.any():
            labels[:] = -1

        # Renumber by decreasing size (ties by cluster id, itself deterministic), 1-based.
        keep = labels >= 0
        uniq, counts = np.unique(labels[keep], return_counts=True)
        order = sorted(range(len(uniq)), key=lambda i: (-counts[i], i))
        remap = np.full(int(labels.max()) + 2 if len(labels) else 1, 0, dtype=np.int32)
        for new, i in enumerate(order, start=1):
            remap[uniq[i]] = new
        image = np.zeros(h * w, dtype=np.int32)
        image[idx[keep]] = remap[labels[keep]]
        image = image.reshape(h, w)

        # Pixels without depth take the nearest object label within a few pixels (no pin-holes).
        frac = float(valid.mean())
        radius_px = float(np.clip(np.ceil(1.5 / np.sqrt(max(frac, 1e-3))), 2, 8))
        if (image > 0).any():
            dist_px, (ri, ci) = distance_transform_edt(image == 0, return_indices=True)
            fill = ~valid & (dist_px <= radius_px)
            image[fill] = image[ri[fill], ci[fill]]
        # Geometry gives no calibrated confidence: every cluster gets the same middling score.
        scores = np.full(len(order), 0.5, dtype=np.float32)
        return InstanceMasks(image, scores)
