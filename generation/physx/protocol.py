"""The PhysX-Anything / PhysX-Omni overall-description parser: the text (grammar in
:mod:`generation.physx.description`) read into its dataclasses (upstream ``basic_info.json``
files: :mod:`generation.physx.basic_info`, which shares the unit and repair helpers here).
:func:`parse_description` reads every known variation, repairs what it can and
lists each repair or drop in :class:`ParseReport`; values are stored in SI (kg/m^3, Pa), joints in
the text's grid units (so that :func:`~generation.physx.description.write_description`
round-trips); :mod:`generation.physx.grid_frame` converts joints to the asset frame in metres and
radians. Raises only :class:`ProtocolError` on any input (``scene_builder.bench.fuzz``).
"""

from __future__ import annotations

import math
import re
from dataclasses import replace

from generation.physx.description import (
    MovementType,
    ParseReport,
    PhysxDescription,
    PhysxGroup,
    PhysxPart,
    ProtocolError,
)
from generation.physx.description import round_sig as _sig

__all__ = ["ProtocolError", "parse_description"]

# --------------------------------------------------------------------------------------------
# Numbers and units
# --------------------------------------------------------------------------------------------

_NUM = r"(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?(?:\s*[x×*]\s*10\s*\^\s*[-+]?[0-9]+)?"
# The lookbehind anchors a range at the start of a number: without it a long digit run with no
# separator after it costs quadratic time (a match is tried, and backtracked, from every digit).
_RANGE = re.compile(rf"(?<![0-9.])({_NUM})\s*(?:-|–|—|~|to)\s*({_NUM})")
_SIGNED = re.compile(rf"[-+]?{_NUM}")
_CUBE = r"(?:\^\s*3|3|³)"
_UNITS: dict[str, tuple[tuple[str, float], ...]] = {
    "density": (
        (rf"kg\s*/\s*m\s*{_CUBE}", 1.0),
        (rf"t\s*/\s*m\s*{_CUBE}", 1000.0),
        (rf"g\s*/\s*(?:cm\s*{_CUBE}|cc|ml)", 1000.0),
    ),
    "modulus": (("GPa", 1e9), ("MPa", 1e6), ("kPa", 1e3), (r"(?<![A-Za-z])Pa", 1.0), (r"N\s*/\s*m\s*\^?\s*2", 1.0)),
    "ratio": (),
}
_DEFAULT_SCALE = {"density": 1000.0, "modulus": 1e9, "ratio": 1.0}  # g/cm^3, GPa, unitless
_UNIT_NAME = {"density": "g/cm^3", "modulus": "GPa", "ratio": ""}


def _to_float(token: str) -> float:
    """The float of a number token (``1.5``, ``2e9``, ``2 x 10^9``); inf or 0 when it is out of
    float range (never an OverflowError). Raises ValueError for a token that is no number."""
    m = re.match(r"^([-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?)(?:\s*[x×*]\s*10\s*\^\s*([-+]?[0-9]+))?$", token.strip())
    if m is None:
        raise ValueError(token)
    value = float(m.group(1))
    if m.group(2) is not None:
        digits = m.group(2).lstrip("+-")
        exponent = int(digits) if len(digits) <= 6 else 999999
        sign = "-" if m.group(2).startswith("-") else ""
        value *= float(f"1e{sign}{exponent}")  # saturates to inf / 0.0 where 10.0 ** n raises
    return value


#: A density, modulus or ratio field longer than this is no number (real ones are < 30 characters).
_MAX_FIELD = 200

#: Labels, group ids, ranks longer than this many digits are no PhysX numbers (Python also refuses
#: int() of more than 4300 digits).
_MAX_DIGITS = 9


def _small_int(digits: str) -> int | None:
    """int of a (signed) digit string from model text, None when it has more than _MAX_DIGITS digits."""
    return int(digits) if len(digits.lstrip("+-")) <= _MAX_DIGITS else None


