"""The physics verdict and render-and-compare, measured in MuJoCo on the exported MJCF.

Naming conventions (DEVELOPERS.md): the root part of object NAME is body ``NAME`` (free joint
``NAME/free`` unless fixed), other parts ``NAME/PART``, collision geoms in group 3, ``floor``,
``wall_i``, camera ``input_camera``, deformables are flex objects named ``NAME``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scene_builder.config import LayoutConfig
from scene_builder.errors import ExportError, InputError
from scene_builder.frames import matrix_from_quat_wxyz, pose
from scene_builder.model import AssetKind, Fidelity, ObjectVerdict, Perception, PhysicsVerdict, PlacedObject, Scene, Trajectory

TOPPLE_DEG = 30.0
RECORD_HZ = 30.0
# A soft body's centroid sinks as it settles under its own weight (that is the point of a soft
# body); it counts as unstable only when its centroid moves more than this share of its height
# (or stable_drift_m, whichever is larger): sliding or falling off its support.
DEFORMABLE_SAG_FRACTION = 0.25
MAX_CONTACT_POINTS = 256


def _rotation_deg(q0: np.ndarray, q1: np.ndarray) -> float:
    """Angle (deg) of the rotation between two unit quaternions (w, x, y, z)."""
    c = abs(float(np.dot(q0, q1))) / (np.linalg.norm(q0) * np.linalg.norm(q1))
    return float(np.degrees(2.0 * np.arccos(min(1.0, c))))


def _tilt_deg(q0: np.ndarray, q1: np.ndarray) -> float:
    """Angle (deg) between the body's z axis at the start and at the end."""
    z0 = matrix_from_quat_wxyz(q0)[:, 2]
    z1 = matrix_from_quat_wxyz(q1)[:, 2]
    return float(np.degrees(np.arccos(np.clip(np.dot(z0, z1), -1.0, 1.0))))


class _SceneIndex:
    """Which MuJoCo body / flex belongs to which scene object."""

    def __init__(self, m, scene: Scene, mjcf_path: Path) -> None:
        import mujoco

        self.root_body: dict[str, int] = {}
        self.flex: dict[str, int] = {}
        self.free_qpos: dict[str, int] = {}
        for o in scene.objects:
            bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, o.name)
            fid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_FLEX, o.name)
            if bid >= 0:
                self.root_body[o.name] = bid
                jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{o.name}/free")
                if jid >= 0 and m.jnt_type[jid] == mujoco.mjtJoint.mjJNT_FREE:
                    self.free_qpos[o.name] = int(m.jnt_qposadr[jid])
            elif fid >= 0:
                self.flex[o.name] = fid
            else:
                raise ExportError(
                    f"{mjcf_path.name}: no body or flex named {o.name!r}; the MJCF must follow the naming conventions of DEVELOPERS.md"
                )
        # body id -> object name (every body of an object hangs below its root body).
        root_to_name = {bid: n for n, bid in self.root_body.items()}
        self.body_object = [root_to_name.get(int(m.body_rootid[b]), "") for b in range(m.nbody)]
        self.flex_object = {fid: n for n, fid in self.flex.items()}

    def geom_object(self, m, geom: int) -> str:
        return self.body_object[int(m.geom_bodyid[geom])]

    def contact_side(self, m, c, k: int) -> tuple[str, int]:
        """(object name or "" for the room, body id or -1 - flex id) of side k of a contact."""
        g = int(c.geom[k])
        if g >= 0:
            b = int(m.geom_bodyid[g])
            return self.body_object[b], b
        f = int(c.flex[k])
        return self.flex_object.get(f, ""), -1 - f


def _flex_centroid(m, d, fid: int) -> np.ndarray:
    adr, num = int(m.flex_vertadr[fid]), int(m.flex_vertnum[fid])
    return d.flexvert_xpos[adr : adr + num].mean(axis=0)


def _start_penetration(m, d, index: _SceneIndex) -> tuple[float, dict[str, float], list[tuple[float, float, float]]]:
    """Deepest contact penetration between distinct bodies (objects, floor, walls) at the current
    state, per object, and the points of penetrating contacts."""
    worst = 0.0
    per_object: dict[str, float] = {}
    points: list[tuple[float, float, float, float]] = []
    for i in range(d.ncon):
        c = d.contact[i]
        pen = -float(c.dist)
        if pen <= 0.0:
            continue
        (na, ba), (nb, bb) = index.contact_side(m, c, 0), index.contact_side(m, c, 1)
        if ba == bb:
            continue
        worst = max(worst, pen)
        for n in (na, nb):
            if n:
                per_object[n] = max(per_object.get(n, 0.0), pen)
        points.append((pen, float(c.pos[0]), float(c.pos[1]), float(c.pos[2])))
    points.sort(key=lambda p: (-p[0], p[1], p[2], p[3]))
    return worst, per_object, [p[1:] for p in points[:MAX_CONTACT_POINTS]]


