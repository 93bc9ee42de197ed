"""``--robot`` on the real RGB-D samples: where the robot stood, what its arm reached, how long.

Run: ``python -m scene_builder.bench.robot [--data ../shared/data] [--robot panda]``.

Every sample of ``DATA/real`` with aligned depth and a camera.json is built with ``--robot``
(the built-in model, so no download is timed; no URDF, glTF or rerun output), then the scripted
reach of :func:`layout.reach.simulate_reach` runs 4 s in MuJoCo from the home pose. Per sample:
objects (movable), the target's kind, support and height, whether the reach held the tool's axis, the robot's clearance on the floor plan,
seconds of the ``robot`` stage (model, placement candidates measured in MuJoCo, the physics check
again) and of the whole build, the tool's final distance to the target, and the robot-scene
contacts during the reach. Prints a Markdown table and the medians.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["main", "robot_rows"]

REACH_S = 4.0


def robot_rows(data: Path, robot: str) -> list[dict]:
    """One row per real sample (see the module docstring)."""
    import mujoco

    from layout.reach import arm_ids, reset_home, simulate_reach
    from scene_builder.config import BuildConfig, ExportConfig, InputSpec, RobotConfig
    from scene_builder.errors import SceneBuilderError
    from scene_builder.pipeline import build

    rows = []
    config = BuildConfig(export=ExportConfig(usd=True, urdf=False, gltf=False, viz="off"), robot=RobotConfig(robot, "built-in"))
    for src in sorted(p for p in (Path(data) / "real").iterdir() if (p / "camera.json").is_file() and (p / "depth.png").is_file()):
        cam = json.loads((src / "camera.json").read_text())
        rgb = next(src.glob("rgb.*"))
        inputs = InputSpec(rgb, src / "depth.png", 0.001, (cam["fx"], cam["fy"], cam["cx"], cam["cy"]))
        with tempfile.TemporaryDirectory() as tmp:
            try:
                result = build(inputs, Path(tmp) / "out", config)
            except SceneBuilderError as err:
                rows.append(dict(sample=src.name, error=str(err)))
                continue
            r = result.scene.robot
            timings = dict(result.timings_s)
            m = mujoco.MjModel.from_xml_path(str(result.files.mjcf))
            d = mujoco.MjData(m)
            arm = arm_ids(m, f"robot/{r.model.ee_site}", [f"robot/{j}" for j in r.model.arm_joints], r.model.home_qpos)
            reset_home(m, d, arm)
            reach = simulate_reach(m, d, arm, r.target_m, REACH_S, hold_tool_axis=r.hold_tool_axis)
        rows.append(dict(
            sample=src.name, objects=len(result.scene.objects), movable=sum(not o.asset.is_fixed for o in result.scene.objects),
            target_kind=r.target_kind, target_support=r.target_support, clearance_m=r.clearance_m,
            target_z_m=float(r.target_m[2]), hold_tool_axis=r.hold_tool_axis,
            robot_s=timings.get("robot", float("nan")), build_s=timings["total"], final_error_m=reach.final_error_m,
            contacts=len(reach.contacts), max_penetration_m=result.verdict.max_penetration_m, stable=result.verdict.stable,
        ))
    return rows


def render(rows: list[dict], robot: str) -> str:
    lines = [f"Robot `{robot}` (built-in), {len(rows)} samples.", "",
             "| sample | objects (movable) | target | target height (m) | tool axis | clearance (m) | robot stage (s) | build (s) | final error (cm) | contacts | max penetration (mm) | stable |",
             "|---|---|---|---:|---|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['sample']} | failed: {r['error']} | | | | | | | | | | |")
            continue
        lines.append(
            f"| {r['sample']} | {r['objects']} ({r['movable']}) | {r['target_kind']} of {r['target_support']} | {r['target_z_m']:.2f} | "
            f"{'held' if r['hold_tool_axis'] else 'free'} | {r['clearance_m']:.2f} | "
            f"{r['robot_s']:.1f} | {r['build_s']:.1f} | {r['final_error_m'] * 100:.2f} | {r['contacts']} | "
            f"{r['max_penetration_m'] * 1000:.2f} | {'yes' if r['stable'] else 'no'} |"
        )
    ok = [r for r in rows if "error" not in r]
    if ok:
        lines += ["", f"Median robot stage {np.median([r['robot_s'] for r in ok]):.1f} s of a median build of "
                      f"{np.median([r['build_s'] for r in ok]):.1f} s; median final error "
                      f"{np.median([r['final_error_m'] for r in ok]) * 100:.2f} cm; "
                      f"{sum(r['contacts'] == 0 and r['final_error_m'] <= 0.02 for r in ok)}/{len(rows)} reached within 2 cm without contact."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2].parent / "shared" / "data")
    p.add_argument("--robot", default="panda", help="panda or mobile_panda (default panda)")
    args = p.parse_args(argv)
    print(render(robot_rows(args.data, args.robot), args.robot))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