def _quantity(text: str, kind: str, what: str, warnings: list[str]) -> float | None:
    """SI value of a density ('density'), Young's modulus ('modulus') or Poisson ratio ('ratio')
    field: units recognised and removed, ranges -> midpoint, several values -> mean."""
    raw = text.strip()
    if not raw or raw.upper() in ("N/A", "NA", "NONE", "NULL", "-"):
        warnings.append(f"{what}: no value ({raw!r})")
        return None
    if len(raw) > _MAX_FIELD:
        warnings.append(f"{what}: {len(raw)} characters is no number, dropped")
        return None
    scale, unit_seen = _DEFAULT_SCALE[kind], False
    rest = raw
    for pattern, s in _UNITS[kind]:
        if re.search(pattern, rest, flags=re.IGNORECASE if kind == "density" else 0):
            scale, unit_seen = s, True
            rest = re.sub(pattern, " ", rest, flags=re.IGNORECASE if kind == "density" else 0)
            break
    values: list[float] = []
    for a, b in _RANGE.findall(rest):
        values.append((_to_float(a) + _to_float(b)) / 2.0)
        warnings.append(f"{what}: range {a}-{b} read as its midpoint")
    rest = _RANGE.sub(" ", rest)
    values += [_to_float(t) for t in _SIGNED.findall(rest)]
    if not values:
        warnings.append(f"{what}: no number in {raw!r}")
        return None
    if len(values) > 1:
        warnings.append(f"{what}: {len(values)} values in {raw!r}, using their mean")
    # fsum raises on inf + -inf (ValueError) and on an intermediate sum beyond float range
    # (OverflowError): such values are out of range for any quantity, and dropped below.
    finite = all(math.isfinite(v) and abs(v) < 1e300 for v in values)
    value = math.fsum(values) / len(values) if finite else math.inf
    if not math.isfinite(value):
        warnings.append(f"{what}: {raw[:40]!r} is out of range, dropped")
        return None
    if not unit_seen and kind == "density" and value > 30.0:
        warnings.append(f"{what}: {value:g} is no density in g/cm^3, read as kg/m^3")
        scale = 1.0
    if not unit_seen and kind == "modulus" and value > 1e5:
        warnings.append(f"{what}: {value:g} is no modulus in GPa, read as Pa")
        scale = 1.0
    value *= scale
    if kind == "ratio" and not 0.0 <= value < 0.5:
        clamped = min(max(value, 0.0), 0.49)
        warnings.append(f"{what}: Poisson ratio {value:g} outside [0, 0.5), clamped to {clamped:g}")
        value = clamped
    if kind != "ratio" and value <= 0.0:
        warnings.append(f"{what}: non-positive value {value:g} dropped")
        return None
    return _sig(value)


# --------------------------------------------------------------------------------------------
# Parser
# --------------------------------------------------------------------------------------------

_HEADER = re.compile(r"^\s*(name|category|dimensions?|parts|group_info|group info|groups)\s*:\s*(.*)$", re.IGNORECASE)
_PART = re.compile(r"^\s*l_([0-9]{1,9})\s*:\s*(.*)$")
_GROUP = re.compile(r"^\s*group_([0-9]{1,9})\s*:\s*(.*)$", re.IGNORECASE)
_INT = re.compile(r"[-+]?[0-9]+")
_TYPE_WORDS = {
    "FIXED": MovementType.FIXED,
    "FREE": MovementType.FREE,
    "SLIDE": MovementType.SLIDE,
    "PRISMATIC": MovementType.SLIDE,
    "REVOLUTE": MovementType.REVOLUTE,
    "ROTATE": MovementType.REVOLUTE,
    "HINGE": MovementType.REVOLUTE,
    "BALL": MovementType.BALL,
    "SPHERICAL": MovementType.BALL,
}


