"""Interaction probes on the exported MJCF: a scripted push and doors / drawers pulled open.

What a robot would do first with a twin: push an object a few centimetres and open a door. Both
run in MuJoCo on ``scene.xml`` as written (naming conventions of DEVELOPERS.md: root body ``NAME``
with free joint ``NAME/free``, articulation joints ``NAME/PART/joint``, collision geoms in
group 3), after a short settle (``PRE_SETTLE_S``) so that every measurement starts from rest.

Push (:func:`push_object`): a kinematic pusher, a mocap paddle added to the model by
:func:`load_probe_model`, collides with the pushed object only (contype bit ``PUSHER_BIT``): it is
the robot's fingertip, which a real robot brings in from wherever it has room. It is driven at
``PUSH_SPEED_M_S`` horizontally into the object's side along one of the four horizontal face
directions of its body frame (:func:`plan_push` picks the one with the most free space ahead,
found by sliding its collision geometry there, whose support polygon still holds its centre of
mass after the push, and which does not drag a neighbour touching its side), on an upright face
at the lowest height up to its centre of mass and below the height where it would tip before
sliding; it advances ``PUSH_TRAVEL_M`` past first contact, is withdrawn, and the scene settles for
``POST_SETTLE_S``. Objects resting on the pushed one (directly or on each other, found from the
contacts at rest: normal within 45 degrees of vertical) ride along: they are reported as
``carried``, not as others. Free bodies only: soft bodies (flex) are neither pushed nor tracked.

Door / drawer (:func:`open_joint`): a pull at the handle (the part's ``*handle`` child body, else
its edge farthest from the hinge axis), tangential to the swing for a hinge and along the axis
for a slide, applied through ``xfrc_applied``; like a hand it pulls with at most ``force_n`` and
eases off above ``PULL_SPEED`` (so it neither slams the part into its stop nor lets go while
the part is slow). Measured: travel, backtracking, excursion beyond the joint range, and how far
the carcass moved.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scene_builder.errors import ExportError, InputError
from scene_builder.model import JointProbe, PushPlan, PushResult

__all__ = ["interaction_problems", "joint_names", "load_probe_model", "open_joint", "plan_push", "probe_lines", "probe_scene", "push_object"]

PUSHER = "probe/pusher"
PUSHER_BIT = 2  # contype bit of the pusher; only the pushed object's geoms get it in conaffinity
PUSHER_HALF_THICKNESS_M = 0.01
PUSHER_FRICTION = 0.3
PUSH_SPEED_M_S = 0.05
PUSH_TRAVEL_M = 0.06
APPROACH_GAP_M = 0.01  # the pusher starts this far from the object's surface
MIN_CLEARANCE_M = 0.10  # free space needed ahead: the push travel, the settle and a margin
CLEARANCE_CAP_M = 0.3  # free space is measured up to this far
CLEARANCE_STEP_M = 0.01
BLOCK_DEPTH_M = 0.002
DRAG_COS = 0.5  # a push must leave a side-touching neighbour at least 60 deg off its contact normal
NEAR_M = 0.01  # a neighbour this close beside an object counts as touching it (a push swerves;
# the layout leaves 2 mm between neighbours)
SUPPORT_DROP_M = 0.03  # a bottom point is supported by anything within this below it
SUPPORT_MARGIN_M = 0.03  # support is checked this much beyond the push travel
SUPPORT_INSET_M = 0.01  # the centre of mass must stay this far inside the support polygon
UPRIGHT_NZ = 0.3  # a face whose normal is within ~17 deg of horizontal is upright enough to push
PRE_SETTLE_S = 0.5
POST_SETTLE_S = 1.0
RIDER_NORMAL_Z = 0.7  # a contact whose normal is within ~45 deg of vertical is resting contact
PULL_N = 10.0  # a hand's pull; raised for joints that need more (friction, gravity: see _pull_force)
PULL_SPEED = {"hinge": 1.0, "slide": 0.25}  # rad/s, m/s: the hand pulls at most this fast
PULL_S = 3.0
RELEASE_S = 0.5
# What counts as a good interaction (``interaction_problems``; the bar).
PUSH_MOVE_M = (0.02, 0.10)
PUSH_TILT_MAX_DEG = 10.0
OTHERS_MAX_M = 0.01
OPEN_MIN_FRACTION = 0.5
LIMIT_TOLERANCE = {"hinge": np.radians(2.0), "slide": 0.005}
BACKTRACK_TOLERANCE = {"hinge": np.radians(1.0), "slide": 0.002}
CARCASS_MAX_M = 0.01


def load_probe_model(mjcf_path: Path):
    """The MJCF at ``mjcf_path`` compiled with the pusher: a mocap body ``probe/pusher`` holding a
    box geom that collides with nothing until :func:`push_object` enables it for one object."""
    import mujoco

    mjcf_path = Path(mjcf_path)
    if not mjcf_path.is_file():
        raise InputError(f"interaction probe: {mjcf_path} does not exist; pass the scene.xml of a built scene")
    try:
        spec = mujoco.MjSpec.from_file(str(mjcf_path))
        body = spec.worldbody.add_body(name=PUSHER, mocap=True, pos=[0.0, 0.0, -10.0])
        body.add_geom(name=PUSHER, type=mujoco.mjtGeom.mjGEOM_BOX, size=[PUSHER_HALF_THICKNESS_M, 0.03, 0.03],
                      contype=PUSHER_BIT, conaffinity=0, group=3, friction=[PUSHER_FRICTION, 0.005, 0.0001],
                      condim=3, rgba=[0.2, 0.8, 0.2, 1.0], density=0.0)
        return spec.compile()
    except ValueError as err:
        raise ExportError(f"interaction probe: MuJoCo cannot load {mjcf_path.name}: {str(err).splitlines()[0]}") from err


def _as_model(model, with_pusher: bool):
    import mujoco

    if isinstance(model, mujoco.MjModel):
        if with_pusher and mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, PUSHER) < 0:
            raise InputError("interaction probe: the model has no pusher; load it with layout.interaction.load_probe_model")
        return model
    if with_pusher:
        return load_probe_model(model)
    path = Path(model)
    if not path.is_file():
        raise InputError(f"interaction probe: {path} does not exist; pass the scene.xml of a built scene")
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as err:
        raise ExportError(f"interaction probe: MuJoCo cannot load {path.name}: {str(err).splitlines()[0]}") from err


class _Objects:
    """Free objects of the model: root body ``NAME`` with free joint ``NAME/free``; every body
    and colliding geom of each object."""

    def __init__(self, m) -> None:
        import mujoco

        self.root: dict[str, int] = {}
        for b in range(1, m.nbody):
            if int(m.body_parentid[b]) != 0:
                continue
            name = m.body(b).name
            j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{name}/free")
            if j >= 0 and int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE) and int(m.jnt_bodyid[j]) == b:
                self.root[name] = b
        by_root = {b: n for n, b in self.root.items()}
        self.body_object = [by_root.get(int(m.body_rootid[b]), "") for b in range(m.nbody)]
        colliding = (m.geom_contype != 0) | (m.geom_conaffinity != 0)
        pusher = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, PUSHER)
        self.pusher_geom = pusher
        self.geom_object = np.array([self.body_object[int(m.geom_bodyid[g])] for g in range(m.ngeom)], dtype=object)
        self.colliding = colliding.copy()
        if pusher >= 0:
            self.colliding[pusher] = False
        self.names = sorted(self.root)
        self.groups = np.zeros(6, dtype=np.uint8)  # geom groups that hold colliding geoms (for rays)
        for g in np.flatnonzero(self.colliding):
            if 0 <= int(m.geom_group[g]) < 6:
                self.groups[int(m.geom_group[g])] = 1

    def geoms(self, name: str) -> np.ndarray:
        return np.flatnonzero((self.geom_object == name) & self.colliding)


def _settle(m, d, seconds: float, on_step=None) -> None:
    import mujoco

    for _ in range(int(round(seconds / float(m.opt.timestep)))):
        mujoco.mj_step(m, d)
        if on_step is not None:
            on_step()
    if not np.all(np.isfinite(d.qpos)):
        raise ExportError("interaction probe: the simulation diverged (NaN state); check masses, inertias and contact settings")


def _points(m, d, geoms: np.ndarray) -> np.ndarray:
    """(N, 3) world points of the geoms: mesh vertices, or the corners of a primitive's box."""
    import mujoco

    out = []
    for g in geoms:
        g = int(g)
        rot = d.geom_xmat[g].reshape(3, 3)
        if int(m.geom_type[g]) == int(mujoco.mjtGeom.mjGEOM_MESH):
            mid = int(m.geom_dataid[g])
            v = m.mesh_vert[int(m.mesh_vertadr[mid]) : int(m.mesh_vertadr[mid]) + int(m.mesh_vertnum[mid])]
        else:
            c, h = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
            v = c + h * np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
        out.append(d.geom_xpos[g] + v @ rot.T)
    return np.concatenate(out) if out else np.zeros((0, 3))


