"""The rerun recording of a build (rerun-sdk 0.41). The only module of the project importing rerun.

Entity tree (world is Z up, ``RIGHT_HAND_Z_UP``)::

    world                                   ViewCoordinates
    world/camera                            Transform3D world_from_camera + Pinhole (OpenCV RDF)
    world/camera/rgb | depth | masks        Image, DepthImage (metres), SegmentationImage
    world/points/<name>                     observed points of each object (perception)
    world/objects/<name>                    Transform3D world_from_asset, on the ``sim_time``
                                            timeline (the settle simulation when a verdict is given)
    world/background/surface               the static background: the observed room, photo-textured
    world/background/objects/<name>         objects that became background (textured)
    world/background/collision              its collision boxes and pieces (hidden by the blueprint)
    world/objects/<name>/visual/<part>      Mesh3D with the photo texture (else vertex colours), asset frame
    world/objects/<name>/collision/<part>/piece_<k>   convex pieces (hidden by the blueprint: tick the
                                            eye of an object's ``collision`` subtree to show them)
    world/objects/<name>/label              the object's name at its centre
    world/robot/<body>/geom_<k>             the robot (``--robot``) at its start pose (qpos0), world frame
    world/robot_target                      the point its scripted reach aims at, labelled
    world/support                           LineStrips3D child centre -> supporter centre, labelled
    world/contacts                          contact / penetration points of the physics check
    render/input_camera                     the scene rendered by MuJoCo from the input camera (t = 0)
    render/settled                          the same after the settle simulation
    report                                  TextDocument: physics verdict and fidelity

A blueprint puts the photo and the ``input_camera`` render side by side (how faithful the twin
is, at a glance), with the 3D view seen from the input camera, the masks, the depth image and
the report. The recording is deterministic for a given build: fixed recording id, no recording
properties, and nothing on a wall-clock timeline (poses are sent as ``sim_time`` columns).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scene_builder.frames import quat_wxyz_from_matrix, transform_points
from scene_builder.model import Fidelity, LayoutResult, Perception, PhysicsVerdict, PlacedObject, Scene

APP_ID = "scene_builder"


def _xyzw(rotation: np.ndarray) -> np.ndarray:
    q = quat_wxyz_from_matrix(rotation)
    return np.array([q[1], q[2], q[3], q[0]])


def _mesh3d(mesh, rgba=(0.7, 0.7, 0.7, 1.0)):
    """``rr.Mesh3D`` of a TriangleMesh: photo-textured when it has a texture (rerun's texture
    coordinates follow the image, v down, as the model's), else vertex colours (``rgba`` in
    [0, 1] when it has none)."""
    import rerun as rr

    if mesh.texture is not None:
        return rr.Mesh3D(vertex_positions=mesh.vertices_m, triangle_indices=mesh.faces, vertex_texcoords=mesh.uv,
                         albedo_texture=np.ascontiguousarray(mesh.texture.image_rgb))
    colors = mesh.vertex_colors_rgba
    if colors is None:
        colors = np.tile(np.round(np.clip(rgba, 0.0, 1.0) * 255).astype(np.uint8), (len(mesh.vertices_m), 1))
    return rr.Mesh3D(vertex_positions=mesh.vertices_m, triangle_indices=mesh.faces, vertex_colors=np.asarray(colors))


def _centre_world(placed: PlacedObject) -> np.ndarray:
    lo = np.min([p.visual.bounds_m[0] for p in placed.asset.parts], axis=0)
    hi = np.max([p.visual.bounds_m[1] for p in placed.asset.parts], axis=0)
    return transform_points(placed.world_from_asset, ((lo + hi) / 2.0)[None])[0]


def object_entity(name: str) -> str:
    """Entity path of an object (rerun escapes characters that are not path-safe)."""
    import rerun as rr

    return "world/objects/" + rr.escape_entity_path_part(name)


def record_scene(
    out_path: Path,
    *,
    scene: Scene,
    perception: Perception | None = None,
    layout: LayoutResult | None = None,
    verdict: PhysicsVerdict | None = None,
    fidelity: Fidelity | None = None,
    spawn: bool = False,
) -> Path:
    """Write the recording to ``out_path`` (.rrd); ``spawn`` also opens the viewer."""
    import rerun as rr

    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    # A fixed recording id keeps the output deterministic for a given build.
    rec = rr.RecordingStream(APP_ID, recording_id=f"{APP_ID}-{out_path.stem}", send_properties=False)
    blueprint = _blueprint(scene, perception is not None, fidelity is not None and fidelity.render_rgb is not None)
    if spawn:
        # The viewer listens on 127.0.0.1 only; the file gets everything the viewer gets.
        rr.spawn(connect=False, recording=rec)
        rec.set_sinks(rr.FileSink(out_path), rr.GrpcSink("rerun+http://127.0.0.1:9876/proxy"), default_blueprint=blueprint)
    else:
        rec.save(out_path, default_blueprint=blueprint)

    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    _log_camera(rec, scene, perception)
    if perception is not None:
        _log_perception(rec, perception)
    _log_background(rec, scene)
    _log_objects(rec, scene, verdict)
    _log_support(rec, scene, layout)
    _log_robot(rec, scene)
    if fidelity is not None and fidelity.render_rgb is not None:
        rec.log("render/input_camera", rr.Image(fidelity.render_rgb), static=True)
        if fidelity.render_settled_rgb is not None:
            rec.log("render/settled", rr.Image(fidelity.render_settled_rgb), static=True)
    if verdict is not None and verdict.contact_points_m:
        rec.log("world/contacts", rr.Points3D(np.asarray(verdict.contact_points_m), colors=[255, 40, 40], radii=0.01), static=True)
    _log_report(rec, scene, layout, verdict, fidelity)
    rec.flush()
    rec.disconnect()
    return out_path


def viewer_binary() -> str:
    """Path of the rerun viewer executable installed with rerun-sdk (beside the interpreter)."""
    import shutil
    import sys

    beside = Path(sys.executable).parent / "rerun"
    found = str(beside) if beside.exists() else shutil.which("rerun")
    if not found:
        from scene_builder.errors import ExportError

        raise ExportError("the rerun viewer is not installed (pip install rerun-sdk); it ships with the project's dependencies")
    return found


def screenshot(rrd_path: Path, png_path: Path, size_px: tuple[int, int] = (1600, 1000), timeout_s: float = 180.0) -> Path:
    """Render the recording's default view (photo beside the input-camera render, 3D view,
    masks, depth, report) at its first time (the solved scene, before the settle simulation) to
    ``png_path`` with the viewer in headless mode (no display needed; Mesa's Vulkan driver
    renders on the CPU). Raises ExportError with the viewer's last line when no picture comes out.

    The viewer is driven through rerun's ViewerClient, not ``--screenshot-to``: that one shoots
    after a fixed number of frames, before a real scene's recording (10 MB) has loaded (an empty
    picture, twice in a row on an idle machine). Here the recording is loaded, the time set,
    and pictures are taken until two in a row are the same (every texture drawn)."""
    import os
    import signal
    import subprocess
    import tempfile
    import time

    from scene_builder.errors import ExportError

    png_path = Path(png_path)
    png_path.parent.mkdir(parents=True, exist_ok=True)
    cmd = [viewer_binary(), str(rrd_path), "--headless", "--bind", "127.0.0.1", "--port", "0", "--hide-welcome-screen",
           "--window-size", f"{size_px[0]}x{size_px[1]}"]
    deadline = time.monotonic() + timeout_s
    with tempfile.TemporaryFile("w+") as log:
        # Only 127.0.0.1, a free port (never a viewer someone else runs); its own process group so
        # that the real binary is killed whatever happens.
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            port = _wait_for_port(proc, log, deadline)
            png = _settled_picture(port, deadline) if port else None
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        log.seek(0)
        text = log.read().strip()
    if png is None:
        last = text.splitlines()[-1] if text else "no output"
        raise ExportError(f"the rerun viewer gave no screenshot ({last}); it needs Mesa's Vulkan driver (apt install mesa-vulkan-drivers)")
    png_path.write_bytes(png)
    return png_path


def _wait_for_port(proc, log, deadline: float) -> int | None:
    """The port the headless viewer listens on, read from its log (None if it exits first)."""
    import re
    import time

    while time.monotonic() < deadline and proc.poll() is None:
        log.seek(0)
        found = re.search(r"Listening for gRPC connections on [0-9.]+:(\d+)", log.read())
        if found:
            return int(found.group(1))
        time.sleep(0.1)
    return None


#: Pictures taken this far apart until two in a row are the same.
SHOT_INTERVAL_S = 0.5


def _settled_picture(port: int, deadline: float) -> bytes | None:
    """PNG bytes of the viewer's window once the recording is shown at its first time and two
    pictures in a row agree (the last one taken when time runs out; None without any)."""
    import time

    from rerun.experimental import ViewerClient

    client = None
    while client is None and time.monotonic() < deadline:
        try:
            client = ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy")
            client.get_state()
        except OSError:  # not answering yet (rerun raises ConnectionError "transport error"): retried until the deadline
            client = None
            time.sleep(0.2)
    if client is None:
        return None
    while time.monotonic() < deadline and not client.get_state().recordings:
        time.sleep(0.2)
    state = client.get_state()
    if state.recordings:
        timeline = state.recordings[0].current_timeline
        start = next((t.start for t in state.recordings[0].timelines if t.name == timeline), None)
        if timeline and start is not None:
            client.set_time(timeline, duration=start / 1e9, play_state="paused")
    previous, png = None, None
    while time.monotonic() < deadline:
        png = client.take_screenshot()
        if previous is not None and _same_picture(previous, png):
            break
        previous = png
        time.sleep(SHOT_INTERVAL_S)
    return png


def _same_picture(a: bytes, b: bytes) -> bool:
    import io

    from PIL import Image

    pa, pb = (np.asarray(Image.open(io.BytesIO(x)).convert("RGB")) for x in (a, b))
    return pa.shape == pb.shape and bool(np.array_equal(pa, pb))


def _blueprint(scene: Scene, with_images: bool, with_render: bool = False):
    """The photo beside the ``input_camera`` render (when there is one), the 3D view seen from
    the input camera, the masks, the depth and the report.

    Collision pieces are hidden by a blueprint override on each object's ``collision`` subtree
    (an ``EntityBehavior`` logged into the recording itself is ignored by the 0.41 viewer):
    tick the eye of ``collision`` in the blueprint panel to show them.
    """
    import rerun.blueprint as rrb

    hidden = {f"{object_entity(o.name)}/collision": rrb.EntityBehavior(visible=False) for o in scene.objects}
    hidden["world/background/collision"] = rrb.EntityBehavior(visible=False)
    # The photo, depth and masks would be drawn on the camera's image plane, right in front of
    # the eye: keep them in the 2D views only.
    view3d = rrb.Spatial3DView(
        name="scene",
        origin="world",
        contents=["+ world/**", "- world/camera/rgb", "- world/camera/depth", "- world/camera/masks"],
        overrides=hidden,
        eye_controls=_input_camera_eye(scene),
    )
    panels = (rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"), rrb.TimePanel(state="collapsed"))
    if not with_images:
        root = rrb.Horizontal(view3d, rrb.TextDocumentView(origin="report", name="report"), column_shares=[3, 1])
        return rrb.Blueprint(_with_fixed_ids(root), *panels)
    side = rrb.Vertical(
        rrb.Spatial2DView(name="photo + masks", origin="world/camera", contents=["world/camera/rgb", "world/camera/masks"]),
        rrb.Spatial2DView(name="depth", origin="world/camera", contents=["world/camera/depth"]),
        rrb.TextDocumentView(origin="report", name="report"),
        row_shares=[2, 2, 1],
    )
    root = rrb.Horizontal(view3d, side, column_shares=[3, 2])
    if with_render:
        compare = rrb.Horizontal(
            rrb.Spatial2DView(name="photo", origin="world/camera", contents=["world/camera/rgb"]),
            rrb.Spatial2DView(name="twin (input camera)", origin="render", contents=["render/input_camera"]),
        )
        root = rrb.Vertical(compare, root, row_shares=[1, 1])
    return rrb.Blueprint(_with_fixed_ids(root), *panels)


#: Namespace of the blueprint's view and container ids (uuid5 of their place in the layout).
#: uuid5(NAMESPACE_URL, "scene-builder/rerun-blueprint").
_BLUEPRINT_NAMESPACE = "51c5483e-5d36-5689-a20e-7ccd1d8df9ae"


def _with_fixed_ids(node, where: str = "root"):
    """Give every container and view of the layout a uuid5 of its place in the tree instead of
    rerun's random uuid4, so that the same scene always gets the same blueprint."""
    import uuid

    import rerun.blueprint as rrb

    node.id = uuid.uuid5(uuid.UUID(_BLUEPRINT_NAMESPACE), where)
    if isinstance(node, rrb.Container):
        for i, child in enumerate(node.contents):
            _with_fixed_ids(child, f"{where}/{i}")
    return node


