"""What the interaction probes share: the scene compiled with the pusher, its free objects, the
settle, geometry queries (points of geoms, rays through the collision geometry).

The model is ``scene.xml`` as written (naming conventions of DEVELOPERS.md: root body ``NAME``
with free joint ``NAME/free``, articulation joints ``NAME/PART/joint``, collision geoms in group
3) plus one body added by :func:`load_probe_model`, never written to the file: the pusher
``probe/pusher``, a box paddle on three slide joints (``probe/pusher/push`` along the body's +x,
``/side`` along +y, ``/lift`` along +z) driven by position servos whose force is limited to
``PUSHER_FORCE_N``; it collides with everything (objects, fixed furniture, walls, floor,
background) and is compensated for gravity. Between pushes it is parked ``PARK_Z_M`` above the
scene, where it touches nothing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scene_builder.errors import ExportError, InputError

PUSHER = "probe/pusher"
PUSHER_JOINTS = ("push", "side", "lift")  # slide joints along the pusher body's x, y, z
#: The pusher's force limit, on each of its joints: about what one arm of a person pushes a piece
#: of furniture with, and more than a light arm's wrist bears (a Franka Panda carries 3 kg). An
#: object that needs more to slide (a loaded wardrobe on the floor) is a failure a robot meets too.
PUSHER_FORCE_N = 100.0
#: Position-servo stiffness: the 100 N limit is reached 5 mm behind the commanded position.
PUSHER_KP_N_M = 20000.0
#: About what an arm's hand and forearm weigh; with it the critically damped servo (MuJoCo's
#: dampratio 1) has a 63 ms period, 31 steps of the scenes' 2 ms timestep.
PUSHER_MASS_KG = 2.0
PUSHER_HALF_THICKNESS_M = 0.01
PUSHER_FRICTION = 0.3
PARK_Z_M = 50.0
PRE_SETTLE_S = 0.5
RIDER_NORMAL_Z = 0.7  # a contact whose normal is within ~45 deg of vertical is resting contact


def load_probe_model(mjcf_path: Path):
    """The MJCF at ``mjcf_path`` compiled with the pusher (see the module docstring)."""
    import mujoco

    mjcf_path = Path(mjcf_path)
    if not mjcf_path.is_file():
        raise InputError(f"interaction probe: {mjcf_path} does not exist; pass the scene.xml of a built scene")
    try:
        spec = mujoco.MjSpec.from_file(str(mjcf_path))
        body = spec.worldbody.add_body(name=PUSHER, pos=[0.0, 0.0, PARK_Z_M], gravcomp=1.0, mass=PUSHER_MASS_KG,
                                       inertia=[1e-3, 1e-3, 1e-3], explicitinertial=True)
        for name, axis in zip(PUSHER_JOINTS, np.eye(3)):
            body.add_joint(name=f"{PUSHER}/{name}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis.tolist())
            act = spec.add_actuator(name=f"{PUSHER}/{name}", target=f"{PUSHER}/{name}", trntype=mujoco.mjtTrn.mjTRN_JOINT)
            act.set_to_position(kp=PUSHER_KP_N_M, dampratio=1.0)
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
            act.forcerange = [-PUSHER_FORCE_N, PUSHER_FORCE_N]
        body.add_geom(name=PUSHER, type=mujoco.mjtGeom.mjGEOM_BOX, size=[PUSHER_HALF_THICKNESS_M, 0.03, 0.03],
                      contype=1, conaffinity=1, group=3, friction=[PUSHER_FRICTION, 0.005, 0.0001], condim=3,
                      rgba=[0.2, 0.8, 0.2, 1.0], density=0.0)
        for key in spec.keys:  # a keyframe (the robot's home) covers the pusher's joints too, at rest
            if len(key.qpos):
                key.qpos = list(key.qpos) + [0.0] * len(PUSHER_JOINTS)
            if len(key.qvel):
                key.qvel = list(key.qvel) + [0.0] * len(PUSHER_JOINTS)
            if len(key.ctrl):
                key.ctrl = list(key.ctrl) + [0.0] * len(PUSHER_JOINTS)
            if len(key.act):
                key.act = list(key.act) + [0.0] * len(PUSHER_JOINTS)
        return spec.compile()
    except ValueError as err:
        raise ExportError(f"interaction probe: MuJoCo cannot load {mjcf_path.name}: {str(err).splitlines()[0]}") from err


def as_model(model, with_pusher: bool):
    """``model`` as an MjModel: a compiled model (with the pusher when ``with_pusher``) or a
    scene.xml path, compiled (with the pusher when ``with_pusher``)."""
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


class Objects:
    """Movable objects of the model: rigid ones (root body ``NAME`` with free joint ``NAME/free``;
    every body and colliding geom of each) and soft ones (a flex ``NAME`` whose vertices are
    bodies on three world-aligned slide joints); who owns each geom and flex (:meth:`owner`)."""

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
        self.flex: dict[str, int] = {}
        self.flex_qpos: dict[str, np.ndarray] = {}  # (V, 3) qpos addresses of each vertex's x, y, z slides
        vertex_body = np.zeros(m.nbody, dtype=bool)
        for f in range(m.nflex):
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_FLEX, f)
            if not name:
                continue
            bodies = m.flex_vertbodyid[int(m.flex_vertadr[f]) : int(m.flex_vertadr[f]) + int(m.flex_vertnum[f])]
            adr = []
            for b in bodies:
                j0, nj = int(m.body_jntadr[b]), int(m.body_jntnum[b])
                axes = [m.jnt_axis[j] for j in range(j0, j0 + nj)] if j0 >= 0 else []
                if nj != 3 or not np.allclose(np.abs(np.array(axes)), np.eye(3)) or not np.allclose(m.body_quat[b], [1, 0, 0, 0]):
                    break  # not free-moving vertices on world-aligned slides: not a movable soft body
                adr.append([int(m.jnt_qposadr[j0 + int(np.argmax(np.abs(axes[k])))]) for k in range(3)])
            else:
                self.flex[name] = f
                self.flex_qpos[name] = np.array(adr, dtype=int).reshape(-1, 3)
                vertex_body[bodies] = True
        by_root = {b: n for n, b in self.root.items()}
        self.body_object = [by_root.get(int(m.body_rootid[b]), "") for b in range(m.nbody)]
        colliding = (m.geom_contype != 0) | (m.geom_conaffinity != 0)
        pusher = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, PUSHER)
        self.pusher_geom = pusher
        self.geom_object = np.array([self.body_object[int(m.geom_bodyid[g])] for g in range(m.ngeom)], dtype=object)
        self.colliding = colliding.copy()
        if pusher >= 0:
            self.colliding[pusher] = False
        self.rigid = sorted(self.root)
        self.names = sorted(self.root) + sorted(self.flex)  # rigid first, then soft
        self.groups = np.zeros(6, dtype=np.uint8)  # geom groups that hold colliding geoms (for rays)
        for g in np.flatnonzero(self.colliding):
            if 0 <= int(m.geom_group[g]) < 6:
                self.groups[int(m.geom_group[g])] = 1
        owners = [self._owner_of(m, g) for g in range(m.ngeom)]
        flex_owner = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_FLEX, f) or f"flex {f}" for f in range(m.nflex)]
        self.owners = sorted(set(owners) | set(flex_owner))
        index = {n: k for k, n in enumerate(self.owners)}
        self.geom_owner = np.array([index[n] for n in owners], dtype=int)
        self.flex_owner = np.array([index[n] for n in flex_owner], dtype=int)
        self.index = index
        self._m_vertadr, self._m_vertnum = m.flex_vertadr.copy(), m.flex_vertnum.copy()
        self._m_qposadr = {n: int(m.jnt_qposadr[int(m.body_jntadr[b])]) for n, b in self.root.items()}

    def _owner_of(self, m, g: int) -> str:
        if self.geom_object[g]:
            return str(self.geom_object[g])
        root = int(m.body_rootid[int(m.geom_bodyid[g])])
        if root > 0:  # fixed furniture (its root body is NAME), the robot (robot/...), the pusher
            name = m.body(root).name
            return "robot" if name.startswith("robot/") else name
        name = m.geom(g).name
        return "background" if name.startswith("background/") else (name or f"geom {g}")

    def owner(self, g: int) -> str:
        """What geom ``g`` belongs to: a free object's name, fixed furniture's, ``robot``, the
        pusher, ``floor``, ``wall_i`` or ``background``."""
        return self.owners[int(self.geom_owner[int(g)])]

    def contact_owners(self, d) -> np.ndarray:
        """(ncon, 2) index into ``owners`` of each side of each contact (a geom's or a flex's)."""
        n = d.ncon
        g = d.contact.geom[:n]
        f = d.contact.flex[:n]
        return np.where(g >= 0, self.geom_owner[np.maximum(g, 0)], self.flex_owner[np.maximum(f, 0)] if len(self.flex_owner) else -1)

    def geoms(self, name: str) -> np.ndarray:
        return np.flatnonzero((self.geom_object == name) & self.colliding)

    def vertices(self, d, name: str) -> np.ndarray:
        """(V, 3) world positions of soft object ``name``'s vertices."""
        f = self.flex[name]
        return d.flexvert_xpos[int(self._m_vertadr[f]) : int(self._m_vertadr[f]) + int(self._m_vertnum[f])]

    def mass(self, m, name: str) -> float:
        """Mass (kg) of object ``name``: its bodies', or a soft body's vertices'."""
        if name in self.root:
            return float(m.body_subtreemass[self.root[name]])
        f = self.flex[name]
        return float(m.body_mass[m.flex_vertbodyid[int(m.flex_vertadr[f]) : int(m.flex_vertadr[f]) + int(m.flex_vertnum[f])]].sum())

    def position(self, d, name: str) -> np.ndarray:
        """Where object ``name`` is: its root body's origin, or a soft body's vertex centroid."""
        return d.xpos[self.root[name]].copy() if name in self.root else self.vertices(d, name).mean(axis=0)

    def shift(self, d_to, d_from, names, offset_xy) -> None:
        """``d_to.qpos``: ``d_from``'s with the objects ``names`` moved by ``offset_xy``."""
        for n in names:
            if n in self.root:
                a = int(self._m_qposadr[n])
                d_to.qpos[a : a + 2] = d_from.qpos[a : a + 2] + offset_xy
            else:
                q = self.flex_qpos[n]
                d_to.qpos[q[:, 0]] = d_from.qpos[q[:, 0]] + offset_xy[0]
                d_to.qpos[q[:, 1]] = d_from.qpos[q[:, 1]] + offset_xy[1]


