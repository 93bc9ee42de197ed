"""The room's objects against ground truth, not against the input photo.

The render from the photo's own camera matches the photo whatever became of the objects (the
background carries the photo), so this benchmark scores only the **interactive** objects of a
build (movable bodies, and fixed furniture with joints) against annotations made by people:

* **3D boxes** (SUN RGB-D ``ground_truth.boxes_3d`` of ``../shared/data/real/sunrgbd_*``): recall
  at 3D IoU >= 0.25 (greedy one-to-one matching, best IoU first), and with the label right, built
  with the sensor depth and as plain photos (same intrinsics, no depth).
* **Instance masks** (COCO ``gt_instances.json`` of ``../shared/data/photos_gt``, plain photos):
  each interactive object's silhouette rendered from ``input_camera`` (MuJoCo segmentation, so
  what stands in front hides it) against the furniture-like instances; recall at mask IoU >= 0.5
  (all furniture-like classes, large furniture and appliances, label right) and precision (objects
  matching an instance at IoU >= 0.25 / interactive objects; as in COCO's own evaluation, an
  object that matches no scored instance and is under the smallest scored size, or matches an
  annotated instance that small, is not scored). The pixels of annotated people and animals are
  left out of both masks (the twin removes them and shows what they hid, which an annotation of
  what was visible cannot score); ``people_scored_*`` gives the figures with them counted.
* **What became of the perceived objects**: interactive (movable, or fixed with joints), fixed
  without joints, static background; crashes and refusals per input.

Every table stands beside the control "everything is background" (the same build with every
object made static background: the photo on the room, no object), which scores 0 on each figure:
a figure above 0 is earned by objects.

    .venv/bin/python -m scene_builder.bench.groundtruth --json objects.json     # all three sets
    .venv/bin/python -m scene_builder.bench.groundtruth --sets sun-rgbd --keep /tmp/gt

Denominators: boxes and instances of the ground truth (every annotated one, visible or not);
precision: the interactive objects built; shares: every object perception found.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = [
    "COCO_FURNITURE",
    "COCO_LARGE",
    "COCO_REMOVED",
    "SUN_SYNONYMS",
    "BoxScore",
    "CocoTruth",
    "MaskScore",
    "ObjectFates",
    "coco_masks",
    "coco_truth",
    "interactive_names",
    "object_fates",
    "score_boxes",
    "score_masks",
    "silhouettes",
    "sun_boxes",
    "sun_gt_from_world",
]

REPO = Path(__file__).resolve().parents[2]
DEFAULT_DATA = REPO.parent / "shared" / "data"


def repo_relative(text: str) -> str:
    """``text`` with the absolute paths under the repository's parent folder written relative to
    the repository (``../shared/data/...``): the results committed with it name no machine's folders."""
    return text.replace(str(REPO.parent) + "/", "../")
BOX_IOU = 0.25
MASK_IOU = 0.5
MASK_IOU_LOOSE = 0.25

#: SUN RGB-D labels -> vocabulary labels that name the same thing (a night stand is a small
#: cabinet or drawer unit to the vocabulary).
SUN_SYNONYMS: dict[str, tuple[str, ...]] = {
    "bed": ("bed",),
    "night_stand": ("nightstand", "cabinet", "drawer_unit", "dresser", "side_table", "table"),
    "dresser": ("dresser", "cabinet", "drawer_unit", "wardrobe"),
    "dresser_mirror": ("mirror",),
    "lamp": ("lamp",),
    "ottoman": ("ottoman", "stool", "bench", "pouf"),
    "chair": ("chair", "armchair", "stool"),
    "sofa": ("sofa", "armchair"),
    "table": ("table", "desk", "coffee_table", "side_table"),
    "desk": ("desk", "table"),
    "bookshelf": ("shelf", "bookshelf"),
    "toilet": ("toilet",),
}