EYE_BACK_M = 0.5  # the eye sits this far behind the input camera, so its (small) frustum is in view


def _input_camera_eye(scene: Scene):
    """Eye controls at the input camera (slightly behind it), looking along its optical axis at
    the depth of the scene's centre, world Z up."""
    import rerun.blueprint as rrb

    t = scene.camera.world_from_camera
    centre, forward = t[:3, 3], t[:3, 2]  # OpenCV camera: +Z is the optical axis
    if scene.objects:
        centres = np.array([_centre_world(o) for o in scene.objects])
        distance = float(np.clip(np.median((centres - centre) @ forward), 1.0, 8.0))
    else:
        distance = 2.5
    return rrb.EyeControls3D(
        kind=rrb.Eye3DKind.Orbital,
        position=centre - EYE_BACK_M * forward,
        look_target=centre + distance * forward,
        eye_up=[0.0, 0.0, 1.0],
    )


def _log_camera(rec, scene: Scene, perception: Perception | None) -> None:
    import rerun as rr

    t = scene.camera.world_from_camera
    k = scene.camera.intrinsics
    rec.log("world/camera", rr.Transform3D(translation=t[:3, 3], quaternion=_xyzw(t[:3, :3])), static=True)
    rec.log(
        "world/camera",
        rr.Pinhole(image_from_camera=k.matrix, resolution=[k.width_px, k.height_px], camera_xyz=rr.ViewCoordinates.RDF,
                   image_plane_distance=0.1),
        static=True,
    )


