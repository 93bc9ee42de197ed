"""The physics verdict and render-and-compare, measured in MuJoCo on the exported MJCF.

Naming conventions (DEVELOPERS.md): the root part of object NAME is body ``NAME`` (free joint
``NAME/free`` unless fixed), other parts ``NAME/PART``, collision geoms in group 3, ``floor``,
``wall_i``, camera ``input_camera``, deformables are flex objects named ``NAME``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from scene_builder.config import LayoutConfig
from scene_builder.errors import ExportError, InputError
from scene_builder.frames import matrix_from_quat_wxyz
from scene_builder.model import Fidelity, ObjectVerdict, Perception, PhysicsVerdict, Scene, Trajectory

TOPPLE_DEG = 30.0
RECORD_HZ = 30.0
# A soft body's centroid sinks as it settles under its own weight (that is the point of a soft
# body); it counts as unstable only when its centroid moves more than this share of its height
# (or stable_drift_m, whichever is larger): sliding or falling off its support.
DEFORMABLE_SAG_FRACTION = 0.25
MAX_CONTACT_POINTS = 256
# The settle simulation ends before ``settle_s`` once every tracked object (free body, flex
# centroid) has moved less than REST_MOVE_M and turned less than REST_TURN_DEG over the last
# REST_WINDOW_S, and no degree of freedom is faster than REST_QVEL (m/s or rad/s: mid-bounce,
# mid-swing), but never before MIN_SETTLE_S: a body whose centre of mass lies past its support
# is turning faster than that within a fraction of a second, and a body at rest gains nothing
# from the rest of the simulation (a creep under 0.5 mm/s is under 1 mm in the 2 s left, against
# stable_drift_m = 1 cm). Net motion, not speed alone: resting contacts jitter at a few mm/s and
# a few deg/s without going anywhere (sunrgbd_imvotenet_000003: 0.05 mm and 0.03 deg net per
# 0.5 s from 0.7 s on). Measured on sunrgbd_imvotenet_000005: every body at rest after 0.3 s of
# its 3 s, which were 1.5 s of its 17 s build.
REST_MOVE_M = 2.5e-4
REST_TURN_DEG = 0.1
REST_QVEL = 0.05
REST_WINDOW_S = 0.5
MIN_SETTLE_S = 1.0


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
        # The robot (``--robot``, bodies ``robot/...``) is one owner: its links may touch each other.
        for b in range(m.nbody):
            if m.body(b).name.startswith("robot/"):
                self.body_object[b] = "robot"
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


def _collision_geoms(m) -> np.ndarray:
    """Ids of the geoms that take part in collisions (contype or conaffinity set)."""
    return np.flatnonzero((m.geom_contype != 0) | (m.geom_conaffinity != 0))


def _world_aabbs(m, d, geoms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(G, 3) lower and upper world-frame bounds of each geom (from its local AABB)."""
    c_local = m.geom_aabb[geoms, :3]
    h_local = m.geom_aabb[geoms, 3:]
    rot = d.geom_xmat[geoms].reshape(-1, 3, 3)
    centre = d.geom_xpos[geoms] + np.einsum("gij,gj->gi", rot, c_local)
    half = np.einsum("gij,gj->gi", np.abs(rot), h_local)
    return centre - half, centre + half


