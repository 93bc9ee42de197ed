"""Interaction probes (issues 15 and 26): a force-limited pusher that collides with everything
pushes a movable object a few centimetres while the others stay, or fails with the reason (no
room for it, blocked, too heavy for its 100 N); the doors and drawers of an articulated object
open along their joints under a pull and stay within their limits. On hand-built scenes (fast),
then on every movable object of every real RGB-D sample, and on built cabinet photos (slow).

The bar (the issue's words, written out here rather than read from the module under test): the
pushed object moves 2-10 cm horizontally and does not topple; every other free object moves less
than 1 cm (objects resting on the pushed one ride along and are reported apart); a pulled joint
opens at least half of its range, never goes back more than 1 deg / 2 mm while pulled, stays
within its range (2 deg / 5 mm) and its carcass moves less than 1 cm.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scene_builder.frames import pose
from scene_builder.model import AssetKind, PlacedObject, Scene

from .conftest import PHOTOS, real_sample_params, real_samples, require
from .fixtures_scenes import WOOD, box_asset, boxes_scene, cabinet_scene, fixture_camera, fixture_room, pillow_scene

SAMPLES = real_samples(with_intrinsics=True)
MOVE_M = (0.02, 0.10)
OTHERS_M = 0.01
LIMIT_TOL = {"hinge": np.radians(2.0), "slide": 0.005}
BACKTRACK_TOL = {"hinge": np.radians(1.0), "slide": 0.002}


def _mjcf(scene: Scene, out: Path) -> Path:
    from exporters.mjcf import write_mjcf

    return write_mjcf(scene, out)


def assert_good_push(r) -> None:
    assert r.pusher_travel_m > 0.05, f"{r.name}: the pusher touched it for only {r.pusher_travel_m * 100:.1f} cm"
    assert MOVE_M[0] <= r.displacement_m <= MOVE_M[1], f"{r.name} moved {r.displacement_m * 100:.1f} cm"
    assert r.along_m > 0.8 * r.displacement_m, f"{r.name} moved sideways: {r.along_m:.3f} of {r.displacement_m:.3f} m along the push"
    assert not r.toppled and r.tilt_deg < 10.0, f"{r.name} tilted {r.tilt_deg:.0f} deg"
    bad = [(n, round(v, 4)) for n, v in r.others if v >= OTHERS_M]
    assert not bad, f"pushing {r.name} moved others: {bad}"


def assert_good_opening(j) -> None:
    lo, hi = j.range
    assert j.open_fraction >= 0.5, f"{j.joint} opened only {j.open_fraction:.0%} of its range ({j.travel:.3f})"
    assert j.backtrack <= BACKTRACK_TOL[j.kind], f"{j.joint} went back {j.backtrack:.4f} while pulled"
    assert lo - LIMIT_TOL[j.kind] <= j.positions.min() and j.positions.max() <= hi + LIMIT_TOL[j.kind], (j.joint, j.positions.min(), j.positions.max(), j.range)
    assert j.limit_violation <= LIMIT_TOL[j.kind]
    assert j.body_displacement_m < 0.01, f"{j.object} moved {j.body_displacement_m * 100:.1f} cm while {j.joint} was pulled"


# --- hand-built scenes (fast) --------------------------------------------------------------


def test_push_moves_one_box_a_few_centimetres_and_the_others_stay(tmp_path):
    from layout.interaction import PUSH_TRAVEL_M, push_object

    r = push_object(_mjcf(boxes_scene(), tmp_path), "box_c")
    assert_good_push(r)
    # the paddle advanced PUSH_TRAVEL_M past contact: the box follows it to within 1.5 cm
    assert r.along_m == pytest.approx(PUSH_TRAVEL_M, abs=0.015)
    assert {n for n, _ in r.others} == {"box_a", "box_b"} and r.carried == ()


def test_what_rests_on_the_pushed_object_rides_along(tmp_path):
    from layout.interaction import push_object

    r = push_object(_mjcf(boxes_scene(), tmp_path), "box_a")  # box_b stands on box_a
    assert_good_push(r)
    assert [n for n, _ in r.carried] == ["box_b"] and [n for n, _ in r.others] == ["box_c"]
    (_, carried_m), = r.carried
    assert carried_m > 0.5 * r.displacement_m  # it went along, not left behind


def test_push_direction_has_room_ahead_and_a_push_into_a_wall_is_blocked(tmp_path):
    from layout.interaction import MIN_CLEARANCE_M, PUSHER_FORCE_N, interaction_problems, plan_push, push_object

    # a 40 cm box 2 cm in front of the back wall (x = 2), a fixed counter 6 cm beside it (+y): the
    # pusher (2 cm thick, starting 1 cm off) fits beside the counter, not between box and wall
    box = PlacedObject(box_asset("box", (0.4, 0.4, 0.3)), pose(np.eye(3), (2.0 - 0.22, 0.0, 0.0)), "floor")
    counter = PlacedObject(box_asset("counter", (0.6, 0.6, 0.9), is_fixed=True, label="counter"), pose(np.eye(3), (1.7, 0.56, 0.0)), "floor")
    path = _mjcf(Scene(fixture_camera(), fixture_room(), (box, counter)), tmp_path)
    (plan,) = plan_push(path)
    assert plan.pushable and plan.clearance_m >= MIN_CLEARANCE_M
    assert plan.direction_xy == pytest.approx((0.0, -1.0), abs=1e-6)  # along the wall, away from the counter
    assert_good_push(push_object(path, "box", plan.direction_xy))
    into_wall = push_object(path, "box", (1.0, 0.0))
    assert into_wall.clearance_m < 0.05 and into_wall.displacement_m < 0.03
    # the pusher pressed with its whole force and stopped short; the wall took the push
    assert into_wall.stalled and into_wall.max_force_n == pytest.approx(PUSHER_FORCE_N, rel=0.02)
    assert into_wall.resisted_by[0][0].startswith("wall_") and into_wall.resisted_by[0][1] > 0.5 * PUSHER_FORCE_N
    problems = interaction_problems((into_wall,))
    assert len(problems) == 1 and problems[0].startswith("push box: blocked by wall_"), problems
    # toward -x the pusher would have to stand in the 2 cm between the wall and the box
    behind_wall = push_object(path, "box", (-1.0, 0.0))
    assert behind_wall.pusher_travel_m == 0.0 and behind_wall.displacement_m == 0.0
    assert interaction_problems((behind_wall,)) == ("push box: no room for the pusher behind it: the paddle overlaps wall_0",) or \
        interaction_problems((behind_wall,))[0].startswith("push box: no room for the pusher behind it: the paddle overlaps wall_")


def test_an_object_too_heavy_for_the_force_limit_fails_and_a_stronger_pusher_moves_it(tmp_path):
    from layout.interaction import PUSHER_FORCE_N, interaction_problems, push_object

    # solid wood, 50 cm cube: 75 kg; sliding it on the floor takes about 75 x 9.81 x 0.5 N
    heavy = PlacedObject(box_asset("chest", (0.5, 0.5, 0.5), WOOD), pose(np.eye(3), (0.8, 0.0, 0.0)), "floor")
    path = _mjcf(Scene(fixture_camera(), fixture_room(), (heavy,)), tmp_path)
    weak = push_object(path, "chest", (0.0, 1.0))
    assert weak.mass_kg == pytest.approx(75.0, rel=0.01) and weak.slide_force_n > 2 * PUSHER_FORCE_N
    assert weak.stalled and weak.displacement_m < 0.005 and weak.max_force_n == pytest.approx(PUSHER_FORCE_N, rel=0.02)
    (problem,) = interaction_problems((weak,))
    assert problem.startswith(f"push chest: too heavy for {PUSHER_FORCE_N:.0f} N: sliding it takes about"), problem
    strong = push_object(path, "chest", (0.0, 1.0), force_n=2 * weak.slide_force_n)
    assert_good_push(strong)
    assert not strong.stalled and strong.max_force_n > weak.slide_force_n  # it took more than 100 N


def test_an_object_that_would_fall_off_its_support_is_not_pushable_and_says_why(tmp_path):
    from layout.interaction import plan_push

    # a 30 cm box on a 14 cm fixed pedestal: after a 6 cm push its centre of mass would be 1 cm
    # from the pedestal's edge (the plan asks for support 3 cm beyond the push)
    pedestal = PlacedObject(box_asset("pedestal", (0.14, 0.14, 0.5), is_fixed=True, label="counter"), pose(np.eye(3), (0.5, 0.0, 0.0)), "floor")
    box = PlacedObject(box_asset("box", (0.3, 0.3, 0.2)), pose(np.eye(3), (0.5, 0.0, 0.5)), "pedestal")
    (plan,) = plan_push(_mjcf(Scene(fixture_camera(), fixture_room(), (pedestal, box)), tmp_path))
    assert not plan.pushable and plan.reason.count("no support 9 cm ahead") == 4, plan.reason


def test_a_neighbour_just_beside_blocks_the_pusher_and_is_pushed_along(tmp_path):
    """Two boxes 5 mm apart: the pusher does not fit between them, so neither is pushed away
    from the other (the push fails: no room for the pusher); pushed toward the other, a box
    moves it too (a failure naming it); pushed along the gap on the line of its centre of mass,
    it leaves the other where it was. The planner forecasts all of it (no side is safe: along the
    gap a swerve would drag the other by friction)."""
    from layout.interaction import interaction_problems, plan_push, push_object

    a = PlacedObject(box_asset("box_a", (0.4, 0.4, 0.3)), pose(np.eye(3), (0.6, 0.0, 0.0)), "floor")
    b = PlacedObject(box_asset("box_b", (0.3, 0.3, 0.3)), pose(np.eye(3), (0.6, 0.2 + 0.005 + 0.15, 0.0)), "floor")
    path = _mjcf(Scene(fixture_camera(), fixture_room(), (a, b)), tmp_path)
    plans = {p.name: p for p in plan_push(path)}
    assert not plans["box_a"].pushable
    assert "toward its right (-y) 0 cm behind it for the pusher" in plans["box_a"].reason
    assert plans["box_a"].reason.count("would drag box_b") == 2
    away = push_object(path, "box_a", (0.0, -1.0))
    assert interaction_problems((away,)) == ("push box_a: no room for the pusher behind it: the paddle overlaps box_b",)
    assert away.displacement_m == 0.0 and away.max_other_m == 0.0
    into = push_object(path, "box_a", (0.0, 1.0))
    assert into.max_other_m > 0.02 and dict(into.others)["box_b"] == into.max_other_m
    assert [p for p in interaction_problems((into,)) if "box_b moved" in p], interaction_problems((into,))
    along = push_object(path, "box_a", plans["box_a"].direction_xy)
    assert_good_push(along)


@pytest.mark.slow  # a flex steps at about 1.5 ms here: two pushes take 6 s
def test_a_soft_body_is_pushed_and_rides_along_on_what_it_rests_on(tmp_path):
    """A soft pillow (a flex) on a box: both are movable and both are pushed. The pillow moves
    2-10 cm and the box stays; pushed, the box carries the pillow (it rests on the box: a rider,
    not another object) and the pillow stays on it."""
    from layout.interaction import interaction_problems, load_probe_model, plan_and_push

    # 300 N: the 18 kg cardboard box with the pillow on it slides at about 110 N
    plans, (box, pillow) = plan_and_push(load_probe_model(_mjcf(pillow_scene(), tmp_path)), force_n=300.0)
    assert [p.name for p in plans] == [box.name, pillow.name] == ["box_a", "pillow"]
    assert pillow.touched and MOVE_M[0] <= pillow.displacement_m <= MOVE_M[1] and pillow.along_m > 0.8 * pillow.displacement_m
    assert dict(pillow.others)["box_a"] < OTHERS_M and interaction_problems((pillow,)) == ()
    assert_good_push(box)
    (name, carried_m), = box.carried
    assert name == "pillow" and carried_m > 0.5 * box.displacement_m and dict(box.carried_drop)["pillow"] < 0.01


@pytest.mark.parametrize("fixed", [False, True], ids=["free", "fixed"])
def test_cabinet_door_and_drawer_open_along_their_joints_within_limits(tmp_path, fixed):
    from layout.interaction import joint_names, open_joint

    path = _mjcf(cabinet_scene(is_fixed=fixed), tmp_path)
    joints = joint_names(path)
    assert joints == ("cabinet/door/joint", "cabinet/drawer/joint")
    for name in joints:
        j = open_joint(path, name)
        assert_good_opening(j)
        assert j.open_sign == 1.0 and j.start == pytest.approx(0.0, abs=1e-3)
        # opened all the way: the pull holds it at the stop
        assert j.open_fraction > 0.95, (name, j.open_fraction)
        assert j.kind == ("hinge" if "door" in name else "slide")


def test_a_weak_pull_is_reported_as_not_opening(tmp_path):
    from layout.interaction import interaction_problems, open_joint

    path = _mjcf(cabinet_scene(), tmp_path)
    # below the drawer's joint friction (0.1 N) nothing moves
    j = open_joint(path, "cabinet/drawer/joint", force_n=0.05)
    assert j.travel < 0.01
    assert any(p.startswith("open cabinet/drawer/joint: opened") for p in interaction_problems(joints=(j,)))


def test_a_heavy_damped_drawer_is_pulled_as_hard_and_as_long_as_its_range_needs(tmp_path):
    """An oven-like drawer (12.5 kg, 6.4 N of dry friction, 60 N s/m of damping): a 10 N pull for
    3 s creeps it open; the default pull covers the damping at the speed that opens its range
    and lasts as long as the range takes at the hand's speed, and it opens fully."""
    import mujoco

    from layout.interaction import FULL_OPEN_FRACTION, open_joint

    m = mujoco.MjModel.from_xml_path(str(_mjcf(cabinet_scene(is_fixed=True), tmp_path)))
    jid = m.joint("cabinet/drawer/joint").id
    body, dof = int(m.jnt_bodyid[jid]), int(m.jnt_dofadr[jid])
    scale = 12.5 / float(m.body_mass[body])
    m.body_mass[body] *= scale
    m.body_inertia[body] *= scale
    m.dof_damping[dof], m.dof_frictionloss[dof] = 60.0, 6.4
    weak = open_joint(m, "cabinet/drawer/joint", force_n=10.0, pull_s=3.0)
    assert weak.open_fraction < 0.6
    j = open_joint(m, "cabinet/drawer/joint")
    assert j.force_n > 10.0 and j.open_fraction >= FULL_OPEN_FRACTION
    assert_good_opening(j)



