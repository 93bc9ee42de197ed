"""Perception: photo (and optional depth) -> gravity-aligned camera, room and object instances.

Entry point: :func:`perceive`. Importing this package is cheap (numpy and the data model):
open3d, scipy, PIL and the learned models are imported inside the functions that use them.
"""

from __future__ import annotations

# Bound eagerly: a lazy ``__getattr__`` would be shadowed by the submodule ``perception.perceive``
# as soon as anything imports it.
from perception.perceive import perceive

__all__ = ["perceive"]