def _simulate(m, d, scene: Scene, index: _SceneIndex, settle_s: float) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Step ``settle_s`` seconds; sample free bodies and flex centroids at about 30 Hz.
    Returns name -> (times (T,), positions (T, 3), quats (T, 4))."""
    import mujoco

    dt = float(m.opt.timestep)
    steps = int(round(settle_s / dt))
    every = max(1, int(round(1.0 / (RECORD_HZ * dt))))
    tracked = [o.name for o in scene.objects if o.name in index.free_qpos or o.name in index.flex]
    times: list[float] = []
    pos: dict[str, list[np.ndarray]] = {n: [] for n in tracked}
    quat: dict[str, list[np.ndarray]] = {n: [] for n in tracked}

    def sample() -> None:
        times.append(float(d.time))
        for n in tracked:
            if n in index.flex:
                pos[n].append(_flex_centroid(m, d, index.flex[n]).copy())
                quat[n].append(np.array([1.0, 0.0, 0.0, 0.0]))
            else:
                b = index.root_body[n]
                pos[n].append(d.xpos[b].copy())
                quat[n].append(d.xquat[b].copy())

    sample()
    for k in range(1, steps + 1):
        mujoco.mj_step(m, d)
        if k % every == 0 or k == steps:
            sample()
    if not np.all(np.isfinite(d.qpos)):
        raise ExportError("physics check: the simulation diverged (NaN state); check masses, inertias and contact settings")
    t = np.array(times)
    return {n: (t, np.array(pos[n]), np.array(quat[n])) for n in tracked}


def _render_compare(m, index: _SceneIndex, perception: Perception, scene: Scene, mjcf_path: Path) -> Fidelity:
    """Render depth and segmentation from ``input_camera`` at the solved poses and compare them
    with the observation: depth AbsRel on perceived object pixels with valid observed depth (and
    some rendered geometry: object, floor or wall), and per-object mask IoU (geom -> body ->
    object; flex -> object)."""
    import mujoco

    cam = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, "input_camera")
    if cam < 0:
        raise ExportError(f"{mjcf_path.name}: no camera named 'input_camera'; the exporter must add the input camera")
    obs = perception.observation
    h, w = obs.depth_m.shape
    m.vis.global_.offwidth = max(int(m.vis.global_.offwidth), w)
    m.vis.global_.offheight = max(int(m.vis.global_.offheight), h)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    renderer = mujoco.Renderer(m, height=h, width=w)
    try:
        renderer.enable_depth_rendering()
        renderer.update_scene(d, camera=cam)
        depth = np.array(renderer.render(), dtype=np.float64)
        renderer.disable_depth_rendering()
        renderer.enable_segmentation_rendering()
        renderer.update_scene(d, camera=cam)
        seg = np.array(renderer.render())
    finally:
        renderer.close()

    # Segmentation ids -> object names (index 0 is "not an object").
    names = [o.name for o in scene.objects]
    code = {n: k + 1 for k, n in enumerate(names)}
    label = np.zeros((h, w), dtype=np.int64)
    ids, types = seg[..., 0], seg[..., 1]
    geom_code = np.array([code.get(index.geom_object(m, g), 0) for g in range(m.ngeom)] + [0], dtype=np.int64)
    is_geom = (types == int(mujoco.mjtObj.mjOBJ_GEOM)) & (ids >= 0)
    label[is_geom] = geom_code[ids[is_geom]]
    if index.flex:
        flex_code = np.zeros(max(m.nflex, 1) + 1, dtype=np.int64)
        for fid, n in index.flex_object.items():
            flex_code[fid] = code[n]
        is_flex = (types == int(mujoco.mjtObj.mjOBJ_FLEX)) & (ids >= 0)
        label[is_flex] = flex_code[ids[is_flex]]

    ious = []
    union_mask = np.zeros((h, w), dtype=bool)
    for po in perception.objects:
        perceived = po.mask
        union_mask |= perceived
        rendered = label == code.get(po.name, -1)
        union = int(np.count_nonzero(perceived | rendered))
        ious.append((po.name, float(np.count_nonzero(perceived & rendered)) / union if union else 0.0))
    # Pixels where the render hit no geometry hold the far clipping distance, not a depth.
    hit = ids >= 0
    valid = union_mask & (obs.depth_m > 0) & hit & np.isfinite(depth) & (depth > 0)
    if np.any(valid):
        d_obs = obs.depth_m[valid].astype(np.float64)
        absrel = float(np.mean(np.abs(depth[valid] - d_obs) / d_obs))
    else:
        absrel = float("nan")  # nothing to compare: no perceived object pixel has valid depth
    mean_iou = float(np.mean([v for _, v in ious])) if ious else float("nan")
    return Fidelity(depth_absrel=absrel, mask_iou_mean=mean_iou, mask_iou=tuple(ious))


def verify_scene(
    mjcf_path: Path, scene: Scene, config: LayoutConfig, perception: Perception | None = None
) -> tuple[PhysicsVerdict, Fidelity | None]:
    """Physics verdict of the exported scene, and render-and-compare when ``perception`` is given.

    At t = 0 (``mj_forward``): the deepest contact penetration between distinct bodies and
    against floor and walls (max of ``-contact.dist``) and the penetrating contact points. Then
    ``config.settle_s`` seconds of simulation at the model's own timestep: per object the drift
    of its root body origin (a flex: its vertex centroid), its rotation, and whether it toppled
    (rotation or up-axis tilt > 30 deg). ``stable``: every object within ``stable_drift_m`` and
    ``stable_rotation_deg`` (deformables: see DEFORMABLE_SAG_FRACTION). Fixed furniture cannot
    move and reports zero motion. Trajectories are sampled at about 30 Hz.
    """
    import mujoco

    mjcf_path = Path(mjcf_path)
    if not mjcf_path.is_file():
        raise InputError(f"physics check: {mjcf_path} does not exist; write the MJCF (exporters.write_mjcf) first")
    try:
        m = mujoco.MjModel.from_xml_path(str(mjcf_path))
    except ValueError as err:
        raise ExportError(f"physics check: MuJoCo cannot load {mjcf_path.name}: {str(err).splitlines()[0]}") from err
    index = _SceneIndex(m, scene, mjcf_path)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    max_pen, pen_by_object, contact_points = _start_penetration(m, d, index)
    tracks = _simulate(m, d, scene, index, float(config.settle_s))

    verdicts, trajectories = [], []
    max_drift, max_rot, stable = 0.0, 0.0, True
    for o in scene.objects:
        start_pen = pen_by_object.get(o.name, 0.0)
        if o.name not in tracks:  # fixed furniture: welded to the world
            verdicts.append(ObjectVerdict(o.name, start_pen, 0.0, 0.0, False))
            continue
        t, p, q = tracks[o.name]
        trajectories.append(Trajectory(o.name, t, p, q))
        drift = float(np.linalg.norm(p[-1] - p[0]))
        if o.name in index.flex:
            height = float(o.asset.size_m[2])
            ok = drift <= max(config.stable_drift_m, DEFORMABLE_SAG_FRACTION * height)
            verdicts.append(ObjectVerdict(o.name, start_pen, drift, 0.0, False))
            stable &= ok
            continue
        rot = _rotation_deg(q[0], q[-1])
        toppled = rot > TOPPLE_DEG or _tilt_deg(q[0], q[-1]) > TOPPLE_DEG
        verdicts.append(ObjectVerdict(o.name, start_pen, drift, rot, toppled))
        max_drift, max_rot = max(max_drift, drift), max(max_rot, rot)
        stable &= drift <= config.stable_drift_m and rot <= config.stable_rotation_deg
    verdict = PhysicsVerdict(
        max_penetration_m=float(max_pen),
        settle_max_drift_m=max_drift,
        settle_max_rotation_deg=max_rot,
        simulated_s=float(d.time),
        stable=bool(stable),
        objects=tuple(verdicts),
        trajectories=tuple(trajectories),
        contact_points_m=tuple(contact_points),
    )
    fidelity = _render_compare(m, index, perception, scene, mjcf_path) if perception is not None else None
    return verdict, fidelity


def settled_scene(scene: Scene, verdict: PhysicsVerdict) -> Scene:
    """The scene with each free rigid object moved to where it came to rest in the settle
    simulation: ``world_from_asset`` is premultiplied by the body's motion ``T_end @ T_start^-1``
    (so the result does not depend on where the exporter put the body frame). Fixed furniture
    and deformables (whose rest shape is the asset) keep their poses."""
    tracks = {t.name: t for t in verdict.trajectories}
    placed = []
    for o in scene.objects:
        t = tracks.get(o.name)
        if t is None or len(t.times_s) < 2 or o.asset.kind is AssetKind.DEFORMABLE:
            placed.append(o)
            continue
        start = pose(matrix_from_quat_wxyz(t.quats_wxyz[0]), t.positions_m[0])
        end = pose(matrix_from_quat_wxyz(t.quats_wxyz[-1]), t.positions_m[-1])
        motion = end @ np.linalg.inv(start)
        new = motion @ o.world_from_asset
        # Re-orthonormalise the rotation (float round-off of the quaternion products).
        u, _, vt = np.linalg.svd(new[:3, :3])
        new[:3, :3] = u @ vt
        placed.append(PlacedObject(asset=o.asset, world_from_asset=new, support=o.support))
    return Scene(camera=scene.camera, room=scene.room, objects=tuple(placed))


adopt_settled = settled_scene