#: COCO classes a room's twin should make objects of -> vocabulary labels naming them.
COCO_FURNITURE: dict[str, tuple[str, ...]] = {
    "couch": ("sofa", "armchair"),
    "chair": ("chair", "armchair", "stool"),
    "bed": ("bed",),
    "dining table": ("table", "desk", "coffee_table", "side_table"),
    "tv": ("tv", "monitor"),
    "refrigerator": ("refrigerator",),
    "oven": ("oven", "stove"),
    "microwave": ("microwave",),
    "sink": ("sink",),
    "toilet": ("toilet",),
    "potted plant": ("plant",),
    "laptop": ("laptop",),
    "bench": ("bench",),
    "toaster": ("toaster",),
    "vase": ("vase",),
    "clock": ("clock",),
    "book": ("book",),
    "bowl": ("bowl",),
    "bottle": ("bottle",),
    "cup": ("cup", "mug"),
    "teddy bear": ("soft_toy", "toy", "teddy_bear"),
}
#: Large furniture and appliances.
COCO_LARGE = frozenset({"couch", "chair", "bed", "dining table", "tv", "refrigerator", "oven", "microwave", "sink", "toilet", "bench"})
#: COCO instances smaller than this share of the photo are not scored.
MIN_INSTANCE_SHARE = 0.002


def _label_ok(label: str, synonyms: tuple[str, ...]) -> bool:
    lab = label.lower().replace(" ", "_")
    return any(lab == s or lab.startswith(s) for s in synonyms)


# ---------------------------------------------------------------------------------------------
# What became of the perceived objects
# ---------------------------------------------------------------------------------------------


def interactive_names(scene) -> tuple[str, ...]:
    """Objects a robot can act on: movable bodies, and fixed furniture whose parts have joints."""
    out = []
    for o in scene.objects:
        if not o.asset.is_fixed or any(p.joint is not None for p in o.asset.parts):
            out.append(o.name)
    return tuple(out)


@dataclass(frozen=True)
class ObjectFates:
    """Every object perception found, by what it ended as. perceived = interactive + fixed +
    background; background_reasons: (name, reason) of those that became static background;
    left_out_behind_walls: instances perception left out for lying behind a wall (not perceived);
    left_out_unmeasured: instances left out for too little measured depth on them (not perceived)."""

    perceived: int
    interactive: int
    fixed: int
    background: int
    background_reasons: tuple[tuple[str, str], ...] = ()
    left_out_behind_walls: int = 0
    left_out_unmeasured: int = 0


def object_fates(perceived_names, scene, placements, left_out_behind_walls: int = 0, left_out_unmeasured: int = 0) -> ObjectFates:
    """Fates of ``perceived_names`` (every object perception found) in the built ``scene``."""
    inter = set(interactive_names(scene))
    placed = {o.name for o in scene.objects}
    reasons = tuple((p.name, p.reason) for p in placements if p.became_background)
    n = len(tuple(perceived_names))
    n_inter = sum(1 for name in perceived_names if name in inter)
    n_fixed = sum(1 for name in perceived_names if name in placed and name not in inter)
    return ObjectFates(n, n_inter, n_fixed, n - n_inter - n_fixed, reasons, int(left_out_behind_walls), int(left_out_unmeasured))


# ---------------------------------------------------------------------------------------------
# 3D boxes (SUN RGB-D)
# ---------------------------------------------------------------------------------------------


def sun_boxes(sample_dir: Path):
    """The annotated boxes of a SUN RGB-D sample as ``metrics.ObjectBox`` in its upright depth
    frame (x right, y forward, z up, metres, origin at the camera), and its Rtilt (3, 3)."""
    from scene_builder.bench.metrics import Box3D, ObjectBox

    meta = json.loads((Path(sample_dir) / "meta.json").read_text())
    gt = meta.get("ground_truth") or {}
    boxes = []
    for i, b in enumerate(gt.get("boxes_3d") or ()):
        boxes.append(ObjectBox(f"{b['label']}_{i}", b["label"], Box3D(np.asarray(b["center_m"]), np.asarray(b["size_m"]), float(b["yaw_rad"]))))
    return boxes, np.asarray(gt.get("Rtilt", np.eye(3)), dtype=np.float64).reshape(3, 3)


def sun_gt_from_world(world_from_camera: np.ndarray, rtilt: np.ndarray) -> np.ndarray:
    """(4, 4) from the twin's world to SUN RGB-D's upright depth frame: world -> OpenCV camera ->
    the tilted depth frame (x_c, z_c, -y_c) -> Rtilt."""
    cam_from_world = np.linalg.inv(world_from_camera)
    depth_from_cam = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    out = np.eye(4)
    out[:3, :] = rtilt @ depth_from_cam @ cam_from_world[:3, :]
    return out


@dataclass(frozen=True)
class BoxScore:
    """3D box matches of one build: n_true boxes, n_pred interactive objects, matched at
    IoU >= 0.25 (matched_label: with the label right); best_iou per true box (label, IoU)."""

    n_true: int
    n_pred: int
    matched: int
    matched_label: int
    best_iou: tuple[tuple[str, float], ...]
    pairs: tuple[tuple[str, str, float], ...]


