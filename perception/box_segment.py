"""Box-prompted instance masks without learned weights: the ``"grabcut"`` box-prompt backend.

GrabCut (Rother, Kolmogorov and Blake 2004; OpenCV's ``cv2.grabCut``) models the colours inside
and outside a box with two Gaussian mixtures and cuts the box's pixels between them with a graph
cut that follows colour edges. Each box is cut in its own crop (the box plus a margin, scaled so
that its longer side is at most ``max_side_px``: the cost is bounded per box whatever the photo's
size).

Evidence other than colour comes in as per-pixel *hints* (:data:`HINT_BACKGROUND` ...): the
detection-driven segmenter marks pixels that depth puts on the floor or a wall, or far behind the
object, and pixels the semantic map gives another class, as probable background, and the
semantic map's own class as probable foreground. GrabCut keeps them as its initial labelling and
may overrule the probable ones where colour disagrees.

Deterministic: OpenCV's RNG (GrabCut's k-means initialisation) is seeded before every cut.
"""

from __future__ import annotations

import numpy as np

__all__ = ["HINT_BACKGROUND", "HINT_FOREGROUND", "HINT_PROBABLY_BACKGROUND", "HINT_PROBABLY_FOREGROUND", "GrabCutBoxSegmenter", "keep_main_regions"]

HINT_BACKGROUND = -2
HINT_PROBABLY_BACKGROUND = -1
HINT_PROBABLY_FOREGROUND = 1
HINT_FOREGROUND = 2


def keep_main_regions(mask: np.ndarray, share: float = 0.2) -> np.ndarray:
    """(h, w) bool: the 8-connected regions of ``mask`` holding at least ``share`` of its largest
    region's pixels (drops specks a graph cut leaves around the object)."""
    import cv2

    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if n <= 2:
        return mask.astype(bool)
    areas = stats[1:, cv2.CC_STAT_AREA]
    keep = np.zeros(n, dtype=bool)
    keep[1:] = areas >= share * areas.max()
    return keep[lab]


class GrabCutBoxSegmenter:
    """One mask per box by GrabCut (see the module doc). Implements
    :class:`perception.protocols.BoxPromptSegmenter`.

    iterations: GrabCut iterations per box. max_side_px: the crop is downscaled to this longer
    side. margin: the crop reaches this fraction of the box size past each side (at least 6 px);
    it gives GrabCut its background colours. seed: OpenCV RNG seed.
    """

    #: ``segment_boxes`` takes per-box hints (the detection-driven segmenter passes them).
    accepts_hints = True

    def __init__(self, iterations: int = 3, max_side_px: int = 128, margin: float = 0.12, seed: int = 0) -> None:
        self.iterations = int(iterations)
        self.max_side_px = int(max_side_px)
        self.margin = float(margin)
        self.seed = int(seed)

    def segment_boxes(self, rgb: np.ndarray, boxes_xyxy_px: np.ndarray, hints: np.ndarray | None = None) -> np.ndarray:
        """rgb: (H, W, 3) uint8; boxes_xyxy_px: (K, 4); hints: None or (K, H, W) int8 of the
        HINT_* values (0 = no opinion). Returns (K, H, W) bool."""
        rgb = np.ascontiguousarray(np.asarray(rgb, dtype=np.uint8))
        h, w = rgb.shape[:2]
        boxes = np.asarray(boxes_xyxy_px, dtype=np.float64).reshape(-1, 4)
        out = np.zeros((len(boxes), h, w), dtype=bool)
        for k, box in enumerate(boxes):
            hint = None if hints is None else hints[k]
            out[k] = self._one(rgb, box, hint)
        return out

    def _one(self, rgb: np.ndarray, box: np.ndarray, hint: np.ndarray | None) -> np.ndarray:
        import cv2

        h, w = rgb.shape[:2]
        full = np.zeros((h, w), dtype=bool)
        x0, y0 = int(np.floor(np.clip(box[0], 0, w))), int(np.floor(np.clip(box[1], 0, h)))
        x1, y1 = int(np.ceil(np.clip(box[2], 0, w))), int(np.ceil(np.clip(box[3], 0, h)))
        if x1 - x0 < 4 or y1 - y0 < 4:
            return full
        mx, my = max(6, int(self.margin * (x1 - x0))), max(6, int(self.margin * (y1 - y0)))
        cx0, cy0, cx1, cy1 = max(0, x0 - mx), max(0, y0 - my), min(w, x1 + mx), min(h, y1 + my)
        crop = rgb[cy0:cy1, cx0:cx1]
        ch, cw = crop.shape[:2]
        init = np.full((ch, cw), cv2.GC_BGD, dtype=np.uint8)
        init[y0 - cy0 : y1 - cy0, x0 - cx0 : x1 - cx0] = cv2.GC_PR_FGD
        if hint is not None:
            hc = hint[cy0:cy1, cx0:cx1]
            inside = init == cv2.GC_PR_FGD
            init[inside & (hc == HINT_PROBABLY_BACKGROUND)] = cv2.GC_PR_BGD
            init[inside & (hc == HINT_BACKGROUND)] = cv2.GC_BGD
            init[inside & (hc == HINT_FOREGROUND)] = cv2.GC_FGD
        if not ((init == cv2.GC_BGD) | (init == cv2.GC_PR_BGD)).any():
            # The box fills the photo: its outer ring stands in for the background.
            ring = np.ones((ch, cw), dtype=bool)
            ring[2:-2, 2:-2] = False
            init[ring & (init != cv2.GC_FGD)] = cv2.GC_PR_BGD
        if not ((init == cv2.GC_FGD) | (init == cv2.GC_PR_FGD)).any():
            return full
        scale = min(1.0, self.max_side_px / max(ch, cw))
        sw, sh = max(4, int(round(cw * scale))), max(4, int(round(ch * scale)))
        small = cv2.resize(crop, (sw, sh), interpolation=cv2.INTER_AREA) if scale < 1.0 else crop.copy()
        mask = cv2.resize(init, (sw, sh), interpolation=cv2.INTER_NEAREST) if scale < 1.0 else init.copy()
        bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
        cv2.setRNGSeed(self.seed)
        try:
            cv2.grabCut(small, mask, None, bgd, fgd, self.iterations, cv2.GC_INIT_WITH_MASK)
        except cv2.error:
            # GrabCut refuses a crop whose fore- or background has too few distinct colours to fit
            # its mixtures (a flat, saturated patch): the initial labelling is the best answer.
            pass
        fg = ((mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD)).astype(np.uint8)
        if scale < 1.0:
            fg = cv2.resize(fg, (cw, ch), interpolation=cv2.INTER_NEAREST)
        fg = fg.astype(bool) & (init != cv2.GC_BGD)
        if fg.sum() < 0.03 * (x1 - x0) * (y1 - y0):
            # The cut gave the object up to the background (too alike in colour): the hints'
            # foreground when they have one, else no mask (a box is no outline).
            fg = np.zeros_like(fg)
            if hint is not None and (hint[cy0:cy1, cx0:cx1] > 0).sum() >= 0.1 * (x1 - x0) * (y1 - y0):
                fg = (hint[cy0:cy1, cx0:cx1] > 0) & (init != cv2.GC_BGD)
        full[cy0:cy1, cx0:cx1] = keep_main_regions(fg)
        return full
