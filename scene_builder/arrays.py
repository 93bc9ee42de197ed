"""Frozen-array helpers of the data model: every array a dataclass of :mod:`scene_builder.model`
or :mod:`scene_builder.checks` holds is copied, type- and shape-checked and made read-only here."""

from __future__ import annotations

import numpy as np

__all__ = ["as_array"]


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
