"""rerun recording: read the .rrd back and find every expected entity; a headless screenshot
proves it renders."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from exporters import record_scene
from scene_builder.model import (
    LayoutResult,
    Observation,
    PerceivedObject,
    Perception,
    PhysicsVerdict,
    SupportEdge,
    Trajectory,
)
from tests.fixtures_scenes import mixed_scene


def _perception(scene) -> Perception:
    k = scene.camera.intrinsics
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 255, (k.height_px, k.width_px, 3), dtype=np.uint8)
    depth = np.full((k.height_px, k.width_px), 2.5, np.float32)
    objs = []
    for i, name in enumerate(["box_a", "cabinet"]):
        mask = np.zeros((k.height_px, k.width_px), bool)
        mask[100 + 150 * i: 200 + 150 * i, 100:300] = True
        pts = rng.normal(scene.object(name).world_from_asset[:3, 3], 0.05, (50, 3))
        objs.append(PerceivedObject(i + 1, name, scene.object(name).asset.label, 0.9, mask, pts, np.full((50, 3), 200, np.uint8)))
    return Perception(Observation("photo.png", rgb, depth, k, "sensor"), scene.camera, scene.room, tuple(objs))


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    scene = mixed_scene()
    times = np.linspace(0.0, 1.0, 26)
    start = scene.object("box_b").world_from_asset[:3, 3]
    traj = Trajectory("box_b", times, start + np.outer(times, [0.0, 0.0, -0.001]), np.tile([1.0, 0.0, 0.0, 0.0], (26, 1)))
    verdict = PhysicsVerdict(0.0005, 0.001, 0.1, 1.0, True, trajectories=(traj,), contact_points_m=((0.4, -0.6, 0.3),))
    layout = LayoutResult(scene, tuple(SupportEdge(o.name, o.support) for o in scene.objects))
    path = record_scene(tmp_path_factory.mktemp("rrd") / "scene.rrd", scene=scene, perception=_perception(scene),
                        layout=layout, verdict=verdict)
    return scene, path


def _chunks(path: Path):
    from rerun.chunk import RrdReader

    return list(RrdReader(str(path)).store().stream())


def test_recording_has_every_entity(recording):
    scene, path = recording
    chunks = _chunks(path)
    paths = {c.entity_path for c in chunks}
    expected = {"/world", "/world/camera", "/world/camera/rgb", "/world/camera/depth", "/world/camera/masks",
                "/world/points/box_a", "/world/points/cabinet", "/world/support", "/world/contacts", "/report"}
    for o in scene.objects:
        expected.add(f"/world/objects/{o.name}")
        expected.add(f"/world/objects/{o.name}/label")
        for part in o.asset.parts:
            expected.add(f"/world/objects/{o.name}/visual/{part.name}")
            expected |= {f"/world/objects/{o.name}/collision/{part.name}/piece_{k}" for k in range(len(part.collision))}
    assert expected <= paths, sorted(expected - paths)


def test_settle_simulation_is_a_sim_time_series(recording):
    _, path = recording
    rows = sum(c.num_rows for c in _chunks(path) if c.entity_path == "/world/objects/box_b" and "sim_time" in c.timeline_names)
    assert rows == 1 + 26  # solved pose at t = 0, then the trajectory


def test_recording_without_perception(tmp_path):
    scene = mixed_scene()
    path = record_scene(tmp_path / "s.rrd", scene=scene)
    paths = {c.entity_path for c in _chunks(path)}
    assert "/world/objects/cabinet/visual/door" in paths and "/world/camera/rgb" not in paths


@pytest.mark.slow
def test_headless_screenshot_renders(recording, tmp_path):
    """exporters.rerun_viz.screenshot: the default view, drawn headless at the asked size."""
    from PIL import Image

    from exporters.rerun_viz import screenshot

    img = np.asarray(Image.open(screenshot(recording[1], tmp_path / "shot.png", size_px=(1280, 800))).convert("RGB")).astype(np.float64)
    assert img.shape[0] >= 800 and img.shape[1] * 800 == img.shape[0] * 1280
    # Not blank: many distinct colours, and the 3D view area (left half, below the top bar) varies.
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 500
    h, w = img.shape[:2]
    assert img[h // 10: h * 7 // 10, w // 6: w // 2].std() > 10.0


def test_collision_pieces_hidden_by_the_blueprint_and_eye_at_the_camera(recording):
    from rerun.chunk import RrdReader

    scene, path = recording
    reader = RrdReader(str(path))
    bp = list(reader.store(store=reader.blueprints()[0]).stream())
    hidden = {c.entity_path.split("/overrides/")[1].rsplit("/visualizers", 1)[0] for c in bp if "/overrides/" in c.entity_path}
    assert hidden == {f"world/objects/{o.name}/collision" for o in scene.objects} | {"world/background/collision"}
    eye = next(c for c in bp if c.entity_path.endswith("/EyeControls3D")).to_record_batch()
    position = np.asarray(eye.column("EyeControls3D:position").to_pylist()[0][0])
    target = np.asarray(eye.column("EyeControls3D:look_target").to_pylist()[0][0])
    cam = scene.camera.world_from_camera
    np.testing.assert_allclose(position, cam[:3, 3] - 0.5 * cam[:3, 2], atol=1e-5)
    assert np.dot((target - position) / np.linalg.norm(target - position), cam[:3, 2]) > 0.9999


def test_recording_content_is_deterministic(recording, tmp_path):
    """Same inputs, same recording (rerun's time-based row ids aside); no wall-clock timeline."""
    import json

    import pyarrow as pa

    scene, path = recording
    times = np.linspace(0.0, 1.0, 26)
    start = scene.object("box_b").world_from_asset[:3, 3]
    traj = Trajectory("box_b", times, start + np.outer(times, [0.0, 0.0, -0.001]), np.tile([1.0, 0.0, 0.0, 0.0], (26, 1)))
    verdict = PhysicsVerdict(0.0005, 0.001, 0.1, 1.0, True, trajectories=(traj,), contact_points_m=((0.4, -0.6, 0.3),))
    layout = LayoutResult(scene, tuple(SupportEdge(o.name, o.support) for o in scene.objects))
    again = record_scene(tmp_path / "scene.rrd", scene=scene, perception=_perception(scene), layout=layout, verdict=verdict)

    def canonical(p):
        out = []
        for c in _chunks(p):
            assert set(c.timeline_names) <= {"sim_time"}, (c.entity_path, c.timeline_names)
            rb = c.to_record_batch()
            cols = {n: (rb.column(n).cast(pa.int64()) if pa.types.is_temporal(rb.column(n).type) else rb.column(n)).to_pylist()
                    for n in rb.schema.names if "RowId" not in n}
            out.append((c.entity_path, json.dumps(cols, default=str)))
        return sorted(out)

    assert canonical(again) == canonical(path)


def test_blueprint_ids_are_deterministic(recording, tmp_path):
    """Views and containers get ids from their place in the layout, not rerun's random uuid4: two
    recordings of one scene have the same blueprint entity paths and contents."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    scene, path = recording
    again = record_scene(tmp_path / "scene.rrd", scene=scene, perception=_perception(scene))

    def blueprint(p):
        reader = RrdReader(str(p))
        chunks = list(reader.store(store=reader.blueprints()[0]).stream())
        out = {}
        for c in chunks:
            rb = c.to_record_batch()
            out.setdefault(c.entity_path, []).append(
                sorted(
                    (n, str(rb.column(n).to_pylist()))
                    for n in rb.schema.names
                    if "RowId" not in n and not pa.types.is_temporal(rb.column(n).type)
                )
            )
        return out

    a, b = blueprint(path), blueprint(again)
    views = sorted(p for p in a if p.startswith("/view/") and p.count("/") == 2)
    assert len(views) == 4  # 3D scene, photo + masks, depth, report
    assert sorted(a) == sorted(b)
    assert {k: sorted(v) for k, v in a.items()} == {k: sorted(v) for k, v in b.items()}


def test_photo_and_twin_render_side_by_side(tmp_path):
    """With a render-and-compare result, the recording holds the input-camera render and the
    default blueprint gains the photo and the render as two views (six views in all)."""
    from rerun.chunk import RrdReader

    from scene_builder.model import Fidelity

    scene = mixed_scene()
    k = scene.camera.intrinsics
    render = np.full((k.height_px, k.width_px, 3), 90, np.uint8)
    fidelity = Fidelity(0.1, 0.5, (), psnr_db=20.0, ssim=0.8, render_rgb=render, render_settled_rgb=render)
    path = record_scene(tmp_path / "s.rrd", scene=scene, perception=_perception(scene), fidelity=fidelity)
    paths = {c.entity_path for c in _chunks(path)}
    assert {"/render/input_camera", "/render/settled"} <= paths
    reader = RrdReader(str(path))
    views = {c.entity_path for c in reader.store(store=reader.blueprints()[0]).stream() if c.entity_path.count("/") == 2 and c.entity_path.startswith("/view/")}
    plain = record_scene(tmp_path / "p.rrd", scene=scene, perception=_perception(scene))
    reader = RrdReader(str(plain))
    plain_views = {c.entity_path for c in reader.store(store=reader.blueprints()[0]).stream() if c.entity_path.count("/") == 2 and c.entity_path.startswith("/view/")}
    assert len(views) == 6 and len(plain_views) == 4


@pytest.mark.slow
def test_view_screenshot_from_the_cli(recording, tmp_path):
    """`scene-builder view OUT --screenshot PNG` writes the default view without a display."""
    import sys

    from PIL import Image

    shot = tmp_path / "view.png"
    proc = subprocess.run([sys.executable, "-m", "scene_builder.cli", "view", str(recording[1]), "--screenshot", str(shot)],
                          capture_output=True, text=True, timeout=300)
    if proc.returncode != 0 and ("vulkan" in proc.stderr.lower() or "adapter" in proc.stderr.lower()):
        pytest.skip(f"no Vulkan adapter for the headless viewer: {proc.stderr.strip().splitlines()[-1]}")
    assert proc.returncode == 0, proc.stderr
    img = np.asarray(Image.open(shot).convert("RGB"))
    # The viewer may render at a pixel ratio above 1 (2x here): same aspect, at least that size.
    assert img.shape[0] >= 1000 and img.shape[1] * 1000 == img.shape[0] * 1600 and img.std() > 10.0
