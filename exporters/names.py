"""Names shared by the exporters: MJCF body/joint/geom names (DEVELOPERS.md conventions), file
names for meshes and sanitised, unique identifiers for USD prims and URDF links.

Pure Python (no heavy imports)."""

from __future__ import annotations

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


def file_stem(*pieces: str) -> str:
    """A file-system safe stem made of ``pieces`` joined by ``__`` (characters outside
    ``[A-Za-z0-9_.-]`` become ``_``)."""
    return "__".join(_FILE_UNSAFE.sub("_", p) for p in pieces)


def valid_identifier(name: str) -> str:
    """A USD prim name (``Tf.MakeValidIdentifier`` rules: letters, digits, ``_``, not starting
    with a digit). Written without pxr so that it is cheap; ``test_export_usd`` checks it agrees
    with ``Tf.MakeValidIdentifier``."""
    name = name.split("\x00", 1)[0]  # Tf reads a C string
    if not name:
        return "_"
    # Tf works on UTF-8 bytes: every byte that is not [A-Za-z0-9_] becomes one "_".
    out = "".join(chr(b) if chr(b).isascii() and (chr(b).isalnum() or b == 0x5F) else "_" for b in name.encode("utf-8"))
    if out[0].isdigit():
        out = "_" + out[1:]
    return out


class UniqueNames:
    """Hands out unique sanitised names: ``a``, ``a_1``, ``a_2`` ... in call order (deterministic)."""

    def __init__(self) -> None:
        self._used: set[str] = set()

    def __call__(self, name: str) -> str:
        base = valid_identifier(name)
        out, k = base, 1
        while out in self._used:
            out = f"{base}_{k}"
            k += 1
        self._used.add(out)
        return out
