"""The placed robot in MuJoCo: overlap at the start, and whether its arm reaches the target.

The reach is scripted, no learning: the tool centre point rises (or sinks) from the home pose to
the target's height, then moves across to the target (minimum-jerk timing on each leg), its
orientation held. Each waypoint becomes arm joint targets by damped least squares on the 6-D
site Jacobian (``mj_jacSite``) with a pull towards the home pose in the null space, within the
joint limits. :func:`check_reach` sweeps that path kinematically and measures the robot's
distance to the scene (``mj_geomDistance``); the pipeline keeps a placement only when the arm
gets there clear of everything. ``examples/robot_reach.py`` drives the same path through the
robot's own position actuators in simulation.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from scene_builder.robot import RobotPlacement

PREFIX = "robot/"
DAMPING = 0.05
NULL_GAIN = 0.3
SWEEP_STEPS = 60
RISE_SHARE = 0.4  # of the path's duration spent on the vertical leg
#: The kinematic sweep must keep this far from the scene: the simulated arm lags the plan and
#: sags under gravity by a few millimetres.
SWEEP_CLEARANCE_M = 0.01
REACH_TOL_M = 0.01
CONTROL_DT_S = 0.01


@dataclass
class ArmIds:
    """MuJoCo ids of the robot in a compiled scene (names carry the ``robot/`` prefix)."""

    site: int
    qpos: np.ndarray  # qpos address of each arm joint
    dof: np.ndarray
    act: np.ndarray  # the actuator driving each arm joint
    lo: np.ndarray
    hi: np.ndarray
    home: np.ndarray
    geoms: np.ndarray  # the robot's collision geoms
    moving: np.ndarray  # those the arm carries (its first joint's body and below)


def arm_ids(m, ee_site: str, arm_joints: list[str] | tuple[str, ...], home: np.ndarray) -> ArmIds:
    """Ids of the arm called ``arm_joints`` (full names) with tool site ``ee_site``."""
    import mujoco

    joints = [m.joint(n) for n in arm_joints]
    act_of_joint = {int(m.actuator_trnid[a, 0]): a for a in range(m.nu) if int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)}
    robot_body = np.array([m.body(b).name.startswith(PREFIX) for b in range(m.nbody)])
    collides = (m.geom_contype != 0) | (m.geom_conaffinity != 0)
    first = int(joints[0].bodyid[0])
    carried = np.zeros(m.nbody, dtype=bool)
    for b in range(m.nbody):
        k = b
        while k > 0 and k != first:
            k = int(m.body_parentid[k])
        carried[b] = k == first
    return ArmIds(
        site=m.site(ee_site).id,
        qpos=np.array([int(j.qposadr[0]) for j in joints]),
        dof=np.array([int(j.dofadr[0]) for j in joints]),
        act=np.array([act_of_joint.get(j.id, -1) for j in joints]),
        lo=np.array([j.range[0] for j in joints]),
        hi=np.array([j.range[1] for j in joints]),
        home=np.asarray(home, dtype=np.float64),
        geoms=np.flatnonzero(collides & robot_body[m.geom_bodyid]),
        moving=np.flatnonzero(collides & carried[m.geom_bodyid]),
    )


def reset_home(m, d, arm: ArmIds) -> None:
    """Keyframe ``robot/home`` when the scene has it, else the arm's home pose."""
    import mujoco

    key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, f"{PREFIX}home")
    if key >= 0:
        mujoco.mj_resetDataKeyframe(m, d, key)
    else:
        mujoco.mj_resetData(m, d)
        d.qpos[arm.qpos] = arm.home
        d.ctrl[arm.act[arm.act >= 0]] = arm.home[arm.act >= 0]
    mujoco.mj_forward(m, d)


