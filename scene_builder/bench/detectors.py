"""The offline detectors alone and merged, against box ground truth and the hand-made inventory;
NanoDet's decoding variants; CPU time per photo.

    .venv/bin/python -m scene_builder.bench.detectors                  # ../shared/models, ../shared/data

Markdown on stdout (BENCHMARKS.md, "Offline detectors"). What it measures:

* **Boxes** (``photos_gt``: 7 COCO train photos with their COCO instance boxes): a detection
  (a vocabulary label at or over the threshold) matches an unmatched ground-truth box of its
  label family (:data:`perception.detection.FAMILIES`) at IoU >= 0.5, best score first; recall =
  matched / ground-truth boxes, precision = matched / detections. "furniture" counts only the
  labels of :data:`FURNITURE` on both sides; "all" every vocabulary label. Both COCO detectors were
  trained on these photos: their figures here flatter them (the SSD's Open Images did not).
* **Inventory** (``photos``: 15 photos counted by hand, ``tests/data/photo_inventory.json``):
  instance and category recall / precision of the detections' labels as
  :mod:`scene_builder.bench.detect` scores them (counts, no boxes).
* **False detections**: on the inventory photos, detections of a category the photo does not
  have (a sofa in a classroom) are wrong whatever their box: their highest scores, per detector,
  against the scores of its detections that match a ground-truth box on ``photos_gt``.
* Thresholds are on the merged scale of :func:`perception.detection.merge_detections` (a
  detector's ``accept_score`` becomes :data:`~perception.detection.CONFIDENT` = 0.5), the scale of
  ``perception.segment_detect``: 0.5 stands alone, 0.2 (``FLOOR_SCORE``) needs a witness, 0.12
  (proposals) goes to the classifier. Each single detector's row also gives its raw score.
* **Decoding** of NanoDet's raw heads: the chosen decoding
  (:func:`perception.learned.detectors.nanodet_decode`) against one wrong choice at a time, on
  ``photos_gt`` (AP at IoU 0.5 over all 80 COCO classes, recall and precision at score 0.3,
  mean IoU and median centre offset of the matched boxes) and against CenterNet's boxes (score
  >= 0.3) on the 29 room photos of ``photos`` and ``real``.
* **Time**: CPU seconds (this process, all threads) of each detector's ``detect`` per photo over
  the 29 room photos, after one warm-up call.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scene_builder.bench.detect import load_inventory, pooled, score_inventory

__all__ = ["FURNITURE", "THRESHOLDS", "BoxScore", "gt_photos", "load_detectors", "main", "score_boxes"]

REPO = Path(__file__).resolve().parents[2]
DEFAULT_DATA = REPO.parent / "shared" / "data"
DEFAULT_MODELS = REPO.parent / "shared" / "models"
DEFAULT_INVENTORY = REPO / "tests" / "data" / "photo_inventory.json"
REAL_INVENTORY = REPO / "tests" / "data" / "real_inventory.json"

#: Vocabulary labels of furniture-like things (the objects a twin is mostly about).
FURNITURE: frozenset[str] = frozenset(
    {"bed", "bench", "cabinet", "chair", "desk", "drawer_unit", "microwave", "monitor", "oven", "plant", "refrigerator", "shelf", "sink", "sofa", "table", "toilet", "tv"}
)
#: Thresholds on the merged scale (see the module doc).
THRESHOLDS: tuple[float, ...] = (0.12, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)
DETECTORS: tuple[str, ...] = ("centernet-mbv3-coco", "nanodet-coco", "ssd-mobilenet-oid")
SHORT = {"centernet-mbv3-coco": "CenterNet", "nanodet-coco": "NanoDet", "ssd-mobilenet-oid": "SSD"}
COMBOS: tuple[tuple[str, ...], ...] = (
    ("centernet-mbv3-coco",),
    ("nanodet-coco",),
    ("ssd-mobilenet-oid",),
    ("centernet-mbv3-coco", "ssd-mobilenet-oid"),
    ("centernet-mbv3-coco", "nanodet-coco"),
    ("nanodet-coco", "ssd-mobilenet-oid"),
    ("centernet-mbv3-coco", "nanodet-coco", "ssd-mobilenet-oid"),
)


@dataclass(frozen=True)
class BoxScore:
    """matched ground-truth boxes, detections, ground-truth boxes."""

    matched: int
    found: int
    truth: int

    def __add__(self, other: BoxScore) -> BoxScore:
        return BoxScore(self.matched + other.matched, self.found + other.found, self.truth + other.truth)


def _image(d: Path) -> np.ndarray:
    from PIL import Image

    path = next(p for p in (d / "rgb.jpg", d / "rgb.png") if p.exists())
    return np.asarray(Image.open(path).convert("RGB"))


def gt_photos(data: Path) -> list[tuple[str, np.ndarray, list[tuple[list[float], str]]]]:
    """(name, rgb, [(xyxy box, COCO class)]) per photo of ``data``/photos_gt (crowd boxes left out)."""
    out = []
    for d in sorted((data / "photos_gt").iterdir()):
        gt = json.loads((d / "gt_instances.json").read_text())
        out.append((d.name, _image(d), [(g["bbox_xyxy_px"], g["label"]) for g in gt if not g.get("iscrowd")]))
    return out


def room_photos(data: Path) -> list[tuple[str, np.ndarray]]:
    return [(f"{root}/{d.name}", _image(d)) for root in ("photos", "real") for d in sorted((data / root).iterdir()) if d.is_dir()]


def load_detectors(models_dir: Path | None) -> dict[str, object]:
    """The detectors of :data:`DETECTORS` whose files are in ``models_dir``, built through the
    registry (also those off by default, ``perception.learned.OFF_BY_DEFAULT``)."""
    from perception import models
    from perception.backends import build_registries
    from scene_builder.config import PerceptionConfig

    reg = build_registries(PerceptionConfig(models_dir=models_dir))
    entries = {e.name: e for e in reg.detection.entries()}
    return {n: entries[n].factory() for n in DETECTORS if n in entries and models.resolve_weights(n, models_dir) is not None}


def score_boxes(boxes: np.ndarray, scores: np.ndarray, labels, truth: list[tuple[list[float], str]], threshold: float, keep=None) -> BoxScore:
    """Greedy matching, best score first, of the detections at ``threshold`` or more with a
    vocabulary label (in ``keep`` when given) to ground-truth (box, label) pairs of the same label
    family at IoU >= 0.5."""
    from perception.detection import box_iou, family

    idx = [i for i in np.argsort(-np.asarray(scores), kind="stable") if labels[i] and scores[i] >= threshold and (keep is None or labels[i] in keep)]
    truth = [t for t in truth if keep is None or t[1] in keep]
    used = np.zeros(len(truth), dtype=bool)
    tb = np.asarray([t[0] for t in truth], dtype=np.float64).reshape(-1, 4)
    matched = 0
    for i in idx:
        if not len(truth):
            break
        iou = box_iou(np.asarray(boxes)[i : i + 1], tb)[0]
        fam = family(labels[i])
        iou[used | np.array([t[1] not in fam for t in truth])] = 0.0
        k = int(iou.argmax())
        if iou[k] >= 0.5:
            used[k] = True
            matched += 1
    return BoxScore(matched, len(idx), len(truth))


def _vocab_truth(truth: list[tuple[list[float], str]]) -> list[tuple[list[float], str]]:
    from perception.detection import COCO_TO_LABEL

    return [(b, COCO_TO_LABEL[c]) for b, c in truth if c in COCO_TO_LABEL]


def _run_all(detectors: dict, photos) -> tuple[dict, dict]:
    """Each detector's detections per photo and its CPU seconds per photo (after a warm-up)."""
    dets: dict[str, list] = {n: [] for n in detectors}
    secs: dict[str, list] = {n: [] for n in detectors}
    for name, det in detectors.items():
        det.detect(photos[0][1])
        for p in photos:
            t0 = time.process_time()
            dets[name].append(det.detect(p[1]))
            secs[name].append(time.process_time() - t0)
    return dets, secs


