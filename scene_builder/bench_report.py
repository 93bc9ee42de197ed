"""Render bench JSON files as Markdown: ``python -m scene_builder.bench_report bench.json real.json > BENCHMARKS.md``.

For each file: the exact command, machine and date, the pipeline-versus-baseline summary table,
median seconds per stage, and one row per scene; then the metric definitions once.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from scene_builder.bench import DEFINITIONS, SUMMARY_ROWS, format_value
from scene_builder.errors import InputError


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
    return f"{m.get('cpu')}, {m.get('cores')} cores, {m.get('memory_gb')} GB RAM, {gpu}; {m.get('os')}; Python {m.get('python')}, MuJoCo {m.get('mujoco')}"


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


def render(paths: list[Path]) -> str:
    """The Markdown document for the bench JSON files ``paths``."""
    docs = [_load(p) for p in paths]
    out = ["# Benchmarks", "", "Produced by `make bench`: the pipeline and a naive baseline on the same inputs, in the same process.", ""]
    out += [
        "The baseline is the placement of a published scene application: an axis-aligned box in the camera frame from each perceived "
        "object's depth points, gravity along the camera's y axis, the floor at the lowest observed point, no penetration handling, no "
        "settling. Both are scored by the same code (`scene_builder.bench`): MuJoCo contacts at t = 0, 3 s of simulation, rendering "
        "from the input camera, and box metrics against ground truth.",
        "",
    ]
    for d in docs:
        s = d["summary"]
        out += [f"## Suite `{d['suite']}`: {s['scenes']} scenes ({s['failed_scenes']} failed)", ""]
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
    out += ["## Definitions", ""] + [f"- **{k}**: {v}" for k, v in DEFINITIONS.items()] + [""]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if not args:
        print("usage: python -m scene_builder.bench_report BENCH.json [MORE.json ...] > BENCHMARKS.md", file=sys.stderr)
        return 2
    try:
        sys.stdout.write(render([Path(a) for a in args]))
    except InputError as err:
        print(f"error: {err}", file=sys.stderr)
        return err.exit_code
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