def ik_step(m, scratch, arm: ArmIds, q: np.ndarray, pos: np.ndarray, rot: np.ndarray | None, iters: int = 5) -> np.ndarray:
    """Arm joint values that bring the tool site to ``pos`` with its approach axis (z) along
    ``rot``'s (3x3) z, free to turn about it (a gripper coming down on a table keeps pointing
    down; its wrist may turn: the arm reaches further; ``rot`` None: position only), starting from ``q`` (damped least
    squares, home pulled in the null space, clipped to the limits). ``scratch``: an MjData
    holding the rest of the state (kinematics only)."""
    import mujoco

    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    q = q.copy()
    for _ in range(iters):
        scratch.qpos[arm.qpos] = q
        mujoco.mj_kinematics(m, scratch)
        mujoco.mj_comPos(m, scratch)
        err_p = pos - scratch.site_xpos[arm.site]
        cur = scratch.site_xmat[arm.site].reshape(3, 3)
        axis = cur[:, 2]
        mujoco.mj_jacSite(m, scratch, jacp, jacr, arm.site)
        if rot is None:
            jac, err = jacp[:, arm.dof], err_p
        else:
            # Turning about the approach axis is free: that part of the rotation is projected out.
            jac = np.vstack([jacp[:, arm.dof], (np.eye(3) - np.outer(axis, axis)) @ jacr[:, arm.dof]])
            err = np.concatenate([err_p, np.cross(axis, rot[:, 2])])
        dq = jac.T @ np.linalg.solve(jac @ jac.T + DAMPING**2 * np.eye(len(err)), err)
        dq += (np.eye(len(q)) - np.linalg.pinv(jac) @ jac) @ (NULL_GAIN * (arm.home - q))
        q = np.clip(q + dq, arm.lo, arm.hi)
    return q


def tool_path(start: np.ndarray, target: np.ndarray, seconds: float) -> Callable[[float], np.ndarray]:
    """Tool position at time t: to the target's height over RISE_SHARE of ``seconds``, then
    across to the target (minimum-jerk on each leg), then held."""
    mid = np.array([start[0], start[1], target[2]])

    def smooth(s: float) -> float:
        s = min(max(s, 0.0), 1.0)
        return 10 * s**3 - 15 * s**4 + 6 * s**5

    def at(t: float) -> np.ndarray:
        s = t / seconds
        if s < RISE_SHARE:
            return start + smooth(s / RISE_SHARE) * (mid - start)
        return mid + smooth((s - RISE_SHARE) / (1.0 - RISE_SHARE)) * (target - mid)

    return at


def _min_distance(m, d, mine: np.ndarray, others: np.ndarray, cutoff: float) -> float:
    """Smallest distance (negative: overlap) between geoms ``mine`` and ``others``, up to ``cutoff``."""
    import mujoco

    fromto = np.zeros(6)
    best = cutoff
    for a in mine:
        near = others[np.linalg.norm(d.geom_xpos[others] - d.geom_xpos[a], axis=1) <= m.geom_rbound[a] + m.geom_rbound[others] + cutoff]
        near = np.concatenate([near, others[m.geom_rbound[others] == 0]])  # planes have no bounding sphere
        for b in near:
            best = min(best, float(mujoco.mj_geomDistance(m, d, int(a), int(b), cutoff, fromto)))
    return best


def _scene_geoms(m, arm: ArmIds) -> np.ndarray:
    collides = np.flatnonzero((m.geom_contype != 0) | (m.geom_conaffinity != 0))
    return np.setdiff1d(collides, arm.geoms)


def robot_overlaps(mjcf_path: Path, placement: RobotPlacement) -> float:
    """Deepest overlap (m, 0 when none) between the robot's collision geoms and the scene's, at
    the start pose and at the home pose (the MJCF written with ``placement``)."""
    return PlacementTrials(mjcf_path, placement).overlap(placement)


def _arm(m, placement: RobotPlacement) -> ArmIds:
    model = placement.model
    return arm_ids(m, PREFIX + model.ee_site, [PREFIX + j for j in model.arm_joints], model.home_qpos)


def check_reach(mjcf_path: Path, placement: RobotPlacement) -> tuple[float, float]:
    """Sweep the scripted reach kinematically (SWEEP_STEPS waypoints): (tool's distance to the
    target at the end, smallest distance between the arm's geoms and the scene on the way; the
    base, which does not move, is measured by :func:`robot_overlaps`)."""
    return PlacementTrials(mjcf_path, placement).reach(placement)