def score_boxes(pred, true) -> BoxScore:
    """Greedy one-to-one matching of ``pred`` to ``true`` (``metrics.ObjectBox`` in one frame) by
    3D IoU, best first, down to :data:`BOX_IOU`."""
    from scene_builder.bench.metrics import box_iou_3d

    iou = np.array([[box_iou_3d(p.box, t.box) for t in true] for p in pred]).reshape(len(pred), len(true))
    cand = sorted(((iou[i, j], i, j) for i in range(len(pred)) for j in range(len(true)) if iou[i, j] >= BOX_IOU), reverse=True)
    used_p, used_t, pairs = set(), set(), []
    for v, i, j in cand:
        if i in used_p or j in used_t:
            continue
        used_p.add(i)
        used_t.add(j)
        pairs.append((pred[i].name, true[j].name, float(v)))
    by_name = {p.name: p for p in pred}
    lab = {t.name: t.label for t in true}
    ok = sum(1 for pn, tn, _ in pairs if _label_ok(by_name[pn].label, SUN_SYNONYMS.get(lab[tn], (lab[tn],))))
    best = tuple((t.label, float(iou[:, j].max()) if len(pred) else 0.0) for j, t in enumerate(true))
    return BoxScore(len(true), len(pred), len(pairs), ok, best, tuple(pairs))


# ---------------------------------------------------------------------------------------------
# Instance masks (COCO)
# ---------------------------------------------------------------------------------------------


#: COCO classes the twin removes (people and animals are not part of a room, issue 23): their
#: pixels are left out of every mask comparison (see :func:`score_masks`).
COCO_REMOVED = frozenset({"person", "bird", "cat", "dog", "horse", "sheep", "cow", "elephant", "bear", "zebra", "giraffe"})


def _polygon_mask(g: dict, h: int, w: int) -> np.ndarray | None:
    """(H, W) bool of one annotation's polygons, or None where it has none (a crowd's RLE)."""
    from skimage.draw import polygon as draw_polygon

    if not isinstance(g.get("polygon"), (list, str)):
        return None
    m = np.zeros((h, w), dtype=bool)
    polys = g["polygon"] if isinstance(g["polygon"], list) else json.loads(g["polygon"])
    for p in polys:
        p = np.asarray(p, dtype=np.float64).reshape(-1, 2)
        rr, cc = draw_polygon(p[:, 1], p[:, 0], (h, w))
        m[rr, cc] = True
    return m


@dataclass(frozen=True)
class CocoTruth:
    """A photo's annotation as the bench scores it: scored: (COCO class, (H, W) bool) of the
    furniture-like, non-crowd instances of at least :data:`MIN_INSTANCE_SHARE` of the photo;
    small: the masks of those under it (not scored, but an object matching one is no false
    positive, see :func:`score_masks`); removed: (H, W) bool pixels of the annotated people and
    animals, crowds included."""

    scored: list[tuple[str, np.ndarray]]
    small: list[np.ndarray]
    removed: np.ndarray


def coco_truth(sample_dir: Path, h: int, w: int) -> CocoTruth:
    """The :class:`CocoTruth` of a sample folder's ``gt_instances.json``, read once."""
    scored, small, removed = [], [], np.zeros((h, w), dtype=bool)
    for g in json.loads((Path(sample_dir) / "gt_instances.json").read_text()):
        crowd = str(g.get("iscrowd", 0)) == "1"
        if g["label"] in COCO_REMOVED:
            m = _polygon_mask(g, h, w)
            if m is not None:
                removed |= m
        elif g["label"] in COCO_FURNITURE and not crowd:
            m = _polygon_mask(g, h, w)
            if m is None:
                continue
            if m.sum() >= MIN_INSTANCE_SHARE * h * w:
                scored.append((g["label"], m))
            else:
                small.append(m)
    return CocoTruth(scored, small, removed)


def coco_masks(sample_dir: Path, h: int, w: int) -> list[tuple[str, np.ndarray]]:
    """(COCO class, (H, W) bool) of the furniture-like, non-crowd instances of a photo (at least
    :data:`MIN_INSTANCE_SHARE` of it): :attr:`CocoTruth.scored`."""
    return coco_truth(sample_dir, h, w).scored


