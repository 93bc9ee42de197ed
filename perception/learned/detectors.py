"""Offline object detectors and a semantic segmenter over small model files (no model hub):

* :class:`CenterNetCocoDetector`: CenterNet with a MobileNetV3 backbone, 80 COCO classes, ONNX
  (onnxruntime). Input: the whole photo resized (bilinear) to 512 x 512, RGB 0..255, no
  normalisation; output ``tower_0/detections`` (1, 100, 6) = x1, y1, x2, y2 in the 512 px input,
  score, COCO class index. Overlapping boxes remain: NMS here.
* :class:`NanoDetCocoDetector`: NanoDet (ShuffleNetV2, generalised-focal-loss head), 80 COCO
  classes, ONNX. Raw heads per stride 8, 16, 32 (:func:`nanodet_decode`); the decoding was
  verified on photos with COCO ground truth (BENCHMARKS.md, ``scene_builder.bench.detectors``).
* :class:`SsdOidDetector`: SSD MobileNetV2, 23 Open Images classes, TFLite (ai-edge-litert).
  Raw heads: box regressions (1917, 4) and class logits (1917, 24) over the TF Object Detection
  API's multiple-grid anchors (:func:`ssd_anchors`), box coder scales (10, 10, 5, 5), sigmoid
  scores. It adds desks and tables, which COCO's "dining table" often misses in offices and
  classrooms.
* :class:`DeepLabPascalSegmenter`: DeepLab v3 MobileNetV2, PASCAL VOC 21 classes, quantised
  TFLite: (1, 513, 513, 3) uint8 in, (1, 513, 513) class map out.

The file formats are described in the shared models folder's README; the model registry
(:mod:`perception.models`) finds the files.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from perception.detection import COCO_CLASSES, COCO_TO_LABEL, OID_TO_LABEL, PASCAL_TO_LABEL, empty_detections, suppress
from perception.protocols import Detections, SemanticMap
from scene_builder.errors import InputError

__all__ = ["CenterNetCocoDetector", "DeepLabPascalSegmenter", "NanoDetCocoDetector", "SsdOidDetector", "nanodet_decode", "ssd_anchors"]

#: CPU threads for the detectors (the machines this runs on have 2 cores).
_THREADS = 2


def _resize(rgb: np.ndarray, width: int, height: int) -> np.ndarray:
    from PIL import Image

    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise InputError(f"detector input must be an (H, W, 3) uint8 image, got {rgb.shape} {rgb.dtype}")
    return np.asarray(Image.fromarray(rgb).resize((width, height), Image.BILINEAR))


def _labelled(boxes: np.ndarray, scores: np.ndarray, classes: list[str], table: dict[str, str]) -> Detections:
    """Detections with the vocabulary label of each class (``""`` for classes outside it)."""
    keep = [i for i, c in enumerate(classes) if c]
    if not keep:
        return empty_detections()
    return Detections(
        np.asarray(boxes, dtype=np.float64)[keep],
        np.asarray(scores, dtype=np.float32)[keep],
        tuple(table.get(classes[i], "") for i in keep),
        tuple(classes[i] for i in keep),
    )


class CenterNetCocoDetector:
    """COCO detections (mapped to the vocabulary) from ``centernet_mbv3_coco.onnx``.

    min_score: the lowest score returned. accept_score: the score at which a detection is
    trusted alone (0.3: on real rooms its sofas, chairs, plants and tvs score 0.35-0.65).
    """

    input_px = 512
    accept_score = 0.3

    def __init__(self, weights: Path | str, min_score: float = 0.08) -> None:
        import onnxruntime as ort

        opts = ort.SessionOptions()
        opts.intra_op_num_threads = _THREADS
        opts.inter_op_num_threads = 1
        self.session = ort.InferenceSession(str(weights), sess_options=opts, providers=["CPUExecutionProvider"])
        self.input_name = self.session.get_inputs()[0].name
        outputs = [o.name for o in self.session.get_outputs()]
        self.output_name = next((n for n in outputs if n.endswith("detections")), None)
        if self.output_name is None:
            raise InputError(f"{weights} has no 'detections' output (outputs: {', '.join(outputs)}); is it the CenterNet COCO model?")
        self.min_score = float(min_score)

    def raw(self, rgb: np.ndarray) -> np.ndarray:
        """(100, 6) rows x1, y1, x2, y2 (input pixels), score, COCO class index."""
        h, w = np.asarray(rgb).shape[:2]
        x = _resize(rgb, self.input_px, self.input_px).astype(np.float32)[None]
        out = np.asarray(self.session.run([self.output_name], {self.input_name: x})[0], dtype=np.float64).reshape(-1, 6)
        out[:, [0, 2]] *= w / self.input_px
        out[:, [1, 3]] *= h / self.input_px
        out[:, [0, 2]] = np.clip(out[:, [0, 2]], 0, w)
        out[:, [1, 3]] = np.clip(out[:, [1, 3]], 0, h)
        return out

    def detect(self, rgb: np.ndarray) -> Detections:
        out = self.raw(rgb)
        out = out[(out[:, 4] >= self.min_score) & (out[:, 2] > out[:, 0]) & (out[:, 3] > out[:, 1])]
        classes = [COCO_CLASSES[int(c)] if 0 <= int(c) < len(COCO_CLASSES) else "" for c in out[:, 5]]
        return suppress(_labelled(out[:, :4], out[:, 4], classes, COCO_TO_LABEL))


#: NanoDet's strides and bins per box side (distances 0..10 strides).
NANODET_STRIDES = (8, 16, 32)
NANODET_BINS = 11
#: NanoDet's input normalisation: BGR channel order, then (x - mean) / std per channel.
_NANODET_MEAN_BGR = np.array([103.53, 116.28, 123.675], dtype=np.float32)
_NANODET_STD_BGR = np.array([57.375, 57.12, 58.395], dtype=np.float32)


def nanodet_decode(heads: list[tuple[np.ndarray, np.ndarray, int]], min_score: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boxes from NanoDet's raw heads, in the pixels of its square input.

    heads: per stride, (class scores (N, C), already through a sigmoid in the graph; box
    distributions (N, 4 * 11): for each side left, top, right, bottom in that order, 11 logits over
    distances of 0..10 strides; stride). Cells are row-major over a (side / stride)^2 grid, each
    centred at ((column + 0.5) stride, (row + 0.5) stride). A side's distance is the expectation of
    the softmax over its bins (the generalised-focal-loss integral) times the stride.
    Returns (boxes (K, 4) xyxy, scores (K,), class indices (K,)): one row per (cell, class) pair
    scoring ``min_score`` or more (multi-label, as NanoDet's own post-processing).
    """
    boxes, scores, classes = [], [], []
    for cls, reg, stride in heads:
        cls = np.asarray(cls, dtype=np.float64)
        n = cls.shape[0]
        side = int(round(np.sqrt(n)))
        if side * side != n or np.asarray(reg).shape != (n, 4 * NANODET_BINS):
            raise InputError(f"NanoDet head of {n} cells and box shape {np.asarray(reg).shape} is not a square grid with 4 x {NANODET_BINS} bins")
        cell, c = np.nonzero(cls >= min_score)
        if not len(cell):
            continue
        logits = np.asarray(reg, dtype=np.float64)[cell].reshape(-1, 4, NANODET_BINS)
        p = np.exp(logits - logits.max(axis=2, keepdims=True))
        dist = (p / p.sum(axis=2, keepdims=True)) @ np.arange(NANODET_BINS, dtype=np.float64) * stride
        cx = (cell % side + 0.5) * stride
        cy = (cell // side + 0.5) * stride
        boxes.append(np.stack([cx - dist[:, 0], cy - dist[:, 1], cx + dist[:, 2], cy + dist[:, 3]], axis=1))
        scores.append(cls[cell, c])
        classes.append(c)
    if not boxes:
        return np.zeros((0, 4)), np.zeros(0), np.zeros(0, dtype=np.int64)
    return np.concatenate(boxes), np.concatenate(scores), np.concatenate(classes).astype(np.int64)


class NanoDetCocoDetector:
    """COCO detections (mapped to the vocabulary) from ``nanodet_coco.onnx`` (NanoDet-m, 416 px).

    Input: the photo letterboxed into 416 x 416 (scaled to fit, centred, black borders; NanoDet's
    own ``keep_ratio`` transform: it gave higher scores and box IoU than a plain stretch on the
    COCO ground truth of ``photos_gt``), BGR, ``(x - mean) / std`` with NanoDet's ImageNet
    statistics, NCHW. Heads decoded by :func:`nanodet_decode`; per-class NMS (IoU 0.6, NanoDet's),
    then :func:`perception.detection.suppress` as for the other detectors.

    min_score: the lowest score returned (0.1: just under the segmenter's proposal floor, 0.12 on
    the merged scale, where an accept_score of 0.5 leaves NanoDet's scores unchanged). accept_score: the score at which a detection is
    trusted alone: 0.5, over every detection of a category absent from an inventory photo (the
    highest 0.49: pictures called tv, cabinets called refrigerator; 4 reach 0.4); its beds, sofas
    and chairs on room photos score 0.5-0.75, its true detections on photos_gt a median of 0.39.
    In the pipeline 0.5 kept precision higher than 0.4 (0.836 against 0.797 on the inventory
    photos; BENCHMARKS.md, "Offline detectors in the pipeline").
    """

    input_px = 416
    accept_score = 0.5

    def __init__(self, weights: Path | str, min_score: float = 0.1) -> None:
        import onnxruntime as ort

        opts = ort.SessionOptions()
        opts.intra_op_num_threads = _THREADS
        opts.inter_op_num_threads = 1
        self.session = ort.InferenceSession(str(weights), sess_options=opts, providers=["CPUExecutionProvider"])
        inp = self.session.get_inputs()[0]
        self.input_name = inp.name
        if list(inp.shape) != [1, 3, self.input_px, self.input_px]:
            raise InputError(f"{weights} takes input {inp.shape}, expected [1, 3, 416, 416]; is it the NanoDet COCO model?")
        self.output_names = [o.name for o in self.session.get_outputs()]
        if len(self.output_names) != 6:
            raise InputError(f"{weights} has {len(self.output_names)} outputs, expected 6 (class scores and box bins per stride); is it the NanoDet COCO model?")
        self.min_score = float(min_score)

    def preprocess(self, rgb: np.ndarray) -> tuple[np.ndarray, float, int, int]:
        """(the (1, 3, 416, 416) float32 input, scale, x offset, y offset): the photo letterboxed
        (input pixel = photo pixel * scale + offset), BGR, normalised."""
        h, w = np.asarray(rgb).shape[:2]
        scale = self.input_px / max(h, w)
        nw, nh = max(1, round(w * scale)), max(1, round(h * scale))
        canvas = np.zeros((self.input_px, self.input_px, 3), dtype=np.float32)
        ox, oy = (self.input_px - nw) // 2, (self.input_px - nh) // 2
        canvas[oy : oy + nh, ox : ox + nw] = _resize(rgb, nw, nh)
        x = ((canvas[..., ::-1] - _NANODET_MEAN_BGR) / _NANODET_STD_BGR).transpose(2, 0, 1)[None]
        return np.ascontiguousarray(x, dtype=np.float32), scale, ox, oy

    def heads(self, x: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, int]]:
        """The raw heads of input ``x`` (1, 3, 416, 416), as :func:`nanodet_decode` takes them."""
        outs = [np.asarray(o)[0] for o in self.session.run(self.output_names, {self.input_name: x})]
        by_cells: dict[int, dict[str, np.ndarray]] = {}
        for o in outs:
            by_cells.setdefault(o.shape[0], {})["box" if o.shape[1] == 4 * NANODET_BINS else "cls"] = o
        heads = []
        for stride in NANODET_STRIDES:
            n = (self.input_px // stride) ** 2
            pair = by_cells.get(n, {})
            if set(pair) != {"box", "cls"} or pair["cls"].shape[1] != len(COCO_CLASSES):
                raise InputError(f"NanoDet output for stride {stride} ({n} cells) missing or not 80 classes; is it the NanoDet COCO model?")
            heads.append((pair["cls"], pair["box"], stride))
        return heads

    @staticmethod
    def finish(boxes: np.ndarray, scores: np.ndarray, classes: np.ndarray, size: tuple[int, int], scale: tuple[float, float], offset: tuple[float, float]) -> np.ndarray:
        """Input-pixel detections into (K, 6) rows x1, y1, x2, y2 (photo pixels), score, class
        index: mapped back (photo = (input - offset) / scale, per axis), clipped to the photo of
        ``size`` (h, w), per-class NMS at IoU 0.6, best first, at most 100."""
        import cv2

        h, w = size
        boxes = np.array(boxes, dtype=np.float64).reshape(-1, 4)
        boxes[:, [0, 2]] = np.clip((boxes[:, [0, 2]] - offset[0]) / scale[0], 0, w)
        boxes[:, [1, 3]] = np.clip((boxes[:, [1, 3]] - offset[1]) / scale[1], 0, h)
        ok = (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])
        boxes, scores, classes = boxes[ok], np.asarray(scores, dtype=np.float64)[ok], np.asarray(classes, dtype=np.int64)[ok]
        if not len(scores):
            return np.zeros((0, 6))
        rects = [[float(x0), float(y0), float(x1 - x0), float(y1 - y0)] for x0, y0, x1, y1 in boxes]
        hit = np.asarray(cv2.dnn.NMSBoxesBatched(rects, scores.tolist(), classes.tolist(), 0.0, 0.6), dtype=np.int64).reshape(-1)
        hit = hit[np.lexsort((hit, -scores[hit]))][:100]
        return np.concatenate([boxes[hit], scores[hit, None], classes[hit, None].astype(np.float64)], axis=1)

    def raw(self, rgb: np.ndarray) -> np.ndarray:
        """(K, 6) rows x1, y1, x2, y2 (photo pixels), score, COCO class index (see :meth:`finish`)."""
        x, scale, ox, oy = self.preprocess(rgb)
        boxes, scores, classes = nanodet_decode(self.heads(x), self.min_score)
        return self.finish(boxes, scores, classes, np.asarray(rgb).shape[:2], (scale, scale), (ox, oy))

    def detect(self, rgb: np.ndarray) -> Detections:
        out = self.raw(rgb)
        classes = [COCO_CLASSES[int(c)] for c in out[:, 5]]
        return suppress(_labelled(out[:, :4], out[:, 4], classes, COCO_TO_LABEL))