def test_an_oven_door_opens_fully_without_slamming_into_its_stop(tmp_path):
    """The oven template's door, hinged at its bottom, welded oven on the floor, as exported:
    pulled open it travels its whole range without bouncing back off its stop (it did, 1.6
    degrees, before its hinge carried a counterbalance spring: coco128_000000000338), and the
    exported hinge carries the spring."""
    import mujoco

    from generation.articulation import articulated_parts
    from generation.assembly import assemble_asset
    from layout.interaction import FULL_OPEN_FRACTION, open_joint, opens_fully
    from scene_builder.frames import rot_z
    from scene_builder.vocabulary import category

    oven = assemble_asset("oven_1", "oven", articulated_parts("oven", category("oven").typical_size_m), is_fixed=True)
    scene = Scene(fixture_camera(), fixture_room(), (PlacedObject(oven, pose(rot_z(np.pi), (1.2, 0.0, 0.0)), "floor"),))
    path = _mjcf(scene, tmp_path)
    m = mujoco.MjModel.from_xml_path(str(path))
    assert float(m.jnt_stiffness[m.joint("oven_1/door/joint").id]) > 0.0
    j = open_joint(path, "oven_1/door/joint")
    assert j.open_fraction >= FULL_OPEN_FRACTION and opens_fully(j), j
    assert_good_opening(j)
    # control: the same door without its spring falls open onto its stop and bounces back
    m.jnt_stiffness[m.joint("oven_1/door/joint").id] = 0.0
    assert not opens_fully(open_joint(m, "oven_1/door/joint"))

