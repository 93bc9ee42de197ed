"""Frozen-array helpers of the data model: every array a dataclass of :mod:`scene_builder.model`
or :mod:`scene_builder.checks` holds is copied, type- and shape-checked and made read-only here."""

from __future__ import annotations

import numpy as np

__all__ = ["INERTIA_MARGIN", "MIN_PIECE_THICKNESS_M", "as_array", "inertia_problem", "thickness_m"]


def as_array(value, dtype, shape: tuple[int | None, ...], name: str) -> np.ndarray:
    """Return ``value`` as a read-only array of ``dtype`` and check its shape.

    ``shape`` uses ``None`` for a free dimension, e.g. ``(None, 3)`` for an (N, 3) array.
    Raises ``ValueError`` naming the field when the shape does not match or values are not finite
    (for floating dtypes).
    """
    arr = np.array(value, dtype=dtype, copy=True)
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "x".join("N" if s is None else str(s) for s in shape)
        raise ValueError(f"{name}: expected shape ({want}), got {arr.shape}")
    if np.issubdtype(arr.dtype, np.floating) and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    arr.setflags(write=False)
    return arr


def _freeze(obj, name: str, dtype, shape) -> None:
    object.__setattr__(obj, name, as_array(getattr(obj, name), dtype, shape, f"{type(obj).__name__}.{name}"))


def _check_rigid(t: np.ndarray, name: str) -> None:
    r = t[:3, :3]
    if not np.allclose(r.T @ r, np.eye(3), atol=1e-6) or not np.isclose(np.linalg.det(r), 1.0, atol=1e-6):
        raise ValueError(f"{name}: rotation block is not a proper rotation")
    if not np.allclose(t[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"{name}: last row must be [0, 0, 0, 1]")


#: The principal moments A <= B <= C of every inertia tensor satisfy A + B >= (1 + INERTIA_MARGIN) C.
#: Any mass distribution has A + B - C = 2 * (its second moment along C's axis) >= 0; the margin
#: keeps the inequality true after the exporters round the tensor (MJCF 12 digits, URDF and SDF 9,
#: USD float32: relative errors up to 1e-7), so MuJoCo ("inertia must satisfy A + B >= C"),
#: libsdformat and PhysX never see a tensor they reject. A plate 1 m wide meets it from 1 mm thick.
INERTIA_MARGIN = 1e-6


def inertia_problem(inertia) -> str:
    """Why ``inertia`` (3, 3), kg m^2 about the centre of mass, is not the inertia tensor of a mass
    distribution ("" when it is): finite, symmetric, positive definite and its principal moments
    satisfy the triangle inequality with :data:`INERTIA_MARGIN`."""
    i = np.asarray(inertia, dtype=np.float64)
    if i.shape != (3, 3) or not np.all(np.isfinite(i)):
        return "must be a finite 3 x 3 matrix"
    scale = float(np.abs(i).max())
    if not np.allclose(i, i.T, atol=1e-12 + 1e-9 * scale):
        return "must be symmetric"
    a, b, c = np.linalg.eigvalsh(0.5 * (i + i.T))
    if not a > 0:
        return f"must be positive definite (principal moments {a:.3g}, {b:.3g}, {c:.3g} kg m^2)"
    if a + b < (1.0 + INERTIA_MARGIN) * c:
        return (f"principal moments {a:.6g}, {b:.6g}, {c:.6g} kg m^2 break the triangle inequality A + B >= C "
                "(no mass distribution has them; MuJoCo rejects them)")
    return ""


#: Every collision piece is a solid at least this thick (m) along its thinnest principal axis:
#: MuJoCo cannot take the convex hull of a flat or straight piece ("mesh has coplanar vertices")
#: nor the volume of a micrometre one ("mesh volume is too small").
MIN_PIECE_THICKNESS_M = 1e-4


def thickness_m(vertices) -> float:
    """Extent (m) of the points (N, 3) along their least principal axis: 0 for a flat, straight
    or single-point set (and fewer than 4 points); never less than the width of their hull."""
    v = np.asarray(vertices, dtype=np.float64)
    if len(v) < 4 or not np.all(np.isfinite(v)):
        return 0.0
    centred = v - v.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][-1]
    along = centred @ axis
    return float(along.max() - along.min())