def _penetration(m, d, index: _SceneIndex) -> tuple[float, dict[str, float], list[tuple[float, float, float]]]:
    """Deepest overlap at the current state over every pair of collision geoms of different
    bodies (objects, fixed furniture, floor, walls, static background; parts of one object
    excepted), measured exactly with ``mj_geomDistance`` after a box broad phase; soft bodies
    (flex) by their contacts. Returns the depth, the depth per object and the points of
    overlapping pairs (deepest first)."""
    import mujoco

    from layout.pushes import candidate_pairs

    geoms = _collision_geoms(m)
    lo, hi = _world_aabbs(m, d, geoms)
    body = m.geom_bodyid[geoms]
    owner = np.array([index.body_object[int(b)] for b in body], dtype=object)
    worst = 0.0
    per_object: dict[str, float] = {}
    points: list[tuple[float, float, float, float]] = []
    fromto = np.zeros(6)
    for a, b in candidate_pairs(lo, hi, 0.0):
        ga, gb = int(geoms[a]), int(geoms[b])
        if body[a] == body[b] or (owner[a] and owner[a] == owner[b]):
            continue
        dist = float(mujoco.mj_geomDistance(m, d, ga, gb, 1e-3, fromto))
        if dist >= 0.0:
            continue
        pen = -dist
        worst = max(worst, pen)
        for n in (owner[a], owner[b]):
            if n:
                per_object[n] = max(per_object.get(n, 0.0), pen)
        mid = 0.5 * (fromto[:3] + fromto[3:])
        points.append((pen, float(mid[0]), float(mid[1]), float(mid[2])))
    # Soft bodies: MuJoCo's own contacts with them (mj_geomDistance does not take flexes).
    for i in range(d.ncon):
        c = d.contact[i]
        if c.flex[0] < 0 and c.flex[1] < 0:
            continue
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
    """Step up to ``settle_s`` seconds, less once everything is at rest (:data:`REST_MOVE_M`);
    sample free bodies and flex centroids at about 30 Hz.
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

    def at_rest() -> bool:
        if d.time < MIN_SETTLE_S or (m.nv and float(np.max(np.abs(d.qvel))) >= REST_QVEL):
            return False
        back = int(np.searchsorted(times, d.time - REST_WINDOW_S + 1e-9)) - 1
        if back < 0:
            return False
        for n in tracked:
            if np.linalg.norm(pos[n][-1] - pos[n][back]) >= REST_MOVE_M or _rotation_deg(quat[n][-1], quat[n][back]) >= REST_TURN_DEG:
                return False
        return True

    sample()
    for k in range(1, steps + 1):
        mujoco.mj_step(m, d)
        if k % every == 0 or k == steps:
            sample()
            if at_rest():
                break
    if not np.all(np.isfinite(d.qpos)):
        raise ExportError("physics check: the simulation diverged (NaN state); check masses, inertias and contact settings")
    t = np.array(times)
    return {n: (t, np.array(pos[n]), np.array(quat[n])) for n in tracked}


#: A depth pixel more than this share off the median of its OUTLIER_WINDOW_PX neighbourhood is an
#: isolated outlier (sensor speckle, a flying pixel on a depth edge), not a measurement.
OUTLIER_SHARE = 0.10
OUTLIER_WINDOW_PX = 5


def valid_depth(depth_m: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels with a measured depth that agrees within OUTLIER_SHARE with the median
    of its OUTLIER_WINDOW_PX x OUTLIER_WINDOW_PX neighbourhood (the reference for depth AbsRel:
    the TUI-NICR Kinect samples have near-zero speckle that would otherwise dominate the mean)."""
    import cv2

    d = np.asarray(depth_m, dtype=np.float64)
    # OpenCV's median (edges replicated, as scipy's mode="nearest") on float32: 40x faster than
    # scipy.ndimage.median_filter on a 640 x 480 map; the 10 % test cannot tell the rounding.
    med = cv2.medianBlur(d.astype(np.float32), OUTLIER_WINDOW_PX).astype(np.float64)
    return (d > 0) & (np.abs(d - med) <= OUTLIER_SHARE * med)


#: A rendered depth this share of the far clipping plane's distance or farther hit nothing.
FAR_SHARE = 0.999


