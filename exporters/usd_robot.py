"""The robot (``Scene.robot``) in ``scene.usda``: an articulation under ``/World/Robot``.

Why our own writer: ``mujoco-usd-converter`` (newton-physics) converts MJCF to UsdPhysics, but it
pins ``mujoco<3.17`` and would replace the MuJoCo 4 this project runs on. So the robot's MJCF is
compiled alone (the file as loaded, Menagerie's or the built-in one) and its bodies, geoms,
joints and position actuators are written from the compiled ``MjModel``, at the start pose
(qpos0) moved to the placement:

* ``/World/Robot``: ArticulationRootAPI, the source and sensors as ``sceneBuilder:*`` attributes.
* ``/World/Robot/<body>``: one Xform per body (flat, world transform), RigidBodyAPI + MassAPI
  (mass, centre of mass, principal inertia and axes as compiled); children are its geoms as
  UsdGeom primitives (Sphere, Capsule, Cylinder, Cube scaled, Mesh with the compiled vertices);
  collision geoms carry CollisionAPI (meshes: convexHull, as MuJoCo collides them), visual
  geoms none.
* ``/World/Robot/Joints``: one joint per body: Revolute / Prismatic along local X (rotated onto
  the MuJoCo axis), limits in degrees / metres; a body with several joints (a planar x, y, yaw
  base) gets a generic joint with those axes free and the others locked (LimitAPI); a welded body
  a FixedJoint (to the world for a fixed base). A joint driven by a MuJoCo position actuator gets
  a DriveAPI with its stiffness and damping (angular ones per degree), its force range as
  maxForce and the target of a zero control; a joint coupled to it by an equality (the second
  finger) gets the same drive.
"""

from __future__ import annotations

import numpy as np

from exporters import names
from exporters.robot import compiled_robot, position_drives, quat_matrix
from scene_builder.errors import ExportError
from scene_builder.frames import quat_wxyz_from_matrix
from scene_builder.robot import RobotPlacement

ROOT = "/World/Robot"
UNBOUNDED = 1.0e6  # the range of a free axis without limits (metres or degrees)


def _quatf(r: np.ndarray):
    from pxr import Gf

    q = quat_wxyz_from_matrix(r)
    return Gf.Quatf(float(q[0]), Gf.Vec3f(*q[1:].tolist()))


def _xform(prim_xf, pos: np.ndarray, rot: np.ndarray, scale: np.ndarray | None = None) -> None:
    from pxr import Gf

    prim_xf.AddTranslateOp().Set(Gf.Vec3d(*np.asarray(pos, float).tolist()))
    prim_xf.AddOrientOp().Set(_quatf(rot))
    if scale is not None:
        prim_xf.AddScaleOp().Set(Gf.Vec3f(*np.asarray(scale, float).tolist()))


def _geom(stage, m, g: int, path) -> None:
    import mujoco
    from pxr import Gf, UsdGeom, UsdPhysics, Vt

    t = int(m.geom_type[g])
    size = m.geom_size[g]
    scale = None
    if t == int(mujoco.mjtGeom.mjGEOM_SPHERE):
        shape = UsdGeom.Sphere.Define(stage, path)
        shape.CreateRadiusAttr(float(size[0]))
    elif t == int(mujoco.mjtGeom.mjGEOM_CAPSULE):
        shape = UsdGeom.Capsule.Define(stage, path)
        shape.CreateRadiusAttr(float(size[0]))
        shape.CreateHeightAttr(float(2 * size[1]))
        shape.CreateAxisAttr(UsdGeom.Tokens.z)
    elif t == int(mujoco.mjtGeom.mjGEOM_CYLINDER):
        shape = UsdGeom.Cylinder.Define(stage, path)
        shape.CreateRadiusAttr(float(size[0]))
        shape.CreateHeightAttr(float(2 * size[1]))
        shape.CreateAxisAttr(UsdGeom.Tokens.z)
    elif t == int(mujoco.mjtGeom.mjGEOM_BOX):
        shape = UsdGeom.Cube.Define(stage, path)
        shape.CreateSizeAttr(2.0)
        scale = size.copy()
    elif t == int(mujoco.mjtGeom.mjGEOM_MESH):
        k = int(m.geom_dataid[g])
        va, vn = int(m.mesh_vertadr[k]), int(m.mesh_vertnum[k])
        fa, fn = int(m.mesh_faceadr[k]), int(m.mesh_facenum[k])
        shape = UsdGeom.Mesh.Define(stage, path)
        shape.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(m.mesh_vert[va : va + vn].astype(np.float32)))
        shape.CreateFaceVertexCountsAttr(Vt.IntArray([3] * fn))
        shape.CreateFaceVertexIndicesAttr(Vt.IntArray(m.mesh_face[fa : fa + fn].ravel().tolist()))
        shape.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    else:
        raise ExportError(f"robot geom {m.geom(g).name or g} is of a type (MuJoCo {t}) the USD export does not write")
    _xform(shape, m.geom_pos[g], quat_matrix(m.geom_quat[g]), scale)
    shape.CreateDisplayColorAttr([Gf.Vec3f(*m.geom_rgba[g][:3].tolist())])
    if m.geom_contype[g] or m.geom_conaffinity[g]:
        UsdPhysics.CollisionAPI.Apply(shape.GetPrim())
        if t == int(mujoco.mjtGeom.mjGEOM_MESH):
            UsdPhysics.MeshCollisionAPI.Apply(shape.GetPrim()).CreateApproximationAttr(UsdPhysics.Tokens.convexHull)
    else:
        shape.CreatePurposeAttr(UsdGeom.Tokens.render)