def silhouettes(mjcf_path: Path, names, h: int, w: int) -> dict[str, np.ndarray]:
    """(H, W) bool silhouette of each object of ``names`` from ``input_camera`` of the MJCF at
    t = 0, hidden where anything else (background included) stands in front of it."""
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(mjcf_path))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    cam = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, "input_camera")
    m.vis.global_.offwidth = max(m.vis.global_.offwidth, w)
    m.vis.global_.offheight = max(m.vis.global_.offheight, h)
    renderer = mujoco.Renderer(m, h, w)
    try:
        renderer.enable_segmentation_rendering()
        renderer.update_scene(d, camera=cam)
        seg = renderer.render()[..., 0]
    finally:
        renderer.close()
    wanted = set(names)
    owner = {}
    for b in range(1, m.nbody):
        root = b
        while m.body_parentid[root] != 0:
            root = m.body_parentid[root]
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, root) or ""
        obj = name.split("/")[0]
        if obj in wanted:
            owner[b] = obj
    out = {n: np.zeros((h, w), dtype=bool) for n in wanted}
    for g in range(m.ngeom):
        obj = owner.get(int(m.geom_bodyid[g]))
        if obj is not None:
            out[obj] |= seg == g
    return {k: v for k, v in out.items() if v.any()}


@dataclass(frozen=True)
class MaskScore:
    """Instance matches of one photo: n_true instances (n_large of them large furniture), n_pred
    interactive objects with a silhouette, less those left out of the precision as COCO's own
    evaluation leaves out detections outside its area range (n_ignored: under
    :data:`MIN_INSTANCE_SHARE`, or matching a furniture-like instance that small, and matching no
    scored instance); matched at IoU >= 0.5 (label right, large), matched_loose at IoU >= 0.25
    (the precision's numerator)."""

    n_true: int
    n_large: int
    n_pred: int
    matched: int
    matched_label: int
    matched_large: int
    matched_loose: int
    n_ignored: int = 0


def _small_or_unscored(sil: np.ndarray, small: list[np.ndarray]) -> bool:
    """Is a silhouette under :data:`MIN_INSTANCE_SHARE` of the photo, or a match (IoU >=
    :data:`MASK_IOU_LOOSE`) of a furniture-like instance that small (a mug on a shelf)?"""
    if sil.sum() < MIN_INSTANCE_SHARE * sil.size:
        return True
    return any(np.count_nonzero(sil & g) >= MASK_IOU_LOOSE * np.count_nonzero(sil | g) for g in small)


def score_masks(pred: dict[str, tuple[str, np.ndarray]], true: list[tuple[str, np.ndarray]], small: list[np.ndarray] = (),
                removed: np.ndarray | None = None) -> MaskScore:
    """Greedy one-to-one matching by mask IoU, best first, down to :data:`MASK_IOU_LOOSE`.
    pred: name -> (label, silhouette); small: masks of the instances too small to score. An
    object that matches no scored instance and is that small itself, or matches a small one, is
    left out of the precision (COCO's area ranges: the annotation cannot judge it). removed:
    (H, W) bool pixels of the people and animals, left out of both masks: the twin removes them
    and shows what they hid (a sofa's seat under the person on it), which the photo's
    annotation, of what was visible, cannot score."""
    if removed is not None and removed.any():
        pred = {n: (lab, m & ~removed) for n, (lab, m) in pred.items()}
        true = [(lab, m & ~removed) for lab, m in true]
    names = sorted(pred)
    cand = []
    for i, (_, g) in enumerate(true):
        for j, n in enumerate(names):
            t = pred[n][1]
            inter = np.count_nonzero(g & t)
            if inter:
                cand.append((inter / np.count_nonzero(g | t), i, j))
    cand.sort(reverse=True)
    used_t, used_p, match = set(), set(), []
    for v, i, j in cand:
        if v < MASK_IOU_LOOSE or i in used_t or j in used_p:
            continue
        used_t.add(i)
        used_p.add(j)
        match.append((v, i, j))
    strict = [x for x in match if x[0] >= MASK_IOU]
    ignored = sum(1 for j, n in enumerate(names) if j not in used_p and _small_or_unscored(pred[n][1], list(small)))
    return MaskScore(
        n_true=len(true),
        n_large=sum(1 for c, _ in true if c in COCO_LARGE),
        n_pred=len(names) - ignored,
        matched=len(strict),
        matched_label=sum(1 for _, i, j in strict if _label_ok(pred[names[j]][0], COCO_FURNITURE[true[i][0]])),
        matched_large=sum(1 for _, i, _ in strict if true[i][0] in COCO_LARGE),
        matched_loose=len(match),
        n_ignored=ignored,
    )