def _cast(m, d, objects: _Objects, pnt, vec, accept, cap: float, normal: np.ndarray | None = None) -> float:
    """Distance along the unit ``vec`` from ``pnt`` to the first colliding geom ``accept(g)``
    takes (rays pass through the others: visual geoms, the pushed object itself); inf if none
    within ``cap``. ``normal`` (3,), when given, receives the surface normal at the hit."""
    import mujoco

    groups = objects.groups
    gid = np.zeros(1, dtype=np.int32)
    if normal is None:
        normal = np.zeros(3)
    p = np.asarray(pnt, dtype=np.float64).copy()
    vec = np.asarray(vec, dtype=np.float64)
    gone = 0.0
    for _ in range(64):
        dist = float(mujoco.mj_ray(m, d, p, vec, groups, 1, -1, gid, normal))
        if dist < 0.0 or gone + dist > cap:
            return float("inf")
        g = int(gid[0])
        if objects.colliding[g] and accept(g):
            return gone + dist
        step = dist + 1e-4
        gone += step
        p = p + step * vec
    return float("inf")


def _riders(m, d, objects: _Objects, name: str) -> set[str]:
    """Objects resting on ``name``, directly or on each other (from the contacts at rest)."""
    on: dict[str, set[str]] = {}
    for i in range(d.ncon):
        c = d.contact[i]
        g0, g1 = int(c.geom[0]), int(c.geom[1])
        if g0 < 0 or g1 < 0:
            continue
        a, b = objects.geom_object[g0], objects.geom_object[g1]
        if not a or not b or a == b:
            continue
        nz = float(c.frame[2])  # contact normal, from geom 0 toward geom 1
        if nz > RIDER_NORMAL_Z:
            on.setdefault(a, set()).add(b)  # b rests on a
        elif nz < -RIDER_NORMAL_Z:
            on.setdefault(b, set()).add(a)
    out: set[str] = set()
    todo = [name]
    while todo:
        for r in sorted(on.get(todo.pop(), ())):
            if r not in out and r != name:
                out.add(r)
                todo.append(r)
    return out


