"""``check_output`` passes a good export and names what is wrong in a broken one."""

from __future__ import annotations

import json
import shutil

import pytest

from exporters import check_output, export_scene
from scene_builder.config import ExportConfig
from scene_builder.serialize import scene_to_json
from tests.fixtures_scenes import mixed_scene, pillow_scene


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    scene = mixed_scene()
    out = tmp_path_factory.mktemp("good")
    files = export_scene(scene, out, ExportConfig(viz="off", scene_urdf=True))
    assert all(p is not None and p.is_file() for p in (files.mjcf, files.usd, files.urdf, files.gltf, files.sdf))
    assert files.object_urdfs is not None and len(list(files.object_urdfs.glob("*.urdf"))) == len(scene.objects)
    report = {
        "timings_s": {"export": 0.5},
        "objects": [{"name": o.name} for o in scene.objects],
        "layout": {"max_penetration_m": 0.0, "settle_max_drift_m": 0.0004},
    }
    (out / "report.json").write_text(json.dumps(report))
    # scene.json exactly as the pipeline writes it (scene_builder.serialize).
    (out / "scene.json").write_text(scene_to_json(scene))
    return scene, out


def _copy(src, dst):
    shutil.copytree(src, dst)
    return dst


def test_good_export_passes(good):
    assert check_output(good[1]) == ()


def test_deformable_export_passes(tmp_path):
    export_scene(pillow_scene(), tmp_path, ExportConfig(viz="off"))
    assert check_output(tmp_path) == ()


def test_missing_mesh_is_reported(good, tmp_path):
    out = _copy(good[1], tmp_path / "o")
    (out / "meshes" / "cabinet__door__collision_0.obj").unlink()
    problems = check_output(out)
    assert any("cabinet__door__collision_0.obj" in p and "scene.xml" in p for p in problems)
    assert any("cabinet__door__collision_0.obj" in p and "scene.urdf" in p for p in problems)
    assert any("cabinet__door__collision_0.obj" in p and "urdf/cabinet.urdf" in p for p in problems)
    assert any("cabinet__door__collision_0.obj" in p and "scene.sdf" in p for p in problems)


def test_floating_joint_in_a_per_object_urdf_is_reported(good, tmp_path):
    out = _copy(good[1], tmp_path / "o")
    path = out / "urdf" / "cabinet.urdf"
    path.write_text(path.read_text().replace('type="revolute"', 'type="floating"'))
    assert any("urdf/cabinet.urdf" in p and "floating" in p for p in check_output(out))


def test_broken_sdf_is_reported(good, tmp_path, sdf_checker, monkeypatch):
    from exporters.sdf import CHECKER_ENV

    monkeypatch.setenv(CHECKER_ENV, sdf_checker[0])
    out = _copy(good[1], tmp_path / "o")
    assert check_output(out) == ()  # libsdformat passes the good one
    sdf = out / "scene.sdf"
    sdf.write_text(sdf.read_text().replace("<mass>", "<weight>1</weight><mass>", 1))
    assert any("libsdformat rejects scene.sdf" in p and "weight" in p for p in check_output(out))
    sdf.write_text(sdf.read_text().replace("<child>door</child>", "<child>lid</child>", 1))
    assert any("scene.sdf" in p and "lid" in p for p in check_output(out))


def test_mesh_outside_the_folder_is_reported(good, tmp_path):
    out = _copy(good[1], tmp_path / "o")
    xml = (out / "scene.urdf").read_text().replace('filename="meshes/box_a__body__visual.obj"', f'filename="{good[1]}/meshes/box_a__body__visual.obj"')
    (out / "scene.urdf").write_text(xml)
    assert any("outside the output folder" in p for p in check_output(out))


def test_report_inconsistencies_are_reported(good, tmp_path):
    out = _copy(good[1], tmp_path / "o")
    report = json.loads((out / "report.json").read_text())
    report["objects"] = report["objects"][:-1]
    del report["layout"]["settle_max_drift_m"]
    (out / "report.json").write_text(json.dumps(report))
    problems = check_output(out)
    assert any("settle_max_drift_m" in p for p in problems)
    assert any("differ" in p and "box_on_cabinet" in p for p in problems)


def test_invalid_usd_and_unstable_mjcf_are_reported(good, tmp_path):
    out = _copy(good[1], tmp_path / "o")
    usda = (out / "scene.usda").read_text().replace("</World/Objects/cabinet/door>", "</World/Objects/cabinet/nowhere>")
    (out / "scene.usda").write_text(usda)
    # Drop box_b 5 cm into box_a: the contact solver throws it out violently.
    xml = (out / "scene.xml").read_text().replace('name="box_b" pos="0.4 -0.6 0.3"', 'name="box_b" pos="0.4 -0.6 0.1"')
    (out / "scene.xml").write_text(xml)
    problems = check_output(out)
    assert any("scene.usda" in p and "door_joint" in p for p in problems)
    assert any("scene.xml" in p and "box_b" in p for p in problems)


def test_scene_json_that_names_other_objects_is_reported(good, tmp_path):
    out = _copy(good[1], tmp_path / "o")
    doc = json.loads((out / "scene.json").read_text())
    doc["scene"]["objects"] = doc["scene"]["objects"][1:]
    (out / "scene.json").write_text(json.dumps(doc))
    dropped = good[0].objects[0].name
    assert any("scene.json" in p and "differ" in p and dropped in p for p in check_output(out))
    (out / "scene.json").write_text(json.dumps({"objects": []}))
    assert any("scene.json is not a readable scene" in p for p in check_output(out))


def test_unreadable_usd_and_glb_are_problem_lines_not_tracebacks(good, tmp_path):
    out = _copy(good[1], tmp_path / "o")
    (out / "scene.usda").write_text("#usda 1.0\n( this is not a layer")
    glb = (out / "scene.glb").read_bytes()
    (out / "scene.glb").write_bytes(glb[: len(glb) // 2])
    problems = check_output(out)
    assert any(p.startswith("scene.usda does not open: ") for p in problems), problems
    assert any(p.startswith("scene.glb does not load: ") for p in problems), problems


def test_corrupted_glb_files_are_reported_with_the_loaders_own_error_types(good, tmp_path):
    """300 corruptions of the good scene.glb (byte changes, deletions, insertions, truncation):
    each loads or is one problem line; nothing else escapes exporters.check.GLB_LOAD_ERRORS."""
    import random

    from exporters.check import _check_glb

    glb = (good[1] / "scene.glb").read_bytes()
    rng = random.Random(0)
    path = tmp_path / "scene.glb"
    reported = 0
    for _ in range(300):
        b = bytearray(glb)
        for _ in range(rng.randint(1, 6)):
            op, k = rng.random(), rng.randrange(len(b) or 1)
            if op < 0.5 and b:
                b[k] = rng.randrange(256)
            elif op < 0.7:
                del b[k : k + rng.randint(1, 64)]
            elif op < 0.8:
                del b[k:]
            else:
                b[k:k] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
        path.write_bytes(bytes(b))
        problems: list[str] = []
        _check_glb(path, problems)
        assert all(p.startswith("scene.glb ") for p in problems) and len(problems) <= 1
        reported += len(problems)
    assert reported > 200  # most corruptions are caught, the rest load
