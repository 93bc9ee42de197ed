"""SAM 2 automatic instance masks and box-prompted masks (``transformers`` ``Sam2Model``).

transformers' ``Sam2ImageProcessor`` needs torchvision, which cannot be installed on this
project's machines, so preprocessing is written here: the SAM 2 checkpoints were trained on the
whole image resized to a 1024 x 1024 square (SAM 2's own ``SAM2Transforms``; SAM 1 instead
letterboxed the longest side to 1024), ImageNet mean/std. ``letterbox=True`` selects the SAM 1
style (longest side to 1024, zero padding bottom/right) for checkpoints trained that way; masks are
mapped back either way. Prompt coordinates follow ``SAM2Transforms.transform_coords``: continuous
image coordinates scaled by 1024 / width and 1024 / height.

The automatic generator is upstream's ``SAM2AutomaticMaskGenerator`` (facebookresearch/sam2,
``sam2/automatic_mask_generator.py``) with one crop layer, its defaults in
:class:`scene_builder.config.Sam2Settings`: a regular grid of single positive point prompts
(``build_point_grid``), three masks per point, predicted IoU ``> pred_iou_thresh``, stability
``>= stability_score_thresh``, then **box** NMS (boxes of the masks, scored by predicted IoU,
``batched_nms`` at ``box_nms_thresh``), then, only when ``min_mask_region_area_px > 0``, removal
of small islands and holes followed by another box NMS that prefers unchanged masks. torchvision's
``batched_nms`` cannot be used here (no torchvision), so :func:`box_nms` reimplements it (same
IoU, same strict ``>`` test).

One deviation, for memory: upstream computes the stability score and the mask boxes on logits
upsampled to the full photo; here they are computed on the decoder's 256 x 256 logits (16x fewer
pixels than a 1024 image, and no K x H x W float array for a 12 MP photo), and only the surviving
masks are upsampled. Box IoU is unchanged by the common scaling; stability differs only by
boundary pixels.

After upstream's generator, :meth:`Sam2Segmenter.segment` drops masks lying mostly on floor,
walls or ceiling and gives each pixel to the best-ranked mask covering it (no pixel in two
instances), this project's own steps.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from perception.protocols import InstanceMasks
from scene_builder.config import Sam2Settings
from scene_builder.errors import InputError, ModelUnavailableError
from scene_builder.model import CameraIntrinsics, as_array

__all__ = [
    "MaskProposals",
    "Sam2Segmenter",
    "assign_instances",
    "box_iou_matrix",
    "box_nms",
    "mask_iou_matrix",
    "mask_nms",
    "masks_to_boxes",
    "point_grid",
    "preprocess",
    "remove_small_regions",
    "stability_score",
]

IMAGENET_MEAN = np.array([0.485, 0.456, 0.406], dtype=np.float32)
IMAGENET_STD = np.array([0.229, 0.224, 0.225], dtype=np.float32)


@dataclass(frozen=True, eq=False)
class MaskProposals:
    """Candidate masks of one image, best first.

    masks: (K, H, W) bool at the input resolution (may overlap).
    predicted_iou: (K,) float32, the decoder's own IoU estimate.
    stability: (K,) float32, IoU of the mask thresholded at +offset and -offset on the logits.
    points_px: (K, 2) float64 (u, v) of the prompt point each mask came from (NaN for box prompts).
    """

    masks: np.ndarray
    predicted_iou: np.ndarray
    stability: np.ndarray
    points_px: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "masks", as_array(self.masks, np.bool_, (None, None, None), "MaskProposals.masks"))
        k = self.masks.shape[0]
        object.__setattr__(self, "predicted_iou", as_array(self.predicted_iou, np.float32, (k,), "MaskProposals.predicted_iou"))
        object.__setattr__(self, "stability", as_array(self.stability, np.float32, (k,), "MaskProposals.stability"))
        pts = np.array(self.points_px, dtype=np.float64).reshape(k, 2)
        pts.setflags(write=False)
        object.__setattr__(self, "points_px", pts)

    @property
    def scores(self) -> np.ndarray:
        """(K,) float32 ranking score: the predicted IoU (upstream ranks and NMS-es by it)."""
        return self.predicted_iou


# --------------------------------------------------------------------------------------------
# Pure functions on masks (numpy; unit-tested on hand-made masks)
# --------------------------------------------------------------------------------------------


def point_grid(points_per_side: int, width_px: int, height_px: int) -> np.ndarray:
    """(n*n, 2) float64 continuous image coordinates (u, v) of a regular grid with half-cell
    margins, rows first, x fastest: upstream's ``build_point_grid(n)`` (points
    ``(i + 0.5) / n`` of [0, 1]) times the image size, as ``_process_crop`` scales it."""
    if points_per_side < 1:
        raise InputError("points_per_side must be at least 1")
    t = (np.arange(points_per_side) + 0.5) / points_per_side
    uu, vv = np.meshgrid(t * width_px, t * height_px)
    return np.stack([uu.ravel(), vv.ravel()], axis=-1)


def stability_score(logits: np.ndarray, threshold: float = 0.0, offset: float = 1.0) -> np.ndarray:
    """Stability of masks under a shift of the logit threshold.

    logits: (N, H, W) float. Returns (N,) float32: |logits > t + offset| / |logits > t - offset|
    (the IoU of the two masks, since one contains the other); 0 for an empty mask.
    """
    x = np.asarray(logits)
    inter = (x > threshold + offset).reshape(len(x), -1).sum(axis=1)
    union = (x > threshold - offset).reshape(len(x), -1).sum(axis=1)
    return np.where(union > 0, inter / np.maximum(union, 1), 0.0).astype(np.float32)


def mask_iou_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, M) float64 IoU between masks a: (N, H, W) bool and b: (M, H, W) bool."""
    fa = np.asarray(a, dtype=np.float32).reshape(len(a), -1)
    fb = np.asarray(b, dtype=np.float32).reshape(len(b), -1)
    inter = fa @ fb.T
    union = fa.sum(1)[:, None] + fb.sum(1)[None, :] - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-9), 0.0).astype(np.float64)


