"""verify_scene: penetration, settling, toppling and render-and-compare on MJCF fixtures.

``write_fixture_mjcf`` is a deliberately small MJCF writer that follows the naming conventions
of DEVELOPERS.md (body NAME, free joint NAME/free, collision pieces in group 3, floor, wall_i,
input_camera); it lets the physics check be tested independently of the exporter.
"""

from __future__ import annotations

import numpy as np
import pytest

from scene_builder.bench.clutter import box_asset, empty_perception
from scene_builder.config import LayoutConfig
from scene_builder.frames import mujoco_camera, pose, quat_wxyz_from_matrix, rot_z, transform_points
from scene_builder.model import Observation, PerceivedObject, Perception, PlacedObject, Plane, Scene


def write_fixture_mjcf(scene: Scene, path, timestep_s: float = 0.002):
    """Write ``scene`` as MJCF (single-part rigid objects), returns the path."""
    import mujoco

    spec = mujoco.MjSpec()
    spec.compiler.degree = False
    spec.option.timestep = timestep_s
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    k = scene.camera.intrinsics
    spec.visual.global_.offwidth = max(640, k.width_px)
    spec.visual.global_.offheight = max(480, k.height_px)
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[20, 20, 0.1], group=0)
    for i, w in enumerate(scene.room.walls):
        n = np.asarray(w.normal)
        x = np.cross([0.0, 0.0, 1.0], n)
        x /= np.linalg.norm(x)
        r = np.stack([x, np.cross(n, x), n], axis=1)
        spec.worldbody.add_geom(
            name=f"wall_{i}", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[20, 20, 0.1], pos=-w.offset_m * n,
            quat=quat_wxyz_from_matrix(r), group=2, rgba=[0.8, 0.8, 0.8, 0.3],
        )
    cam = mujoco_camera(scene.camera.world_from_camera, k)
    c = spec.worldbody.add_camera(name="input_camera", pos=cam["pos"], quat=cam["quat"])
    c.resolution = list(cam["resolution"])
    c.focal_pixel = list(cam["focalpixel"])
    c.principal_pixel = list(cam["principalpixel"])
    c.sensor_size = list(cam["sensorsize"])
    for o in scene.objects:
        part = o.asset.root
        body = spec.worldbody.add_body(name=o.name, pos=o.world_from_asset[:3, 3], quat=quat_wxyz_from_matrix(o.world_from_asset[:3, :3]))
        if not o.asset.is_fixed:
            body.add_freejoint(name=f"{o.name}/free")
        moments, axes = part.inertial.principal()
        body.explicitinertial = True
        body.mass = part.inertial.mass_kg
        body.ipos = part.inertial.com_m
        body.iquat = quat_wxyz_from_matrix(axes)
        body.inertia = moments
        vis = spec.add_mesh(name=f"{o.name}/visual", uservert=part.visual.vertices_m.ravel(), userface=part.visual.faces.ravel())
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=vis.name, group=1, contype=0, conaffinity=0, density=0.0)
        for j, piece in enumerate(part.collision):
            mesh = spec.add_mesh(name=f"{o.name}/collision_{j}", uservert=piece.vertices_m.ravel())
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=mesh.name, group=3, density=0.0, friction=[0.6, 0.005, 0.0001])
    spec.compile()
    path.write_text(spec.to_xml())
    return path


def _scene(objects, walls=()) -> Scene:
    p = empty_perception(tuple(walls))
    return Scene(camera=p.camera, room=p.room, objects=tuple(objects))


def _placed(name, size, xyz, yaw=0.0, rotation=None):
    r = rot_z(yaw) if rotation is None else rotation
    return PlacedObject(box_asset(name, size), pose(r, xyz))