class PlacementTrials:
    """One compiled scene (the MJCF written with the robot at ``written``) in which the robot is
    moved to other placements of the same model without writing and compiling the scene again:
    the robot's bodies hanging from the world (attached under one frame) are carried from the
    written placement's frame to the new one's."""

    def __init__(self, mjcf_path: Path, written: RobotPlacement) -> None:
        import mujoco

        self.m = mujoco.MjModel.from_xml_path(str(mjcf_path))
        self.d = mujoco.MjData(self.m)
        self.arm = _arm(self.m, written)
        self.others = _scene_geoms(self.m, self.arm)
        self.roots = np.array([b for b in range(1, self.m.nbody) if self.m.body_parentid[b] == 0
                               and self.m.body(b).name.startswith(PREFIX)])
        # Each root's pose in the written placement's robot frame.
        inv = np.linalg.inv(written.world_from_robot)
        self.root_pos = self.m.body_pos[self.roots] @ inv[:3, :3].T + inv[:3, 3]
        self.root_quat = np.array([_quat_mul(_yaw_quat(-written.yaw_rad), q) for q in self.m.body_quat[self.roots]])

    def _move(self, placement: RobotPlacement) -> None:
        t = placement.world_from_robot
        self.m.body_pos[self.roots] = self.root_pos @ t[:3, :3].T + t[:3, 3]
        self.m.body_quat[self.roots] = [_quat_mul(_yaw_quat(placement.yaw_rad), q) for q in self.root_quat]

    def overlap(self, placement: RobotPlacement) -> float:
        """Deepest overlap (m, 0 when none) of the robot at ``placement`` with the scene, at the
        start pose and at the home pose."""
        import mujoco

        self._move(placement)
        m, d = self.m, self.d
        mujoco.mj_resetData(m, d)
        mujoco.mj_forward(m, d)
        worst = _min_distance(m, d, self.arm.geoms, self.others, 0.0)
        reset_home(m, d, self.arm)
        worst = min(worst, _min_distance(m, d, self.arm.geoms, self.others, 0.0))
        return max(0.0, -worst)

    def reach(self, placement: RobotPlacement) -> tuple[float, float]:
        """(tool's final distance to the target, smallest arm-scene distance on the way) of the
        scripted reach swept kinematically from the home pose at ``placement``."""
        import mujoco

        self._move(placement)
        m, d, arm = self.m, self.d, self.arm
        reset_home(m, d, arm)
        start = d.site_xpos[arm.site].copy()
        rot = d.site_xmat[arm.site].reshape(3, 3).copy() if placement.hold_tool_axis else None
        path = tool_path(start, np.asarray(placement.target_m), 1.0)
        q = d.qpos[arm.qpos].copy()
        clearance = np.inf
        for t in np.linspace(0.0, 1.0, SWEEP_STEPS + 1):
            q = ik_step(m, d, arm, q, path(t), rot)
            d.qpos[arm.qpos] = q
            mujoco.mj_kinematics(m, d)
            clearance = min(clearance, _min_distance(m, d, arm.moving, self.others, 0.05))
        for _ in range(5):  # settle the last waypoint
            q = ik_step(m, d, arm, q, path(1.0), rot)
        d.qpos[arm.qpos] = q
        mujoco.mj_kinematics(m, d)
        return float(np.linalg.norm(d.site_xpos[arm.site] - placement.target_m)), float(clearance)

    def first_passing(self, placements, variants=None) -> tuple[RobotPlacement | None, list[str]]:
        """The first placement whose robot overlaps nothing at the start and home poses and
        whose reach ends within REACH_TOL_M of the target, SWEEP_CLEARANCE_M clear of the scene;
        and why each one tried before it failed. ``variants(placement)``: placements to try in
        its stead when it fails (an arm whose home pose reaches over the edge of the bed it
        faces: the robot turned or stepped back; a target lowered)."""
        why = []
        for first in placements:
            for placement in [first, *(variants(first) if variants is not None else ())]:
                overlap = self.overlap(placement)
                if overlap > 0.0:
                    why.append(f"{placement.target_kind} of {placement.target_support}: overlap {overlap * 1000:.1f} mm")
                    continue
                error, clearance = self.reach(placement)
                if error <= REACH_TOL_M and clearance >= SWEEP_CLEARANCE_M:
                    return placement, why
                why.append(f"{placement.target_kind} of {placement.target_support}: reach ends {error * 100:.1f} cm off, "
                           f"{clearance * 1000:.0f} mm clear")
        return None, why