def _log_perception(rec, perception: Perception) -> None:
    import rerun as rr

    obs = perception.observation
    rec.log("world/camera/rgb", rr.Image(obs.rgb), static=True)
    rec.log("world/camera/depth", rr.DepthImage(obs.depth_m, meter=1.0), static=True)
    seg = np.zeros(obs.rgb.shape[:2], dtype=np.uint16)
    infos = [rr.AnnotationInfo(id=0, label="background", color=(0, 0, 0, 0))]
    palette = _palette(len(perception.objects))
    for i, o in enumerate(perception.objects):
        seg[o.mask] = o.object_id
        infos.append(rr.AnnotationInfo(id=o.object_id, label=f"{o.name} ({o.label})", color=palette[i]))
    rec.log("world/camera/masks", rr.AnnotationContext(infos), static=True)
    rec.log("world/camera/masks", rr.SegmentationImage(seg), static=True)
    for o in perception.objects:
        rec.log(
            "world/points/" + rr.escape_entity_path_part(o.name),
            rr.Points3D(o.points_world_m, colors=o.colors_rgb, radii=0.004),
            static=True,
        )


def _palette(n: int) -> list[tuple[int, int, int, int]]:
    """Well-separated colours (golden-ratio hue steps), deterministic."""
    import colorsys

    out = []
    for i in range(n):
        r, g, b = colorsys.hsv_to_rgb((i * 0.618033988749895) % 1.0, 0.75, 0.95)
        out.append((int(r * 255), int(g * 255), int(b * 255), 140))
    return out


