"""Chamfer distance, F-score and box IoU of a built scene's objects against true object surfaces:
the figures of the single-image 3D-FRONT protocol, computed as its published code does.

Definitions (and where they come from)
--------------------------------------
* **MIDI** (Huang et al., "MIDI: Multi-Instance Diffusion for Single Image to 3D Scene
  Generation", CVPR 2025, arXiv 2412.03558, Table 1; evaluation code
  ``midi/systems/system_midi.py::compute_metrics`` and ``midi/utils/metrics.py`` of
  github.com/VAST-AI-Research/MIDI-3D): 20,480 points sampled uniformly on each object's surface.
  *Scene level* (CD-S, F-Score-S): every object's points of a scene together; the prediction
  rigidly aligned to the truth by ICP (50 iterations); CD = mean over predicted points of the
  **squared** distance to the nearest true point + the same from true to predicted (the sum of
  both directions); F-score at tau = 0.1 = harmonic mean of precision (predicted points within
  0.1 of a true point) and recall (true points within 0.1 of a predicted point), in percent.
  *Object level* (CD-O, F-Score-O): each object's predicted and true points normalised
  independently, per axis, to [-0.95, 0.95] (min-max), ICP, the same CD and F-score, averaged
  over objects. *IoU-B*: volume IoU of the axis-aligned bounding boxes of each object's
  predicted and true points in the scene's frame (no alignment), averaged over objects.
  MIDI's scenes live in the [-1, 1] cube its generator works in; here a scene is brought there
  by the one scale and shift that map the true objects' bounding box's largest side onto [-1, 1]
  (the normalisation of MIDI's released 3D-FRONT surfaces is not in its repository; this is our
  reading), so tau = 0.1 is 5 % of the scene's largest extent.
* **CAST** (Yao et al., "CAST: Component-Aligned 3D Scene Reconstruction from an RGB Image",
  SIGGRAPH 2025, arXiv 2502.12894, Table 2) reports CD-S, FS-S, CD-O, FS-O and IoU-B on 3D-FRONT
  beside MIDI's; it publishes no evaluation code, so the definitions above (MIDI's) stand for it.
* **Gen3DSR** (Ardelean et al., "Gen3DSR: Generalizable 3D Scene Reconstruction via Divide and
  Conquer from a Single View", 3DV 2025; ``src/eval_front.py`` of github.com/AndreeaDogaru/Gen3DSR):
  points sampled with Open3D, CD = (mean nearest distance true -> predicted + mean predicted ->
  true) / 2 with **unsquared** distances, F-score at 0.1 (metres on 3D-FRONT), no alignment.
  Reported here as ``cd_m`` / ``fscore_m``: metres in the truth's frame, nothing aligned, which
  is what a robot in the twin meets.

Open3D does the sampling (``TriangleMesh.sample_points_uniformly``), the nearest-neighbour
distances (``PointCloud.compute_point_cloud_distance``, a KD-tree) and the ICP
(``pipelines.registration.registration_icp``, point to point, every point paired with its
nearest neighbour at any distance, as MIDI's ICP pairs them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "F_TAU",
    "SAMPLES_PER_OBJECT",
    "ObjectShapeScore",
    "SceneShapeScore",
    "box_iou_aabb",
    "chamfer_fscore",
    "icp_align",
    "nearest_distances",
    "normalize_per_axis",
    "primitive_mesh",
    "sample_surface",
    "score_objects",
    "score_scene",
]

SAMPLES_PER_OBJECT = 20480  # MIDI's num_surface_samples_per_object
F_TAU = 0.1  # MIDI's and Gen3DSR's F-score threshold
ICP_ITERATIONS = 50  # MIDI's max_iterations


def sample_surface(vertices_m: np.ndarray, faces: np.ndarray, n: int = SAMPLES_PER_OBJECT, seed: int = 0) -> np.ndarray:
    """(n, 3) points uniformly distributed over the area of a triangle mesh (Open3D)."""
    import open3d as o3d

    o3d.utility.random.seed(int(seed))
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.asarray(vertices_m, dtype=np.float64)), o3d.utility.Vector3iVector(np.asarray(faces, dtype=np.int32)))
    return np.asarray(mesh.sample_points_uniformly(number_of_points=int(n)).points)


def primitive_mesh(shape: str, half_size_m, center_m, object_from_primitive: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of a procedural-room primitive (``box``, vertical ``cylinder``,
    ``ellipsoid``; :class:`scene_builder.bench.procedural.Primitive`) centred at ``center_m``."""
    import open3d as o3d

    a, b, c = (float(x) for x in half_size_m)
    if shape == "box":
        m = o3d.geometry.TriangleMesh.create_box(2 * a, 2 * b, 2 * c)
        v = np.asarray(m.vertices) - [a, b, c]
    elif shape == "cylinder":
        m = o3d.geometry.TriangleMesh.create_cylinder(radius=a, height=2 * c, resolution=48, split=1)
        v = np.asarray(m.vertices)
    elif shape == "ellipsoid":
        m = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=24)
        v = np.asarray(m.vertices) * [a, b, c]
    else:
        raise ValueError(f"unknown primitive shape {shape!r}")
    v = v + np.asarray(center_m, dtype=np.float64)
    if object_from_primitive is not None:
        v = v @ object_from_primitive[:3, :3].T + object_from_primitive[:3, 3]
    return v, np.asarray(m.triangles, dtype=np.int64)


