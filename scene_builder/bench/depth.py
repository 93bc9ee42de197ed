"""Benchmark of the depth backends against the real RGB-D samples.

Run: ``python -m scene_builder.bench.depth [--data ../shared/data/real] [--models-dir DIR]``.

For every available depth backend (and a constant-depth reference) prints AbsRel and delta1
(fraction of pixels with max(pred/gt, gt/pred) < 1.25), both metric and after median scaling,
seconds per image (640 x 480 samples), and peak traced Python memory per image (tracemalloc:
numpy buffers included, torch's own allocator not) plus the process's peak RSS. Only samples with
depth aligned to the RGB are used; intrinsics come from camera.json when the sample has one.
"""

from __future__ import annotations

import argparse
import json
import resource
import time
import tracemalloc
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scene_builder.model import CameraIntrinsics

__all__ = ["DepthScore", "bench", "main", "score_depth"]


@dataclass(frozen=True)
class DepthScore:
    """Errors of one prediction against valid ground truth (0.1 m < gt < 10 m)."""

    absrel: float
    delta1: float
    absrel_median_scaled: float
    delta1_median_scaled: float


def score_depth(pred_m: np.ndarray, gt_m: np.ndarray) -> DepthScore:
    """pred_m, gt_m: (H, W) metres (gt 0 = invalid)."""
    valid = (gt_m > 0.1) & (gt_m < 10.0) & (pred_m > 0)
    p = pred_m[valid].astype(np.float64)
    t = gt_m[valid].astype(np.float64)
    ps = p * (np.median(t) / np.median(p))

    def ab(x):
        return float(np.mean(np.abs(x - t) / t))

    def d1(x):
        return float(np.mean(np.maximum(x / t, t / x) < 1.25))

    return DepthScore(ab(p), d1(p), ab(ps), d1(ps))


def _samples(root: Path) -> list[tuple[str, np.ndarray, np.ndarray, CameraIntrinsics | None]]:
    from PIL import Image

    out = []
    for d in sorted(root.iterdir()):
        meta_p, depth_p = d / "meta.json", d / "depth.png"
        if not (meta_p.exists() and depth_p.exists()):
            continue
        meta = json.loads(meta_p.read_text())
        if not meta.get("depth_aligned_to_rgb", False):
            continue
        rgb = np.asarray(Image.open(next(d.glob("rgb.*"))).convert("RGB"))
        gt = np.asarray(Image.open(depth_p), dtype=np.float32) / 1000.0
        if gt.shape != rgb.shape[:2]:
            continue
        k = None
        if (d / "camera.json").exists():
            c = json.loads((d / "camera.json").read_text())
            k = CameraIntrinsics(c["fx"], c["fy"], c["cx"], c["cy"], c["width"], c["height"], "file")
        out.append((d.name, rgb, gt, k))
    return out


class _Constant:
    """Reference: every pixel at the typical indoor distance of 2.5 m."""

    def estimate(self, rgb, intrinsics):
        from perception.protocols import DepthEstimate

        return DepthEstimate(np.full(rgb.shape[:2], 2.5, dtype=np.float32))


def bench(data_root: Path, models_dir: Path | None = None) -> list[dict]:
    """Score every available backend on every sample; returns one row per (backend, sample)."""
    from perception import models
    from perception.single_view import SingleViewDepth

    backends: list[tuple[str, object]] = [("constant-2.5m", _Constant()), ("single-view-geometry", SingleViewDepth())]
    da = models.resolve_weights("depth-anything-v2-metric-indoor-small", models_dir)
    if da is not None:
        from perception.learned.depth_anything import DepthAnythingV2Estimator

        backends.append(("depth-anything-v2", DepthAnythingV2Estimator(da)))
    else:
        print("depth-anything-v2: " + (models.unavailable_reason("depth-anything-v2-metric-indoor-small", models_dir) or ""))
    rows = []
    samples = _samples(data_root)
    for name, est in backends:
        for sample, rgb, gt, k in samples:
            tracemalloc.start()
            t0 = time.perf_counter()
            pred = est.estimate(rgb, k).depth_m
            dt = time.perf_counter() - t0
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
            s = score_depth(pred, gt)
            rows.append(dict(backend=name, sample=sample, size=f"{rgb.shape[1]}x{rgb.shape[0]}", seconds=dt, peak_mb=peak / 2**20, **s.__dict__))
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[3] / "shared" / "data" / "real")
    parser.add_argument("--models-dir", type=Path, default=None)
    args = parser.parse_args(argv)
    rows = bench(args.data, args.models_dir)
    print(f"{'backend':22s} {'sample':26s} {'size':>9s} {'AbsRel':>7s} {'d1':>6s} {'AbsRel*':>7s} {'d1*':>6s} {'s':>6s} {'MB':>6s}")
    for r in rows:
        print(f"{r['backend']:22s} {r['sample']:26s} {r['size']:>9s} {r['absrel']:7.3f} {r['delta1']:6.3f} "
              f"{r['absrel_median_scaled']:7.3f} {r['delta1_median_scaled']:6.3f} {r['seconds']:6.2f} {r['peak_mb']:6.0f}")
    print("\nmean over samples (* = median-scaled; s/img over 640x480 samples)")
    for name in dict.fromkeys(r["backend"] for r in rows):
        rs = [r for r in rows if r["backend"] == name]
        vga = [r["seconds"] for r in rs if r["size"] == "640x480"]
        nyu = [r for r in rs if r["sample"].startswith("nyuv2")]
        print(f"{name:22s} all({len(rs)}): AbsRel {np.mean([r['absrel'] for r in rs]):.3f} d1 {np.mean([r['delta1'] for r in rs]):.3f} "
              f"AbsRel* {np.mean([r['absrel_median_scaled'] for r in rs]):.3f} d1* {np.mean([r['delta1_median_scaled'] for r in rs]):.3f} | "
              f"NYU({len(nyu)}): AbsRel {np.mean([r['absrel'] for r in nyu]):.3f} AbsRel* {np.mean([r['absrel_median_scaled'] for r in nyu]):.3f} | "
              f"{np.mean(vga) if vga else float('nan'):.2f} s/img, peak {max(r['peak_mb'] for r in rs):.0f} MB traced")
    print(f"process peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
