"""Robots built offline with ``mujoco.MjSpec`` when MuJoCo Menagerie cannot be downloaded.

Why our own: Menagerie's models come as archives from GitHub, which an offline machine cannot
reach, and no PyPI wheel that installs beside MuJoCo 4 ships a Franka Panda MJCF with meshes
(``mujoco-usd-converter`` and the robotics suites pin older MuJoCo or pull their own physics).

Franka Emika Panda: the kinematics are Franka's published modified Denavit-Hartenberg table
(Craig's convention: a frame's offset ``a`` and twist ``alpha`` precede its joint's rotation and
``d``), the joint limits, torque limits and link masses are Franka's published figures, and the
names follow Menagerie's ``panda.xml`` (``link0``..``link7``, ``hand``, ``joint1``..``joint7``,
``finger_joint1/2``, ``actuator1``..``actuator8``), so the same controller drives either source.
Links are capsules around the segments between joint centres; each link's published mass is
spread over its geoms by volume and MuJoCo integrates the inertia over those solids. Position
servos with Menagerie's gains (kp 4500 / 2000 N m/rad, kv 450 / 200). The robot's geoms collide
with the scene but not with each other (contype 2, conaffinity 1).

``mobile_panda``: the same arm on a holonomic base (planar x, y, yaw joints with position
servos, like Menagerie's TidyBot base) of 0.70 x 0.56 x 0.30 m and 100 kg.
"""

from __future__ import annotations

import numpy as np

# Franka's modified DH table: (a_m, d_m, alpha_rad) of joint 1..7 and the flange.
PANDA_DH = (
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -np.pi / 2),
    (0.0, 0.316, np.pi / 2),
    (0.0825, 0.0, np.pi / 2),
    (-0.0825, 0.384, -np.pi / 2),
    (0.0, 0.0, np.pi / 2),
    (0.088, 0.0, np.pi / 2),
)
PANDA_FLANGE_D_M = 0.107
PANDA_LIMITS_RAD = (
    (-2.8973, 2.8973), (-1.7628, 1.7628), (-2.8973, 2.8973), (-3.0718, -0.0698),
    (-2.8973, 2.8973), (-0.0175, 3.7525), (-2.8973, 2.8973),
)
PANDA_TORQUE_NM = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
PANDA_KP = (4500.0, 4500.0, 3500.0, 3500.0, 2000.0, 2000.0, 2000.0)
PANDA_KV = (450.0, 450.0, 350.0, 350.0, 200.0, 200.0, 200.0)
# Link masses (kg) of link0..link7 and the hand, from Franka's published dynamic parameters.
PANDA_MASS_KG = (0.629769, 4.970684, 0.646926, 3.228604, 3.587895, 1.225946, 1.666555, 0.735522, 0.73)
PANDA_HOME_RAD = (0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785)
#: Tool centre point: between the fingertips, along the hand's z axis.
PANDA_TCP_M = 0.1034
LINK_RADIUS_M = (0.075, 0.065, 0.065, 0.06, 0.06, 0.055, 0.05, 0.045)
FINGER_TRAVEL_M = 0.04

BASE_HALF_M = (0.35, 0.28, 0.15)
BASE_MASS_KG = 100.0
BASE_CLEARANCE_M = 0.005  # the base's geometry floats this far above the floor (its joints are planar)
ARM_MOUNT_X_M = 0.12

ROBOT_CONTYPE, ROBOT_CONAFFINITY = 2, 1


def _rot_x(alpha: float) -> list[float]:
    return [float(np.cos(alpha / 2)), float(np.sin(alpha / 2)), 0.0, 0.0]


def _volume(kind: str, size: tuple[float, ...]) -> float:
    if kind == "capsule":
        r, half = size
        return np.pi * r * r * 2 * half + 4.0 / 3.0 * np.pi * r**3
    if kind == "cylinder":
        r, half = size
        return np.pi * r * r * 2 * half
    return 8.0 * float(np.prod(size))


