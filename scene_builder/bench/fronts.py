"""Door and drawer fronts of built scenes against the hand count (issue 24).

Every photo of ``tests/data/fronts_annotation.json`` (the URDFormer cabinet photos, the kitchens of
``photos_gt``, the SUN RGB-D bedrooms of ``real``: a person's count of the doors and drawers seen,
with their rectangles, written by looking at the photos) is built with the default configuration
(RGB-D samples with their depth and camera.json, as ``scene-builder bench --suite real`` builds
them), and again with ``PerceptionConfig.fronts`` off: the control, where articulated furniture
gets its category template's doors and drawers and the built-ins stay on the background.

    .venv/bin/python -m scene_builder.bench.fronts [--data ../shared/data] [--only NAME ...] [--no-control] [--no-probe]

Per photo: the built fronts (every part on a revolute or prismatic joint named ``door*``,
``drawer*`` or ``flap*``, of every object) projected into the photo as the bounding rectangle of
the part's front face at its placed pose; one-to-one matching (Hungarian) to the hand-counted
rectangles, a match when IoU >= 0.5; recall = matched / hand-counted, precision = matched / built;
of the matched, how many move as the hand count's kind does (a drawer slides; a door, an appliance
door or a flap turns on a hinge).
Then every built front's joint is pulled open (``layout.interaction.open_joint``, as ``scene-builder
check --interact``): the share that opens fully (``layout.interaction.opens_fully``: 90 % of its
range, within its limits, the carcass still). Also the built-in runs (fixed objects with front
joints), and the build's wall and CPU seconds (the machine's 2 cores are shared: see the load).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
DEFAULT_DATA = REPO.parent / "shared" / "data"
ANNOTATION = REPO / "tests" / "data" / "fronts_annotation.json"
MATCH_IOU = 0.5
FRONT_NAMES = ("door", "drawer", "flap")

__all__ = ["ANNOTATION", "MATCH_IOU", "SWINGS", "built_fronts", "iou", "joint_kind", "kinds_right", "main", "match_count", "match_pairs", "seen_rectangle"]


def iou(a, b) -> float:
    """IoU of two (x0, y0, x1, y1) rectangles."""
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def match_pairs(built: list, truth: list, min_iou: float = MATCH_IOU) -> list[tuple[int, int]]:
    """(built index, truth index) of the pairs a one-to-one assignment (Hungarian, on IoU) of
    ``truth`` rectangles to ``built`` ones matches at IoU >= ``min_iou``."""
    from scipy.optimize import linear_sum_assignment

    if not built or not truth:
        return []
    m = np.array([[iou(b, t) for t in truth] for b in built])
    rows, cols = linear_sum_assignment(-m)
    return [(int(r), int(c)) for r, c in zip(rows, cols) if m[r, c] >= min_iou]


def match_count(built: list, truth: list, min_iou: float = MATCH_IOU) -> int:
    """How many of ``truth`` rectangles :func:`match_pairs` matches."""
    return len(match_pairs(built, truth, min_iou))


#: The hand count's kinds by how they move: a door and an appliance door (an oven's or a
#: refrigerator's) turn on a hinge, a drawer slides.
SWINGS = {"door": "hinge", "appliance_door": "hinge", "drawer": "slide"}


def joint_kind(part_name: str) -> str:
    """``"slide"`` for a built drawer, ``"hinge"`` for a door or a flap (by the part's name)."""
    return "slide" if "drawer" in part_name.lower() else "hinge"


def kinds_right(fronts: list, truth_kinds: list[str], pairs: list[tuple[int, int]]) -> int:
    """How many matched pairs move the way the hand count says (hinge or slide)."""
    return sum(joint_kind(fronts[b][1]) == SWINGS.get(truth_kinds[t], "") for b, t in pairs)


def is_front(part) -> bool:
    """A part that is a door, drawer or flap front (on a revolute or prismatic joint)."""
    from scene_builder.model import JointType

    name = part.name.lower()
    return part.joint is not None and part.joint.type in (JointType.REVOLUTE, JointType.PRISMATIC) and any(k in name for k in FRONT_NAMES)


def seen_rectangle(px: np.ndarray, photo_size: tuple[int, int]) -> tuple[float, float, float, float]:
    """(x0, y0, x1, y1): the bounding rectangle of the (N, 2) pixels ``px`` clipped to the photo
    of ``photo_size`` (w, h). The hand count outlines a front the photo's edge cuts (a dresser at
    the right edge, wall cabinets at the top) as far as it is seen; a front wholly outside keeps
    an empty rectangle on the edge (built, matching nothing)."""
    size = np.asarray(photo_size, dtype=np.float64)
    lo, hi = np.clip(px.min(axis=0), 0.0, size), np.clip(px.max(axis=0), 0.0, size)
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def built_fronts(scene, photo_size: tuple[int, int]) -> list[tuple[str, str, tuple[float, float, float, float]]]:
    """[(object, part, (x0, y0, x1, y1) in the photo's pixels at ``photo_size`` (w, h))] of every
    front part of ``scene``: the bounding rectangle of the part's front face (its visual
    vertices within 2.5 cm of its largest x, the asset's front) at the placed pose, clipped to
    the photo (a front wholly outside it keeps an empty rectangle on the edge: built, unmatched)."""
    from scene_builder.frames import transform_points

    k = scene.camera.intrinsics
    sx = photo_size[0] / k.width_px
    camera_from_world = np.linalg.inv(scene.camera.world_from_camera)
    out = []
    for obj in scene.objects:
        for part in obj.asset.parts:
            if not is_front(part):
                continue
            v = part.visual.vertices_m
            front = v[v[:, 0] >= v[:, 0].max() - 0.025]
            pc = transform_points(camera_from_world @ obj.world_from_asset, front)
            if np.any(pc[:, 2] <= 0.05):
                continue
            px = k.project(pc) * sx
            out.append((obj.name, part.name, seen_rectangle(px, photo_size)))
    return out


def sample_inputs(src: Path):
    """The InputSpec of a shared sample folder: ``rgb.jpg`` / ``rgb.png``, with ``depth.png``
    (millimetres) and ``camera.json`` (fx, fy, cx, cy) when it has them."""
    from scene_builder.config import InputSpec

    rgb = next(p for p in (src / "rgb.jpg", src / "rgb.png") if p.exists())
    if (src / "depth.png").exists():
        k = None
        if (src / "camera.json").exists():
            cam = json.loads((src / "camera.json").read_text())
            k = (cam["fx"], cam["fy"], cam["cx"], cam["cy"])
        return InputSpec(rgb, src / "depth.png", 0.001, k)
    return InputSpec(rgb)


def _build(src: Path, out: Path, fronts: bool):
    """(BuildResult, wall s, CPU s of this process) of ``src`` built into ``out``."""
    from dataclasses import replace

    from scene_builder.config import BuildConfig, ExportConfig
    from scene_builder.pipeline import build

    cfg = BuildConfig(export=ExportConfig(usd=False, urdf=False, gltf=False, viz="off"))
    cfg = replace(cfg, perception=replace(cfg.perception, fronts=fronts))
    r0 = resource.getrusage(resource.RUSAGE_SELF)
    t0 = time.perf_counter()
    result = build(sample_inputs(src), out, cfg)
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    return result, time.perf_counter() - t0, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def _probe(mjcf: Path, fronts: list) -> tuple[int, int, list[str]]:
    """(opened fully, pulled, failures) over the joints of ``fronts``."""
    from layout.interaction import load_probe_model, open_joint, opens_fully

    if not fronts:
        return 0, 0, []
    m = load_probe_model(mjcf)
    ok, fails = 0, []
    for obj, part, _ in fronts:
        j = open_joint(m, f"{obj}/{part}/joint")
        if opens_fully(j):
            ok += 1
        else:
            fails.append(f"{j.joint}: {j.open_fraction:.0%} of its range, {j.limit_violation:.3f} beyond, carcass {j.body_displacement_m * 1000:.1f} mm")
    return ok, len(fronts), fails


def main(argv: list[str] | None = None) -> int:
    from scene_builder.errors import SceneBuilderError

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the shared data folder (default ../shared/data)")
    ap.add_argument("--only", nargs="*", default=None, help="photo folder names to run (default: every annotated photo)")
    ap.add_argument("--no-control", action="store_true", help="skip the control builds (category templates, no built-ins)")
    ap.add_argument("--no-probe", action="store_true", help="skip pulling the built fronts open")
    args = ap.parse_args(argv)
    ann = json.loads(ANNOTATION.read_text())["photos"]
    rows, fails, not_built = [], [], []
    totals: dict[str, list[int]] = {}  # group -> [truth, built, matched, built control, matched control]
    probe = [0, 0]
    times, cpus = [], []
    kitchens: dict[str, int] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for key, photo in ann.items():
            name = key.split("/")[-1]
            if args.only and name not in args.only:
                continue
            src = args.data / key
            truth = [f["box_xyxy_px"] for f in photo["fronts"]]
            size = tuple(photo["size"])
            try:
                result, wall, cpu = _build(src, Path(tmp) / name, True)
            except SceneBuilderError as err:
                not_built.append(f"{name}: {type(err).__name__}: {str(err).splitlines()[0]}")
                continue
            fronts = built_fronts(result.scene, size)
            pairs = match_pairs([b for _, _, b in fronts], truth)
            matched = len(pairs)
            right = kinds_right(fronts, [f["kind"] for f in photo["fronts"]], pairs)
            runs = sorted({o for o, _, _ in fronts if result.scene.object(o).asset.is_fixed and o.startswith("built_in")})
            opened, pulled, pf = (0, 0, []) if args.no_probe else _probe(result.files.mjcf, fronts)
            probe[0] += opened
            probe[1] += pulled
            fails += [f"{name}: {f}" for f in pf]
            times.append(wall)
            cpus.append(cpu)
            c_built, c_matched = "-", "-"
            if not args.no_control:
                control, _, _ = _build(src, Path(tmp) / f"{name}_control", False)
                cf = built_fronts(control.scene, size)
                c_built, c_matched = len(cf), match_count([b for _, _, b in cf], truth)
            group = photo["scene"]
            t = totals.setdefault(group, [0, 0, 0, 0, 0, 0])
            t[0] += len(truth)
            t[1] += len(fronts)
            t[2] += matched
            t[5] += right
            if not args.no_control:
                t[3] += c_built
                t[4] += c_matched
            if group == "kitchen":
                kitchens[name] = sum(1 for o in runs if any(ob == o for ob, _, _ in fronts))
            rows.append(f"| {name} | {group} | {len(truth)} | {len(fronts)} | {matched} | {right} | {c_built} | {c_matched} | {len(runs)} "
                        f"| {opened}/{pulled} | {wall:.1f} | {cpu:.1f} |")
    print(f"Load average at the end: {' / '.join(f'{v:.1f}' for v in os.getloadavg())} (2 cores shared with other work).")
    print()
    print("| photo | scene | hand-counted fronts | built fronts | matched (IoU >= 0.5) | matched, joint kind right | control: built | control: matched | built-in runs | opened fully / pulled | build s (wall) | build s (CPU) |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    print("\n".join(rows))
    print()
    print("| photos | hand-counted | built | matched | recall | precision | joint kind right (of matched) | control recall | control precision |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    all_t = [sum(t[i] for t in totals.values()) for i in range(6)]
    for group, t in list(totals.items()) + [("all", all_t)]:
        rec = f"{t[2]}/{t[0]} = {t[2] / t[0]:.2f}" if t[0] else "-"
        prec = f"{t[2]}/{t[1]} = {t[2] / t[1]:.2f}" if t[1] else "-"
        crec = f"{t[4]}/{t[0]} = {t[4] / t[0]:.2f}" if t[0] and not args.no_control else "-"
        cprec = f"{t[4]}/{t[3]} = {t[4] / t[3]:.2f}" if t[3] and not args.no_control else "-"
        kind = f"{t[5]}/{t[2]}" if t[2] else "-"
        print(f"| {group} | {t[0]} | {t[1]} | {t[2]} | {rec} | {prec} | {kind} | {crec} | {cprec} |")
    print()
    if probe[1]:
        print(f"Probe: {probe[0]} of {probe[1]} built doors and drawers open fully = {probe[0] / probe[1]:.0%} "
              "(90 % of their range or more, within their limits, the carcass still).")
    if kitchens:
        print(f"Kitchen photos with at least one built-in run with fronts: {sum(v > 0 for v in kitchens.values())} of {len(kitchens)}.")
    if times:
        print(f"Build time, median over {len(times)} photos: {np.median(times):.1f} s wall, {np.median(cpus):.1f} s CPU (max {max(times):.1f} s wall).")
    if not_built:
        print("Not built: " + "; ".join(not_built))
    if fails:
        print()
        print("\n".join(f"- {f}" for f in fails))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
