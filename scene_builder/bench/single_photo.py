"""Single-photo benchmark: depth from one photo against sensor depth, and perception time per photo.

Run: ``python -m scene_builder.bench.single_photo [--data ../shared/data] [--models-dir DIR]
[--skip-depth] [--skip-time] [--large]`` (the models dir defaults to ../shared/models when present).

Depth: every real sample of ``DATA/real`` with depth aligned to its RGB is used as a plain photo
(its depth only for scoring); intrinsics from its camera.json when it has one, as the CLI would.
Rows: a constant 2.5 m, the ``single-view-geometry`` backend with no weights, and (when the COCO
detector ``centernet-mbv3-coco`` resolves from the models dir) the same backend with detected
objects of known size. AbsRel and delta1 per sample, then the median and mean over the samples.

Time: ``perceive`` wall time per photo, per suite: ``photos`` (``DATA/photos``, plain),
``real-plain`` (the real samples as plain photos), ``real-rgbd`` (with their depth maps, where
aligned), and with ``--large`` a ``12mp`` suite (a real sample upscaled to 4000 x 3000, plain and
with depth), slowest photo of every suite named.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["depth_rows", "main", "time_rows"]


def depth_rows(data: Path, models_dir: Path | None) -> list[dict]:
    """One row per (method, sample): absrel, delta1 (metric), and the median-scaled pair."""
    from perception import models
    from scene_builder.bench.depth import _samples, score_depth
    from perception.single_view import SingleViewDepth

    methods: list[tuple[str, object]] = [("constant-2.5m", None), ("single-view-geometry", SingleViewDepth())]
    det_path = models.resolve_weights("centernet-mbv3-coco", models_dir)
    if det_path is not None:
        from perception.learned.detectors import CenterNetCocoDetector

        methods.append(("single-view-geometry+coco-boxes", SingleViewDepth(detector=CenterNetCocoDetector(det_path))))
    rows = []
    samples = _samples(data / "real")
    for name, est in methods:
        for sample, rgb, gt, k in samples:
            pred = np.full(gt.shape, 2.5, np.float32) if est is None else est.estimate(rgb, k).depth_m
            s = score_depth(pred, gt)
            rows.append(dict(method=name, sample=sample, absrel=s.absrel, delta1=s.delta1,
                             absrel_scaled=s.absrel_median_scaled, delta1_scaled=s.delta1_median_scaled))
    return rows


def _suites(data: Path, large: bool, tmp: Path) -> dict[str, list[tuple[str, "object"]]]:
    from scene_builder.config import InputSpec

    def rgb_of(d: Path) -> Path:
        return next(d.glob("rgb.*"))

    suites: dict[str, list] = {"photos": [], "real-plain": [], "real-rgbd": []}
    for d in sorted((data / "photos").iterdir()):
        if d.is_dir():
            suites["photos"].append((d.name, InputSpec(rgb_of(d))))
    for d in sorted((data / "real").iterdir()):
        if not d.is_dir():
            continue
        suites["real-plain"].append((d.name, InputSpec(rgb_of(d))))
        meta = json.loads((d / "meta.json").read_text())
        if (d / "depth.png").exists() and meta.get("depth_aligned_to_rgb", False):
            suites["real-rgbd"].append((d.name, InputSpec(rgb_of(d), depth_path=d / "depth.png")))
    if large:
        from PIL import Image

        src = data / "real" / "nyuv2_metric3d_00000"
        big = tmp / "nyuv2_12mp"
        big.mkdir(parents=True, exist_ok=True)
        Image.open(rgb_of(src)).convert("RGB").resize((4000, 3000), Image.Resampling.BICUBIC).save(big / "rgb.jpg", quality=92)
        Image.open(src / "depth.png").resize((4000, 3000), Image.Resampling.NEAREST).save(big / "depth.png")
        cam = json.loads((src / "camera.json").read_text())
        s = 4000 / cam["width"]
        (big / "camera.json").write_text(json.dumps({"fx": cam["fx"] * s, "fy": cam["fy"] * s, "cx": (cam["cx"] + 0.5) * s - 0.5,
                                                     "cy": (cam["cy"] + 0.5) * s - 0.5, "width": 4000, "height": 3000}))
        suites["12mp"] = [("nyuv2_00000 upscaled, plain", InputSpec(big / "rgb.jpg")),
                          ("nyuv2_00000 upscaled, rgb-d", InputSpec(big / "rgb.jpg", depth_path=big / "depth.png"))]
    return suites


def time_rows(data: Path, models_dir: Path | None, large: bool = False, on_row=None) -> list[dict]:
    """One row per (suite, photo): perception seconds, objects found, depth backend (or the
    error's class when perception refused the photo). on_row: called with each row as it is done."""
    from perception.perceive import perceive
    from scene_builder.config import PerceptionConfig
    from scene_builder.errors import SceneBuilderError

    cfg = PerceptionConfig(models_dir=models_dir)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for suite, items in _suites(data, large, Path(tmp)).items():
            for name, spec in items:
                t0, c0 = time.perf_counter(), time.process_time()
                try:
                    p = perceive(spec, cfg)
                    n, depth = len(p.objects), next(b.backend for b in p.backends if b.task == "depth")
                except SceneBuilderError as err:
                    n, depth = 0, type(err).__name__
                rows.append(dict(suite=suite, photo=name, seconds=time.perf_counter() - t0, cpu_s=time.process_time() - c0, objects=n, depth=depth))
                if on_row is not None:
                    on_row(rows[-1])
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[1].parent / "shared" / "data")
    shared_models = Path(__file__).resolve().parents[1].parent / "shared" / "models"
    parser.add_argument("--models-dir", type=Path, default=shared_models if shared_models.is_dir() else None,
                        help="where the COCO detector is looked up (default: ../shared/models when present)")
    parser.add_argument("--skip-depth", action="store_true")
    parser.add_argument("--skip-time", action="store_true")
    parser.add_argument("--large", action="store_true", help="also time a 12 MP upscaled photo (plain and RGB-D)")
    args = parser.parse_args(argv)
    if not args.skip_depth:
        rows = depth_rows(args.data, args.models_dir)
        methods = list(dict.fromkeys(r["method"] for r in rows))
        samples = list(dict.fromkeys(r["sample"] for r in rows))
        print("| sample | " + " | ".join(f"{m} AbsRel / delta1" for m in methods) + " |")
        print("|---|" + "---|" * len(methods))
        for s in samples:
            cells = [next(f"{r['absrel']:.3f} / {r['delta1']:.3f}" for r in rows if r["method"] == m and r["sample"] == s) for m in methods]
            print(f"| {s} | " + " | ".join(cells) + " |")
        for stat in ("median", "mean"):
            f = np.median if stat == "median" else np.mean
            cells = [f"{f([r['absrel'] for r in rows if r['method'] == m]):.3f} / {f([r['delta1'] for r in rows if r['method'] == m]):.3f}" for m in methods]
            print(f"| **{stat}** ({len(samples)}) | " + " | ".join(cells) + " |")
        print()
    if not args.skip_time:
        import sys

        def progress(r: dict) -> None:
            print(f"{r['suite']:10s} {r['photo']:32s} {r['seconds']:6.1f} s wall {r['cpu_s']:6.1f} s CPU  {r['objects']:2d} objects  depth {r['depth']}", file=sys.stderr, flush=True)

        rows = time_rows(args.data, args.models_dir, args.large, on_row=progress)
        import os

        print(f"Load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (wall seconds grow with it; "
              "CPU seconds are the process's own, all threads).")
        print()
        print("| suite | photos | median s wall / CPU | slowest | its s wall / CPU |")
        print("|---|---|---|---|---|")
        for suite in dict.fromkeys(r["suite"] for r in rows):
            rs = [r for r in rows if r["suite"] == suite]
            worst = max(rs, key=lambda r: r["seconds"])
            print(f"| {suite} | {len(rs)} | {np.median([r['seconds'] for r in rs]):.1f} / {np.median([r['cpu_s'] for r in rs]):.1f} | "
                  f"{worst['photo']} | {worst['seconds']:.1f} / {worst['cpu_s']:.1f} |")
        print()
        print("| suite | photo | s wall | s CPU | objects | depth |")
        print("|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['suite']} | {r['photo']} | {r['seconds']:.1f} | {r['cpu_s']:.1f} | {r['objects']} | {r['depth']} |")


if __name__ == "__main__":
    main()
