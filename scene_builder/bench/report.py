"""Render bench JSON files as Markdown: ``python -m scene_builder.bench.report bench.json real.json [--extras] > BENCHMARKS.md``.

For each file: the exact command, machine and date, the pipeline-versus-baseline summary table,
median seconds per stage, and one row per scene; then the metric definitions once. With
``--extras``, the stage benchmark scripts (:data:`EXTRAS`: layout solver scaling, generation
timings and physics errors, PhysX token counts, depth backends) are run, each in its own process
with this interpreter, and their output is pasted under its exact command, date and wall time.
"""

from __future__ import annotations

import datetime
import json
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from scene_builder.bench.suites import DEFINITIONS, SUMMARY_ROWS, format_value
from scene_builder.errors import InputError

__all__ = ["EXTRAS", "Extra", "main", "render", "render_extra", "run_extra"]


@dataclass(frozen=True)
class Extra:
    """A stage benchmark script: its section title, what it measures, the arguments after
    ``python`` that run it, and whether it prints Markdown (else its output goes in a code block)."""

    title: str
    about: str
    argv: tuple[str, ...]
    markdown: bool = False
    timeout_s: float = 900.0


EXTRAS: tuple[Extra, ...] = (
    Extra(
        "Layout solver scaling",
        "Random clutter of boxes, tables and convex pieces dropped overlapping (`scene_builder.bench.clutter.clutter`), solved to no "
        "penetration: wall and CPU seconds, iterations, penetration before / after, CPU seconds by phase.",
        ("-m", "scene_builder.bench.solver"),
    ),
    Extra(
        "Generation: per-object timings and physics against analytic solids",
        "One asset per vocabulary category from synthetic half-observed points (`scene_builder.bench.assets`): kind, parts, collision "
        "pieces, mass, seconds per object; then the voxel path (completion, meshing, CoACD).",
        ("-m", "scene_builder.bench.assets"),
        markdown=True,
    ),
    Extra(
        "PhysX token counts and encode / decode times",
        "Voxel parts of the PhysX-Anything representation under each encoding (`scene_builder.bench.tokens`): units and "
        "Qwen tokens, milliseconds to encode and decode.",
        ("-m", "scene_builder.bench.tokens"),
        markdown=True,
    ),
    Extra(
        "Depth backends",
        "Every available depth backend on the real RGB-D samples (`scene_builder.bench.depth`): AbsRel, delta1 (metric and median "
        "scaled), seconds and memory per image. Learned backends appear only where their weights are installed.",
        ("-m", "scene_builder.bench.depth"),
    ),
    Extra(
        "Single photo: depth and perception time",
        "The real RGB-D samples used as plain photos, their depth only for scoring (`scene_builder.bench.single_photo`): "
        "AbsRel and delta1 of single-photo depth per sample with their median, against a constant 2.5 m, with no weights and "
        "with the COCO detector's objects of known size; then `perceive` seconds per photo for every suite (plain photos, "
        "real samples plain and RGB-D, a 12 MP upscaled photo plain and RGB-D) with the slowest named.",
        ("-m", "scene_builder.bench.single_photo", "--large"),
        markdown=True,
    ),
    Extra(
        "Learned backends at their published size",
        "Depth Anything V2 Small, SAM 2 Hiera-Tiny and Grounding DINO Swin-T built from their published architectures with random "
        "weights and run through the project's backends on a real 640 x 480 photo (`scene_builder.bench.learned`): CPU and wall "
        "seconds, peak memory. Compute does not depend on the weights' values; no weights reach these machines.",
        ("-m", "scene_builder.bench.learned"),
        markdown=True,
        timeout_s=2400.0,  # 1500 s wall on 2026-11-24 under load, before Grounding DINO (about 420 s more under load)
    ),
    Extra(
        "Segmentation and naming on procedural rooms",
        "The default (best available) segmentation and naming backends on rendered procedural rooms with ground-truth "
        "instances (`scene_builder.bench.perception`; `--segmentation NAME`, `--naming NAME` pick others): object recall "
        "at mask IoU 0.5, mean best IoU, category accuracy of the matched objects, seconds of `perceive` per frame. "
        "Here only `depth-clusters` segmentation is available: SAM2 needs its weights.",
        ("-m", "scene_builder.bench.perception"),
    ),
    Extra(
        "Detection-driven instances on real photos used as plain photos",
        "Every photo of `../shared/data/photos` and `../shared/data/real` without its depth map, with the offline "
        "detectors of `../shared/models` (`scene_builder.bench.detect`): objects and movable objects per photo, category "
        "recall and precision against the hand-made inventory `tests/data/photo_inventory.json`, the SUN RGB-D "
        "ground-truth boxes' labels, seconds of `perceive` per photo (the slowest named).",
        ("-m", "scene_builder.bench.detect"),
    ),
    Extra(
        "Offline detectors",
        "CenterNet, NanoDet and the SSD alone and merged (`scene_builder.bench.detectors`): box recall and precision at IoU "
        "0.5 against the COCO boxes of `../shared/data/photos_gt` (COCO train photos: flattering for both COCO detectors), "
        "instance and category recall / precision against the hand-made inventory of `../shared/data/photos`, per threshold "
        "on the merged scale; scores of true and of certainly false detections; each accept_score varied; CPU seconds per "
        "photo; NanoDet's decoding against one wrong choice at a time.",
        ("-m", "scene_builder.bench.detectors"),
        markdown=True,
    ),
    Extra(
        "Offline detectors in the pipeline",
        "`perceive` with the `detections` segmenter on the 15 inventory photos (`scene_builder.bench.detectors --pipeline`) "
        "per detector setting: NanoDet added (off by default), `FLOOR_SCORE` and each detector's accept_score varied; "
        "instance and category recall / precision against the inventory and the labels gained and lost per photo; then the "
        "real RGB-D photos used as plain photos against `tests/data/real_inventory.json`, with and without NanoDet.",
        ("-m", "scene_builder.bench.detectors", "--pipeline", "both"),
        markdown=True,
        timeout_s=5400.0,
    ),
    Extra(
        "Batch throughput: many photos on one machine and on Ray",
        "`scene-builder batch` over 20 real RGB-D photos downscaled to 320 px wide (`scene_builder.bench.batch`) with 1 and "
        "2 local workers and on a local Ray cluster: scenes per minute, overhead per item, worker warm-up, peak memory per "
        "worker, the machine's load average; one full-size photo to scale up; what 10,000 photos cost on 100 nodes.",
        ("-m", "scene_builder.bench.batch"),
        markdown=True,
        timeout_s=1800.0,
    ),
    Extra(
        "Interaction probes on built real scenes",
        "Every real RGB-D sample with a depth map and every URDFormer cabinet photo built as `scene-builder bench` builds them, "
        "then (`scene_builder.bench.interaction`, as `scene-builder check OUT --interact`) every movable object pushed 6 cm past "
        "contact by a pusher limited to 100 N that collides with everything, and every door and drawer pulled open by a "
        "hand-like pull: the push success rate over every movable object with each failure's reason (no room for the pusher, "
        "blocked, too heavy, fell, moved another object), how far passing pushes moved their object, how far anything else "
        "moved, tilt; share of each joint's range opened, excursion beyond its limits, carcass motion. The same scenes probed "
        "again at 250 N (a two-handed push) show which failures are the force limit.",
        ("-m", "scene_builder.bench.interaction", "--force-n", "100", "250"),
        markdown=True,
        timeout_s=3600.0,
    ),
    Extra(
        "Output folder: what the marker's hashes cost",
        "Real RGB-D samples built with every output (`scene_builder.bench.outdir`): files and MB written, build seconds, "
        "seconds to hash them into the marker `.scene-builder` and to hash them again when a rebuild checks the folder, "
        "beside reading them without hashing.",
        ("-m", "scene_builder.bench.outdir"),
        markdown=True,
    ),
    Extra(
        "The objects against ground truth",
        "The interactive objects of builds (movable, or fixed with joints) against annotations made by people "
        "(`scene_builder.bench.groundtruth`): SUN RGB-D 3D boxes with and without depth, COCO instance masks of plain photos "
        "(silhouettes rendered from input_camera), the hand-made inventory of the real RGB-D photos; each beside the control "
        "'everything background' (the same build with no object), which scores 0; then what became of every perceived "
        "object (interactive, fixed, background) and build seconds. Writes bench_results/groundtruth.json, from which the "
        "README's table is generated. About 40 minutes on 2 cores.",
        ("-m", "scene_builder.bench.groundtruth", "--json", "bench_results/groundtruth.json", "--markdown"),
        markdown=True,
        timeout_s=5400.0,
    ),
    Extra(
        "Parser fuzzing",
        "Every parser of outside data (`scene_builder.bench.fuzz`): PhysX geometry token decoders (strict and lenient), the "
        "PhysX text protocol, basic_info.json, scene.json, depth, camera.json and image files, on mutated real seeds. "
        "`rejected` = the parser's documented error; a crash is any other exception. The slowest input bounds the time "
        "one input can take. About 40 minutes on 2 cores.",
        ("-m", "scene_builder.bench.fuzz", "--n", "100000"),
        markdown=True,
        timeout_s=5400.0,
    ),
    Extra(
        "A robot in the real scenes (`--robot panda`)",
        "Every real RGB-D sample built with the built-in Franka Panda (`scene_builder.bench.robot`): the target the "
        "placement chose, the robot's clearance, seconds of the `robot` stage and of the build, then 4 s of the scripted "
        "reach in MuJoCo: the tool's final distance to the target and the robot-scene contacts (the control: the placement "
        "keeps only spots that reach their target); then the reach rate over a fixed target set decided before the "
        "placement (18 cm above every flat top on a 16 cm grid): the share of those in the arm's workspace that the "
        "simulated reach gets within 2 cm of without contact, per sample and overall, with the denominators.",
        ("-m", "scene_builder.bench.robot"),
        markdown=True,
        timeout_s=3600.0,
    ),
)


