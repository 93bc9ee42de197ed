"""Layout solver: no interpenetration (checked independently with manifold3d and in MuJoCo),
support graph, resting contacts, walls, minimal moves, yaw snapping, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from layout.pushes import candidate_pairs
from layout.solver import solve_layout_with_stats
from scene_builder.bench.clutter import asset_from_pieces, clutter_layout_config, box_asset, box_mesh, clutter, empty_perception, surface_points, table_asset
from scene_builder.config import LayoutConfig
from scene_builder.frames import pose, rot_z, transform_points, yaw_of
from scene_builder.model import GeneratedAsset, Plane

CFG = LayoutConfig()
CLUTTER = clutter_layout_config()


def _gen(asset, xyz, yaw=0.0, points=None):
    p = pose(rot_z(yaw), xyz)
    pts = np.zeros((0, 3)) if points is None else points
    return GeneratedAsset(asset, p, pts)


def _world_pieces(placed):
    return [transform_points(placed.world_from_asset, m.vertices_m) for part in placed.asset.parts for m in part.collision]


def _max_intersection_volume(scene) -> float:
    """Largest intersection volume (m^3) of two convex pieces of distinct objects, by manifold3d
    booleans (independent of the solver's GJK/EPA and SAT)."""
    import manifold3d

    objs = [[(p, manifold3d.Manifold.hull_points(p)) for p in _world_pieces(o)] for o in scene.objects]
    worst = 0.0
    for i in range(len(objs)):
        for j in range(i + 1, len(objs)):
            for pa, ma in objs[i]:
                for pb, mb in objs[j]:
                    if np.any(pa.min(0) > pb.max(0)) or np.any(pb.min(0) > pa.max(0)):
                        continue
                    worst = max(worst, (ma ^ mb).volume())
    return worst


def _bottom(placed) -> float:
    return float(min(p[:, 2].min() for p in _world_pieces(placed)))


def test_broad_phase_matches_brute_force():
    rng = np.random.default_rng(3)
    lo = rng.uniform(0, 10, size=(300, 3))
    hi = lo + rng.uniform(0.1, 1.0, size=(300, 3))
    got = {tuple(p) for p in candidate_pairs(lo, hi, 0.01)}
    ov = np.all(lo[:, None] <= hi[None] + 0.01, axis=2) & np.all(lo[None] <= hi[:, None] + 0.01, axis=2)
    want = {(i, j) for i, j in zip(*np.nonzero(np.triu(ov, 1)))}
    assert got == want and len(want) > 50


def test_clutter_has_no_interpenetration_and_everything_rests():
    perception, generated = clutter(40, seed=1)
    result, stats = solve_layout_with_stats(perception, generated, CLUTTER)
    assert stats.converged
    assert result.max_penetration_before_m > 0.1  # the clutter really overlapped
    assert result.max_penetration_after_m < 1e-4
    # Independent check: no two convex pieces share volume (1 cm^3 would be a 2 mm deep overlap
    # over a 5 cm^2 face).
    assert _max_intersection_volume(result.scene) < 1e-7
    support = {e.child: e.parent for e in result.support}
    by_name = {o.name: o for o in result.scene.objects}
    on_objects = 0
    for o in result.scene.objects:
        assert o.support == support[o.name]
        if support[o.name] == "floor":
            assert abs(_bottom(o)) < 1e-9
        else:
            on_objects += 1
            parent = by_name[support[o.name]]
            top = max(p[:, 2].max() for p in _world_pieces(parent))
            assert abs(_bottom(o) - top) < 1e-9
    assert on_objects >= 2
    # Walls: every vertex on the room side, at least the clearance minus tolerance away.
    for o in result.scene.objects:
        v = np.concatenate(_world_pieces(o))
        for w in perception.room.walls:
            assert w.signed_distance_m(v).min() > CFG.clearance_m - 2e-4
    # The solver moves objects only to separate them: the displacement stays small.
    assert stats.mean_shift_m < 0.35


def test_solved_clutter_is_stable_in_mujoco(tmp_path):
    """The solved layout, exported, starts without penetration and stays put for 3 s."""
    from layout import verify_scene
    from tests.test_layout_verify import write_fixture_mjcf

    perception, generated = clutter(12, seed=5, mix=(0.6, 0.0, 0.2, 0.2))
    result = solve_layout_with_stats(perception, generated, CLUTTER)[0]
    assert result.max_penetration_before_m > 0.05
    assert any(e.parent not in ("floor", "wall") for e in result.support)
    verdict, _ = verify_scene(write_fixture_mjcf(result.scene, tmp_path / "c.xml"), result.scene, CFG)
    assert verdict.max_penetration_m < 1e-3
    assert verdict.stable, [o for o in verdict.objects if o.drift_m > 0.01 or o.rotation_deg > 2]


def test_box_on_table_rests_on_the_top():
    table = table_asset("table", (0.8, 1.2, 0.75))
    box = box_asset("box", (0.2, 0.3, 0.15))
    # The box was observed 3 cm sunk into the table top (box bottom 0.73, table top 0.01 + 0.75),
    # and slightly overhanging an edge.
    gen = (_gen(table, (0.0, 0.0, 0.01)), _gen(box, (0.3, 0.1, 0.73), yaw=0.1))
    result, _ = solve_layout_with_stats(empty_perception(), gen, CFG)
    placed = {o.name: o for o in result.scene.objects}
    assert {(e.child, e.parent) for e in result.support} == {("table", "floor"), ("box", "table")}
    assert placed["box"].support == "table"
    assert _bottom(placed["table"]) == pytest.approx(0.0, abs=1e-9)
    assert _bottom(placed["box"]) == pytest.approx(0.75, abs=1e-9)
    edge = next(e for e in result.support if e.child == "box")
    assert edge.contact_gap_m == pytest.approx(-0.03, abs=1e-6)
    # Its centre of mass lies over the table top.
    com = placed["box"].world_from_asset[:3, 3]
    assert abs(com[0]) < 0.4 and abs(com[1]) < 0.6


def test_support_graph_of_a_hand_made_stack():
    a = box_asset("a_base", (0.6, 0.6, 0.4))
    b = box_asset("b_mid", (0.4, 0.4, 0.3))
    c = box_asset("c_top", (0.2, 0.2, 0.1))
    d = box_asset("d_beside", (0.3, 0.3, 0.5))
    e = box_asset("e_low_neighbour", (0.5, 0.5, 0.1))
    gen = (
        _gen(c, (0.02, 0.0, 0.72)),  # on b (b top at 0.7), 2 cm high
        _gen(a, (0.0, 0.0, 0.0)),
        _gen(b, (0.05, 0.0, 0.39)),  # on a, 1 cm sunk
        _gen(d, (1.5, 0.0, 0.03)),
        # f stands on the floor overlapping the low box e: it must stay on the floor (the low
        # box's top is 10 cm above f's bottom), and be pushed beside it.
        _gen(e, (3.0, 0.0, 0.0)),
        _gen(box_asset("f_tall", (0.3, 0.3, 1.0)), (3.2, 0.0, 0.0)),
    )
    result, _ = solve_layout_with_stats(empty_perception(), gen, CFG)
    edges = {(e.child, e.parent) for e in result.support}
    assert edges == {
        ("a_base", "floor"),
        ("b_mid", "a_base"),
        ("c_top", "b_mid"),
        ("d_beside", "floor"),
        ("e_low_neighbour", "floor"),
        ("f_tall", "floor"),
    }
    placed = {o.name: o for o in result.scene.objects}
    assert _bottom(placed["c_top"]) == pytest.approx(0.7, abs=1e-9)
    assert _bottom(placed["b_mid"]) == pytest.approx(0.4, abs=1e-9)
    assert result.max_penetration_after_m < 1e-5


def test_buried_face_is_not_a_support():
    # A solid cabinet decomposed into two stacked pieces: the lower piece's top face (z = 0.4)
    # lies inside the object. A box observed at 0.45 must not be set on it; with nothing else
    # within reach under it (the floor is 45 cm down, the space under it unseen, and a column
    # down to the floor would pass through the cabinet) it is left where it was seen, as static
    # background, and the placement says why.
    cabinet = asset_from_pieces("cabinet", "cabinet", [box_mesh([-0.3, -0.4, 0.0], [0.3, 0.4, 0.4]), box_mesh([-0.3, -0.4, 0.4], [0.3, 0.4, 0.8])])
    box = box_asset("box", (0.2, 0.2, 0.2))
    result, _ = solve_layout_with_stats(empty_perception(), (_gen(cabinet, (0, 0, 0)), _gen(box, (0.0, 0.0, 0.45), yaw=0.5)), CFG)
    assert "box" not in {e.child for e in result.support} and [o.name for o in result.scene.objects] == ["cabinet"]
    placement = {p.name: p for p in result.placements}["box"]
    assert placement.became_background and placement.displacement_m == 0.0 and "another object's" in placement.reason
    assert result.scene.room.background is not None and result.scene.room.background.static_names == ("box",)
    # Observed 2 cm sunk into the real top, it rests on the top.
    result, _ = solve_layout_with_stats(empty_perception(), (_gen(cabinet, (0, 0, 0)), _gen(box, (0.0, 0.0, 0.78), yaw=0.5)), CFG)
    assert {e.child: e.parent for e in result.support}["box"] == "cabinet"
    assert _bottom(result.scene.objects[1]) == pytest.approx(0.8, abs=1e-9)


def test_minimal_horizontal_push_split_by_mass():
    a = box_asset("a", (0.4, 0.4, 0.4))
    b = box_asset("b", (0.4, 0.4, 0.4))
    # 10 cm overlap along x (deeper than layout.trim cuts), equal masses: each moves
    # (10 cm + clearance) / 2, along x only.
    result, _ = solve_layout_with_stats(empty_perception(), (_gen(a, (0.0, 0.0, 0.0)), _gen(b, (0.30, 0.0, 0.0))), CFG)
    pa, pb = (o.world_from_asset[:3, 3] for o in result.scene.objects)
    half = (0.10 + CFG.clearance_m) / 2
    np.testing.assert_allclose(pa, [-half, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(pb, [0.30 + half, 0.0, 0.0], atol=1e-6)
    # A heavy (larger) box moves less than a light one.
    big = box_asset("big", (0.8, 0.8, 0.4))
    small = box_asset("small", (0.2, 0.2, 0.2))
    result, _ = solve_layout_with_stats(empty_perception(), (_gen(big, (0.0, 0.0, 0.0)), _gen(small, (0.41, 0.0, 0.0))), CFG)
    p = {o.name: o.world_from_asset[:3, 3] for o in result.scene.objects}
    move_big, move_small = abs(p["big"][0]), abs(p["small"][0] - 0.41)
    assert move_small > 10 * move_big
    assert move_big + move_small == pytest.approx(0.09 + CFG.clearance_m, abs=1e-6)


def test_shallow_overlap_is_trimmed_not_pushed():
    """Two boxes whose hidden backs overlap by 4 cm stay where they were seen: their collision
    pieces are cut apart at the mid-plane (layout.trim), leaving the clearance, and no volume is
    shared (manifold3d)."""
    a = box_asset("a", (0.4, 0.4, 0.4))
    b = box_asset("b", (0.4, 0.4, 0.4))
    gen = (_gen(a, (0.0, 0.0, 0.0)), _gen(b, (0.36, 0.0, 0.0)))
    result, _ = solve_layout_with_stats(empty_perception(), gen, CFG)
    for g, o in zip(gen, result.scene.objects):
        np.testing.assert_array_equal(o.world_from_asset, g.world_from_asset)
    assert all(p.displacement_m == 0.0 for p in result.placements)
    assert result.max_penetration_after_m < 1e-5
    assert _max_intersection_volume(result.scene) < 1e-9
    xa = max(p[:, 0].max() for p in _world_pieces(result.scene.objects[0]))
    xb = min(p[:, 0].min() for p in _world_pieces(result.scene.objects[1]))
    assert xa == pytest.approx(0.18 - 0.001, abs=1e-6) and xb == pytest.approx(0.18 + 0.001, abs=1e-6)
    # Visual meshes and masses are the observed ones.
    assert result.scene.objects[0].asset.parts[0].visual is a.parts[0].visual
    assert result.scene.objects[0].asset.mass_kg == a.mass_kg


def test_separated_objects_do_not_move():
    gen = (_gen(box_asset("a", (0.3, 0.3, 0.3)), (0.0, 0.0, 0.0), yaw=0.5), _gen(box_asset("b", (0.3, 0.3, 0.3)), (1.0, 0.4, 0.0), yaw=-0.4))
    result, stats = solve_layout_with_stats(empty_perception(), gen, CFG)
    for g, o in zip(gen, result.scene.objects):
        np.testing.assert_array_equal(o.world_from_asset, g.world_from_asset)
    assert stats.max_shift_m == 0.0 and result.iterations == 1


def test_fixed_furniture_does_not_move_and_walls_push_out():
    walls = (Plane(np.array([1.0, 0.0, 0.0]), 1.0, "wall", 100), Plane(np.array([0.0, -1.0, 0.0]), 2.0, "wall", 50))
    counter = box_asset("counter", (0.6, 1.5, 0.9), label="counter", fixed=True)
    box = box_asset("box", (0.4, 0.4, 0.4))
    # The box overlaps the counter and sticks 4 cm through the x = -1 wall; a second box is 3 cm
    # through the y = 2 wall; a third 15 cm through the x = -1 wall: its completion is cut at the
    # wall (layout.trim.trim_to_walls), it is not pushed out nor made background.
    gen = (
        _gen(counter, (0.0, 0.0, 0.0)),
        _gen(box, (-0.84, 0.5, 0.0)),
        _gen(box_asset("other", (0.3, 0.3, 0.3)), (1.0, 1.88, 0.0)),
        _gen(box_asset("in_wall", (0.3, 0.3, 0.3)), (-1.0, 1.9, 0.0)),
    )
    result, stats = solve_layout_with_stats(empty_perception(walls), gen, CFG)
    assert stats.converged
    placed = {o.name: o for o in result.scene.objects}
    np.testing.assert_array_equal(placed["counter"].world_from_asset, gen[0].world_from_asset)
    for name in ("box", "other", "in_wall"):
        v = np.concatenate(_world_pieces(placed[name]))
        for w in walls:
            assert w.signed_distance_m(v).min() >= CFG.clearance_m - 1e-4
    deep = {p.name: p for p in result.placements}["in_wall"]
    assert not deep.became_background and deep.displacement_m < 1e-9
    # Cut at the wall: 15 of its 30 cm of collision depth are left, on the room side.
    v = np.concatenate(_world_pieces(placed["in_wall"]))
    assert np.ptp(v[:, 0]) == pytest.approx(0.15 - CFG.clearance_m, abs=1e-6)
    # Built-in furniture completed 2 cm into the wall it stands against is cut at it too (it
    # cannot move, but it overlapped the wall), where it stands.
    run = box_asset("run", (0.6, 1.0, 0.9), label="counter", fixed=True)
    result, _ = solve_layout_with_stats(empty_perception(walls), (_gen(run, (-0.72, 0.0, 0.0)),), CFG)
    v = np.concatenate(_world_pieces(result.scene.objects[0]))
    assert walls[0].signed_distance_m(v).min() >= CFG.clearance_m - 1e-4
    assert v[:, 0].max() == pytest.approx(-0.72 + 0.3)  # its front where it stood
    assert result.max_penetration_after_m < 1e-5 and not result.placements[0].became_background
    # A part wholly behind a wall is not cut to nothing: that object is wall (a picture, a door).
    behind = box_asset("behind", (0.2, 0.2, 0.3))
    result, _ = solve_layout_with_stats(empty_perception(walls), (_gen(behind, (-1.2, 0.0, 0.0)),), CFG)
    p = result.placements[0]
    assert p.became_background and "into a wall" in p.reason
    assert result.max_penetration_after_m < 1e-5
    assert _max_intersection_volume(result.scene) < 1e-9


def test_determinism_and_input_order_independence():
    perception, generated = clutter(25, seed=7)
    r1 = solve_layout_with_stats(perception, generated, CLUTTER, seed=3)[0]
    r2 = solve_layout_with_stats(perception, generated, CLUTTER, seed=3)[0]
    r3 = solve_layout_with_stats(perception, tuple(reversed(generated)), CLUTTER, seed=3)[0]
    for a, b in zip(r1.scene.objects, r2.scene.objects):
        np.testing.assert_array_equal(a.world_from_asset, b.world_from_asset)
    p3 = {o.name: o.world_from_asset for o in r3.scene.objects}
    for a in r1.scene.objects:
        np.testing.assert_allclose(a.world_from_asset, p3[a.name], atol=1e-12)
    left = {p.name for p in r1.placements if p.became_background}
    assert left == {p.name for p in r3.placements if p.became_background}
    assert [o.name for o in r3.scene.objects] == [g.asset.name for g in reversed(generated) if g.asset.name not in left]
    assert r1.support == r2.support


def test_yaw_snapping_follows_the_evidence():
    rng = np.random.default_rng(0)
    walls = (Plane(np.array([np.cos(0.1), np.sin(0.1), 0.0]), 3.0, "wall", 500),)  # room axes at 0.1 rad
    cabinet = box_asset("cabinet", (0.5, 1.0, 0.9))
    # Truly aligned with the room; the initial estimate is 7 degrees off: snapped back.
    true_pose = pose(rot_z(0.1), (0.0, 0.0, 0.0))
    pts = surface_points(cabinet, true_pose, rng, 400, 0.004)
    off = GeneratedAsset(cabinet, pose(rot_z(0.1 + np.radians(7)), (0.01, -0.01, 0.0)), pts)
    # Truly turned 30 degrees from the room axes, initial estimate exact: kept.
    chair = box_asset("chair", (0.5, 0.5, 0.9))
    turned = pose(rot_z(0.1 + np.radians(30)), (2.0, 0.0, 0.0))
    keep = GeneratedAsset(chair, turned, surface_points(chair, turned, rng, 400, 0.004))
    result, stats = solve_layout_with_stats(empty_perception(walls), (off, keep), CFG)
    placed = {o.name: o for o in result.scene.objects}
    assert stats.snaps[0].snapped and stats.snaps[0].delta_deg == pytest.approx(-7.0, abs=1e-6)
    assert yaw_of(placed["cabinet"].world_from_asset[:3, :3]) == pytest.approx(0.1, abs=1e-9)
    assert np.linalg.norm(placed["cabinet"].world_from_asset[:2, 3]) < 0.01  # re-fitted to the points
    assert not stats.snaps[1].snapped
    np.testing.assert_array_equal(placed["chair"].world_from_asset[:3, :3], turned[:3, :3])
    # Geometry is never changed.
    assert placed["cabinet"].asset is cabinet


def test_unsupported_object_is_never_welded_in_mid_air_nor_dropped():
    """A picture seen 1.5 m up against a wall, a box floating in the room and one 40 cm up have
    nothing under them within reach, and the camera saw through the space under them: none is
    welded to the wall or dropped metres from its pixels; each hangs where it was seen as static
    background, and the placement says so. A box seen 1.5 cm above the floor comes down onto it
    (the move is reported)."""
    walls = (Plane(np.array([1.0, 0.0, 0.0]), 1.0, "wall", 100),)  # x = -1, room at x > -1
    gen = (
        _gen(box_asset("picture", (0.04, 0.6, 0.4)), (-0.95, 0.0, 1.5)),
        _gen(box_asset("floating", (0.04, 0.6, 0.4)), (0.5, 0.0, 1.5)),
        _gen(box_asset("low", (0.04, 0.6, 0.4)), (-0.95, 0.65, 0.4)),
        _gen(box_asset("near_floor", (0.3, 0.3, 0.3)), (0.5, 2.0, 0.015)),
    )
    result, _ = solve_layout_with_stats(empty_perception(walls, depth_m=20.0), gen, CFG)
    placements = {p.name: p for p in result.placements}
    for name in ("picture", "floating", "low"):
        assert placements[name].became_background and placements[name].displacement_m == 0.0
        assert "camera saw empty space under it" in placements[name].reason
    assert [o.name for o in result.scene.objects] == ["near_floor"]
    assert not any(o.asset.is_fixed for o in result.scene.objects)
    bg = result.scene.room.background
    assert sorted(bg.static_names) == ["floating", "low", "picture"]
    # Their geometry is in the background exactly where it was seen.
    for g in gen[:3]:
        k = bg.static_names.index(g.asset.name)
        np.testing.assert_allclose(bg.static_meshes[k].vertices_m, transform_points(g.world_from_asset, g.asset.parts[0].visual.vertices_m))
    near = placements["near_floor"]
    assert near.support == "floor" and near.lowered_m == pytest.approx(0.015) and "lowered 2 cm onto the floor" in near.reason
    assert _bottom(result.scene.objects[0]) == pytest.approx(0.0, abs=1e-9)


def test_wall_mountable_things_against_a_wall_are_mounted_and_fixed_categories_welded_where_seen():
    """A television 1.7 m up (beyond the legs a television's stand could have) and an
    over-the-range microwave seen against a wall with empty space under them are mounted there
    (welded where seen, fixed objects, support "wall"), not background; the same television in
    the middle of the room, and a bottle against the wall, still hang as background; a sink (a
    fixed category) with nothing under it is welded where seen."""
    walls = (Plane(np.array([1.0, 0.0, 0.0]), 1.0, "wall", 100),)  # x = -1, room at x > -1
    gen = (
        _gen(box_asset("tv", (0.12, 1.0, 0.6), label="tv"), (-0.97, 0.0, 1.7)),  # its back 3 cm into the wall
        _gen(box_asset("microwave", (0.4, 0.6, 0.35), label="microwave"), (-0.78, 1.2, 1.4)),
        _gen(box_asset("tv_mid", (0.08, 1.0, 0.6), label="tv"), (0.8, 0.0, 1.7)),
        _gen(box_asset("bottle", (0.07, 0.07, 0.25), label="bottle"), (-0.95, -1.0, 1.2)),
        _gen(box_asset("sink", (0.5, 0.6, 0.2), label="sink", fixed=True), (0.8, 2.0, 0.7)),
    )
    result, _ = solve_layout_with_stats(empty_perception(walls, depth_m=20.0), gen, CFG)
    placements = {p.name: p for p in result.placements}
    placed = {o.name: o for o in result.scene.objects}
    for g in gen:
        name = g.asset.name
        if name in ("tv", "microwave", "sink"):
            assert not placements[name].became_background and placements[name].displacement_m == 0.0
            assert placed[name].asset.is_fixed
            np.testing.assert_array_equal(placed[name].world_from_asset, g.world_from_asset)  # exactly where seen
        else:
            assert placements[name].became_background and "camera saw empty space under it" in placements[name].reason
    assert placed["tv"].support == "wall" and "mounted on the wall" in placements["tv"].reason
    # Its completion is cut at the wall like a movable one's: nothing of it is in the wall.
    for name in ("tv", "microwave"):
        v = np.concatenate(_world_pieces(placed[name]))
        assert walls[0].signed_distance_m(v).min() >= CFG.clearance_m - 1e-4
    assert result.max_penetration_after_m < 1e-5
    assert placed["microwave"].support == "wall"
    assert placed["sink"].support == "room" and "welded where seen" in placements["sink"].reason
    assert not gen[0].asset.is_fixed  # the generated asset itself is not changed


def test_wall_mountable_thing_seen_far_above_a_bed_hangs_on_the_wall():
    """A picture read as a television, seen 12 cm in front of the wall (estimated depth) and
    70 cm above a bed's top, more than its own height: it is mounted on the wall where seen, not
    stood on 70 cm legs on the bed (where it toppled). A lamp in the same place (a floor lamp's
    stem may be hidden) is not mounted; a television only 20 cm above the bed stands on it."""
    walls = (Plane(np.array([1.0, 0.0, 0.0]), 1.0, "wall", 100),)  # x = -1, room at x > -1
    bed = _gen(box_asset("bed", (2.0, 1.5, 0.6), label="bed"), (0.1, 0.0, 0.0))
    gen = (
        bed,
        _gen(box_asset("tv", (0.05, 0.3, 0.3), label="tv"), (-0.85, -0.3, 1.3)),
        _gen(box_asset("lamp", (0.05, 0.3, 0.3), label="lamp"), (-0.85, 0.3, 1.3)),
    )
    result, _ = solve_layout_with_stats(empty_perception(walls, depth_m=20.0), gen, CFG)
    placements = {p.name: p for p in result.placements}
    placed = {o.name: o for o in result.scene.objects}
    assert placed["tv"].support == "wall" and placed["tv"].asset.is_fixed
    assert "mounted on the wall" in placements["tv"].reason and placements["tv"].displacement_m == 0.0
    assert not placements["lamp"].became_background and placed["lamp"].support != "wall"
    low = (bed, _gen(box_asset("tv", (0.05, 0.3, 0.3), label="tv"), (-0.85, -0.3, 0.8)))
    result, _ = solve_layout_with_stats(empty_perception(walls, depth_m=20.0), low, CFG)
    tv = {o.name: o for o in result.scene.objects}["tv"]
    assert tv.support == "bed" and not tv.asset.is_fixed


def test_object_seen_above_its_support_stands_on_legs(tmp_path):
    """A nightstand seen 8 cm above the floor (its dark plinth cut from its mask) keeps its
    height: it stands on four collision legs down to the floor, nothing visual is added, and it
    is at rest in MuJoCo."""
    from exporters import write_mjcf
    from layout import verify_scene

    stand = box_asset("stand", (0.4, 0.5, 0.5))
    gen = (_gen(stand, (0.0, 0.0, 0.08)),)
    result, _ = solve_layout_with_stats(empty_perception(), gen, CFG)
    placed = result.scene.object("stand")
    np.testing.assert_array_equal(placed.world_from_asset, gen[0].world_from_asset)
    p = result.placements[0]
    assert p.support == "floor" and p.displacement_m == 0.0 and "8 cm collision legs" in p.reason
    root = placed.asset.root
    assert len(root.collision) == 1 + 4 and root.visual is stand.root.visual and placed.asset.mass_kg == stand.mass_kg
    assert _bottom(placed) == pytest.approx(0.0, abs=1e-9)
    verdict, _ = verify_scene(write_mjcf(result.scene, tmp_path), result.scene, CFG)
    assert verdict.max_penetration_m < 1e-3 and verdict.stable and verdict.settle_max_drift_m < 2e-3



def test_a_cut_never_removes_a_main_piece_whole():
    """A bed's collision piece bulged up around a table top (its visual stays below): the cut
    between the visuals, with their tolerance, would have removed the table's whole top piece
    (seen on a real photo with the offline detectors: a table colliding by its legs only). The
    top is kept; the bed's bulge is cut above it."""
    import dataclasses

    from layout.trim import trim_pair

    table = table_asset("table", (1.0, 1.0, 0.75), top_m=0.03)
    bed = asset_from_pieces("bed", "bed", [box_mesh([-0.6, -0.6, 0.5], [0.6, 0.6, 1.0])])
    bed = dataclasses.replace(bed, parts=(dataclasses.replace(bed.parts[0], visual=box_mesh([-0.6, -0.6, 0.0], [0.6, 0.6, 0.45])),))
    top = table.parts[0].collision[0]
    new_table, new_bed, cut, left = trim_pair(table, np.eye(4), bed, np.eye(4))
    assert len(new_table.parts[0].collision) == 5
    kept_top = new_table.parts[0].collision[0]
    assert kept_top.vertices_m[:, 2].max() == pytest.approx(top.vertices_m[:, 2].max(), abs=2e-3)
    assert kept_top.vertices_m[:, 2].min() == pytest.approx(0.72, abs=1e-9)
    # The bed's piece keeps only what lies above the top, clear of it.
    assert len(new_bed.parts[0].collision) == 1
    assert new_bed.parts[0].collision[0].vertices_m[:, 2].min() > top.vertices_m[:, 2].max()
    assert cut > 0.2 and left == 0.0


@pytest.mark.parametrize("seed", [7, 11])
def test_pushes_adding_up_past_max_push_leave_the_object_where_seen(seed):
    """Each push of a pair is at most ``max_push_m``, but in a dense cluster one object can be
    pushed again and again (on a real photo a cabinet ended 45 cm from where it was seen). No
    object on the floor ends farther than ``max_push_m`` from where it was seen: the one that
    would is left where seen as background, with the reason."""
    config = LayoutConfig()
    perception, generated = clutter(16, seed=seed)
    result, _ = solve_layout_with_stats(perception, generated, config)
    on_floor = [p for p in result.placements if not p.became_background and p.support == "floor"]
    assert on_floor and max(p.displacement_m for p in on_floor) <= config.max_push_m + 0.02
    assert any("sideways in all" in p.reason and p.became_background for p in result.placements)


def test_a_body_whose_pad_is_blocked_says_so_and_not_that_it_hangs():
    """A mug seen on a surface whose pad would reach into a board standing under its middle (the
    board's top under a fifth of the mug's footprint, too little to rest on, and no cut of the
    pad keeps the mug's centre of mass over it) is left where seen because what is under it is
    another object's: the report said "hangs: the camera saw empty space under it"
    (open3d_TUM's mug, a box of sunrgbd_imvotenet_000003), which was not what happened."""
    from layout.bodies import make_body
    from layout.support import BLOCKED_PAD_REASON, UNSUPPORTED, build_support

    def seen_surface(foot, lo_m, hi_m):  # the surface seen around the mug, at 0.70 m
        return 0.7 if lo_m <= 0.7 <= hi_m else None

    board = make_body(box_asset("board", (0.02, 0.5, 0.69)), pose(np.eye(3), (0.29, 0.0, 0.0)))
    mug = make_body(box_asset("mug", (0.1, 0.1, 0.1)), pose(np.eye(3), (0.29, 0.0, 0.7)))  # 1 cm over the board
    build_support([board, mug], (), None, seen_surface, 0.02, lambda foot, bottom: False)
    assert mug.parent == UNSUPPORTED and mug.unsupported_reason == BLOCKED_PAD_REASON
    far = make_body(box_asset("mug", (0.1, 0.1, 0.1)), pose(np.eye(3), (0.6, 0.0, 0.7)))  # clear of the board
    build_support([make_body(box_asset("board", (0.02, 0.5, 0.69)), pose(np.eye(3), (0.29, 0.0, 0.0))), far], (), None, seen_surface, 0.02,
                  lambda foot, bottom: False)
    assert far.parent != UNSUPPORTED


def test_a_pad_stops_short_of_a_neighbour_reaching_under_its_edge():
    """A cabinet's top reaching 1 cm under a mug's edge (a tenth of its footprint, too little to
    rest on) cuts the pad under the mug back, with its centre of mass still over it, instead of
    leaving the mug as background; a thin board lying diagonally beside a box (a mirror beside a
    box on a dresser, sunrgbd_imvotenet_000003), whose extent in the box's axes covers the box's
    pad but which misses it, leaves the pad whole."""
    from layout.bodies import make_body
    from layout.support import BACKGROUND, build_support, pad_box

    def seen_surface(foot, lo_m, hi_m):
        return 0.7 if lo_m <= 0.7 <= hi_m else None

    cabinet = make_body(box_asset("cabinet", (0.5, 0.5, 0.69)), pose(np.eye(3), (0.0, 0.0, 0.0)))
    mug = make_body(box_asset("mug", (0.1, 0.1, 0.1)), pose(np.eye(3), (0.29, 0.0, 0.7)))
    build_support([cabinet, mug], (), None, seen_surface, 0.02, lambda foot, bottom: False)
    assert mug.parent == BACKGROUND
    centre, half, _ = pad_box(mug, 0.7)
    assert centre[0] - half[0] == pytest.approx(0.25, abs=1e-6) and centre[0] + half[0] == pytest.approx(0.34, abs=1e-6)

    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    board = make_body(box_asset("mirror", (0.02, 1.0, 0.8)), pose(rot, (0.0, 0.0, 0.0)))  # along y = -x
    box = make_body(box_asset("box", (0.2, 0.2, 0.2)), pose(np.eye(3), (0.2, 0.2, 0.7)))  # 0.14 m clear of it
    build_support([board, box], (), None, seen_surface, 0.02, lambda foot, bottom: False)
    assert box.parent == BACKGROUND and box.pad_rect_m is None


def test_a_cut_never_takes_away_the_piece_an_object_stands_on():
    """A monitor's 16 mm base plate inside a cabinet's completion reaching 2 cm under the floor:
    the level cut of least overlap took the plate away whole and the monitor, left on its stem,
    toppled (sunrgbd_imvotenet_000002). The pieces are cut apart sideways instead: the plate keeps
    its bottom on the floor."""
    from layout.trim import trim_pair

    plate = box_mesh([-0.25, -0.05, 0.0], [0.25, 0.05, 0.016])
    panel = box_mesh([-0.25, -0.15, 0.016], [-0.2, 0.15, 0.5])
    monitor = asset_from_pieces("monitor", "monitor", [plate, panel])
    cabinet = asset_from_pieces("cabinet", "cabinet", [box_mesh([0.2, -0.5, -0.02], [0.8, 0.5, 0.8])])
    cut_monitor, cut_cabinet, depth, _ = trim_pair(monitor, np.eye(4), cabinet, np.eye(4))
    assert depth > 0.0
    pieces = cut_monitor.parts[0].collision
    assert len(pieces) == 2
    base = min(pieces, key=lambda m: float(m.vertices_m[:, 2].max()))
    assert float(base.vertices_m[:, 2].min()) == pytest.approx(0.0, abs=1e-9)
    # Cut at the mid-plane of the 5 cm overlap, the cabinet's side on the other side of it.
    assert float(base.vertices_m[:, 0].max()) == pytest.approx(0.224, abs=1e-6)
    assert float(cut_cabinet.parts[0].collision[0].vertices_m[:, 0].min()) == pytest.approx(0.226, abs=1e-6)


def test_a_thing_on_a_stepped_top_rests_on_the_step_under_it_and_is_kept_on_it():
    """A night stand's top completed as two pieces 2 cm apart in height is one merged top at the
    higher one's height; a price card seen over the lower piece rested at the merged height, 2 cm
    over what held it, and the pushes kept its centre of mass anywhere in the merged top, past
    the lower piece's edge: it dropped and tipped in the settle (sunrgbd_imvotenet_000002). It
    rests on the step under it, and that step is the face it is kept on; pushed 25 cm off it
    (by neighbours), it is brought back onto it."""
    from layout.bodies import make_body
    from layout.pushes import Solver
    from layout.support import build_support

    stand = make_body(asset_from_pieces("stand", "night_stand", [box_mesh([-0.5, -0.25, 0.0], [0.0, 0.25, 0.82]),
                                                                  box_mesh([0.0, -0.25, 0.0], [0.5, 0.25, 0.80])], fixed=True), np.eye(4))
    assert stand.merged_from == 2 and len(stand.surfaces) == 3  # two piece tops, one merged top
    card = make_body(box_asset("card", (0.1, 0.1, 0.2)), pose(np.eye(3), (0.3, 0.0, 0.79)))  # seen 1 cm sunk into the lower piece
    build_support([stand, card], (), None, None, 0.02, None)
    assert card.parent == 0 and card.bottom_m == pytest.approx(0.80)
    assert card.step_face is not None and card.step_face.polygon_rel_m[:, 0].min() == pytest.approx(0.0)
    on_both = make_body(box_asset("box", (0.2, 0.2, 0.2)), pose(np.eye(3), (0.0, 0.0, 0.81)))
    build_support([stand, on_both], (), None, None, 0.02, None)
    assert on_both.parent == 0 and on_both.bottom_m == pytest.approx(0.82)

    solver = Solver([stand, card], (), clutter_layout_config())
    region = solver.support_region(1) + stand.position_m[:2]
    assert region[:, 0].min() >= 0.02 - 1e-9  # over the lower piece, by the stability inset
    card.position_m[:2] += np.array([0.25, 0.0])  # pushed 25 cm, off the top's edge at x = 0.5
    assert solver.keep_on_support()
    assert card.position_m[0] + card.com_rel_m[0] <= 0.5 - 0.02 + 1e-9


def test_a_thing_whose_step_a_cut_lowered_comes_down_onto_it():
    """A cut between a table's completion and a book lowered the step of the table's top that a
    thin device stood on (emsanet_sample): the device kept its height and hovered 3 cm over the
    step, and dropped at the start of the settle. It comes down onto the highest face under it."""
    from layout.bodies import make_body
    from layout.pushes import Solver
    from layout.solver import _trim_overlaps

    table = make_body(asset_from_pieces("table", "table", [box_mesh([-0.5, -0.3, 0.0], [0.5, 0.3, 0.43]),
                                                            box_mesh([0.0, -0.1, 0.43], [0.1, 0.1, 0.46])], fixed=True), np.eye(4))
    book = make_body(box_asset("book", (0.275, 0.2, 0.04)), pose(np.eye(3), (0.1625, 0.0, 0.43)))  # into the step's side
    device = make_body(box_asset("device", (0.04, 0.04, 0.05)), pose(np.eye(3), (0.0, 0.0, 0.46)))  # half over the step
    for b, face in ((book, 0), (device, 1)):
        b.parent, b.support_surface = 0, face
    table.children = [1, 2]
    bodies = [table, book, device]
    solver = Solver(bodies, (), clutter_layout_config())
    assert _trim_overlaps(solver, {})
    step_top = max(float(m.vertices_m[:, 2].max()) for m in bodies[0].asset.parts[0].collision if m.vertices_m[:, 0].min() > -0.01)
    assert step_top < 0.455  # the cut lowered the step
    assert bodies[2].bottom_m == pytest.approx(step_top, abs=1e-6)  # and the device stands on it


def test_a_cut_under_a_small_thing_takes_only_the_blockers_pieces_around_it():
    """A book seen sunk 4 cm into a desk's completed top: cut against the whole convex top slab,
    the half-space lowered the whole top (everything on open3d_TUM's desk fell). Split along the
    sides of the book's plan box first (layout.trim.split_around), the cut takes only the piece
    under the book: the rest of the top keeps its height and the desk keeps over 95 % of its
    collision volume."""
    from layout.trim import collision_volume_m3, split_around, trim_pair

    desk = asset_from_pieces("desk", "desk", [box_mesh([-0.6, -0.3, 0.0], [0.6, 0.3, 0.75])])
    book = box_asset("book", (0.2, 0.15, 0.05), label="book")
    t_desk, t_book = np.eye(4), pose(np.eye(3), (0.2, 0.0, 0.71))
    whole = trim_pair(book, t_book, desk, np.eye(4))[1]
    assert max(float(m.vertices_m[:, 2].max()) for m in whole.parts[0].collision) < 0.74  # the whole top lowered
    local = split_around(desk, t_desk, np.array([0.08, -0.095]), np.array([0.32, 0.095]))
    assert len(local.parts[0].collision) == 9 and collision_volume_m3(local) == pytest.approx(collision_volume_m3(desk))
    cut = trim_pair(book, t_book, local, t_desk)[1]
    tops = [(m.vertices_m[:, :2].mean(axis=0), float(m.vertices_m[:, 2].max())) for m in cut.parts[0].collision]
    inside = [z for c, z in tops if 0.08 < c[0] < 0.32 and abs(c[1]) < 0.095]
    outside = [z for c, z in tops if not (0.08 < c[0] < 0.32 and abs(c[1]) < 0.095)]
    assert max(inside) < 0.74 and min(outside) == pytest.approx(0.75)
    assert collision_volume_m3(cut) > 0.95 * collision_volume_m3(desk)


def test_a_bounded_wall_holds_back_what_stands_along_it_and_not_what_stands_past_its_end(tmp_path):
    """A wall seen from y = -2 to 1 m (x = -1, room at x > -1) ends there: the room goes on past
    it (an opening, an L-shaped room). A box 4 cm through it along its span is cut back to the
    room side (``layout.trim``); a table seen half a metre behind its plane but past its end stands where it was
    seen, an object, and the MJCF's wall is a slab that does not touch it."""
    import mujoco

    from exporters.mjcf import write_mjcf

    wall = Plane(np.array([1.0, 0.0, 0.0]), 1.0, "wall", 100, span_m=(-2.0, 1.0))
    gen = (
        _gen(box_asset("along", (0.4, 0.4, 0.4)), (-0.84, 0.0, 0.0)),
        _gen(table_asset("past_end", (0.8, 0.6, 0.72)), (-1.6, 2.0, 0.0)),
    )
    result, stats = solve_layout_with_stats(empty_perception((wall,)), gen, CFG)
    assert stats.converged
    placed = {o.name: o for o in result.scene.objects}
    placements = {p.name: p for p in result.placements}
    assert set(placed) == {"along", "past_end"}
    along = np.concatenate(_world_pieces(placed["along"]))
    assert wall.signed_distance_m(along).min() >= CFG.clearance_m - 1e-4
    assert placements["past_end"].displacement_m < 1e-9 and not placements["past_end"].became_background
    past = np.concatenate(_world_pieces(placed["past_end"]))
    assert wall.signed_distance_m(past).max() < -0.1  # wholly behind the wall's plane, as seen
    # The same wall unbounded pushes the table 1.2 m or leaves it background: the old behaviour.
    unbounded = Plane(wall.normal, wall.offset_m, "wall", 100)
    old, _ = solve_layout_with_stats(empty_perception((unbounded,)), gen, CFG)
    old_past = {p.name: p for p in old.placements}["past_end"]
    assert old_past.became_background or old_past.displacement_m > 0.5
    # Exported, the wall is a box behind its face over its span, and the settle check passes.
    path = write_mjcf(result.scene, tmp_path)
    m = mujoco.MjModel.from_xml_path(str(path))
    g = m.geom("wall_0")
    assert g.type[0] == mujoco.mjtGeom.mjGEOM_BOX
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    past_body = m.body("past_end").id
    for c in d.contact[: d.ncon]:
        bodies = {int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])}
        assert not (past_body in bodies and "wall_0" in (m.geom(c.geom1).name, m.geom(c.geom2).name))
