"""Plain photos (no depth map, no learned weights): close-up detection on the real photos, and a
URDFormer cabinet photo built end to end into an articulated asset whose joint limits follow its size."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from perception.single_view import SingleViewDepth, closeup_box_px
from perception.vanishing_points import analysis_image, detect_segments
from tests.conftest import PHOTOS, REAL_DATA, require


def _rgb(d: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(next(d.glob("rgb.*"))).convert("RGB"))


def _cabinet_dirs() -> list[Path]:
    dirs = sorted(require(PHOTOS).glob("urdformer_*"))
    if not dirs:
        pytest.skip(f"no urdformer_* cabinet photos in {PHOTOS}")
    return dirs


def test_closeup_detected_on_cabinet_photos_and_not_on_rooms():
    """At the analysis size the depth estimator uses: all 10 URDFormer cabinet photos are close-ups
    of one object filling most of the frame; none of the room photos (plain and RGB-D) is."""
    cabinets = _cabinet_dirs()
    rooms = sorted(require(PHOTOS).glob("sunrgbd_total3d_demo_*")) + [d for d in sorted(require(REAL_DATA).iterdir()) if d.is_dir()]
    for d in cabinets:
        rgb = analysis_image(_rgb(d))
        box = closeup_box_px(detect_segments(rgb), *rgb.shape[:2])
        assert box is not None, d.name
        u0, v0, u1, v1 = box
        assert (u1 - u0) > 0.6 * rgb.shape[1] and (v1 - v0) > 0.6 * rgb.shape[0], (d.name, box)
    assert len(rooms) >= 15
    for d in rooms:
        rgb = analysis_image(_rgb(d))
        assert closeup_box_px(detect_segments(rgb), *rgb.shape[:2]) is None, d.name


def test_a_head_on_wall_of_horizontal_lines_is_no_closeup():
    """Issue 11: a head-on kitchen photo (1000x667) gave 23 mostly horizontal segments, frame
    aligned and spread over the image, and was taken for a close-up of one object at 0.38 m. The
    same pattern, and a denser one, must not count: a close-up shows the object's full-height
    vertical edges too."""
    h, w = 667, 1000
    rows = np.linspace(60, 620, 20)
    horizontal = np.array([[40.0 + 7 * i, r, 960.0 - 5 * i, r + 0.5] for i, r in enumerate(rows)])
    vertical = np.array([[100.0, 300.0, 100.5, 420.0], [500.0, 300.0, 500.0, 400.0], [900.0, 320.0, 900.5, 420.0]])
    kitchen = np.concatenate([horizontal, vertical])
    assert len(kitchen) == 23 and closeup_box_px(kitchen, h, w) is None
    denser = np.concatenate([kitchen, horizontal + [0.0, 12.0, 0.0, 12.0]])  # 43 segments, still 9 % vertical
    assert closeup_box_px(denser, h, w) is None
    # with full-height verticals (carcass sides, door edges) the same photo would be one
    cabinet = np.concatenate([denser, np.array([[u, 50.0, u, 630.0] for u in np.linspace(40.0, 960.0, 24)])])
    assert closeup_box_px(cabinet, h, w) is not None


def test_closeup_depth_has_the_category_scale():
    d = _cabinet_dirs()[0]
    rgb = _rgb(d)
    est = SingleViewDepth()
    depth = est.estimate(rgb, None).depth_m
    cu = est.last_closeup
    assert cu is not None and cu.note and cu.category in ("cabinet", "drawer_unit", "wardrobe", "refrigerator")
    from scene_builder.vocabulary import category

    _, width_m, height_m = category(cu.category).typical_size_m
    f = 0.5 * rgb.shape[1] / np.tan(np.radians(30.0))  # the default 60 deg field of view
    u0, v0, u1, v1 = cu.box_px
    # The object's metric width and height from its depth and pixel box: the category's, to 20 %
    measured_w = depth[int((v0 + v1) / 2), int((u0 + u1) / 2)] * (u1 - u0) / f
    measured_h = depth[int((v0 + v1) / 2), int((u0 + u1) / 2)] * (v1 - v0) / f
    assert np.sqrt(measured_w * measured_h) == pytest.approx(np.sqrt(width_m * height_m), rel=0.2)
    assert np.all(depth[:, : int(u0) - 1] == 0.0)  # nothing invented around it


@pytest.mark.slow
def test_cabinet_photo_builds_an_articulated_asset(tmp_path):
    from scene_builder.config import BuildConfig, ExportConfig, InputSpec
    from scene_builder.pipeline import build

    d = _cabinet_dirs()[0]
    out = tmp_path / "cabinet_scene"
    cfg = BuildConfig(export=ExportConfig(usd=False, urdf=False, gltf=False, viz="off"))
    build(InputSpec(next(d.glob("rgb.*"))), out, cfg)
    report = json.loads((out / "report.json").read_text())
    depth_use = next(b for b in report["backends"] if b["task"] == "depth")
    assert depth_use["backend"] == "single-view-geometry" and "close-up" in depth_use["reason"]
    # no floor in view: gravity from the photo's vertical vanishing point, not a pitched-camera guess
    assert next(b for b in report["backends"] if b["task"] == "gravity")["backend"] == "vanishing-points"
    articulated = [o for o in report["objects"] if o["kind"] == "articulated"]
    assert len(articulated) == 1, [(o["name"], o["label"]) for o in report["objects"]]
    obj = articulated[0]
    depth_x, width_y, height_z = obj["size_m"]
    assert 0.5 < height_z < 1.5 and 0.5 < width_y < 1.5  # a cabinet's size, not a room's or a toy's

    root = ET.parse(out / "scene.xml").getroot()
    # MJCF's default joint type is hinge
    joints = [j for j in root.iter("joint") if j.get("name", "").startswith(obj["name"] + "/") and j.get("type", "hinge") in ("hinge", "slide")]
    assert joints, "no hinge or slide joint in the MJCF"
    for j in joints:
        lo, hi = (float(x) for x in j.get("range").split())
        assert lo == 0.0 and hi > 0.0
        if j.get("type", "hinge") == "slide":
            # a drawer travels out less than the carcass is deep, and at least a third of it
            assert depth_x / 3.0 < hi < depth_x, (j.get("name"), hi, depth_x)
        else:
            assert np.radians(60.0) < hi <= np.pi, (j.get("name"), hi)
    stable = obj["physics"]
    assert stable["start_penetration_m"] < 1e-3 and not stable["toppled"]


@pytest.mark.slow
def test_room_photo_with_camera_json_builds_offline(tmp_path):
    """Issue 7: a plain room photo (intrinsics from the camera.json beside it) builds a full scene
    with no weights, and report.json names the backends that ran."""
    from exporters.check import check_output
    from scene_builder.config import BuildConfig, ExportConfig, InputSpec
    from scene_builder.pipeline import build

    d = require(PHOTOS / "sunrgbd_total3d_demo_1")
    out = tmp_path / "room_scene"
    build(InputSpec(next(d.glob("rgb.*"))), out, BuildConfig(export=ExportConfig(usd=False, urdf=False, gltf=False, viz="off")))
    report = json.loads((out / "report.json").read_text())
    uses = {b["task"]: b for b in report["backends"]}
    assert uses["intrinsics"]["backend"] == "file"
    assert uses["depth"]["backend"] == "single-view-geometry" and "close-up" not in uses["depth"]["reason"]
    assert {"gravity", "segmentation", "naming", "generation"} <= set(uses)
    assert len(report["objects"]) >= 1
    assert check_output(out) == ()
