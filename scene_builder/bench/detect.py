"""Detection benchmark on real photos used as plain photos (no depth map): movable objects per
photo, category recall and precision against a hand-made inventory of what a person sees, the
detector's classes against the SUN RGB-D ground-truth boxes, and ``perceive`` time per photo
(after one untimed warm-up run: imports and model loading happen once per process).

    .venv/bin/python -m scene_builder.bench.detect                              # ../shared/models
    .venv/bin/python -m scene_builder.bench.detect --segmentation depth-clusters  # the geometric chain

Photos: every folder of ``../shared/data/photos`` and ``../shared/data/real`` (their depth maps
are not given to ``perceive``). The inventory (``tests/data/photo_inventory.json``) lists, per
photo of ``photos``, how many things of each vocabulary label a person sees; labels of one
``same_category`` group count as one category. Scores pool over the photos:

* instance recall = sum over photos and categories of min(found, seen) / sum of seen;
  instance precision = the same sum / sum of found (objects of categories not in the photo count
  as wrong, "object" included);
* category recall / precision: the same with each category counted once per photo (is there a
  chair, a bed ...).

Speed numbers belong in BENCHMARKS.md, never in tests.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["InventoryScore", "SUN_TO_LABELS", "canonical", "load_inventory", "pooled", "score_inventory"]

REPO = Path(__file__).resolve().parents[2]
DEFAULT_INVENTORY = REPO / "tests" / "data" / "photo_inventory.json"
DEFAULT_DATA = REPO.parent / "shared" / "data"
DEFAULT_MODELS = REPO.parent / "shared" / "models"

#: SUN RGB-D box labels -> the vocabulary labels that name the same thing.
SUN_TO_LABELS: dict[str, tuple[str, ...]] = {
    "bed": ("bed",),
    "night_stand": ("cabinet", "drawer_unit"),
    "dresser": ("cabinet", "drawer_unit"),
    "chair": ("chair",),
    "sofa": ("sofa",),
    "table": ("table", "desk"),
    "desk": ("desk", "table"),
    "bookshelf": ("shelf",),
    "toilet": ("toilet",),
    "bathtub": (),
}


@dataclass(frozen=True)
class InventoryScore:
    """One photo against its inventory. matched: sum over categories of min(found, seen);
    found / seen: object counts; cats_*: the same with each category counted once."""

    matched: int
    found: int
    seen: int
    cats_matched: int
    cats_found: int
    cats_seen: int


def load_inventory(path: Path = DEFAULT_INVENTORY) -> tuple[dict[str, dict[str, int]], tuple[tuple[str, ...], ...]]:
    """(photo name -> {label: count}, same-category groups) from the inventory JSON."""
    data = json.loads(Path(path).read_text())
    photos = {name: {k: int(v) for k, v in entry["objects"].items()} for name, entry in data["photos"].items()}
    groups = tuple(tuple(g) for g in data.get("same_category", ()))
    return photos, groups


def canonical(label: str, groups: tuple[tuple[str, ...], ...]) -> str:
    """The first label of ``label``'s same-category group (itself when in none)."""
    for g in groups:
        if label in g:
            return g[0]
    return label


def _counts(labels, groups) -> dict[str, int]:
    out: dict[str, int] = {}
    for lab in labels:
        c = canonical(lab, groups)
        out[c] = out.get(c, 0) + 1
    return out


def score_inventory(found_labels: list[str], seen: dict[str, int], groups: tuple[tuple[str, ...], ...] = ()) -> InventoryScore:
    """Score the labels of the objects found in one photo against what a person sees there."""
    found = _counts(found_labels, groups)
    truth: dict[str, int] = {}
    for lab, n in seen.items():
        c = canonical(lab, groups)
        truth[c] = truth.get(c, 0) + int(n)
    matched = sum(min(n, truth.get(c, 0)) for c, n in found.items())
    cats = set(found) & set(truth)
    return InventoryScore(matched, sum(found.values()), sum(truth.values()), len(cats), len(found), len(truth))


def pooled(scores: list[InventoryScore]) -> dict[str, float]:
    """Instance and category recall / precision pooled over photos."""
    m, f, s = (sum(getattr(x, k) for x in scores) for k in ("matched", "found", "seen"))
    cm, cf, cs = (sum(getattr(x, k) for x in scores) for k in ("cats_matched", "cats_found", "cats_seen"))
    return {
        "instance_recall": m / max(s, 1),
        "instance_precision": m / max(f, 1),
        "category_recall": cm / max(cs, 1),
        "category_precision": cm / max(cf, 1),
    }


def _sun_boxes(sample: Path) -> list[dict]:
    meta = json.loads((sample / "meta.json").read_text())
    gt = meta.get("ground_truth") or {}
    return [b for b in (gt.get("boxes_3d") or []) if b.get("bbox2d_xyxy_px")]


def _mask_box(mask) -> tuple[float, float, float, float]:
    import numpy as np

    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    return float(cols[0]), float(rows[0]), float(cols[-1] + 1), float(rows[-1] + 1)