def _log_objects(rec, scene: Scene, verdict: PhysicsVerdict | None) -> None:
    import rerun as rr

    for placed in scene.objects:
        ent = object_entity(placed.name)
        for part in placed.asset.parts:
            pe = rr.escape_entity_path_part(part.name)
            rec.log(f"{ent}/visual/{pe}", _mesh3d(part.visual, part.material.rgba), static=True)
            for k, piece in enumerate(part.collision):
                rec.log(
                    f"{ent}/collision/{pe}/piece_{k}",
                    rr.Mesh3D(vertex_positions=piece.vertices_m, triangle_indices=piece.faces, albedo_factor=[230, 80, 80, 110]),
                    static=True,
                )
        lo = np.min([p.visual.bounds_m[0] for p in placed.asset.parts], axis=0)
        hi = np.max([p.visual.bounds_m[1] for p in placed.asset.parts], axis=0)
        rec.log(f"{ent}/label", rr.Points3D([(lo + hi) / 2.0], labels=[placed.name], radii=0.005), static=True)

    # Poses live on the sim_time timeline: the solved pose at t = 0, then the settle simulation.
    # They are sent as columns, never with rec.log: that would stamp a wall-clock log_time.
    trajectories = {tr.name: tr for tr in (verdict.trajectories if verdict is not None else ())}
    for placed in scene.objects:
        t = placed.world_from_asset
        times = [0.0]
        positions = [t[:3, 3]]
        quats_xyzw = [_xyzw(t[:3, :3])]
        tr = trajectories.get(placed.name)
        if tr is not None:
            # Trajectories give the free body's origin; the root body frame is the asset frame.
            times += list(np.asarray(tr.times_s, dtype=np.float64))
            positions += list(np.asarray(tr.positions_m))
            quats_xyzw += list(np.asarray(tr.quats_wxyz)[:, [1, 2, 3, 0]])
        rec.send_columns(
            object_entity(placed.name),
            indexes=[rr.TimeColumn("sim_time", duration=np.asarray(times))],
            columns=rr.Transform3D.columns(translation=np.asarray(positions), quaternion=np.asarray(quats_xyzw)),
        )