@dataclass(frozen=True)
class ExtraRun:
    """One run of an :class:`Extra`: its output (stdout, or the tail of stderr on failure)."""

    extra: Extra
    returncode: int
    output: str
    seconds: float
    date: str


def run_extra(extra: Extra, timeout_s: float | None = None) -> ExtraRun:
    """Run one stage benchmark in its own process (this interpreter) and capture its output
    (``timeout_s``: default the Extra's own)."""
    timeout_s = extra.timeout_s if timeout_s is None else timeout_s
    date = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, *extra.argv], capture_output=True, text=True, timeout=timeout_s, check=False)
    seconds = time.perf_counter() - t0
    out = proc.stdout if proc.returncode == 0 else (proc.stdout + "\n" + "\n".join(proc.stderr.splitlines()[-20:]))
    return ExtraRun(extra, proc.returncode, out.strip("\n"), seconds, date)


def render_extra(run: ExtraRun, machine: dict) -> str:
    """The Markdown section of one stage benchmark run."""
    e = run.extra
    cmd = "python " + " ".join(e.argv)
    lines = [f"## {e.title}", "", e.about, "", f"- command: `{cmd}`", f"- machine: {_machine(machine)}", f"- date: {run.date}; {run.seconds:.0f} s wall", ""]
    if run.returncode != 0:
        lines += [f"**Failed (exit status {run.returncode})**:", ""]
    if e.markdown and run.returncode == 0:
        lines += [run.output, ""]
    else:
        lines += ["```", run.output, "```", ""]
    return "\n".join(lines)