def test_stable_scene_passes(tmp_path):
    scene = _scene(
        [
            _placed("a", (0.4, 0.4, 0.3), (0.0, 0.0, 0.0)),
            _placed("b", (0.3, 0.3, 0.2), (0.0, 0.0, 0.3), yaw=0.3),
            _placed("c", (0.5, 0.3, 0.6), (1.0, 0.5, 0.0), yaw=1.0),
        ],
        walls=[Plane(np.array([1.0, 0.0, 0.0]), 2.0, "wall")],
    )
    verdict, fidelity = __import__("layout").verify_scene(write_fixture_mjcf(scene, tmp_path / "s.xml"), scene, LayoutConfig())
    assert fidelity is None
    assert verdict.max_penetration_m < 1e-3
    assert verdict.stable, verdict.objects
    # At rest from the start: the check stops after its minimum second and half a second at rest.
    from layout.verify import MIN_SETTLE_S, REST_WINDOW_S

    assert MIN_SETTLE_S - 0.01 <= verdict.simulated_s <= MIN_SETTLE_S + REST_WINDOW_S + 0.05
    assert {t.name for t in verdict.trajectories} == {"a", "b", "c"}
    t = verdict.trajectories[0]
    assert abs(t.times_s[-1] - verdict.simulated_s) < 1e-6
    assert 25 <= len(t.times_s) <= 50  # ~30 Hz
    assert all(not o.toppled for o in verdict.objects)


def test_planted_penetration_is_measured(tmp_path):
    from layout import verify_scene

    # b overlaps a by 3 cm along x; c is sunk 2 cm into the floor.
    scene = _scene(
        [
            _placed("a", (0.4, 0.4, 0.3), (0.0, 0.0, 0.0)),
            _placed("b", (0.4, 0.4, 0.3), (0.37, 0.0, 0.0)),
            _placed("c", (0.3, 0.3, 0.3), (2.0, 0.0, -0.02)),
        ]
    )
    verdict, _ = verify_scene(write_fixture_mjcf(scene, tmp_path / "p.xml"), scene, LayoutConfig(settle_s=0.1))
    pens = {o.name: o.start_penetration_m for o in verdict.objects}
    assert verdict.max_penetration_m == pytest.approx(0.03, abs=0.004)
    assert pens["a"] == pytest.approx(0.03, abs=0.004) and pens["b"] == pytest.approx(0.03, abs=0.004)
    assert pens["c"] == pytest.approx(0.02, abs=0.004)
    assert len(verdict.contact_points_m) > 0
    pts = np.array(verdict.contact_points_m)
    assert np.any(np.abs(pts[:, 0] - 0.185) < 0.03)  # contacts in the overlap of a and b (x 0.17..0.2)


def test_toppling_object_is_caught(tmp_path):
    from layout import verify_scene

    # A tall thin box standing on one bottom edge, tilted 15 degrees about y: it falls over.
    tilt = np.array([[np.cos(0.26), 0, np.sin(0.26)], [0, 1, 0], [-np.sin(0.26), 0, np.cos(0.26)]])
    tall = _placed("tall", (0.06, 0.06, 0.7), (0.0, 0.0, 0.0), rotation=tilt)
    # Lift it so its lowest corner touches the floor.
    low = transform_points(tall.world_from_asset, tall.asset.root.collision[0].vertices_m)[:, 2].min()
    tall = PlacedObject(tall.asset, pose(tilt, (0.0, 0.0, -low)))
    scene = _scene([tall, _placed("calm", (0.3, 0.3, 0.3), (1.5, 0.0, 0.0))])
    verdict, _ = verify_scene(write_fixture_mjcf(scene, tmp_path / "t.xml"), scene, LayoutConfig())
    v = {o.name: o for o in verdict.objects}
    assert v["tall"].toppled and v["tall"].rotation_deg > 30.0
    assert not v["calm"].toppled and v["calm"].drift_m < 0.01
    assert not verdict.stable
    assert verdict.settle_max_rotation_deg == pytest.approx(v["tall"].rotation_deg)