def _log_background(rec, scene: Scene) -> None:
    import rerun as rr

    bg = scene.room.background
    if bg is None:
        return
    if len(bg.surface.faces):
        rec.log("world/background/surface", _mesh3d(bg.surface), static=True)
    for label, mesh in zip(bg.static_names, bg.static_meshes):
        rec.log("world/background/objects/" + rr.escape_entity_path_part(label), _mesh3d(mesh), static=True)
    if bg.box_count:
        quats = np.stack([np.zeros(bg.box_count), np.zeros(bg.box_count), np.sin(bg.box_yaws_rad / 2), np.cos(bg.box_yaws_rad / 2)], axis=1)
        rec.log("world/background/collision/boxes", rr.Boxes3D(centers=bg.box_centers_m, half_sizes=bg.box_half_extents_m,
                                                                 quaternions=quats, colors=[80, 130, 230, 90]), static=True)
    for k, piece in enumerate(bg.static_pieces):
        rec.log(f"world/background/collision/piece_{k}", rr.Mesh3D(vertex_positions=piece.vertices_m, triangle_indices=piece.faces,
                                                                   albedo_factor=[80, 130, 230, 110]), static=True)


def _log_robot(rec, scene: Scene) -> None:
    """The robot's look (visual geoms, else collision geoms) at its start pose, and its target."""
    import rerun as rr
    import trimesh

    from exporters.robot import robot_meshes

    r = scene.robot
    if r is None:
        return
    for geom in robot_meshes(r, "rerun"):
        ent = "world/robot/" + "/".join(rr.escape_entity_path_part(p) for p in geom.name.split("/"))
        v, f = geom.mesh.vertices_m, geom.mesh.faces
        # With its normals the viewer shades it; without (as _mesh3d logs the photo-textured
        # objects) a one-colour robot is drawn as a flat silhouette.
        normals = trimesh.Trimesh(v, f, process=False).vertex_normals
        rec.log(ent, rr.Mesh3D(vertex_positions=v, triangle_indices=f, vertex_normals=normals,
                               albedo_factor=np.round(np.clip(geom.rgba, 0.0, 1.0) * 255).astype(np.uint8)), static=True)
    rec.log("world/robot_target", rr.Points3D([r.target_m], labels=[f"{r.model.name} reach target: {r.target_kind} of {r.target_support}"],
                                              colors=[255, 190, 0], radii=0.015), static=True)