def add_robot(stage, placement: RobotPlacement) -> None:
    """Write the robot under ROOT (see the module docstring)."""
    from pxr import Sdf, UsdGeom, UsdPhysics

    m, d = compiled_robot(placement, "USD")
    world = placement.world_from_robot
    root = UsdGeom.Xform.Define(stage, ROOT)
    rp = root.GetPrim()
    UsdPhysics.ArticulationRootAPI.Apply(rp)
    rp.CreateAttribute("sceneBuilder:robot", Sdf.ValueTypeNames.String).Set(placement.model.name)
    rp.CreateAttribute("sceneBuilder:source", Sdf.ValueTypeNames.String).Set(placement.model.detail)
    sensors = [m.sensor(s).name for s in range(m.nsensor)]
    rp.CreateAttribute("sceneBuilder:sensors", Sdf.ValueTypeNames.StringArray).Set(sensors)
    unique = names.UniqueNames(reserved=("Joints",))
    paths = {0: None}
    for b in range(1, m.nbody):
        path = Sdf.Path(ROOT).AppendChild(unique(m.body(b).name or f"body_{b}"))
        paths[b] = path
        xf = UsdGeom.Xform.Define(stage, path)
        xf.GetPrim().SetDisplayName(m.body(b).name)
        pos = world[:3, :3] @ d.xpos[b] + world[:3, 3]
        _xform(xf, pos, world[:3, :3] @ d.xmat[b].reshape(3, 3))
        UsdPhysics.RigidBodyAPI.Apply(xf.GetPrim())
        mass = UsdPhysics.MassAPI.Apply(xf.GetPrim())
        from pxr import Gf

        mass.CreateMassAttr(float(max(m.body_mass[b], 1e-6)))
        mass.CreateCenterOfMassAttr(Gf.Vec3f(*m.body_ipos[b].tolist()))
        mass.CreateDiagonalInertiaAttr(Gf.Vec3f(*np.maximum(m.body_inertia[b], 1e-9).tolist()))
        mass.CreatePrincipalAxesAttr(_quatf(quat_matrix(m.body_iquat[b])))
        geom_names = names.UniqueNames()
        for g in range(int(m.body_geomadr[b]), int(m.body_geomadr[b]) + int(m.body_geomnum[b])):
            _geom(stage, m, g, path.AppendChild(geom_names(m.geom(g).name or f"geom_{g - int(m.body_geomadr[b])}")))
    joints = Sdf.Path(ROOT).AppendChild("Joints")
    UsdGeom.Scope.Define(stage, joints)
    drives = position_drives(m)
    for b in range(1, m.nbody):
        _add_body_joint(stage, m, d, b, paths, joints, world, drives)