def _merged(combo, detectors, dets, k, by_max: bool = False):
    from perception.detection import merge_detections

    parts = [(dets[n][k], float(detectors[n].accept_score)) for n in combo]
    return merge_coco_by_max(parts) if by_max else merge_detections(parts)


def _pct(a: int, b: int) -> str:
    return f"{a / b:.2f} ({a}/{b})" if b else "-"


def box_tables(detectors, gt, gt_dets, inv_photos, inv_dets, seen, groups) -> list[str]:
    """Markdown rows: per combination and threshold, box recall / precision on photos_gt and the
    inventory scores."""
    lines = [
        "| detectors | threshold (raw) | furniture recall | furniture precision | all-vocabulary recall | all-vocabulary precision | inventory instance R / P | inventory category R / P |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for combo, by_max in [(c, False) for c in COMBOS] + [(COMBOS[-1], True)]:
        if not all(n in detectors for n in combo):
            continue
        merged_gt = [_merged(combo, detectors, gt_dets, k, by_max) for k in range(len(gt))]
        merged_inv = [_merged(combo, detectors, inv_dets, k, by_max) for k in range(len(inv_photos))]
        for t in THRESHOLDS:
            furn = sum((score_boxes(m.boxes_xyxy_px, m.scores, m.labels, _vocab_truth(g[2]), t, FURNITURE) for m, g in zip(merged_gt, gt)), BoxScore(0, 0, 0))
            allv = sum((score_boxes(m.boxes_xyxy_px, m.scores, m.labels, _vocab_truth(g[2]), t) for m, g in zip(merged_gt, gt)), BoxScore(0, 0, 0))
            inv = pooled([score_inventory([lab for lab, s in zip(m.labels, m.scores) if lab and s >= t], seen[name], groups) for m, (name, _) in zip(merged_inv, inv_photos)])
            raw = f" ({t * detectors[combo[0]].accept_score / 0.5:.3g})" if len(combo) == 1 else ""
            lines.append(
                f"| {' + '.join(SHORT[n] for n in combo)}{' (COCO pair by max)' if by_max else ''} | {t:g}{raw} | {_pct(furn.matched, furn.truth)} | {_pct(furn.matched, furn.found)} | "
                f"{_pct(allv.matched, allv.truth)} | {_pct(allv.matched, allv.found)} | "
                f"{inv['instance_recall']:.2f} / {inv['instance_precision']:.2f} | {inv['category_recall']:.2f} / {inv['category_precision']:.2f} |"
            )
    return lines


def false_table(detectors, gt, gt_dets, inv_photos, inv_dets, seen, groups) -> list[str]:
    """Per detector: raw scores of its true detections (matching a photos_gt box) and of its
    detections of categories absent from an inventory photo."""
    from perception.detection import box_iou, family
    from scene_builder.bench.detect import canonical

    lines = [
        "| detector | accept_score | true detections on photos_gt: n, median, 10th-90th percentile | absent-category detections on the inventory photos (vocabulary, raw >= 0.1): n, scores of the highest five | n at or over accept_score |",
        "|---|---|---|---|---|",
    ]
    for name, det in detectors.items():
        true_scores = []
        for d, (_, _, truth) in zip(gt_dets[name], gt):
            vt = _vocab_truth(truth)
            tb = np.asarray([t[0] for t in vt], dtype=np.float64).reshape(-1, 4)
            for b, s, lab in zip(d.boxes_xyxy_px, d.scores, d.labels):
                if lab and len(vt) and any(box_iou(b[None], tb[j : j + 1])[0, 0] >= 0.5 and vt[j][1] in family(lab) for j in range(len(vt))):
                    true_scores.append(float(s))
        false_scores = []
        for d, (pname, _) in zip(inv_dets[name], inv_photos):
            have = {canonical(lab, groups) for lab in seen[pname]}
            false_scores += [float(s) for s, lab in zip(d.scores, d.labels) if lab and s >= 0.1 and canonical(lab, groups) not in have]
        ts, fs = np.asarray(true_scores), np.sort(np.asarray(false_scores))[::-1]
        acc = float(det.accept_score)
        tdesc = f"{len(ts)}, {np.median(ts):.2f}, {np.percentile(ts, 10):.2f}-{np.percentile(ts, 90):.2f}" if len(ts) else "0"
        lines.append(f"| {SHORT[name]} | {acc:g} | {tdesc} | {len(fs)}: {', '.join(f'{s:.2f}' for s in fs[:5])} | {int((fs >= acc).sum())} |")
    return lines


#: accept_score values tried per detector (the others keep theirs).
ACCEPT_SWEEP: dict[str, tuple[float, ...]] = {
    "centernet-mbv3-coco": (0.2, 0.25, 0.3, 0.35, 0.4),
    "nanodet-coco": (0.35, 0.4, 0.45, 0.5, 0.55, 0.6),
    "ssd-mobilenet-oid": (0.3, 0.35, 0.4, 0.45, 0.5, 0.6),
}


def accept_table(detectors, gt, gt_dets, inv_photos, inv_dets, seen, groups) -> list[str]:
    """Each detector's accept_score varied, the others at theirs: the detections that stand alone
    (merged score >= CONFIDENT) of the detectors run by default merged, with the varied one added
    when it is off by default."""
    from perception.detection import CONFIDENT
    from perception.learned import OFF_BY_DEFAULT

    lines = [
        "| varied | accept_score | merged detectors | furniture R / P (photos_gt) | all-vocabulary R / P (photos_gt) | inventory instance R / P | inventory category R / P |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, values in ACCEPT_SWEEP.items():
        if name not in detectors:
            continue
        det = detectors[name]
        own = det.accept_score
        combo = tuple(n for n in DETECTORS if n in detectors and (n not in OFF_BY_DEFAULT or n == name))
        try:
            for a in values:
                det.accept_score = a
                merged_gt = [_merged(combo, detectors, gt_dets, k) for k in range(len(gt))]
                merged_inv = [_merged(combo, detectors, inv_dets, k) for k in range(len(inv_photos))]
                furn = sum((score_boxes(m.boxes_xyxy_px, m.scores, m.labels, _vocab_truth(g[2]), CONFIDENT, FURNITURE) for m, g in zip(merged_gt, gt)), BoxScore(0, 0, 0))
                allv = sum((score_boxes(m.boxes_xyxy_px, m.scores, m.labels, _vocab_truth(g[2]), CONFIDENT) for m, g in zip(merged_gt, gt)), BoxScore(0, 0, 0))
                inv = pooled([score_inventory([lab for lab, s in zip(m.labels, m.scores) if lab and s >= CONFIDENT], seen[pn], groups) for m, (pn, _) in zip(merged_inv, inv_photos)])
                mark = " (its own)" if a == own else ""
                lines.append(
                    f"| {SHORT[name]} | {a:g}{mark} | {' + '.join(SHORT[n] for n in combo)} | {furn.matched / max(furn.truth, 1):.2f} / {furn.matched / max(furn.found, 1):.2f} | "
                    f"{allv.matched / max(allv.truth, 1):.2f} / {allv.matched / max(allv.found, 1):.2f} | "
                    f"{inv['instance_recall']:.2f} / {inv['instance_precision']:.2f} | {inv['category_recall']:.2f} / {inv['category_precision']:.2f} |"
                )
        finally:
            det.accept_score = own
    return lines


def merge_coco_by_max(parts, iou_threshold: float = 0.5):
    """A proposal measured here, not the product's merge: :func:`perception.detection.merge_detections`
    with the detectors trained on COCO (every class a COCO class) pooled first by the better score
    (NMS within label families on the merged scale) instead of the noisy-or, since two detectors
    trained on the same data make the same mistakes (pictures called tv)."""
    from perception.detection import COCO_CLASSES, CONFIDENT, merge_detections, suppress
    from perception.protocols import Detections

    coco_names = set(COCO_CLASSES)
    coco = [k for k, (d, _) in enumerate(parts) if len(d) and set(d.classes) <= coco_names]
    if len(coco) < 2:
        return merge_detections(parts, iou_threshold)
    pool = Detections(
        np.concatenate([parts[k][0].boxes_xyxy_px for k in coco]),
        np.concatenate([np.clip(CONFIDENT * parts[k][0].scores / parts[k][1], 0.0, 1.0) for k in coco]).astype(np.float32),
        tuple(lab for k in coco for lab in parts[k][0].labels),
        tuple(c for k in coco for c in parts[k][0].classes),
    )
    rest = [p for k, p in enumerate(parts) if k not in coco]
    return merge_detections([(suppress(pool, iou_threshold), CONFIDENT), *rest], iou_threshold)


#: Pipeline settings (``--pipeline``): name, then (module, attribute, value) set for the run and
#: restored after it. The modules are named; the values are what the run tries.
PIPELINE_SETTINGS: tuple[tuple[str, tuple[tuple[str, str, object], ...]], ...] = (
    ("default: CenterNet + SSD", ()),
    ("+ NanoDet (accept_score 0.4)", (("perception.learned", "OFF_BY_DEFAULT", frozenset()), ("perception.learned.detectors:NanoDetCocoDetector", "accept_score", 0.4))),
    ("+ NanoDet (accept_score 0.5)", (("perception.learned", "OFF_BY_DEFAULT", frozenset()), ("perception.learned.detectors:NanoDetCocoDetector", "accept_score", 0.5))),
    (
        "+ NanoDet (accept_score 0.5), COCO detectors pooled by max",
        (
            ("perception.learned", "OFF_BY_DEFAULT", frozenset()),
            ("perception.learned.detectors:NanoDetCocoDetector", "accept_score", 0.5),
            ("perception.segment_detect", "merge_detections", merge_coco_by_max),
        ),
    ),
    ("FLOOR_SCORE 0.12", (("perception.segment_detect", "FLOOR_SCORE", 0.12),)),
    ("FLOOR_SCORE 0.3", (("perception.segment_detect", "FLOOR_SCORE", 0.3),)),
    ("CenterNet accept_score 0.25", (("perception.learned.detectors:CenterNetCocoDetector", "accept_score", 0.25),)),
    ("CenterNet accept_score 0.35", (("perception.learned.detectors:CenterNetCocoDetector", "accept_score", 0.35),)),
    ("SSD accept_score 0.4", (("perception.learned.detectors:SsdOidDetector", "accept_score", 0.4),)),
    ("SSD accept_score 0.6", (("perception.learned.detectors:SsdOidDetector", "accept_score", 0.6),)),
)


def _target(where: str):
    import importlib

    module, _, cls = where.partition(":")
    obj = importlib.import_module(module)
    return getattr(obj, cls) if cls else obj


def pipeline_table(data: Path, inventory: Path, models_dir: Path | None, settings=PIPELINE_SETTINGS, echo: bool = False, root: str = "photos") -> list[str]:
    """``perceive`` (the "detections" segmenter: confirmation by depth and the semantic map, the
    classifier, masks) on the photos of ``data``/``root`` (as plain photos) under each setting:
    the scores of :mod:`scene_builder.bench.detect` against ``inventory``, objects found, and what
    changed against the first setting. echo: print each line as it is made (a long run keeps what
    it measured)."""
    from collections import Counter

    from scene_builder.bench.detect import run

    lines = [
        "| setting | instance recall | instance precision | category recall | category precision | objects | median s per photo | labels gained (+) and lost (-) against the default, per photo |",
        "|---|---|---|---|---|---|---|---|",
    ]
    if echo:
        print("\n".join(lines), flush=True)
    base = None
    for name, patches in settings:
        saved = []
        try:
            for where, attr, value in patches:
                obj = _target(where)
                saved.append((obj, attr, getattr(obj, attr)))
                setattr(obj, attr, value)
            result = run(data, inventory, models_dir, "detections", roots=(root,), quiet=True)
        finally:
            for obj, attr, value in reversed(saved):
                setattr(obj, attr, value)
        rows = [r for r in result["rows"] if "inventory" in r]
        labels = {r["photo"]: Counter(r["labels"]) for r in rows}
        base = base or labels
        changes = []
        for photo, c in labels.items():
            diff = [f"+{n} {lab}" for lab, n in sorted((c - base[photo]).items())] + [f"-{n} {lab}" for lab, n in sorted((base[photo] - c).items())]
            if diff:
                changes.append(f"{photo.split('/')[-1]}: {' '.join(diff)}")
        s, secs = result["inventory_scores"], sorted(r["seconds"] for r in rows)
        lines.append(
            f"| {name} | {s['instance_recall']:.3f} | {s['instance_precision']:.3f} | {s['category_recall']:.3f} | {s['category_precision']:.3f} | "
            f"{sum(r['objects'] for r in rows)} | {secs[len(secs) // 2]:.1f} | {'; '.join(changes) or '-'} |"
        )
        if echo:
            print(lines[-1], flush=True)
    return lines


def time_table(secs: dict) -> list[str]:
    lines = ["| detector | photos | median CPU s | slowest CPU s |", "|---|---|---|---|"]
    for name, s in secs.items():
        lines.append(f"| {SHORT[name]} | {len(s)} | {np.median(s):.3f} | {max(s):.3f} |")
    return lines


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder holding photos_gt/, photos/ and real/ (default ../shared/data)")
    ap.add_argument("--models-dir", type=Path, default=DEFAULT_MODELS if DEFAULT_MODELS.is_dir() else None, help="model files (default ../shared/models)")
    ap.add_argument("--inventory", type=Path, default=DEFAULT_INVENTORY)
    ap.add_argument("--skip-decoding", action="store_true", help="leave out NanoDet's decoding variants")
    ap.add_argument(
        "--pipeline",
        choices=("photos", "real", "both"),
        default=None,
        help="only the pipeline tables: perceive per setting on the inventory photos (photos: every setting, about 30 minutes) "
        "and on the real RGB-D photos used as plain photos against tests/data/real_inventory.json (real: the default and NanoDet added)",
    )
    args = ap.parse_args(argv)
    if args.pipeline:
        if args.pipeline in ("photos", "both"):
            print(f"On the {len(load_inventory(args.inventory)[0])} photos of {args.data / 'photos'} against {args.inventory.name}:\n", flush=True)
            pipeline_table(args.data, args.inventory, args.models_dir, echo=True)
        if args.pipeline in ("real", "both"):
            print(f"\nOn the photos of {args.data / 'real'} used as plain photos, against {REAL_INVENTORY.name}:\n", flush=True)
            pipeline_table(args.data, REAL_INVENTORY, args.models_dir, PIPELINE_SETTINGS[:3], echo=True, root="real")
        return
    detectors = load_detectors(args.models_dir)
    if not detectors:
        from scene_builder.errors import ModelUnavailableError

        raise ModelUnavailableError(f"no detector model file in {args.models_dir}; pass --models-dir with the shared models")
    seen, groups = load_inventory(args.inventory)
    gt = gt_photos(args.data)
    rooms = room_photos(args.data)
    inv_idx = [k for k, (n, _) in enumerate(rooms) if n.startswith("photos/") and n.split("/", 1)[1] in seen]
    inv_photos = [(rooms[k][0].split("/", 1)[1], rooms[k][1]) for k in inv_idx]
    gt_dets, _ = _run_all(detectors, gt)
    room_dets, secs = _run_all(detectors, rooms)
    inv_dets = {n: [room_dets[n][k] for k in inv_idx] for n in room_dets}
    print(f"Detectors found: {', '.join(SHORT[n] for n in detectors)}; photos_gt: {len(gt)} photos; inventory photos: {len(inv_photos)}; room photos: {len(rooms)}.\n")
    print("### Recall and precision per detector and merged\n")
    print("\n".join(box_tables(detectors, gt, gt_dets, inv_photos, inv_dets, seen, groups)))
    print("\n### Scores of true and of certainly false detections\n")
    print("\n".join(false_table(detectors, gt, gt_dets, inv_photos, inv_dets, seen, groups)))
    print("\n### Each detector's accept_score varied (merged, at CONFIDENT)\n")
    print("\n".join(accept_table(detectors, gt, gt_dets, inv_photos, inv_dets, seen, groups)))
    print("\n### CPU seconds per photo\n")
    print("\n".join(time_table(secs)))
    if not args.skip_decoding and "nanodet-coco" in detectors:
        from scene_builder.bench.nanodet_decoding import decoding_table

        print("\n### NanoDet's decoding: the chosen one against one wrong choice at a time\n")
        cn = detectors.get("centernet-mbv3-coco")
        print("\n".join(decoding_table(detectors["nanodet-coco"], gt, rooms, cn)))


if __name__ == "__main__":
    main()