def mask_nms(masks: np.ndarray, scores: np.ndarray, iou_threshold: float = 0.7) -> np.ndarray:
    """Greedy non-maximum suppression by mask IoU.

    masks: (N, H, W) bool; scores: (N,). Returns (K,) int64 indices of the kept masks, best first:
    a mask is dropped when its IoU with an already kept, higher-scoring mask exceeds
    ``iou_threshold``. Ties in score keep the lower index (deterministic).
    """
    scores = np.asarray(scores, dtype=np.float64)
    order = np.lexsort((np.arange(len(scores)), -scores))
    flat = np.asarray(masks, dtype=np.bool_).reshape(len(masks), -1)
    areas = flat.sum(axis=1).astype(np.float64)
    kept: list[int] = []
    for i in order:
        if areas[i] == 0:
            continue
        if kept:
            inter = (flat[kept] & flat[i]).sum(axis=1)
            iou = inter / (areas[kept] + areas[i] - inter)
            if np.any(iou > iou_threshold):
                continue
        kept.append(int(i))
    return np.array(kept, dtype=np.int64)


def masks_to_boxes(masks: np.ndarray) -> np.ndarray:
    """(K, 4) float64 boxes (x0, y0, x1, y1) of (K, H, W) bool masks, x1 / y1 the last occupied
    column / row (inclusive), [0, 0, 0, 0] for an empty mask: upstream's ``batched_mask_to_box``."""
    m = np.asarray(masks, dtype=np.bool_)
    out = np.zeros((len(m), 4), dtype=np.float64)
    if len(m) == 0:
        return out
    cols = m.any(axis=1)  # (K, W)
    rows = m.any(axis=2)  # (K, H)
    nonempty = cols.any(axis=1)
    w, h = m.shape[2], m.shape[1]
    out[:, 0] = np.argmax(cols, axis=1)
    out[:, 2] = w - 1 - np.argmax(cols[:, ::-1], axis=1)
    out[:, 1] = np.argmax(rows, axis=1)
    out[:, 3] = h - 1 - np.argmax(rows[:, ::-1], axis=1)
    out[~nonempty] = 0.0
    return out


