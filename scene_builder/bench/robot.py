"""``--robot`` on the real RGB-D samples: where the robot stood, what its arm reached, how long.

Run: ``python -m scene_builder.bench.robot [--data ../shared/data] [--robot panda]``.

Every sample of ``DATA/real`` with a depth map (camera.json intrinsics where it has them, else
estimated, as ``scene-builder bench --suite real`` builds them) is built with ``--robot`` (the
built-in model, so no download is timed; no URDF, glTF or rerun output). Two figures per sample:

* The placement's own target: the scripted reach of :func:`layout.reach.simulate_reach` runs 4 s
  in MuJoCo from the home pose to the target the placement chose. The placement keeps only a
  spot whose kinematic sweep reaches its target, so this holds by construction; it is the
  control for the next figure.
* The reach rate over a fixed target set: :func:`layout.robot.reach_targets` puts a point 18 cm
  above every flat top of the scene on a 16 cm grid (one at least on each top), from the scene
  alone, before and whatever the placement; the targets within the arm's reach of its shoulder
  (its workspace) are each tried by the same 4 s simulated reach from the home pose, tool axis
  held, else free (:func:`layout.reach.score_reach`); a target counts as reached when the tool
  ends within 2 cm with no robot-scene contact. Rate = reached / targets in the workspace, per
  sample and over all samples, with the denominators.

Per sample also: objects (movable), the target's kind, support and height, whether the reach
held the tool's axis, the robot's clearance on the floor plan, seconds of the ``robot`` stage
(model, placement candidates measured in MuJoCo, the physics check again) and of the whole
build, the tool's final distance to the target and the robot-scene contacts during the reach.
Prints Markdown tables and the totals.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["main", "robot_rows"]

REACH_S = 4.0
MAX_CONTACTS = 20  # layout.reach.simulate_reach keeps the first 20 robot-scene contacts


def robot_rows(data: Path, robot: str) -> list[dict]:
    """One row per real sample (see the module docstring)."""
    import mujoco

    from layout.reach import SCORE_TOL_M, arm_ids, reset_home, score_reach, simulate_reach
    from layout.robot import reach_targets
    from scene_builder.config import BuildConfig, ExportConfig, InputSpec, RobotConfig
    from scene_builder.errors import SceneBuilderError
    from scene_builder.pipeline import build

    rows = []
    config = BuildConfig(export=ExportConfig(usd=True, urdf=False, gltf=False, viz="off"), robot=RobotConfig(robot, "built-in"))
    for src in sorted(p for p in (Path(data) / "real").iterdir() if (p / "depth.png").is_file()):
        k = None
        if (src / "camera.json").is_file():
            cam = json.loads((src / "camera.json").read_text())
            k = (cam["fx"], cam["fy"], cam["cx"], cam["cy"])
        rgb = next(src.glob("rgb.*"))
        inputs = InputSpec(rgb, src / "depth.png", 0.001, k)
        with tempfile.TemporaryDirectory() as tmp:
            try:
                result = build(inputs, Path(tmp) / "out", config)
            except SceneBuilderError as err:
                rows.append(dict(sample=src.name, error=f"{type(err).__name__}: {str(err).splitlines()[0]}"))
                continue
            r = result.scene.robot
            timings = dict(result.timings_s)
            m = mujoco.MjModel.from_xml_path(str(result.files.mjcf))
            d = mujoco.MjData(m)
            arm = arm_ids(m, f"robot/{r.model.ee_site}", [f"robot/{j}" for j in r.model.arm_joints], r.model.home_qpos)
            reset_home(m, d, arm)
            reach = simulate_reach(m, d, arm, r.target_m, REACH_S, hold_tool_axis=r.hold_tool_axis)
            # The fixed set is decided from the scene without the robot (as the placement sees it).
            points, owners = reach_targets(result.scene)
            t0 = time.perf_counter()
            scored = score_reach(result.files.mjcf, r, points, owners, REACH_S)
            score_s = time.perf_counter() - t0
        tried = [t for t in scored if t.in_workspace]
        rows.append(dict(
            sample=src.name, objects=len(result.scene.objects), movable=sum(not o.asset.is_fixed for o in result.scene.objects),
            target_kind=r.target_kind, target_support=r.target_support, clearance_m=r.clearance_m,
            target_z_m=float(r.target_m[2]), hold_tool_axis=r.hold_tool_axis,
            robot_s=timings.get("robot", float("nan")), build_s=timings["total"], final_error_m=reach.final_error_m,
            contacts=len(reach.contacts), max_penetration_m=result.verdict.max_penetration_m, stable=result.verdict.stable,
            targets=len(scored), in_workspace=len(tried), reached=sum(t.reached for t in tried),
            reached_free_axis=sum(t.reached and not t.hold_tool_axis for t in tried),
            missed=[dict(owner=t.owner, target_m=[round(float(v), 3) for v in t.target_m], error_m=t.final_error_m, contacts=t.contacts)
                    for t in tried if not t.reached],
            tops=sorted({t.owner for t in tried}), score_s=score_s, tol_m=SCORE_TOL_M,
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
                      f"{np.median([r['final_error_m'] for r in ok]) * 100:.2f} cm; the placement's own target (the control: the "
                      f"placement keeps only spots that reach it) reached within 2 cm without contact on "
                      f"{sum(r['contacts'] == 0 and r['final_error_m'] <= 0.02 for r in ok)} of {len(ok)} built samples"
                      + (f" ({len(rows) - len(ok)} not built)" if len(rows) > len(ok) else "") + "."]
        lines += ["", "Reach rate over the fixed target set (18 cm above every flat top, 16 cm grid; decided before the placement):", "",
                  "| sample | targets in the scene | in the workspace | reached | rate | with the tool's axis free | tops in the workspace | scoring (s) |",
                  "|---|---:|---:|---:|---:|---:|---|---:|"]
        for r in ok:
            rate = f"{r['reached'] / r['in_workspace']:.0%}" if r["in_workspace"] else "-"
            lines.append(f"| {r['sample']} | {r['targets']} | {r['in_workspace']} | {r['reached']} | {rate} | {r['reached_free_axis']} | "
                         f"{', '.join(r['tops']) or '-'} | {r['score_s']:.0f} |")
        n_ws, n_ok = sum(r["in_workspace"] for r in ok), sum(r["reached"] for r in ok)
        per = [r["reached"] / r["in_workspace"] for r in ok if r["in_workspace"]]
        lines += ["", f"Overall: {n_ok} of {n_ws} targets in the workspace reached ({n_ok / n_ws:.0%}) on {len(ok)} built samples "
                      f"({sum(r['targets'] for r in ok)} targets in all, {len(ok) - len(per)} samples with none in the workspace)"
                      + (f"; per-sample rate median {np.median(per):.0%}, range {min(per):.0%}-{max(per):.0%}" if per else "") + "."]
        missed = [(r["sample"], t) for r in ok for t in r["missed"]]
        if missed:
            lines += ["", "Targets missed (above which top, where; the tool's final distance, robot-scene contacts: "
                          f"the reach keeps the first {MAX_CONTACTS}):", ""]
            lines += [f"- {s}: above {t['owner']} at ({t['target_m'][0]:.2f}, {t['target_m'][1]:.2f}, {t['target_m'][2]:.2f}): "
                      f"{t['error_m'] * 100:.1f} cm off, {t['contacts']}{'+' if t['contacts'] >= MAX_CONTACTS else ''} contacts"
                      for s, t in missed]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2].parent / "shared" / "data")
    p.add_argument("--robot", default="panda", help="panda or mobile_panda (default panda)")
    p.add_argument("--json", type=Path, help="also write the rows here (to render them again: --render-json)")
    p.add_argument("--render-json", type=Path, help="render rows written by --json instead of building")
    args = p.parse_args(argv)
    if args.render_json is not None:
        rows = json.loads(args.render_json.read_text())
    else:
        rows = robot_rows(args.data, args.robot)
        if args.json is not None:
            args.json.write_text(json.dumps(rows, indent=1, default=float) + "\n")
    print(render(rows, args.robot))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
