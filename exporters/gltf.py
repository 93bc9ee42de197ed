"""glTF binary export of the visual scene (``scene.glb``) with trimesh.

One node per part, named ``NAME`` (root part) or ``NAME/PART`` like the MJCF bodies, carrying
the part's world transform (parts at rest pose); geometry in the asset frame with its photo
texture (embedded PNG, unlit-looking base colour), else per-vertex colours (the material colour
when the mesh has none). The static background is one node ``background`` (world frame) plus
``background/object/NAME`` for objects that became background. glTF is +Y up, so every node transform is
premultiplied by ``GLTF_FROM_WORLD`` (a -90 degree rotation about X taking our Z-up world to
Y-up): viewers show the room upright. The robot (``--robot``) is one node per geom,
``robot/BODY/geom_K``, at its start pose (qpos0) in the world frame, coloured as its materials.
Collision pieces are not written (glTF is for looking).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from exporters import names
from exporters.robot import robot_meshes
from scene_builder.errors import ExportError
from scene_builder.model import Scene, TriangleMesh

# Z-up world -> glTF Y-up: (x, y, z) -> (x, z, -y).
GLTF_FROM_WORLD = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)


def _trimesh(v: TriangleMesh, rgba, images: dict):
    """A ``trimesh.Trimesh`` of ``v``: textured (one PIL image per texture name, shared) or with
    vertex colours (``rgba`` (4,) in [0, 1] when the mesh has none)."""
    import trimesh
    from PIL import Image

    if v.texture is not None:
        if v.texture.name not in images:
            image = Image.fromarray(np.ascontiguousarray(v.texture.image_rgb))
            # Photo textures go into the .glb as JPEG (trimesh writes an image marked JPEG as
            # JPEG, anything else as PNG at zlib's default level: 0.9 s of a 21 s build for a
            # room's textures, cut from a JPEG photo in the first place).
            image.format = "JPEG"
            images[v.texture.name] = image
        material = trimesh.visual.material.PBRMaterial(baseColorTexture=images[v.texture.name], metallicFactor=0.0,
                                                       roughnessFactor=1.0, name=f"photo_{v.texture.name}")
        # trimesh's uv runs up from the bottom of the image (OpenGL); it flips v when writing glTF.
        uv = np.stack([v.uv[:, 0], 1.0 - v.uv[:, 1]], axis=1)
        visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
        return trimesh.Trimesh(vertices=np.array(v.vertices_m), faces=np.array(v.faces), visual=visual, process=False)
    colors = v.vertex_colors_rgba
    if colors is None:
        colors = np.tile(np.round(np.clip(rgba, 0.0, 1.0) * 255).astype(np.uint8), (len(v.vertices_m), 1))
    return trimesh.Trimesh(vertices=np.array(v.vertices_m), faces=np.array(v.faces), vertex_colors=np.array(colors), process=False)


def build_trimesh_scene(scene: Scene):
    """A ``trimesh.Scene`` with one geometry node per part (transforms already in glTF Y-up)."""
    import trimesh

    out = trimesh.Scene(base_frame="world")
    images: dict = {}
    bg = scene.room.background
    if bg is not None:
        grey = (0.7, 0.7, 0.7, 1.0)
        if len(bg.surface.faces):
            out.add_geometry(_trimesh(bg.surface, grey, images), node_name="background", geom_name="background", transform=GLTF_FROM_WORLD)
        for label, mesh in zip(bg.static_names, bg.static_meshes):
            name = f"background/object/{label}"
            out.add_geometry(_trimesh(mesh, grey, images), node_name=name, geom_name=name, transform=GLTF_FROM_WORLD)
    for placed in scene.objects:
        for part in placed.asset.parts:
            name = names.body_name(placed.asset, part)
            out.add_geometry(_trimesh(part.visual, part.material.rgba, images), node_name=name, geom_name=name,
                             transform=GLTF_FROM_WORLD @ placed.world_from_asset)
    if scene.robot is not None:
        for geom in robot_meshes(scene.robot, "glTF"):
            name = f"robot/{geom.name}"
            out.add_geometry(_trimesh(geom.mesh, geom.rgba, images), node_name=name, geom_name=name, transform=GLTF_FROM_WORLD)
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
    lost = sorted({n for n in tm.graph.nodes_geometry if n.startswith("robot/")} - set(back.graph.nodes_geometry))
    if lost:
        raise ExportError(f"glTF: {len(lost)} of the robot's nodes ({lost[0]}, ...) missing after reading {path.name} back")
    return path
