"""Interaction probes on built real scenes: every sample of ``DATA/real`` with a depth map
(camera.json intrinsics where the sample has them, else estimated, as ``scene-builder bench
--suite real`` builds them) and every URDFormer cabinet photo of ``DATA/photos`` is built with
the default configuration, then every movable object is pushed by the force-limited pusher and
every door and drawer pulled open (``layout.interaction.probe_scene``, as ``scene-builder check
--interact``).

    .venv/bin/python -m scene_builder.bench.interaction [--data ../shared/data] [--built DIR ...] [--force-n 100 [250 ...]]

``--built`` probes output folders already written by ``scene-builder build`` instead of
building; ``--force-n`` sets the pusher's force limit (default ``PUSHER_FORCE_N``, 100 N; with
several, each scene is probed with each and the first gets the full table).
Prints a Markdown table per sample (pushes: movable objects, pushes that passed, the passed
pushes' displacement median and range, the largest motion of any other object, the largest
tilt; joints: how many opened, the smallest open fraction, the largest excursion beyond a
limit, the largest carcass motion; problems against the bar of
``layout.interaction.interaction_problems``), the push success rate over every movable object
with the failures counted by kind, and every failed push with its reason.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
DEFAULT_DATA = REPO.parent / "shared" / "data"

#: Kinds of push failure, by the start of :func:`layout.push.push_failures`' first reason.
FAILURE_KINDS = (
    ("no room for the pusher", "no room for the pusher behind it"),
    ("the pusher was stopped by", "the pusher stopped by something else"),
    ("the pusher never touched", "the pusher never touched it"),
    ("blocked by", "blocked (by a neighbour, a wall, the background)"),
    ("too heavy", "too heavy for the force limit"),
    ("stuck", "stuck under the force limit"),
    ("it has no collision geometry", "no collision geometry"),
)


def failure_kind(reason: str) -> str:
    """The kind of a push failure from its first reason (see FAILURE_KINDS)."""
    for start, kind in FAILURE_KINDS:
        if reason.startswith(start):
            return kind
    if reason.startswith("moved "):
        value = float(reason.split()[1])
        return "moved too little" if value < 2.0 else "moved too far (fell or slid off)"
    if reason.startswith(("toppled", "tilted")):
        return "toppled or tilted"
    if " moved " in reason and reason.rstrip().endswith(("too", "(the pusher hit it)")):
        return "moved another object"
    if "resting on it, fell" in reason:
        return "what rides on it fell"
    return "other"


def _build(src: Path, out: Path) -> Path:
    from scene_builder.bench.fronts import sample_inputs
    from scene_builder.config import BuildConfig, ExportConfig
    from scene_builder.pipeline import build

    inputs = sample_inputs(src)
    build(inputs, out, BuildConfig(export=ExportConfig(usd=False, urdf=False, gltf=False, viz="off")))
    return out


def _row(name: str, out: Path, force_n: float) -> tuple[str, list[tuple[str, str, str]], int, int]:
    """(table row, failures (sample, object, reasons), movable, passed)."""
    from layout.interaction import interaction_problems, probe_scene, push_failures

    t0 = time.perf_counter()
    plans, pushes, joints = probe_scene(out / "scene.xml", force_n)
    seconds = time.perf_counter() - t0
    failed = {r.name: push_failures(r) for r in pushes}
    good = [r for r in pushes if not failed[r.name]]
    disp = np.array([p.displacement_m for p in good]) * 100
    push = "-" if not pushes else f"{len(good)}/{len(pushes)}"
    moved = f"{np.median(disp):.1f} ({disp.min():.1f}-{disp.max():.1f})" if len(disp) else "-"
    started = [p for p in pushes if not p.not_started]
    others = f"{max(p.max_other_m for p in started) * 1000:.1f}" if started else "-"
    tilt = f"{max(p.tilt_deg for p in started):.1f}" if started else "-"
    opened = f"{len(joints)}, min {min(j.open_fraction for j in joints):.0%}" if joints else "-"
    hinge = max([np.degrees(j.limit_violation) for j in joints if j.kind == "hinge"], default=0.0)
    slide = max([j.limit_violation * 1000 for j in joints if j.kind == "slide"], default=0.0)
    beyond = f"{hinge:.2f} deg / {slide:.1f} mm" if joints else "-"
    carcass = f"{max(j.body_displacement_m for j in joints) * 1000:.1f}" if joints else "-"
    problems = interaction_problems(pushes, joints)
    row = f"| {name} | {push} | {moved} | {others} | {tilt} | {opened} | {beyond} | {carcass} | {len(problems)} | {seconds:.1f} |"
    fails = [(name, r.name, "; ".join(failed[r.name])) for r in pushes if failed[r.name]]
    joint_problems = [p for p in problems if p.startswith("open ")]
    fails += [(name, "", p) for p in joint_problems]
    return row, fails, len(pushes), len(good)


def _report(force_n: float, rows: list[str], fails: list, movable: int, passed: int, not_built: list[str], table: bool) -> None:
    print(f"### Pusher force limit {force_n:g} N")
    print()
    if table:
        print("| sample | pushes passed / movable | passed pushes moved, cm: median (range) | others moved, max mm | tilt, max deg "
              "| joints opened, min share of range | beyond a limit, max (hinge / slide) | carcass moved, max mm | problems | probe s |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        print("\n".join(rows))
        print()
    push_fails = [f for f in fails if f[1]]
    kinds = Counter(failure_kind(reason) for _, _, reason in push_fails)
    rate = f"{passed}/{movable} = {passed / movable:.0%}" if movable else "0/0"
    print(f"Push success rate at {force_n:g} N: {rate} of the movable objects of {len(rows)} built scenes"
          + (f" ({len(not_built)} not built: {'; '.join(not_built)})" if not_built else "") + ".")
    if kinds:
        print("Failures by kind (first reason): " + ", ".join(f"{k} {v}" for k, v in kinds.most_common()) + ".")
    if fails:
        print()
        print("\n".join(f"- {s}: {o + ': ' if o else ''}{reason}" for s, o, reason in fails))
    print()


def main(argv: list[str] | None = None) -> int:
    from layout.interaction import PUSHER_FORCE_N
    from scene_builder.errors import SceneBuilderError

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder with real/ and photos/ (default ../shared/data)")
    ap.add_argument("--built", type=Path, nargs="*", help="probe these output folders instead of building")
    ap.add_argument("--force-n", type=float, nargs="+", default=[PUSHER_FORCE_N],
                    help=f"the pusher's force limit; several: each scene is probed with each (default {PUSHER_FORCE_N:g} N)")
    args = ap.parse_args(argv)

    runs = {f: ([], [], [0, 0]) for f in args.force_n}  # force -> (rows, fails, [movable, passed])
    not_built: list[str] = []

    def add(name: str, out: Path) -> None:
        for f, (rows, fails, counts) in runs.items():
            r, fl, n, k = _row(name, out, f)
            rows.append(r)
            fails.extend(fl)
            counts[0] += n
            counts[1] += k

    if args.built:
        for out in args.built:
            add(out.name, out)
    else:
        real = [d for d in sorted((args.data / "real").iterdir()) if (d / "depth.png").exists()]
        photos = sorted((args.data / "photos").glob("urdformer_*"))
        with tempfile.TemporaryDirectory() as tmp:
            for src in real + photos:
                try:
                    out = _build(src, Path(tmp) / src.name)
                except SceneBuilderError as err:
                    not_built.append(f"{src.name}: {type(err).__name__}: {str(err).splitlines()[0]}")
                    continue
                add(src.name, out)
    for k, (f, (rows, fails, (movable, passed))) in enumerate(runs.items()):
        _report(f, rows, fails, movable, passed, not_built, table=k == 0)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
