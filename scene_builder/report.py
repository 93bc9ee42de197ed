"""``report.json`` and ``scene.json``: what a build made, how long each stage took, which backend
answered each task, and the physics verdict measured in MuJoCo."""

from __future__ import annotations

import json
import platform
from pathlib import Path

import numpy as np

from scene_builder import __version__
from scene_builder.config import BuildConfig, InputSpec, LayoutConfig
from scene_builder.frames import yaw_of
from scene_builder.model import Fidelity, GeneratedAsset, LayoutResult, Perception, PhysicsVerdict, Scene
from scene_builder.serialize import scene_to_json

REPORT_FORMAT = "scene-builder/report"


def _r(x: float, nd: int = 6) -> float:
    return float(round(float(x), nd))


def build_report(
    inputs: InputSpec,
    config: BuildConfig,
    perception: Perception,
    layout: LayoutResult,
    scene: Scene,
    verdict: PhysicsVerdict,
    fidelity: Fidelity | None,
    timings_s: tuple[tuple[str, float], ...],
    generated: tuple[GeneratedAsset, ...] = (),
    first_verdict: PhysicsVerdict | None = None,
) -> dict:
    """The report as JSON-ready data (the file format; not passed between stages).

    ``generated`` (the generation stage's output) lets ``generation_failures`` name every object
    the preferred generator failed on, also those the layout later kept as static background
    (``became_background``); without it only the objects in ``scene`` are listed."""
    k = perception.observation.intrinsics
    perceived = {o.name: o for o in perception.objects}
    verdicts = {v.name: v for v in verdict.objects}
    placements = {p.name: p for p in layout.placements}
    objects = []
    for placed in scene.objects:
        a = placed.asset
        obs = perceived.get(a.name)
        v = verdicts.get(a.name)
        joints = [
            {"part": p.name, "type": p.joint.type.value, "lower": _r(p.joint.lower), "upper": _r(p.joint.upper)}
            for p in a.parts
            if p.joint is not None
        ]
        objects.append(
            {
                "name": a.name,
                "label": a.label,
                "label_confidence": _r(obs.label_confidence, 3) if obs else None,
                "kind": a.kind.value,
                "fixed": a.is_fixed,
                "size_m": [_r(s, 4) for s in a.size_m],
                "mass_kg": _r(a.mass_kg, 4),
                "position_m": [_r(x, 4) for x in placed.world_from_asset[:3, 3]],
                "yaw_deg": _r(np.degrees(yaw_of(placed.world_from_asset[:3, :3])), 2),
                "support": placed.support,
                "displacement_m": _r(placements[a.name].displacement_m, 4) if a.name in placements else None,
                "yaw_change_deg": _r(placements[a.name].yaw_change_deg, 2) if a.name in placements else None,
                "moved_because": placements[a.name].reason if a.name in placements else "",
                "became_background": False,
                "parts": len(a.parts),
                "collision_pieces": int(sum(len(p.collision) for p in a.parts)),
                "materials": sorted({p.material.name for p in a.parts}),
                "joints": joints,
                "generator": a.backend,
                "generator_fallback_reason": a.fallback_reason or None,
                "physics": None
                if v is None
                else {
                    "start_penetration_m": _r(v.start_penetration_m),
                    "drift_m": _r(v.drift_m),
                    "rotation_deg": _r(v.rotation_deg, 3),
                    "toppled": v.toppled,
                    "end_penetration_m": _r(v.end_penetration_m),
                },
            }
        )
    # Objects that could not stand where they were seen and became static background.
    made = {g.asset.name: g.asset for g in generated}
    for p in layout.placements:
        if p.became_background:
            obs = perceived.get(p.name)
            asset = made.get(p.name)
            objects.append({"name": p.name, "label": obs.label if obs else None, "became_background": True, "support": "none",
                            "displacement_m": 0.0, "moved_because": p.reason,
                            "generator": asset.backend if asset else None,
                            "generator_fallback_reason": (asset.fallback_reason or None) if asset else None})
    moved = [p.displacement_m for p in layout.placements if not p.became_background]
    lowered = sum(1 for p in layout.placements if p.lowered_m > 0.10)
    timings = {name: _r(s, 3) for name, s in timings_s}
    background = {p.name for p in layout.placements if p.became_background}
    assets = list(made.values()) or [o.asset for o in scene.objects]
    failures = [
        {"object": a.name, "answered_by": a.backend, "reason": a.fallback_reason, "became_background": a.name in background}
        for a in sorted(assets, key=lambda a: a.name)
        if a.fallback_reason
    ]
    return {
        "format": REPORT_FORMAT,
        "version": __version__,
        "input": {
            "image": str(inputs.image_path),
            "depth": None if inputs.depth_path is None else str(inputs.depth_path),
            "depth_source": perception.observation.depth_source,
            "image_size_px": [k.width_px, k.height_px],
            "intrinsics": {"fx": _r(k.fx_px, 3), "fy": _r(k.fy_px, 3), "cx": _r(k.cx_px, 3), "cy": _r(k.cy_px, 3), "source": k.source},
            "camera_height_m": _r(perception.camera.position_m[2], 4),
        },
        "seed": config.seed,
        "backends": [{"task": b.task, "backend": b.backend, "reason": b.reason} for b in perception.backends]
        + [_generation_use(b, scene) for b in sorted({o.asset.backend for o in scene.objects})]
        + ([{"task": "robot", "backend": scene.robot.model.source, "reason": scene.robot.model.detail}] if scene.robot else []),
        "generation_failures": failures,
        "timings_s": timings,
        "object_fates": object_fates(perception, layout, scene, first_verdict, verdict, config.layout),
        "objects": objects,
        "layout": {
            "max_penetration_m": _r(verdict.max_penetration_m, 7),
            "settle_max_drift_m": _r(verdict.settle_max_drift_m, 7),
            "settle_max_rotation_deg": _r(verdict.settle_max_rotation_deg, 4),
            "simulated_s": verdict.simulated_s,
            "stable": verdict.stable,
            "max_penetration_settled_m": _r(verdict.max_penetration_settled_m, 7),
            "movable_objects": verdict.movable_count,
            "fixed_objects": verdict.fixed_count,
            "background_objects": sum(1 for p in layout.placements if p.became_background),
            "displacement_m": {"median": _r(float(np.median(moved)), 4), "max": _r(float(np.max(moved)), 4)} if moved else None,
            "lowered_over_10cm": lowered,
            "solver_iterations": layout.iterations,
            "max_penetration_before_solver_m": _r(layout.max_penetration_before_m, 7),
            "support": [{"child": e.child, "parent": e.parent} for e in layout.support],
            "walls": len(scene.room.walls),
        },
        "fidelity": None
        if fidelity is None
        else {
            "psnr_db": _r(fidelity.psnr_db, 3),
            "ssim": _r(fidelity.ssim, 4),
            "psnr_settled_db": _r(fidelity.psnr_settled_db, 3),
            "ssim_settled": _r(fidelity.ssim_settled, 4),
            "depth_absrel": _r(fidelity.depth_absrel, 5),
            "depth_absrel_settled": _r(fidelity.depth_absrel_settled, 5),
            "object_depth_absrel": _r(fidelity.object_depth_absrel, 5),
            "mask_iou_mean": _r(fidelity.mask_iou_mean, 5),
            "mask_iou": {name: _r(iou, 4) for name, iou in fidelity.mask_iou},
        },
        "robot": robot_report(scene),
        "machine": {"python": platform.python_version(), "platform": platform.platform()},
    }


