"""``scene-builder bench``: score the pipeline and a naive baseline on the same inputs.

Suites
------
* ``synthetic``: N procedural rooms (:mod:`scene_builder.bench.procedural`, seeds ``seed .. seed+N-1``,
  5 to 8 objects, every other room with sensor-like depth noise) with exact ground truth: boxes,
  masses, instance masks and clean depth.
* ``real``: every sample with depth under ``../shared/data/real`` (or a folder given). Only the
  SUN RGB-D sample with 3D boxes has object ground truth; the others are scored on physics and on
  render-and-compare against the observation.

The baseline
------------
The naive placement of a published scene application (:mod:`scene_builder.bench.baseline`): for
each perceived object (the same masks and depth the pipeline perceived), the axis-aligned box of
its depth points **in the camera frame**, gravity taken along the camera's +y axis, the floor at
the lowest observed point, no penetration handling and no settling; free box bodies of density
500 kg/m^3.

Both methods are :class:`~scene_builder.model.Scene` objects that go through one code path: the
project's MJCF exporter (``exporters.write_mjcf``) and its physics check (``layout.verify_scene``:
deepest penetration at t = 0 between different objects or an object and the floor / walls,
``settle_s`` (3 s) of simulation, a free body is stable when it moves < 1 cm and turns < 2 deg).
Render-and-compare (depth AbsRel, mask IoU) is ``verify_scene``'s too, against the perceived
masks and observed depth (real photos) or the true instances and clean depth (synthetic rooms).
Objects are scored in the ground truth's world frame, reached through the camera:
``truth_from_method = truth.world_from_camera @ inv(method.world_from_camera)``.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import os
import platform
import resource
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scene_builder import frames
from scene_builder.bench import metrics
from scene_builder.bench.baseline import naive_baseline
from scene_builder.config import BuildConfig, ExportConfig, InputSpec
from scene_builder.errors import InputError, SceneBuilderError
from scene_builder.model import (
    AssetKind,
    BackendUse,
    Camera,
    CameraIntrinsics,
    Fidelity,
    LayoutResult,
    Observation,
    PerceivedObject,
    Perception,
    PhysicsVerdict,
    Plane,
    Room,
    Scene,
)

__all__ = [
    "BenchResult",
    "MethodScores",
    "SceneResult",
    "Summary",
    "evaluate_baseline",
    "evaluate_sample",
    "oracle_perception",
    "print_result",
    "run_bench",
]

SUITES = ("synthetic", "real")
DEFAULT_REAL_DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "real"

DEFINITIONS = {
    "recall": "matched visible true objects / visible true objects (>= 150 visible pixels), pooled over scenes",
    "precision": "matched built objects / built objects, pooled over scenes with object ground truth",
    "matching": "Hungarian on mask IoU >= 0.25 between perceived masks and true instance masks (synthetic); on 3D centre distance gated at max(0.3 m, half the true box diagonal) (SUN RGB-D boxes)",
    "position_error_m": "distance between the centres of matched true and built bounding boxes, in the truth's world reached through the camera",
    "yaw_error_deg": "yaw difference modulo the true box's symmetry (180 deg, 90 deg for a square footprint)",
    "size_error_rel": "mean over the 3 axes of |built - true| / true extent, after matching horizontal axes",
    "mass_error_rel": "|built - true| / true mass (procedural rooms: density x primitive volume)",
    "box_iou_3d": "exact IoU of gravity-aligned yawed boxes (footprint polygon overlap x height overlap)",
    "max_penetration_m": "per scene: deepest contact between different objects or an object and the floor/walls at t = 0 (layout.verify_scene on the exported MJCF); summary: median over scenes (worst in max_penetration_m_worst)",
    "stable_fraction": "free objects that move < 1 cm and rotate < 2 deg over 3 s of simulation (soft bodies: centroid within their sag allowance) / free objects, pooled over scenes (layout.verify_scene)",
    "depth_absrel": "per scene: mean |rendered - reference| / reference depth over every pixel with valid reference depth (isolated outliers, more than 10 % off their 5x5 median, excluded; a pixel where the render hits nothing counts as error 1), rendered from input_camera by layout.verify_scene at t = 0 and after settling (clean depth for synthetic rooms; observed depth for real photos); summary: median over scenes",
    "max_penetration_settled_m": "per scene: deepest overlap over every pair of collision geoms of different bodies (objects, fixed furniture, floor, walls, static background), measured with mj_geomDistance after 3 s of settling; summary: worst scene",
    "psnr_db / ssim": "per scene: the input_camera render (the scene's own lights, t = 0) against the photo, scikit-image peak_signal_noise_ratio / structural_similarity on RGB; summary: median over scenes",
    "displacement_m": "per movable object: distance from its observed pose (generation's fit to its points) to its placed pose; pooled over objects (the baseline has none: it places its boxes where seen and does not fix anything)",
    "lowered / fixed / background objects": "objects the layout lowered more than 10 cm, fixed (built-in) objects (never counted as at rest), objects that could not stand where seen and became static background; totals over scenes",
    "mask_iou": "per movable object: IoU of the object's rendered (visible) silhouette and its true instance mask (synthetic, matched objects) or perceived mask (real); summary: median over objects",
    "seconds_per_scene": "wall-clock seconds of pipeline.build (pipeline) or of building the baseline's box assets and exporting its MJCF (baseline)",
    "peak_rss_mb": "resource.getrusage(RUSAGE_SELF).ru_maxrss of the bench process after the scene (MiB)",
}


# --------------------------------------------------------------------------------------------
# Inputs made from ground truth, and the baseline scored like the pipeline
# --------------------------------------------------------------------------------------------


def oracle_perception(sample_dir: Path, clean_depth: bool = False) -> Perception:
    """A :class:`Perception` made from a procedural sample's ground truth: true instance masks,
    the sample's depth (``clean_depth``: the noise-free depth where the sample has one), the true
    camera pose and walls. For testing the baseline and the scoring without the perception stage,
    and as the reference that scenes are rendered against in the synthetic suite."""
    from PIL import Image

    sample_dir = Path(sample_dir)
    meta = json.loads((sample_dir / "meta.json").read_text())
    gt = meta.get("ground_truth") or {}
    if gt.get("objects") is None or not gt.get("instances"):
        raise InputError(f"{sample_dir} has no instance ground truth (a procedural room sample is needed)")
    s = _sample(sample_dir)
    rgb = np.asarray(Image.open(s.rgb).convert("RGB"))
    depth_file = sample_dir / gt["metric_depth"] if clean_depth and gt.get("metric_depth") else s.depth
    depth = np.asarray(Image.open(depth_file)).astype(np.float32) / 1000.0
    c = json.loads((sample_dir / "camera.json").read_text())
    k = CameraIntrinsics(c["fx"], c["fy"], c["cx"], c["cy"], c["width"], c["height"], "file")
    cam = Camera(k, np.array(gt["camera"]["world_from_camera"], dtype=np.float64))
    inst = np.asarray(Image.open(sample_dir / gt["instances"]))
    pts = frames.transform_points(cam.world_from_camera, k.unproject(depth).reshape(-1, 3)).reshape(depth.shape + (3,))
    objects = []
    for o in gt["objects"]:
        mask = inst == o["object_id"]
        valid = mask & (depth > 0)
        if not valid.any():
            continue
        objects.append(PerceivedObject(o["object_id"], o["name"], o["category"], 1.0, mask, pts[valid], rgb[valid]))
    walls = tuple(Plane(np.array(w["normal"], dtype=np.float64), float(w["offset_m"]), "wall") for w in gt["walls"])
    obs = Observation(str(s.rgb), rgb, depth, k, "sensor")
    return Perception(obs, cam, Room(walls), tuple(objects), (BackendUse("segmentation", "oracle", "ground-truth instances"),))


def evaluate_baseline(perception: Perception, truth, work_dir: Path, config: BuildConfig, reference: Perception | None = None) -> MethodScores:
    """Build the naive baseline on a perception (the pipeline's, or an oracle), export it with
    ``exporters.write_mjcf`` and score it with ``layout.verify_scene``, as the pipeline is.
    reference: what to render-and-compare against (default: ``perception``)."""
    from exporters import write_mjcf

    t0 = time.perf_counter()
    scene = naive_baseline(perception, config.perception.max_depth_m)
    path = write_mjcf(scene, Path(work_dir))
    seconds = time.perf_counter() - t0
    return _score_scene(scene, path, None, perception, truth, config, seconds, reference)


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MethodScores:
    """One method on one scene. Object scores are None where the scene has no object truth."""

    objects: metrics.ObjectScores | None
    max_penetration_m: float
    max_drift_m: float
    n_free: int
    n_stable: int
    depth_absrel: float | None
    mask_iou: tuple[float, ...]
    seconds: float
    pipeline_verdict: dict | None = None
    psnr_db: float | None = None
    ssim: float | None = None
    depth_absrel_settled: float | None = None
    max_penetration_settled_m: float | None = None
    displacement_m: tuple[float, ...] | None = None
    n_fixed: int = 0
    n_background: int = 0
    n_lowered_10cm: int = 0


@dataclass(frozen=True)
class SceneResult:
    """One scene: inputs, both methods' scores, timings (pipeline stages) and memory."""

    name: str
    path: str
    n_true: int | None
    n_perceived: int | None
    depth_noise: bool
    pipeline: MethodScores | None
    baseline: MethodScores | None
    stage_seconds: tuple[tuple[str, float], ...]
    peak_rss_mb: float
    error: str | None = None


@dataclass(frozen=True)
class Summary:
    """Aggregates over the scenes of a suite (see ``DEFINITIONS``); None where nothing to score."""

    scenes: int
    failed_scenes: int
    recall: float | None
    precision: float | None
    position_error_m_median: float | None
    position_error_m_p90: float | None
    yaw_error_deg_median: float | None
    size_error_rel_median: float | None
    category_accuracy: float | None
    mass_error_rel_median: float | None
    box_iou_3d_median: float | None
    max_penetration_m: float | None
    max_penetration_m_worst: float | None
    stable_fraction: float | None
    depth_absrel_median: float | None
    mask_iou_median: float | None
    seconds_per_scene_median: float | None
    stage_seconds_median: dict[str, float] | None = None
    peak_rss_mb: float | None = None
    psnr_db_median: float | None = None
    ssim_median: float | None = None
    depth_absrel_settled_median: float | None = None
    depth_absrel_worst: float | None = None
    max_penetration_settled_m_worst: float | None = None
    displacement_m_median: float | None = None
    displacement_m_max: float | None = None
    fixed_objects: int | None = None
    background_objects: int | None = None
    lowered_10cm_objects: int | None = None


@dataclass(frozen=True)
class BenchResult:
    suite: str
    summary: Summary
    baseline: Summary
    scenes: tuple[SceneResult, ...]
    machine: dict
    date: str
    command: str
    out_json: Path

    def to_json(self) -> dict:
        def clean(v):
            if isinstance(v, float):
                return v if np.isfinite(v) else None
            if isinstance(v, dict):
                return {k: clean(x) for k, x in v.items()}
            if isinstance(v, (list, tuple)):
                return [clean(x) for x in v]
            if isinstance(v, Path):
                return str(v)
            return v

        d = dataclasses.asdict(self)
        d["out_json"] = str(self.out_json)
        d["definitions"] = DEFINITIONS
        return clean(d)


def summarize(scenes: list[SceneResult] | tuple[SceneResult, ...], which: str) -> Summary:
    """Aggregate ``which`` (``"pipeline"`` or ``"baseline"``) over the scenes (see DEFINITIONS)."""
    ms = [getattr(s, which) for s in scenes if getattr(s, which) is not None]
    objs = [m.objects for m in ms if m.objects is not None]
    n_vis = sum(o.n_true_visible for o in objs)
    n_pred = sum(o.n_pred for o in objs)
    matched_vis = sum(o.n_matched_visible for o in objs)
    matched_pred = sum(len(o.pairs) for o in objs)
    pool = lambda attr: [x for o in objs for x in getattr(o, attr)]  # noqa: E731
    cat = [(o.category_accuracy, len(o.pairs)) for o in objs if o.category_accuracy is not None]
    n_free = sum(m.n_free for m in ms)
    pens = [m.max_penetration_m for m in ms]
    disp = [x for m in ms if m.displacement_m is not None for x in m.displacement_m]
    stages: dict[str, list[float]] = {}
    if which == "pipeline":
        for s in scenes:
            for k, v in s.stage_seconds:
                stages.setdefault(k, []).append(v)
    return Summary(
        scenes=len(scenes),
        failed_scenes=sum(1 for s in scenes if s.error is not None),
        recall=matched_vis / n_vis if n_vis else None,
        precision=matched_pred / n_pred if n_pred else None,
        position_error_m_median=metrics.median_or_none(pool("position_error_m")),
        position_error_m_p90=metrics.p90_or_none(pool("position_error_m")),
        yaw_error_deg_median=metrics.median_or_none(pool("yaw_error_deg")),
        size_error_rel_median=metrics.median_or_none(pool("size_error_rel")),
        category_accuracy=sum(a * n for a, n in cat) / sum(n for _, n in cat) if cat and sum(n for _, n in cat) else None,
        mass_error_rel_median=metrics.median_or_none(pool("mass_error_rel")),
        box_iou_3d_median=metrics.median_or_none(pool("box_iou")),
        max_penetration_m=metrics.median_or_none(pens),
        max_penetration_m_worst=max(pens) if pens else None,
        stable_fraction=sum(m.n_stable for m in ms) / n_free if n_free else None,
        depth_absrel_median=metrics.median_or_none([m.depth_absrel for m in ms]),
        mask_iou_median=metrics.median_or_none([x for m in ms for x in m.mask_iou]),
        seconds_per_scene_median=metrics.median_or_none([m.seconds for m in ms]),
        stage_seconds_median={k: float(np.median(v)) for k, v in stages.items()} or None,
        peak_rss_mb=max((s.peak_rss_mb for s in scenes), default=None),
        psnr_db_median=metrics.median_or_none([m.psnr_db for m in ms]),
        ssim_median=metrics.median_or_none([m.ssim for m in ms]),
        depth_absrel_settled_median=metrics.median_or_none([m.depth_absrel_settled for m in ms]),
        depth_absrel_worst=max((m.depth_absrel for m in ms if m.depth_absrel is not None), default=None),
        max_penetration_settled_m_worst=max((m.max_penetration_settled_m for m in ms if m.max_penetration_settled_m is not None), default=None),
        displacement_m_median=metrics.median_or_none(disp),
        displacement_m_max=max(disp) if disp else None,
        fixed_objects=sum(m.n_fixed for m in ms) if ms else None,
        background_objects=sum(m.n_background for m in ms) if ms else None,
        lowered_10cm_objects=sum(m.n_lowered_10cm for m in ms) if ms else None,
    )


# --------------------------------------------------------------------------------------------
# Evaluating one scene
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Sample:
    name: str
    path: Path
    rgb: Path
    depth: Path
    intrinsics: tuple[float, float, float, float] | None
    noisy: bool


def _sample(path: Path) -> _Sample:
    rgb = path / "rgb.png" if (path / "rgb.png").exists() else path / "rgb.jpg"
    if not rgb.exists() or not (path / "depth.png").exists():
        raise InputError(f"{path} is not a sample folder (needs rgb.png or rgb.jpg and depth.png)")
    k = None
    if (path / "camera.json").exists():
        c = json.loads((path / "camera.json").read_text())
        k = (float(c["fx"]), float(c["fy"]), float(c["cx"]), float(c["cy"]))
    noisy = False
    if (path / "meta.json").exists():
        noisy = json.loads((path / "meta.json").read_text()).get("depth_noise") is not None
    return _Sample(path.name, path, rgb, path / "depth.png", k, noisy)


def _n_stable(scene: Scene, verdict: PhysicsVerdict, config: BuildConfig) -> tuple[int, int]:
    """(free objects, stable ones) by ``layout.verify_scene``'s criteria: a rigid body within
    ``stable_drift_m`` and ``stable_rotation_deg``; a soft body's centroid within its sag allowance."""
    from layout.verify import DEFORMABLE_SAG_FRACTION

    lay = config.layout
    tracked = {t.name for t in verdict.trajectories}
    n_free = n_stable = 0
    for v in verdict.objects:
        if v.name not in tracked:
            continue  # fixed furniture
        n_free += 1
        asset = scene.object(v.name).asset
        if asset.kind is AssetKind.DEFORMABLE:
            n_stable += v.drift_m <= max(lay.stable_drift_m, DEFORMABLE_SAG_FRACTION * float(asset.size_m[2]))
        else:
            n_stable += v.drift_m <= lay.stable_drift_m and v.rotation_deg <= lay.stable_rotation_deg
    return n_free, n_stable


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def _score_scene(
    scene: Scene,
    mjcf: Path,
    checked: tuple[PhysicsVerdict, Fidelity | None] | None,
    perception: Perception,
    truth,
    config: BuildConfig,
    seconds: float,
    reference: Perception | None = None,
    verdict_json: dict | None = None,
    layout: LayoutResult | None = None,
) -> MethodScores:
    """Score one method's scene: boxes against the truth, physics and render-and-compare by
    ``layout.verify_scene`` on its exported MJCF (``checked``: a verdict already measured on that
    MJCF with ``perception``, e.g. the pipeline's own). Render-and-compare is against
    ``reference`` when given (the ground truth's masks and clean depth), else ``perception``
    (the perceived masks and observed depth)."""
    from layout import verify_scene

    pred: list[metrics.ObjectBox] = []
    if truth is not None:
        pred = metrics.scene_boxes(scene, truth.world_from_camera @ np.linalg.inv(scene.camera.world_from_camera))
    match = _match(pred, perception, truth)
    obj_scores = metrics.score_objects(pred, truth.objects, match, truth.synonyms) if truth is not None and match is not None else None
    verdict, fidelity = checked if checked is not None else verify_scene(mjcf, scene, config.layout, perception)
    ious: tuple[float, ...]
    if reference is not None:
        # The truth's instances renamed after the method's objects they matched; unmatched true
        # objects keep their own names (they count in the depth region, not in the IoUs).
        renamed = dict((t, p) for p, t in obj_scores.pairs) if obj_scores else {}
        ref = dataclasses.replace(reference, objects=tuple(dataclasses.replace(o, name=renamed.get(o.name, f"~{o.name}")) for o in reference.objects))
        _, fidelity = verify_scene(mjcf, scene, dataclasses.replace(config.layout, settle_s=0.0), ref)
        ious = tuple(v for n, v in fidelity.mask_iou if not n.startswith("~"))
    else:
        ious = tuple(v for _, v in fidelity.mask_iou)
    n_free, n_stable = _n_stable(scene, verdict, config)
    placements = layout.placements if layout is not None else ()
    return MethodScores(
        obj_scores, verdict.max_penetration_m, verdict.settle_max_drift_m, n_free, n_stable, _finite_or_none(fidelity.depth_absrel), ious, seconds, verdict_json,
        psnr_db=_finite_or_none(fidelity.psnr_db),
        ssim=_finite_or_none(fidelity.ssim),
        depth_absrel_settled=_finite_or_none(fidelity.depth_absrel_settled),
        max_penetration_settled_m=float(verdict.max_penetration_settled_m),
        displacement_m=tuple(float(p.displacement_m) for p in placements if not p.became_background) if layout is not None else None,
        n_fixed=verdict.fixed_count,
        n_background=sum(1 for p in placements if p.became_background),
        n_lowered_10cm=sum(1 for p in placements if p.lowered_m > 0.10),
    )


def _match(pred: list[metrics.ObjectBox], perception: Perception, truth) -> metrics.Match | None:
    if truth is None:
        return None
    if truth.instances is not None and truth.instances.shape == perception.observation.depth_m.shape:
        # Masks are shared by both methods: match perceived objects to true instances once, then
        # map to each method's objects by name (a method may drop objects).
        masks = [o.mask for o in perception.objects]
        m = metrics.match_by_mask_iou(metrics.mask_iou_matrix(masks, truth.instances, truth.object_ids))
        pos = {p.name: i for i, p in enumerate(pred)}
        pairs = [(pos[perception.objects[i].name], j) for i, j in m.pairs if perception.objects[i].name in pos]
        scores = [s for (i, _), s in zip(m.pairs, m.scores) if perception.objects[i].name in pos]
        return metrics.Match(tuple(pairs), tuple(scores))
    return metrics.match_by_center(np.array([p.box.center_m for p in pred]).reshape(-1, 3), [t.box for t in truth.objects])


def evaluate_sample(sample_dir: Path, work_dir: Path, config: BuildConfig) -> SceneResult:
    """Build one sample with the pipeline and the baseline and score both."""
    from scene_builder.pipeline import build
    from scene_builder.bench.truth import load_truth

    s = _sample(Path(sample_dir))
    truth = load_truth(s.path)
    inputs = InputSpec(s.rgb, s.depth, 0.001, s.intrinsics)
    work_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    result = build(inputs, work_dir / s.name, config)
    t_pipe = time.perf_counter() - t0
    perception = result.perception
    reference = oracle_perception(s.path, clean_depth=True) if truth is not None and truth.instances is not None else None

    v = result.verdict
    verdict = {"max_penetration_m": v.max_penetration_m, "settle_max_drift_m": v.settle_max_drift_m, "stable": v.stable}
    pipe = _score_scene(result.scene, result.files.mjcf, (result.verdict, result.fidelity), perception, truth, config, t_pipe, reference, verdict, result.layout)
    bl = evaluate_baseline(perception, truth, work_dir / f"{s.name}_baseline", config, reference)
    return SceneResult(
        name=s.name,
        path=str(s.path),
        n_true=len(truth.objects) if truth is not None else None,
        n_perceived=len(perception.objects),
        depth_noise=s.noisy,
        pipeline=pipe,
        baseline=bl,
        stage_seconds=tuple((k, float(x)) for k, x in result.timings_s),
        peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
    )


# --------------------------------------------------------------------------------------------
# run_bench
# --------------------------------------------------------------------------------------------


def machine_description() -> dict:
    """CPU model, core count, memory, OS, Python and key library versions."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem_gb = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                mem_gb = round(int(line.split()[1]) / 1024 / 1024, 1)
    except OSError:
        pass
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count()
    import mujoco

    return {
        "cpu": cpu,
        "cores": cores,
        "memory_gb": mem_gb,
        "os": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "mujoco": mujoco.__version__,
        "gpu": None,
        # Timings depend on what else runs: the 1-minute load average when the description was taken.
        "load_avg_1m": round(os.getloadavg()[0], 1),
    }


def _suite_samples(suite: str, rooms: int, data_dir: Path | None, seed: int, tmp: Path, n_objects: int | None = None) -> list[Path]:
    if suite == "synthetic":
        from scene_builder.bench.procedural import make_room
        from scene_builder.bench.render import render_room

        if rooms < 1:
            raise InputError(f"--rooms must be at least 1, got {rooms}")
        out = []
        for i in range(rooms):
            s = seed + i
            spec = make_room(s, n_objects=n_objects or 5 + s % 4, noise=i % 2 == 1)
            out.append(render_room(spec, tmp / "rooms" / spec.name))
        return out
    if suite == "real":
        root = Path(data_dir) if data_dir is not None else DEFAULT_REAL_DATA
        if not root.is_dir():
            raise InputError(f"real data folder {root} not found; pass --data with a folder of samples (rgb + depth.png)")
        samples = sorted(d for d in root.iterdir() if d.is_dir() and (d / "depth.png").exists())
        if not samples and (root / "depth.png").exists():
            samples = [root]
        if not samples:
            raise InputError(f"no samples with depth.png under {root}; pass --data with a folder of samples")
        return samples
    raise InputError(f"unknown suite '{suite}'; choose one of: {', '.join(SUITES)}")


def run_bench(
    suite: str,
    rooms: int,
    data_dir: Path | None,
    out_json: Path,
    seed: int = 0,
    config: BuildConfig | None = None,
    console=None,
    keep_dir: Path | None = None,
    n_objects: int | None = None,
) -> BenchResult:
    """Run a suite, write ``out_json`` and print a table; returns the result.

    A scene on which the pipeline raises is recorded with its error (and counted in
    ``failed_scenes``) and the suite goes on: one failing photo must not hide the other numbers.
    config: build settings (default: seed ``seed``, no rerun recording). keep_dir: keep every
    scene's outputs there (default: a temporary folder, removed at the end). n_objects: objects
    per procedural room (default 5 to 8, varying with the seed).
    """
    from rich.console import Console

    console = console or Console(stderr=True, highlight=False)
    config = config or BuildConfig(seed=seed, export=ExportConfig(viz="off"))
    out_json = Path(out_json)
    command = f"scene-builder bench --suite {suite}" + (f" --rooms {rooms}" if suite == "synthetic" else "") + (f" --data {data_dir}" if data_dir else "") + f" --json {out_json} --seed {seed}"
    if os.environ.get("SCENE_BUILDER_MODELS"):  # the models dir changes which backends answer
        command = f"SCENE_BUILDER_MODELS={os.environ['SCENE_BUILDER_MODELS']} {command}"
    tmp = Path(tempfile.mkdtemp(prefix="scene-builder-bench-")) if keep_dir is None else Path(keep_dir)
    tmp.mkdir(parents=True, exist_ok=True)
    scenes: list[SceneResult] = []
    try:
        samples = _suite_samples(suite, rooms, data_dir, seed, tmp, n_objects)
        for i, sample in enumerate(samples):
            t0 = time.perf_counter()
            try:
                res = evaluate_sample(sample, tmp / "builds", config)
            except SceneBuilderError as err:  # a sample the pipeline refuses: recorded in the results and the table
                res = SceneResult(sample.name, str(sample), None, None, False, None, None, (), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, f"{type(err).__name__}: {err}")
            scenes.append(res)
            console.print(_scene_line(i + 1, len(samples), res, time.perf_counter() - t0))
    finally:
        if keep_dir is None:
            shutil.rmtree(tmp, ignore_errors=True)
    result = BenchResult(
        suite=suite,
        summary=summarize(scenes, "pipeline"),
        baseline=summarize(scenes, "baseline"),
        scenes=tuple(scenes),
        machine=machine_description(),
        date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        command=command,
        out_json=out_json,
    )
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(result.to_json(), indent=1) + "\n")
    print_result(result, console)
    return result


def _scene_line(i: int, n: int, r: SceneResult, seconds: float) -> str:
    if r.error is not None:
        return f"[red]✗[/red] {i}/{n} {r.name}: {r.error}"
    p, b = r.pipeline, r.baseline
    rec = "" if p.objects is None or p.objects.recall is None else f"recall {p.objects.recall:.2f}, "
    return (
        f"[green]✓[/green] {i}/{n} {r.name}: {r.n_perceived} objects, {rec}penetration {p.max_penetration_m * 1000:.1f} mm "
        f"(baseline {b.max_penetration_m * 1000:.0f} mm), stable {p.n_stable}/{p.n_free} (baseline {b.n_stable}/{b.n_free}), {seconds:.1f} s"
    )


SUMMARY_ROWS = (
    ("recall", "recall", "{:.2f}"),
    ("precision", "precision", "{:.2f}"),
    ("position error median (m)", "position_error_m_median", "{:.3f}"),
    ("position error p90 (m)", "position_error_m_p90", "{:.3f}"),
    ("yaw error median (deg)", "yaw_error_deg_median", "{:.1f}"),
    ("size error median (rel)", "size_error_rel_median", "{:.2f}"),
    ("3D box IoU median", "box_iou_3d_median", "{:.2f}"),
    ("category accuracy", "category_accuracy", "{:.2f}"),
    ("mass error median (rel)", "mass_error_rel_median", "{:.2f}"),
    ("max penetration, median scene (mm)", "max_penetration_m", "{:.1f}", 1000.0),
    ("max penetration, worst scene (mm)", "max_penetration_m_worst", "{:.1f}", 1000.0),
    ("stable fraction (3 s)", "stable_fraction", "{:.2f}"),
    ("max penetration after settling, worst scene (mm)", "max_penetration_settled_m_worst", "{:.1f}", 1000.0),
    ("render vs photo PSNR median (dB)", "psnr_db_median", "{:.1f}"),
    ("render vs photo SSIM median", "ssim_median", "{:.2f}"),
    ("depth AbsRel median (t = 0)", "depth_absrel_median", "{:.3f}"),
    ("depth AbsRel median (after settling)", "depth_absrel_settled_median", "{:.3f}"),
    ("depth AbsRel, worst scene", "depth_absrel_worst", "{:.3f}"),
    ("mask IoU median", "mask_iou_median", "{:.2f}"),
    ("displacement from where seen, median (m)", "displacement_m_median", "{:.3f}"),
    ("displacement from where seen, max (m)", "displacement_m_max", "{:.3f}"),
    ("objects lowered > 10 cm", "lowered_10cm_objects", "{:d}"),
    ("fixed objects", "fixed_objects", "{:d}"),
    ("objects turned into background", "background_objects", "{:d}"),
    ("seconds per scene median", "seconds_per_scene_median", "{:.2f}"),
)


def format_value(summary: dict | Summary, row: tuple) -> str:
    """One cell of the summary table ('-' where there is nothing to report)."""
    key, fmt = row[1], row[2]
    v = summary.get(key) if isinstance(summary, dict) else getattr(summary, key)
    if v is None:
        return "-"
    return fmt.format(v * row[3]) if len(row) > 3 else fmt.format(v)


def print_result(result: BenchResult, console=None) -> None:
    """The pipeline-versus-baseline table of a bench result, printed with rich."""
    from rich.console import Console
    from rich.table import Table

    console = console or Console(highlight=False)
    t = Table(title=f"scene-builder bench --suite {result.suite}: {result.summary.scenes} scenes ({result.summary.failed_scenes} failed)")
    t.add_column("metric")
    t.add_column("pipeline", justify="right")
    t.add_column("naive baseline", justify="right")
    for row in SUMMARY_ROWS:
        t.add_row(row[0], format_value(result.summary, row), format_value(result.baseline, row))
    console.print(t)
    if result.summary.stage_seconds_median:
        console.print("median seconds per stage: " + ", ".join(f"{k} {v:.2f}" for k, v in result.summary.stage_seconds_median.items()))
    console.print(f"peak memory {result.summary.peak_rss_mb or 0:.0f} MiB; results in {result.out_json}")


def run_meta(module: str, argv: list[str] | None) -> dict:
    """When, where and with what a bench's figures were measured: UTC date, short commit, the
    command (``python -m MODULE ARGS``), the machine in words and the 1-minute load average."""
    import subprocess

    repo = Path(__file__).resolve().parents[2]
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=repo, capture_output=True, text=True, timeout=10).stdout.strip()
    except OSError:
        commit = ""
    m = machine_description()
    args = " ".join(sys.argv[1:] if argv is None else argv)
    return {
        "date": datetime.datetime.now(datetime.timezone.utc).date().isoformat(),
        "commit": commit or "?",
        "command": f"python -m {module} {args}".strip(),
        "machine": f"{m['cpu'].split()[0]} CPU, {m['cores']} cores, {m['memory_gb']} GB, no GPU",
        "load": f"{os.getloadavg()[0]:.1f}",
    }
