"""Interaction probes on built real scenes: every RGB-D sample of ``DATA/real`` with intrinsics
and every URDFormer cabinet photo of ``DATA/photos`` is built with the default configuration
(as the tests build them), then every pushable movable object is pushed and every door and
drawer pulled open (``layout.interaction.probe_scene``, as ``scene-builder check --interact``).

    .venv/bin/python -m scene_builder.bench.interaction [--data ../shared/data] [--built DIR ...]

``--built`` probes output folders already written by ``scene-builder build`` instead of
building. Prints a Markdown table per sample (pushes: how many objects were pushable, the
pushed object's displacement median and range, the largest motion of any other object and the
largest tilt; joints: how many opened, the smallest open fraction, the largest excursion beyond
a limit, the largest carcass motion; problems against the bar of
``layout.interaction.interaction_problems``) and the objects that could not be pushed, with why.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
DEFAULT_DATA = REPO.parent / "shared" / "data"


def _build(src: Path, out: Path) -> Path:
    import json

    from scene_builder.config import BuildConfig, ExportConfig, InputSpec
    from scene_builder.pipeline import build

    rgb = next(p for p in (src / "rgb.jpg", src / "rgb.png") if p.exists())
    if (src / "depth.png").exists():
        cam = json.loads((src / "camera.json").read_text())
        inputs = InputSpec(rgb, src / "depth.png", 0.001, (cam["fx"], cam["fy"], cam["cx"], cam["cy"]))
    else:
        inputs = InputSpec(rgb)
    build(inputs, out, BuildConfig(export=ExportConfig(usd=False, urdf=False, gltf=False, viz="off")))
    return out


def _row(name: str, out: Path) -> tuple[str, list[str]]:
    from layout.interaction import interaction_problems, probe_scene

    t0 = time.perf_counter()
    plans, pushes, joints = probe_scene(out / "scene.xml")
    seconds = time.perf_counter() - t0
    disp = np.array([p.displacement_m for p in pushes]) * 100
    push = "-" if not plans else f"{len(pushes)}/{len(plans)}"
    moved = f"{np.median(disp):.1f} ({disp.min():.1f}-{disp.max():.1f})" if len(disp) else "-"
    others = f"{max(p.max_other_m for p in pushes) * 1000:.1f}" if pushes else "-"
    tilt = f"{max(p.tilt_deg for p in pushes):.1f}" if pushes else "-"
    opened = f"{len(joints)}, min {min(j.open_fraction for j in joints):.0%}" if joints else "-"
    hinge = max([np.degrees(j.limit_violation) for j in joints if j.kind == "hinge"], default=0.0)
    slide = max([j.limit_violation * 1000 for j in joints if j.kind == "slide"], default=0.0)
    beyond = f"{hinge:.2f} deg / {slide:.1f} mm" if joints else "-"
    carcass = f"{max(j.body_displacement_m for j in joints) * 1000:.1f}" if joints else "-"
    problems = interaction_problems(pushes, joints)
    row = f"| {name} | {push} | {moved} | {others} | {tilt} | {opened} | {beyond} | {carcass} | {len(problems)} | {seconds:.1f} |"
    notes = [f"{name}: {p.name} not pushed: {p.reason}" for p in plans if not p.pushable] + [f"{name}: {p}" for p in problems]
    return row, notes


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder with real/ and photos/ (default ../shared/data)")
    ap.add_argument("--built", type=Path, nargs="*", help="probe these output folders instead of building")
    args = ap.parse_args(argv)

    rows, notes = [], []
    if args.built:
        for out in args.built:
            r, n = _row(out.name, out)
            rows.append(r)
            notes += n
    else:
        real = [d for d in sorted((args.data / "real").iterdir()) if (d / "depth.png").exists() and (d / "camera.json").exists()]
        photos = sorted((args.data / "photos").glob("urdformer_*"))
        with tempfile.TemporaryDirectory() as tmp:
            for src in real + photos:
                r, n = _row(src.name, _build(src, Path(tmp) / src.name))
                rows.append(r)
                notes += n
    print("| sample | pushed / movable | pushed object moved, cm: median (range) | others moved, max mm | tilt, max deg "
          "| joints opened, min share of range | beyond a limit, max (hinge / slide) | carcass moved, max mm | problems | probe s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    print("\n".join(rows))
    if notes:
        print()
        print("\n".join(f"- {n}" for n in notes))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