def _face_directions(d, root: int) -> list[np.ndarray]:
    """The four horizontal face directions of the body frame (+x, +y, -x, -y; unit, z = 0)."""
    rot = d.xmat[root].reshape(3, 3)
    x = rot[:, 0].copy()
    x[2] = 0.0
    if np.linalg.norm(x) < 1e-6:  # lying on its side: the world axes
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.array([-x[1], x[0], 0.0])
    return [x, y, -x, -y]


def _clearance(m, d, objects: _Objects, movers: set[str], direction: np.ndarray) -> float:
    """Free space ahead along the horizontal unit ``direction``: the pushed object and what rides
    on it are slid there in CLEARANCE_STEP_M steps (kinematics and MuJoCo's own collision
    detection on a copy of the state, no dynamics) until one of their collision geoms reaches
    BLOCK_DEPTH_M into anything else with a contact normal more than 45 deg from vertical (a
    wall, the background, a neighbour: resting contacts on the floor or a support do not block).
    Exact for the real (non-convex, multi-piece) shapes, unlike rays over the front face."""
    import mujoco

    d2 = mujoco.MjData(m)
    d2.qpos[:] = d.qpos
    d2.mocap_pos[:] = d.mocap_pos
    d2.mocap_quat[:] = d.mocap_quat
    adrs = [int(m.jnt_qposadr[int(m.body_jntadr[objects.root[n]])]) for n in sorted(movers)]
    moving = np.isin(objects.geom_object, sorted(movers))
    s = 0.0
    while s < CLEARANCE_CAP_M - 1e-9:
        s = min(s + CLEARANCE_STEP_M, CLEARANCE_CAP_M)
        for a in adrs:
            d2.qpos[a : a + 2] = d.qpos[a : a + 2] + s * direction[:2]
        mujoco.mj_kinematics(m, d2)
        mujoco.mj_collision(m, d2)
        n = d2.ncon
        if not n:
            continue
        g = d2.contact.geom[:n]
        valid = (g[:, 0] >= 0) & (g[:, 1] >= 0)
        g = np.where(valid[:, None], g, 0)
        one_side = moving[g[:, 0]] ^ moving[g[:, 1]]
        lateral = np.abs(d2.contact.frame[:n, 2]) < RIDER_NORMAL_Z
        deep = d2.contact.dist[:n] < -BLOCK_DEPTH_M
        if np.any(valid & one_side & lateral & deep):
            return s - CLEARANCE_STEP_M
    return CLEARANCE_CAP_M


def _touching(m, d, objects: _Objects, name: str, riders: set[str]) -> list[tuple[str, np.ndarray]]:
    """Free objects beside ``name`` at rest (not riders): touching it, or within NEAR_M of its
    side (a push that swerves a little closes that gap and drags them by friction); (neighbour,
    horizontal unit normal from ``name`` toward it), one per contact or near pair of geoms."""
    import mujoco

    out = []
    for i in range(d.ncon):
        c = d.contact[i]
        g0, g1 = int(c.geom[0]), int(c.geom[1])
        if g0 < 0 or g1 < 0 or float(c.dist) > BLOCK_DEPTH_M or abs(float(c.frame[2])) >= RIDER_NORMAL_Z:
            continue
        a, b = objects.geom_object[g0], objects.geom_object[g1]
        if name not in (a, b) or a == b:
            continue
        other, n = (b, np.array(c.frame[:3])) if a == name else (a, -np.array(c.frame[:3]))
        if not other or other in riders:
            continue
        n[2] = 0.0
        out.append((other, n / max(float(np.linalg.norm(n)), 1e-9)))
    mine = objects.geoms(name)
    others = [g for g in np.flatnonzero(objects.colliding) if objects.geom_object[g] not in ("", name) and objects.geom_object[g] not in riders]
    fromto = np.zeros(6)
    for g0 in mine:
        for g1 in others:
            gap = float(np.linalg.norm(d.geom_xpos[g0] - d.geom_xpos[g1])) - float(m.geom_rbound[g0] + m.geom_rbound[g1])
            if gap > NEAR_M:
                continue
            dist = mujoco.mj_geomDistance(m, d, int(g0), int(g1), NEAR_M, fromto)
            n = fromto[3:] - fromto[:3]
            if not 0.0 < dist <= NEAR_M or abs(n[2]) >= RIDER_NORMAL_Z * np.linalg.norm(n):
                continue
            n[2] = 0.0
            out.append((str(objects.geom_object[g1]), n / max(float(np.linalg.norm(n)), 1e-9)))
    return out


