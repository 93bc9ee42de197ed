"""SAM 2 automatic instance masks and prompted refinement (``transformers`` ``Sam2Model``).

transformers' ``Sam2ImageProcessor`` needs torchvision, which cannot be installed on this
project's machines, so preprocessing is written here: the SAM 2 checkpoints were trained on the
whole image resized to a 1024 x 1024 square (SAM 2's own transform; SAM 1 instead letterboxed the
longest side to 1024), ImageNet mean/std. ``letterbox=True`` selects the SAM 1 style (longest side
to 1024, zero padding bottom/right) for checkpoints trained that way; masks are mapped back either
way.

The automatic generator follows SAM's recipe: a regular grid of single positive point prompts,
three masks per point (multimask output), predicted-IoU and stability-score filters, mask NMS,
removal of small islands and holes, and finally each pixel to the highest-scoring mask that covers
it so that no pixel belongs to two instances. The filters and NMS run on the decoder's 256 x 256
low-resolution logits (16x fewer pixels than the full image) and only the surviving masks are
upsampled: the ranking they produce is the same up to boundary pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from perception.protocols import InstanceMasks
from scene_builder.errors import InputError, ModelUnavailableError
from scene_builder.model import CameraIntrinsics, as_array

__all__ = [
    "MaskProposals",
    "Sam2Segmenter",
    "assign_instances",
    "mask_iou_matrix",
    "mask_nms",
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
        """(K,) float32 ranking score: predicted IoU times stability."""
        return (self.predicted_iou * self.stability).astype(np.float32)


# --------------------------------------------------------------------------------------------
# Pure functions on masks (numpy; unit-tested on hand-made masks)
# --------------------------------------------------------------------------------------------


def point_grid(points_per_side: int, width_px: int, height_px: int) -> np.ndarray:
    """(n*n, 2) float64 pixel coordinates (u, v) of a regular grid with half-cell margins, rows
    first (SAM's point layout)."""
    if points_per_side < 1:
        raise InputError("points_per_side must be at least 1")
    t = (np.arange(points_per_side) + 0.5) / points_per_side
    uu, vv = np.meshgrid(t * width_px - 0.5, t * height_px - 0.5)
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
    """SAM 2 automatic masks (an ``InstanceSegmenter``) and prompted masks.

    weights_dir: folder with ``config.json`` and ``model.safetensors`` of a transformers ``Sam2Model``.
    points_per_side: the prompt grid is points_per_side^2 points. points_per_batch: prompts decoded
    together. pred_iou_threshold, stability_threshold: SAM's filters. nms_iou_threshold: mask NMS.
    min_region_frac: islands/holes smaller than this fraction of the image are removed, and
    instances smaller than it dropped. max_background_frac: masks with more of their pixels on
    ``background`` (floor, walls) than this are not objects.
    """

    def __init__(
        self,
        weights_dir: Path | str,
        device: str | None = None,
        points_per_side: int = 16,
        points_per_batch: int = 64,
        pred_iou_threshold: float = 0.7,
        stability_threshold: float = 0.85,
        stability_offset: float = 1.0,
        nms_iou_threshold: float = 0.7,
        min_region_frac: float = 0.001,
        max_background_frac: float = 0.5,
        letterbox: bool = False,
    ) -> None:
        import torch
        from transformers import Sam2Model

        weights_dir = Path(weights_dir)
        if not (weights_dir / "config.json").is_file():
            raise ModelUnavailableError(f"no config.json in {weights_dir}; run: scene-builder models fetch sam2-hiera-tiny")
        self.device = device or ("cuda" if torch.cuda.is_available() else "cpu")
        self.model = Sam2Model.from_pretrained(weights_dir, use_safetensors=True).to(self.device).eval()
        self.image_size = int(self.model.config.prompt_encoder_config.image_size)
        self.points_per_side = points_per_side
        self.points_per_batch = points_per_batch
        self.pred_iou_threshold = pred_iou_threshold
        self.stability_threshold = stability_threshold
        self.stability_offset = stability_offset
        self.nms_iou_threshold = nms_iou_threshold
        self.min_region_frac = min_region_frac
        self.max_background_frac = max_background_frac
        self.letterbox = letterbox

    # -- model plumbing ---------------------------------------------------------------------

    def _embed(self, rgb: np.ndarray):
        import torch

        pixels, inner = preprocess(rgb, self.image_size, self.letterbox)
        with torch.inference_mode():
            emb = self.model.get_image_embeddings(torch.from_numpy(pixels)[None].to(self.device))
        return emb, inner

    def _to_model_coords(self, uv: np.ndarray, shape: tuple[int, int], inner: tuple[int, int]) -> np.ndarray:
        """Pixel (u, v) of the input image -> pixel coordinates of the S x S model input."""
        h0, w0 = shape
        h, w = inner
        out = np.asarray(uv, dtype=np.float64).copy()
        out[..., 0] = (out[..., 0] + 0.5) * (w / w0) - 0.5
        out[..., 1] = (out[..., 1] + 0.5) * (h / h0) - 0.5
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

    def _upsample(self, logits: np.ndarray, shape: tuple[int, int], inner: tuple[int, int]) -> np.ndarray:
        """(K, m, m) low-res logits -> (K, H, W) bool masks at the input resolution."""
        import torch

        if len(logits) == 0:
            return np.zeros((0, *shape), dtype=np.bool_)
        m = logits.shape[-1]
        ch = max(1, int(round(inner[0] * m / self.image_size)))
        cw = max(1, int(round(inner[1] * m / self.image_size)))
        t = torch.from_numpy(np.ascontiguousarray(logits[:, None, :ch, :cw]))
        up = torch.nn.functional.interpolate(t, size=shape, mode="bilinear", align_corners=False)[:, 0]
        return (up > 0.0).numpy()

    # -- public API -------------------------------------------------------------------------

    def generate(self, rgb: np.ndarray) -> MaskProposals:
        """All masks of the automatic generator, after filtering and NMS, best first."""
        shape = rgb.shape[:2]
        emb, inner = self._embed(rgb)
        grid = point_grid(self.points_per_side, shape[1], shape[0])
        all_logits, all_iou, all_pts = [], [], []
        for start in range(0, len(grid), self.points_per_batch):
            pts = grid[start : start + self.points_per_batch]
            model_pts = self._to_model_coords(pts, shape, inner)[:, None, :]  # (P, 1, 2)
            logits, iou = self._decode(emb, model_pts, np.ones((len(pts), 1), dtype=np.int64))
            p, m = iou.shape
            all_logits.append(logits.reshape(p * m, *logits.shape[-2:]))
            all_iou.append(iou.reshape(p * m))
            all_pts.append(np.repeat(pts, m, axis=0))
        logits = np.concatenate(all_logits)
        iou = np.concatenate(all_iou)
        pts = np.concatenate(all_pts)
        stab = stability_score(logits, 0.0, self.stability_offset)
        keep = np.flatnonzero((iou >= self.pred_iou_threshold) & (stab >= self.stability_threshold))
        logits, iou, stab, pts = logits[keep], iou[keep], stab[keep], pts[keep]
        nms_keep = mask_nms(logits > 0.0, iou * stab, self.nms_iou_threshold)
        logits, iou, stab, pts = logits[nms_keep], iou[nms_keep], stab[nms_keep], pts[nms_keep]
        masks = self._upsample(logits, shape, inner)
        min_area = int(self.min_region_frac * shape[0] * shape[1])
        masks = np.stack([remove_small_regions(m, min_area) for m in masks]) if len(masks) else masks
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
        props = self.generate(rgb)
        masks = props.masks
        scores = props.scores
        if background is not None and len(masks):
            bg = np.asarray(background, dtype=np.bool_)
            area = masks.reshape(len(masks), -1).sum(1)
            on_bg = (masks & bg).reshape(len(masks), -1).sum(1)
            ok = on_bg <= self.max_background_frac * np.maximum(area, 1)
            masks = masks[ok] & ~bg
            scores = scores[ok]
        if len(masks) == 0:
            return InstanceMasks(np.zeros(rgb.shape[:2], dtype=np.int32), np.zeros(0, dtype=np.float32))
        min_area = max(1, int(self.min_region_frac * rgb.shape[0] * rgb.shape[1]))
        return assign_instances(masks, scores, min_area)

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
        stab = stability_score(best_logits, 0.0, self.stability_offset)
        masks = self._upsample(best_logits, shape, inner)
        if points is not None:
            src = np.asarray(points, dtype=np.float64).reshape(len(best), -1, 2)[:, 0]
        else:
            src = np.full((len(best), 2), np.nan)
        return MaskProposals(masks, best_iou, stab, src)