def _box_iou(a, b) -> float:
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    ua = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - ix
    return ix / ua if ua > 0 else 0.0


def run(data: Path, inventory: Path, models_dir: Path | None, segmentation: str, roots: tuple[str, ...] = ("photos", "real"), quiet: bool = False) -> dict:
    """Perceive every photo of the ``roots`` folders of ``data`` (photos and real) as a plain
    photo; returns the rows and the pooled scores (see the module doc). quiet: no line per photo."""
    from perception import perceive
    from scene_builder.config import InputSpec, PerceptionConfig
    from scene_builder.errors import EmptySceneError
    from scene_builder.vocabulary import category

    seen, groups = load_inventory(inventory)
    cfg = PerceptionConfig(models_dir=models_dir, segmentation_backend=segmentation)
    rows, scores = [], []
    samples = [d for root in roots for d in sorted((data / root).iterdir())]
    # One untimed run first: the imports and model loading (about 10 s) happen once per process.
    first = next((p for d in samples for p in (d / "rgb.jpg", d / "rgb.png") if p.exists()), None)
    if first is not None:
        try:
            perceive(InputSpec(first), cfg, seed=0)
        except EmptySceneError:
            pass
    for d in samples:
        image = next((p for p in (d / "rgb.jpg", d / "rgb.png") if p.exists()), None)
        if image is None:
            continue
        t0 = time.perf_counter()
        try:
            p = perceive(InputSpec(image), cfg, seed=0)
            objects = list(p.objects)
            seg = next((b.backend for b in p.backends if b.task == "segmentation"), "")
        except EmptySceneError:
            objects, seg = [], "none"
        seconds = time.perf_counter() - t0
        labels = sorted(o.label for o in objects)
        row = {
            "photo": f"{d.parent.name}/{d.name}",
            "seconds": round(seconds, 2),
            "segmentation": seg,
            "objects": len(objects),
            "movable": sum(1 for lab in labels if not category(lab).fixed),
            "labels": labels,
        }
        if d.name in seen:
            s = score_inventory(labels, seen[d.name], groups)
            scores.append(s)
            row["inventory"] = s.__dict__
        boxes = _sun_boxes(d)
        if boxes:
            hits = []
            for b in boxes:
                best = max(objects, key=lambda o: _box_iou(_mask_box(o.mask), b["bbox2d_xyxy_px"]), default=None)
                iou = _box_iou(_mask_box(best.mask), b["bbox2d_xyxy_px"]) if best is not None else 0.0
                label = best.label if best is not None and iou >= 0.3 else None
                hits.append({"truth": b["label"], "found": label, "iou": round(iou, 3), "named_right": label in SUN_TO_LABELS.get(b["label"], (b["label"],))})
            row["sun_boxes"] = hits
        rows.append(row)
        if not quiet:
            print(f"{row['photo']:38s} {seconds:6.2f} s  {row['movable']:3d} movable  {seg:15s} {', '.join(labels)}", flush=True)
    summary = pooled(scores)
    slowest = max(rows, key=lambda r: r["seconds"]) if rows else None
    return {"rows": rows, "inventory_scores": summary, "slowest": slowest["photo"] if slowest else None}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder holding photos/ and real/ (default ../shared/data)")
    ap.add_argument("--inventory", type=Path, default=DEFAULT_INVENTORY)
    ap.add_argument(
        "--models-dir",
        type=Path,
        default=DEFAULT_MODELS if DEFAULT_MODELS.is_dir() else None,
        help="model files (default ../shared/models when it exists, else $SCENE_BUILDER_MODELS)",
    )
    ap.add_argument("--segmentation", default="auto", help="segmentation backend (auto, detections, depth-clusters, ...)")
    ap.add_argument("--json", type=Path, default=None, help="write the rows and scores here")
    args = ap.parse_args(argv)
    result = run(args.data, args.inventory, args.models_dir, args.segmentation)
    s = result["inventory_scores"]
    demo = [r for r in result["rows"] if "sunrgbd_total3d_demo" in r["photo"]]
    print(
        f"inventory ({sum(1 for r in result['rows'] if 'inventory' in r)} photos): "
        f"instance recall {s['instance_recall']:.3f} precision {s['instance_precision']:.3f}; "
        f"category recall {s['category_recall']:.3f} precision {s['category_precision']:.3f}"
    )
    if demo:
        print("movable objects on the SUN RGB-D demo photos: " + ", ".join(str(r["movable"]) for r in demo))
    for r in result["rows"]:
        for h in r.get("sun_boxes", []):
            print(f"SUN RGB-D {r['photo']}: {h['truth']} -> {h['found']} (box IoU {h['iou']:.2f})")
    secs = sorted(r["seconds"] for r in result["rows"])
    if secs:
        print(f"perceive: median {secs[len(secs) // 2]:.2f} s, slowest {secs[-1]:.2f} s ({result['slowest']})")
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
