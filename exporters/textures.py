"""Texture files shared by the exporters: ``OUT/textures/<name>.png`` (one per scene texture,
deterministic bytes), and the OBJ material library that points OBJ consumers (URDF tools, mesh
viewers) at them. Pure Python."""

from __future__ import annotations

import threading
from pathlib import Path

from exporters import names
from scene_builder.model import Scene, Texture, TriangleMesh

TEXTURE_DIR = "textures"

#: Held while a file shared by several formats (``meshes/``, ``textures/``) is checked and written:
#: ``exporters.export_scene`` writes the SDF on a second thread beside the URDFs, and one of them
#: must not find a file the other is half-way through writing.
SHARED_FILES = threading.RLock()


def texture_file(texture: Texture) -> str:
    """File name of ``texture`` under ``textures/``."""
    return names.file_stem(texture.name) + ".png"


def write_texture(texture: Texture, out_dir: Path) -> str:
    """Write ``out_dir/textures/<name>.png`` (once per name; PNG at a fixed compression level, so
    the same image gives the same bytes: ``Texture.png_bytes``) and return its path relative
    to ``out_dir``."""
    rel = f"{TEXTURE_DIR}/{texture_file(texture)}"
    path = Path(out_dir) / rel
    with SHARED_FILES:
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(texture.png_bytes)
    return rel


def scene_textures(scene: Scene) -> list[Texture]:
    """Every distinct texture of the scene (by name), in a deterministic order."""
    seen: dict[str, Texture] = {}
    meshes: list[TriangleMesh] = []
    bg = scene.room.background
    if bg is not None:
        meshes += [bg.surface, *bg.static_meshes]
    for placed in scene.objects:
        meshes += [p.visual for p in placed.asset.parts]
    for m in meshes:
        if m.texture is not None and m.texture.name not in seen:
            seen[m.texture.name] = m.texture
    return [seen[k] for k in sorted(seen)]


def write_mtl(obj_path: Path, texture: Texture, out_dir: Path) -> str:
    """Write ``<obj stem>.mtl`` beside an OBJ file: one material ``photo`` whose diffuse map is
    the texture (path relative to the OBJ's folder). Returns the .mtl file name."""
    import os

    rel_tex = write_texture(texture, out_dir)
    tex_from_obj = os.path.relpath(Path(out_dir) / rel_tex, Path(obj_path).parent)
    name = Path(obj_path).stem + ".mtl"
    (Path(obj_path).parent / name).write_text(
        "# scene-builder: the photo projected from the input camera\n"
        "newmtl photo\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\n"
        f"map_Kd {tex_from_obj}\n"
    )
    return name