def _parse_dimension(text: str, warnings: list[str]) -> tuple[float, float, float] | None:
    nums = [float(t) for t in re.findall(r"[0-9]+(?:\.[0-9]+)?|\.[0-9]+", text)]
    if len(nums) != 3 or min(nums, default=0.0) <= 0.0 or not all(math.isfinite(n) and n < 1e6 for n in nums):
        warnings.append(f"Dimension: expected three positive numbers A*B*C in cm, got {text.strip()[:40]!r}")
        return None
    low = text.lower()
    scale = 1.0
    if re.search(r"\bmm\b", low):
        scale = 0.1
        warnings.append("Dimension: given in mm, converted to cm")
    elif re.search(r"(?<![cm])\bm\b|\bmeters?\b|\bmetres?\b", low):
        scale = 100.0
        warnings.append("Dimension: given in m, converted to cm")
    return (_sig(nums[0] * scale), _sig(nums[1] * scale), _sig(nums[2] * scale))


def _split_part_fields(body: str, where: str, warnings: list[str]) -> list[str]:
    """Seven fields: name, rank, material, density, young, poisson, description."""
    if "|" in body:
        fields = [f.strip() for f in body.split("|")]
        return fields[:6] + ["| ".join(fields[6:])] if len(fields) > 7 else fields
    pieces = [p.strip() for p in body.split(",")]
    # The name may itself contain commas: the rank is the first later field that is an integer.
    for i in range(1, len(pieces)):
        if re.fullmatch(r"[-+]?\d+", pieces[i]):
            if i > 1:
                warnings.append(f"{where}: name contains {i - 1} comma(s), kept whole")
            return [", ".join(pieces[:i])] + pieces[i : i + 5] + [", ".join(pieces[i + 5 :])]
    return pieces[:6] + [", ".join(pieces[6:])] if len(pieces) > 7 else pieces


def _parse_part(label: int, body: str, warnings: list[str]) -> PhysxPart:
    where = f"l_{label}"
    fields = _split_part_fields(body, where, warnings)
    if len(fields) < 7:
        warnings.append(f"{where}: {len(fields)} of 7 fields, the missing ones left empty")
        fields += [""] * (7 - len(fields))
    name, rank_s, material, dens_s, young_s, pois_s, desc = fields
    m = _INT.search(rank_s)
    rank = None if m is None else _small_int(m.group())
    if rank is None:
        warnings.append(f"{where}: no affordance rank in {rank_s[:20]!r}, using 5")
        rank = 5
    else:
        if not 1 <= rank <= 10:
            warnings.append(f"{where}: affordance rank {rank} clamped to 1..10")
            rank = min(max(rank, 1), 10)
    return PhysxPart(
        label=label,
        name=name.strip(),
        affordance_rank=rank,
        material=material.strip(),
        density_kg_m3=_quantity(dens_s, "density", f"{where} density", warnings),
        youngs_modulus_pa=_quantity(young_s, "modulus", f"{where} Young's modulus", warnings),
        poisson_ratio=_quantity(pois_s, "ratio", f"{where} Poisson's ratio", warnings),
        description=desc.strip(),
    )


def _bracket(line: str, key: str, n: int, where: str, warnings: list[str]) -> tuple[float, ...] | None:
    m = re.search(rf"{key}[^:\[]*:\s*\[([^\]]*)\]", line, flags=re.IGNORECASE)
    if m is None:
        warnings.append(f"{where}: no '{key}: [...]'")
        return None
    out: list[float] = []
    for item in m.group(1).split(","):
        try:
            v = _to_float(item.strip().strip("'\""))
            if not math.isfinite(v):
                raise ValueError(item)
            out.append(v)
        except ValueError:
            warnings.append(f"{where}: {key} item {item.strip()[:15]!r} is not a finite number, read as 0")
            out.append(0.0)
    if len(out) != n:
        warnings.append(f"{where}: {key} has {len(out)} values, expected {n}")
        out = (out + [0.0] * n)[:n]
    return tuple(out)


def _movement(line: str, where: str, warnings: list[str]) -> MovementType | None:
    m = re.search(r"Type\s*:\s*([A-Za-z]+)", line, flags=re.IGNORECASE)
    if m is None:
        return None
    word = m.group(1).upper()
    if word.startswith("CB"):
        return MovementType.REVOLUTE_SLIDE
    for key, mt in _TYPE_WORDS.items():
        if word.startswith(key):
            warnings.append(f"{where}: movement type {m.group(1)!r} read as {mt.value}")
            return mt
    try:
        return MovementType(word[0])
    except ValueError:
        return None


