"""Ground truth read back from a sample folder (procedural rooms and the SUN RGB-D boxes of
``../shared/data``), and a built scene scored against it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["MIN_VISIBLE_PX", "SUN_SYNONYMS", "SampleTruth", "compare_to_ground_truth", "load_truth"]


# --------------------------------------------------------------------------------------------
# Reading ground truth back (procedural samples and the SUN RGB-D boxes of ../shared/data)
# --------------------------------------------------------------------------------------------

MIN_VISIBLE_PX = 150  # true objects with fewer visible pixels do not count against recall
# Vocabulary labels accepted for the SUN RGB-D benchmark classes.
SUN_SYNONYMS: dict[str, tuple[str, ...]] = {
    "bed": ("bed",),
    "table": ("table", "desk"),
    "desk": ("desk", "table"),
    "sofa": ("sofa",),
    "chair": ("chair", "stool"),
    "toilet": ("toilet",),
    "dresser": ("cabinet", "drawer_unit", "wardrobe"),
    "night_stand": ("cabinet", "drawer_unit", "table"),
    "bookshelf": ("shelf",),
    "bathtub": (),
}
# SUN RGB-D upright depth frame (x right, y forward, z up) from the OpenCV camera axes.
_UPRIGHT_FROM_CV = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True, eq=False)
class SampleTruth:
    """Ground truth of one sample folder.

    world_from_camera: (4, 4) camera pose in the truth's world frame (Z up).
    objects: the true objects as metric boxes in that frame.
    object_ids: instance id of each object in ``instances`` (procedural rooms), else None.
    instances: (H, W) uint16 instance ids, or None. depth_m: (H, W) float32 clean depth, or None.
    synonyms: predicted labels accepted for each true label.
    """

    world_from_camera: np.ndarray
    objects: tuple
    object_ids: tuple[int, ...] | None = None
    instances: np.ndarray | None = None
    depth_m: np.ndarray | None = None
    synonyms: dict[str, tuple[str, ...]] = field(default_factory=dict)


def load_truth(sample_dir: Path) -> SampleTruth | None:
    """Ground truth of a sample folder: a procedural room (``ground_truth.objects``) or a SUN RGB-D
    sample with 3D boxes (``ground_truth.boxes_3d`` + ``Rtilt``); None when it has neither."""
    from PIL import Image

    from scene_builder.bench.metrics import Box3D, ObjectBox

    sample_dir = Path(sample_dir)
    gt = json.loads((sample_dir / "meta.json").read_text()).get("ground_truth") or {}
    if gt.get("objects") is not None:
        objects = tuple(
            ObjectBox(o["name"], o["category"], Box3D(o["position_m"], o["size_m"], o["yaw_rad"]), o.get("mass_kg"), (o.get("visible_px") or 0) >= MIN_VISIBLE_PX)
            for o in gt["objects"]
        )
        inst = np.asarray(Image.open(sample_dir / gt["instances"])) if gt.get("instances") else None
        depth = np.asarray(Image.open(sample_dir / gt["metric_depth"])).astype(np.float32) / 1000.0 if gt.get("metric_depth") else None
        return SampleTruth(
            np.array(gt["camera"]["world_from_camera"], dtype=np.float64),
            objects,
            tuple(int(o["object_id"]) for o in gt["objects"]),
            inst,
            depth,
        )
    if gt.get("boxes_3d") and gt.get("Rtilt") is not None:
        world_from_camera = np.eye(4)
        world_from_camera[:3, :3] = np.array(gt["Rtilt"], dtype=np.float64) @ _UPRIGHT_FROM_CV
        # Rtilt is stored in float32: re-orthonormalise so the pose is a proper rotation.
        u, _, vt = np.linalg.svd(world_from_camera[:3, :3])
        world_from_camera[:3, :3] = u @ vt
        objects = tuple(
            ObjectBox(f"{b['label']}_{i}", b["label"], Box3D(b["center_m"], b["size_m"], b["yaw_rad"]), None, True) for i, b in enumerate(gt["boxes_3d"])
        )
        return SampleTruth(world_from_camera, objects, synonyms=SUN_SYNONYMS)
    return None


def compare_to_ground_truth(scene, sample_dir: Path) -> dict:
    """Score a built :class:`scene_builder.model.Scene` against the truth of its sample folder.

    The scene's world and the truth's world are related through the camera (both know its pose):
    ``truth_from_scene = truth.world_from_camera @ inv(scene.camera.world_from_camera)``. Objects
    are matched by Hungarian assignment on 3D centre distance with a size-dependent gate (see
    :mod:`scene_builder.bench.metrics`). Returns JSON-ready ``{"summary": {...}, "objects": [...]}``.
    """
    from scene_builder.bench import metrics

    truth = load_truth(sample_dir)
    if truth is None:
        raise ValueError(f"{sample_dir} has no ground truth to compare with (meta.json ground_truth.objects or boxes_3d)")
    gt_from_world = truth.world_from_camera @ np.linalg.inv(scene.camera.world_from_camera)
    pred = metrics.scene_boxes(scene, gt_from_world)
    match = metrics.match_by_center(np.array([p.box.center_m for p in pred]).reshape(-1, 3), [t.box for t in truth.objects])
    s = metrics.score_objects(pred, truth.objects, match, truth.synonyms)
    summary = {
        "true_objects": s.n_true,
        "built_objects": s.n_pred,
        "recall": s.recall,
        "precision": s.precision,
        "position_error_m_median": metrics.median_or_none(s.position_error_m),
        "yaw_error_deg_median": metrics.median_or_none(s.yaw_error_deg),
        "size_error_rel_median": metrics.median_or_none(s.size_error_rel),
        "box_iou_3d_median": metrics.median_or_none(s.box_iou),
        "category_accuracy": s.category_accuracy,
        "mass_error_rel_median": metrics.median_or_none(s.mass_error_rel),
    }
    objects = [
        {
            "built": p,
            "true": t,
            "position_error_m": pe,
            "yaw_error_deg": ye,
            "size_error_rel": se,
            "box_iou_3d": bi,
            "mass_error_rel": me,
        }
        for (p, t), pe, ye, se, bi, me in zip(s.pairs, s.position_error_m, s.yaw_error_deg, s.size_error_rel, s.box_iou, s.mass_error_rel)
    ]
    return {"summary": summary, "objects": objects}
