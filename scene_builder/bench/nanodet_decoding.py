"""NanoDet's decoding measured, not guessed: the chosen decoding of the raw heads
(:class:`perception.learned.detectors.NanoDetCocoDetector`) against one wrong choice at a time
(channel order, normalisation, letterbox or stretch, softmax or arg-max over the bins, side order,
cell centres, cell order, bin layout). Run through :mod:`scene_builder.bench.detectors`; the
variants here are measurement code, the product decodes with
:func:`perception.learned.detectors.nanodet_decode` only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["VARIANTS", "Variant", "ap50", "decoding_table", "variant_raw"]


@dataclass(frozen=True)
class Variant:
    """One way to feed and decode NanoDet. sides: where left, top, right, bottom are among the 4
    groups of bins; layout "side" = 4 groups of 11 bins, "bin" = 11 groups of 4 sides."""

    name: str
    bgr: bool = True
    meanstd: bool = True
    letterbox: bool = True
    softmax: bool = True
    sides: tuple[int, int, int, int] = (0, 1, 2, 3)
    centre: float = 0.5
    row_major: bool = True
    layout: str = "side"


VARIANTS: tuple[Variant, ...] = (
    Variant("chosen: BGR, mean/std, letterbox, softmax, l-t-r-b, (x + 0.5) stride, row-major, 4 x 11"),
    Variant("RGB order", bgr=False),
    Variant("x / 255, no mean/std", meanstd=False),
    Variant("stretched to 416 x 416", letterbox=False),
    Variant("arg-max bin, no softmax", softmax=False),
    Variant("sides t-l-b-r", sides=(1, 0, 3, 2)),
    Variant("sides l-r-t-b", sides=(0, 2, 1, 3)),
    Variant("centres x stride", centre=0.0),
    Variant("column-major cells", row_major=False),
    Variant("bins 11 x 4", layout="bin"),
)

_MEAN_BGR = np.array([103.53, 116.28, 123.675], dtype=np.float32)
_STD_BGR = np.array([57.375, 57.12, 58.395], dtype=np.float32)


def _input(det, rgb: np.ndarray, v: Variant) -> tuple[np.ndarray, tuple[float, float], tuple[float, float]]:
    from PIL import Image

    h, w = rgb.shape[:2]
    n = det.input_px
    if v.letterbox:
        s = n / max(h, w)
        nw, nh = max(1, round(w * s)), max(1, round(h * s))
        img = np.zeros((n, n, 3), dtype=np.float32)
        ox, oy = (n - nw) // 2, (n - nh) // 2
        img[oy : oy + nh, ox : ox + nw] = np.asarray(Image.fromarray(rgb).resize((nw, nh), Image.BILINEAR))
        scale, offset = (s, s), (ox, oy)
    else:
        img = np.asarray(Image.fromarray(rgb).resize((n, n), Image.BILINEAR)).astype(np.float32)
        scale, offset = (n / w, n / h), (0.0, 0.0)
    x = img[..., ::-1] if v.bgr else img
    if v.meanstd:
        mean, std = (_MEAN_BGR, _STD_BGR) if v.bgr else (_MEAN_BGR[::-1], _STD_BGR[::-1])
        x = (x - mean) / std
    else:
        x = x / 255.0
    return np.ascontiguousarray(x.transpose(2, 0, 1)[None], dtype=np.float32), scale, offset


def _decode(heads, v: Variant, min_score: float):
    boxes, scores, classes = [], [], []
    for cls, reg, stride in heads:
        n = cls.shape[0]
        side = int(round(np.sqrt(n)))
        cell, c = np.nonzero(cls >= min_score)
        r = np.asarray(reg, dtype=np.float64)[cell]
        r = r.reshape(-1, 4, 11) if v.layout == "side" else r.reshape(-1, 11, 4).transpose(0, 2, 1)
        if v.softmax:
            p = np.exp(r - r.max(axis=2, keepdims=True))
            d = (p / p.sum(axis=2, keepdims=True)) @ np.arange(11.0)
        else:
            d = r.argmax(axis=2).astype(np.float64)
        d = d[:, list(v.sides)] * stride
        col, row = (cell % side, cell // side) if v.row_major else (cell // side, cell % side)
        cx, cy = (col + v.centre) * stride, (row + v.centre) * stride
        boxes.append(np.stack([cx - d[:, 0], cy - d[:, 1], cx + d[:, 2], cy + d[:, 3]], axis=1))
        scores.append(cls[cell, c])
        classes.append(c)
    return np.concatenate(boxes), np.concatenate(scores), np.concatenate(classes)


def variant_raw(det, rgb: np.ndarray, v: Variant, min_score: float = 0.05) -> np.ndarray:
    """(K, 6) rows x1, y1, x2, y2 (photo pixels), score, COCO class of NanoDet fed and decoded as
    ``v`` says (the detector's own per-class NMS and mapping back)."""
    x, scale, offset = _input(det, rgb, v)
    boxes, scores, classes = _decode(det.heads(x), v, min_score)
    return det.finish(boxes, scores, classes, rgb.shape[:2], scale, offset)


def ap50(items: list[tuple[np.ndarray, np.ndarray]]) -> float:
    """Average precision at IoU 0.5 pooled over classes: items = (truth (M, 5) xyxy + class,
    detections (K, 6)) per photo; all-point interpolation."""
    from perception.detection import box_iou

    rows, n_truth = [], 0
    for truth, det in items:
        n_truth += len(truth)
        used = np.zeros(len(truth), dtype=bool)
        for j in np.argsort(-det[:, 4], kind="stable"):
            ok = False
            if len(truth):
                iou = box_iou(det[j : j + 1, :4], truth[:, :4])[0]
                iou[(truth[:, 4] != det[j, 5]) | used] = 0.0
                k = int(iou.argmax())
                if iou[k] >= 0.5:
                    used[k], ok = True, True
            rows.append((float(det[j, 4]), ok))
    if not rows or not n_truth:
        return 0.0
    rows.sort(key=lambda r: -r[0])
    hits = np.array([r[1] for r in rows])
    tp, fp = np.cumsum(hits), np.cumsum(~hits)
    recall, precision = tp / n_truth, tp / (tp + fp)
    precision = np.maximum.accumulate(precision[::-1])[::-1]
    return float(np.sum(np.diff(np.concatenate([[0.0], recall])) * precision))


def _match(truth: np.ndarray, det: np.ndarray, min_iou: float) -> list[tuple[int, int, float]]:
    """Greedy same-class matches (truth index, detection index, IoU), best score first."""
    from perception.detection import box_iou

    out, used = [], np.zeros(len(truth), dtype=bool)
    for j in np.argsort(-det[:, 4], kind="stable"):
        if not len(truth):
            break
        iou = box_iou(det[j : j + 1, :4], truth[:, :4])[0]
        iou[(truth[:, 4] != det[j, 5]) | used] = 0.0
        k = int(iou.argmax())
        if iou[k] >= min_iou:
            used[k] = True
            out.append((k, int(j), float(iou[k])))
    return out


def decoding_table(det, gt, rooms, centernet=None) -> list[str]:
    """Markdown rows, one per variant. gt: (name, rgb, [(box, COCO class)]) per photo; rooms:
    (name, rgb) per photo; centernet: its detector, whose boxes (score >= 0.3) are a second
    reference on the rooms."""
    from perception.detection import COCO_CLASSES

    truths = [np.asarray([[*b, COCO_CLASSES.index(c)] for b, c in t], dtype=np.float64).reshape(-1, 5) for _, _, t in gt]
    refs = []
    if centernet is not None:
        for _, rgb in rooms:
            r = centernet.raw(rgb)
            r = r[r[:, 4] >= 0.3]
            r = det.finish(r[:, :4], r[:, 4], r[:, 5].astype(np.int64), rgb.shape[:2], (1.0, 1.0), (0.0, 0.0))
            refs.append(np.concatenate([r[:, :4], r[:, 5:6]], axis=1))
    n_truth, n_ref = sum(len(t) for t in truths), sum(len(r) for r in refs)
    lines = [
        f"| variant | AP50, photos_gt ({n_truth} COCO boxes) | recall at score 0.3 | precision at 0.3 | mean IoU of matches | median centre offset dx, dy (input px) "
        f"| CenterNet boxes found, score >= 0.1 (of {n_ref}) | AP50 against CenterNet's boxes |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for v in VARIANTS:
        dets = [variant_raw(det, rgb, v) for _, rgb, _ in gt]
        hit = found = 0
        ious, offs = [], []
        for (_, rgb, _), t, d in zip(gt, truths, dets):
            strong = d[d[:, 4] >= 0.3]
            hit += len([m for m in _match(t, strong, 0.5)])
            found += len(strong)
            s = det.input_px / max(rgb.shape[:2])
            for k, j, iou in _match(t, d[d[:, 4] >= 0.2], 0.3):
                ious.append(iou)
                offs.append(((d[j, 0] + d[j, 2] - t[k, 0] - t[k, 2]) * s / 2, (d[j, 1] + d[j, 3] - t[k, 1] - t[k, 3]) * s / 2))
        ap = ap50(list(zip(truths, dets)))
        off = np.median(np.asarray(offs), axis=0) if offs else (np.nan, np.nan)
        row = f"| {v.name} | {ap:.3f} | {hit}/{n_truth} | {hit}/{found} | {np.mean(ious) if ious else 0:.3f} | {off[0]:+.1f}, {off[1]:+.1f} |"
        if refs:
            rdets = [variant_raw(det, rgb, v) for _, rgb in rooms]
            got = sum(len(_match(r, d[d[:, 4] >= 0.1], 0.5)) for r, d in zip(refs, rdets))
            row += f" {got}/{n_ref} | {ap50(list(zip(refs, rdets))):.3f} |"
        else:
            row += " - | - |"
        lines.append(row)
    return lines