def _log_support(rec, scene: Scene, layout: LayoutResult | None) -> None:
    import rerun as rr

    edges = [(e.child, e.parent) for e in layout.support] if layout is not None else [(o.name, o.support) for o in scene.objects]
    names = {o.name for o in scene.objects}
    strips, labels = [], []
    for child, parent in sorted(edges):
        if child not in names:
            continue
        c = _centre_world(scene.object(child))
        if parent in names:
            p = _centre_world(scene.object(parent))
        elif parent in ("floor", "background"):
            o = scene.object(child)
            bottom = float(np.min([transform_points(o.world_from_asset, p.visual.vertices_m)[:, 2].min() for p in o.asset.parts]))
            p = np.array([c[0], c[1], bottom if parent == "background" else 0.0])
        else:
            continue
        strips.append([c, p])
        labels.append(f"{child} on {parent}")
    if strips:
        rec.log("world/support", rr.LineStrips3D(np.asarray(strips), labels=labels, show_labels=False, colors=[60, 200, 90], radii=0.006), static=True)


def _log_report(rec, scene: Scene, layout: LayoutResult | None, verdict: PhysicsVerdict | None, fidelity: Fidelity | None) -> None:
    import rerun as rr

    lines = [f"# {len(scene.objects)} objects", ""]
    for o in scene.objects:
        lines.append(f"- **{o.name}** ({o.asset.label}, {o.asset.kind.value}{', fixed' if o.asset.is_fixed else ''}): "
                     f"{o.asset.mass_kg:.2f} kg, {len(o.asset.parts)} part(s), on {o.support}")
    if layout is not None:
        lines += ["", f"layout: {layout.iterations} iterations, penetration {layout.max_penetration_before_m * 1000:.1f} mm -> {layout.max_penetration_after_m * 1000:.1f} mm"]
    if verdict is not None:
        lines += ["", f"physics ({verdict.simulated_s:g} s): {'stable' if verdict.stable else 'NOT stable'}, "
                  f"max penetration {verdict.max_penetration_m * 1000:.1f} mm, max drift {verdict.settle_max_drift_m * 1000:.1f} mm, "
                  f"max rotation {verdict.settle_max_rotation_deg:.2f} deg"]
    if fidelity is not None:
        lines += ["", f"fidelity (input camera vs photo): PSNR {fidelity.psnr_db:.1f} dB, SSIM {fidelity.ssim:.3f}, "
                  f"depth AbsRel {fidelity.depth_absrel:.3f} (after settling {fidelity.depth_absrel_settled:.3f}), "
                  f"silhouette IoU {fidelity.mask_iou_mean:.3f}"]
    if scene.robot is not None:
        r = scene.robot
        lines += ["", f"robot: {r.model.name} ({r.model.source}) at ({r.position_m[0]:.2f}, {r.position_m[1]:.2f}) m, "
                  f"reaching for the {r.target_kind} of {r.target_support}"]
    bg = scene.room.background
    if bg is not None and bg.static_names:
        lines += ["", "became background (could not stand where seen): " + ", ".join(sorted({n.split('/')[0] for n in bg.static_names}))]
    rec.log("report", rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN), static=True)