def test_probes_refuse_unknown_names(tmp_path):
    from layout.interaction import open_joint, push_object
    from scene_builder.errors import InputError

    path = _mjcf(boxes_scene(), tmp_path)
    with pytest.raises(InputError, match="no free object 'nothing'"):
        push_object(path, "nothing")
    with pytest.raises(InputError, match="no joint 'box_a/lid/joint'"):
        open_joint(path, "box_a/lid/joint")
    with pytest.raises(InputError, match="does not exist"):
        push_object(tmp_path / "missing.xml", "box_a")


# --- built scenes (slow) --------------------------------------------------------------------


def assert_push_verdict_holds(r) -> None:
    """A push of a built scene either meets the bar (checked here against the bar written above,
    not the module's) or fails for a reason the measurements support."""
    from layout.interaction import PUSHER_FORCE_N, push_failures

    assert r.max_force_n <= PUSHER_FORCE_N * 1.001, f"{r.name}: the pusher exceeded its limit ({r.max_force_n:.0f} N)"
    failures = push_failures(r)
    passes = (r.touched and MOVE_M[0] <= r.displacement_m <= MOVE_M[1] and not r.toppled and r.tilt_deg <= 10.0
              and r.max_other_m < OTHERS_M)
    if not failures:
        assert passes, r
        return
    first = failures[0]
    if first.startswith("no room for the pusher"):
        assert not r.touched and r.displacement_m == 0.0 and r.max_force_n == 0.0, r
    elif first.startswith("too heavy"):
        assert r.stalled and r.displacement_m < MOVE_M[0] and r.slide_force_n >= 0.8 * PUSHER_FORCE_N, r
        assert r.max_force_n == pytest.approx(PUSHER_FORCE_N, rel=0.02), r
    elif first.startswith("blocked by"):
        assert r.stalled and r.displacement_m < MOVE_M[0] and first.startswith(f"blocked by {r.resisted_by[0][0]} "), (first, r)
    else:
        assert not passes or any("resting on it, fell" in f for f in failures), (failures, r)


