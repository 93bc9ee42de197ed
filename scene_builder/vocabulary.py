"""The project's object category vocabulary (part of the data model).

Perception names objects with these labels; generation keys its material table, shape priors and
articulation templates on them. ``"object"`` is the label of anything not recognised.

Each category: typical size (extents along x, y, z of the asset frame in metres; +X is the
front, so x is the depth of a cabinet and y its width), the asset kind, whether it is usually fixed to the building, and
whether it usually stands on the floor or on another object.
"""

from __future__ import annotations

from dataclasses import dataclass

from scene_builder.model import AssetKind


@dataclass(frozen=True)
class Category:
    """name: label. typical_size_m: (depth x, width y, height z) in the asset frame.
    kind: rigid / articulated / deformable. fixed: usually built in. on_floor: usually stands on
    the floor (else on furniture)."""

    name: str
    typical_size_m: tuple[float, float, float]
    kind: AssetKind
    fixed: bool = False
    on_floor: bool = True


_R, _A, _D = AssetKind.RIGID, AssetKind.ARTICULATED, AssetKind.DEFORMABLE

CATEGORIES: tuple[Category, ...] = (
    Category("table", (0.8, 1.2, 0.75), _R),
    Category("desk", (0.6, 1.2, 0.75), _R),
    Category("chair", (0.5, 0.5, 0.9), _R),
    Category("stool", (0.4, 0.4, 0.5), _R),
    Category("sofa", (0.9, 2.0, 0.85), _R),
    Category("bed", (2.0, 1.5, 0.6), _R),
    Category("shelf", (0.35, 0.9, 1.8), _R),
    Category("cabinet", (0.5, 0.8, 0.9), _A),
    Category("wardrobe", (0.6, 1.0, 2.0), _A),
    Category("drawer_unit", (0.5, 0.6, 0.8), _A),
    Category("refrigerator", (0.7, 0.7, 1.8), _A),
    Category("microwave", (0.4, 0.5, 0.3), _A, on_floor=False),
    Category("oven", (0.6, 0.6, 0.9), _A, fixed=True),
    Category("dishwasher", (0.6, 0.6, 0.85), _A, fixed=True),
    Category("door", (0.05, 0.9, 2.0), _A, fixed=True),
    Category("laptop", (0.25, 0.35, 0.02), _A, on_floor=False),
    Category("box_with_lid", (0.3, 0.4, 0.3), _A),
    Category("counter", (0.6, 1.5, 0.9), _R, fixed=True),
    Category("sink", (0.5, 0.6, 0.9), _R, fixed=True),
    Category("toilet", (0.7, 0.4, 0.75), _R, fixed=True),
    Category("tv", (0.1, 1.0, 0.6), _R, on_floor=False),
    Category("monitor", (0.2, 0.55, 0.4), _R, on_floor=False),
    Category("lamp", (0.3, 0.3, 0.5), _R, on_floor=False),
    Category("plant", (0.3, 0.3, 0.5), _R),
    Category("box", (0.3, 0.4, 0.3), _R),
    Category("bin", (0.3, 0.3, 0.4), _R),
    Category("bottle", (0.07, 0.07, 0.25), _R, on_floor=False),
    Category("mug", (0.09, 0.09, 0.1), _R, on_floor=False),
    Category("bowl", (0.15, 0.15, 0.07), _R, on_floor=False),
    Category("book", (0.2, 0.15, 0.03), _R, on_floor=False),
    Category("pillow", (0.4, 0.6, 0.15), _D, on_floor=False),
    Category("cushion", (0.45, 0.45, 0.12), _D, on_floor=False),
    Category("towel", (0.3, 0.5, 0.03), _D, on_floor=False),
    Category("blanket", (1.0, 1.5, 0.05), _D, on_floor=False),
    Category("soft_toy", (0.2, 0.2, 0.3), _D, on_floor=False),
    # Classes an object detector (COCO, Open Images) names that the furniture above does not cover.
    Category("bench", (0.4, 1.2, 0.45), _R),
    Category("suitcase", (0.25, 0.45, 0.65), _R),
    Category("bag", (0.2, 0.35, 0.4), _R),
    Category("vase", (0.15, 0.15, 0.3), _R, on_floor=False),
    Category("clock", (0.05, 0.3, 0.3), _R, on_floor=False),
    Category("keyboard", (0.15, 0.45, 0.03), _R, on_floor=False),
    Category("object", (0.3, 0.3, 0.3), _R),
)

BY_NAME: dict[str, Category] = {c.name: c for c in CATEGORIES}
LABELS: tuple[str, ...] = tuple(c.name for c in CATEGORIES)


def category(label: str) -> Category:
    """The category of ``label``; unknown labels map to ``"object"``."""
    return BY_NAME.get(label, BY_NAME["object"])