def _parse_group(gid: int, body: str, warnings: list[str]) -> PhysxGroup | None:
    where = f"group_{gid}"
    bm = re.search(r"\[([^\]]*)\]", body)
    member_text = bm.group(1) if bm else re.split(r"[;(]", body, maxsplit=1)[0]
    members = tuple(int(x) for x in re.findall(r"l_([0-9]{1,9})(?![0-9])", member_text))
    if not members:
        warnings.append(f"{where}: no member parts, group dropped")
        return None
    movement = _movement(body, where, warnings)
    parents = re.findall(r"relative\s+to\s+group_([0-9]{1,9})(?![0-9])", body, flags=re.IGNORECASE)
    parent = int(parents[-1]) if parents else None
    if movement is None:
        movement = MovementType.FIXED
        warnings.append(f"{where}: no readable movement type, made fixed")
    kw: dict = {}
    if movement is MovementType.SLIDE:
        kw["slide_direction"] = _bracket(body, "direction", 3, where, warnings)
        kw["slide_range_vox"] = _bracket(body, "range", 2, where, warnings)
    elif movement is MovementType.REVOLUTE:
        kw["axis_direction"] = _bracket(body, "direction", 3, where, warnings)
        kw["axis_position_vox"] = _bracket(body, "position", 3, where, warnings)
        kw["revolute_range_deg"] = _bracket(body, "range", 2, where, warnings)
    elif movement is MovementType.BALL:
        kw["axis_position_vox"] = _bracket(body, "position", 3, where, warnings)
    elif movement is MovementType.REVOLUTE_SLIDE:
        kw["axis_direction"] = _bracket(body, "axis direction", 3, where, warnings)
        kw["axis_position_vox"] = _bracket(body, "axis position", 3, where, warnings)
        kw["revolute_range_deg"] = _bracket(body, "revolute range", 2, where, warnings)
        kw["slide_direction"] = _bracket(body, "slide direction", 3, where, warnings)
        kw["slide_range_vox"] = _bracket(body, "slide range", 2, where, warnings)
    for key in ("revolute_range_deg", "slide_range_vox"):
        r = kw.get(key)
        if r is not None and r[0] > r[1]:
            warnings.append(f"{where}: {key} given as [max, min], re-sorted")
            kw[key] = (r[1], r[0])
    for key in ("axis_direction", "slide_direction"):
        d = kw.get(key)
        if d is not None and not any(abs(c) > 1e-9 for c in d):
            warnings.append(f"{where}: zero {key}, joint made fixed")
            return PhysxGroup(gid, members, MovementType.FIXED, parent)
    if any(v is None for v in kw.values()):
        warnings.append(f"{where}: missing joint parameters, joint made fixed")
        return PhysxGroup(gid, members, MovementType.FIXED, parent)
    return PhysxGroup(gid, members, movement, parent, **kw)


