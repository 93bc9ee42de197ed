"""The robot (``Scene.robot``) in ``scene.sdf``: a model ``robot`` with links, joints and
position controllers, written from the robot's compiled MJCF (the file as loaded, Menagerie's or
the built-in one) at its start pose (qpos0), placed at the placement's pose:

* one link per body, posed in the model frame, with its inertial as MuJoCo compiled it (mass,
  centre of mass, principal moments along the inertial pose's axes); its geoms as visuals and,
  those that collide, collisions: sphere, capsule, cylinder, box, and meshes written as .obj
  files of the compiled vertices (``meshes/robot_*.obj``; MuJoCo collides a mesh as its convex
  hull);
* a body's joint as a ``revolute`` / ``prismatic`` joint (pose and axis in the child link's
  frame, limits, damping, dry friction, the effort of its actuator); a body with several joints
  (the planar x, y, yaw base) through 1 g links, one joint each; a base without a joint welded to
  ``world``;
* every joint driven by a MuJoCo position actuator gets Gazebo's joint position controller
  (``gz-sim-joint-position-controller-system``) with the actuator's stiffness as P gain, its
  damping as D gain, its force range and the start target; a joint that an equality couples to a
  driven one (the second finger) gets the same controller, since SDFormat 1.9 has no mimic joint.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from exporters import names
from exporters.mjcf import MESH_DIR
from exporters.robot import compiled_robot, position_drives, quat_matrix
from exporters.sdf_xml import fmt as _fmt, sub as _sub
from exporters.urdf import rpy_from_matrix
from scene_builder.errors import ExportError
from scene_builder.robot import RobotPlacement

MODEL_NAME = "robot"
#: Mass of the links between the joints of a body with several (kg), as the scene's slide links.
CHAIN_LINK_MASS_KG = 0.001
POSITION_CONTROLLER = ("gz-sim-joint-position-controller-system", "gz::sim::systems::JointPositionController")


def _pose(parent: ET.Element, pos, rot: np.ndarray) -> None:
    _sub(parent, "pose", _fmt(np.concatenate([np.asarray(pos, float), rpy_from_matrix(rot)])))


def robot_mass_kg(m) -> float:
    """Mass of the robot's links as written: every body's (at least 1 mg, as SDFormat needs a
    positive one) plus the chain links of bodies with several joints."""
    return float(sum(max(float(m.body_mass[b]), 1e-6) for b in range(1, m.nbody))
                 + CHAIN_LINK_MASS_KG * sum(max(int(m.body_jntnum[b]) - 1, 0) for b in range(1, m.nbody)))


def _geometry(parent: ET.Element, m, g: int, out_dir: Path, mesh_files: dict[int, str]) -> None:
    import mujoco

    t, size = int(m.geom_type[g]), m.geom_size[g]
    geometry = _sub(parent, "geometry")
    if t == int(mujoco.mjtGeom.mjGEOM_SPHERE):
        _sub(_sub(geometry, "sphere"), "radius", size[0])
    elif t in (int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_CYLINDER)):
        shape = _sub(geometry, "capsule" if t == int(mujoco.mjtGeom.mjGEOM_CAPSULE) else "cylinder")
        _sub(shape, "radius", size[0])
        _sub(shape, "length", 2.0 * size[1])
    elif t == int(mujoco.mjtGeom.mjGEOM_BOX):
        _sub(_sub(geometry, "box"), "size", 2.0 * size)
    elif t == int(mujoco.mjtGeom.mjGEOM_MESH):
        k = int(m.geom_dataid[g])
        if k not in mesh_files:
            va, vn = int(m.mesh_vertadr[k]), int(m.mesh_vertnum[k])
            fa, fn = int(m.mesh_faceadr[k]), int(m.mesh_facenum[k])
            fname = f"{MESH_DIR}/robot_{names.file_stem(m.mesh(k).name or f'mesh_{k}')}_{k}.obj"
            lines = [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in m.mesh_vert[va : va + vn]]
            lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in m.mesh_face[fa : fa + fn]]
            (out_dir / fname).parent.mkdir(parents=True, exist_ok=True)
            (out_dir / fname).write_text("\n".join(lines) + "\n")
            mesh_files[k] = fname
        _sub(_sub(geometry, "mesh"), "uri", mesh_files[k])
    else:
        raise ExportError(f"robot geom {m.geom(g).name or g} is of a type (MuJoCo {t}) the SDF export does not write")


def add_robot(world: ET.Element, placement: RobotPlacement, out_dir: Path) -> ET.Element:
    """Write the robot as the model MODEL_NAME into ``world`` (see the module docstring); its
    mesh files go to ``out_dir/meshes``. Returns the model element."""
    m, d = compiled_robot(placement, "SDF")
    model = _sub(world, "model", name=MODEL_NAME)
    t = placement.world_from_robot
    _pose(model, t[:3, 3], t[:3, :3])
    unique = names.UniqueNames()
    link_of = {b: unique(names.valid_identifier(m.body(b).name or f"body_{b}").strip("_") or f"body_{b}") for b in range(1, m.nbody)}
    mesh_files: dict[int, str] = {}
    for b in range(1, m.nbody):
        link = _sub(model, "link", name=link_of[b])
        _pose(link, d.xpos[b], d.xmat[b].reshape(3, 3))
        inertial = _sub(link, "inertial")
        _pose(inertial, m.body_ipos[b], quat_matrix(m.body_iquat[b]))
        _sub(inertial, "mass", f"{max(float(m.body_mass[b]), 1e-6):.9g}")
        moments = np.maximum(m.body_inertia[b], 1e-9)
        tensor = _sub(inertial, "inertia")
        for tag, v in (("ixx", moments[0]), ("ixy", 0.0), ("ixz", 0.0), ("iyy", moments[1]), ("iyz", 0.0), ("izz", moments[2])):
            _sub(tensor, tag, f"{v:.9g}")
        for k, g in enumerate(range(int(m.body_geomadr[b]), int(m.body_geomadr[b]) + int(m.body_geomnum[b]))):
            collides = bool(m.geom_contype[g] or m.geom_conaffinity[g])
            for kind in ("visual", "collision") if collides else ("visual",):
                el = _sub(link, kind, name=f"{kind}_{k}")
                _pose(el, m.geom_pos[g], quat_matrix(m.geom_quat[g]))
                _geometry(el, m, g, out_dir, mesh_files)
                if kind == "visual":
                    material = _sub(el, "material")
                    _sub(material, "diffuse", m.geom_rgba[g])
                    _sub(material, "ambient", m.geom_rgba[g])
                else:
                    friction = _sub(_sub(el, "surface"), "friction")
                    _sub(_sub(friction, "ode"), "mu", f"{float(m.geom_friction[g][0]):.9g}")
                    _sub(_sub(friction, "bullet"), "friction", f"{float(m.geom_friction[g][0]):.9g}")
    drives = position_drives(m)
    joint_names = names.UniqueNames(tuple(link_of.values()))
    for b in range(1, m.nbody):
        _body_joints(model, m, b, link_of, joint_names, drives)
    return model


def _body_joints(model: ET.Element, m, b: int, link_of: dict[int, str], joint_names, drives) -> None:
    import mujoco

    parent = link_of.get(int(m.body_parentid[b]), "world")
    adr, num = int(m.body_jntadr[b]), int(m.body_jntnum[b])
    if num == 0:
        j = _sub(model, "joint", name=joint_names(f"{link_of[b]}_fixed"), type="fixed")
        _sub(j, "parent", parent)
        _sub(j, "child", link_of[b])
        return
    kinds = {int(mujoco.mjtJoint.mjJNT_HINGE): "revolute", int(mujoco.mjtJoint.mjJNT_SLIDE): "prismatic"}
    for k, jid in enumerate(range(adr, adr + num)):
        kind = kinds.get(int(m.jnt_type[jid]))
        if kind is None:
            raise ExportError(f"robot joint {m.joint(jid).name or jid} is of a type (MuJoCo {int(m.jnt_type[jid])}) the SDF export does not write")
        if k < num - 1:
            # A 1 g link between this joint and the next one of the same body, at the body's pose.
            child = joint_names(f"{link_of[b]}_{m.joint(jid).name or k}_link")
            link = _sub(model, "link", name=child)
            _sub(link, "pose", _fmt([0.0] * 6), relative_to=link_of[b])
            inertial = _sub(link, "inertial")
            _sub(inertial, "mass", f"{CHAIN_LINK_MASS_KG:.9g}")
            tensor = _sub(inertial, "inertia")
            for tag in ("ixx", "iyy", "izz"):
                _sub(tensor, tag, "1e-09")
        else:
            child = link_of[b]
        name = joint_names(names.valid_identifier(m.joint(jid).name or f"joint_{jid}").strip("_") or f"joint_{jid}")
        j = _sub(model, "joint", name=name, type=kind)
        _sub(j, "pose", _fmt(np.concatenate([m.jnt_pos[jid], np.zeros(3)])), relative_to=link_of[b])
        _sub(j, "parent", parent)
        _sub(j, "child", child)
        axis = _sub(j, "axis")
        _sub(axis, "xyz", m.jnt_axis[jid], expressed_in=link_of[b])
        limit = _sub(axis, "limit")
        lo, hi = m.jnt_range[jid] if m.jnt_limited[jid] else (-1e16, 1e16)
        _sub(limit, "lower", f"{lo:.9g}")
        _sub(limit, "upper", f"{hi:.9g}")
        drive = drives.get(jid)
        _sub(limit, "effort", f"{drive[2]:.9g}" if drive is not None and drive[2] > 0 else "-1")
        dof = int(m.jnt_dofadr[jid])
        dynamics = _sub(axis, "dynamics")
        _sub(dynamics, "damping", f"{float(m.dof_damping[dof]):.9g}")
        _sub(dynamics, "friction", f"{float(m.dof_frictionloss[dof]):.9g}")
        if drive is not None:
            kp, kv, force, target = drive
            plugin = _sub(model, "plugin", filename=POSITION_CONTROLLER[0], name=POSITION_CONTROLLER[1])
            _sub(plugin, "joint_name", name)
            _sub(plugin, "p_gain", f"{kp:.9g}")
            _sub(plugin, "d_gain", f"{kv:.9g}")
            if force > 0:
                _sub(plugin, "cmd_max", f"{force:.9g}")
                _sub(plugin, "cmd_min", f"{-force:.9g}")
            _sub(plugin, "initial_position", f"{target:.9g}")
        parent = child