class _Renders:
    """RGB (the scene's own lights), depth and object labels rendered from ``input_camera``."""

    @staticmethod
    def renderer(m, mjcf_path: Path, size: tuple[int, int]):
        """A MuJoCo renderer of ``size`` (h, w) for the model ``m`` (about 0.5 s to make: one
        serves every render of a check); the caller closes it."""
        import mujoco

        if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, "input_camera") < 0:
            raise ExportError(f"{mjcf_path.name}: no camera named 'input_camera'; the exporter must add the input camera")
        h, w = size
        m.vis.global_.offwidth = max(int(m.vis.global_.offwidth), w)
        m.vis.global_.offheight = max(int(m.vis.global_.offheight), h)
        return mujoco.Renderer(m, height=h, width=w)

    def __init__(self, renderer, m, d, index: _SceneIndex, scene: Scene, labels: bool = True) -> None:
        """``labels``: render the segmentation too (which object each pixel shows, ``label``);
        without it (the settled state's renders, whose labels nothing reads) a pixel hit
        something where its depth lies nearer than the far clipping plane (on the real photos'
        scenes the same pixels as the segmentation's; one render and read-back fewer)."""
        import mujoco

        cam = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, "input_camera")
        h, w = renderer.height, renderer.width
        renderer.update_scene(d, camera=cam)
        self.rgb = np.array(renderer.render(), dtype=np.uint8)
        renderer.enable_depth_rendering()
        renderer.update_scene(d, camera=cam)
        self.depth = np.array(renderer.render(), dtype=np.float64)
        renderer.disable_depth_rendering()
        if not labels:
            self.hit = self.depth < FAR_SHARE * float(m.vis.map.zfar * m.stat.extent)
            self.code, self.label = {}, None
            return
        renderer.enable_segmentation_rendering()
        renderer.update_scene(d, camera=cam)
        seg = np.array(renderer.render())
        renderer.disable_segmentation_rendering()
        ids, types = seg[..., 0], seg[..., 1]
        self.hit = ids >= 0
        # Segmentation ids -> object index + 1 (0: not an object: the room, the background).
        code = {o.name: k + 1 for k, o in enumerate(scene.objects)}
        label = np.zeros((h, w), dtype=np.int64)
        geom_code = np.array([code.get(index.geom_object(m, g), 0) for g in range(m.ngeom)] + [0], dtype=np.int64)
        is_geom = (types == int(mujoco.mjtObj.mjOBJ_GEOM)) & self.hit
        label[is_geom] = geom_code[ids[is_geom]]
        if index.flex:
            flex_code = np.zeros(max(m.nflex, 1) + 1, dtype=np.int64)
            for fid, n in index.flex_object.items():
                flex_code[fid] = code[n]
            is_flex = (types == int(mujoco.mjtObj.mjOBJ_FLEX)) & self.hit
            label[is_flex] = flex_code[ids[is_flex]]
        self.label = label
        self.code = code

    def depth_absrel(self, observed_m: np.ndarray, valid: np.ndarray) -> float:
        """Mean |d_render - d_obs| / d_obs over the ``valid`` pixels (:func:`valid_depth`, computed
        once per check for both renders); a pixel where the render hit nothing counts as
        relative error 1."""
        if not np.any(valid):
            return float("nan")
        d_obs = observed_m[valid].astype(np.float64)
        err = np.abs(self.depth[valid] - d_obs) / d_obs
        err[~self.hit[valid]] = 1.0
        return float(np.mean(err))

    def image_scores(self, photo: np.ndarray) -> tuple[float, float]:
        """(PSNR dB, SSIM) of the RGB render against the photo. PSNR is written here:
        scikit-image's ``peak_signal_noise_ratio`` lives beside a module that imports scipy.stats
        (0.7 s of a build) for one line of arithmetic; the same definition (10 log10(255^2 / MSE)
        over every channel). SSIM: :func:`ssim`. Both compared with scikit-image's in the tests."""
        mse = float(np.mean((photo.astype(np.float64) - self.rgb.astype(np.float64)) ** 2))
        psnr = float("inf") if mse == 0 else float(10.0 * np.log10(255.0 ** 2 / mse))
        return psnr, ssim(photo, self.rgb)


#: SSIM's window (pixels) and constants, scikit-image's defaults (Wang et al. 2004 with a
#: uniform window and the sample covariance).
SSIM_WINDOW_PX = 7
SSIM_K1, SSIM_K2 = 0.01, 0.03


def ssim(a: np.ndarray, b: np.ndarray, data_range: float = 255.0) -> float:
    """Mean structural similarity of two (H, W, C) images: scikit-image's
    ``structural_similarity(a, b, channel_axis=2, data_range=data_range)`` (same window,
    constants, sample covariance and border crop; equal to about 1e-15), with the window means
    taken by OpenCV's box filter on all channels at once: 2-3x faster (0.5 -> 0.2 s on a
    1280 x 960 photo, computed twice per physics check)."""
    import cv2

    x, y = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    win = SSIM_WINDOW_PX
    cov = win * win / (win * win - 1.0)
    c1, c2 = (SSIM_K1 * data_range) ** 2, (SSIM_K2 * data_range) ** 2

    def mean(im: np.ndarray) -> np.ndarray:
        return cv2.blur(im, (win, win), borderType=cv2.BORDER_REFLECT)

    ux, uy = mean(x), mean(y)
    vx, vy, vxy = cov * (mean(x * x) - ux * ux), cov * (mean(y * y) - uy * uy), cov * (mean(x * y) - ux * uy)
    s = ((2.0 * ux * uy + c1) * (2.0 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2))
    pad = (win - 1) // 2
    return float(s[pad:-pad, pad:-pad].mean())