def _supported(m, d, objects: _Objects, pts: np.ndarray, com: np.ndarray, shift: np.ndarray, accept) -> bool:
    """Whether the object would still stand with its points moved by ``shift``: rays down from
    its bottom points (those within 2 cm of its lowest, at most 256) find support within
    SUPPORT_DROP_M, and its centre of mass lies at least SUPPORT_INSET_M inside the convex hull
    of the supported ones (its support polygon)."""
    from scipy.spatial import ConvexHull, QhullError

    bottom = float(pts[:, 2].min())
    base = pts[pts[:, 2] < bottom + 0.02]
    if len(base) > 256:
        base = base[np.linspace(0, len(base) - 1, 256).astype(int)]
    down = np.array([0.0, 0.0, -1.0])
    held = [p[:2] + shift[:2] for p in base
            if np.isfinite(_cast(m, d, objects, np.array([p[0] + shift[0], p[1] + shift[1], bottom + 0.01]), down, accept, cap=0.01 + SUPPORT_DROP_M))]
    if len(held) < 3:
        return False
    try:
        hull = ConvexHull(np.array(held))
    except QhullError:  # collinear: a knife edge
        return False
    c = com[:2] + shift[:2]
    return bool(np.all(hull.equations[:, :2] @ c + hull.equations[:, 2] <= -SUPPORT_INSET_M))


SIDES = ("front (+x)", "left (+y)", "back (-x)", "right (-y)")  # of the object's body frame


def _plan(m, d, objects: _Objects, name: str, riders: set[str], travel_m: float) -> PushPlan:
    root = objects.root[name]
    geoms = objects.geoms(name)
    if len(geoms) == 0:
        return PushPlan(name, False, (0.0, 0.0), 0.0, "it has no collision geometry")
    pts = _points(m, d, geoms)
    skip = {name} | riders
    accept = lambda g: objects.geom_object[g] not in skip  # noqa: E731
    com = d.subtree_com[root]
    touching = _touching(m, d, objects, name, riders)
    tried = []
    for k, u in enumerate(_face_directions(d, root)):
        clear = _clearance(m, d, objects, skip, u)
        supported = _supported(m, d, objects, pts, com, (travel_m + SUPPORT_MARGIN_M) * u, accept)
        # a neighbour touching its side (or near it) is dragged along by friction unless the push leaves it
        dragged = sorted({n for n, normal in touching if float(normal @ u) > -DRAG_COS})
        if clear < MIN_CLEARANCE_M:
            why = f"{clear * 100:.0f} cm free"
        elif not supported:
            why = f"no support {(travel_m + SUPPORT_MARGIN_M) * 100:.0f} cm ahead"
        elif dragged:
            why = f"would drag {', '.join(dragged)} at (or within 1 cm of) its side"
        else:
            why = ""
        tried.append((-clear, k, u, clear, why))
    tried.sort(key=lambda t: (t[0], t[1]))
    for _, _, u, clear, why in tried:
        if not why:
            return PushPlan(name, True, (float(u[0]), float(u[1])), float(clear))
    _, _, u, clear, _ = tried[0]
    why = "no side to push it from: " + "; ".join(f"toward its {SIDES[k]} {w}" for _, k, _, _, w in sorted(tried, key=lambda t: t[1]))
    return PushPlan(name, False, (float(u[0]), float(u[1])), float(clear), why)


def _settled(model, with_pusher: bool):
    import mujoco

    m = _as_model(model, with_pusher)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    _settle(m, d, PRE_SETTLE_S)
    mujoco.mj_forward(m, d)
    return m, d


def plan_push(model, travel_m: float = PUSH_TRAVEL_M) -> tuple[PushPlan, ...]:
    """Push plans of every free object of ``model`` (a scene.xml path or a model from
    :func:`load_probe_model`), sorted by name, after ``PRE_SETTLE_S`` of settling."""
    m, d = _settled(model, True)
    objects = _Objects(m)
    return tuple(_plan(m, d, objects, n, _riders(m, d, objects, n), travel_m) for n in objects.names)


