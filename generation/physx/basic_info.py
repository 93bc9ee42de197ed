"""``basic_info.json`` (the upstream parsers' output / the annotation schema, README G6 of
``shared/data/physx_protocol``) read into the dataclasses of :mod:`generation.physx.description`.

Every value is checked for its type before it is used, and a value of the wrong type or range
raises :class:`~generation.physx.protocol.ProtocolError` naming the field: no exception is turned
into a ProtocolError after the fact, so a bug of this module surfaces as itself
(``python -m scene_builder.bench.fuzz --only basic-info`` checks that nothing else escapes).

The schema::

    {"object_name": str, "category": str, "dimension": "A*B*C",
     "parts": [{"label": int, "name": str, "material": str, "priority_rank": int,
                "density": number | str, "Young's Modulus (GPa)": number | str,
                "Poisson's Ratio": number | str, "Basic_description": str}, ...],
     "group_info": {"0": [label, ...],
                    "<g>": [[label, ...], "<parent>", [params...], "<type>"], ...}}

Numbers may also be given as text (``"3"``); params are normalised (positions in [-0.5, 0.5] of
the grid, ranges in units of 180 degrees or of the grid) and are turned back into the text's grid
units.
"""

from __future__ import annotations

import math
import re

from generation.physx.description import MovementType, ParseReport, PhysxDescription, PhysxGroup, PhysxPart, ProtocolError
from generation.physx.description import round_sig as _sig
from generation.physx.protocol import _DEFAULT_SCALE, _MAX_DIGITS, _parse_dimension, _quantity, _repair_groups

#: How many params each movement type reads (direction, position, range; both for CB).
_PARAMS_NEEDED = {
    MovementType.FREE: 0,
    MovementType.FIXED: 0,
    MovementType.BALL: 6,
    MovementType.SLIDE: 8,
    MovementType.REVOLUTE: 8,
    MovementType.REVOLUTE_SLIDE: 16,
}
_SMALL_INT = re.compile(rf"\s*[-+]?[0-9]{{1,{_MAX_DIGITS}}}\s*")
_DIGITS = re.compile(rf"[0-9]{{1,{_MAX_DIGITS}}}")


def _shown(value) -> str:
    """A short, safe description of a JSON value for an error line."""
    if isinstance(value, bool) or value is None or isinstance(value, float):
        return repr(value)
    if isinstance(value, int):
        return repr(value) if abs(value) < 10**12 else "a very large integer"
    if isinstance(value, str):
        return repr(value[:30] + ("..." if len(value) > 30 else ""))
    return f"a {'list' if isinstance(value, list) else 'object' if isinstance(value, dict) else type(value).__name__}"


def _error(where: str, want: str, value) -> ProtocolError:
    return ProtocolError(f"basic_info does not follow the PhysX schema ({where}: expected {want}, got {_shown(value)})")


def _dict(value, where: str) -> dict:
    if not isinstance(value, dict):
        raise _error(where, "an object", value)
    return value


def _list(value, where: str) -> list:
    if not isinstance(value, list):
        raise _error(where, "a list", value)
    return value


def _int(value, where: str) -> int:
    """A whole number: an int, a finite float (truncated, as int() does) or its text; at most
    ``_MAX_DIGITS`` digits."""
    if isinstance(value, bool):
        raise _error(where, "a whole number", value)
    if isinstance(value, float) and math.isfinite(value) and abs(value) < 10.0**_MAX_DIGITS:
        return int(value)
    if isinstance(value, int) and abs(value) < 10**_MAX_DIGITS:
        return value
    if isinstance(value, str) and _SMALL_INT.fullmatch(value):
        return int(value)
    raise _error(where, "a whole number", value)


def _number(value, where: str) -> float:
    """The float of a number (an int or float, not a bool) or of its text (at most 64
    characters); inf for an int beyond float range; may be inf or nan."""
    if isinstance(value, bool):
        raise _error(where, "a number", value)
    if isinstance(value, int):
        return float(value) if abs(value) < 10**300 else math.copysign(math.inf, value)
    if isinstance(value, float):
        return value
    if isinstance(value, str) and len(value) <= 64:
        try:
            return float(value)
        except ValueError:  # what float() documents for text that is no number
            pass
    raise _error(where, "a number", value)


def _float(value, where: str) -> float:
    """A finite number (see :func:`_number`)."""
    v = _number(value, where)
    if not math.isfinite(v):
        raise _error(where, "a finite number", value)
    return v


def _text(value, where: str) -> str:
    """Text: a string, or a number written as text (JSON writers differ)."""
    if isinstance(value, str):
        return value
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return str(value)
    raise _error(where, "text", value)


