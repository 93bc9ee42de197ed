"""End to end on real RGB-D photos: every output is written, MuJoCo loads and steps the MJCF, the
USD validates, and the physics verdict meets the product's bar (issue 4): no penetration at
t = 0 beyond 1 mm, and every object at rest after 3 s (within 1 cm and 2 deg)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from .conftest import real_sample_params, real_samples

SAMPLES = real_samples(with_intrinsics=True)


@pytest.mark.slow
@pytest.mark.skipif(not SAMPLES, reason="no real RGB-D samples with intrinsics in ../shared/data/real")
@pytest.mark.parametrize("sample", real_sample_params(with_intrinsics=True))
def test_real_sample_builds_a_valid_stable_scene(sample: Path, built_real_sample):
    import mujoco
    from pxr import Usd, UsdValidation

    result = built_real_sample(sample)
    out = result.out_dir
    for name in ("scene.xml", "scene.usda", "scene.json", "report.json", "scene.sdf", "urdf/placements.json", "scene.glb"):
        assert (out / name).is_file(), name
    model = mujoco.MjModel.from_xml_path(str(out / "scene.xml"))
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data, nstep=50)
    assert np.all(np.isfinite(data.qpos))

    stage = Usd.Stage.Open(str(out / "scene.usda"))
    assert stage is not None
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    errors = [e for e in context.Validate(stage) if e.GetType() == UsdValidation.ValidationErrorType.Error]
    assert not errors, [e.GetMessage() for e in errors[:3]]

    report = json.loads((out / "report.json").read_text())
    assert report["objects"], "no objects"
    assert report["layout"]["max_penetration_m"] < 0.001
    assert result.verdict.stable, [(o.name, o.drift_m, o.rotation_deg) for o in result.verdict.objects if o.drift_m > 0.01 or o.rotation_deg > 2]
    assert report["layout"]["settle_max_drift_m"] < 0.01
    assert result.verdict.max_penetration_m == pytest.approx(report["layout"]["max_penetration_m"], abs=1e-6)
    for obj in report["objects"]:
        if not obj["became_background"]:
            assert obj["mass_kg"] > 0 and min(obj["size_m"]) > 0
        else:
            assert obj["moved_because"], obj


def _sun_box_samples() -> list:
    """The real samples whose meta.json carries SUN RGB-D's annotated 3D boxes."""
    return [p for p in real_sample_params(with_intrinsics=True) if (json.loads((p.values[0] / "meta.json").read_text()).get("ground_truth") or {}).get("boxes_3d")]


@pytest.mark.slow
@pytest.mark.parametrize("sample", _sun_box_samples())
def test_sun_sample_bed_is_one_object_named_bed_in_its_true_box(sample: Path, built_real_sample):
    """Every SUN RGB-D sample with boxes shows a bed: its annotated 3D box is matched (IoU >= 0.25,
    the ground-truth bench's rule) by one interactive object named bed, and no other interactive
    object of the seat-or-bed family overlaps that box (sunrgbd_000017's sleigh bed was a "sofa"
    frame beside a "bed" mattress before the fragments were merged)."""
    from scene_builder.bench.groundtruth import interactive_names, score_boxes, sun_boxes, sun_gt_from_world
    from scene_builder.bench.metrics import box_iou_3d, scene_boxes

    scene = built_real_sample(sample).scene
    true, rtilt = sun_boxes(sample)
    beds = [t for t in true if t.label == "bed"]
    assert len(beds) == 1
    inter = set(interactive_names(scene))
    pred = [b for b in scene_boxes(scene, sun_gt_from_world(scene.camera.world_from_camera, rtilt)) if b.name in inter]
    score = score_boxes(pred, beds)
    assert score.matched == 1 and score.matched_label == 1, (score.pairs, [(p.name, round(box_iou_3d(p.box, beds[0].box), 2)) for p in pred])
    seats = [p.name for p in pred if p.label in ("bed", "sofa", "bench") and box_iou_3d(p.box, beds[0].box) > 0.05]
    assert len(seats) == 1, seats


_ARKIT = [s for s in real_samples(with_intrinsics=False) if s.name == "promptda_arkit"]