def push_object(model, name: str, direction_xy=None, travel_m: float = PUSH_TRAVEL_M, speed_m_s: float = PUSH_SPEED_M_S) -> PushResult:
    """Push free object ``name`` of ``model`` (a scene.xml path or a model from
    :func:`load_probe_model`) ``travel_m`` past first contact at ``speed_m_s`` along
    ``direction_xy`` (default: the direction :func:`plan_push` picks, pushable or not) and
    measure what moved (:class:`~scene_builder.model.PushResult`)."""
    import mujoco

    m, d = _settled(model, True)
    objects = _Objects(m)
    if name not in objects.root:
        raise InputError(f"interaction probe: no free object {name!r} in the model (free objects: {', '.join(objects.names) or 'none'})")
    riders = _riders(m, d, objects, name)
    geoms = objects.geoms(name)
    if len(geoms) == 0:
        raise InputError(f"interaction probe: {name} has no collision geometry to push")
    if direction_xy is None:
        plan = _plan(m, d, objects, name, riders, travel_m)
        u = np.array([plan.direction_xy[0], plan.direction_xy[1], 0.0])
        clearance = plan.clearance_m
    else:
        u = np.array([float(direction_xy[0]), float(direction_xy[1]), 0.0])
        if np.linalg.norm(u) < 1e-9:
            raise InputError("interaction probe: the push direction is zero")
        u /= np.linalg.norm(u)
        clearance = _clearance(m, d, objects, {name} | riders, u)
    perp = np.array([-u[1], u[0], 0.0])
    root = objects.root[name]
    pts = _points(m, d, geoms)
    bottom, top = float(pts[:, 2].min()), float(pts[:, 2].max())
    lat = pts @ perp
    half_w = float(np.clip(0.3 * (lat.max() - lat.min()), 0.01, 0.05))
    half_h = float(np.clip(0.25 * (top - bottom), 0.01, 0.04))
    com = d.subtree_com[root].copy()
    # Where to push: on the line through its centre of mass (else the nearest line across its
    # extent where the paddle meets it), at the lowest height up to its centre of mass where the paddle meets an upright
    # face (a sloped face wedges the object against its support instead of sliding it), at most
    # half the height at which a push would tip it over its leading bottom edge before it slides
    # (it tips when height x friction > the lever of its weight), as a robot pushes a tall
    # cabinet low. Rays over the paddle's face from behind the object find where it first meets it.
    base_pts = pts[pts[:, 2] < bottom + 0.02]
    lever = max(float((base_pts @ u).max() - com @ u), 0.0)
    mu = float(np.max(m.geom_friction[objects.colliding, 0]))
    low, high = bottom + half_h + 0.005, max(bottom + half_h + 0.005, top - half_h)
    z_top = float(np.clip(min(com[2], bottom + 0.5 * lever / mu), low, high))
    back = float((pts @ u).min()) - 0.05
    target = set(int(g) for g in geoms)
    best = None  # ((not upright, above the tipping height, line index, height index), hit, line, z)
    n_out = np.zeros(3)
    heights = [(float(zc), False) for zc in (np.linspace(low, z_top, 5) if z_top > low + 1e-3 else [low])]
    heights += [(float(zc), True) for zc in np.linspace(z_top, high, 6)[1:] if high > z_top + 1e-3]  # legs missed below
    # lines: through the centre of mass, the middle of its extent, then across its extent nearest
    # the centre first (a table whose collision is only its legs has nothing on the middle lines)
    across = np.linspace(float(lat.min()) + half_w, float(lat.max()) - half_w, 7) if lat.max() - lat.min() > 2 * half_w else []
    lines = [float(com @ perp), float(np.median(lat))] + sorted((float(v) for v in across), key=lambda v: (abs(v - float(com @ perp)), v))
    for li, lv in enumerate(lines):
        for zi, (zc, above) in enumerate(heights):
            hits = []
            for dl in np.linspace(-half_w, half_w, 5):
                for dz in np.linspace(-half_h, half_h, 9):  # rows 1 cm apart: a thin table top falls between coarser ones
                    origin = back * u + (lv + dl) * perp + np.array([0.0, 0.0, zc + dz])
                    t = _cast(m, d, objects, origin, u, lambda g: g in target, cap=5.0, normal=n_out)
                    if np.isfinite(t):
                        hits.append((t, abs(float(n_out[2]))))
            if not hits:
                continue
            first = min(t for t, _ in hits)
            slope = max(nz for t, nz in hits if t < first + 0.005)
            key = (slope > UPRIGHT_NZ, above, li, zi)
            if best is None or key < best[0]:
                best = (key, first, lv, zc)
        if best is not None and not best[0][0] and not best[0][1]:
            break
    hit, line, z = (float("inf"), float(com @ perp), z_top) if best is None else best[1:]
    pusher_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, PUSHER)
    mocap = int(m.body_mocapid[pusher_body])
    pg = objects.pusher_geom
    m.geom_size[pg] = [PUSHER_HALF_THICKNESS_M, half_w, half_h]
    m.geom_aabb[pg] = [0.0, 0.0, 0.0, PUSHER_HALF_THICKNESS_M, half_w, half_h]
    m.geom_rbound[pg] = float(np.linalg.norm(m.geom_size[pg]))
    yaw = float(np.arctan2(u[1], u[0]))
    d.mocap_quat[mocap] = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
    saved = m.geom_conaffinity[geoms].copy()
    bodies = np.unique(m.geom_bodyid[geoms])
    saved_bodies = m.body_conaffinity[bodies].copy()
    m.geom_conaffinity[geoms] = saved | PUSHER_BIT
    m.body_conaffinity[bodies] = saved_bodies | PUSHER_BIT  # MuJoCo filters body pairs by these first

    base = {n: d.xpos[b].copy() for n, b in objects.root.items()}
    q_base = d.xquat[root].copy()
    moved = {n: 0.0 for n in objects.names}

    def track() -> None:
        for n, b in objects.root.items():
            moved[n] = max(moved[n], float(np.linalg.norm(d.xpos[b] - base[n])))

    travelled = 0.0
    try:
        if np.isfinite(hit):
            start = (back + hit - APPROACH_GAP_M - PUSHER_HALF_THICKNESS_M) * u + line * perp + np.array([0.0, 0.0, z])
            # The rays sample the paddle's face: a part of the object between them (a panel of
            # an open shelf) may still reach into it there. Back off until it touches nothing.
            backed = 0.0
            for _ in range(int(round(0.3 / APPROACH_GAP_M))):
                d.mocap_pos[mocap] = start
                mujoco.mj_kinematics(m, d)
                mujoco.mj_collision(m, d)
                if not (d.ncon and np.any(d.contact.geom[: d.ncon] == pg)):
                    break
                start = start - APPROACH_GAP_M * u
                backed += APPROACH_GAP_M
            dt = float(m.opt.timestep)
            step = speed_m_s * dt
            s, contact_at = 0.0, None
            limit = APPROACH_GAP_M + backed + 0.05 + travel_m  # give up if nothing is touched by then
            while s < limit and (contact_at is None or s - contact_at < travel_m):
                s += step
                d.mocap_pos[mocap] = start + s * u
                mujoco.mj_step(m, d)
                track()
                if contact_at is None and d.ncon and np.any(d.contact.geom[: d.ncon] == pg):
                    contact_at = s
            travelled = 0.0 if contact_at is None else s - contact_at
        d.mocap_pos[mocap] = [0.0, 0.0, -10.0]  # withdrawn
        _settle(m, d, POST_SETTLE_S, track)
    finally:
        m.geom_conaffinity[geoms] = saved
        m.body_conaffinity[bodies] = saved_bodies
    delta = d.xpos[root] - base[name]
    from layout.verify import TOPPLE_DEG, _tilt_deg

    tilt = _tilt_deg(q_base, d.xquat[root].copy())

    others = tuple((n, moved[n]) for n in objects.names if n != name and n not in riders)
    carried = tuple((n, float(np.linalg.norm((d.xpos[objects.root[n]] - base[n])[:2]))) for n in sorted(riders))
    return PushResult(
        name=name,
        direction_xy=(float(u[0]), float(u[1])),
        clearance_m=float(clearance),
        height_m=z,
        speed_m_s=float(speed_m_s),
        pusher_travel_m=float(travelled),
        displacement_m=float(np.linalg.norm(delta[:2])),
        along_m=float(delta[:2] @ u[:2]),
        tilt_deg=tilt,
        toppled=bool(tilt > TOPPLE_DEG),
        carried=carried,
        others=others,
        max_other_m=max([v for _, v in others], default=0.0),
    )