def _check_built(out: Path, movable: set[str]) -> tuple[int, int]:
    """Both probes on a built scene, as `check --interact` runs them: every movable object
    pushed by the force-limited pusher (each push meets the bar or fails for a reason its
    measurements support), every articulation joint pulled open. Returns (pushes, joints)."""
    from layout.interaction import probe_scene

    plans, pushes, joints = probe_scene(out / "scene.xml")
    assert {r.name for r in pushes} == {p.name for p in plans} == movable  # every movable object, none skipped
    for r in pushes:
        assert_push_verdict_holds(r)
    for j in joints:
        assert_good_opening(j)
    return len(pushes), len(joints)


@pytest.mark.slow
@pytest.mark.skipif(not SAMPLES, reason="no real RGB-D samples with intrinsics in ../shared/data/real")
@pytest.mark.parametrize("sample", real_sample_params(with_intrinsics=True)[1::2])
def test_real_sample_push_and_open(sample, built_real_sample):
    """Every other real sample (none of them one test_robot builds with the Panda; built once per
    session, shared with test_end_to_end): every movable object pushed, every door and drawer
    pulled open. The probes take 35-150 s a sample on the CI machine; the interaction bench of
    BENCHMARKS.md probes all of them."""
    built = built_real_sample(sample)
    movable = {o.name for o in built.scene.objects if not o.asset.is_fixed}
    if not movable:
        pytest.skip(f"{sample.name}: the build has no movable object (all became background)")
    pushes, _ = _check_built(built.out_dir, movable)
    assert pushes == len(movable)