def _yaw_quat(yaw: float) -> np.ndarray:
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    import mujoco

    out = np.zeros(4)
    mujoco.mju_mulQuat(out, np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    return out


def robot_contacts(m, d, mine) -> list[tuple[str, str, float]]:
    """(robot geom, other geom, distance) of every contact between the robot and the scene;
    ``mine``: the robot's geom ids (a set) or a (ngeom,) bool mask of them."""
    n = d.ncon
    if not n:
        return []
    mask = mine if isinstance(mine, np.ndarray) else np.isin(np.arange(m.ngeom), sorted(mine))
    g = d.contact.geom[:n]
    valid = (g >= 0).all(axis=1)
    g = np.where(valid[:, None], g, 0)
    out = []
    for i in np.flatnonzero(valid & (mask[g[:, 0]] != mask[g[:, 1]])):
        a, b = int(g[i, 0]), int(g[i, 1])
        own, other = (a, b) if mask[a] else (b, a)
        out.append((m.geom(own).name or f"geom {own} of {m.body(int(m.geom_bodyid[own])).name}",
                    m.geom(other).name or f"geom {other}", float(d.contact.dist[i])))
    return out


@dataclass
class ReachResult:
    """final_error_m: tool to target at the end; min_error_m: closest on the way; contacts:
    (time s, robot geom, scene geom, distance m) of robot-scene contacts (the first 20)."""

    final_error_m: float
    min_error_m: float
    contacts: list[tuple[float, str, str, float]]


def simulate_reach(m, d, arm: ArmIds, target: np.ndarray, seconds: float, on_step: Callable[[int], None] | None = None,
                   hold_tool_axis: bool = True) -> ReachResult:
    """Run the scripted reach in simulation from the current state for ``seconds``: every
    CONTROL_DT_S the next waypoint of :func:`tool_path` (over 80 % of the time, then held) goes
    through :func:`ik_step` to the arm's position actuators; ``on_step(k)`` after each step."""
    import mujoco

    scratch = mujoco.MjData(m)
    scratch.qpos[:] = d.qpos
    start = d.site_xpos[arm.site].copy()
    rot = d.site_xmat[arm.site].reshape(3, 3).copy() if hold_tool_axis else None
    path = tool_path(start, np.asarray(target, dtype=np.float64), 0.8 * seconds)
    q = d.qpos[arm.qpos].copy()
    mine = np.array([m.body(int(m.geom_bodyid[g])).name.startswith(PREFIX) for g in range(m.ngeom)], dtype=bool)
    every = max(1, int(round(CONTROL_DT_S / m.opt.timestep)))
    contacts: list[tuple[float, str, str, float]] = []
    min_err = np.inf
    for k in range(int(round(seconds / m.opt.timestep))):
        if k % every == 0:
            q = ik_step(m, scratch, arm, q, path(d.time), rot)
            d.ctrl[arm.act] = q
        mujoco.mj_step(m, d)
        for a, b, dist in robot_contacts(m, d, mine):
            if len(contacts) < 20:
                contacts.append((float(d.time), a, b, dist))
        min_err = min(min_err, float(np.linalg.norm(d.site_xpos[arm.site] - target)))
        if on_step is not None:
            on_step(k)
    return ReachResult(float(np.linalg.norm(d.site_xpos[arm.site] - target)), min_err, contacts)


#: A target of the reach figure counts as reached when the simulated tool ends this close to it
#: with no robot-scene contact on the way.
SCORE_TOL_M = 0.02
SCORE_REACH_S = 4.0


@dataclass
class TargetReach:
    """One target of the fixed set (``layout.robot.reach_targets``) tried from the placed robot.

    target_m: (3,) the point; owner: the top it is above; in_workspace: within the arm's reach
    (``RobotModel.reach_m``) of its shoulder; reached: the simulated reach ended within
    SCORE_TOL_M without a robot-scene contact (the tool's axis held down, else free);
    final_error_m / contacts: of the last reach tried (nan / 0 outside the workspace);
    hold_tool_axis: whether the reach that counted held the tool's axis."""

    target_m: np.ndarray
    owner: str
    in_workspace: bool
    reached: bool = False
    final_error_m: float = float("nan")
    contacts: int = 0
    hold_tool_axis: bool = True


def score_reach(mjcf_path: Path, placement: RobotPlacement, targets: np.ndarray, owners: tuple[str, ...],
                seconds: float = SCORE_REACH_S) -> list[TargetReach]:
    """Try every target of ``targets`` (T, 3) within the workspace of the robot of the scene
    ``mjcf_path`` (written with ``placement``): from the home pose, :func:`simulate_reach` for
    ``seconds`` with the tool's axis held, and again with it free when that misses (as the
    placement's alternatives do). The figure is the share of in-workspace targets reached."""
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(mjcf_path))
    d = mujoco.MjData(m)
    arm = _arm(m, placement)
    model = placement.model
    shoulder = placement.world_from_robot[:3, :3] @ model.arm_mount_m + placement.position_m
    out = []
    for target, owner in zip(np.asarray(targets, dtype=np.float64), owners):
        if float(np.linalg.norm(target - shoulder)) > model.reach_m:
            out.append(TargetReach(target, owner, False))
            continue
        for hold in (True, False):
            reset_home(m, d, arm)
            r = simulate_reach(m, d, arm, target, seconds, hold_tool_axis=hold)
            ok = r.final_error_m <= SCORE_TOL_M and not r.contacts
            if ok or not hold:
                out.append(TargetReach(target, owner, True, ok, r.final_error_m, len(r.contacts), hold))
                break
    return out