def test_settle_runs_until_everything_is_at_rest(tmp_path):
    """A box dropped from 1.2 m is still moving after the minimum second (it lands near 0.5 s and
    rocks): the check runs on until it has been at rest half a second, and it ends where the
    full 3 s of simulation ends, to the millimetre."""
    import mujoco

    from layout import verify_scene
    from layout.verify import MIN_SETTLE_S, REST_MOVE_M, REST_WINDOW_S

    tilt = np.array([[np.cos(0.5), 0, np.sin(0.5)], [0, 1, 0], [-np.sin(0.5), 0, np.cos(0.5)]])
    scene = _scene([_placed("drop", (0.3, 0.2, 0.1), (0.0, 0.0, 1.2), rotation=tilt)])
    path = write_fixture_mjcf(scene, tmp_path / "d.xml")
    verdict, _ = verify_scene(path, scene, LayoutConfig())
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    mujoco.mj_step(m, d, nstep=int(round(3.0 / m.opt.timestep)))
    assert MIN_SETTLE_S < verdict.simulated_s < 3.0
    t = verdict.trajectories[0]
    speed = np.linalg.norm(np.diff(t.positions_m, axis=0), axis=1) / np.diff(t.times_s)
    assert np.max(speed[t.times_s[1:] < 0.5]) > 1.0  # falling
    assert np.all(speed[-10:] < 2 * REST_MOVE_M / REST_WINDOW_S)
    assert verdict.settle_max_drift_m > 1.0
    assert np.linalg.norm(t.positions_m[-1] - d.xpos[m.body("drop").id]) < 1e-3


def test_settled_scene_adopts_final_poses(tmp_path):
    from layout import settled_scene, verify_scene

    # A box dropped from 10 cm lands on the floor: the settled pose has its bottom at z ~ 0.
    scene = _scene([_placed("drop", (0.3, 0.3, 0.2), (0.0, 0.0, 0.1), yaw=0.4)])
    verdict, _ = verify_scene(write_fixture_mjcf(scene, tmp_path / "d.xml"), scene, LayoutConfig(settle_s=1.0))
    assert verdict.settle_max_drift_m == pytest.approx(0.1, abs=0.01)
    settled = settled_scene(scene, verdict)
    t = settled.objects[0].world_from_asset
    assert abs(t[2, 3]) < 0.005
    np.testing.assert_allclose(t[:3, :3], scene.objects[0].world_from_asset[:3, :3], atol=1e-3)
    verdict2, _ = verify_scene(write_fixture_mjcf(settled, tmp_path / "d2.xml"), settled, LayoutConfig(settle_s=1.0))
    assert verdict2.settle_max_drift_m < 0.005


def _raycast_perception(scene: Scene, width: int = 48, height: int = 36) -> Perception:
    """An observation made independently of MuJoCo: trimesh ray casting of the visual meshes
    from the scene camera gives planar depth and instance masks."""
    import trimesh

    base = empty_perception(scene.room.walls, width, height)
    k = base.camera.intrinsics
    cam = base.camera.world_from_camera
    u, v = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    dirs_cam = np.stack([(u - k.cx_px) / k.fx_px, (v - k.cy_px) / k.fy_px, np.ones_like(u)], -1).reshape(-1, 3)
    dirs = dirs_cam @ cam[:3, :3].T
    origins = np.repeat(cam[:3, 3][None], len(dirs), axis=0)
    depth = np.zeros(len(dirs))
    owner = np.full(len(dirs), -1)
    for idx, o in enumerate(scene.objects):
        mesh = o.asset.root.visual
        tm = trimesh.Trimesh(transform_points(o.world_from_asset, mesh.vertices_m), mesh.faces, process=False)
        locs, ray_ids, _ = tm.ray.intersects_location(origins, dirs, multiple_hits=False)
        z = (locs - cam[:3, 3]) @ cam[:3, 2]  # planar depth along the optical axis
        closer = (depth[ray_ids] == 0) | (z < depth[ray_ids])
        depth[ray_ids[closer]] = z[closer]
        owner[ray_ids[closer]] = idx
    objs = []
    for idx, o in enumerate(scene.objects):
        mask = (owner == idx).reshape(height, width)
        pts = np.zeros((1, 3))
        objs.append(PerceivedObject(idx + 1, o.name, "box", 1.0, mask, pts, np.zeros((1, 3), np.uint8)))
    obs = Observation("raycast", np.zeros((height, width, 3), np.uint8), depth.reshape(height, width).astype(np.float32), k, "sensor")
    return Perception(obs, base.camera, base.room, tuple(objs))