@pytest.mark.slow
@pytest.mark.skipif(not _ARKIT, reason="no ../shared/data/real/promptda_arkit (an error under CI=true)")
def test_an_open_bookcase_holds_its_books_on_boards_where_they_were_seen(tmp_path):
    """promptda_arkit (ARKit LiDAR depth): a wall of open cubbies with rows of books. The cubbies
    are openings (measured 7-33 cm behind the face), not 16 doors and drawers; the bookcase is a
    frame with boards under the rows of books, and the books rest on them as interactive objects
    (before: 24 of its 30 perceived objects were static background, "nothing seen under it" or
    "what is under it is another object's"; then 7, five of them books toppling)."""
    from scene_builder.config import BuildConfig, ExportConfig, InputSpec
    from scene_builder.pipeline import build

    src = _ARKIT[0]
    result = build(InputSpec(src / "rgb.jpg", src / "depth.png"), tmp_path / "out",
                   BuildConfig(export=ExportConfig(viz="off", usd=False, urdf=False, gltf=False, sdf=False)))
    (shelf,) = [o.asset for o in result.scene.objects if o.asset.label == "shelf"]
    from scene_builder.model import JointType

    moving = [q.name for q in shelf.parts if q.joint is not None and q.joint.type is not JointType.FIXED]
    assert not moving and "boards under what it holds" in shelf.description, (moving, shelf.description)
    on_shelf = [p for p in result.layout.placements if p.support == shelf.name and not p.became_background]
    assert len(on_shelf) >= 15, [(p.name, p.reason) for p in result.layout.placements]
    assert result.verdict.max_penetration_m < 1e-3 and result.verdict.stable
    # Measured: 1 of 30 background (a bottle with another's pad under it). Each book is whole
    # (a shelf's column does not carve what stands in it; carved, 5 toppled) and the pushes end
    # clear (two stacked books overlapping 15 mm were cut apart; before, 3 more background).
    background = [p for p in result.layout.placements if p.became_background]
    assert len(background) <= 2, [(p.name, p.reason) for p in background]


@pytest.mark.slow
@pytest.mark.parametrize("sample", [p for p in real_sample_params(with_intrinsics=True) if p.values[0].name in ("sunrgbd_imvotenet_000004", "sunrgbd_imvotenet_000005")])
def test_beds_and_what_stands_at_their_foot_are_all_objects(sample: Path, built_real_sample):
    """sunrgbd_imvotenet_000004's ottoman at the bed's foot was part of the bed (perception's
    bed_foot cuts it out: a bench), and 000005's near bed, completed to a bed's proportions, grew
    over the bench at the far bed's foot (shape_prior.depth_to_others stops it there): the pair
    became background. Every perceived object is an object of the scene, each bed among them,
    000004's bench is one, and 000005's near bed has its headboard."""
    result = built_real_sample(sample)
    reasons = {p.name: p.reason for p in result.layout.placements}
    placed = {o.name for o in result.scene.objects}
    assert all(o.name in placed for o in result.perception.objects), {n: r for n, r in reasons.items() if n not in placed}
    assert any(o.label == "bed" for o in result.perception.objects)
    if sample.name == "sunrgbd_imvotenet_000004":
        assert any(o.label == "bench" for o in result.perception.objects)
    if sample.name == "sunrgbd_imvotenet_000005":
        # the near bed's leather headboard, 1-10 cm off the wall, is the bed's (perception's
        # headboard): the bed rises to its top, 1.44 m (the ground truth boxes it 1.59 m high),
        # where it ended at its mattress, 0.92 m
        bed = next(o for o in result.scene.objects if o.name == "bed_1")
        assert bed.asset.size_m[2] > 1.3
        assert any(b.task == "headboards" for b in result.perception.backends)
    assert result.verdict.stable


@pytest.mark.slow
@pytest.mark.parametrize("sample", [p for p in real_sample_params(with_intrinsics=True) if p.values[0].name in ("sunrgbd_imvotenet_000002", "sunrgbd_imvotenet_000004")])
def test_pillows_against_a_headboard_are_objects_resting_on_the_bed(sample: Path, built_real_sample):
    """A bed's completion rose in columns around the pillows seen against its headboard: no face
    of the bed lay under them and the pad under them reached into the bed, so each was left where
    seen as background (sunrgbd_imvotenet_000002's pillow_4, sunrgbd_imvotenet_000004's
    pillow_1). The layout cuts that pair apart where each was seen and builds the support graph
    again: every pillow is an object (resting on the bed, another pillow or the surface seen under
    it) and the scene is at rest. (sunrgbd_imvotenet_000005's second pillow, with nothing seen
    under it, is still background.)"""
    result = built_real_sample(sample)
    perceived = [o.name for o in result.perception.objects if o.label == "pillow"]
    assert perceived
    placed = {o.name for o in result.scene.objects}
    reasons = {p.name: p.reason for p in result.layout.placements}
    assert all(n in placed for n in perceived), {n: reasons[n] for n in perceived if n not in placed}
    assert result.verdict.stable