def _load(path: Path) -> dict:
    try:
        d = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise InputError(f"{path} not found; run `scene-builder bench --json {path}` first") from None
    except json.JSONDecodeError as err:
        raise InputError(f"{path} is not valid JSON ({err}); re-run the bench") from None
    for key in ("suite", "summary", "baseline", "scenes", "machine", "date", "command"):
        if key not in d:
            raise InputError(f"{path} has no '{key}'; it was not written by `scene-builder bench`")
    return d


def _fmt(v, fmt: str = "{:.3f}", scale: float = 1.0) -> str:
    return "-" if v is None else fmt.format(v * scale)


def _machine(m: dict) -> str:
    gpu = m.get("gpu") or "no GPU"
    load = f"; load average {m['load_avg_1m']} at the end" if m.get("load_avg_1m") is not None else ""
    return f"{m.get('cpu')}, {m.get('cores')} cores, {m.get('memory_gb')} GB RAM, {gpu}; {m.get('os')}; Python {m.get('python')}, MuJoCo {m.get('mujoco')}{load}"


def _twin_rows(d: dict) -> list[str]:
    """Per-scene twin fidelity of the pipeline (render against the photo, depth, silhouettes,
    displacement, what became background)."""
    rows = [
        "| scene | PSNR dB | SSIM | depth AbsRel t = 0 / settled | mask IoU median | displacement median / max (m) | movable / fixed / background | penetration mm t = 0 / settled |",
        "|---|---:|---:|---|---:|---|---|---|",
    ]
    for s in d["scenes"]:
        p = s.get("pipeline")
        if s.get("error") or not p:
            continue
        ious = sorted(p.get("mask_iou") or [])
        disp = sorted(p.get("displacement_m") or [])
        movable = p["n_free"]
        rows.append(
            f"| {s['name']} | {_fmt(p.get('psnr_db'), '{:.1f}')} | {_fmt(p.get('ssim'), '{:.2f}')} | "
            f"{_fmt(p.get('depth_absrel'))} / {_fmt(p.get('depth_absrel_settled'))} | {_fmt(ious[len(ious) // 2] if ious else None, '{:.2f}')} | "
            f"{_fmt(disp[len(disp) // 2] if disp else None)} / {_fmt(disp[-1] if disp else None)} | {movable} / {p.get('n_fixed', 0)} / {p.get('n_background', 0)} | "
            f"{_fmt(p['max_penetration_m'], '{:.2f}', 1000)} / {_fmt(p.get('max_penetration_settled_m'), '{:.2f}', 1000)} |"
        )
    return rows