def test_render_and_compare_matches_independent_raycast(tmp_path):
    from layout import verify_scene

    scene = _scene([_placed("left", (0.5, 0.6, 0.5), (0.0, 0.6, 0.0)), _placed("right", (0.4, 0.4, 0.8), (0.4, -0.7, 0.0), yaw=0.5)])
    perception = _raycast_perception(scene)
    assert all(o.mask.sum() > 20 for o in perception.objects)
    cfg = LayoutConfig(settle_s=0.05)
    _, fid = verify_scene(write_fixture_mjcf(scene, tmp_path / "r.xml"), scene, cfg, perception)
    assert fid.depth_absrel < 0.02
    assert fid.mask_iou_mean > 0.85
    assert {n for n, _ in fid.mask_iou} == {"left", "right"}
    # The same observation against a scene with "right" moved 40 cm: its IoU and the depth error
    # degrade, "left" is unaffected.
    moved = _scene([scene.objects[0], _placed("right", (0.4, 0.4, 0.8), (0.4, -0.3, 0.0), yaw=0.5)])
    _, fid2 = verify_scene(write_fixture_mjcf(moved, tmp_path / "m.xml"), moved, cfg, perception)
    iou = dict(fid2.mask_iou)
    assert iou["right"] < 0.6 and iou["left"] > 0.85
    assert fid2.depth_absrel > fid.depth_absrel


def test_renders_only_when_asked_and_from_the_start_pose(tmp_path):
    """A check whose scene will be repaired skips its renders; asked for, the t = 0 render is of
    the start pose although it is made after the settle (a box dropped from 30 cm renders where
    it started, and after the settle where it landed)."""
    from layout import verify_scene

    scene = _scene([_placed("drop", (0.4, 0.4, 0.4), (0.2, 0.0, 0.3))])
    perception = _raycast_perception(scene)
    path = write_fixture_mjcf(scene, tmp_path / "f.xml")
    cfg = LayoutConfig(settle_s=0.5)
    seen = []
    verdict, none = verify_scene(path, scene, cfg, perception, fidelity_when=lambda v: seen.append(v) or False)
    assert none is None and seen == [verdict] and verdict.settle_max_drift_m > 0.25
    _, fid = verify_scene(path, scene, cfg, perception, fidelity_when=lambda v: True)
    assert fid.depth_absrel < 0.02 and fid.mask_iou_mean > 0.85  # where it was seen
    assert fid.depth_absrel_settled > 0.02  # after it fell


def test_missing_body_is_an_export_error(tmp_path):
    from layout import verify_scene
    from scene_builder.errors import ExportError

    scene = _scene([_placed("a", (0.3, 0.3, 0.3), (0, 0, 0))])
    path = write_fixture_mjcf(scene, tmp_path / "a.xml")
    other = _scene([_placed("b", (0.3, 0.3, 0.3), (0, 0, 0))])
    with pytest.raises(ExportError, match="no body or flex named 'b'"):
        verify_scene(path, other, LayoutConfig(settle_s=0.01))