def ssd_anchors(
    feature_maps: tuple[int, ...] = (19, 10, 5, 3, 2, 1),
    min_scale: float = 0.2,
    max_scale: float = 0.95,
    aspect_ratios: tuple[float, ...] = (1.0, 2.0, 0.5, 3.0, 1.0 / 3.0),
) -> np.ndarray:
    """(N, 4) anchors (y_centre, x_centre, height, width), normalised, in the TF Object Detection
    API's ``multiple_grid_anchor_generator`` order (per feature map, row-major cells, anchors per
    cell): the lowest layer has 3 anchors ((0.1, 1), (0.2, 2), (0.2, 1/2)); every other layer its
    scale with each aspect ratio plus one of scale sqrt(s_k s_k+1) at ratio 1. 1917 anchors for the
    default 300 x 300 SSD MobileNet."""
    n = len(feature_maps)
    scales = [min_scale + (max_scale - min_scale) * i / (n - 1) for i in range(n)] + [1.0]
    rows = []
    for k, fm in enumerate(feature_maps):
        if k == 0:
            specs = [(0.1, 1.0), (scales[0], 2.0), (scales[0], 0.5)]
        else:
            specs = [(scales[k], ar) for ar in aspect_ratios] + [(float(np.sqrt(scales[k] * scales[k + 1])), 1.0)]
        ys, xs = np.meshgrid((np.arange(fm) + 0.5) / fm, (np.arange(fm) + 0.5) / fm, indexing="ij")
        cells = np.stack([ys.ravel(), xs.ravel()], axis=1)
        hw = np.array([[s / np.sqrt(ar), s * np.sqrt(ar)] for s, ar in specs])
        rows.append(np.concatenate([np.repeat(cells, len(specs), axis=0), np.tile(hw, (len(cells), 1))], axis=1))
    return np.concatenate(rows)


