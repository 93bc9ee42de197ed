"""A PhysX-Anything / PhysX-Omni overall description: its grammar, the dataclasses it is read
into, and its writer.

The layout (README section G1 of ``shared/data/physx_protocol``)::

    Name: <object name>
    Category: <category>
    Dimension: <A>*<B>*<C>                      (cm, along x, y, z of the PhysX grid)
    Parts: 
    l_<i>: <name>S<rank>S<material>S<density>S<young>S<poisson>S<description>
    Group_info: 
    group_0: ['l_<i>', ...]; Type: E; Param: N/A
    group_<g>: ['l_<i>', ...]; Type: <T> relative to group_<p>; Param: <params>

with ``S`` = ``", "`` (PhysX-Anything) or ``"| "`` (PhysX-Omni). Density is in g/cm^3, Young's
modulus in GPa, joint positions and slide ranges in voxel units of the grid (32 or 64), revolute
ranges in degrees. Values are stored in SI (kg/m^3, Pa), joints in the text's grid units, so that
:func:`write_description` round-trips what :func:`generation.physx.protocol.parse_description`
reads; :mod:`generation.physx.grid_frame` converts joints to the asset frame.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from scene_builder.errors import InputError

__all__ = [
    "MovementType",
    "ParseReport",
    "PhysxDescription",
    "PhysxGroup",
    "PhysxPart",
    "ProtocolError",
    "round_sig",
    "write_description",
]


class ProtocolError(InputError, ValueError):
    """An overall description that cannot be read at all (one-line message says why)."""


class MovementType(str, enum.Enum):
    """PhysX movement types of a group relative to its parent group."""

    FREE = "A"
    SLIDE = "B"
    REVOLUTE = "C"
    BALL = "D"
    REVOLUTE_SLIDE = "CB"
    FIXED = "E"


@dataclass(frozen=True)
class PhysxPart:
    """One ``l_<label>`` line. density_kg_m3 / youngs_modulus_pa / poisson_ratio (unitless) are
    None when the text had no usable number. affordance_rank: 1..10, 1 = most likely touched."""

    label: int
    name: str
    affordance_rank: int
    material: str
    density_kg_m3: float | None
    youngs_modulus_pa: float | None
    poisson_ratio: float | None
    description: str = ""


@dataclass(frozen=True)
class PhysxGroup:
    """One ``group_<id>`` line: member part labels moving together, relative to ``parent``.

    Joint parameters are kept in the text's units: directions unitless (PhysX grid axes),
    positions in voxel units from the grid's minimum corner, revolute ranges in degrees, slide
    ranges in voxel units. axis_* apply to REVOLUTE and REVOLUTE_SLIDE (axis_position_vox is the
    hinge point for BALL); slide_* to SLIDE and REVOLUTE_SLIDE; all None where they do not apply.
    """

    group_id: int
    members: tuple[int, ...]
    movement: MovementType
    parent: int | None = None
    axis_direction: tuple[float, float, float] | None = None
    axis_position_vox: tuple[float, float, float] | None = None
    revolute_range_deg: tuple[float, float] | None = None
    slide_direction: tuple[float, float, float] | None = None
    slide_range_vox: tuple[float, float] | None = None


@dataclass(frozen=True)
class PhysxDescription:
    """A parsed overall description. dimension_cm: extents along the PhysX grid's x, y, z (None
    when the text gave no three numbers). grid: voxels per side of the geometry grid (32 / 64)."""

    name: str
    category: str
    dimension_cm: tuple[float, float, float] | None
    parts: tuple[PhysxPart, ...]
    groups: tuple[PhysxGroup, ...]
    grid: int = 32

    def part(self, label: int) -> PhysxPart:
        for p in self.parts:
            if p.label == label:
                return p
        raise KeyError(label)


@dataclass(frozen=True)
class ParseReport:
    """What the parser repaired or dropped, one line each (empty for a clean text)."""

    warnings: tuple[str, ...] = field(default_factory=tuple)

    @property
    def clean(self) -> bool:
        return not self.warnings


# --------------------------------------------------------------------------------------------
# Numbers as text
# --------------------------------------------------------------------------------------------


def round_sig(x: float) -> float:
    """Round to 12 significant digits, so that unit conversions round-trip through text."""
    return float(f"{x:.12g}")


def _fmt_decimal(x: float) -> str:
    """Like the targets: '0.7', '10.0', '0.35' (always a decimal point unless exponent form)."""
    s = f"{round_sig(x):.12g}"
    return s if ("." in s or "e" in s or "inf" in s or "nan" in s) else s + ".0"


def _fmt_bracket(x: float) -> str:
    """Like the targets: integers without a decimal point, others as short decimals."""
    if abs(x - round(x)) < 1e-9:
        return str(int(round(x)))
    return f"{x:.12g}"


# --------------------------------------------------------------------------------------------
# Writer
# --------------------------------------------------------------------------------------------


def _fmt_list(values) -> str:
    return "[" + ", ".join(_fmt_bracket(v) for v in values) + "]"


def _fmt_quantity(value: float | None, scale: float, unit: str) -> str:
    if value is None:
        return "N/A"
    return _fmt_decimal(value / scale) + (f" {unit}" if unit else "")


def _group_params(g: PhysxGroup) -> str:
    mt = g.movement
    if mt is MovementType.SLIDE:
        return f"direction: {_fmt_list(g.slide_direction)}, slide range (in voxel grid): {_fmt_list(g.slide_range_vox)}"
    if mt is MovementType.REVOLUTE:
        return (
            f"direction: {_fmt_list(g.axis_direction)}, axis position (in voxel grid): {_fmt_list(g.axis_position_vox)}, "
            f"revolute range (degree): {_fmt_list(g.revolute_range_deg)}"
        )
    if mt is MovementType.BALL:
        return f"hinge position (in voxel grid): {_fmt_list(g.axis_position_vox)}"
    if mt is MovementType.REVOLUTE_SLIDE:
        return (
            f"axis direction: {_fmt_list(g.axis_direction)}, axis position (in voxel grid): {_fmt_list(g.axis_position_vox)}, "
            f"revolute range (degree): {_fmt_list(g.revolute_range_deg)}, slide direction: {_fmt_list(g.slide_direction)}, "
            f"slide range (in voxel grid): {_fmt_list(g.slide_range_vox)}"
        )
    return "N/A"


def write_description(desc: PhysxDescription, separator: str | None = None) -> str:
    """The training-target layout (G1): ``", "`` separators for grid 32 (PhysX-Anything),
    ``"| "`` for grid 64 (PhysX-Omni) unless ``separator`` says otherwise; no trailing newline."""
    sep = separator if separator is not None else (", " if desc.grid == 32 else "| ")
    lines = [f"Name: {desc.name}", f"Category: {desc.category}"]
    if desc.dimension_cm is not None:
        lines.append("Dimension: " + "*".join(_fmt_bracket(v) for v in desc.dimension_cm))
    lines.append("Parts: ")
    for p in desc.parts:
        fields = [
            p.name,
            str(p.affordance_rank),
            p.material,
            _fmt_quantity(p.density_kg_m3, 1000.0, "g/cm^3"),
            _fmt_quantity(p.youngs_modulus_pa, 1e9, ""),
            _fmt_quantity(p.poisson_ratio, 1.0, ""),
            p.description,
        ]
        lines.append(f"l_{p.label}: " + sep.join(fields))
    lines.append("Group_info: ")
    for g in desc.groups:
        members = "[" + ", ".join(f"'l_{m}'" for m in g.members) + "]"
        rel = "" if g.parent is None else f" relative to group_{g.parent}"
        lines.append(f"group_{g.group_id}: {members}; Type: {g.movement.value}{rel}; Param: {_group_params(g)}")
    return "\n".join(lines)
