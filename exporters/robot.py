"""The robot (``Scene.robot``) as the exporters write it: its own MJCF, attached with MjSpec.

The robot's model is read from its file (Menagerie's or the built-in one), its mesh and texture
files are copied beside the scene's (``meshes/robot/``, ``textures/robot/``) so the output folder
stands alone, and it is attached at its placement under a frame with the prefix ``robot/``: its
bodies, joints, actuators, sensors and keyframes keep their names behind that prefix (Menagerie's
``home`` becomes the scene keyframe ``robot/home``, the rest of the scene at its start pose).
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from exporters.textures import TEXTURE_DIR
from scene_builder.errors import ExportError
from scene_builder.model import TriangleMesh
from scene_builder.robot import RobotPlacement

PREFIX = "robot/"
MESH_DIR = "meshes"
SUBDIR = "robot"


def _copy(src: Path, dst: Path) -> None:
    if not src.is_file():
        raise ExportError(f"robot model file {src} is missing; clear the Menagerie cache (MENAGERIE_CACHE_DIR) and build again")
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, dst)


def _rel(name: str) -> str:
    """A file name from the robot's MJCF as a relative path below ``robot/`` (no ``..``)."""
    parts = [p for p in Path(name).parts if p not in ("", ".", "..", "/")]
    if not parts:
        raise ExportError(f"robot model names an empty file {name!r}")
    return "/".join([SUBDIR, *parts])


def robot_child_spec(placement: RobotPlacement, out_dir: Path):
    """The robot's ``MjSpec`` with its files copied under ``out_dir`` and paths rewritten to
    resolve against the scene's ``meshes/`` and ``textures/`` folders."""
    import mujoco

    src = Path(placement.model.mjcf_path)
    try:
        child = mujoco.MjSpec.from_file(str(src))
    except ValueError as err:
        raise ExportError(f"MuJoCo cannot read the robot model {src}: {str(err).strip().splitlines()[0]}") from err
    base = src.parent
    for assets, folder, out_folder in ((child.meshes, child.meshdir, MESH_DIR), (child.textures, child.texturedir, TEXTURE_DIR)):
        root = base / folder if folder else base
        for asset in assets:
            if asset.file:
                rel = _rel(asset.file)
                _copy(root / asset.file, Path(out_dir) / out_folder / rel)
                asset.file = rel
    if len(child.hfields) or len(child.skins):
        raise ExportError(f"robot model {src.name} uses height fields or skins, which the scene export does not carry")
    child.meshdir, child.texturedir = MESH_DIR, TEXTURE_DIR
    child.nkey = 0  # the size hint of a written file; the scene's keyframes are sized by the compiler
    child.modelfiledir = str(Path(out_dir).resolve())
    return child


def attach_robot(spec, placement: RobotPlacement, out_dir: Path) -> None:
    """Attach the robot to ``spec``'s world body at ``placement`` with the prefix ``robot/``."""
    child = robot_child_spec(placement, out_dir)
    yaw = float(placement.yaw_rad)
    frame = spec.worldbody.add_frame(pos=placement.position_m.tolist(), quat=[float(np.cos(yaw / 2)), 0.0, 0.0, float(np.sin(yaw / 2))])
    spec.attach(child, prefix=PREFIX, frame=frame)


# ---------------------------------------------------------------------------------------------
# The robot's own compiled model, as the USD and SDF writers read it
# ---------------------------------------------------------------------------------------------


def compiled_robot(placement: RobotPlacement, target: str):
    """(model, data at qpos0 after kinematics) of the robot's own MJCF; ``target`` names the
    export in the error when MuJoCo cannot load it."""
    import mujoco

    try:
        m = mujoco.MjModel.from_xml_path(str(placement.model.mjcf_path))
    except ValueError as err:
        raise ExportError(f"{target} export: MuJoCo cannot load the robot model: {str(err).strip().splitlines()[0]}") from err
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    return m, d


def quat_matrix(q: np.ndarray) -> np.ndarray:
    """(3, 3) rotation of a MuJoCo quaternion (w, x, y, z)."""
    import mujoco

    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, np.asarray(q, dtype=np.float64))
    return out.reshape(3, 3)


def position_drives(m) -> dict[int, tuple[float, float, float, float]]:
    """joint id -> (kp, kv, max force (0: none), target at zero control) of its position
    actuator (an affine-bias actuator: force = gain ctrl + b0 + b1 q + b2 dq/dt, so kp = -b1,
    kv = -b2, and the target is where the force vanishes with the control clamped to its
    range); joints coupled to a driven one by an equality (the second finger) get the same.

    A position actuator on a fixed tendon (Menagerie's Panda splits its gripper force between
    the fingers with one) drives each of the tendon's joints: with the tendon length
    L = sum(c_i q_i) and the joints moving together (as the equality holds them), joint j
    feels c_j * (-kp L - kv dL/dt) = -(kp c_j S) q - (kv c_j S) dq/dt with S = sum(c_i), so its
    drive is kp c_j S, kv c_j S, the force limit times |c_j|. A spatial tendon is not a joint
    drive and is left out."""
    import mujoco

    out = {}
    for a in range(m.nu):
        if int(m.actuator_biastype[a]) != int(mujoco.mjtBias.mjBIAS_AFFINE):
            continue
        trn = int(m.actuator_trntype[a])
        if trn == int(mujoco.mjtTrn.mjTRN_JOINT):
            coefs = {int(m.actuator_trnid[a, 0]): 1.0}
        elif trn == int(mujoco.mjtTrn.mjTRN_TENDON):
            t = int(m.actuator_trnid[a, 0])
            wraps = range(int(m.tendon_adr[t]), int(m.tendon_adr[t]) + int(m.tendon_num[t]))
            if any(int(m.wrap_type[w]) != int(mujoco.mjtWrap.mjWRAP_JOINT) for w in wraps):
                continue
            coefs = {int(m.wrap_objid[w]): float(m.wrap_prm[w]) for w in wraps}
        else:
            continue
        kp, kv = -float(m.actuator_biasprm[a, 1]), -float(m.actuator_biasprm[a, 2])
        force = float(np.max(np.abs(m.actuator_forcerange[a]))) if m.actuator_forcelimited[a] else 0.0
        total = sum(coefs.values())
        if kp <= 0.0 or total == 0.0:
            continue
        # the length (or position) it holds at zero control, the control clamped to its range
        ctrl = float(np.clip(0.0, *m.actuator_ctrlrange[a])) if m.actuator_ctrllimited[a] else 0.0
        held = (float(m.actuator_gainprm[a, 0]) * ctrl + float(m.actuator_biasprm[a, 0])) / kp
        for j, c in coefs.items():
            out[j] = (kp * c * total, kv * c * total, force * abs(c), held / total)
    for e in range(m.neq):
        if int(m.eq_type[e]) == int(mujoco.mjtEq.mjEQ_JOINT):
            j1, j2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
            if j1 in out and j2 not in out:
                out[j2] = out[j1]
    return out