class SsdOidDetector:
    """Open Images detections (mapped to the vocabulary) from the SSD MobileNetV2 TFLite file.

    accept_score: 0.5 (its sigmoid scores reach 0.4 on plain walls and floors).
    """

    input_px = 300
    accept_score = 0.5

    def __init__(self, weights: Path | str, labelmap: Path | str | None = None, min_score: float = 0.12) -> None:
        from ai_edge_litert.interpreter import Interpreter

        weights = Path(weights)
        labelmap = Path(labelmap) if labelmap is not None else weights.with_name("object_detection_oidv4_labelmap.txt")
        if not labelmap.is_file():
            raise InputError(f"label map {labelmap} not found; put it beside {weights.name}")
        self.classes = [line.strip() for line in labelmap.read_text().splitlines()]
        self.interpreter = Interpreter(model_path=str(weights), num_threads=_THREADS)
        self.interpreter.allocate_tensors()
        self.input_index = self.interpreter.get_input_details()[0]["index"]
        outs = {o["name"]: o["index"] for o in self.interpreter.get_output_details()}
        self.box_index = next(i for n, i in outs.items() if "box" in n)
        self.class_index = next(i for n, i in outs.items() if "class" in n)
        self.anchors = ssd_anchors()
        self.min_score = float(min_score)

    def detect(self, rgb: np.ndarray) -> Detections:
        import cv2

        h, w = np.asarray(rgb).shape[:2]
        x = _resize(rgb, self.input_px, self.input_px).astype(np.float32) / 127.5 - 1.0
        self.interpreter.set_tensor(self.input_index, x[None])
        self.interpreter.invoke()
        reg = np.asarray(self.interpreter.get_tensor(self.box_index), dtype=np.float64)[0]
        logits = np.asarray(self.interpreter.get_tensor(self.class_index), dtype=np.float64)[0]
        if len(reg) != len(self.anchors):
            raise InputError(f"SSD model has {len(reg)} anchors, expected {len(self.anchors)}; is it the 300 px SSD MobileNetV2?")
        a = self.anchors
        yc = reg[:, 0] / 10.0 * a[:, 2] + a[:, 0]
        xc = reg[:, 1] / 10.0 * a[:, 3] + a[:, 1]
        bh = np.exp(reg[:, 2] / 5.0) * a[:, 2]
        bw = np.exp(reg[:, 3] / 5.0) * a[:, 3]
        boxes = np.stack([(xc - bw / 2) * w, (yc - bh / 2) * h, (xc + bw / 2) * w, (yc + bh / 2) * h], axis=1)
        boxes[:, [0, 2]] = np.clip(boxes[:, [0, 2]], 0, w)
        boxes[:, [1, 3]] = np.clip(boxes[:, [1, 3]], 0, h)
        scores = 1.0 / (1.0 + np.exp(-logits))
        out_boxes, out_scores, out_classes = [], [], []
        for c in range(1, min(scores.shape[1], len(self.classes))):
            name = self.classes[c]
            idx = np.flatnonzero(scores[:, c] >= self.min_score)
            if not len(idx):
                continue
            rects = [[float(b[0]), float(b[1]), float(b[2] - b[0]), float(b[3] - b[1])] for b in boxes[idx]]
            hit = np.asarray(cv2.dnn.NMSBoxes(rects, [float(s) for s in scores[idx, c]], 0.0, 0.5), dtype=np.int64).reshape(-1)
            out_boxes.append(boxes[idx[hit]])
            out_scores.append(scores[idx[hit], c])
            out_classes.extend([name] * len(hit))
        if not out_classes:
            return empty_detections()
        return suppress(_labelled(np.concatenate(out_boxes), np.concatenate(out_scores), out_classes, OID_TO_LABEL))