def joint_names(model) -> tuple[str, ...]:
    """Names of the articulation joints (hinge or slide, limited, named ``NAME/PART/joint``)."""
    import mujoco

    m = _as_model(model, False)
    kinds = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    return tuple(sorted(
        m.joint(j).name for j in range(m.njnt)
        if int(m.jnt_type[j]) in kinds and m.joint(j).name.endswith("/joint") and m.joint(j).name.count("/") >= 2 and m.jnt_limited[j]
    ))


def _subtree(m, body: int) -> list[int]:
    out = []
    for b in range(m.nbody):
        a = b
        while a > 0 and a != body:
            a = int(m.body_parentid[a])
        if a == body:
            out.append(b)
    return out


def _handle_local(m, d, objects: _Objects, jid: int, body: int, kind: str) -> np.ndarray:
    """The pull point in the part's body frame: its handle's centre of mass, else (hinge) the
    middle of its edge farthest from the axis, else (slide) its centre of mass."""
    rot, pos = d.xmat[body].reshape(3, 3), d.xpos[body]
    handles = [b for b in _subtree(m, body) if b != body and "handle" in m.body(b).name.rsplit("/", 1)[-1]]
    if handles:
        p = d.xipos[sorted(handles, key=lambda b: m.body(b).name)[0]]
    elif kind == "hinge":
        geoms = np.flatnonzero((m.geom_bodyid == body) & objects.colliding)
        pts = _points(m, d, geoms) if len(geoms) else d.xipos[body][None]
        a, anchor = d.xaxis[jid], d.xanchor[jid]
        r = pts - anchor
        dist = np.linalg.norm(r - np.outer(r @ a, a), axis=1)
        p = pts[dist >= 0.95 * dist.max()].mean(axis=0)
    else:
        p = d.xipos[body]
    return rot.T @ (np.asarray(p) - pos)


