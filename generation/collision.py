"""Convex collision pieces of a part: CoACD with a convex fast path, a bound on the number of
pieces, a content-addressed cache and a seed.

Every piece returned is the convex hull of its points (closed, convex, outward-facing).
"""

from __future__ import annotations

import hashlib
import io
from pathlib import Path

import numpy as np

__all__ = ["convex_pieces", "is_convex_enough", "CONVEX_VOLUME_RATIO", "COACD_MAX_FACES"]

# A part whose convex hull has at most 1 / 0.95 of its volume collides as its hull.
CONVEX_VOLUME_RATIO = 0.95
# CoACD cost grows with the face count (NOTES: 19 s at 20k faces, 5 s at 2k): decimate first.
COACD_MAX_FACES = 2000
_CACHE_VERSION = "coacd-1.0.14-v1"


def _hull(points: np.ndarray):
    import trimesh

    hull = trimesh.convex.convex_hull(np.asarray(points, dtype=np.float64))
    if float(hull.volume) < 0:
        hull.invert()
    return hull


def is_convex_enough(tm, ratio: float = CONVEX_VOLUME_RATIO) -> bool:
    """True when ``volume(mesh) / volume(hull) >= ratio``."""
    hull_volume = float(tm.convex_hull.volume)
    return hull_volume > 0 and float(tm.volume) / hull_volume >= ratio


def _cache_key(tm, threshold: float, max_pieces: int, seed: int, search: str = "") -> str:
    h = hashlib.sha256()
    h.update(_CACHE_VERSION.encode())
    h.update(np.ascontiguousarray(tm.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(tm.faces, dtype=np.int64).tobytes())
    h.update(f"{threshold:.6g}/{max_pieces}/{seed}/{search}".encode())
    return h.hexdigest()[:32]


def _load_cache(path: Path):
    with np.load(path) as data:
        n = int(data["count"])
        return [_hull(data[f"piece_{i}"]) for i in range(n)]


def _save_cache(path: Path, pieces) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    np.savez_compressed(buf, count=np.array(len(pieces)), **{f"piece_{i}": np.asarray(p.vertices) for i, p in enumerate(pieces)})
    tmp = path.with_suffix(".tmp")
    tmp.write_bytes(buf.getvalue())
    tmp.replace(path)  # atomic: concurrent builds never read half a file


def _merge_smallest(pieces, max_pieces: int):
    """Merge the smallest piece into its nearest neighbour (hull of both) until at most
    ``max_pieces`` remain."""
    pieces = list(pieces)
    while len(pieces) > max_pieces:
        vols = np.array([float(p.volume) for p in pieces])
        i = int(np.argmin(vols))
        small = pieces.pop(i)
        centres = np.array([p.centroid for p in pieces])
        j = int(np.argmin(np.linalg.norm(centres - small.centroid, axis=1)))
        pieces[j] = _hull(np.vstack([pieces[j].vertices, small.vertices]))
    return pieces


def convex_pieces(
    mesh,
    *,
    threshold: float = 0.08,
    max_pieces: int = 12,
    seed: int = 0,
    cache_dir: Path | None = None,
    mcts_iterations: int = 40,
    mcts_max_depth: int = 2,
    resolution: int = 800,
) -> list:
    """Convex pieces (list of ``trimesh.Trimesh``) covering a watertight mesh.

    mesh: ``trimesh.Trimesh`` or :class:`TriangleMesh` (asset frame). Fast path: one hull when the
    mesh is nearly convex. Otherwise CoACD (``threshold`` = concavity, ``seed``) on the mesh
    decimated to :data:`COACD_MAX_FACES`, at most ``max_pieces`` pieces (CoACD's own merge, then
    merging the smallest into its nearest neighbour). The search is lighter than CoACD's
    defaults (40 MCTS iterations, depth 2, 800 samples instead of 150 / 3 / 2000): on a notched
    48^3 box 0.8 s instead of 4.6 s, the same pieces and coverage. Results are cached under ``cache_dir``
    keyed by the mesh bytes and parameters. Deterministic for a given mesh and seed.
    """
    from generation.meshing import decimate, to_trimesh

    tm = to_trimesh(mesh)
    if is_convex_enough(tm):
        return [_hull(tm.vertices)]
    key = _cache_key(tm, threshold, max_pieces, seed, f"{mcts_iterations}/{mcts_max_depth}/{resolution}")
    cache_path = None if cache_dir is None else Path(cache_dir) / "coacd" / f"{key}.npz"
    if cache_path is not None and cache_path.exists():
        return _load_cache(cache_path)

    import coacd

    coacd.set_log_level("error")
    small = decimate(tm, COACD_MAX_FACES)
    if len(small.faces) > COACD_MAX_FACES:
        # decimation could not keep the mesh watertight: CoACD repairs its input (preprocess
        # "on"), so a non-manifold decimated copy is fine for it, and far faster than 100k faces
        small = tm.simplify_quadric_decimation(face_count=COACD_MAX_FACES)
    result = coacd.run_coacd(
        coacd.Mesh(np.asarray(small.vertices, dtype=np.float64), np.asarray(small.faces, dtype=np.int32)),
        threshold=float(threshold),
        max_convex_hull=int(max_pieces),
        preprocess_mode="off" if small.is_watertight else "on",
        resolution=int(resolution),
        mcts_iterations=int(mcts_iterations),
        mcts_max_depth=int(mcts_max_depth),
        seed=int(seed),
    )
    pieces = []
    for verts, _faces in result:
        verts = np.asarray(verts, dtype=np.float64)
        if len(verts) >= 4 and np.linalg.matrix_rank(verts - verts.mean(axis=0), tol=1e-9) == 3:
            pieces.append(_hull(verts))
    if not pieces:
        pieces = [_hull(tm.vertices)]
    # deterministic order: by centroid (x, y, z)
    pieces.sort(key=lambda p: tuple(np.round(p.centroid, 9)))
    pieces = _merge_smallest(pieces, max_pieces)
    if cache_path is not None:
        _save_cache(cache_path, pieces)
    return pieces