# ---------------------------------------------------------------------------------------------
# Running the builds
# ---------------------------------------------------------------------------------------------


def _rgb(sample: Path) -> Path:
    return next(p for p in (sample / "rgb.jpg", sample / "rgb.png") if p.exists())


def _config(models_dir: Path | None, segmentation: str):
    from scene_builder.config import BuildConfig, ExportConfig, PerceptionConfig

    perception = PerceptionConfig(models_dir=models_dir, segmentation_backend=segmentation)
    return BuildConfig(perception=perception, export=ExportConfig(usd=False, urdf=False, sdf=False, gltf=False, viz="off"))


def _all_background(scene):
    """The control: the same scene with no object (every one static background; what the twin is
    when objects are painted on the room)."""
    return dataclasses.replace(scene, objects=())


@dataclass(frozen=True)
class Item:
    """One input's outcome. status: "built", "refused" (a documented one-line error) or "crash"."""

    set: str
    name: str
    status: str
    seconds: float
    message: str = ""
    fates: ObjectFates | None = None
    boxes: BoxScore | None = None
    boxes_control: BoxScore | None = None
    masks: MaskScore | None = None
    masks_control: MaskScore | None = None
    masks_people_scored: MaskScore | None = None  # the same with people's pixels scored (the twin removed them)
    objects: tuple[tuple[str, str, bool], ...] = ()  # (name, label, interactive)
    inventory: object = None  # detect.InventoryScore of the interactive objects (set "real")
    inventory_perceived: object = None  # ... of every perceived object
    max_penetration_m: float | None = None  # the built scene's deepest overlap at t = 0 (verify_scene)
    stable: bool | None = None  # every movable object stayed at rest in the settle check


def run_item(set_name: str, sample: Path, out_dir: Path, config, with_depth: bool) -> Item:
    """Build one input and score it against its ground truth (and the control)."""
    from scene_builder.bench.metrics import scene_boxes
    from scene_builder.config import InputSpec
    from scene_builder.errors import SceneBuilderError
    from scene_builder.pipeline import build

    depth = sample / "depth.png" if with_depth and (sample / "depth.png").exists() else None
    inputs = InputSpec(_rgb(sample), depth_path=depth)
    start = time.perf_counter()
    try:
        result = build(inputs, out_dir, config, progress=False, overwrite=True)
    except SceneBuilderError as err:
        return Item(set_name, sample.name, "refused", time.perf_counter() - start, repo_relative(str(err).splitlines()[0]))
    except Exception:  # noqa: BLE001 - the bench counts crashes (any other exception is a bug) and goes on
        import traceback

        return Item(set_name, sample.name, "crash", time.perf_counter() - start, traceback.format_exc())
    seconds = time.perf_counter() - start
    scene = result.scene
    fates = object_fates([o.name for o in result.perception.objects], scene, result.layout.placements, result.perception.left_out_behind_walls,
                         result.perception.left_out_unmeasured)
    inter = set(interactive_names(scene))
    objects = tuple((o.name, o.asset.label, o.name in inter) for o in scene.objects)
    item = Item(set_name, sample.name, "built", seconds, fates=fates, objects=objects,
                max_penetration_m=float(result.verdict.max_penetration_m), stable=bool(result.verdict.stable))
    if set_name == "real":
        inv = _inventory().get(sample.name)
        if inv is not None:
            from scene_builder.bench.detect import score_inventory

            seen, groups = inv
            item = dataclasses.replace(
                item,
                inventory=score_inventory([lab for _, lab, inter in objects if inter], seen, groups),
                inventory_perceived=score_inventory([o.label for o in result.perception.objects], seen, groups),
            )
        return item
    if set_name.startswith("sun"):
        true, rtilt = sun_boxes(sample)
        t = sun_gt_from_world(scene.camera.world_from_camera, rtilt)
        pred = [b for b in scene_boxes(scene, t) if b.name in inter]
        item = dataclasses.replace(
            item, boxes=score_boxes(pred, true),
            boxes_control=score_boxes([b for b in scene_boxes(_all_background(scene), t)], true),
        )
    else:
        h, w = result.perception.observation.rgb_full.shape[:2] if result.perception.observation.rgb_full is not None else result.perception.observation.rgb.shape[:2]
        truth = coco_truth(sample, h, w)
        sil = silhouettes(out_dir / "scene.xml", inter, h, w)
        labels = {o.name: o.asset.label for o in scene.objects}
        pred = {n: (labels[n], s) for n, s in sil.items()}
        item = dataclasses.replace(
            item, masks=score_masks(pred, truth.scored, truth.small, truth.removed),
            masks_control=score_masks({}, truth.scored),
            masks_people_scored=score_masks(pred, truth.scored, truth.small),
        )
    return item