def _add_solids(body, solids: list[tuple], mass_kg: float, rgba: list[float]) -> None:
    """Geoms of one link; its published mass spread over them by volume. solids: (kind, size,
    fromto or pos) with kind capsule (fromto), cylinder or box (pos)."""
    import mujoco

    vols = []
    for kind, size, where in solids:
        if kind == "capsule":
            half = 0.5 * float(np.linalg.norm(np.subtract(where[3:], where[:3])))
            vols.append(_volume(kind, (size[0], max(half, 1e-4))))
        else:
            vols.append(_volume(kind, size))
    total = sum(vols)
    types = {"capsule": mujoco.mjtGeom.mjGEOM_CAPSULE, "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER, "box": mujoco.mjtGeom.mjGEOM_BOX}
    for (kind, size, where), vol in zip(solids, vols):
        g = body.add_geom(type=types[kind], mass=mass_kg * vol / total, rgba=rgba,
                          contype=ROBOT_CONTYPE, conaffinity=ROBOT_CONAFFINITY, group=2)
        if kind == "capsule":
            g.fromto = list(where)
            g.size = [size[0], 0.0, 0.0]
        else:
            g.pos = list(where)
            g.size = list(size) + [0.0] * (3 - len(size))


def _panda_arm(spec, parent, mount_pos: list[float]) -> None:
    """link0..link7, hand and fingers under ``parent``, with actuators and sensors."""
    import mujoco

    white, dark = [0.95, 0.95, 0.95, 1.0], [0.25, 0.25, 0.25, 1.0]
    link0 = parent.add_body(name="link0", pos=mount_pos)
    _add_solids(link0, [("cylinder", (0.09, 0.07), [0.0, 0.0, 0.075]), ("capsule", (LINK_RADIUS_M[0],), [-0.02, 0, 0.1, 0, 0, 0.16])],
                PANDA_MASS_KG[0], white)
    body = link0
    offsets = [np.array([a, -np.sin(al) * d, np.cos(al) * d]) for a, d, al in PANDA_DH]
    for i, (a, d, alpha) in enumerate(PANDA_DH):
        body = body.add_body(name=f"link{i + 1}", pos=offsets[i].tolist(), quat=_rot_x(alpha))
        lo, hi = PANDA_LIMITS_RAD[i]
        body.add_joint(name=f"joint{i + 1}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1], range=[lo, hi],
                       armature=0.1, damping=1.0)
        r = LINK_RADIUS_M[i + 1]
        # The joint housing along the joint axis, and the segment to the next joint centre.
        solids = [("capsule", (r,), [0, 0, -0.06, 0, 0, 0.06])]
        if i == 0:
            solids.append(("capsule", (r,), [0, 0, -0.18, 0, 0, 0]))
        nxt = offsets[i + 1] if i + 1 < len(offsets) else np.array([0.0, 0.0, PANDA_FLANGE_D_M])
        if np.linalg.norm(nxt) > 1e-6:
            end = nxt - (0.08 * nxt / np.linalg.norm(nxt) if i + 1 == len(offsets) else 0.0)
            solids.append(("capsule", (r,), [0.0, 0.0, 0.0, *end.tolist()]))
        _add_solids(body, solids, PANDA_MASS_KG[i + 1], dark if i == 6 else white)
    hand = body.add_body(name="hand", pos=[0, 0, PANDA_FLANGE_D_M], quat=[np.cos(-np.pi / 8), 0, 0, np.sin(-np.pi / 8)])
    _add_solids(hand, [("box", (0.03, 0.095, 0.025), [0, 0, 0.03]), ("cylinder", (0.045, 0.01), [0, 0, 0.0])],
                PANDA_MASS_KG[8], white)
    hand.add_site(name="tcp", pos=[0, 0, PANDA_TCP_M], size=[0.01, 0, 0], rgba=[1, 0, 0, 1], group=4)
    for k, sign in ((1, 1.0), (2, -1.0)):
        finger = hand.add_body(name="left_finger" if k == 1 else "right_finger", pos=[0, 0, 0.0584])
        finger.add_joint(name=f"finger_joint{k}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, sign, 0],
                         range=[0, FINGER_TRAVEL_M], armature=0.1, damping=10.0)
        _add_solids(finger, [("box", (0.01, 0.01, 0.025), [0, sign * 0.01, 0.025])], 0.015, dark)
    spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1="finger_joint1", name2="finger_joint2", data=[0, 1] + [0] * 10)
    for i in range(7):
        act = spec.add_actuator(name=f"actuator{i + 1}", target=f"joint{i + 1}", trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=PANDA_KP[i], kv=PANDA_KV[i])
        act.ctrlrange = list(PANDA_LIMITS_RAD[i])
        act.forcerange = [-PANDA_TORQUE_NM[i], PANDA_TORQUE_NM[i]]
    grip = spec.add_actuator(name="actuator8", target="finger_joint1", trntype=mujoco.mjtTrn.mjTRN_JOINT)
    grip.set_to_position(kp=100.0, kv=10.0)
    grip.ctrlrange = [0.0, FINGER_TRAVEL_M]
    grip.forcerange = [-70.0, 70.0]
    for i in range(7):
        spec.add_sensor(name=f"joint{i + 1}_pos", type=mujoco.mjtSensor.mjSENS_JOINTPOS, objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=f"joint{i + 1}")
        spec.add_sensor(name=f"joint{i + 1}_vel", type=mujoco.mjtSensor.mjSENS_JOINTVEL, objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=f"joint{i + 1}")
    spec.add_sensor(name="tcp_pos", type=mujoco.mjtSensor.mjSENS_FRAMEPOS, objtype=mujoco.mjtObj.mjOBJ_SITE, objname="tcp")
    spec.add_sensor(name="tcp_quat", type=mujoco.mjtSensor.mjSENS_FRAMEQUAT, objtype=mujoco.mjtObj.mjOBJ_SITE, objname="tcp")


