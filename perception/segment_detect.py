"""Detection-driven instances: the ``"detections"`` segmentation backend (Grounded-SAM style, with
geometry and a classifier as second witnesses).

1. **Detect**: every available detector (Grounding DINO prompted with the room vocabulary, COCO
   CenterNet, Open Images SSD) gives boxes down to a low score;
   :func:`perception.detection.merge_detections` puts them on one scale (a detector's own trust
   score becomes :data:`~perception.detection.CONFIDENT`) and fuses boxes that several detectors
   agree on.
2. **Confirm** (two passes): a detection at :data:`~perception.detection.CONFIDENT` or more
   stands alone. A weaker one (down to :data:`FLOOR_SCORE`) is kept only when geometry or the
   semantic map confirms it among the pixels the confident ones left: a depth cluster
   (:class:`perception.segment_depth.DepthClusterSegmenter`) lies mostly inside its box and fills
   a fair part of it, or the semantic map (PASCAL DeepLab) gives its family in a region that fills
   the box. (At its usual 0.3 the COCO detector finds a few of the chairs of a classroom; at 0.12
   it finds nearly all of them, with false boxes that neither witness confirms.)
3. **Classify** (third pass): a box of any class, even one outside the vocabulary (a night stand
   boxed as "oven"), that nothing explains yet becomes an object when the EfficientNet classifier
   of the naming backend is sure what it shows (:data:`_CLASSIFIER_SURE`, summed over a label
   family); the classifier also renames an unsure detection it plainly disagrees with (the SSD
   calls sideboards tables).
4. **Masks**: each kept box prompts a box segmenter (SAM 2 when its weights are present, else
   GrabCut, :mod:`perception.box_segment`) with hints from depth (floor and wall pixels, pixels of
   other depth clusters, far behind the object), from the semantic map (its class, other
   classes) and from the better boxes already cut (on estimated depth, a confident box whose
   hinted cut is empty is cut again without the depth and semantic hints, which were wrong about
   it). Masks are trimmed to their main 3D clusters
   where depth sees the object; overlaps go to the object in front (what lies inside another's
   box, else the nearer, else the lower in the image); a weaker duplicate in the same family is
   dropped.
5. **Extras**: depth clusters no detection explains become objects only when they are clear:
   compact in the image (solid, filling their box), of a plausible height and footprint, and of
   3D shape with a visible top, or alone in the view (a close-up); an unclear cluster only when the
   classifier is sure what it is. Unexplained semantic-map regions of an object class become
   objects when they are solid and not part of a detected object. Everything else stays in the
   static background (the room), which is safe: a missed object is still seen in the
   background's texture, an invented one is a box that is not there.

Names: each instance carries its label (``InstanceMasks.names``: the detector's class, or the
classifier's); depth extras carry the semantic map's label when it has one, else ``""`` (the
naming backend names them). Deterministic: no random sampling (GrabCut's RNG is seeded).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from perception.box_clusters import BOXY, box_slices as _box_slices, cuboid_faces, fill_box, whole_cluster
from perception.box_segment import HINT_BACKGROUND, HINT_FOREGROUND, HINT_PROBABLY_BACKGROUND, HINT_PROBABLY_FOREGROUND, keep_main_regions
from perception.detection import CONFIDENT, box_inside, box_iou, box_is_slice, family, merge_detections
from perception.extras import is_clear, point_normals, solidity
from perception.protocols import BoxPromptSegmenter, Detections, InstanceMasks, ObjectDetector, SemanticMap
from scene_builder.model import BackendUse, CameraIntrinsics

__all__ = ["DetectionSegmenter", "FLOOR_SCORE", "NamedBackend"]

#: The weakest (rescaled) detection score considered at all; below CONFIDENT it needs a witness.
FLOOR_SCORE = 0.2
#: A depth cluster confirms a box when this share of the cluster lies inside the box ...
_CLUSTER_INSIDE = 0.6
#: ... and it covers this share of the box.
_CLUSTER_COVER = 0.12
#: ... or, a cluster reaching out of the box (several touching things that depth joined: a
#: wardrobe, the cabinet beside it and the wall behind), when it fills this share of the box and
#: the depth is a sensor's (on COCO photos with estimated depth it confirmed 48 more weak boxes,
#: mask precision 0.47 -> 0.22).
_CLUSTER_FILLS = 0.5
#: The semantic map confirms a box when its family covers this share of the box.
_SEMANTIC_COVER = 0.15
#: A box's depth hints are used only when depth leaves this share of its pixels with depth off
#: the room planes (estimated depth that does not see the object says nothing about its outline).
_DEPTH_SEES = 0.25
#: Pixels this far (metres) behind an object's median depth are probably background.
_BEHIND_M = 0.6
#: A person's box where the semantic map's people pixels fill this share is outlined by them.
_PEOPLE_SEEN = 0.15
#: A depth cluster that instances cover less than this share of is unexplained.
_UNEXPLAINED = 0.3
#: ... and of a cluster explained in part up to this share, the rest splits into its 3D pieces.
_REST_SPLIT_MAX = 0.8
#: Boxes of any class down to this (rescaled) score are object proposals for the classifier ...
_PROPOSAL_SCORE = 0.12
#: ... between these shares of the image's area ...
_PROPOSAL_MIN_AREA = 0.004
_PROPOSAL_MAX_AREA = 0.9
#: ... at most this many, best first ...
_MAX_PROPOSALS = 24
#: ... and one becomes an object when the classifier gives a vocabulary label this probability.
_CLASSIFIER_SURE = 0.5
#: ... or this probability for a label of the family the detector named the box with.
_CLASSIFIER_AGREES = 0.3
#: A detection under this score takes the classifier's label when the classifier gives that
#: label's family this probability (:data:`_CLASSIFIER_SURE` for a detection under CONFIDENT,
#: whose class is a guess) and the detection's family at most this much.
_RENAME_BELOW = 0.9
_RENAME_SURE = 0.6
_RENAME_FAMILY_MAX = 0.1
#: A confident box the colour cut gives up is cut around its centre only up to this share of the
#: image (:meth:`DetectionSegmenter._confident_outline`).
_CORE_MAX_AREA = 0.05
#: Unclear depth clusters of at least this share of the image go to the classifier, the largest
#: this many.
_UNCLEAR_MIN_AREA = 0.01
_MAX_UNCLEAR = 8


@dataclass(frozen=True)
class NamedBackend:
    """A backend with its registry name (for the report)."""

    name: str
    backend: object


@dataclass
class _Candidate:
    box: np.ndarray  # (4,) xyxy px
    score: float
    label: str
    witness: str  # "score", "depth", "semantic", "depth+semantic", "classifier", "extra-depth", "extra-semantic", "extra-classifier"
    cluster: int = 0  # the depth cluster that confirms it (0 = none)
    mask: np.ndarray | None = None
    depth_sees: bool = False
    meta: dict = field(default_factory=dict)


def _best_family(label_probs: dict[str, float]) -> tuple[str, float]:
    """The classifier's answer: the family (:data:`perception.detection.FAMILIES`) of highest
    summed probability, named by its most probable label, and that sum ("", 0 when empty).
    ImageNet splits one kind of thing over neighbouring classes (a sideboard is part chiffonier,
    part wardrobe, part china cabinet)."""
    if not label_probs:
        return "", 0.0
    sums: dict[frozenset[str], float] = {}
    for lab, p in label_probs.items():
        sums[family(lab)] = sums.get(family(lab), 0.0) + float(p)
    fam = max(sorted(sums, key=lambda f: sorted(f)), key=lambda f: sums[f])
    best = max(sorted(fam), key=lambda lab: label_probs.get(lab, 0.0))
    return best, sums[fam]


def _semantic_cover(inside: np.ndarray) -> float:
    """Share of a box (``inside``: (h, w) bool, the box's pixels of the detection's family) that
    its semantic region covers, counting only a region that fills the box: its largest
    connected piece's bounding box overlaps the detection box by IoU 0.3 (a small blob of the
    class in a corner of a false box is another object)."""
    import cv2

    if not inside.any():
        return 0.0
    n, _, stats, _ = cv2.connectedComponentsWithStats(inside.astype(np.uint8), connectivity=8)
    big = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    bw, bh = stats[big, cv2.CC_STAT_WIDTH], stats[big, cv2.CC_STAT_HEIGHT]
    if bw * bh < 0.3 * inside.size:  # the piece's box lies inside the detection box: IoU = its area share
        return 0.0
    return float(inside.mean())


def _same_object(box: np.ndarray, others: np.ndarray) -> bool:
    """Whether ``box`` (4,) boxes the same thing as one of ``others`` (N, 4): IoU 0.5, or 0.6 of
    the smaller inside the larger with sizes within a factor 2 (a lamp inside a dresser's box
    is another thing)."""
    lt = np.maximum(box[:2], others[:, :2])
    rb = np.minimum(box[2:], others[:, 2:])
    inter = np.prod(np.clip(rb - lt, 0.0, None), axis=1)
    area = float(np.prod(box[2:] - box[:2]))
    areas = np.prod(others[:, 2:] - others[:, :2], axis=1)
    small, large = np.minimum(area, areas), np.maximum(area, areas)
    iou = inter / np.maximum(area + areas - inter, 1e-9)
    return bool(np.any((iou >= 0.5) | ((inter >= 0.6 * small) & (small >= 0.5 * large))))


class DetectionSegmenter:
    """Instances from detector boxes, confirmed and outlined with depth, colour and the semantic
    map (see the module doc). Implements :class:`perception.protocols.InstanceSegmenter`.

    detectors: the detectors to run (each with ``accept_score``), in registry order.
    box_segmenter: SAM 2 or GrabCut. semantic: the semantic segmenter or None. geometry: the
    depth-cluster segmenter (its clusters confirm boxes and become the extras). min_points:
    the smallest instance in valid-depth pixels. classifier: a naming backend with
    ``label_scores_many`` (EfficientNet-Lite0) that names unexplained boxes, or None.
    """

    accepts_gravity = True
    accepts_depth_source = True  # segment() takes depth_measured

    def __init__(
        self,
        detectors: list[NamedBackend],
        box_segmenter: NamedBackend,
        semantic: NamedBackend | None,
        geometry,
        min_points: int = 150,
        max_depth_m: float = 10.0,
        classifier: NamedBackend | None = None,
    ) -> None:
        self.detectors = list(detectors)
        self.classifier = classifier
        self.box_segmenter = box_segmenter
        self.semantic = semantic
        self.geometry = geometry
        self.min_points = int(min_points)
        self.max_depth_m = float(max_depth_m)
        #: What answered the last ``segment`` call, for ``Perception.backends``.
        self.uses: list[BackendUse] = []
        self._boxes_per_detector: list[tuple[str, int]] = []
        self._depth_measured = True  # the last segment() call's depth was a sensor's

    # -- the stages ---------------------------------------------------------------------------

    def detect(self, rgb: np.ndarray) -> Detections:
        """All detectors' boxes on one scale (see :func:`merge_detections`)."""
        parts = []
        for nb in self.detectors:
            det: ObjectDetector = nb.backend
            parts.append((det.detect(rgb), float(getattr(det, "accept_score", CONFIDENT))))
        self._boxes_per_detector = [(nb.name, len(d)) for nb, (d, _) in zip(self.detectors, parts)]
        return merge_detections(parts)

    def segment(
        self,
        rgb: np.ndarray,
        depth_m: np.ndarray,
        intrinsics: CameraIntrinsics,
        background: np.ndarray,
        up_cam: np.ndarray | None = None,
        depth_measured: bool = True,
    ) -> InstanceMasks:
        """rgb: (H, W, 3) uint8; depth_m: (H, W) float32 (0 = invalid); background: (H, W) bool
        room pixels; up_cam: (3,) up in the camera frame or None; depth_measured: the depth is a
        sensor's (estimated depth joins too much into one cluster for a cluster reaching out of a
        box to witness it). Returns the instances with their detector names (``""`` for extras
        without a semantic class)."""
        h, w = depth_m.shape
        valid = (depth_m > 0) & (depth_m < self.max_depth_m)
        self._depth_measured = bool(depth_measured)
        dets = self.detect(rgb)
        sem: SemanticMap | None = self.semantic.backend.segment_classes(rgb) if self.semantic is not None else None
        sem_labels = None
        if sem is not None:
            # Fixed-width strings, not Python objects: comparing and sorting them per pixel is
            # 5x faster (np.unique over the map was 0.6 s of emsanet_sample's perception).
            lut = np.asarray([str(v) for v in sem.labels])
            sem_labels = lut[np.clip(sem.classes, 0, len(lut) - 1)]
        clusters = np.asarray(self.geometry.segment(rgb, depth_m, intrinsics, background, up_cam=up_cam).labels)
        cluster_sizes = np.bincount(clusters.ravel())
        points = intrinsics.unproject(depth_m)
        focal = 0.5 * (intrinsics.fx_px + intrinsics.fy_px)
        # Pass 1: the confident boxes. Pass 2: the weak ones, witnessed only by evidence the
        # confident ones leave unexplained (a chair's pixels confirm one box, not a second one
        # over its legs), and cut with the confident masks as background.
        # Pass 3: boxes of any class (or of none the vocabulary has) that nothing explains yet,
        # when the classifier sees a vocabulary object in them (a night stand boxed as "oven").
        # People and animals are cut first: their pixels are no object's and no witness.
        removed, n_removed = self._people(rgb, dets, depth_m, valid, background, clusters, sem, sem_labels, points, focal)
        claimed = removed.copy()
        cands: list[_Candidate] = []
        for stage in ("strong", "weak", "classifier"):
            if stage == "classifier":
                batch = self._classified(rgb, dets, cands, claimed, h, w)
            else:
                batch = self._confirm(dets, stage == "strong", clusters, sem_labels, claimed, h, w, depth_measured)
            self._outline(rgb, batch, depth_m, valid, background, clusters, sem_labels, points, focal, claimed)
            for c in batch:
                if c.mask is not None:
                    c.mask = c.mask & ~removed
            batch = [c for c in batch if c.mask is not None and c.mask.sum() >= max(30, self.min_points // 3)]
            cands = self._drop_duplicates(self._merge_parts(cands + batch, points, valid & ~background, focal))
            claimed = removed.copy()
            for c in cands:
                claimed |= c.mask
        labels, kept = self._paint(cands, depth_m, valid, h, w)
        self._check_names(rgb, kept, labels)
        n_det = len(kept)
        extras = self._extras(rgb, clusters, cluster_sizes, labels, kept, sem_labels, points, depth_m, valid, background, up_cam, h, w, removed, focal)
        for c in extras:
            free = c.mask & (labels == 0) & ~removed
            if free.sum() >= self.min_points:
                kept.append(c)
                labels[free] = len(kept)
        names = tuple(c.label for c in kept)
        scores = np.asarray([c.score for c in kept], dtype=np.float32)
        boxes = np.asarray([np.full(4, np.nan) if c.witness.startswith("extra") else c.box for c in kept], dtype=np.float64).reshape(-1, 4)
        self._record(dets, kept, n_det)
        return InstanceMasks(labels.astype(np.int32), scores, names, boxes, removed=removed, removed_count=n_removed)

    def _people(self, rgb, dets: Detections, depth_m, valid, background, clusters, sem, sem_labels, points, focal) -> tuple[np.ndarray, int]:
        """(H, W) bool pixels of the detected people and animals (:mod:`perception.people`), and
        how many there are: in each box, the semantic map's people pixels when it sees one
        there, else the box segmenter's cut."""
        from perception.people import people_boxes, people_pixels, removal_mask

        h, w = depth_m.shape
        seen = people_pixels(sem)
        boxes = people_boxes(dets, seen)
        if not len(boxes):
            return np.zeros((h, w), dtype=bool), 0
        found = [_Candidate(b, 1.0, "person", "people") for b in boxes]
        cut = [c for c in found if seen is None or seen[_box_slices(c.box, h, w)].mean() < _PEOPLE_SEEN]
        self._outline(rgb, cut, depth_m, valid, background, clusters, sem_labels, points, focal, np.zeros((h, w), dtype=bool))
        masks = []
        for c in found:
            if c.mask is None:  # the semantic map sees this one: its people pixels in the box
                c.mask = np.zeros((h, w), dtype=bool)
                rs, cs = _box_slices(c.box, h, w)
                c.mask[rs, cs] = seen[rs, cs]
            if c.mask.any():
                masks.append(c.mask)
        return removal_mask(masks, (h, w)), len(masks)

    def _confirm(self, dets: Detections, strong: bool, clusters, sem_labels, claimed, h: int, w: int, depth_measured: bool = True) -> list[_Candidate]:
        """The detections of one pass (``strong``: at CONFIDENT or more; else the weak ones with
        a witness among the pixels not ``claimed`` yet; a cluster filling a box but reaching out
        of it is a witness only where the depth is ``depth_measured``)."""
        free_clusters = np.where(claimed, 0, clusters)
        free_sizes = np.bincount(free_clusters.ravel())
        out = []
        for box, score, label in zip(dets.boxes_xyxy_px, dets.scores, dets.labels):
            score = float(score)
            if not label or score < FLOOR_SCORE or (score >= CONFIDENT) != strong:
                continue
            rs, cs = _box_slices(box, h, w)
            area = max(1, (rs.stop - rs.start) * (cs.stop - cs.start))
            inside = np.bincount(free_clusters[rs, cs].ravel(), minlength=len(free_sizes))
            inside[0] = 0
            share_inside = inside / np.maximum(free_sizes, 1)
            ok = (share_inside >= _CLUSTER_INSIDE) & (inside >= _CLUSTER_COVER * area) & (free_sizes >= self.min_points)
            cluster = int(np.argmax(np.where(ok, inside, 0))) if ok.any() else 0
            if cluster == 0 and depth_measured:
                fills = (inside >= _CLUSTER_FILLS * area) & (free_sizes >= self.min_points)
                cluster = int(np.argmax(np.where(fills, inside, 0))) if fills.any() else 0
            fam = family(label)
            sem_cover = 0.0
            if sem_labels is not None:
                sem_cover = _semantic_cover(np.isin(sem_labels[rs, cs], list(fam)) & ~claimed[rs, cs])
            witnesses = [n for n, yes in (("depth", cluster > 0), ("semantic", sem_cover >= _SEMANTIC_COVER)) if yes]
            if strong:
                witness = "score"
            elif witnesses:
                witness = "+".join(witnesses)
            else:
                continue
            out.append(_Candidate(np.asarray(box, dtype=np.float64), score, label, witness, cluster, meta={"sem_cover": sem_cover}))
        return out

    def _classified(self, rgb, dets: Detections, cands: list[_Candidate], claimed, h: int, w: int) -> list[_Candidate]:
        """Boxes no instance explains, named by the classifier when it sees a vocabulary object
        in them with probability :data:`_CLASSIFIER_SURE` (at these scores a detector's class is
        a guess, its box is not), or :data:`_CLASSIFIER_AGREES` when the box's class agrees."""
        if self.classifier is None:
            return []
        area_img = float(h * w)
        boxes = [c.box for c in cands]
        props = []
        for box, score, label in zip(dets.boxes_xyxy_px, dets.scores, dets.labels):
            bw, bh = box[2] - box[0], box[3] - box[1]
            if float(score) < _PROPOSAL_SCORE or bw * bh < _PROPOSAL_MIN_AREA * area_img or bw * bh > _PROPOSAL_MAX_AREA * area_img:
                continue
            if min(bw, bh) < 16:
                continue
            rs, cs = _box_slices(box, h, w)
            if claimed[rs, cs].mean() > 0.4:
                continue
            if boxes and float(box_iou(box[None], np.stack(boxes)).max()) >= 0.4:
                continue
            if props and _same_object(box, np.stack([p[0] for p in props])):
                continue  # class-agnostic suppression: one object, one proposal
            props.append((np.asarray(box, dtype=np.float64), float(score), str(label)))
            if len(props) >= _MAX_PROPOSALS:
                break
        if not props:
            return []
        crops, crop_masks = [], []
        for box, _, _ in props:
            rs, cs = _box_slices(box, h, w)
            crops.append(np.ascontiguousarray(rgb[rs, cs]))
            crop_masks.append(np.ones((rs.stop - rs.start, cs.stop - cs.start), dtype=bool))
        scores = self.classifier.backend.label_scores_many(crops, crop_masks, [None] * len(crops))
        out = []
        for (box, score, label), lp in zip(props, scores):
            best, p = _best_family(lp)
            # Sure, or fairly sure and of the detector's own family: two witnesses agreeing (an
            # oven boxed at 0.32 that the classifier calls oven at 0.38), whose confidence is
            # that of either being right (noisy-or: 0.58).
            if best and p >= _CLASSIFIER_SURE:
                out.append(_Candidate(box, p, best, "classifier"))
            elif best and p >= _CLASSIFIER_AGREES and label in family(best):
                out.append(_Candidate(box, 1.0 - (1.0 - p) * (1.0 - score), best, "classifier"))
        return out

    def _outline(self, rgb, cands, depth_m, valid, background, clusters, sem_labels, points, focal, claimed) -> None:
        """Each candidate's mask: the box segmenter with depth and semantic hints, then trimmed to
        its main 3D clusters where depth sees the object. A segmenter that takes hints cuts the
        boxes one by one, best first, with the pixels already cut (``claimed`` by earlier passes
        and this one's better boxes) as probable background: a chair behind a chair gets its own
        pixels, not the front one's."""
        if not cands:
            return
        seg: BoxPromptSegmenter = self.box_segmenter.backend
        off_room = valid & ~background
        for c in cands:
            rs, cs = _box_slices(c.box, *depth_m.shape)
            # Share of the box's pixels with depth (sparse sensor depth has few) off the room.
            seen = int(valid[rs, cs].sum())
            c.depth_sees = bool(seen >= 0.05 * off_room[rs, cs].size and off_room[rs, cs].sum() >= _DEPTH_SEES * seen)
        if getattr(seg, "accepts_hints", False):
            order = sorted(range(len(cands)), key=lambda i: (-cands[i].score, i))
            masks: list[np.ndarray | None] = [None] * len(cands)
            for n, i in enumerate(order):
                c = cands[i]
                hint = self._hint(c, depth_m, valid, background, clusters, sem_labels)
                # What a better box took is probably not this one's, unless this box lies (half)
                # inside that one's and names another kind of thing (a coffee table in front of
                # a sofa, a book on a bed): then it may be in front of it or on it.
                taken = claimed.copy()
                for j in order[:n]:
                    if not (box_inside(c.box, cands[j].box, 0.5) and cands[j].label not in family(c.label)):
                        taken |= masks[j]
                hint[taken & (hint >= 0)] = HINT_PROBABLY_BACKGROUND
                masks[i] = seg.segment_boxes(rgb, c.box[None], hints=hint[None])[0]
        else:
            masks = list(np.asarray(seg.segment_boxes(rgb, np.stack([c.box for c in cands])), dtype=bool))
            for i, c in enumerate(cands):
                # A segmenter that takes no hints still should not keep what is surely not the object.
                masks[i] = masks[i] & ~(self._hint(c, depth_m, valid, background, clusters, sem_labels) == HINT_BACKGROUND)
        for i, c in enumerate(cands):
            # Estimated depth's hints can be wrong about a whole box; a sensor's are not (on
            # open3d_TUM the recut gave a desk's pixels to a confident box the depth called room).
            if not self._depth_measured and c.score >= CONFIDENT and not np.asarray(masks[i]).any():
                masks[i] = self._confident_outline(rgb, c, claimed, [m for j, m in enumerate(masks) if j != i and m is not None])
            if not self._depth_measured and c.score >= CONFIDENT and c.label in BOXY:
                masks[i] = fill_box(c.box, np.asarray(masks[i], dtype=bool), claimed, [m for j, m in enumerate(masks) if j != i and m is not None])
        for c, m in zip(cands, masks):
            m = np.asarray(m, dtype=bool)
            if c.depth_sees and m.any() and valid[m].mean() >= 0.5:  # sparse depth: no 3D trim
                m = self._trim_3d(m, points, off_room, focal)
                m = m | whole_cluster(c.box, m, clusters, claimed)
            c.mask = m

    def _confident_outline(self, rgb, c: _Candidate, claimed: np.ndarray, others: list[np.ndarray]) -> np.ndarray:
        """The outline of a confident box whose hinted cut came back empty on estimated depth: the
        cut again with only what other instances took as probable background. The depth and
        semantic hints were wrong (estimated depth laid an over-the-range microwave flat on the
        wall behind it, so its pixels were all "room"); a box the detector is sure of does not
        vanish for them. When colour alone gives the object up too (a glass bowl with a plant on a
        dark blue wall), the cut once more with the box's central ellipse (half its width and
        height, free of other instances) as the object's: the detector found something there. Only
        for a small box (:data:`_CORE_MAX_AREA` of the image): a large one has pixels enough for
        the colour models, and a cut that finds nothing in it says the box is wrong (COCO 164's
        "chair" across a counter's edge, whose core merged into the real chair). Empty then, or
        when even that comes back empty."""
        taken = claimed.copy()
        for m in others:
            taken |= np.asarray(m, dtype=bool)
        seg: BoxPromptSegmenter = self.box_segmenter.backend
        if not getattr(seg, "accepts_hints", False):
            return np.zeros_like(taken)
        hint = np.where(taken, HINT_PROBABLY_BACKGROUND, 0).astype(np.int8)
        m = np.asarray(seg.segment_boxes(rgb, c.box[None], hints=hint[None])[0], dtype=bool)
        if m.any():
            c.meta["outline"] = "cut without depth hints"
            return m
        h, w = taken.shape
        x0, y0, x1, y1 = (float(v) for v in c.box)
        if (x1 - x0) * (y1 - y0) > _CORE_MAX_AREA * h * w:
            return m
        rs, cs = _box_slices(c.box, h, w)
        yy, xx = np.mgrid[rs, cs]
        rx, ry = max(0.5 * (x1 - x0), 1.0), max(0.5 * (y1 - y0), 1.0)
        core = ((xx + 0.5 - 0.5 * (x0 + x1)) / rx) ** 2 + ((yy + 0.5 - 0.5 * (y0 + y1)) / ry) ** 2 <= 0.25
        sub = hint[rs, cs]
        sub[core & ~taken[rs, cs]] = HINT_FOREGROUND
        m = np.asarray(seg.segment_boxes(rgb, c.box[None], hints=hint[None])[0], dtype=bool) & ~taken
        if m.any():
            c.meta["outline"] = "cut around the box's centre"
        return m

    def _hint(self, c: _Candidate, depth_m, valid, background, clusters, sem_labels) -> np.ndarray:
        """(H, W) int8 hints for the box of ``c`` (see :mod:`perception.box_segment`): room
        pixels and pixels far behind the object are probably background where depth sees the
        object, its depth cluster probably foreground; the semantic map's pixels of its family
        probably foreground and of other classes probably background."""
        h, w = depth_m.shape
        hint = np.zeros((h, w), dtype=np.int8)
        rs, cs = _box_slices(c.box, h, w)
        sub = hint[rs, cs]
        if c.depth_sees:
            box_off = valid[rs, cs] & ~background[rs, cs]
            sub[valid[rs, cs] & background[rs, cs]] = HINT_PROBABLY_BACKGROUND
            d = depth_m[rs, cs]
            cl = clusters[rs, cs]
            mine = c.cluster
            if mine == 0 and (cl > 0).any():
                # No witness cluster (a confident box): the cluster that fills most of the box
                # among those lying mostly inside it (not the desk a chair's box cuts into).
                inside = np.bincount(cl.ravel(), minlength=int(clusters.max()) + 1)
                total = np.bincount(clusters.ravel(), minlength=len(inside))
                inside[0] = 0
                inside[inside < 0.5 * np.maximum(total, 1)] = 0
                mine = int(inside.argmax()) if inside.max() > 0 else 0
            own = (cl == mine) if mine > 0 else np.zeros_like(box_off)
            if mine > 0 and not self._depth_measured:
                own = own | cuboid_faces(own, cl, clusters, mine)
            if (own & box_off).any():
                ref = float(np.median(d[own & box_off]))
                sub[own] = HINT_PROBABLY_FOREGROUND
                # Other depth clusters in the box are other things (a coffee table in front of
                # the sofa): probably background.
                sub[(cl > 0) & ~own] = HINT_PROBABLY_BACKGROUND
            else:
                ref = float(np.percentile(d[box_off], 30)) if box_off.any() else np.inf
            behind = valid[rs, cs] & (d > ref + _BEHIND_M)
            if not self._depth_measured:
                behind &= ~own  # an estimated cuboid's top and headboard recede behind its front
            sub[behind] = HINT_PROBABLY_BACKGROUND
        if sem_labels is not None:
            sl = sem_labels[rs, cs]
            same = np.isin(sl, list(family(c.label)))
            if c.meta.get("sem_cover", 0.0) >= _SEMANTIC_COVER:
                sub[~same & (sub == 0)] = HINT_PROBABLY_BACKGROUND
                sub[same & (sub >= 0)] = HINT_PROBABLY_FOREGROUND
                if c.cluster > 0:
                    sub[same & (clusters[rs, cs] == c.cluster)] = HINT_FOREGROUND
            else:
                # Pixels the semantic map gives to another object class belong to that object.
                sub[(sl != "") & ~same & (sub == 0)] = HINT_PROBABLY_BACKGROUND
        return hint

    def _trim_3d(self, mask: np.ndarray, points: np.ndarray, off_room: np.ndarray, focal: float) -> np.ndarray:
        """``mask`` less the pixels of its small 3D clusters (bleed onto what is behind or beside
        the object); pixels without off-room depth stay (their depth says nothing)."""
        from perception.segment_depth import cluster_points

        pix = mask & off_room
        idx = np.flatnonzero(pix.ravel())
        if len(idx) < self.min_points:
            return mask
        lab = cluster_points(points.reshape(-1, 3)[idx], focal)
        sizes = np.bincount(lab)
        drop = idx[sizes[lab] < 0.1 * len(idx)]
        out = mask.copy().ravel()
        out[drop] = False
        return keep_main_regions(out.reshape(mask.shape), share=0.1)

    def _merge_parts(self, cands: list[_Candidate], points, off_room, focal: float) -> list[_Candidate]:
        """Two boxes, one inside the other, whose masks depth joins into one connected 3D piece
        are one object cut in two (a bed boxed whole and by its headboard, each box cut with the
        other's pixels taken): one candidate, the stronger's, with both masks. The boxes are of
        one family, or of any two classes when the inner box is a slice of the outer one
        (:func:`perception.detection.box_is_slice`: sunrgbd_imvotenet_000005's night stand
        boxed whole as "oven" and by its lower drawers as "suitcase"; the inner one's mask,
        painted in front, took most of the whole's, and the whole was dropped). Without depth
        that sees both, nothing is merged."""
        from perception.segment_depth import cluster_points

        order = sorted(range(len(cands)), key=lambda i: (-cands[i].score, i))
        gone: set[int] = set()
        for a in order:
            if a in gone or not cands[a].depth_sees:
                continue
            for b in order:
                ca, cb = cands[a], cands[b]
                if b == a or b in gone or not cb.depth_sees:
                    continue
                if cb.label not in family(ca.label) and not (box_is_slice(ca.box, cb.box) or box_is_slice(cb.box, ca.box)):
                    continue
                if not (box_inside(ca.box, cb.box) or box_inside(cb.box, ca.box)):  # 0.7 of the smaller inside the other
                    continue
                pa, pb = ca.mask & off_room, cb.mask & off_room
                if pa.sum() < self.min_points or pb.sum() < self.min_points:
                    continue
                union = pa | pb
                lab = cluster_points(points[union], focal)
                main = int(np.bincount(lab).argmax())
                in_main = np.zeros(union.shape, dtype=bool)
                in_main[union] = lab == main
                if in_main.sum() < 0.8 * union.sum() or (in_main & pa).sum() < 0.5 * pa.sum() or (in_main & pb).sum() < 0.5 * pb.sum():
                    continue
                ca.mask = ca.mask | cb.mask
                ca.box = np.concatenate([np.minimum(ca.box[:2], cb.box[:2]), np.maximum(ca.box[2:], cb.box[2:])])
                gone.add(b)
        return [c for i, c in enumerate(cands) if i not in gone]

    def _drop_duplicates(self, cands: list[_Candidate]) -> list[_Candidate]:
        """Of two masks of one family where one lies mostly inside the other, the weaker goes."""
        order = sorted(range(len(cands)), key=lambda i: (-cands[i].score, i))
        kept: list[int] = []
        for i in order:
            mi = cands[i].mask
            ai = int(mi.sum())
            dup = False
            for j in kept:
                if cands[j].label not in family(cands[i].label):
                    continue
                mj = cands[j].mask
                inter = int(np.count_nonzero(mi & mj))
                if inter >= 0.6 * min(ai, int(mj.sum())):
                    dup = True
                    break
            if not dup:
                kept.append(i)
        return [cands[i] for i in sorted(kept)]

    def _paint(self, cands: list[_Candidate], depth_m, valid, h: int, w: int) -> tuple[np.ndarray, list[_Candidate]]:
        """Labels (H, W) with each overlap given to the object in front (:meth:`_in_front`);
        instances that lose most of their mask are dropped."""
        import functools

        med = []
        for c in cands:
            d = depth_m[c.mask & valid]
            med.append(float(np.median(d)) if c.depth_sees and len(d) else np.inf)
        areas = [int(c.mask.sum()) for c in cands]

        def far_first(i: int, j: int) -> int:
            return -1 if self._in_front(cands[j], cands[i], med[j], med[i], areas[j], areas[i]) else 1

        # Paint back to front: what is painted last is seen.
        order = sorted(range(len(cands)), key=functools.cmp_to_key(lambda i, j: 0 if i == j else far_first(i, j)))
        canvas = np.zeros((h, w), dtype=np.int32)
        for i in order:
            canvas[cands[i].mask] = i + 1
        kept = []
        labels = np.zeros((h, w), dtype=np.int32)
        for i, c in enumerate(cands):
            own = canvas == i + 1
            if own.sum() < max(30, 0.4 * areas[i]) or own.sum() < self.min_points // 3:
                continue
            kept.append(c)
            labels[own] = len(kept)
        return labels, kept

    @staticmethod
    def _in_front(a: _Candidate, b: _Candidate, med_a: float, med_b: float, area_a: int, area_b: int) -> bool:
        """Whether ``a`` hides ``b`` where their masks overlap: what lies inside the other's box
        is on it or in front of it (a book on a bed); else the nearer median depth when depth
        sees both (0.3 m apart), else the lower box bottom in the image (for things on one floor,
        the nearer one reaches lower), else the smaller mask."""

        a_in, b_in = box_inside(a.box, b.box, 0.8), box_inside(b.box, a.box, 0.8)
        if a_in != b_in:
            return a_in
        if np.isfinite(med_a) and np.isfinite(med_b) and abs(med_a - med_b) > 0.3:
            return med_a < med_b
        if abs(a.box[3] - b.box[3]) > 4:
            return a.box[3] > b.box[3]
        return area_a < area_b

    def _check_names(self, rgb, kept: list[_Candidate], labels: np.ndarray) -> None:
        """A detector's class gives way to the classifier's label when the detection is not sure
        (score under :data:`_RENAME_BELOW`), the classifier is (:data:`_RENAME_SURE`) and it gives
        the detector's family almost nothing (:data:`_RENAME_FAMILY_MAX`): the Open Images SSD
        calls a sideboard a table, EfficientNet a chiffonier."""
        if self.classifier is None:
            return
        idx = [i for i, c in enumerate(kept) if c.witness != "classifier" and c.score < _RENAME_BELOW]
        if not idx:
            return
        crops, crop_masks = [], []
        for i in idx:
            m = labels == i + 1
            rows, cols = np.flatnonzero(m.any(axis=1)), np.flatnonzero(m.any(axis=0))
            crops.append(np.ascontiguousarray(rgb[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]))
            crop_masks.append(m[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1])
        for i, lp in zip(idx, self.classifier.backend.label_scores_many(crops, crop_masks, [None] * len(crops))):
            c = kept[i]
            best, p = _best_family(lp)
            sure = _RENAME_SURE if c.score >= CONFIDENT else _CLASSIFIER_SURE
            if not best or best in family(c.label) or p < sure:
                continue
            if sum(lp.get(lab, 0.0) for lab in family(c.label)) > _RENAME_FAMILY_MAX:
                continue
            c.meta["detector_label"] = c.label
            c.label = best
            c.witness = c.witness + ", renamed"

    def _classify_masks(self, rgb, masks: list[np.ndarray]) -> list[tuple[str, float]]:
        """(label, probability) the classifier gives each (H, W) mask's crop when it reaches
        :data:`_CLASSIFIER_SURE`, else ("", 0)."""
        if self.classifier is None or not masks:
            return [("", 0.0)] * len(masks)
        crops, crop_masks = [], []
        for m in masks:
            rows, cols = np.flatnonzero(m.any(axis=1)), np.flatnonzero(m.any(axis=0))
            crops.append(np.ascontiguousarray(rgb[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]))
            crop_masks.append(m[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1])
        out = []
        for lp in self.classifier.backend.label_scores_many(crops, crop_masks, [None] * len(crops)):
            best, p = _best_family(lp)
            out.append((best, p) if best and p >= _CLASSIFIER_SURE else ("", 0.0))
        return out

    def _extras(self, rgb, clusters, cluster_sizes, labels, kept, sem_labels, points, depth_m, valid, background, up_cam, h: int, w: int, removed,
                focal: float) -> list[_Candidate]:
        """Depth clusters and semantic regions no detection explains, when they are clear objects
        (people and animals, ``removed``, explain what they cover). Of a cluster a detection
        explains in part (depth joined a wardrobe, the cabinet beside it and the box in front),
        the rest falls into its own 3D pieces, each an extra when clear."""
        import cv2

        from perception.segment_depth import cluster_points

        out = []
        unclear: list[tuple[int, np.ndarray]] = []
        claimed = (labels > 0) | removed
        up = None if up_cam is None else np.asarray(up_cam, dtype=np.float64)
        cache: list[np.ndarray] = []

        def normals() -> np.ndarray:
            if not cache:
                cache.append(point_normals(points))
            return cache[0]

        pieces: list[tuple[int, np.ndarray]] = []
        for c in np.flatnonzero(cluster_sizes >= self.min_points):
            if c == 0:
                continue
            m = clusters == c
            share = (m & claimed).sum() / cluster_sizes[c]
            m = m & ~claimed
            if share < _UNEXPLAINED:
                pieces.append((int(c), m))
            elif share < _REST_SPLIT_MAX and m.sum() >= self.min_points:
                lab = cluster_points(points[m], focal)
                for k in np.unique(lab):
                    sub = np.zeros_like(m)
                    sub[m] = lab == k
                    if sub.sum() >= self.min_points:
                        pieces.append((int(c), sub))
        for c, m in pieces:
            if not is_clear(m, points, valid & ~background, up, depth_m, valid, self.min_points, normals):
                unclear.append((int(c), m))
                continue
            name = ""
            if sem_labels is not None:
                vals, counts = np.unique(sem_labels[m], return_counts=True)
                best = int(np.argmax(counts))
                if vals[best] != "" and counts[best] >= 0.5 * m.sum():
                    name = str(vals[best])
            out.append(_Candidate(np.zeros(4), 0.3, name, "extra-depth", int(c), mask=m))
        # A cluster that is not clear by its shape (a close-up's flat cabinet front) is still an
        # object when the classifier is sure what it is (the largest few: each costs a forward pass).
        unclear = sorted((u for u in unclear if u[1].sum() >= _UNCLEAR_MIN_AREA * h * w), key=lambda u: (-int(u[1].sum()), u[0]))[:_MAX_UNCLEAR]
        for (c, m), (label, p) in zip(unclear, self._classify_masks(rgb, [m for _, m in unclear])):
            if label:
                out.append(_Candidate(np.zeros(4), p, label, "extra-classifier", c, mask=m))
        if sem_labels is not None:
            for label in sorted({str(v) for v in np.unique(sem_labels)} - {""}):
                region = (sem_labels == label) & ~claimed
                n, comp, stats, _ = cv2.connectedComponentsWithStats(region.astype(np.uint8), connectivity=8)
                for r in range(1, n):
                    if stats[r, cv2.CC_STAT_AREA] < max(2 * self.min_points, 0.01 * h * w) or stats[r, cv2.CC_STAT_AREA] > 0.25 * h * w:
                        continue
                    m = comp == r
                    # What the semantic map left of an instance of the same family beside it is
                    # a part of that instance the cut missed, not another object.
                    ring = (cv2.dilate(m.astype(np.uint8), np.ones((11, 11), np.uint8)) > 0) & ~m
                    beside = {kept[i - 1].label for i in np.unique(labels[ring]) if i > 0}
                    if beside & family(label):
                        continue
                    # Inside a detected object's box it is a part of that object or lies on it.
                    if any(m[_box_slices(e.box, h, w)].sum() >= 0.7 * m.sum() for e in kept):
                        continue
                    if any((m & e.mask).sum() >= _UNEXPLAINED * m.sum() for e in out) or solidity(m) < 0.5:
                        continue
                    out.append(_Candidate(np.zeros(4), 0.3, label, "extra-semantic", mask=keep_main_regions(m)))
        return out

    def _record(self, dets: Detections, kept: list[_Candidate], n_det: int) -> None:
        witnesses: dict[str, int] = {}
        for c in kept:
            witnesses[c.witness] = witnesses.get(c.witness, 0) + 1
        said = ", ".join(f"{n} by {k}" for k, n in sorted(witnesses.items()))
        names = "+".join(nb.name for nb in self.detectors)
        n_named = sum(1 for lab in dets.labels if lab)
        each = ", ".join(f"{name} {n}" for name, n in self._boxes_per_detector)
        self.uses = [
            BackendUse("detection", names, f"{len(dets)} boxes ({n_named} of vocabulary classes; before merging: {each}); {len(kept)} objects: {said or 'none'}"),
            BackendUse("box-segmentation", self.box_segmenter.name, f"{n_det} box prompts"),
        ]
        if self.semantic is not None:
            self.uses.append(BackendUse("semantic-segmentation", self.semantic.name, "confirms boxes, hints masks, names extras"))
        if self.classifier is not None and witnesses.get("classifier"):
            self.uses.append(BackendUse("proposal-naming", self.classifier.name, f"named {witnesses['classifier']} boxes no vocabulary class explained"))
