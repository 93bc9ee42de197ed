"""Photo textures and the static background in every export: MJCF (texture + material), USD
(UsdPreviewSurface reading ./textures/*.png through the st primvar; the background a static
triangle-mesh collider; --usdz packs it all), URDF (texture, background link), glTF (embedded
textures) and rerun."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from PIL import Image

from exporters import export_scene, record_scene
from generation.texture import photo_textured
from perception.background import observed_background
from scene_builder.bench.clutter import box_asset
from scene_builder.config import ExportConfig
from scene_builder.frames import pose, rot_z, transform_points
from scene_builder.model import GeneratedAsset, PlacedObject, Room, Scene
from tests import twin_fixtures as tf


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    obs, board = tf.observation()
    cam = tf.camera()
    bg = observed_background(obs, cam, (tf.wall(),), (board,))
    # The board as a thin box where it was seen, textured with the photo.
    centre = board.points_world_m.mean(axis=0)
    asset = box_asset("board_1", (0.02, 0.6, 0.4))
    world_from_asset = pose(rot_z(0.0), [centre[0] + 0.01, centre[1], centre[2] - 0.2])
    textured = photo_textured(GeneratedAsset(asset, world_from_asset, board.points_world_m), board, obs, cam)
    scene = Scene(cam, Room((tf.wall(),), bg), (PlacedObject(textured.asset, textured.world_from_asset),))
    out = tmp_path_factory.mktemp("textured")
    files = export_scene(scene, out, ExportConfig(usdz=True, viz="off", scene_urdf=True))
    return scene, out, files, obs, board


def test_textures_are_written_once_and_exact(exported):
    scene, out, files, obs, board = exported
    pngs = sorted(p.name for p in (out / "textures").glob("*.png"))
    assert pngs == ["background.png", "board_1.png"]
    back = np.array(Image.open(out / "textures" / "background.png"))
    np.testing.assert_array_equal(back, scene.room.background.surface.texture.image_rgb)
    # The object's texture is its crop of the photo: the board's red where the board was seen.
    tex = np.array(Image.open(out / "textures" / "board_1.png")).reshape(-1, 3).astype(int)
    assert np.mean(tex[:, 0] - tex[:, 1]) > 150  # red everywhere (outside the mask: filled from it)


def test_texture_files_and_scene_json_carry_the_same_png(exported, tmp_path):
    """Each texture is encoded once (``Texture.png_bytes``): the file under textures/ holds those
    bytes, scene.json the same bytes in base64, and they decode to the image."""
    import base64
    import io
    import json

    from scene_builder.serialize import scene_to_json

    scene, out, *_ = exported
    texture = scene.room.background.surface.texture
    assert (out / "textures" / "background.png").read_bytes() == texture.png_bytes
    np.testing.assert_array_equal(np.array(Image.open(io.BytesIO(texture.png_bytes))), texture.image_rgb)
    text = scene_to_json(scene)
    assert base64.b64encode(texture.png_bytes).decode("ascii") in text
    assert json.loads(text)["format"] == "scene-builder/scene"


def test_object_texture_coordinates_project_onto_its_pixels(exported):
    scene, out, files, obs, board = exported
    part = scene.objects[0].asset.parts[0]
    tex = part.visual.texture.image_rgb
    # Every front vertex (x = +0.01, facing the camera) maps into the board's red pixels.
    front = part.visual.vertices_m[:, 0] > 0.0
    uv = part.visual.uv[front]
    px = np.floor(uv * [tex.shape[1], tex.shape[0]]).astype(int)
    px = np.clip(px, 0, [tex.shape[1] - 1, tex.shape[0] - 1])
    assert np.all(tex[px[:, 1], px[:, 0], 0] > 150)


def test_mjcf_loads_with_textured_materials(exported):
    import mujoco

    scene, out, files, obs, board = exported
    m = mujoco.MjModel.from_xml_path(str(files.mjcf))
    assert m.ntex >= 2
    mats = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_MATERIAL, i) for i in range(m.nmat)]
    assert "photo/background" in mats and "photo/board_1" in mats
    g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "background/surface")
    assert g >= 0 and m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0
    assert m.mesh_texcoordnum[m.geom_dataid[g]] == len(scene.room.background.surface.vertices_m)


def test_usd_textures_are_relative_and_the_background_collides_as_a_triangle_mesh(exported):
    from pxr import Usd, UsdGeom, UsdPhysics, UsdShade

    scene, out, files, obs, board = exported
    stage = Usd.Stage.Open(str(files.usd))
    surface = stage.GetPrimAtPath("/World/Background/Surface")
    st = UsdGeom.PrimvarsAPI(surface).GetPrimvar("st")
    assert len(st.Get()) == len(scene.room.background.surface.vertices_m)
    np.testing.assert_allclose(np.array(st.Get())[:, 1], 1.0 - scene.room.background.surface.uv[:, 1], atol=1e-6)
    assert surface.HasAPI(UsdPhysics.CollisionAPI) and not surface.HasAPI(UsdPhysics.RigidBodyAPI)
    assert UsdPhysics.MeshCollisionAPI(surface).GetApproximationAttr().Get() == UsdPhysics.Tokens.none
    mat, _ = UsdShade.MaterialBindingAPI(surface).ComputeBoundMaterial()
    tex = stage.GetPrimAtPath(str(mat.GetPath()) + "/Texture")
    asset = tex.GetAttribute("inputs:file").Get()
    assert asset.path == "./textures/background.png"
    assert (out / "textures" / "background.png").samefile(asset.resolvedPath)


def test_usdz_holds_the_stage_and_its_textures(exported):
    from pxr import Usd

    scene, out, files, obs, board = exported
    usdz = out / "scene.usdz"
    with zipfile.ZipFile(usdz) as z:
        names = set(z.namelist())
    assert {"scene.usda", "textures/background.png", "textures/board_1.png"} <= names
    stage = Usd.Stage.Open(str(usdz))
    assert stage.GetPrimAtPath("/World/Background/Surface").IsValid()


def test_urdf_and_gltf_carry_the_background_and_textures(exported):
    import trimesh
    import yourdfpy

    scene, out, files, obs, board = exported
    urdf = yourdfpy.URDF.load(str(files.urdf), build_scene_graph=False, load_meshes=False)
    assert "background" in urdf.link_map and urdf.joint_map["background/fixed"].type == "fixed"
    assert len(urdf.link_map["background"].collisions) == scene.room.background.box_count + len(scene.room.background.static_pieces)
    # The per-object files: the background on its own (one link, no world), the board textured.
    alone = yourdfpy.URDF.load(str(files.object_urdfs / "background.urdf"), build_scene_graph=False, load_meshes=False)
    assert list(alone.link_map) == ["background"] and not alone.robot.joints
    assert len(alone.link_map["background"].collisions) == len(urdf.link_map["background"].collisions)
    board = yourdfpy.URDF.load(str(files.object_urdfs / "board_1.urdf"), build_scene_graph=False, load_meshes=False)
    assert (files.object_urdfs / board.link_map["board_1"].visuals[0].material.texture.filename).resolve() == (out / "textures" / "board_1.png").resolve()
    glb = trimesh.load(str(files.gltf), force="scene")
    surface = glb.geometry["background"]
    assert isinstance(surface.visual, trimesh.visual.TextureVisuals)
    atlas = scene.room.background.surface.texture.image_rgb  # the photo and the completed planes' textures
    assert surface.visual.material.baseColorTexture.size == (atlas.shape[1], atlas.shape[0])


def test_sdf_carries_the_background_and_textures(exported):
    import xml.etree.ElementTree as ET

    scene, out, files, obs, board = exported
    root = ET.parse(files.sdf).getroot()
    bg = root.find("world/model[@name='room']/link[@name='background']")
    assert len(bg.findall("collision")) == scene.room.background.box_count + len(scene.room.background.static_pieces)
    maps = {v.get("name"): v.findtext("material/pbr/metal/albedo_map") for v in bg.findall("visual")}
    assert maps["background_surface"] == "textures/background.png"
    board_map = root.find("world/model[@name='board_1']/link/visual/material/pbr/metal/albedo_map").text
    assert (out / board_map).resolve() == (out / "textures" / "board_1.png").resolve()


def test_rerun_shows_the_textured_background(exported, tmp_path):
    from rerun.chunk import RrdReader

    scene, out, files, obs, board = exported
    rrd = record_scene(tmp_path / "scene.rrd", scene=scene)
    paths = {c.entity_path for c in RrdReader(str(rrd)).store().stream()}
    assert "/world/background/surface" in paths
