"""What the pipeline does with objects that settled: re-seating against the support's motion and
with the neighbours they came to rest against (layout.repair), on scenes settled in MuJoCo."""

from __future__ import annotations

import numpy as np

from scene_builder.config import LayoutConfig
from scene_builder.frames import pose
from scene_builder.model import PhysicsVerdict, PlacedObject, Scene, Trajectory
from scene_builder.bench.clutter import box_asset
from tests.test_layout_verify import _scene, write_fixture_mjcf


def _on(name, size, xyz, support="floor") -> PlacedObject:
    return PlacedObject(box_asset(name, size), pose(np.eye(3), xyz), support)


def _settle(scene: Scene, tmp_path, tag: str) -> PhysicsVerdict:
    from layout import verify_scene

    verdict, _ = verify_scene(write_fixture_mjcf(scene, tmp_path / f"{tag}.xml"), scene, LayoutConfig(settle_s=1.0))
    return verdict


def test_a_box_riding_on_a_settling_one_is_reseated_with_it(tmp_path):
    from layout import reseat_objects, reseatable, unstable_objects
    from scene_builder.model import LayoutResult, Placement

    # The base hangs 4 cm above the floor; the top box 2.5 cm above the base: the top falls
    # 6.5 cm in all (more than a re-seat allows) but only 2.5 cm relative to the base under it.
    base = _on("base", (0.6, 0.6, 0.3), (0.0, 0.0, 0.04))
    top = _on("top", (0.2, 0.2, 0.15), (0.0, 0.0, 0.365), support="base")
    loose = _on("loose", (0.2, 0.2, 0.15), (1.2, 0.0, 0.065))  # the same 6.5 cm fall onto the floor
    scene = _scene([base, top, loose])
    verdict = _settle(scene, tmp_path, "a")
    drift = {v.name: v.drift_m for v in verdict.objects}
    assert drift["top"] > 0.06 and drift["loose"] > 0.06 and 0.035 < drift["base"] < 0.045
    unstable = unstable_objects(verdict, scene, LayoutConfig(settle_s=1.0))
    assert set(unstable) == {"base", "top", "loose"}
    reseat = reseatable(verdict, unstable, scene)
    assert set(reseat) == {"base", "top"}  # the loose box fell 6.5 cm onto the floor: not re-seated
    assert "on its base" in reseat["top"]
    placements = tuple(Placement(o.name, 0.0, 0.0, o.support, False, "") for o in scene.objects)
    layout = reseat_objects(LayoutResult(scene=scene, support=(), placements=placements), verdict, reseat)
    again = _settle(layout.scene, tmp_path, "b")
    moved = {v.name: v for v in again.objects}
    assert moved["base"].drift_m < 0.003 and moved["top"].drift_m < 0.003
    assert max(moved["base"].start_penetration_m, moved["top"].start_penetration_m) < 1e-3
    assert {p.name: p.displacement_m for p in layout.placements}["top"] > 0.06


def _track(name: str, start: np.ndarray, end: np.ndarray) -> Trajectory:
    """A three-sample trajectory from pose ``start`` to ``end`` (4x4), at rest at the end."""
    from scene_builder.frames import quat_wxyz_from_matrix

    poses = [start, end, end]
    return Trajectory(name, np.array([0.0, 1.0, 2.0]), np.array([p[:3, 3] for p in poses]), np.array([quat_wxyz_from_matrix(p[:3, :3]) for p in poses]))


