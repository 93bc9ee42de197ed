"""Layout: poses in the world (initial poses, Manhattan yaw snapping, support graph,
penetration-free solver) and the physics verdict and render-and-compare from the exported MJCF.

Importing this package is cheap: the entry functions load their modules (and MuJoCo) on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

__all__ = ["adopt_settled", "knocked", "make_background", "reseat_objects", "reseatable", "settled_scene", "settled_together", "solve_layout", "unstable_objects", "verify_scene"]

if TYPE_CHECKING:  # pragma: no cover
    from layout.solver import solve_layout
    from layout.repair import adopt_settled, knocked, make_background, reseat_objects, reseatable, settled_scene, settled_together, unstable_objects
    from layout.verify import verify_scene


def __getattr__(name: str):
    if name == "solve_layout":
        from layout.solver import solve_layout

        return solve_layout
    if name == "verify_scene":
        from layout.verify import verify_scene

        return verify_scene
    if name in ("adopt_settled", "knocked", "settled_scene", "unstable_objects", "make_background", "reseat_objects", "reseatable", "settled_together"):
        from layout import repair

        return getattr(repair, name)
    raise AttributeError(f"module 'layout' has no attribute {name!r}")