def box_iou_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, M) IoU of boxes a: (N, 4) and b: (M, 4), xyxy, area (x1 - x0) * (y1 - y0) as
    torchvision's ``box_iou`` computes it."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    wh = np.clip(rb - lt, 0.0, None)
    inter = wh[..., 0] * wh[..., 1]
    union = area_a[:, None] + area_b[None, :] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def box_nms(boxes_xyxy: np.ndarray, scores: np.ndarray, iou_threshold: float = 0.7) -> np.ndarray:
    """Greedy box non-maximum suppression with torchvision's ``nms`` semantics: boxes in
    decreasing score; a box is dropped when its IoU with a kept box is strictly above
    ``iou_threshold``. Returns (K,) int64 kept indices, best first (ties: lower index first)."""
    boxes = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
    scores = np.asarray(scores, dtype=np.float64)
    order = np.lexsort((np.arange(len(scores)), -scores))
    iou = box_iou_matrix(boxes, boxes)
    suppressed = np.zeros(len(boxes), dtype=bool)
    kept: list[int] = []
    for i in order:
        if suppressed[i]:
            continue
        kept.append(int(i))
        suppressed |= iou[i] > iou_threshold
    return np.array(kept, dtype=np.int64)


def remove_small_regions(mask: np.ndarray, min_area_px: int) -> np.ndarray:
    """Fill holes smaller than ``min_area_px`` and drop islands smaller than it.

    mask: (H, W) bool. Returns a new (H, W) bool mask (SAM's post-processing step).
    """
    from skimage import measure

    out = np.asarray(mask, dtype=np.bool_).copy()
    if min_area_px <= 0:
        return out
    # Holes: background components not touching... any small background component is a hole.
    holes = measure.label(~out, connectivity=1)
    if holes.max() > 0:
        sizes = np.bincount(holes.ravel())
        small = np.flatnonzero(sizes < min_area_px)
        small = small[small > 0]
        out |= np.isin(holes, small)
    islands = measure.label(out, connectivity=1)
    if islands.max() > 0:
        sizes = np.bincount(islands.ravel())
        small = np.flatnonzero(sizes < min_area_px)
        small = small[small > 0]
        out &= ~np.isin(islands, small)
    return out


def assign_instances(masks: np.ndarray, scores: np.ndarray, min_area_px: int = 0) -> InstanceMasks:
    """Turn possibly overlapping masks into non-overlapping instances.

    masks: (K, H, W) bool; scores: (K,). Each pixel goes to the highest-scoring mask covering it
    (ties to the lower index); an instance left with fewer than ``min_area_px`` pixels (or none)
    is dropped and its pixels go to the next-best covering mask. Instances are numbered 1..N in
    decreasing score. Returns InstanceMasks(labels (H, W) int32, scores (N,) float32).
    """
    masks = np.asarray(masks, dtype=np.bool_)
    scores = np.asarray(scores, dtype=np.float64)
    if masks.ndim != 3 or len(scores) != len(masks):
        raise InputError(f"assign_instances: masks (K, H, W) and scores (K,) expected, got {masks.shape}, {scores.shape}")
    h, w = masks.shape[1:]
    order = list(np.lexsort((np.arange(len(scores)), -scores)))
    while True:
        labels = np.zeros((h, w), dtype=np.int32)
        # Paint from worst to best so that the best mask ends on top.
        for rank in range(len(order) - 1, -1, -1):
            labels[masks[order[rank]]] = rank + 1
        counts = np.bincount(labels.ravel(), minlength=len(order) + 1)[1:]
        too_small = [r for r, c in enumerate(counts) if c < max(min_area_px, 1)]
        if not too_small:
            break
        order = [o for r, o in enumerate(order) if r not in set(too_small)]
    return InstanceMasks(labels=labels, scores=scores[order].astype(np.float32))


def preprocess(rgb: np.ndarray, image_size: int = 1024, letterbox: bool = False) -> tuple[np.ndarray, tuple[int, int]]:
    """SAM 2 input of one image.

    rgb: (H, W, 3) uint8. Returns ((3, S, S) float32 normalised pixels, (h, w) the size of the
    resized image inside the S x S input: (S, S) for the square resize, the letterboxed size else).
    """
    from PIL import Image

    arr = np.asarray(rgb)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8:
        raise InputError(f"expected an (H, W, 3) uint8 RGB image, got {arr.shape} {arr.dtype}")
    h0, w0 = arr.shape[:2]
    if letterbox:
        s = image_size / max(h0, w0)
        h, w = int(round(h0 * s)), int(round(w0 * s))
    else:
        h, w = image_size, image_size
    resized = np.asarray(Image.fromarray(arr).resize((w, h), Image.Resampling.BILINEAR), dtype=np.float32) / 255.0
    out = np.zeros((image_size, image_size, 3), dtype=np.float32)
    out[:h, :w] = (resized - IMAGENET_MEAN) / IMAGENET_STD
    return np.ascontiguousarray(out.transpose(2, 0, 1)), (h, w)