def test_relative_motion_follows_the_support_turning():
    from layout.repair import reseatable
    from scene_builder.model import ObjectVerdict

    # The support tips 6 degrees about its own origin; the box on it, 0.5 m to the side, is
    # carried along (it drops ~5 cm) and slides 1 cm on it: 1 cm relative motion, re-seated.
    a = np.radians(6.0)
    tip = pose(np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]]), np.zeros(3))
    start_top = pose(np.eye(3), np.array([0.5, 0.0, 0.3]))
    end_top = tip @ start_top
    end_top[:3, 3] += end_top[:3, :3] @ np.array([0.01, 0.0, 0.0])
    tracks = (_track("bed", np.eye(4), tip), _track("pillow", start_top, end_top))
    drift = float(np.linalg.norm(end_top[:3, 3] - start_top[:3, 3]))
    assert drift > 0.05
    objects = (ObjectVerdict("bed", 0.0, 0.02, 6.0, False), ObjectVerdict("pillow", 0.0, drift, 6.0, False))
    verdict = PhysicsVerdict(0.0, drift, 6.0, 2.0, False, objects, tracks)
    scene = _scene([_on("bed", (1.6, 1.0, 0.3), (0.0, 0.0, 0.0)), _on("pillow", (0.3, 0.3, 0.1), (0.5, 0.0, 0.3), support="bed")])
    reasons = reseatable(verdict, {"bed": "moved", "pillow": "moved"}, scene)
    assert "(1.0 cm, 0 deg on its bed" in reasons["pillow"]
    # The same motion with nothing moving under it: too far to re-seat.
    alone = _scene([_on("bed", (1.6, 1.0, 0.3), (0.0, 0.0, 0.0)), _on("pillow", (0.3, 0.3, 0.1), (0.5, 0.0, 0.3), support="floor")])
    assert "pillow" not in reseatable(verdict, {"bed": "moved", "pillow": "moved"}, alone)


def test_neighbours_that_settled_against_a_reseated_object_move_with_it(tmp_path):
    from layout import settled_together

    # A heavy box hangs 3 cm up, its neighbour stands 1 cm from it on the floor, a third box 1 m
    # away; a fourth next to the neighbour is becoming background (it stays where it is).
    hanging = _on("hanging", (0.5, 0.5, 0.4), (0.0, 0.0, 0.03))
    beside = _on("beside", (0.3, 0.3, 0.3), (0.41, 0.0, 0.0))
    chained = _on("chained", (0.3, 0.3, 0.3), (0.72, 0.0, 0.0))
    far = _on("far", (0.3, 0.3, 0.3), (0.0, 1.5, 0.0))
    stays = _on("stays", (0.2, 0.2, 0.2), (0.0, -0.37, 0.0))
    scene = _scene([hanging, beside, chained, far, stays])
    verdict = _settle(scene, tmp_path, "c")
    together = settled_together(scene, verdict, {"hanging"}, {"stays"})
    assert together == {"beside", "chained"}  # chained: 1 cm from beside, in turn
    assert settled_together(scene, verdict, set(), set()) == set()


def test_a_box_knocked_over_by_a_falling_board_gets_another_check(tmp_path):
    from layout import knocked, make_background, unstable_objects
    from scene_builder.model import LayoutResult, Placement

    # A 2 m board leaning 10 degrees towards a tall box 0.5 m away falls onto it; a third box hangs
    # 5 cm up far from both and drops at once (it moves first: nothing knocked it).
    a = np.radians(10.0)
    lean = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    board = PlacedObject(box_asset("board", (0.04, 0.6, 2.0)), pose(lean, (0.02 * np.cos(a), 0.0, 0.02 * np.sin(a))), "floor")
    box = _on("box", (0.15, 0.3, 0.9), (0.6, 0.0, 0.0))  # tall and light: pushed over when hit
    drop = _on("drop", (0.3, 0.3, 0.3), (0.0, 2.0, 0.05))
    scene = _scene([board, box, drop])
    config = LayoutConfig(settle_s=1.5)
    from layout import verify_scene

    verdict, _ = verify_scene(write_fixture_mjcf(scene, tmp_path / "k.xml"), scene, config)
    unstable = unstable_objects(verdict, scene, config)
    assert {"board", "box", "drop"} <= set(unstable)
    assert knocked(verdict, scene, set(unstable), set(unstable)) == {"box"}
    assert knocked(verdict, scene, set(unstable), {"drop"}) == set()  # only the board fell onto it
    # With the board made background where it was seen, the box stands.
    placements = tuple(Placement(o.name, 0.0, 0.0, o.support, False, "") for o in scene.objects)
    layout = make_background(LayoutResult(scene=scene, support=(), placements=placements), {"board": "toppled", "drop": "fell"})
    again, _ = verify_scene(write_fixture_mjcf(layout.scene, tmp_path / "k2.xml"), layout.scene, config)
    assert {v.name: v.drift_m for v in again.objects}["box"] < 0.002
