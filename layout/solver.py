"""The layout solver: initial poses, Manhattan yaw snapping, support graph, and a penetration-free
placement that stays as close as it can to the observation.

Method
------
1. Start from each ``GeneratedAsset.world_from_asset`` (the pose that best explains the observed
   points); snap its yaw to the walls when the points agree (``layout.snapping``).
2. Build the support graph bottom-up and set each object's height so that its bottom touches its
   support exactly (``layout.support``); a rigid object seen with nothing under it, 0.6 m or more
   up and against a wall, is welded where it was seen instead of falling to the floor
   (``support.wall_mountable``). Heights never change after this.
3. Remove interpenetration by the smallest horizontal moves, Gauss-Seidel over the colliding
   pairs until nothing moves: broad phase by a sort-and-sweep of object boxes, exact narrow
   phase between convex pieces by MuJoCo's GJK/EPA (``layout.narrowphase``); a colliding pair is
   pushed apart along the horizontal minimum-translation vector of the pieces clipped to their
   common height band (``layout.geometry.horizontal_mtv``) plus ``clearance_m``, the move split
   by mass (fixed furniture does not move); an object carries everything resting on it. Walls
   push objects back to the room side; an object resting on another stays where it rests
   stably: a rigid body's centre of mass 20 % of its footprint width inside the supporting face,
   a soft body's whole footprint on it (``support_region``).
4. When the pushes stall (a table jammed between a shelf and a wall, two cabinets observed on one
   small top), what still overlaps is cut apart once more (``layout.trim``) and pushed again; then
   the lighter side of each pair still overlapping, and any body that its support
   region holds inside a wall, goes to its nearest free spot (rings of candidate moves); with
   no room left on its support it comes down to the floor.
Since every move is the minimum that removes a violation, the result is the nearest feasible
layout that the greedy scheme reaches, i.e. the least deviation from the observation it can find.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from layout.background import BackgroundSupport, HiddenBelow
from layout.background_policy import pad_blockers, static_background, uncage_bodies, unsupport_blocked_pads, unsupport_in_walls
from layout.bodies import Body, make_body, rebuilt, with_legs
from layout.pushes import PENETRATION_TOL_M, Solver
from layout.snapping import YawSnap, reference_yaw, snap_yaw
from layout.support import BLOCKED_PAD_REASON, MAX_DROP_M, MIN_FOOTPRINT_OVERLAP, UNSUPPORTED, overlap_fraction, build_support, subtree
from layout.trim import collision_volume_m3, split_around, trim_pair, trim_to_walls
from scene_builder.config import LayoutConfig
from scene_builder.errors import InputError
from scene_builder.model import AssetKind, GeneratedAsset, LayoutResult, Perception, PlacedObject, Placement, Scene

# Rounds of the nearest-free-spot search (Solver.relocate_remaining) and pushes after the pushes stall.
RELOCATE_ROUNDS = 3
# Rounds of cutting overlapping collision pieces apart (layout.trim) before the pushes.
TRIM_PASSES = 3
# A child whose bottom lies within this of a face under it rests on it.
REST_TOL_M = 0.002


@dataclass(frozen=True)
class SolveStats:
    """Diagnostics of one solve (for benchmarks and tests).

    snaps: per object (input order). mean_shift_m / max_shift_m: plan displacement of the objects
    from their (snapped) starting position. converged: no violation was left to fix.
    """

    snaps: tuple[YawSnap, ...]
    mean_shift_m: float
    max_shift_m: float
    converged: bool
    iterations: int
    phase_cpu_s: tuple[tuple[str, float], ...] = ()


def _trim_overlaps(solver: Solver, observed: dict[str, np.ndarray]) -> bool:
    """Cut apart the collision pieces of overlapping bodies (``layout.trim``): shallow overlaps at
    the mid-plane, deep ones between the visuals or, where those overlap, between what the camera
    saw of each (``observed``: name -> (N, 3) world points where it was seen); bodies are replaced
    in place (pose, support and flags kept). Returns whether anything was cut (the solver's
    narrow phase must then be rebuilt)."""
    bodies = solver.bodies
    changed = False

    def seen(b: Body) -> np.ndarray | None:
        pts = observed.get(b.name)
        return None if pts is None else pts + (b.position_m - b.initial_position_m)  # moved with the body

    for i, j in solver.penetrating_pairs():
        bi, bj = bodies[i], bodies[j]
        if bi.asset.kind is AssetKind.DEFORMABLE or bj.asset.kind is AssetKind.DEFORMABLE:
            continue  # a flex is simulated as its box: nothing to cut
        a, b, cut, _ = trim_pair(bi.asset, bi.world_from_asset(), bj.asset, bj.world_from_asset(), observed_a=seen(bi), observed_b=seen(bj))
        if cut <= PENETRATION_TOL_M:
            continue
        for k, asset in ((i, a), (j, b)):
            old = bodies[k]
            if asset is old.asset:
                continue
            bodies[k] = rebuilt(old, asset)
            changed = True
        bodies[i].trimmed_with.add(bodies[j].name)
        bodies[j].trimmed_with.add(bodies[i].name)
    if changed:
        # Cut pieces may have changed a supporter's top faces: each child rests on the face at
        # its bottom's height again (the nearest one); where the cut lowered the top under it (a
        # thin device on a table's stepped completion, emsanet_sample: it hovered 3 cm and
        # tipped), on the highest face under its footprint, lowered onto it with what rests on it.
        for i, b in enumerate(bodies):
            if b.parent < 0:
                continue
            s = bodies[b.parent]
            heights = np.array([s.position_m[2] + f.height_rel_m for f in s.surfaces])
            if not len(heights):
                b.support_surface = -1
                continue
            b.support_surface = int(np.argmin(np.abs(heights - b.bottom_m)))
            if b.step_face is not None or b.asset.kind is AssetKind.DEFORMABLE:
                continue
            foot = b.footprint_rel_m + b.position_m[:2]
            under = [k for k, f in enumerate(s.surfaces) if heights[k] <= b.bottom_m + REST_TOL_M
                     and overlap_fraction(foot, f.polygon_rel_m + s.position_m[:2]) >= MIN_FOOTPRINT_OVERLAP]
            if under and not any(abs(heights[k] - b.bottom_m) <= REST_TOL_M for k in under):
                k = max(under, key=lambda k: heights[k])
                if b.bottom_m - heights[k] <= MAX_DROP_M:
                    for t in subtree(bodies, i):
                        bodies[t].position_m[2] -= b.bottom_m - heights[k]
                    b.support_surface = k
    return changed


#: A cut may take at most this share of a blocker's collision volume: a cut is a half-space
#: through a whole convex piece, and through a desk's top slab or a shelf's board it lowered the
#: whole top under everything else on it (open3d_TUM, promptda_arkit: they fell).
MAX_CUT_SHARE = 0.05
#: The blocker is split this far outside the body's plan box before the cut.
SPLIT_MARGIN_M = 0.02


def _cut_blockers(bodies: list[Body], poses: list[np.ndarray], assets: list, observed: dict[str, np.ndarray]) -> list | None:
    """The assets (body order) with every body left unsupported because another body's pieces
    fill the space under it (``layout.support.BLOCKED_PAD_REASON``) cut apart from those
    bodies at the poses where both were seen (``poses``; ``layout.trim.trim_pair``, between what
    the camera saw of each where their visuals overlap), or None when there is nothing to cut."""
    out = list(assets)
    changed = False
    for i, b in enumerate(bodies):
        if b.unsupported_reason != BLOCKED_PAD_REASON:
            continue
        for k in pad_blockers(b, bodies):
            o = bodies[k]
            if AssetKind.DEFORMABLE in (out[i].kind, out[k].kind):
                continue  # a flex is simulated as its box: nothing to cut (as in _trim_overlaps)
            # The blocker's pieces are split along the sides of the body's plan box first, so the
            # cut takes only what lies under and around the body.
            foot = b.footprint_rel_m + b.position_m[:2]
            local = split_around(out[k], poses[k], foot.min(axis=0) - SPLIT_MARGIN_M, foot.max(axis=0) + SPLIT_MARGIN_M)
            a, c, depth, _ = trim_pair(out[i], poses[i], local, poses[k], observed_a=observed.get(b.name), observed_b=observed.get(o.name))
            if c is local and local is not out[k]:
                c = out[k]  # nothing cut: the blocker stays as it was, unsplit
            if c is not out[k] and collision_volume_m3(c) < (1.0 - MAX_CUT_SHARE) * collision_volume_m3(out[k]):
                continue
            if depth > PENETRATION_TOL_M and (a is not out[i] or c is not out[k]):
                out[i], out[k] = a, c
                changed = True
    return out if changed else None


def _trim_walls(solver: Solver, observed: dict[str, np.ndarray], clearance_m: float) -> bool:
    """Cut each body's collision to the room side of the walls where its completion reaches into
    one (``layout.trim.trim_to_walls``), instead of pushing it out: movable ones, things mounted
    on the wall where seen, and built-in furniture (a kitchen run completed 9 mm into the wall it
    stands against was left overlapping it: static, but a penetration all the same). Returns
    whether anything was cut."""
    changed = False
    for k, b in enumerate(solver.bodies):
        if b.asset.kind is AssetKind.DEFORMABLE or not solver.walls:
            continue
        pts = observed.get(b.name)
        seen = None if pts is None else pts + (b.position_m - b.initial_position_m)
        asset, cut = trim_to_walls(b.asset, b.world_from_asset(), solver.walls, clearance_m, seen)
        if asset is not b.asset:
            solver.bodies[k] = rebuilt(b, asset)
            changed = True
    return changed


def _yaw_deg(rotation: np.ndarray) -> float:
    return float(np.degrees(np.arctan2(rotation[1, 0], rotation[0, 0])))


def _placement(g: GeneratedAsset, b: Body, support: str, absorbed: bool) -> Placement:
    """How far ``b`` ended from where ``g`` was seen, and why."""
    seen = g.world_from_asset[:3, 3]
    delta = b.position_m - seen
    dist = float(np.linalg.norm(delta))
    yaw = abs((_yaw_deg(b.rotation) - _yaw_deg(g.world_from_asset[:3, :3]) + 180.0) % 360.0 - 180.0)
    reasons = []
    if absorbed:
        reasons.append(f"{b.unsupported_reason or 'nothing seen under it to rest on'}: kept where seen as static background")
        if b.cut_for:
            reasons.append(f"its collision cut back out of the outline of {', '.join(b.cut_for)}, which it held caged")
    if b.mounted == "wall" and not absorbed:
        reasons.append("mounted on the wall where seen (welded: nothing under it, against the wall)")
    elif b.mounted and not absorbed:
        reasons.append(f"welded where seen (a {b.asset.label} is fixed to the room; nothing under it)")
    if b.pad_bottom_m is not None and not absorbed:
        reasons.append(f"rests where seen on a static {(b.bottom_m - b.pad_bottom_m) * 100:.0f} cm column standing in for the support hidden under it")
    if b.legs_m > 0.0 and not absorbed:
        why = "the space under it was hidden from the camera" if b.hidden_support else "its feet were not seen"
        reasons.append(f"stands where seen on {b.legs_m * 100:.0f} cm collision legs down to the {support} ({why})")
    if dist > 0.01 and not absorbed:
        if abs(delta[2]) > 0.01:
            reasons.append(f"{'lowered' if delta[2] < 0 else 'raised'} {abs(delta[2]) * 100:.0f} cm onto the {support if support in ('floor', 'background', 'wall') else support}")
        if float(np.linalg.norm(delta[:2])) > 0.01:
            reasons.append(f"pushed {float(np.linalg.norm(delta[:2])) * 100:.0f} cm sideways out of interpenetration")
    if yaw > 1.0 and not absorbed:
        reasons.append(f"turned {yaw:.0f} deg to align with the walls")
    return Placement(g.asset.name, 0.0 if absorbed else dist, 0.0 if absorbed else yaw, support, absorbed, "; ".join(reasons),
                     0.0 if absorbed else float(-delta[2]))


def solve_layout_with_stats(
    perception: Perception, generated: tuple[GeneratedAsset, ...], config: LayoutConfig, seed: int = 0
) -> tuple[LayoutResult, SolveStats]:
    """:func:`solve_layout` plus diagnostics (snapping decisions, displacements)."""
    names = [g.asset.name for g in generated]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise InputError(f"layout: object names must be unique, repeated: {', '.join(dup)}; rename the assets")
    # Work in name order so that the result does not depend on the input order.
    order = sorted(range(len(generated)), key=lambda k: names[k])
    clock = [time.process_time()]
    phases: list[tuple[str, float]] = []

    def lap(name: str) -> None:
        now = time.process_time()
        phases.append((name, now - clock[0]))
        clock[0] = now

    ref = reference_yaw(perception.room)
    snaps: list[YawSnap] = [YawSnap(False, 0.0, np.nan, np.nan)] * len(generated)
    bodies: list[Body] = []
    poses: list[np.ndarray] = []
    for k in order:
        g = generated[k]
        pose, snap = snap_yaw(g.asset, g.world_from_asset, g.observed_points_world_m, ref, seed=seed + k)
        snaps[k] = snap
        poses.append(pose)
        bodies.append(make_body(g.asset, pose))
    lap("snap")
    if not bodies:
        scene = Scene(camera=perception.camera, room=perception.room, objects=())
        return LayoutResult(scene=scene, support=()), SolveStats(tuple(snaps), 0.0, 0.0, True, 0)

    walls = tuple(perception.room.walls)
    solver = Solver(bodies, walls, config, seed)
    lap("narrowphase_setup")
    before = solver.max_penetration()
    lap("measure_before")
    background = perception.room.background
    ground = BackgroundSupport(background, walls)
    hidden = HiddenBelow(perception.observation, perception.camera)
    observed = {g.asset.name: g.observed_points_world_m for g in generated}

    def support() -> tuple[list, set[str]]:
        edges, _ = build_support(bodies, walls, solver.vertical_clash, ground.height_under if background is not None else None, config.max_lower_m, hidden)
        # Pads under bodies resting on the background are cut back clear of their neighbours (legged
        # furniture whose pad cannot be stands on legs down to the floor) before the legs are made.
        return edges, unsupport_blocked_pads(bodies)

    edges, to_floor = support()
    cut = _cut_blockers(bodies, poses, [generated[k].asset for k in order], observed)
    if cut is not None:
        # What is under such a body was another's completion reaching around where it was seen
        # (a bed's top completed up around the pillows seen on it, to the headboard): the pair is
        # cut apart where each was seen, and the support graph is built again from the start.
        bodies = [make_body(a, pose) for a, pose in zip(cut, poses)]
        solver = Solver(bodies, walls, config, seed)
        edges, to_floor = support()
    edges = [dataclasses.replace(e, parent="floor") if e.child in to_floor else e for e in edges]
    for i, b in enumerate(bodies):
        if b.legs_m > 0.0 and b.parent != UNSUPPORTED:
            bodies[i] = with_legs(b)
    if any(b.legs_m > 0.0 for b in bodies):
        solver = Solver(bodies, walls, config, seed)
    # Completions reaching into a wall are cut at it before anything is judged to be in one.
    if _trim_walls(solver, {g.asset.name: g.observed_points_world_m for g in generated}, float(config.clearance_m)):
        solver = Solver(bodies, walls, config, seed)
    unsupport_in_walls(solver, config.max_wall_push_m)
    absorbed = [i for i, b in enumerate(bodies) if b.parent == UNSUPPORTED]
    for i in absorbed:
        if bodies[i].asset.kind is AssetKind.DEFORMABLE:
            # Static now: no flex box, its own collision pieces (which layout.trim can cut).
            bodies[i] = rebuilt(bodies[i], dataclasses.replace(bodies[i].asset, kind=AssetKind.RIGID, deformable=None))
            solver = Solver(bodies, walls, config, seed)
        bodies[i].fixed = True  # left where seen; the others make room around it
    for i, b in enumerate(bodies):
        solver.world.set_position(i, b.position_m)
    lap("support")
    for _ in range(TRIM_PASSES):  # a cut changes the pieces: look again
        if not _trim_overlaps(solver, observed):
            break
        solver = Solver(bodies, walls, config, seed)
    lap("trim")
    iterations, converged = solver.run(int(config.max_iterations))
    if not converged and solver.penetrating_pairs() and _trim_overlaps(solver, observed):
        # The pushes and the support-keeping step can undo each other (a thing resting on its
        # neighbour, its stable spot over that neighbour's top overlapping its side, fifteen
        # millimetres in promptda_arkit): what overlaps where the pushes left it is cut apart.
        stuck = solver.stuck  # left where seen by the pushes so far
        solver = Solver(bodies, walls, config, seed)
        solver.stuck.extend(stuck)
        more, converged = solver.run(int(config.max_iterations) // 2)
        iterations += more
    for _ in range(RELOCATE_ROUNDS):
        # Pushes that stall (a table jammed between a shelf and a wall) leave overlaps: the
        # movable side goes to its nearest free spot, then the pushes tidy the clearances.
        # (Converged pushes can still leave an overlap with a fixed body they cannot move.)
        if (converged and not solver.penetrating_pairs()) or not solver.relocate_remaining():
            break
        more, converged = solver.run(int(config.max_iterations) // 2)
        iterations += more
    lap("solve")
    after = solver.max_penetration()
    lap("measure_after")
    absorbed = sorted(set(absorbed) | set(solver.stuck))
    seen = {g.asset.name: g.world_from_asset for g in generated}
    uncage_bodies(bodies, absorbed, walls, seen)
    lap("uncage")

    by_name = {b.name: b for b in bodies}
    parent_of = {e.child: e.parent for e in edges}
    absorbed_names = {bodies[i].name for i in absorbed}
    # What rests on an object that became background rests on the background.
    parent_of = {c: ("background" if p in absorbed_names else p) for c, p in parent_of.items()}
    edges = [dataclasses.replace(e, parent=parent_of[e.child]) for e in edges]
    placed = tuple(
        PlacedObject(asset=by_name[g.asset.name].asset, world_from_asset=by_name[g.asset.name].world_from_asset(), support=parent_of[g.asset.name])
        for g in generated
        if g.asset.name not in absorbed_names
    )
    room = dataclasses.replace(perception.room, background=static_background(background, bodies, absorbed, walls, seen))
    scene = Scene(camera=perception.camera, room=room, objects=placed)
    edge_order = {n: k for k, n in enumerate(names)}
    support = tuple(sorted((e for e in edges if e.child not in absorbed_names), key=lambda e: edge_order[e.child]))
    placements = tuple(
        _placement(g, by_name[g.asset.name], parent_of[g.asset.name], g.asset.name in absorbed_names)
        for g in generated
    )
    lap("background")
    shifts = np.array([np.linalg.norm(b.position_m[:2] - b.initial_position_m[:2]) for b in bodies])
    stats = SolveStats(tuple(snaps), float(shifts.mean()), float(shifts.max()), converged, iterations, tuple(phases))
    return (
        LayoutResult(scene=scene, support=support, iterations=iterations, max_penetration_before_m=before,
                     max_penetration_after_m=after, placements=placements),
        stats,
    )


def solve_layout(
    perception: Perception, generated: tuple[GeneratedAsset, ...], config: LayoutConfig, seed: int = 0
) -> LayoutResult:
    """Place the generated assets in the world: gravity-aligned, no interpenetration (objects,
    floor, walls), every object resting on its support, as close to the observation as possible.

    ``seed`` picks the subsample of observed points used for yaw snapping and the pair order of
    late sweeps (after SHUFFLE_AFTER_ITERATIONS); the result is a deterministic function of the
    inputs and the seed. ``scene.objects`` keeps the input order.
    """
    return solve_layout_with_stats(perception, generated, config, seed)[0]