def _pull_force(m, d, jid: int, body: int, kind: str, p: np.ndarray) -> float:
    """PULL_N, or 1.5 x what the joint's friction and the part's weight resist at the pull point."""
    a = d.xaxis[jid]
    weight = float(m.body_subtreemass[body]) * 9.81
    friction = float(m.dof_frictionloss[int(m.jnt_dofadr[jid])])
    if kind == "slide":
        need = friction + weight * abs(float(a[2]))
    else:
        r = p - d.xanchor[jid]
        lever = max(float(np.linalg.norm(r - (r @ a) * a)), 1e-3)
        rc = d.subtree_com[body] - d.xanchor[jid]
        com_lever = float(np.linalg.norm(rc - (rc @ a) * a))
        need = (friction + weight * com_lever * float(np.sqrt(max(0.0, 1.0 - a[2] ** 2)))) / lever
    return max(PULL_N, 1.5 * need)


def open_joint(model, joint: str, force_n: float | None = None, pull_s: float = PULL_S, release_s: float = RELEASE_S) -> JointProbe:
    """Pull articulation ``joint`` (``NAME/PART/joint``) of ``model`` (a scene.xml path or an
    MjModel) open for ``pull_s`` seconds, release it for ``release_s``, and measure its motion
    (:class:`~scene_builder.model.JointProbe`). ``force_n`` defaults to :func:`_pull_force`."""
    import mujoco

    m, d = _settled(model, False)
    jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint)
    if jid < 0:
        raise InputError(f"interaction probe: no joint {joint!r} in the model (articulation joints: {', '.join(joint_names(m)) or 'none'})")
    jt = int(m.jnt_type[jid])
    kind = {int(mujoco.mjtJoint.mjJNT_HINGE): "hinge", int(mujoco.mjtJoint.mjJNT_SLIDE): "slide"}.get(jt)
    if kind is None or not m.jnt_limited[jid]:
        raise InputError(f"interaction probe: joint {joint!r} is not a limited hinge or slide joint")
    objects = _Objects(m)
    body = int(m.jnt_bodyid[jid])
    root = int(m.body_rootid[body])
    lo, hi = (float(v) for v in m.jnt_range[jid])
    adr, dof = int(m.jnt_qposadr[jid]), int(m.jnt_dofadr[jid])
    q0 = float(d.qpos[adr])
    sign = 1.0 if hi - q0 >= q0 - lo else -1.0
    local = _handle_local(m, d, objects, jid, body, kind)
    p0 = d.xpos[body] + d.xmat[body].reshape(3, 3) @ local
    force = float(force_n) if force_n is not None else _pull_force(m, d, jid, body, kind, p0)
    vcap = PULL_SPEED[kind]
    base = d.xpos[root].copy()
    times, qs, carcass = [float(d.time)], [q0], [0.0]

    def record() -> None:
        times.append(float(d.time))
        qs.append(float(d.qpos[adr]))
        carcass.append(float(np.linalg.norm(d.xpos[root] - base)))

    def pull() -> None:
        p = d.xpos[body] + d.xmat[body].reshape(3, 3) @ local
        if kind == "slide":
            direction = sign * d.xaxis[jid]
        else:
            r = p - d.xanchor[jid]
            t = np.cross(d.xaxis[jid], r)
            direction = sign * t / max(float(np.linalg.norm(t)), 1e-9)
        v = sign * float(d.qvel[dof])
        f = force * float(np.clip(2.0 * (1.0 - v / vcap), 0.0, 1.0)) * direction
        d.xfrc_applied[body, :3] = f
        d.xfrc_applied[body, 3:] = np.cross(p - d.xipos[body], f)

    steps = int(round(pull_s / float(m.opt.timestep)))
    for _ in range(steps):
        pull()
        mujoco.mj_step(m, d)
        record()
    n_pull = len(qs)
    d.xfrc_applied[body] = 0.0
    _settle(m, d, release_s, record)
    q = np.array(qs)
    s = sign * q[:n_pull]
    far = hi if sign > 0 else lo
    span = abs(far - q0)
    travel = float(s[-1] - sign * q0)
    return JointProbe(
        joint=joint,
        object=joint.split("/")[0],
        kind=kind,
        range=(lo, hi),
        start=q0,
        open_sign=sign,
        force_n=force,
        travel=travel,
        open_fraction=travel / span if span > 0 else 0.0,
        backtrack=float(np.max(np.maximum.accumulate(s) - s)),
        limit_violation=float(max(0.0, np.max(lo - q), np.max(q - hi))),
        final=float(q[-1]),
        body_displacement_m=float(max(carcass)),
        times_s=np.array(times),
        positions=q,
    )


