"""Names from model text, labels or a hand-edited scene.json are sanitised before they become file
or prim names: no path traversal, no collisions (issue 12). Fuzzed with hypothesis, and one export
of a scene whose object and part names are hostile."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from exporters.names import UniqueNames, file_stem, valid_identifier

NAMES = st.text(min_size=0, max_size=80) | st.sampled_from(["..", ".", "/", "a/b", "a b", "a_b", "a__b", "_a", "a_", "CON", "x" * 300, "名前", "a\x00b"])
SAFE_FILE = re.compile(r"[A-Za-z0-9_.~-]+")


@settings(max_examples=600, deadline=None)
@given(st.tuples(NAMES, NAMES, st.sampled_from(["visual", "collision_0", "collision_12"])))
def test_file_stem_is_a_safe_file_name(pieces):
    stem = file_stem(*pieces)
    name = stem + ".obj"
    assert SAFE_FILE.fullmatch(stem), stem
    assert not stem.startswith(".") and "/" not in stem and "\\" not in stem
    assert len(name.encode()) <= 255
    assert Path(name).name == name and Path(name).parent == Path(".")


@settings(max_examples=600, deadline=None)
@given(st.tuples(NAMES, NAMES), st.tuples(NAMES, NAMES))
def test_file_stem_never_collides(a, b):
    if a != b:
        assert file_stem(*a, "visual") != file_stem(*b, "visual")


def test_file_stem_keeps_plain_names_and_separates_lookalikes():
    assert file_stem("chair_1", "door", "visual") == "chair_1__door__visual"
    stems = {file_stem(n, "body", "visual") for n in ("a b", "a_b", "a/b", "a__b", "a\\b", "../a_b")}
    assert len(stems) == 6
    assert file_stem("a b", "body", "visual").startswith("a_b__body__visual~")


@settings(max_examples=400, deadline=None)
@given(st.lists(NAMES, max_size=12))
def test_unique_names_are_valid_and_unique(names):
    unique = UniqueNames(reserved=("Joints",))
    out = [unique(n) for n in names]
    assert len(set(out)) == len(out) and "Joints" not in out
    for o in out:
        assert re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", o), o
    assert valid_identifier("") == "_"


def test_hostile_names_export_to_files_inside_the_output(tmp_path: Path):
    """Objects and parts named like paths, lookalikes, reserved prim names, very long and
    non-ASCII names: every file lands inside the output folder, none overwrites another, MuJoCo
    compiles the MJCF and the USD has one prim per part and per joint."""
    import mujoco
    from pxr import Usd, UsdPhysics

    from exporters import ExportConfig, export_scene
    from scene_builder.model import PlacedObject, Scene

    from .fixtures_scenes import boxes_scene, cabinet_asset, pose

    base = boxes_scene()
    hostile = ["../../escape", "a b", "a_b", "x" * 300, "名前/..", ".hidden"]
    objects = [dataclasses.replace(o, asset=dataclasses.replace(o.asset, name=n), support="floor")
               for o, n in zip(base.objects, hostile)]
    cab = cabinet_asset(name="cab/../inet")
    renamed = {"body": "Joints", "door": "door 1", "drawer": "door_1"}
    parts = tuple(dataclasses.replace(p, name=renamed[p.name], parent=None if p.parent is None else renamed[p.parent]) for p in cab.parts)
    objects.append(PlacedObject(dataclasses.replace(cab, parts=parts), pose(np.eye(3), (1.2, -0.9, 0.0)), "floor"))
    scene = Scene(base.camera, base.room, tuple(objects))

    out = tmp_path / "out"
    files = export_scene(scene, out, ExportConfig(mjcf=True, usd=True, urdf=True, scene_urdf=True, sdf=True, gltf=True, viz="off"))
    written = sorted(p for p in tmp_path.rglob("*") if p.is_file())
    assert all(out in p.parents for p in written), [str(p) for p in written if out not in p.parents]
    n_meshes = sum(1 + len(p.collision) for o in scene.objects for p in o.asset.parts)
    assert len(list((out / "meshes").iterdir())) == n_meshes  # one file per mesh: no overwrites

    model = mujoco.MjModel.from_xml_path(str(files.mjcf))
    assert model.nbody == 1 + sum(len(o.asset.parts) for o in scene.objects)
    stage = Usd.Stage.Open(str(files.usd))
    cab_prims = [p for p in stage.Traverse() if p.GetDisplayName() in renamed.values()]
    assert sorted(p.GetDisplayName() for p in cab_prims) == sorted(renamed.values())
    joints = [p for p in stage.Traverse() if p.IsA(UsdPhysics.Joint) and "/Joints/" in str(p.GetPath())]
    assert len(joints) == 2 + 0  # door 1 and door_1 (the cabinet is not fixed: no world weld)
    # One URDF per object (no overwrites) and an SDF with distinct model, link and joint names.
    assert len(list(files.object_urdfs.glob("*.urdf"))) == len(scene.objects)
    import xml.etree.ElementTree as ET

    world = ET.parse(files.sdf).getroot().find("world")
    models = [m.get("name") for m in world.findall("model")]
    assert len(set(models)) == len(models) == len(scene.objects) + 2  # + room and input_camera
    for m in world.findall("model"):
        siblings = [e.get("name") for e in m if e.tag in ("link", "joint")]
        assert len(set(siblings)) == len(siblings) and not any("::" in n or n.startswith("__") for n in siblings)
