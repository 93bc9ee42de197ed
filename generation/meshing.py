"""Watertight meshes: from occupancy voxel grids (marching cubes), from convex solids (boolean
union), decimation, validation, and vertex colours from the observed points.

Voxel grid convention (used everywhere in ``generation``): ``occupancy[i, j, k]`` is the cube
``[origin + (i, j, k) * s, origin + (i + 1, j + 1, k + 1) * s]`` with ``s = voxel_size_m`` and
``origin_m`` the minimum corner of voxel ``(0, 0, 0)`` in the asset frame.
"""

from __future__ import annotations

import threading

import numpy as np

from scene_builder.model import TriangleMesh

__all__ = [
    "mesh_from_occupancy",
    "union_of_solids",
    "decimate",
    "check_watertight",
    "to_model_mesh",
    "to_trimesh",
    "vertex_colors",
]


def to_trimesh(mesh):
    """``trimesh.Trimesh`` of a :class:`TriangleMesh` (no processing, same vertex order)."""
    import trimesh

    if isinstance(mesh, trimesh.Trimesh):
        return mesh
    return trimesh.Trimesh(np.asarray(mesh.vertices_m), np.asarray(mesh.faces), process=False)


def to_model_mesh(tm, vertex_colors_rgba: np.ndarray | None = None) -> TriangleMesh:
    """:class:`TriangleMesh` of a ``trimesh.Trimesh``. vertex_colors_rgba: (V, 4) uint8 or None."""
    return TriangleMesh(np.asarray(tm.vertices, dtype=np.float64), np.asarray(tm.faces, dtype=np.int64), vertex_colors_rgba)


def check_watertight(tm, what: str) -> None:
    """Raise ValueError unless ``tm`` is watertight, consistently wound and has positive volume."""
    if not tm.is_watertight:
        raise ValueError(f"{what}: mesh is not watertight")
    if not tm.is_winding_consistent:
        raise ValueError(f"{what}: mesh winding is inconsistent")
    if not float(tm.volume) > 0:
        raise ValueError(f"{what}: mesh volume {float(tm.volume):.3g} m^3 is not positive")


#: fast_simplification keeps the mesh it works on in global C++ vectors (its Simplify.h), filled
#: and read back by separate calls: two decimations on two threads (``generation.generate_assets``
#: makes objects on threads) mixed their meshes. One decimation at a time in a process.
DECIMATION_LOCK = threading.Lock()


def quadric_decimation(tm, face_count: int, aggression: int | None = None):
    """``tm.simplify_quadric_decimation`` (fast_simplification) under :data:`DECIMATION_LOCK`."""
    with DECIMATION_LOCK:
        if aggression is None:
            return tm.simplify_quadric_decimation(face_count=face_count)
        return tm.simplify_quadric_decimation(face_count=face_count, aggression=aggression)


def decimate(tm, max_faces: int):
    """Quadric decimation to at most ``max_faces`` faces (``fast_simplification`` via trimesh)
    that stays watertight with positive volume.

    fast_simplification sometimes collapses an edge into a non-manifold fan (measured: a
    33k-face marching-cubes box came back with 2 edges shared by 4 faces at aggressiveness 3,
    while aggressiveness 1 stopped at 14k faces). So a few (aggressiveness, target) settings are
    tried in order, each ~20-40 ms; if none is watertight within ``max_faces``, the smallest
    watertight result is kept (or the input when there is none).
    """
    if len(tm.faces) <= max_faces:
        return tm
    best = tm
    n = int(max_faces)
    for aggression, target in ((3, n), (5, n), (7, n), (2, n), (3, int(0.9 * n)), (5, int(0.8 * n)), (1, n)):
        out = quadric_decimation(tm, target, aggression)
        if not (out.is_watertight and out.is_winding_consistent):
            continue
        if float(out.volume) < 0:
            out.invert()
        if len(out.faces) <= max_faces:
            return out
        if len(out.faces) < len(best.faces):
            best = out
    return best