def interaction_problems(pushes: tuple[PushResult, ...] = (), joints: tuple[JointProbe, ...] = ()) -> tuple[str, ...]:
    """One line per probe that misses the bar: a push moves its object PUSH_MOVE_M (2-10 cm)
    tilting it at most PUSH_TILT_MAX_DEG (10 deg) while every other object moves under OTHERS_MAX_M (1 cm); a joint opens at
    least OPEN_MIN_FRACTION of its range without backtracking, stays within its range
    (LIMIT_TOLERANCE) and its carcass moves under CARCASS_MAX_M (1 cm)."""
    out = []
    for p in pushes:
        if p.pusher_travel_m <= 0.0:
            out.append(f"push {p.name}: the pusher never touched it")
        elif not PUSH_MOVE_M[0] <= p.displacement_m <= PUSH_MOVE_M[1]:
            out.append(f"push {p.name}: moved {p.displacement_m * 100:.1f} cm (expected {PUSH_MOVE_M[0] * 100:.0f}-{PUSH_MOVE_M[1] * 100:.0f} cm)")
        if p.toppled or p.tilt_deg > PUSH_TILT_MAX_DEG:
            out.append(f"push {p.name}: {'toppled' if p.toppled else 'tilted'} ({p.tilt_deg:.0f} deg)")
        if p.max_other_m >= OTHERS_MAX_M:
            n, v = max(p.others, key=lambda o: o[1])
            out.append(f"push {p.name}: {n} moved {v * 100:.1f} cm too")
    for j in joints:
        unit = lambda v, k=j.kind: _joint_unit(k, v)  # noqa: E731
        if j.open_fraction < OPEN_MIN_FRACTION:
            out.append(f"open {j.joint}: opened {unit(j.travel)} ({j.open_fraction:.0%} of its range)")
        if j.backtrack > BACKTRACK_TOLERANCE[j.kind]:
            out.append(f"open {j.joint}: went back {unit(j.backtrack)} while pulled")
        if j.limit_violation > LIMIT_TOLERANCE[j.kind]:
            out.append(f"open {j.joint}: {unit(j.limit_violation)} beyond its range")
        if j.body_displacement_m >= CARCASS_MAX_M:
            out.append(f"open {j.joint}: {j.object} moved {j.body_displacement_m * 100:.1f} cm")
    return tuple(out)


def probe_scene(mjcf_path: Path) -> tuple[tuple[PushPlan, ...], tuple[PushResult, ...], tuple[JointProbe, ...]]:
    """Every probe of a scene: the push plan of each free object, a push of each pushable one,
    and every articulation joint pulled open."""
    m = load_probe_model(mjcf_path)
    plans = plan_push(m)
    pushes = tuple(push_object(m, p.name, p.direction_xy) for p in plans if p.pushable)
    joints = tuple(open_joint(m, j) for j in joint_names(m))
    return plans, pushes, joints


def _joint_unit(kind: str, v: float) -> str:
    return f"{np.degrees(v):.1f} deg" if kind == "hinge" else f"{v * 100:.1f} cm"


def probe_lines(plans: tuple[PushPlan, ...], pushes: tuple[PushResult, ...], joints: tuple[JointProbe, ...]) -> tuple[str, ...]:
    """One human-readable line per probe (what ``scene-builder check --interact`` prints)."""
    out = [f"push {p.name}: not pushable: {p.reason}" for p in plans if not p.pushable]
    for r in pushes:
        carried = f"; carried {', '.join(n for n, _ in r.carried)}" if r.carried else ""
        out.append(
            f"push {r.name}: moved {r.displacement_m * 100:.1f} cm ({r.along_m * 100:.1f} cm along "
            f"({r.direction_xy[0]:+.2f}, {r.direction_xy[1]:+.2f}), {r.clearance_m * 100:.0f} cm free ahead), tilt {r.tilt_deg:.1f} deg, "
            f"others at most {r.max_other_m * 1000:.1f} mm{carried}"
        )
    for j in joints:
        out.append(
            f"open {j.joint}: {j.kind} opened {_joint_unit(j.kind, j.travel)} of {_joint_unit(j.kind, abs(j.range[1] - j.range[0]))} "
            f"({j.open_fraction:.0%}) under {j.force_n:.0f} N, {_joint_unit(j.kind, j.limit_violation)} beyond its range, "
            f"{j.object} moved {j.body_displacement_m * 1000:.1f} mm"
        )
    return tuple(out)