def _cabinet_photos() -> list[Path]:
    return sorted(require(PHOTOS).glob("urdformer_*"))


@pytest.mark.slow
@pytest.mark.parametrize("index", range(0, 10, 3))
def test_built_cabinet_photo_doors_and_drawers_open(index, tmp_path):
    """Every third cabinet photo (four builds of 11-20 s on the CI machine; the fronts bench of
    BENCHMARKS.md builds and probes all ten): an articulated object whose doors and drawers open."""
    from scene_builder.config import BuildConfig, ExportConfig, InputSpec
    from scene_builder.pipeline import build

    photos = _cabinet_photos()
    if index >= len(photos):
        pytest.skip(f"only {len(photos)} urdformer_* cabinet photos in {PHOTOS}")
    d = photos[index]
    result = build(InputSpec(next(d.glob("rgb.*"))), tmp_path / "out",
                   BuildConfig(export=ExportConfig(usd=False, urdf=False, gltf=False, viz="off")))
    # Every cabinet photo shows doors or drawers: a build without a moving part is a failure.
    why = "; ".join(f"{p.name}: {p.reason}" for p in result.layout.placements if p.became_background)
    assert any(o.asset.kind is AssetKind.ARTICULATED for o in result.scene.objects), f"{d.name}: the build has no articulated object ({why or 'none was generated'})"
    movable = {o.name for o in result.scene.objects if not o.asset.is_fixed}
    _, joints = _check_built(result.out_dir, movable)
    assert joints >= 1, f"{d.name}: no hinge or slide joint in the MJCF"