# ---------------------------------------------------------------------------------------------
# The robot's look as triangle meshes, for the exports that only show it (rerun, glTF)
# ---------------------------------------------------------------------------------------------

#: Segments around a tessellated capsule, cylinder or sphere: at most 0.5 % of the radius off
#: the true surface (1 - cos(pi / 32)).
ROUND_SEGMENTS = 32


@dataclass(frozen=True, eq=False)
class RobotMesh:
    """One geom of the robot as a triangle mesh in the world, at the start pose (qpos0, the pose
    scene.xml and scene.usda start in) moved to the placement.

    name: ``BODY/geom_K`` (BODY the robot's body name, K the geom's index within the body).
    mesh: the triangles, world frame (no colours of its own).
    rgba: (4,) in [0, 1], the geom's material colour (its own colour without a material).
    """

    name: str
    mesh: TriangleMesh
    rgba: np.ndarray


def _geom_local_mesh(m, g: int):
    """(vertices, faces) of geom ``g`` in its own frame (MuJoCo's compiled size and mesh)."""
    import mujoco
    import trimesh

    t, size = int(m.geom_type[g]), m.geom_size[g]
    if t == int(mujoco.mjtGeom.mjGEOM_MESH):
        k = int(m.geom_dataid[g])
        va, vn = int(m.mesh_vertadr[k]), int(m.mesh_vertnum[k])
        fa, fn = int(m.mesh_faceadr[k]), int(m.mesh_facenum[k])
        return np.array(m.mesh_vert[va : va + vn], np.float64), np.array(m.mesh_face[fa : fa + fn], np.int32)
    if t == int(mujoco.mjtGeom.mjGEOM_BOX):
        shape = trimesh.creation.box(extents=2.0 * size)
    elif t == int(mujoco.mjtGeom.mjGEOM_CAPSULE):  # trimesh's height: between the two sphere centres
        shape = trimesh.creation.capsule(height=2.0 * size[1], radius=size[0], count=[ROUND_SEGMENTS, ROUND_SEGMENTS])
    elif t == int(mujoco.mjtGeom.mjGEOM_CYLINDER):
        shape = trimesh.creation.cylinder(radius=size[0], height=2.0 * size[1], sections=ROUND_SEGMENTS)
    elif t in (int(mujoco.mjtGeom.mjGEOM_SPHERE), int(mujoco.mjtGeom.mjGEOM_ELLIPSOID)):
        radii = size if t == int(mujoco.mjtGeom.mjGEOM_ELLIPSOID) else np.full(3, size[0])
        shape = trimesh.creation.uv_sphere(radius=1.0, count=[ROUND_SEGMENTS, ROUND_SEGMENTS])
        shape.apply_scale(radii)
    else:
        raise ExportError(f"robot geom {m.geom(g).name or g} is of a type (MuJoCo {t}) that cannot be drawn as a mesh")
    return np.asarray(shape.vertices, np.float64), np.asarray(shape.faces, np.int32)


def robot_meshes(placement: RobotPlacement, target: str) -> tuple[RobotMesh, ...]:
    """The robot's look as world meshes (see :class:`RobotMesh`): each body's visual geoms (those
    that collide with nothing, Menagerie's ``visual`` class), or its collision geoms where it has
    no visual one (the built-in models). ``target`` names the export in errors."""
    import mujoco

    m, d = compiled_robot(placement, target)
    world = placement.world_from_robot
    out = []
    for b in range(m.nbody):
        first = int(m.body_geomadr[b])
        geoms = [g for g in range(first, first + int(m.body_geomnum[b])) if int(m.geom_type[g]) != int(mujoco.mjtGeom.mjGEOM_PLANE)]
        visual = [g for g in geoms if m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0]
        for g in visual or geoms:
            v, f = _geom_local_mesh(m, g)
            rot = world[:3, :3] @ d.geom_xmat[g].reshape(3, 3)
            pos = world[:3, :3] @ d.geom_xpos[g] + world[:3, 3]
            mat = int(m.geom_matid[g])
            rgba = m.mat_rgba[mat] if mat >= 0 else m.geom_rgba[g]
            body = m.body(b).name or f"body_{b}"
            out.append(RobotMesh(f"{body}/geom_{g - first}", TriangleMesh(v @ rot.T + pos, f), np.array(rgba, np.float64)))
    return tuple(out)

