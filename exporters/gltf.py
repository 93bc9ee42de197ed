"""glTF binary export of the visual scene (``scene.glb``) with trimesh.

One node per part, named ``NAME`` (root part) or ``NAME/PART`` like the MJCF bodies, carrying
the part's world transform (parts at rest pose); geometry in the asset frame with per-vertex
colours (the material colour when the mesh has none). glTF is +Y up, so every node transform is
premultiplied by ``GLTF_FROM_WORLD`` (a -90 degree rotation about X taking our Z-up world to
Y-up): viewers show the room upright. Collision pieces are not written (glTF is for looking).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from exporters import names
from scene_builder.errors import ExportError
from scene_builder.model import Scene

# Z-up world -> glTF Y-up: (x, y, z) -> (x, z, -y).
GLTF_FROM_WORLD = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)


def build_trimesh_scene(scene: Scene):
    """A ``trimesh.Scene`` with one geometry node per part (transforms already in glTF Y-up)."""
    import trimesh

    out = trimesh.Scene(base_frame="world")
    for placed in scene.objects:
        for part in placed.asset.parts:
            v = part.visual
            colors = v.vertex_colors_rgba
            if colors is None:
                rgba = np.round(np.clip(part.material.rgba, 0.0, 1.0) * 255).astype(np.uint8)
                colors = np.tile(rgba, (len(v.vertices_m), 1))
            mesh = trimesh.Trimesh(vertices=np.array(v.vertices_m), faces=np.array(v.faces),
                                   vertex_colors=np.array(colors), process=False)
            name = names.body_name(placed.asset, part)
            out.add_geometry(mesh, node_name=name, geom_name=name,
                             transform=GLTF_FROM_WORLD @ placed.world_from_asset)
    return out


def write_gltf(scene: Scene, out_dir: Path) -> Path:
    """Write ``out_dir/scene.glb``, load it back with trimesh and check every part node is there."""
    import trimesh

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "scene.glb"
    tm = build_trimesh_scene(scene)
    path.write_bytes(trimesh.exchange.gltf.export_glb(tm, include_normals=True))
    back = trimesh.load(str(path), force="scene")
    for placed in scene.objects:
        for part in placed.asset.parts:
            name = names.body_name(placed.asset, part)
            if name not in back.graph.nodes_geometry:
                raise ExportError(f"glTF of object {placed.name}: node {name} missing after reading {path.name} back")
    return path