# --------------------------------------------------------------------------------------------
# The segmenter
# --------------------------------------------------------------------------------------------


class Sam2Segmenter:
    """SAM 2 automatic masks (an ``InstanceSegmenter``) and box-prompted masks (a
    ``BoxPromptSegmenter``: detector boxes in, one mask per box out, as Grounded-SAM-2 does).

    weights_dir: folder with ``config.json`` and ``model.safetensors`` of a transformers
    ``Sam2Model``. settings: generator settings, upstream's defaults unless changed through
    ``PerceptionConfig.sam2``. letterbox: SAM 1 style resize (see the module docstring).
    """

    def __init__(
        self,
        weights_dir: Path | str,
        settings: Sam2Settings | None = None,
        device: str | None = None,
        letterbox: bool = False,
    ) -> None:
        import torch
        from transformers import Sam2Model

        weights_dir = Path(weights_dir)
        if not (weights_dir / "config.json").is_file():
            raise ModelUnavailableError(f"no config.json in {weights_dir}; run: scene-builder models fetch sam2-hiera-tiny")
        self.settings = settings if settings is not None else Sam2Settings()
        if self.settings.points_per_side < 1 or self.settings.points_per_batch < 1:
            raise InputError("SAM 2 settings: points_per_side and points_per_batch must be at least 1")
        self.device = device or ("cuda" if torch.cuda.is_available() else "cpu")
        self.model = Sam2Model.from_pretrained(weights_dir, use_safetensors=True).to(self.device).eval()
        self.image_size = int(self.model.config.prompt_encoder_config.image_size)
        self.letterbox = letterbox

    # -- model plumbing ---------------------------------------------------------------------

    def _embed(self, rgb: np.ndarray):
        import torch

        pixels, inner = preprocess(rgb, self.image_size, self.letterbox)
        with torch.inference_mode():
            emb = self.model.get_image_embeddings(torch.from_numpy(pixels)[None].to(self.device))
        return emb, inner

    def _to_model_coords(self, uv: np.ndarray, shape: tuple[int, int], inner: tuple[int, int]) -> np.ndarray:
        """Continuous image coordinates (u, v) -> coordinates of the S x S model input
        (``SAM2Transforms.transform_coords``: divide by the image size, times the resized size)."""
        h0, w0 = shape
        h, w = inner
        out = np.asarray(uv, dtype=np.float64).copy()
        out[..., 0] *= w / w0
        out[..., 1] *= h / h0
        return out

    def _decode(self, emb, points=None, labels=None, boxes=None, multimask: bool = True):
        """Low-res logits (P, M, 256, 256) float32 and predicted IoU (P, M) for P prompts."""
        import torch

        kw = {}
        if points is not None:
            kw["input_points"] = torch.as_tensor(points, dtype=torch.float32, device=self.device)[None]
            kw["input_labels"] = torch.as_tensor(labels, dtype=torch.int64, device=self.device)[None]
        if boxes is not None:
            kw["input_boxes"] = torch.as_tensor(boxes, dtype=torch.float32, device=self.device)[None]
        with torch.inference_mode():
            out = self.model(image_embeddings=emb, multimask_output=multimask, **kw)
        return out.pred_masks[0].float().cpu().numpy(), out.iou_scores[0].float().cpu().numpy()

    def _valid_lowres(self, m: int, inner: tuple[int, int]) -> tuple[int, int]:
        """Rows and columns of the m x m low-res logits that cover the image (all of them unless
        letterboxed)."""
        ch = max(1, int(round(inner[0] * m / self.image_size)))
        cw = max(1, int(round(inner[1] * m / self.image_size)))
        return ch, cw

    def _upsample(self, logits: np.ndarray, shape: tuple[int, int], inner: tuple[int, int]) -> np.ndarray:
        """(K, m, m) low-res logits -> (K, H, W) bool masks at the input resolution: bilinear,
        ``align_corners=False`` (``SAM2Transforms.postprocess_masks``), then ``> mask_threshold``."""
        import torch

        if len(logits) == 0:
            return np.zeros((0, *shape), dtype=np.bool_)
        ch, cw = self._valid_lowres(logits.shape[-1], inner)
        t = torch.from_numpy(np.ascontiguousarray(logits[:, None, :ch, :cw]))
        up = torch.nn.functional.interpolate(t, size=shape, mode="bilinear", align_corners=False)[:, 0]
        return (up > self.settings.mask_threshold).numpy()

    # -- public API -------------------------------------------------------------------------

    def generate(self, rgb: np.ndarray) -> MaskProposals:
        """All masks of the automatic generator after upstream's filters and box NMS, best
        (highest predicted IoU) first."""
        st = self.settings
        shape = rgb.shape[:2]
        emb, inner = self._embed(rgb)
        grid = point_grid(st.points_per_side, shape[1], shape[0])
        kept_logits, kept_iou, kept_stab, kept_pts = [], [], [], []
        for start in range(0, len(grid), st.points_per_batch):
            pts = grid[start : start + st.points_per_batch]
            model_pts = self._to_model_coords(pts, shape, inner)[:, None, :]  # (P, 1, 2)
            logits, iou = self._decode(emb, model_pts, np.ones((len(pts), 1), dtype=np.int64), multimask=st.multimask_output)
            p, m = iou.shape
            logits = logits.reshape(p * m, *logits.shape[-2:])
            iou = iou.reshape(p * m)
            pts = np.repeat(pts, m, axis=0)
            # upstream's _process_batch: predicted IoU (strict), then stability (>=), per batch
            keep = np.ones(len(iou), dtype=bool)
            if st.pred_iou_thresh > 0.0:
                keep &= iou > st.pred_iou_thresh
            stab = stability_score(logits, st.mask_threshold, st.stability_score_offset)
            if st.stability_score_thresh > 0.0:
                keep &= stab >= st.stability_score_thresh
            kept_logits.append(logits[keep])
            kept_iou.append(iou[keep])
            kept_stab.append(stab[keep])
            kept_pts.append(pts[keep])
        logits = np.concatenate(kept_logits)
        iou, stab, pts = np.concatenate(kept_iou), np.concatenate(kept_stab), np.concatenate(kept_pts)
        ch, cw = self._valid_lowres(logits.shape[-1], inner)
        boxes = masks_to_boxes(logits[:, :ch, :cw] > st.mask_threshold)
        nms_keep = box_nms(boxes, iou, st.box_nms_thresh)
        logits, iou, stab, pts = logits[nms_keep], iou[nms_keep], stab[nms_keep], pts[nms_keep]
        masks = self._upsample(logits, shape, inner)
        if st.min_mask_region_area_px > 0 and len(masks):
            # upstream's postprocess_small_regions: clean, then box NMS preferring unchanged masks
            cleaned = np.stack([remove_small_regions(mk, st.min_mask_region_area_px) for mk in masks])
            unchanged = np.all(cleaned == masks, axis=(1, 2)).astype(np.float64)
            keep2 = box_nms(masks_to_boxes(cleaned), unchanged, st.box_nms_thresh)
            keep2 = np.sort(keep2)  # keep the predicted-IoU order
            masks, iou, stab, pts = cleaned[keep2], iou[keep2], stab[keep2], pts[keep2]
        return MaskProposals(masks, iou, stab, pts)

    def segment(
        self,
        rgb: np.ndarray,
        depth_m: np.ndarray | None = None,
        intrinsics: CameraIntrinsics | None = None,
        background: np.ndarray | None = None,
    ) -> InstanceMasks:
        """Non-overlapping instances (labels (H, W) int32, scores (K,) float32); masks lying mostly
        on ``background`` (floor, walls, ceiling) are left out, and background pixels stay 0."""
        st = self.settings
        props = self.generate(rgb)
        masks = props.masks
        scores = props.scores
        if background is not None and len(masks):
            bg = np.asarray(background, dtype=np.bool_)
            area = masks.reshape(len(masks), -1).sum(1)
            on_bg = (masks & bg).reshape(len(masks), -1).sum(1)
            ok = on_bg <= st.max_background_frac * np.maximum(area, 1)
            masks = masks[ok] & ~bg
            scores = scores[ok]
        if len(masks) == 0:
            return InstanceMasks(np.zeros(rgb.shape[:2], dtype=np.int32), np.zeros(0, dtype=np.float32))
        min_area = max(1, int(st.min_instance_frac * rgb.shape[0] * rgb.shape[1]))
        return assign_instances(masks, scores, min_area)

    def segment_boxes(self, rgb: np.ndarray, boxes_xyxy_px: np.ndarray) -> np.ndarray:
        """One mask per detector box (``BoxPromptSegmenter``), as Grounded-SAM-2 prompts SAM 2:
        all boxes on one image embedding, ``multimask_output`` from
        ``Sam2Settings.box_prompt_multimask`` (False upstream; when True, the mask with the best
        predicted IoU). rgb: (H, W, 3) uint8; boxes_xyxy_px: (K, 4) continuous pixel coordinates
        (x1, y1, x2, y2). Returns (K, H, W) bool, possibly overlapping."""
        st = self.settings
        arr = np.asarray(rgb)
        if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8:
            raise InputError(f"expected an (H, W, 3) uint8 RGB image, got {arr.shape} {arr.dtype}")
        boxes = np.asarray(boxes_xyxy_px, dtype=np.float64)
        if boxes.size == 0:
            return np.zeros((0, *arr.shape[:2]), dtype=np.bool_)
        if boxes.ndim != 2 or boxes.shape[1] != 4 or not np.all(np.isfinite(boxes)):
            raise InputError(f"box prompts must be a (K, 4) array of finite x1, y1, x2, y2 pixels, got shape {boxes.shape}")
        if np.any(boxes[:, 2] < boxes[:, 0]) or np.any(boxes[:, 3] < boxes[:, 1]):
            raise InputError("box prompts must have x2 >= x1 and y2 >= y1")
        shape = arr.shape[:2]
        emb, inner = self._embed(arr)
        out = []
        for start in range(0, len(boxes), st.points_per_batch):
            b = boxes[start : start + st.points_per_batch].reshape(-1, 2, 2)
            model_boxes = self._to_model_coords(b, shape, inner).reshape(-1, 4)
            logits, iou = self._decode(emb, boxes=model_boxes, multimask=st.box_prompt_multimask)
            best = np.argmax(iou, axis=1)
            out.append(self._upsample(logits[np.arange(len(best)), best], shape, inner))
        return np.concatenate(out)

    def segment_with_prompts(
        self,
        rgb: np.ndarray,
        boxes_xyxy: np.ndarray | None = None,
        points: np.ndarray | None = None,
        point_labels: np.ndarray | None = None,
    ) -> MaskProposals:
        """One mask per prompt (the best of the three by predicted IoU), in prompt order.

        boxes_xyxy: (B, 4) pixel boxes (u0, v0, u1, v1). points: (B, N, 2) pixel (u, v), N points
        per prompt (with boxes, B must match); point_labels: (B, N) 1 = foreground, 0 = background
        (default all 1). Returns MaskProposals with B masks at the input resolution.
        """
        shape = rgb.shape[:2]
        if boxes_xyxy is None and points is None:
            raise InputError("segment_with_prompts needs boxes_xyxy or points")
        emb, inner = self._embed(rgb)
        model_pts = labels = model_boxes = None
        if points is not None:
            pts = np.asarray(points, dtype=np.float64)
            if pts.ndim == 2:
                pts = pts[:, None, :]
            model_pts = self._to_model_coords(pts, shape, inner)
            labels = np.ones(pts.shape[:2], dtype=np.int64) if point_labels is None else np.asarray(point_labels).reshape(pts.shape[:2])
        if boxes_xyxy is not None:
            b = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 2, 2)
            model_boxes = self._to_model_coords(b, shape, inner).reshape(-1, 4)
        logits, iou = self._decode(emb, model_pts, labels, model_boxes, multimask=True)
        best = np.argmax(iou, axis=1)
        rows = np.arange(len(best))
        best_logits, best_iou = logits[rows, best], iou[rows, best]
        stab = stability_score(best_logits, self.settings.mask_threshold, self.settings.stability_score_offset)
        masks = self._upsample(best_logits, shape, inner)
        if points is not None:
            src = np.asarray(points, dtype=np.float64).reshape(len(best), -1, 2)[:, 0]
        else:
            src = np.full((len(best), 2), np.nan)
        return MaskProposals(masks, best_iou, stab, src)