REAL_INVENTORY = REPO / "tests" / "data" / "real_inventory.json"


def _inventory() -> dict[str, tuple[dict[str, int], tuple[tuple[str, ...], ...]]]:
    """photo name -> (what a person sees there, same-category groups), from REAL_INVENTORY."""
    from scene_builder.bench.detect import load_inventory

    photos, groups = load_inventory(REAL_INVENTORY)
    return {name: (seen, groups) for name, seen in photos.items()}


def inputs_of(data_dir: Path, sets: tuple[str, ...]) -> list[tuple[str, Path, bool]]:
    """(set, sample folder, with depth) of every input of ``sets``."""
    out = []
    sun = sorted(p for p in (data_dir / "real").glob("sunrgbd_*") if (p / "meta.json").exists() and json.loads((p / "meta.json").read_text()).get("ground_truth", {}).get("boxes_3d"))
    if "sun-rgbd" in sets:
        out += [("sun-rgbd", p, True) for p in sun]
    if "sun-plain" in sets:
        out += [("sun-plain", p, False) for p in sun]
    if "real" in sets:  # every RGB-D sample of the real suite: what became of its objects
        out += [("real", p, True) for p in sorted((data_dir / "real").iterdir()) if (p / "depth.png").exists()]
    if "coco" in sets:
        out += [("coco", p, False) for p in sorted((data_dir / "photos_gt").glob("*")) if (p / "gt_instances.json").exists()]
    return out


def summarize(items: list[Item]) -> dict:
    """Pooled figures per set (denominators named in the keys)."""
    out: dict = {}
    for set_name in sorted({i.set for i in items}):
        its = [i for i in items if i.set == set_name]
        built = [i for i in its if i.status == "built"]
        fates = [i.fates for i in built if i.fates is not None]
        perceived = sum(f.perceived for f in fates)
        s: dict = {
            "inputs": len(its),
            "built": len(built),
            "refused": sum(1 for i in its if i.status == "refused"),
            "crashed": sum(1 for i in its if i.status == "crash"),
            "perceived_objects": perceived,
            "interactive_objects": sum(f.interactive for f in fates),
            "fixed_objects": sum(f.fixed for f in fates),
            "background_objects": sum(f.background for f in fates),
            "left_out_behind_walls": sum(f.left_out_behind_walls for f in fates),
            "left_out_unmeasured": sum(f.left_out_unmeasured for f in fates),
            "interactive_share_of_perceived": (sum(f.interactive for f in fates) / perceived) if perceived else None,
            "build_s_median": float(np.median([i.seconds for i in built])) if built else None,
            # Physical validity of what was built (the objects that ended interactive or fixed):
            # the deepest overlap over every build, and the builds not at rest.
            "max_penetration_mm": max((1000.0 * i.max_penetration_m for i in built if i.max_penetration_m is not None), default=None),
            "builds_not_at_rest": sum(1 for i in built if i.stable is False),
        }
        for key, pick in (("inventory", lambda i: i.inventory), ("inventory_perceived", lambda i: i.inventory_perceived)):
            scores = [pick(i) for i in built if pick(i) is not None]
            if scores:
                from scene_builder.bench.detect import pooled

                for k, v in pooled(scores).items():
                    s[f"{key}_{k}"] = v
                s[f"{key}_seen"] = sum(x.seen for x in scores)
        if any(i.boxes for i in built):
            n_true = sum(i.boxes.n_true for i in built if i.boxes)
            for key, pick in (("", lambda i: i.boxes), ("control_", lambda i: i.boxes_control)):
                m = sum(pick(i).matched for i in built if pick(i))
                ml = sum(pick(i).matched_label for i in built if pick(i))
                s[f"{key}box_recall_iou25"] = m / n_true if n_true else None
                s[f"{key}box_recall_iou25_label"] = ml / n_true if n_true else None
            s["true_boxes"] = n_true
        if any(i.masks for i in built):
            n_true = sum(i.masks.n_true for i in built if i.masks)
            n_large = sum(i.masks.n_large for i in built if i.masks)
            picks = (("", lambda i: i.masks), ("control_", lambda i: i.masks_control), ("people_scored_", lambda i: i.masks_people_scored))
            for key, pick in picks:
                ms = [pick(i) for i in built if pick(i)]
                if not ms:
                    continue
                n_pred = sum(x.n_pred for x in ms)
                s[f"{key}mask_recall_iou50"] = sum(x.matched for x in ms) / n_true if n_true else None
                s[f"{key}mask_recall_iou50_label"] = sum(x.matched_label for x in ms) / n_true if n_true else None
                s[f"{key}mask_recall_iou50_large"] = sum(x.matched_large for x in ms) / n_large if n_large else None
                s[f"{key}mask_precision_iou25"] = sum(x.matched_loose for x in ms) / n_pred if n_pred else 0.0
            s["true_instances"] = n_true
            s["true_large_instances"] = n_large
            s["scored_objects"] = sum(i.masks.n_pred for i in built if i.masks)  # the precision's denominator
            s["unscored_small_objects"] = sum(i.masks.n_ignored for i in built if i.masks)
        out[set_name] = s
    return out


