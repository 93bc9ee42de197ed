"""Names shared by the exporters: MJCF body/joint/geom names (DEVELOPERS.md conventions), file
names for meshes and sanitised, unique identifiers for USD prims and URDF links.

Names can come from model text (PhysX part names), detector labels or a hand-edited
``scene.json``: anything a ``str`` can hold. Every name is sanitised before it becomes a file or
prim name: :func:`file_stem` gives file names with no path separators, no leading dot, bounded
length and no collisions (distinct names give distinct stems); :class:`UniqueNames` gives valid,
unique prim names.

Pure Python (no heavy imports)."""

from __future__ import annotations

import hashlib
import json
import re

from scene_builder.model import ObjectAsset, Part

_FILE_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]+")


def body_name(asset: ObjectAsset, part: Part) -> str:
    """MJCF / URDF body name of a part: ``NAME`` for the root part, ``NAME/PART`` otherwise."""
    return asset.name if part.parent is None else f"{asset.name}/{part.name}"


def free_joint_name(asset: ObjectAsset) -> str:
    return f"{asset.name}/free"


def joint_name(asset: ObjectAsset, part: Part, suffix: str = "") -> str:
    """``NAME/PART/joint`` (``suffix`` distinguishes the slide of a revolute-prismatic joint)."""
    return f"{asset.name}/{part.name}/joint{suffix}"


#: A piece kept as it is: starts with a letter or digit, no "__", does not end with "_" (so that
#: joining pieces with "__" can be undone), at most _MAX_PIECE characters.
_PLAIN_PIECE = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9.-]|_(?=[A-Za-z0-9.-]))*")
_MAX_PIECE = 64


def file_stem(*pieces: str) -> str:
    """A file-system safe stem made of ``pieces`` joined by ``__``.

    Plain pieces (letters, digits, ``.``, ``-`` and single inner ``_``; ``chair_1``, ``door``) are
    kept as they are. When any piece is not plain, characters outside ``[A-Za-z0-9_.-]`` become
    ``_``, a leading dot is replaced, long pieces are cut, and ``~`` plus 12 hex digits of a hash
    of the original pieces is appended: ``a b`` and ``a_b`` stay apart. The result is never empty,
    never starts with a dot, holds no path separator, and is at most 230 characters for three
    pieces (a file name may have 255). Distinct piece tuples give distinct stems (plain stems split
    back into their pieces; hashed ones carry ``~``, which plain ones never do)."""
    if pieces and all(len(p) <= _MAX_PIECE and _PLAIN_PIECE.fullmatch(p) for p in pieces):
        return "__".join(pieces)
    safe = "__".join(_FILE_UNSAFE.sub("_", p)[:_MAX_PIECE] for p in pieces).lstrip(".") or "_"
    digest = hashlib.sha256(json.dumps(list(pieces)).encode("utf-8")).hexdigest()[:12]
    return f"{safe}~{digest}"


def valid_identifier(name: str) -> str:
    """A USD prim name (``Tf.MakeValidIdentifier`` rules: letters, digits, ``_``, not starting
    with a digit). Written without pxr so that it is cheap; ``test_export_usd`` checks it agrees
    with ``Tf.MakeValidIdentifier``."""
    if not name:
        return "_"
    # Tf works on UTF-8 bytes: the first byte stays when it is [A-Za-z_] and becomes "_"
    # otherwise (a NUL too); every later byte that is not [A-Za-z0-9_] becomes one "_", except a
    # NUL, which it keeps and which then ends the name (pxr returns a C string): "\x000" -> "_0",
    # "a\x000" -> "a".
    raw = name.encode("utf-8")
    first = chr(raw[0])
    out = first if first.isascii() and (first.isalpha() or first == "_") else "_"
    for b in raw[1:]:
        if b == 0:
            break
        c = chr(b)
        out += c if c.isascii() and (c.isalnum() or c == "_") else "_"
    return out


class UniqueNames:
    """Hands out unique sanitised names: ``a``, ``a_1``, ``a_2`` ... in call order (deterministic).
    ``reserved``: names that are never handed out (siblings the caller defines itself)."""

    def __init__(self, reserved: tuple[str, ...] = ()) -> None:
        self._used: set[str] = set(reserved)

    def __call__(self, name: str) -> str:
        base = valid_identifier(name)
        out, k = base, 1
        while out in self._used:
            out = f"{base}_{k}"
            k += 1
        self._used.add(out)
        return out