def mesh_from_occupancy(
    occupancy: np.ndarray,
    voxel_size_m: float,
    origin_m: np.ndarray,
    max_faces: int = 4000,
    smooth_sigma_vox: float = 0.5,
    taubin_iterations: int = 10,
):
    """Watertight mesh of an occupancy grid.

    occupancy: (X, Y, Z) bool. voxel_size_m: edge of a voxel. origin_m: (3,) min corner of voxel
    (0, 0, 0). Pads the grid, blurs it lightly (Gaussian, ``smooth_sigma_vox`` voxels), runs
    marching cubes at level 0.5 (the surface passes through the voxel faces, so the enclosed
    volume matches the voxel count), Taubin-smooths (volume-preserving) and decimates to
    ``max_faces``. Returns a ``trimesh.Trimesh`` in the asset frame; raises ValueError when the
    grid is empty or the result is not watertight.
    """
    import trimesh
    from scipy import ndimage
    from skimage import measure

    occ = np.asarray(occupancy, dtype=bool)
    if occ.ndim != 3 or not occ.any():
        raise ValueError("mesh_from_occupancy: the occupancy grid is empty; nothing to mesh")
    pad = 2
    field = np.pad(occ.astype(np.float32), pad)
    if smooth_sigma_vox > 0:
        blurred = ndimage.gaussian_filter(field, smooth_sigma_vox)
        # Voxels with no neighbour (a speck, a grid of isolated voxels) all fall below the
        # surface level once blurred, and marching cubes finds no surface: they keep their edges.
        field = blurred if float(blurred.max()) > 0.5 else field
    verts, faces, _, _ = measure.marching_cubes(field, level=0.5, spacing=(voxel_size_m,) * 3)
    # sample (idx) sits at the centre of voxel idx - pad
    verts = verts + np.asarray(origin_m, dtype=np.float64) + (0.5 - pad) * voxel_size_m
    tm = trimesh.Trimesh(verts, faces, process=True)
    if float(tm.volume) < 0:
        tm.invert()
    if taubin_iterations > 0:
        trimesh.smoothing.filter_taubin(tm, lamb=0.5, nu=0.53, iterations=taubin_iterations)
    tm = decimate(tm, max_faces)
    tm.fix_normals()
    check_watertight(tm, "mesh_from_occupancy")
    return tm


def union_of_solids(solids) -> "object":
    """Boolean union (manifold3d, float64) of closed solids, as one watertight ``trimesh.Trimesh``.

    solids: sequence of ``trimesh.Trimesh`` or :class:`TriangleMesh`, each closed. The result is
    not re-processed by trimesh: manifold keeps geometrically coincident but topologically
    distinct vertices apart (where solids touch), and merging them would break the 2-manifold.
    """
    import manifold3d
    import trimesh

    meshes = [to_trimesh(s) for s in solids]
    if len(meshes) == 1:
        out = meshes[0].copy()
    else:
        parts = [
            manifold3d.Manifold(manifold3d.Mesh64(np.array(m.vertices, dtype=np.float64, order="C"), np.array(m.faces, dtype=np.uint64, order="C")))
            for m in meshes
        ]
        for m, part in zip(meshes, parts):
            if part.status() != manifold3d.Error.NoError:
                raise ValueError(f"union_of_solids: a solid is not a closed manifold ({part.status()}), bounds {m.bounds.tolist()}")
        result = manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add).to_mesh64()
        out = trimesh.Trimesh(np.asarray(result.vert_properties)[:, :3], np.asarray(result.tri_verts, dtype=np.int64), process=False)
    if float(out.volume) < 0:
        out.invert()
    check_watertight(out, "union_of_solids")
    return out


def vertex_colors(
    vertices_m: np.ndarray,
    points_m: np.ndarray | None,
    colors_rgb: np.ndarray | None,
    max_distance_m: float,
    fallback_rgb: np.ndarray | None = None,
) -> np.ndarray:
    """(V, 4) uint8 colours: the nearest observed point's colour within ``max_distance_m``, else
    the median observed colour (or ``fallback_rgb``, else mid grey).

    vertices_m: (V, 3); points_m: (N, 3) in the same frame; colors_rgb: (N, 3) uint8.
    """
    from scipy.spatial import cKDTree

    v = np.asarray(vertices_m, dtype=np.float64)
    out = np.full((len(v), 4), 255, dtype=np.uint8)
    if points_m is None or colors_rgb is None or len(points_m) == 0:
        base = np.array([150, 150, 150] if fallback_rgb is None else fallback_rgb, dtype=np.uint8)
        out[:, :3] = base
        return out
    cols = np.asarray(colors_rgb, dtype=np.uint8)
    median = np.median(cols, axis=0).astype(np.uint8) if fallback_rgb is None else np.asarray(fallback_rgb, np.uint8)
    dist, idx = cKDTree(np.asarray(points_m, dtype=np.float64)).query(v, k=1)
    near = dist <= max_distance_m
    out[:, :3] = median
    out[near, :3] = cols[idx[near]]
    return out