def _fidelity(first: _Renders, last: _Renders, perception: Perception, scene: Scene) -> Fidelity:
    obs = perception.observation
    movable = {o.name for o in scene.objects if not o.asset.is_fixed}
    ious = []
    objects_px = np.zeros(obs.depth_m.shape, dtype=bool)
    for po in perception.objects:
        if po.name not in movable:
            continue
        objects_px |= po.mask
        rendered = first.label == first.code.get(po.name, -1)
        union = int(np.count_nonzero(po.mask | rendered))
        ious.append((po.name, float(np.count_nonzero(po.mask & rendered)) / union if union else 0.0))
    valid = valid_depth(obs.depth_m)
    psnr, ssim = first.image_scores(obs.rgb)
    psnr_end, ssim_end = last.image_scores(obs.rgb)
    return Fidelity(
        depth_absrel=first.depth_absrel(obs.depth_m, valid),
        mask_iou_mean=float(np.mean([v for _, v in ious])) if ious else float("nan"),
        mask_iou=tuple(ious),
        depth_absrel_settled=last.depth_absrel(obs.depth_m, valid),
        object_depth_absrel=first.depth_absrel(obs.depth_m, valid & objects_px) if np.any(objects_px) else float("nan"),
        psnr_db=psnr,
        ssim=ssim,
        psnr_settled_db=psnr_end,
        ssim_settled=ssim_end,
        render_rgb=first.rgb,
        render_settled_rgb=last.rgb,
    )


def verify_scene(
    mjcf_path: Path, scene: Scene, config: LayoutConfig, perception: Perception | None = None,
    fidelity_when: Callable[[PhysicsVerdict], bool] | None = None,
) -> tuple[PhysicsVerdict, Fidelity | None]:
    """Physics verdict of the exported scene, and render-and-compare when ``perception`` is given
    (and ``fidelity_when``, if given, says yes of the verdict: a check whose scene will be
    repaired and checked again needs no renders, about 2 s of a build).

    At t = 0 (``mj_forward``) and again after ``config.settle_s`` seconds of simulation at the
    model's own timestep (fewer once every body is at rest, :data:`REST_MOVE_M`): the deepest
    overlap over every pair of collision geoms of different bodies (:func:`_penetration`:
    objects, fixed furniture, floor, walls, static background). Per movable object the drift of
    its root body origin (a flex: its vertex centroid), its rotation, and whether it toppled
    (rotation or up-axis tilt > 30 deg); ``stable``: every movable object within
    ``stable_drift_m`` and ``stable_rotation_deg`` (deformables: see DEFORMABLE_SAG_FRACTION).
    Fixed furniture cannot move: it is counted apart and never as at rest. Trajectories are
    sampled at about 30 Hz. With ``perception``, the scene is rendered from ``input_camera`` at
    t = 0 and after settling and compared with the photo and its depth
    (:class:`~scene_builder.model.Fidelity`).
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
    max_pen, pen_by_object, contact_points = _penetration(m, d, index)
    tracks = _simulate(m, d, scene, index, float(config.settle_s))
    mujoco.mj_forward(m, d)
    end_pen, end_by_object, _ = _penetration(m, d, index)

    verdicts, trajectories = [], []
    max_drift, max_rot, stable = 0.0, 0.0, True
    n_fixed = 0
    for o in scene.objects:
        start_pen, end_p = pen_by_object.get(o.name, 0.0), end_by_object.get(o.name, 0.0)
        if o.name not in tracks:  # fixed furniture: welded to the world
            n_fixed += 1
            verdicts.append(ObjectVerdict(o.name, start_pen, 0.0, 0.0, False, fixed=True, end_penetration_m=end_p))
            continue
        t, p, q = tracks[o.name]
        trajectories.append(Trajectory(o.name, t, p, q))
        drift = float(np.linalg.norm(p[-1] - p[0]))
        if o.name in index.flex:
            height = float(o.asset.size_m[2])
            ok = drift <= max(config.stable_drift_m, DEFORMABLE_SAG_FRACTION * height)
            verdicts.append(ObjectVerdict(o.name, start_pen, drift, 0.0, False, end_penetration_m=end_p))
            stable &= ok
            continue
        rot = _rotation_deg(q[0], q[-1])
        toppled = rot > TOPPLE_DEG or _tilt_deg(q[0], q[-1]) > TOPPLE_DEG
        verdicts.append(ObjectVerdict(o.name, start_pen, drift, rot, toppled, end_penetration_m=end_p))
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
        max_penetration_settled_m=float(end_pen),
        movable_count=len(scene.objects) - n_fixed,
        fixed_count=n_fixed,
    )
    fidelity = None
    if perception is not None and (fidelity_when is None or fidelity_when(verdict)):
        renderer = _Renders.renderer(m, mjcf_path, perception.observation.depth_m.shape)
        try:
            last = _Renders(renderer, m, d, index, scene, labels=False)
            mujoco.mj_resetData(m, d)  # back to t = 0: the model's initial state, as checked above
            mujoco.mj_forward(m, d)
            first = _Renders(renderer, m, d, index, scene)
        finally:
            renderer.close()
        fidelity = _fidelity(first, last, perception, scene)
    return verdict, fidelity
