"""Articulation templates: part trees of cabinets, wardrobes, drawer units, appliances, doors,
laptops and lidded boxes, fitted to measured extents.

Layout of every template in the asset frame (x in [-D/2, D/2], y in [-W/2, W/2], z in [0, H],
+X is the front): the body (carcass panels) at the back, the doors / drawer fronts in front of
it, handles in front of those; 2 mm gaps between parts so nothing overlaps at rest. Seen from
the front (looking along -X) the viewer's right is +Y.

Hinges sit on the outer front edge of a door, so the door swings outward: for a vertical hinge
whose door extends toward +Y from the hinge the axis is -Z (toward -Y: +Z); a bottom hinge
(oven, dishwasher) has axis +Y; a lid hinged at the back top edge has axis -Y. Drawers slide
along +X by up to 0.8 x the body depth. Limits: doors 0..1.7 rad, drop-down doors 0..1.5 rad,
laptop lid 0..1.9 rad, box lid 0..2.0 rad.

Layouts follow the measured aspect ratio: a cabinet at least as wide as tall gets two doors, a
narrow one one door; a drawer unit stacks drawers about 0.2 m high; a refrigerator taller than
1.4 m gets a fridge door over a freezer door; a microwave a door beside a control panel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from generation.assembly import ConvexSolids, JointSpec, PartSpec, box_solid
from scene_builder.model import JointType

__all__ = ["ARTICULATED_LABELS", "articulated_parts", "TemplateParams", "assemble_asset"]

from generation.assembly import assemble_asset  # noqa: E402  (re-exported: the PhysX backend's entry)

GAP_M = 0.002
DOOR_LIMIT_RAD = 1.7
DROP_DOOR_LIMIT_RAD = 1.5
LAPTOP_LIMIT_RAD = 1.9
LID_LIMIT_RAD = 2.0
DRAWER_TRAVEL_FRACTION = 0.8


@dataclass(frozen=True)
class TemplateParams:
    """Construction of one template. panel_m: carcass panel thickness (geometry); door_m: door /
    front thickness; handle_m: how far a handle stands out. sheet_m: for sheet-metal and
    cardboard objects, the equivalent wall thickness of the real material: carcass panels carry
    the mass of one such wall (density x sheet_m / panel_m) and doors are hollow boxes with
    walls of sheet_m (``PartSpec.shell_thickness_m``). None = panels are solid material."""

    material: str
    panel_m: float
    door_m: float
    handle_m: float
    sheet_m: float | None = None

    @property
    def panel_density_scale(self) -> float:
        return 1.0 if self.sheet_m is None else self.sheet_m / self.panel_m


_PARAMS = {
    "cabinet": TemplateParams("particleboard", 0.018, 0.018, 0.025),
    "wardrobe": TemplateParams("particleboard", 0.018, 0.018, 0.025),
    "drawer_unit": TemplateParams("particleboard", 0.018, 0.018, 0.025),
    "refrigerator": TemplateParams("steel", 0.03, 0.05, 0.04, 0.0012 * 1.3),
    "microwave": TemplateParams("steel", 0.015, 0.03, 0.02, 0.0008 * 2.0),
    "oven": TemplateParams("steel", 0.02, 0.04, 0.03, 0.0015 * 1.5),
    "dishwasher": TemplateParams("steel", 0.02, 0.04, 0.025, 0.0010 * 1.8),
    "door": TemplateParams("wood", 0.05, 0.04, 0.06),
    "laptop": TemplateParams("laptop", 0.0, 0.0, 0.0),
    "box_with_lid": TemplateParams("cardboard", 0.006, 0.006, 0.0, 0.004),
}
# Appliance sheet thicknesses above: the steel sheet (0.8-1.5 mm) times a factor for liners,
# insulation, racks and electronics, set so that typical sizes weigh what product sheets say
# (1.8 m refrigerator 60-80 kg, 0.5 m microwave 11-15 kg, oven 40-60 kg, dishwasher 35-50 kg).

ARTICULATED_LABELS = tuple(_PARAMS)


def _mat(params: TemplateParams, rgba, scale: float = 1.0):
    from generation.materials import MATERIALS

    spec = MATERIALS[params.material]
    mat = spec.to_material(rgba)
    if scale != 1.0:
        from dataclasses import replace

        mat = replace(mat, name=f"{spec.name}_panel", density_kg_m3=spec.density_kg_m3 * scale,
                      source=f"{spec.source}; effective density x{scale:.3g} (thin walls modelled as thicker panels)")
    return mat


def _carcass(x0: float, x_front: float, w: float, h: float, t: float, shelves: int = 0) -> list:
    """Open-front box: back, sides, top, bottom (+ shelves), x in [x0, x_front]."""
    solids = [
        box_solid([x0, -w / 2, 0.0], [x0 + t, w / 2, h]),  # back
        box_solid([x0, -w / 2, 0.0], [x_front, -w / 2 + t, h]),  # side -Y
        box_solid([x0, w / 2 - t, 0.0], [x_front, w / 2, h]),  # side +Y
        box_solid([x0, -w / 2, 0.0], [x_front, w / 2, t]),  # bottom
        box_solid([x0, -w / 2, h - t], [x_front, w / 2, h]),  # top
    ]
    for i in range(shelves):
        z = h * (i + 1) / (shelves + 1)
        # shelves sink 0.5 mm into the sides and back: touching faces make non-manifold unions
        e = 5e-4
        solids.append(box_solid([x0 + t - e, -w / 2 + t - e, z - t / 2], [x_front - 0.02, w / 2 - t + e, z + t / 2]))
    return solids


def _handle(name: str, parent: str, x_face: float, y: float, z: float, protrude: float, vertical: bool, size: float, rgba) -> PartSpec:
    """A bar handle standing ``GAP_M`` in front of the face at ``x_face``, centred at (y, z)."""
    thick = max(0.012, 0.3 * protrude)
    long_ = size
    if vertical:
        lo = [x_face + GAP_M, y - thick / 2, z - long_ / 2]
        hi = [x_face + GAP_M + protrude, y + thick / 2, z + long_ / 2]
    else:
        lo = [x_face + GAP_M, y - long_ / 2, z - thick / 2]
        hi = [x_face + GAP_M + protrude, y + long_ / 2, z + thick / 2]
    return PartSpec(
        name, parent, ConvexSolids((box_solid(lo, hi),)), "aluminium",
        JointSpec(JointType.FIXED, (1.0, 0.0, 0.0), ((lo[0] + hi[0]) / 2, y, z)),
        affordance_rank=1, affordance="pull handle to open", description="handle", rgba=(0.8, 0.81, 0.83, 1.0),
    )


def _vertical_door(name, parent, x_back, x_front, y0, y1, z0, z1, hinge_at_low_y: bool, mat, params, rgba, upper=DOOR_LIMIT_RAD):
    shell = params.sheet_m
    """A door panel over y in [y0, y1], hinged on its outer front edge at y0 or y1."""
    y_h = y0 if hinge_at_low_y else y1
    axis = (0.0, 0.0, -1.0) if hinge_at_low_y else (0.0, 0.0, 1.0)  # swings outward (+X)
    door = PartSpec(
        name, parent, ConvexSolids((box_solid([x_back, y0, z0], [x_front, y1, z1]),)), mat,
        JointSpec(JointType.REVOLUTE, axis, (x_front, y_h, z0), 0.0, upper),
        affordance_rank=2, affordance="swing open", description="hinged door", shell_thickness_m=shell,
    )
    handle_y = (y1 - 0.06 if hinge_at_low_y else y0 + 0.06) if (y1 - y0) > 0.2 else (y0 + y1) / 2
    handle_z = z0 + 0.5 * (z1 - z0) if (z1 - z0) < 1.2 else z0 + 1.0
    handle = _handle(f"{name}_handle", name, x_front, handle_y, handle_z, params.handle_m, True,
                     min(0.3, 0.5 * (z1 - z0)), rgba)
    return [door, handle]


def _bottom_door(name, parent, x_back, x_front, y0, y1, z0, z1, mat, params, rgba, upper=DROP_DOOR_LIMIT_RAD):
    """A drop-down door hinged on its bottom front edge (axis +Y: the top moves toward +X)."""
    shell = params.sheet_m
    door = PartSpec(
        name, parent, ConvexSolids((box_solid([x_back, y0, z0], [x_front, y1, z1]),)), mat,
        JointSpec(JointType.REVOLUTE, (0.0, 1.0, 0.0), (x_front, 0.5 * (y0 + y1), z0), 0.0, upper),
        affordance_rank=2, affordance="pull down to open", description="drop-down door", shell_thickness_m=shell,
    )
    handle = _handle(f"{name}_handle", name, x_front, 0.5 * (y0 + y1), z1 - 0.05, params.handle_m, False,
                     min(0.5, 0.7 * (y1 - y0)), rgba)
    return [door, handle]


def _drawer(name, parent, x_body_back, x_front, y0, y1, z0, z1, t, cavity_top, body_depth, mat, params, rgba) -> list[PartSpec]:
    """Drawer: front panel (door_m thick, x in [x_front - door_m, x_front]) and an open tray behind
    it inside the carcass; slides along +X by DRAWER_TRAVEL_FRACTION x body depth."""
    xf_back = x_front - params.door_m
    tray_back = x_body_back + GAP_M
    tin = 0.012  # tray walls
    inset = GAP_M + t  # tray clears the carcass sides
    ty0, ty1 = y0 + inset, y1 - inset
    tz0, tz1 = max(z0, t) + GAP_M, min(z1 - 0.02, cavity_top - GAP_M)
    solids = [box_solid([xf_back, y0, z0], [x_front, y1, z1])]
    if ty1 - ty0 > 3 * tin and tz1 - tz0 > 2 * tin and xf_back - tray_back > 3 * tin:
        solids += [
            box_solid([tray_back, ty0, tz0], [xf_back, ty1, tz0 + tin]),  # bottom
            box_solid([tray_back, ty0, tz0], [xf_back, ty0 + tin, tz1]),  # side
            box_solid([tray_back, ty1 - tin, tz0], [xf_back, ty1, tz1]),  # side
            box_solid([tray_back, ty0, tz0], [tray_back + tin, ty1, tz1]),  # back
        ]
    drawer = PartSpec(
        name, parent, ConvexSolids(tuple(solids)), mat,
        JointSpec(JointType.PRISMATIC, (1.0, 0.0, 0.0), (x_front, 0.5 * (y0 + y1), 0.5 * (z0 + z1)),
                  0.0, DRAWER_TRAVEL_FRACTION * body_depth),
        affordance_rank=2, affordance="pull out", description="drawer",
    )
    handle = _handle(f"{name}_handle", name, x_front, 0.5 * (y0 + y1), z1 - 0.4 * (z1 - z0), params.handle_m, False,
                     min(0.25, 0.5 * (y1 - y0)), rgba)
    return [drawer, handle]


def articulated_parts(label: str, size_m, rgba=None) -> list[PartSpec]:
    """Part specifications of the template for ``label`` fitted to ``size_m`` = (D, W, H).

    The parts fill x in [-D/2, D/2], y in [-W/2, W/2], z in [0, H] (handles included). Raises
    ValueError for a label without a template (see :data:`ARTICULATED_LABELS`).
    """
    if label not in _PARAMS:
        raise ValueError(f"no articulation template for '{label}'; templates: {', '.join(ARTICULATED_LABELS)}")
    p = _PARAMS[label]
    d, w, h = (float(v) for v in size_m)
    if label == "laptop":
        return _laptop(d, w, h, p, rgba)
    if label == "box_with_lid":
        return _box_with_lid(d, w, h, p, rgba)
    if label == "door":
        return _door(d, w, h, p, rgba)
    # keep panels and fronts proportionate for small measured sizes
    t = min(p.panel_m, 0.1 * min(d, w, h))
    td = min(p.door_m, 0.15 * d)
    hp = min(p.handle_m, 0.1 * d)
    x_front = d / 2.0 - hp - GAP_M  # door front face
    x_door_back = x_front - td
    x_body_front = x_door_back - GAP_M
    body_depth = x_body_front + d / 2.0
    mat_body = _mat(p, rgba, p.panel_density_scale)
    mat_front = _mat(p, rgba)  # doors: solid panels, or hollow with sheet_m walls
    shelves = 0
    if label in ("cabinet", "wardrobe") and h > 0.6:
        shelves = 1 if h < 1.2 else 3
    body_solids = _carcass(-d / 2.0, x_body_front, w, h, t, shelves)
    body = lambda extra: PartSpec(  # noqa: E731
        "body", None, ConvexSolids(tuple(body_solids + extra)), mat_body,
        affordance_rank=6, affordance="place objects on top", description=f"{label} body",
    )
    parts: list[PartSpec] = []
    y0, y1, z0, z1 = -w / 2.0, w / 2.0, 0.0, h
    g = GAP_M
    if label in ("cabinet", "wardrobe"):
        doors = 2 if (w >= h or (label == "wardrobe" and w > 0.8)) else 1
        if doors == 1:
            parts += _vertical_door("door", "body", x_door_back, x_front, y0 + g, y1 - g, z0 + g, z1 - g, True, mat_front, p, rgba)
        else:
            parts += _vertical_door("door_left", "body", x_door_back, x_front, y0 + g, -g / 2, z0 + g, z1 - g, True, mat_front, p, rgba)
            parts += _vertical_door("door_right", "body", x_door_back, x_front, g / 2, y1 - g, z0 + g, z1 - g, False, mat_front, p, rgba)
        return [body([])] + parts
    if label == "drawer_unit":
        n = int(np.clip(round(h / 0.2), 1, 6))
        edges = np.linspace(z0, z1, n + 1)
        for i in range(n):
            parts += _drawer(f"drawer_{i}", "body", -d / 2.0 + t, x_front, y0 + g, y1 - g, edges[i] + g, edges[i + 1] - g,
                             t, h - t, body_depth, mat_front, p, rgba)
        return [body([])] + parts
    if label == "refrigerator":
        if h > 1.4:
            split = z0 + h / 3.0
            parts += _vertical_door("freezer_door", "body", x_door_back, x_front, y0 + g, y1 - g, z0 + g, split - g / 2, False, mat_front, p, rgba)
            parts += _vertical_door("fridge_door", "body", x_door_back, x_front, y0 + g, y1 - g, split + g / 2, z1 - g, False, mat_front, p, rgba)
        else:
            parts += _vertical_door("door", "body", x_door_back, x_front, y0 + g, y1 - g, z0 + g, z1 - g, False, mat_front, p, rgba)
        return [body([])] + parts
    if label == "microwave":
        y_split = y0 + 0.72 * w
        panel = [box_solid([x_door_back, y_split + g / 2, z0], [x_front, y1, z1])]
        parts += _vertical_door("door", "body", x_door_back, x_front, y0 + g, y_split - g / 2, z0 + g, z1 - g, True, mat_front, p, rgba)
        # the control panel reaches the door layer: connect it to the carcass
        panel.append(box_solid([x_body_front - t, y_split + g / 2, z0], [x_door_back + 1e-4, y1, z1]))
        return [body(panel)] + parts
    if label == "oven":
        z_split = z0 + 0.8 * h
        panel = [box_solid([x_body_front - t, y0, z_split + g / 2], [x_front, y1, z1])]
        parts += _bottom_door("door", "body", x_door_back, x_front, y0 + g, y1 - g, z0 + g, z_split - g / 2, mat_front, p, rgba)
        return [body(panel)] + parts
    if label == "dishwasher":
        parts += _bottom_door("door", "body", x_door_back, x_front, y0 + g, y1 - g, z0 + g, z1 - g, mat_front, p, rgba)
        return [body([])] + parts
    raise AssertionError(label)


def _laptop(d, w, h, p, rgba) -> list[PartSpec]:
    """Closed laptop: base slab and lid slab hinged at the back top edge of the base (axis -Y:
    the lid's front edge rises). Total thickness min(H, 35 mm) (a laptop photographed open
    still gets a closed model: parts are modelled closed at rest)."""
    hh = min(h, 0.035)
    zb = 0.6 * hh
    mat = _mat(p, rgba)
    base = PartSpec("base", None, ConvexSolids((box_solid([-d / 2, -w / 2, 0.0], [d / 2, w / 2, zb]),)), mat,
                    affordance_rank=3, affordance="type on keyboard", description="laptop base with keyboard")
    lid = PartSpec("lid", "base", ConvexSolids((box_solid([-d / 2, -w / 2, zb + GAP_M], [d / 2, w / 2, hh]),)), mat,
                   JointSpec(JointType.REVOLUTE, (0.0, -1.0, 0.0), (-d / 2, 0.0, zb + GAP_M / 2), 0.0, LAPTOP_LIMIT_RAD),
                   affordance_rank=1, affordance="lift lid to open", description="screen lid")
    return [base, lid]


def _box_with_lid(d, w, h, p, rgba) -> list[PartSpec]:
    """Open-top box (walls ``panel_m``) with a lid slab hinged at its back top edge (axis -Y)."""
    t = min(p.panel_m, 0.1 * min(d, w, h))
    zl = h - t - GAP_M
    mat = _mat(p, rgba, p.panel_density_scale)
    walls = [
        box_solid([-d / 2, -w / 2, 0.0], [d / 2, w / 2, t]),
        box_solid([-d / 2, -w / 2, 0.0], [-d / 2 + t, w / 2, zl]),
        box_solid([d / 2 - t, -w / 2, 0.0], [d / 2, w / 2, zl]),
        box_solid([-d / 2, -w / 2, 0.0], [d / 2, -w / 2 + t, zl]),
        box_solid([-d / 2, w / 2 - t, 0.0], [d / 2, w / 2, zl]),
    ]
    body = PartSpec("body", None, ConvexSolids(tuple(walls)), mat, affordance_rank=4, affordance="put things inside",
                    description="open box")
    lid = PartSpec("lid", "body", ConvexSolids((box_solid([-d / 2, -w / 2, h - t], [d / 2, w / 2, h]),)), mat,
                   JointSpec(JointType.REVOLUTE, (0.0, -1.0, 0.0), (-d / 2, 0.0, zl + GAP_M / 2), 0.0, LID_LIMIT_RAD),
                   affordance_rank=1, affordance="lift lid to open", description="hinged lid")
    return [body, lid]


def _door(d, w, h, p, rgba) -> list[PartSpec]:
    """Door in its frame: jambs and head (root, fixed to the building) and a leaf hinged on the
    -Y jamb, opening toward +X; a lever handle on the +Y side."""
    jamb = min(0.05, 0.08 * w)
    mat = _mat(p, rgba)
    hp = min(p.handle_m, 0.5 * d)
    x_back, x_front_frame = -d / 2, d / 2 - hp - GAP_M
    frame = [
        box_solid([x_back, -w / 2, 0.0], [x_front_frame, -w / 2 + jamb, h]),
        box_solid([x_back, w / 2 - jamb, 0.0], [x_front_frame, w / 2, h]),
        box_solid([x_back, -w / 2, h - jamb], [x_front_frame, w / 2, h]),
    ]
    root = PartSpec("frame", None, ConvexSolids(tuple(frame)), mat, affordance_rank=8, affordance="walk through",
                    description="door frame")
    leaf_t = min(p.door_m, x_front_frame - x_back)
    xl0 = x_front_frame - leaf_t
    y0, y1 = -w / 2 + jamb + GAP_M, w / 2 - jamb - GAP_M
    leaf = PartSpec("leaf", "frame", ConvexSolids((box_solid([xl0, y0, GAP_M * 5], [x_front_frame, y1, h - jamb - GAP_M]),)), mat,
                    JointSpec(JointType.REVOLUTE, (0.0, 0.0, -1.0), (x_front_frame, y0, 0.0), 0.0, DOOR_LIMIT_RAD),
                    affordance_rank=2, affordance="push or pull to open", description="door leaf")
    handle = _handle("leaf_handle", "leaf", x_front_frame, y1 - 0.07, min(1.0, 0.5 * h), hp, False, 0.12, rgba)
    return [root, leaf, handle]