def nearest_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(len(a),) Euclidean distance from each point of ``a`` to the nearest point of ``b``."""
    import open3d as o3d

    pa = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(a, dtype=np.float64)))
    pb = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(b, dtype=np.float64)))
    return np.asarray(pa.compute_point_cloud_distance(pb))


def chamfer_fscore(pred: np.ndarray, true: np.ndarray, tau: float = F_TAU) -> dict[str, float]:
    """``cd_sq`` (MIDI: mean squared nearest distance pred -> true + true -> pred), ``cd_l2``
    (Gen3DSR: mean of the two mean unsquared distances), ``fscore`` (percent, at ``tau``),
    ``precision`` and ``recall`` (percent)."""
    d_pt = nearest_distances(pred, true)
    d_tp = nearest_distances(true, pred)
    precision = 100.0 * float(np.mean(d_pt < tau))
    recall = 100.0 * float(np.mean(d_tp < tau))
    f = 2.0 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return {
        "cd_sq": float(np.mean(d_pt**2) + np.mean(d_tp**2)),
        "cd_l2": float((np.mean(d_pt) + np.mean(d_tp)) / 2.0),
        "fscore": f,
        "precision": precision,
        "recall": recall,
    }


def icp_align(pred: np.ndarray, true: np.ndarray, iterations: int = ICP_ITERATIONS) -> np.ndarray:
    """``pred`` rigidly moved onto ``true`` by point-to-point ICP (Open3D), each point paired with
    its nearest neighbour whatever the distance (as MIDI's ICP), from the identity."""
    import open3d as o3d

    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(pred, dtype=np.float64)))
    dst = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(true, dtype=np.float64)))
    span = float(np.ptp(np.vstack([pred, true]), axis=0).max()) if len(pred) and len(true) else 1.0
    reg = o3d.pipelines.registration
    result = reg.registration_icp(
        src, dst, max(span, 1e-6) * 10.0, np.eye(4), reg.TransformationEstimationPointToPoint(),
        reg.ICPConvergenceCriteria(relative_fitness=1e-9, relative_rmse=1e-9, max_iteration=int(iterations)),
    )
    t = np.asarray(result.transformation)
    return np.asarray(pred) @ t[:3, :3].T + t[:3, 3]


def normalize_per_axis(points: np.ndarray) -> np.ndarray:
    """MIDI's object normalisation: each axis min-max mapped to [-0.95, 0.95] (an axis of zero
    extent is left at -0.95)."""
    p = np.asarray(points, dtype=np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    rng = np.where(hi - lo > 0, hi - lo, 1.0)
    return 1.9 * (p - lo) / rng - 0.95


def box_iou_aabb(pred: np.ndarray, true: np.ndarray) -> float:
    """Volume IoU of the axis-aligned bounding boxes of two point sets (MIDI's IoU-B)."""
    plo, phi = np.min(pred, axis=0), np.max(pred, axis=0)
    tlo, thi = np.min(true, axis=0), np.max(true, axis=0)
    inter = float(np.prod(np.clip(np.minimum(phi, thi) - np.maximum(plo, tlo), 0.0, None)))
    union = float(np.prod(phi - plo) + np.prod(thi - tlo) - inter)
    return inter / union if union > 0 else 0.0


@dataclass(frozen=True)
class ObjectShapeScore:
    """One matched object: its names, MIDI's CD-O / F-Score-O (normalised, ICP), IoU-B, and the
    unaligned metric figures (Gen3DSR's CD in metres, F-score at 0.1 m)."""

    pred: str
    true: str
    cd_o: float
    fscore_o: float
    iou_b: float
    cd_m: float
    fscore_m: float


@dataclass(frozen=True)
class SceneShapeScore:
    """One scene: MIDI's CD-S / F-Score-S (scene in the [-1, 1] cube, ICP) and the unaligned
    metric figures over every object together; n_pred / n_true objects in the point sets."""

    n_pred: int
    n_true: int
    cd_s: float | None
    fscore_s: float | None
    cd_s_m: float | None
    fscore_s_m: float | None


def score_scene(pred_objects: list[np.ndarray], true_objects: list[np.ndarray]) -> SceneShapeScore:
    """Scene-level figures of the predicted objects' points (each (N, 3), the truth's frame, metres)
    against the true objects' points. Without a predicted object, F-scores are 0 and CDs None."""
    if not true_objects:
        raise ValueError("score_scene needs at least one true object")
    true = np.vstack(true_objects)
    if not pred_objects:
        return SceneShapeScore(0, len(true_objects), None, 0.0, None, 0.0)
    pred = np.vstack(pred_objects)
    metric = chamfer_fscore(pred, true)
    lo, hi = true.min(axis=0), true.max(axis=0)
    centre, scale = (lo + hi) / 2.0, 2.0 / float(np.max(hi - lo))
    p_n, t_n = (pred - centre) * scale, (true - centre) * scale
    midi = chamfer_fscore(icp_align(p_n, t_n), t_n)
    return SceneShapeScore(len(pred_objects), len(true_objects), midi["cd_sq"], midi["fscore"], metric["cd_l2"], metric["fscore"])


def score_objects(pairs: list[tuple[str, np.ndarray, str, np.ndarray]]) -> list[ObjectShapeScore]:
    """Object-level figures of each matched ``(pred name, pred points, true name, true points)``
    (the truth's frame, metres)."""
    out = []
    for pn, p, tn, t in pairs:
        metric = chamfer_fscore(p, t)
        p_n, t_n = normalize_per_axis(p), normalize_per_axis(t)
        midi = chamfer_fscore(icp_align(p_n, t_n), t_n)
        out.append(ObjectShapeScore(pn, tn, midi["cd_sq"], midi["fscore"], box_iou_aabb(p, t), metric["cd_l2"], metric["fscore"]))
    return out
