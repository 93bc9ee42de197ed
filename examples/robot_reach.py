"""Load a scene built with ``--robot`` and run a scripted reach, writing a video.

    scene-builder build photo.jpg --depth depth.png --robot panda -o room
    python examples/robot_reach.py room --seconds 4 --video room_reach.mp4

The controller is scripted, no learning: the tool centre point rises from the home pose to the
target's height, then moves over the target that the layout chose (report.json ``robot``), with
the tool's orientation held. Each 10 ms a damped-least-squares inverse kinematics step
(``mj_jacSite``, a pull towards the home pose in the null space, joint limits respected) turns
the next waypoint into joint targets for the robot's own position actuators. The video is drawn
with ``mujoco.Renderer`` from a camera looking at the robot and its target, and written with
imageio's ffmpeg (MP4, H.264).

``python examples/robot_reach.py --help`` lists the options. Exit status 0 when the tool reached
the target within 2 cm without touching the scene, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

CONTROL_DT_S = 0.01
DAMPING = 0.05
NULL_GAIN = 0.3
REACH_TOL_M = 0.02


@dataclass
class Robot:
    """What the controller needs of the robot in a loaded scene (MuJoCo ids)."""

    site: int
    arm_qpos: np.ndarray  # qpos addresses of the arm joints
    arm_dof: np.ndarray  # dof addresses
    arm_act: np.ndarray  # actuator driving each arm joint
    lo: np.ndarray
    hi: np.ndarray
    home: np.ndarray
    geoms: set[int] = field(default_factory=set)


def load(out_dir: Path):
    """(model, data, robot, target (3,), report['robot']) of a scene built with ``--robot``,
    reset to keyframe ``robot/home``."""
    import mujoco

    report = json.loads((Path(out_dir) / "report.json").read_text())
    info = report.get("robot")
    if not info:
        raise SystemExit(f"{out_dir} was built without --robot; build it again with --robot panda")
    m = mujoco.MjModel.from_xml_path(str(Path(out_dir) / "scene.xml"))
    d = mujoco.MjData(m)
    joints = [m.joint(n) for n in info["arm_joints"]]
    act_of_joint = {int(m.actuator_trnid[a, 0]): a for a in range(m.nu) if int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)}
    robot = Robot(
        site=m.site(info["ee_site"]).id,
        arm_qpos=np.array([int(j.qposadr[0]) for j in joints]),
        arm_dof=np.array([int(j.dofadr[0]) for j in joints]),
        arm_act=np.array([act_of_joint[j.id] for j in joints]),
        lo=np.array([j.range[0] for j in joints]),
        hi=np.array([j.range[1] for j in joints]),
        home=np.array(info["home_qpos"]),
        geoms={g for g in range(m.ngeom) if m.body(int(m.geom_bodyid[g])).name.startswith("robot/")},
    )
    key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "robot/home")
    if key >= 0:
        mujoco.mj_resetDataKeyframe(m, d, key)
    else:  # a robot without a home keyframe: start from its measured home pose
        d.qpos[robot.arm_qpos] = robot.home
        d.ctrl[robot.arm_act] = robot.home
    mujoco.mj_forward(m, d)
    return m, d, robot, np.array(info["target_m"]), info


def ik_step(m, scratch, robot: Robot, q: np.ndarray, pos: np.ndarray, rot: np.ndarray, iters: int = 5) -> np.ndarray:
    """Arm joint targets that bring the tool site to ``pos`` with orientation ``rot`` (3x3),
    starting from ``q``: damped least squares on the 6-D site Jacobian, the home pose pulled in
    the null space, clipped to the joint limits. ``scratch`` is an MjData the kinematics use."""
    import mujoco

    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    q = q.copy()
    for _ in range(iters):
        scratch.qpos[robot.arm_qpos] = q
        mujoco.mj_kinematics(m, scratch)
        mujoco.mj_comPos(m, scratch)
        err_p = pos - scratch.site_xpos[robot.site]
        cur = scratch.site_xmat[robot.site].reshape(3, 3)
        err_r = 0.5 * (np.cross(cur[:, 0], rot[:, 0]) + np.cross(cur[:, 1], rot[:, 1]) + np.cross(cur[:, 2], rot[:, 2]))
        mujoco.mj_jacSite(m, scratch, jacp, jacr, robot.site)
        jac = np.vstack([jacp[:, robot.arm_dof], jacr[:, robot.arm_dof]])
        err = np.concatenate([err_p, err_r])
        jjt = jac @ jac.T + DAMPING**2 * np.eye(6)
        dq = jac.T @ np.linalg.solve(jjt, err)
        null = np.eye(len(q)) - np.linalg.pinv(jac) @ jac
        dq += null @ (NULL_GAIN * (robot.home - q))
        q = np.clip(q + dq, robot.lo, robot.hi)
    return q


def waypoints(start: np.ndarray, target: np.ndarray, seconds: float) -> callable:
    """The tool path: up (or down) to the target's height during the first 40 %, then across to
    the target until 85 %, then hold; minimum-jerk timing within each leg."""
    mid = np.array([start[0], start[1], target[2]])

    def smooth(s: float) -> float:
        s = min(max(s, 0.0), 1.0)
        return 10 * s**3 - 15 * s**4 + 6 * s**5

    def at(t: float) -> np.ndarray:
        s = t / seconds
        if s < 0.4:
            return start + smooth(s / 0.4) * (mid - start)
        return mid + smooth((s - 0.4) / 0.45) * (target - mid)

    return at


def robot_contacts(m, d, robot: Robot) -> list[tuple[str, str, float]]:
    """(robot geom, other geom, distance) of every contact between the robot and the scene."""
    out = []
    for i in range(d.ncon):
        c = d.contact[i]
        a, b = int(c.geom[0]), int(c.geom[1])
        if a < 0 or b < 0 or (a in robot.geoms) == (b in robot.geoms):
            continue
        mine, other = (a, b) if a in robot.geoms else (b, a)
        out.append((m.geom(mine).name or f"geom {mine}", m.geom(other).name or f"geom {other}", float(c.dist)))
    return out


@dataclass
class Outcome:
    """final_error_m: tool to target at the end; contacts: robot-scene contacts seen (first
    few, with the time); frames: the rendered frames (H, W, 3) uint8."""

    final_error_m: float
    min_error_m: float
    contacts: list[tuple[float, str, str, float]]
    frames: list[np.ndarray]


def run(out_dir: Path, seconds: float = 4.0, fps: int = 25, size: tuple[int, int] = (480, 360), render: bool = True) -> Outcome:
    """Simulate the scripted reach for ``seconds`` (model timestep), rendering at ``fps``."""
    import mujoco

    m, d, robot, target, _info = load(out_dir)
    scratch = mujoco.MjData(m)
    scratch.qpos[:] = d.qpos
    start = d.site_xpos[robot.site].copy()
    rot = d.site_xmat[robot.site].reshape(3, 3).copy()
    path = waypoints(start, target, 0.8 * seconds)
    q = d.qpos[robot.arm_qpos].copy()
    renderer = cam = None
    if render:
        renderer = mujoco.Renderer(m, height=size[1], width=size[0])
        cam = mujoco.MjvCamera()
        base = d.xpos[m.site_bodyid[robot.site]]
        cam.lookat[:] = 0.5 * (base + target)
        cam.distance = 2.2 + 0.5 * float(np.linalg.norm(base[:2] - target[:2]))
        cam.azimuth = float(np.degrees(np.arctan2(target[1] - base[1], target[0] - base[0]))) - 120.0
        cam.elevation = -25.0
    frames, contacts = [], []
    steps = int(round(seconds / m.opt.timestep))
    every = max(1, int(round(CONTROL_DT_S / m.opt.timestep)))
    frame_every = max(1, int(round(1.0 / (fps * m.opt.timestep))))
    min_err = np.inf
    for k in range(steps):
        if k % every == 0:
            q = ik_step(m, scratch, robot, q, path(d.time), rot)
            d.ctrl[robot.arm_act] = q
        mujoco.mj_step(m, d)
        for a, b, dist in robot_contacts(m, d, robot):
            if len(contacts) < 20:
                contacts.append((float(d.time), a, b, dist))
        min_err = min(min_err, float(np.linalg.norm(d.site_xpos[robot.site] - target)))
        if renderer is not None and k % frame_every == 0:
            renderer.update_scene(d, cam)
            frames.append(renderer.render().copy())
    if renderer is not None:
        renderer.close()
    return Outcome(float(np.linalg.norm(d.site_xpos[robot.site] - target)), min_err, contacts, frames)


def write_video(frames: list[np.ndarray], path: Path, fps: int) -> Path:
    """MP4 (H.264 through imageio-ffmpeg's bundled ffmpeg); ``.gif`` paths are written as GIF."""
    import imageio.v2 as imageio

    path = Path(path)
    if path.suffix.lower() == ".gif":
        imageio.mimsave(path, frames, duration=1.0 / fps, loop=0)
    else:
        imageio.mimsave(path, frames, fps=fps, codec="libx264", quality=7, macro_block_size=8)
    return path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", type=Path, help="output folder of `scene-builder build ... --robot NAME`")
    p.add_argument("--seconds", type=float, default=4.0, help="simulated seconds (default 4)")
    p.add_argument("--fps", type=int, default=25, help="video frame rate (default 25)")
    p.add_argument("--video", type=Path, help="video file, .mp4 or .gif (default SCENE/robot_reach.mp4)")
    args = p.parse_args(argv)
    os.environ.setdefault("MUJOCO_GL", "egl")
    outcome = run(args.scene, args.seconds, args.fps)
    video = write_video(outcome.frames, args.video or args.scene / "robot_reach.mp4", args.fps)
    touched = f"{len(outcome.contacts)} contacts with the scene (first: {outcome.contacts[0]})" if outcome.contacts else "no contact with the scene"
    print(f"tool {outcome.final_error_m * 100:.1f} cm from the target at the end; {touched}; {len(outcome.frames)} frames -> {video}")
    return 0 if outcome.final_error_m <= REACH_TOL_M and not outcome.contacts else 1


if __name__ == "__main__":
    sys.exit(main())