def _add_body_joint(stage, m, d, b: int, paths, joints, world: np.ndarray, drives) -> None:
    import mujoco
    from pxr import UsdPhysics

    parent = int(m.body_parentid[b])
    adr, num = int(m.body_jntadr[b]), int(m.body_jntnum[b])
    jpath = joints.AppendChild(names.file_stem(m.body(b).name or f"body_{b}"))
    # Frame 1 in the body, frame 0 the same frame in the parent (the world for the root).
    anchor = m.jnt_pos[adr] if num else np.zeros(3)
    axis = m.jnt_axis[adr] if num == 1 else np.array([1.0, 0.0, 0.0])
    helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    y = np.cross(helper, axis)
    y /= np.linalg.norm(y)
    rot1 = np.stack([axis, y, np.cross(axis, y)], axis=1) if num == 1 else np.eye(3)
    body_rot = d.xmat[b].reshape(3, 3)
    if parent == 0:
        p_rot, p_pos = world[:3, :3], world[:3, 3]
        rel_rot, rel_pos = p_rot @ body_rot, p_rot @ d.xpos[b] + p_pos
    else:
        pr = d.xmat[parent].reshape(3, 3)
        rel_rot, rel_pos = pr.T @ body_rot, pr.T @ (d.xpos[b] - d.xpos[parent])
    pos0, rot0 = rel_rot @ anchor + rel_pos, rel_rot @ rot1
    types = [int(m.jnt_type[j]) for j in range(adr, adr + num)]
    hinge, slide = int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)
    dofs: list[tuple[int, str, str]] = []  # (joint id, drive token, limit token)
    if num == 0:
        joint = UsdPhysics.FixedJoint.Define(stage, jpath)
    elif num == 1 and types[0] == hinge:
        joint = UsdPhysics.RevoluteJoint.Define(stage, jpath)
        joint.CreateAxisAttr(UsdPhysics.Tokens.x)
        if m.jnt_limited[adr]:
            joint.CreateLowerLimitAttr(float(np.degrees(m.jnt_range[adr][0])))
            joint.CreateUpperLimitAttr(float(np.degrees(m.jnt_range[adr][1])))
        dofs.append((adr, "angular", ""))
    elif num == 1 and types[0] == slide:
        joint = UsdPhysics.PrismaticJoint.Define(stage, jpath)
        joint.CreateAxisAttr(UsdPhysics.Tokens.x)
        if m.jnt_limited[adr]:
            joint.CreateLowerLimitAttr(float(m.jnt_range[adr][0]))
            joint.CreateUpperLimitAttr(float(m.jnt_range[adr][1]))
        dofs.append((adr, "linear", ""))
    else:
        # Several joints on one body (a planar base): a generic joint, their axes free.
        joint = UsdPhysics.Joint.Define(stage, jpath)
        free = {}
        for j, t in zip(range(adr, adr + num), types):
            k = int(np.argmax(np.abs(m.jnt_axis[j])))
            if t not in (hinge, slide) or abs(abs(m.jnt_axis[j][k]) - 1.0) > 1e-6:
                raise ExportError(f"robot body {m.body(b).name}: several joints not along its axes; the USD export cannot write them")
            token = ("rot" if t == hinge else "trans") + "XYZ"[k]
            free[token] = j
            dofs.append((j, token, token))
            # A free axis carries its range too (UNBOUNDED without one): Newton reads a generic
            # joint's axes from their LimitAPI.
            lo, hi = m.jnt_range[j] if m.jnt_limited[j] else (-UNBOUNDED, UNBOUNDED)
            lim = UsdPhysics.LimitAPI.Apply(joint.GetPrim(), token)
            lim.CreateLowAttr(float(np.degrees(lo) if t == hinge and m.jnt_limited[j] else lo))
            lim.CreateHighAttr(float(np.degrees(hi) if t == hinge and m.jnt_limited[j] else hi))
        for token in ("transX", "transY", "transZ", "rotX", "rotY", "rotZ"):
            if token not in free:
                lim = UsdPhysics.LimitAPI.Apply(joint.GetPrim(), token)
                lim.CreateLowAttr(1.0)
                lim.CreateHighAttr(-1.0)
    if parent != 0:
        joint.CreateBody0Rel().SetTargets([paths[parent]])
    joint.CreateBody1Rel().SetTargets([paths[b]])
    from pxr import Gf

    joint.CreateLocalPos0Attr(Gf.Vec3f(*pos0.tolist()))
    joint.CreateLocalRot0Attr(_quatf(rot0))
    joint.CreateLocalPos1Attr(Gf.Vec3f(*np.asarray(anchor, float).tolist()))
    joint.CreateLocalRot1Attr(_quatf(rot1))
    joint.GetPrim().SetDisplayName(m.joint(adr).name if num == 1 else m.body(b).name)
    for j, token, _ in dofs:
        if j not in drives:
            continue
        kp, kv, force, target = drives[j]
        angular = token == "angular" or token.startswith("rot")
        per = np.pi / 180.0 if angular else 1.0
        drive = UsdPhysics.DriveAPI.Apply(joint.GetPrim(), token)
        drive.CreateTypeAttr("force")
        drive.CreateStiffnessAttr(float(kp * per))
        drive.CreateDampingAttr(float(kv * per))
        drive.CreateTargetPositionAttr(float(np.degrees(target) if angular else target))
        if force > 0:
            drive.CreateMaxForceAttr(force)