def _reason_class(reason: str) -> str:
    """The kind of a background reason, for counting: its first clause without the numbers."""
    import re

    head = reason.split(":")[0].split(";")[0].strip()
    head = re.sub(r"\(.*?\)", "", head)
    head = re.sub(r"\d+(\.\d+)?", "N", head)
    return re.sub(r"\s+", " ", head).strip()


def object_fates(perception: Perception, layout: LayoutResult, scene: Scene, first_verdict: PhysicsVerdict | None = None,
                 verdict: PhysicsVerdict | None = None, bounds: LayoutConfig = LayoutConfig()) -> dict:
    """What became of every object perception found, with the denominators named: perceived =
    movable + fixed_with_joints + fixed + background; interactive = movable + fixed_with_joints
    (a robot can act on them); background_by_reason counts the reasons; left_out_behind_walls:
    instances perception left out for lying behind a wall (not among the perceived: in the next
    room, or past a wall's end where the room turns); left_out_unmeasured: instances left out for
    too little measured depth on them (not among the perceived either). ``first_verdict``: the
    physics check before any object became background in the settle rounds (the layout may
    already have kept some where seen); ``verdict``: the final one. Rest and penetration are
    given over the perceived objects (an object that became background is not at rest: it is
    not an object any more) and over the kept ones; at rest means within ``bounds``'
    stable_drift_m and stable_rotation_deg."""
    names = [o.name for o in perception.objects]
    placed = {o.name: o for o in scene.objects}
    movable = [n for n in names if n in placed and not placed[n].asset.is_fixed]
    with_joints = [n for n in names if n in placed and placed[n].asset.is_fixed and any(p.joint is not None for p in placed[n].asset.parts)]
    fixed = [n for n in names if n in placed and n not in movable and n not in with_joints]
    background = [p for p in layout.placements if p.became_background]
    by_reason: dict[str, int] = {}
    for p in background:
        k = _reason_class(p.reason)
        by_reason[k] = by_reason.get(k, 0) + 1
    out = {
        "perceived": len(names),
        "interactive": len(movable) + len(with_joints),
        "movable": len(movable),
        "fixed_with_joints": len(with_joints),
        "fixed": len(fixed),
        "background": len(background),
        "background_by_reason": dict(sorted(by_reason.items(), key=lambda kv: (-kv[1], kv[0]))),
        "interactive_share_of_perceived": _r(len(movable + with_joints) / len(names), 4) if names else None,
        "left_out_behind_walls": int(perception.left_out_behind_walls),
        "left_out_unmeasured": int(perception.left_out_unmeasured),
    }
    if verdict is not None:
        at_rest = sum(1 for v in verdict.objects if not v.fixed and v.name in movable and v.drift_m <= bounds.stable_drift_m and v.rotation_deg <= bounds.stable_rotation_deg)
        out["at_rest"] = at_rest
        out["at_rest_share_of_perceived"] = _r(at_rest / len(names), 4) if names else None
        out["at_rest_share_of_movable"] = _r(at_rest / len(movable), 4) if movable else None
        out["max_penetration_m"] = _r(verdict.max_penetration_m, 7)
    if first_verdict is not None:
        fv = [v for v in first_verdict.objects if not v.fixed]
        out["first_check"] = {
            "simulated_objects": len(fv),
            "at_rest": sum(1 for v in fv if v.drift_m <= bounds.stable_drift_m and v.rotation_deg <= bounds.stable_rotation_deg),
            "max_penetration_m": _r(first_verdict.max_penetration_m, 7),
            "max_start_penetration_m": _r(max((v.start_penetration_m for v in fv), default=0.0), 7),
            "max_drift_m": _r(first_verdict.settle_max_drift_m, 7),
            "max_rotation_deg": _r(first_verdict.settle_max_rotation_deg, 4),
        }
    return out