def description_from_basic_info(data, grid: int) -> tuple[PhysxDescription, ParseReport]:
    """Load an upstream ``basic_info.json`` (PhysX-Anything strings or PhysX-Omni floats, README
    G6) into the same dataclasses as :func:`~generation.physx.protocol.parse_description`.
    Normalised params are turned back into the text's grid units.

    Raises ProtocolError (one line, naming the field) when the data does not follow that schema;
    nothing else on any JSON value."""
    data = _dict(data, "basic_info")
    warnings: list[str] = []
    parts = [_part(_dict(entry, f"parts[{i}]"), i, warnings) for i, entry in enumerate(_list(data.get("parts", []), "parts"))]
    group_info = _dict(data.get("group_info", {}), "group_info")
    keyed = sorted(((_int(key, f"group_info key {_shown(key)}"), value) for key, value in group_info.items()), key=lambda kv: kv[0])
    groups = [_group(gid, value, grid) for gid, value in keyed]
    if not parts:
        raise ProtocolError("basic_info has no parts")
    desc = PhysxDescription(
        name=_text(data.get("object_name", ""), "object_name"),
        category=_text(data.get("category", ""), "category"),
        dimension_cm=_parse_dimension(_text(data.get("dimension", ""), "dimension"), warnings),
        parts=tuple(sorted(parts, key=lambda p: p.label)),
        groups=_repair_groups(groups, sorted(p.label for p in parts), warnings),
        grid=grid,
    )
    return desc, ParseReport(tuple(warnings))


def _part(entry: dict, index: int, warnings: list[str]) -> PhysxPart:
    if "label" not in entry:
        raise ProtocolError(f"basic_info does not follow the PhysX schema (parts[{index}] has no 'label')")
    label = _int(entry["label"], f"parts[{index}].label")
    where = f"l_{label}"

    def quantity(key: str, kind: str) -> float | None:
        v = entry.get(key)
        if v is None:
            warnings.append(f"{where}: {key} is null")
            return None
        if isinstance(v, str):
            return _quantity(v, kind, f"{where} {key}", warnings)
        value = _number(v, f"{where} {key}") * _DEFAULT_SCALE[kind]
        if not math.isfinite(value):
            warnings.append(f"{where} {key}: {v!r} is out of range, dropped")
            return None
        return _sig(value)

    rank = _int(entry.get("priority_rank", 5), f"{where} priority_rank")
    return PhysxPart(
        label=label,
        name=_text(entry.get("name", ""), f"{where} name"),
        affordance_rank=min(max(rank, 1), 10),
        material=_text(entry.get("material", ""), f"{where} material"),
        density_kg_m3=quantity("density", "density"),
        youngs_modulus_pa=quantity("Young's Modulus (GPa)", "modulus"),
        poisson_ratio=quantity("Poisson's Ratio", "ratio"),
        description=_text(entry.get("Basic_description", ""), f"{where} Basic_description"),
    )


def _group(gid: int, value, grid: int) -> PhysxGroup:
    where = f"group_info {gid}"
    if gid == 0:
        return PhysxGroup(0, tuple(_int(v, f"{where} member") for v in _list(value, where)), MovementType.FIXED)
    value = _list(value, where)
    if len(value) != 4:
        raise _error(where, "[members, parent, params, type]", value)
    members_v, parent_v, params_v, type_v = value
    members = tuple(_int(m, f"{where} member") for m in _list(members_v, f"{where} members"))
    # A parent that is no group number ("-1", "none") is no parent: the repair attaches it to 0.
    if isinstance(parent_v, int) and not isinstance(parent_v, bool) and 0 <= parent_v < 10**_MAX_DIGITS:
        parent: int | None = parent_v
    elif isinstance(parent_v, str) and _DIGITS.fullmatch(parent_v):
        parent = int(parent_v)
    else:
        parent = None
    type_s = _text(type_v, f"{where} type").upper()
    movement = next((m for m in MovementType if m.value == type_s), None)
    if movement is None:
        raise _error(f"{where} type", "one of " + ", ".join(m.value for m in MovementType), type_v)
    p = [_float(v, f"{where} param") for v in _list(params_v, f"{where} params")]
    if len(p) < _PARAMS_NEEDED[movement]:
        raise _error(f"{where} params", f"{_PARAMS_NEEDED[movement]} numbers for type {movement.value}", params_v)

    def pos(v: list[float]) -> tuple[float, float, float]:
        return tuple(_sig((c + 0.5) * grid) for c in v)  # type: ignore[return-value]

    kw: dict = {}
    if movement is MovementType.SLIDE:
        kw = {"slide_direction": tuple(p[0:3]), "slide_range_vox": (_sig(p[6] * grid), _sig(p[7] * grid))}
    elif movement is MovementType.REVOLUTE:
        kw = {"axis_direction": tuple(p[0:3]), "axis_position_vox": pos(p[3:6]), "revolute_range_deg": (_sig(p[6] * 180.0), _sig(p[7] * 180.0))}
    elif movement is MovementType.BALL:
        kw = {"axis_position_vox": pos(p[3:6])}
    elif movement is MovementType.REVOLUTE_SLIDE:
        kw = {
            "axis_direction": tuple(p[0:3]),
            "axis_position_vox": pos(p[3:6]),
            "revolute_range_deg": (_sig(p[6] * 180.0), _sig(p[7] * 180.0)),
            "slide_direction": tuple(p[8:11]),
            "slide_range_vox": (_sig(p[14] * grid), _sig(p[15] * grid)),
        }
    return PhysxGroup(gid, members, movement, parent, **kw)