class DeepLabPascalSegmenter:
    """PASCAL VOC semantic classes of every pixel (mapped to the vocabulary) from the DeepLab v3
    MobileNetV2 TFLite file."""

    input_px = 513

    def __init__(self, weights: Path | str, labels: Path | str | None = None) -> None:
        from ai_edge_litert.interpreter import Interpreter

        weights = Path(weights)
        labels = Path(labels) if labels is not None else weights.with_name("pascal_voc_segmentation_labels.txt")
        if not labels.is_file():
            raise InputError(f"label file {labels} not found; put it beside {weights.name}")
        names = [line.strip() for line in labels.read_text().splitlines()][:21]
        self.classes = tuple(names)
        self.labels = tuple(PASCAL_TO_LABEL.get(n, "") for n in names)
        self.interpreter = Interpreter(model_path=str(weights), num_threads=_THREADS)
        self.interpreter.allocate_tensors()
        self.input_index = self.interpreter.get_input_details()[0]["index"]
        self.output_index = self.interpreter.get_output_details()[0]["index"]

    def segment_classes(self, rgb: np.ndarray) -> SemanticMap:
        import cv2

        h, w = np.asarray(rgb).shape[:2]
        x = _resize(rgb, self.input_px, self.input_px)
        self.interpreter.set_tensor(self.input_index, x[None])
        self.interpreter.invoke()
        cls = np.asarray(self.interpreter.get_tensor(self.output_index)).reshape(self.input_px, self.input_px).astype(np.int32)
        cls = np.where((cls >= 0) & (cls < len(self.labels)), cls, 0).astype(np.int32)
        full = cv2.resize(cls.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST)
        return SemanticMap(full.astype(np.int32), self.labels, self.classes)