def _new_spec(name: str):
    import mujoco

    spec = mujoco.MjSpec()
    spec.modelname = name
    spec.compiler.degree = False
    spec.compiler.autolimits = True
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    return spec


def build_panda():
    """The fixed-base Franka Emika Panda (``MjSpec``), base on the floor at the origin."""
    spec = _new_spec("panda")
    _panda_arm(spec, spec.worldbody, [0.0, 0.0, 0.0])
    _home_key(spec, ())
    return spec


def build_mobile_panda():
    """The Panda on a holonomic base: joints ``base_x``, ``base_y`` (slides) and ``base_yaw``."""
    import mujoco

    spec = _new_spec("mobile_panda")
    base = spec.worldbody.add_body(name="base", pos=[0.0, 0.0, 0.0])
    for jname, jtype, axis in (("base_x", mujoco.mjtJoint.mjJNT_SLIDE, [1, 0, 0]), ("base_y", mujoco.mjtJoint.mjJNT_SLIDE, [0, 1, 0]),
                               ("base_yaw", mujoco.mjtJoint.mjJNT_HINGE, [0, 0, 1])):
        base.add_joint(name=jname, type=jtype, axis=axis, damping=50.0, armature=1.0)
    hx, hy, hz = BASE_HALF_M
    _add_solids(base, [("box", BASE_HALF_M, [0.0, 0.0, BASE_CLEARANCE_M + hz])], BASE_MASS_KG, [0.2, 0.22, 0.25, 1.0])
    for jname, kp, kv in (("base_x", 5000.0, 1500.0), ("base_y", 5000.0, 1500.0), ("base_yaw", 2000.0, 600.0)):
        act = spec.add_actuator(name=jname, target=jname, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=kp, kv=kv)
        spec.add_sensor(name=f"{jname}_pos", type=mujoco.mjtSensor.mjSENS_JOINTPOS, objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=jname)
    _panda_arm(spec, base, [ARM_MOUNT_X_M, 0.0, BASE_CLEARANCE_M + 2 * hz])
    _home_key(spec, (0.0, 0.0, 0.0))
    return spec


def _home_key(spec, base_q: tuple[float, ...]) -> None:
    """Keyframe ``home``: the arm in Franka's ready pose, fingers open."""
    qpos = list(base_q) + list(PANDA_HOME_RAD) + [FINGER_TRAVEL_M, FINGER_TRAVEL_M]
    ctrl = list(base_q) + list(PANDA_HOME_RAD) + [FINGER_TRAVEL_M]
    spec.add_key(name="home", qpos=qpos, ctrl=ctrl)


BUILDERS = {"panda": build_panda, "mobile_panda": build_mobile_panda}