@pytest.mark.slow
@pytest.mark.parametrize("sample", [p for p in real_sample_params(with_intrinsics=True) if p.values[0].name == "nyuv2_metric3d_00000"])
def test_check_interact_prints_and_records_the_probes(sample, built_real_sample, capsys):
    """`check --interact` on a built real sample: one line per push with its verdict, the JSON
    record of every movable object's push with ok / failures and the summary, and exit status
    1 exactly when a probe fails (nyuv2_metric3d_00000 has objects too heavy for 100 N)."""
    import json

    from scene_builder.cli import main

    out = built_real_sample(sample).out_dir
    status = main(["check", str(out), "--interact"])
    printed = capsys.readouterr().out.splitlines()
    doc = json.loads((out / "interaction.json").read_text())
    assert status == (1 if doc["problems"] else 0)
    assert {r["name"] for r in doc["pushes"]} == {p["name"] for p in doc["push_plans"]}
    summary = doc["push_summary"]
    assert summary["movable"] == len(doc["pushes"]) == summary["succeeded"] + summary["failed"]
    assert summary["failed"] == sum(not r["ok"] for r in doc["pushes"]) and summary["failed"] >= 1
    for r in doc["pushes"]:
        line = next(x for x in printed if x.startswith(f"push {r['name']}: "))
        if r["ok"]:
            assert line.startswith(f"push {r['name']}: ok: moved {r['displacement_m'] * 100:.1f} cm"), line
        else:
            assert r["failures"] and line.startswith(f"push {r['name']}: FAILED: {'; '.join(r['failures'])}"), line
            assert all(f"push {r['name']}: {f}" in doc["problems"] for f in r["failures"])
    assert "interaction.json" in json.loads((out / ".scene-builder").read_text())["files"]