def main(argv: list[str] | None = None) -> int:
    from scene_builder.bench.suites import run_meta

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the shared data folder (default ../shared/data)")
    parser.add_argument("--sets", default="sun-rgbd,sun-plain,coco,real", help="comma-separated: sun-rgbd, sun-plain, coco, real (every RGB-D sample: fates only)")
    parser.add_argument("--models-dir", type=Path, default=None, help="models dir (default: the bundled offline models)")
    parser.add_argument("--segmentation", default="auto", help="segmentation backend (default auto)")
    parser.add_argument("--keep", type=Path, default=None, help="build into this folder and keep the builds")
    parser.add_argument("--only", default="", help="only samples whose name contains this")
    parser.add_argument("--json", type=Path, default=None, help="write the items and the summary here")
    parser.add_argument("--markdown", action="store_true", help="print the summary as the README's Markdown table on stdout")
    args = parser.parse_args(argv)
    import tempfile

    from rich.console import Console

    console = Console(stderr=True, highlight=False)
    config = _config(args.models_dir, args.segmentation)
    sets = tuple(s.strip() for s in args.sets.split(",") if s.strip())
    todo = [x for x in inputs_of(args.data, sets) if args.only in x[1].name]
    items: list[Item] = []
    with tempfile.TemporaryDirectory(prefix="sb-gt-") as tmp:
        root = args.keep or Path(tmp)
        for set_name, sample, depth in todo:
            (root / set_name).mkdir(parents=True, exist_ok=True)
            item = run_item(set_name, sample, root / set_name / sample.name, config, depth)
            items.append(item)
            extra = ""
            if item.boxes:
                extra = f"boxes {item.boxes.matched}/{item.boxes.n_true} (label {item.boxes.matched_label}) " + " ".join(f"{lab}:{v:.2f}" for lab, v in item.boxes.best_iou)
            if item.inventory is not None:
                v = item.inventory
                extra = f"inventory: {v.matched} of {v.seen} seen things are interactive objects ({v.found} interactive)"
            if item.masks:
                m = item.masks
                extra = f"masks {m.matched}/{m.n_true} (large {m.matched_large}/{m.n_large}, label {m.matched_label}) precision {m.matched_loose}/{m.n_pred}"
            f = item.fates
            fate = f"{f.perceived} perceived, {f.interactive} interactive, {f.fixed} fixed, {f.background} background" if f else item.message
            console.print(f"{set_name:9s} {sample.name:28s} {item.status:7s} {item.seconds:5.1f} s  {fate}  {extra}")
    summary = summarize(items)
    for set_name, s in summary.items():
        console.print(f"[bold]{set_name}[/bold] " + ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in s.items()))
    doc = {"meta": run_meta("scene_builder.bench.groundtruth", argv), "summary": summary, "items": [dataclasses.asdict(i) for i in items]}
    if args.json:
        args.json.write_text(json.dumps(doc, indent=1, default=str))
    if args.markdown:
        from scene_builder.bench.readme import BLOCKS

        print(BLOCKS["objects"][1](json.loads(json.dumps(doc, default=str))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