def _scene_rows(d: dict) -> list[str]:
    rows = [
        "| scene | objects built / true | recall | position error median (m) | max penetration mm (pipeline / baseline) | stable (pipeline / baseline) | depth AbsRel (pipeline / baseline) | seconds |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for s in d["scenes"]:
        if s.get("error"):
            rows.append(f"| {s['name']} | failed: {s['error'].replace('|', '/')} | | | | | | |")
            continue
        p, b = s["pipeline"], s["baseline"]
        po = p.get("objects") or {}
        pos = po.get("position_error_m") or []
        pos_med = sorted(pos)[len(pos) // 2] if pos else None
        true = "-" if s.get("n_true") is None else s["n_true"]
        noise = " (noisy depth)" if s.get("depth_noise") else ""
        rows.append(
            f"| {s['name']}{noise} | {po.get('n_pred', s.get('n_perceived'))} / {true} | {_fmt(po.get('recall'), '{:.2f}')} | {_fmt(pos_med)} | "
            f"{_fmt(p['max_penetration_m'], '{:.1f}', 1000)} / {_fmt(b['max_penetration_m'], '{:.0f}', 1000)} | "
            f"{p['n_stable']}/{p['n_free']} / {b['n_stable']}/{b['n_free']} | {_fmt(p.get('depth_absrel'))} / {_fmt(b.get('depth_absrel'))} | {_fmt(p['seconds'], '{:.1f}')} |"
        )
    return rows


def render(paths: list[Path], extras: tuple[ExtraRun, ...] = ()) -> str:
    """The Markdown document for the bench JSON files ``paths`` and stage benchmark runs ``extras``."""
    docs = [_load(p) for p in paths]
    out = ["# Benchmarks", "", "Produced by `make bench`: the pipeline and a naive baseline on the same inputs, in the same process; "
           "then the stage benchmarks. Every section names the command that reproduces it. Timings are wall-clock on the machine named "
           "(shared: the load average says how busy it was).", ""]
    out += [
        "The baseline is the placement of a published scene application: an axis-aligned box in the camera frame from each perceived "
        "object's depth points, gravity along the camera's y axis, the floor at the lowest observed point, no penetration handling, no "
        "settling; its boxes are solid 500 kg/m^3 assets built by `generation.assembly`. Both methods are `Scene`s that go through one "
        "code path: the MJCF exporter (`exporters.write_mjcf`) and the physics check (`layout.verify_scene`: MuJoCo contacts at t = 0, "
        "3 s of simulation, rendering from the input camera); box metrics against ground truth come from `scene_builder.bench.metrics`.",
        "",
    ]
    for d in docs:
        s = d["summary"]
        models = " with the offline models of `$SCENE_BUILDER_MODELS`" if "SCENE_BUILDER_MODELS=" in str(d["command"]) else ""
        out += [f"## Suite `{d['suite']}`{models}: {s['scenes']} scenes ({s['failed_scenes']} failed)", ""]
        out += [f"- command: `{d['command']}`", f"- machine: {_machine(d['machine'])}", f"- date: {d['date']}", ""]
        out += ["| metric | pipeline | naive baseline |", "|---|---:|---:|"]
        for row in SUMMARY_ROWS:
            out.append(f"| {row[0]} | {format_value(s, row)} | {format_value(d['baseline'], row)} |")
        out.append("")
        if s.get("stage_seconds_median"):
            out.append("Median seconds per stage: " + ", ".join(f"{k} {v:.2f}" for k, v in s["stage_seconds_median"].items()) + ".")
        if s.get("peak_rss_mb") is not None:
            out.append(f"Peak memory (resident set of the bench process): {s['peak_rss_mb']:.0f} MiB.")
        out += ["", "### Per scene", ""] + _scene_rows(d) + [""]
        out += ["### Twin fidelity per scene (pipeline)", ""] + _twin_rows(d) + [""]
    out += ["## Definitions", ""] + [f"- **{k}**: {v}" for k, v in DEFINITIONS.items()] + [""]
    if extras:
        from scene_builder.bench.suites import machine_description

        machine = machine_description()
        out += ["# Stage benchmarks", "", "Each produced by `make bench` (`python -m scene_builder.bench.report ... --extras`) with the command shown.", ""]
        out += [render_extra(r, machine) for r in extras]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    with_extras = "--extras" in args
    args = [a for a in args if a != "--extras"]
    if not args:
        print("usage: python -m scene_builder.bench.report BENCH.json [MORE.json ...] [--extras] > BENCHMARKS.md", file=sys.stderr)
        return 2
    try:
        for a in args:
            _load(Path(a))  # check the inputs before spending minutes on the extras
        runs = tuple(run_extra(e) for e in EXTRAS) if with_extras else ()
        sys.stdout.write(render([Path(a) for a in args], runs))
        failed = [" ".join(r.extra.argv) for r in runs if r.returncode != 0]
        if failed:
            print(f"error: stage benchmark(s) failed: {', '.join(failed)} (their output is in the report)", file=sys.stderr)
            return 1
    except InputError as err:
        print(f"error: {err}", file=sys.stderr)
        return err.exit_code
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