def settle(m, d, seconds: float, on_step=None) -> None:
    import mujoco

    for _ in range(int(round(seconds / float(m.opt.timestep)))):
        mujoco.mj_step(m, d)
        if on_step is not None:
            on_step()
    if not np.all(np.isfinite(d.qpos)):
        raise ExportError("interaction probe: the simulation diverged (NaN state); check masses, inertias and contact settings")


def settled(model, with_pusher: bool):
    """(model, data) after PRE_SETTLE_S of settling from the robot's home keyframe when the
    scene has a robot (its servos hold that pose), else from the model's rest pose."""
    import mujoco

    m = as_model(model, with_pusher)
    d = mujoco.MjData(m)
    key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "robot/home")
    if key >= 0:
        mujoco.mj_resetDataKeyframe(m, d, key)
    mujoco.mj_forward(m, d)
    settle(m, d, PRE_SETTLE_S)
    mujoco.mj_forward(m, d)
    return m, d


def points(m, d, geoms: np.ndarray) -> np.ndarray:
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


def cast(m, d, objects: Objects, pnt, vec, accept, cap: float, normal: np.ndarray | None = None) -> float:
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
        if g >= 0 and objects.colliding[g] and accept(g):  # -1: a flex, which rays pass
            return gone + dist
        step = dist + 1e-4
        gone += step
        p = p + step * vec
    return float("inf")