def fates_line(f: dict) -> str:
    """One line: ``9 perceived: 6 movable, 1 fixed with joints, 0 fixed, 2 background (hangs 1, ...)``."""
    why = ", ".join(f"{k} {n}" for k, n in f["background_by_reason"].items())
    behind = f.get("left_out_behind_walls", 0)
    unmeasured = f.get("left_out_unmeasured", 0)
    return (f"{f['perceived']} perceived: {f['movable']} movable, {f['fixed_with_joints']} fixed with joints, {f['fixed']} fixed, "
            f"{f['background']} background" + (f" ({why})" if why else "") + (f"; {behind} left out behind walls" if behind else "")
            + (f"; {unmeasured} left out with too little depth on them" if unmeasured else ""))


def _generation_use(backend: str, scene: Scene) -> dict:
    """The generation entry of ``backends`` for one generator: how many objects it made, and for
    how many of them it stood in for a generator that failed."""
    made = [o.asset for o in scene.objects if o.asset.backend == backend]
    fell_back = [a.name for a in made if a.fallback_reason]
    reason = f"{len(made)} objects"
    if fell_back:
        reason += f"; fallback for {len(fell_back)} the preferred generator failed on ({', '.join(fell_back)}; see generation_failures)"
    return {"task": "generation", "backend": backend, "reason": reason}


def robot_report(scene: Scene) -> dict | None:
    """Where the robot stands and what drives it (MJCF names, with the ``robot/`` prefix)."""
    r = scene.robot
    if r is None:
        return None
    m = r.model
    return {
        "name": m.name,
        "source": m.source,
        "detail": m.detail,
        "position_m": [_r(float(v), 4) for v in r.position_m],
        "yaw_rad": _r(r.yaw_rad, 5),
        "clearance_m": _r(r.clearance_m, 4),
        "target_m": [_r(float(v), 4) for v in r.target_m],
        "target_support": r.target_support,
        "target_kind": r.target_kind,
        "hold_tool_axis": r.hold_tool_axis,
        "ee_site": f"robot/{m.ee_site}",
        "arm_joints": [f"robot/{j}" for j in m.arm_joints],
        "base_joints": [f"robot/{j}" for j in m.base_joints],
        "home_qpos": [_r(float(v), 5) for v in m.home_qpos],
        "reach_m": _r(m.reach_m, 4),
        "footprint_radius_m": _r(m.footprint_radius_m, 4),
    }


def write_report(out_dir: Path, scene: Scene, report: dict) -> Path:
    """Write ``scene.json`` and ``report.json`` (from :func:`build_report`) into ``out_dir``;
    returns the report's path."""
    (out_dir / "scene.json").write_text(scene_to_json(scene))
    path = out_dir / "report.json"
    path.write_text(json.dumps(report, indent=2) + "\n")
    return path
