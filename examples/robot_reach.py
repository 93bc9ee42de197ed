"""Load a scene built with ``--robot`` and run a scripted reach, writing a video.

    scene-builder build photo.jpg --depth depth.png --robot panda -o room
    python examples/robot_reach.py room            # -> room_reach.mp4

The controller is scripted, no learning (``layout.reach``, the path the build checked the
placement with): the tool centre point rises from the home pose to the target's height, then
moves over the target that the layout chose (report.json ``robot``), with the tool's orientation
held. Each 10 ms a damped-least-squares inverse kinematics step (``mj_jacSite``, a pull towards
the home pose in the null space, joint limits respected) turns the next waypoint into joint
targets for the robot's own position actuators. The video is drawn
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
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REACH_TOL_M = 0.02


def load(out_dir: Path):
    """(model, data, arm ids, target (3,), report['robot']) of a scene built with ``--robot``,
    reset to its home pose."""
    import mujoco

    from layout.reach import arm_ids, reset_home

    report = json.loads((Path(out_dir) / "report.json").read_text())
    info = report.get("robot")
    if not info:
        raise SystemExit(f"{out_dir} was built without --robot; build it again with --robot panda")
    m = mujoco.MjModel.from_xml_path(str(Path(out_dir) / "scene.xml"))
    d = mujoco.MjData(m)
    arm = arm_ids(m, info["ee_site"], info["arm_joints"], np.array(info["home_qpos"]))
    reset_home(m, d, arm)
    return m, d, arm, np.array(info["target_m"]), info


@dataclass
class Outcome:
    """What the reach did (``layout.reach.ReachResult``) and the rendered frames (H, W, 3) uint8."""

    final_error_m: float
    min_error_m: float
    contacts: list[tuple[float, str, str, float]]
    frames: list[np.ndarray]


def run(out_dir: Path, seconds: float = 4.0, fps: int = 25, size: tuple[int, int] = (480, 360), render: bool = True) -> Outcome:
    """Simulate the scripted reach for ``seconds`` (model timestep), rendering at ``fps`` from a
    camera looking at the robot and its target."""
    import mujoco

    from layout.reach import simulate_reach

    m, d, arm, target, info = load(out_dir)
    frames: list[np.ndarray] = []
    on_step = None
    renderer = None
    if render:
        renderer = mujoco.Renderer(m, height=size[1], width=size[0])
        cam = mujoco.MjvCamera()
        base = d.xpos[m.site_bodyid[arm.site]]
        cam.lookat[:] = 0.5 * (base + target)
        cam.distance = 2.2 + 0.5 * float(np.linalg.norm(base[:2] - target[:2]))
        cam.azimuth = float(np.degrees(np.arctan2(target[1] - base[1], target[0] - base[0]))) - 120.0
        cam.elevation = -25.0
        frame_every = max(1, int(round(1.0 / (fps * m.opt.timestep))))

        def on_step(k: int) -> None:
            if k % frame_every == 0:
                renderer.update_scene(d, cam)
                frames.append(renderer.render().copy())

    try:
        result = simulate_reach(m, d, arm, target, seconds, on_step, info.get("hold_tool_axis", True))
    finally:
        if renderer is not None:
            renderer.close()
    return Outcome(result.final_error_m, result.min_error_m, result.contacts, frames)


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
    p.add_argument("--video", type=Path, help="video file, .mp4 or .gif (default SCENE_reach.mp4 beside the folder)")
    args = p.parse_args(argv)
    os.environ.setdefault("MUJOCO_GL", "egl")
    outcome = run(args.scene, args.seconds, args.fps)
    # Beside the output folder, not in it: a build replaces only a folder holding what it wrote.
    video = write_video(outcome.frames, args.video or Path(f"{args.scene}_reach.mp4"), args.fps)
    touched = f"{len(outcome.contacts)} contacts with the scene (first: {outcome.contacts[0]})" if outcome.contacts else "no contact with the scene"
    print(f"tool {outcome.final_error_m * 100:.1f} cm from the target at the end; {touched}; {len(outcome.frames)} frames -> {video}")
    return 0 if outcome.final_error_m <= REACH_TOL_M and not outcome.contacts else 1


if __name__ == "__main__":
    sys.exit(main())