def test_verify_reads_the_project_exporter_mjcf(tmp_path):
    """The solved layout written by the project's MJCF exporter passes the physics check: the
    naming conventions agree and the solver's output is penetration-free and at rest."""
    import exporters.mjcf as exporters_mjcf
    from layout import solve_layout, verify_scene
    from scene_builder.bench.clutter import clutter, clutter_layout_config

    perception, generated = clutter(8, seed=11, mix=(0.6, 0.0, 0.2, 0.2))
    result = solve_layout(perception, generated, clutter_layout_config())
    path = exporters_mjcf.write_mjcf(result.scene, tmp_path)
    verdict, _ = verify_scene(path, result.scene, LayoutConfig())
    assert len(verdict.objects) == 8
    assert verdict.max_penetration_m < 1e-3
    assert verdict.stable, verdict.objects


def test_image_scores_are_scikit_images():
    """The render-vs-photo PSNR (written in numpy to keep scipy.stats' import out of a build) and
    SSIM (OpenCV's box filter) are scikit-image's peak_signal_noise_ratio and
    structural_similarity on the same uint8 images, colour and grey; identical images give inf
    and 1."""
    from types import SimpleNamespace

    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    from layout.verify import _Renders
    from layout.verify import ssim as ssim_of

    rng = np.random.default_rng(5)
    photo = rng.integers(0, 256, (40, 50, 3), dtype=np.uint8)
    render = np.clip(photo.astype(int) + rng.integers(-30, 31, photo.shape), 0, 255).astype(np.uint8)
    psnr, ssim = _Renders.image_scores(SimpleNamespace(rgb=render), photo)
    assert psnr == pytest.approx(peak_signal_noise_ratio(photo, render, data_range=255), rel=1e-9)
    assert ssim == pytest.approx(structural_similarity(photo, render, channel_axis=2, data_range=255), abs=1e-12)
    assert _Renders.image_scores(SimpleNamespace(rgb=photo), photo) == (float("inf"), pytest.approx(1.0))
    # a photo with flat regions and a render that differs in one corner only
    flat = np.full((64, 80, 3), 120, dtype=np.uint8)
    flat[20:40, 30:60] = (200, 40, 10)
    dented = flat.copy()
    dented[:10, :12] = 0
    assert ssim_of(flat, dented) == pytest.approx(structural_similarity(flat, dented, channel_axis=2, data_range=255), abs=1e-12)
    assert ssim_of(photo[..., :1], render[..., :1]) == pytest.approx(structural_similarity(photo[..., 0], render[..., 0], data_range=255), abs=1e-12)


def test_settled_renders_tell_hits_by_depth_as_the_segmentation_does(tmp_path):
    """The settled state's renders skip the segmentation: a pixel hit something where its depth
    is nearer than the far clipping plane. On a scene whose camera also sees past everything
    (sky above the walls' tops) that is the segmentation's hit mask, pixel for pixel, and the
    depth error against an observation is the same."""
    import mujoco

    from layout.verify import _Renders, _SceneIndex

    scene = _scene([_placed("left", (0.5, 0.6, 0.5), (0.0, 0.6, 0.0)), _placed("right", (0.4, 0.4, 0.8), (0.4, -0.7, 0.0), yaw=0.5)])
    perception = _raycast_perception(scene)
    path = write_fixture_mjcf(scene, tmp_path / "h.xml")
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    index = _SceneIndex(m, scene, path)
    renderer = _Renders.renderer(m, path, perception.observation.depth_m.shape)
    try:
        full = _Renders(renderer, m, d, index, scene)
        quick = _Renders(renderer, m, d, index, scene, labels=False)
    finally:
        renderer.close()
    assert 0 < np.count_nonzero(~full.hit) < full.hit.size  # some sky, some scene
    np.testing.assert_array_equal(quick.hit, full.hit)
    np.testing.assert_array_equal(quick.rgb, full.rgb)
    valid = perception.observation.depth_m > 0
    assert quick.depth_absrel(perception.observation.depth_m, valid) == full.depth_absrel(perception.observation.depth_m, valid)
