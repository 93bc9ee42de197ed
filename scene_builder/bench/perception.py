"""Perception benchmark on procedural rooms with ground truth: instance recall at IoU 0.5, mean
best IoU, category accuracy of the matched objects, and wall time of ``perceive`` per frame.

    .venv/bin/python -m scene_builder.bench.perception --seeds 0 1 2 3 4 5 --naming auto

Speed numbers belong in BENCHMARKS.md, never in tests.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["RoomScore", "score_room"]

#: Ground-truth instances with fewer visible pixels are not counted (a 2 cm sliver).
MIN_TRUTH_PX = 300


@dataclass(frozen=True)
class RoomScore:
    """Scores of one perceived room against its truth.

    truths: visible true objects; matched: of those, found with mask IoU >= 0.5; iou_sum: sum of
    each true object's best IoU; named: matched objects whose label is the true category;
    seconds: wall time of ``perceive``; labels: (true category, perceived label) per match.
    """

    truths: int
    matched: int
    iou_sum: float
    named: int
    seconds: float
    labels: tuple[tuple[str, str], ...]


def score_room(perception, truth, seconds: float = 0.0) -> RoomScore:
    """Match perceived masks to the truth's instances (``procedural.SampleTruth``)."""
    category = {oid: o.label for oid, o in zip(truth.object_ids, truth.objects)}
    truths = matched = named = 0
    iou_sum = 0.0
    labels = []
    for k in np.unique(truth.instances):
        gt = truth.instances == k
        if k == 0 or gt.sum() < MIN_TRUTH_PX:
            continue
        truths += 1
        ious = [float((gt & o.mask).sum() / (gt | o.mask).sum()) for o in perception.objects]
        best = int(np.argmax(ious)) if ious else -1
        iou = ious[best] if ious else 0.0
        iou_sum += iou
        if iou >= 0.5:
            matched += 1
            label = perception.objects[best].label
            labels.append((category[int(k)], label))
            named += label == category[int(k)]
    return RoomScore(truths, matched, iou_sum, named, seconds, tuple(labels))


def main(argv: list[str] | None = None) -> None:
    import os

    os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering of the rooms, before mujoco loads
    from perception import perceive
    from scene_builder.config import InputSpec, PerceptionConfig
    from scene_builder.bench.procedural import make_room
    from scene_builder.bench.render import render_room
    from scene_builder.bench.truth import load_truth

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5, 6, 7])
    ap.add_argument("--objects", type=int, default=6)
    ap.add_argument("--naming", default="auto")
    ap.add_argument("--segmentation", default="auto")
    ap.add_argument("--models-dir", type=Path, default=None)
    args = ap.parse_args(argv)
    cfg = PerceptionConfig(naming_backend=args.naming, segmentation_backend=args.segmentation, models_dir=args.models_dir)
    scores = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            d = render_room(make_room(seed, n_objects=args.objects, noise=True), Path(tmp) / f"room{seed}")
            t0 = time.perf_counter()
            p = perceive(InputSpec(d / "rgb.png", d / "depth.png"), cfg, seed=0)
            s = score_room(p, load_truth(d), time.perf_counter() - t0)
            scores.append(s)
            print(f"seed {seed}: {s.matched}/{s.truths} matched, mean IoU {s.iou_sum / max(s.truths, 1):.3f}, "
                  f"named {s.named}/{s.matched}, {s.seconds:.2f} s  {list(s.labels)}")
    t, m, n = (sum(getattr(s, f) for s in scores) for f in ("truths", "matched", "named"))
    print(f"total: recall@0.5 {m}/{t} = {m / max(t, 1):.3f}, mean IoU {sum(s.iou_sum for s in scores) / max(t, 1):.3f}, "
          f"category accuracy {n}/{m} = {n / max(m, 1):.3f}, perceive {np.mean([s.seconds for s in scores]):.2f} s/frame "
          f"(max {max(s.seconds for s in scores):.2f})")


if __name__ == "__main__":
    main()