def _repair_groups(groups: list[PhysxGroup], labels: list[int], warnings: list[str]) -> tuple[PhysxGroup, ...]:
    """One base group 0, every part in exactly one group, parents that exist and form a tree."""
    label_set = set(labels)
    seen: set[int] = set()
    out: list[PhysxGroup] = []
    for g in sorted(groups, key=lambda g: g.group_id):
        members = []
        for m in g.members:
            if m not in label_set:
                warnings.append(f"group_{g.group_id}: unknown part l_{m} dropped")
            elif m in seen:
                warnings.append(f"group_{g.group_id}: part l_{m} already in an earlier group, dropped here")
            else:
                members.append(m)
                seen.add(m)
        if not members:
            warnings.append(f"group_{g.group_id}: no parts left, group dropped")
            continue
        out.append(replace(g, members=tuple(members)))
    if not out or out[0].group_id != 0:
        if out and out[0].parent is None:
            warnings.append(f"no group_0: group_{out[0].group_id} taken as the base")
            out[0] = replace(out[0], group_id=0, movement=MovementType.FIXED)
        else:
            warnings.append("no group_0: an empty base group added")
            out.insert(0, PhysxGroup(0, (), MovementType.FIXED))
    base = out[0]
    if base.movement is not MovementType.FIXED or base.parent is not None:
        warnings.append("group_0: the base is fixed (Type E) with no parent; repaired")
        base = PhysxGroup(0, base.members, MovementType.FIXED, None)
    ids = {g.group_id for g in out}
    fixed: list[PhysxGroup] = [base]
    for g in out[1:]:
        if g.parent is None or g.parent not in ids or g.parent == g.group_id:
            warnings.append(f"group_{g.group_id}: parent group {g.parent} does not exist, attached to group_0")
            g = replace(g, parent=0)
        fixed.append(g)
    # break cycles: walk up from every group; a walk that never reaches 0 is re-attached to 0
    parent_of = {g.group_id: g.parent for g in fixed}
    for i, g in enumerate(fixed[1:], start=1):
        walk, cur = set(), g.group_id
        while cur != 0 and cur not in walk:
            walk.add(cur)
            cur = parent_of[cur]
        if cur != 0:
            warnings.append(f"group_{g.group_id}: parent chain has a cycle, attached to group_0")
            parent_of[g.group_id] = 0
            fixed[i] = replace(g, parent=0)
    orphans = [lab for lab in labels if lab not in seen]
    if orphans:
        warnings.append(f"parts {', '.join(f'l_{o}' for o in orphans)} in no group, fixed to group_0")
        fixed[0] = replace(fixed[0], members=fixed[0].members + tuple(orphans))
    if not fixed[0].members:
        raise ProtocolError("no part can be the base: group_0 is empty and no other group is fixed to the world")
    return tuple(fixed)


def parse_description(text: str, grid: int = 32) -> tuple[PhysxDescription, ParseReport]:
    """Parse an overall description (either separator, ``Param:``/``Params:``, quoted or bare
    member lists, blank lines, missing trailing spaces). Values in SI; joints in grid units.

    Raises ProtocolError when no part line can be read at all.
    """
    warnings: list[str] = []
    header: dict[str, str] = {}
    parts: dict[int, PhysxPart] = {}
    groups: list[PhysxGroup] = []
    for n, raw in enumerate(text.replace("\r\n", "\n").split("\n"), start=1):
        line = raw.strip().strip("`")
        if not line:
            continue
        pm = _PART.match(line)
        if pm is not None:
            label = int(pm.group(1))
            if label in parts:
                warnings.append(f"line {n}: second l_{label} line dropped")
                continue
            parts[label] = _parse_part(label, pm.group(2), warnings)
            continue
        gm = _GROUP.match(line)
        if gm is not None:
            gid = int(gm.group(1))
            if any(g.group_id == gid for g in groups):
                warnings.append(f"line {n}: second group_{gid} line dropped")
                continue
            g = _parse_group(gid, gm.group(2), warnings)
            if g is not None:
                groups.append(g)
            continue
        hm = _HEADER.match(line)
        if hm is not None:
            key = hm.group(1).lower().replace(" ", "_")
            key = {"dimensions": "dimension", "groups": "group_info"}.get(key, key)
            header.setdefault(key, hm.group(2).strip())
            continue
        warnings.append(f"line {n}: unreadable line dropped: {line[:40]!r}")
    if not parts:
        raise ProtocolError("no part line 'l_<i>: ...' in the description; the model output is not a PhysX description")
    labels = sorted(parts)
    if labels != list(range(len(labels))):
        warnings.append(f"part labels {labels} are not 0..{len(labels) - 1}")
    for key in ("name", "category", "dimension"):
        if key not in header:
            warnings.append(f"no '{key.capitalize()}:' line")
    dimension = _parse_dimension(header["dimension"], warnings) if "dimension" in header else None
    desc = PhysxDescription(
        name=header.get("name", ""),
        category=header.get("category", ""),
        dimension_cm=dimension,
        parts=tuple(parts[k] for k in labels),
        groups=_repair_groups(groups, labels, warnings),
        grid=grid,
    )
    return desc, ParseReport(tuple(warnings))

