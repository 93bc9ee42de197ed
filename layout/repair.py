"""What the pipeline does with objects that did not stay at rest in the settle simulation: each
is re-seated where it came to rest (with what rests on it and what it rests on, so that the group
keeps the contacts it settled into) or, when it cannot stand where it was seen, made part of the
static background and counted."""

from __future__ import annotations

import dataclasses

import numpy as np

from scene_builder.config import LayoutConfig
from scene_builder.frames import matrix_from_quat_wxyz, pose
from scene_builder.model import AssetKind, LayoutResult, ObjectVerdict, PhysicsVerdict, PlacedObject, Scene, Trajectory

from layout.snapping import asset_bounds
from layout.verify import DEFORMABLE_SAG_FRACTION


def _body_pose(t: Trajectory, k: int) -> np.ndarray:
    """(4, 4) world pose of a trajectory's body at sample ``k``."""
    return pose(matrix_from_quat_wxyz(t.quats_wxyz[k]), t.positions_m[k])


def settled_scene(scene: Scene, verdict: PhysicsVerdict) -> Scene:
    """The scene with each free rigid object moved to where it came to rest in the settle
    simulation: ``world_from_asset`` is premultiplied by the body's motion ``T_end @ T_start^-1``
    (so the result does not depend on where the exporter put the body frame). Fixed furniture
    and deformables (whose rest shape is the asset) keep their poses."""
    tracks = {t.name: t for t in verdict.trajectories}
    placed = []
    for o in scene.objects:
        t = tracks.get(o.name)
        if t is None or len(t.times_s) < 2 or o.asset.kind is AssetKind.DEFORMABLE:
            placed.append(o)
            continue
        motion = _body_pose(t, -1) @ np.linalg.inv(_body_pose(t, 0))
        new = motion @ o.world_from_asset
        # Re-orthonormalise the rotation (float round-off of the quaternion products).
        u, _, vt = np.linalg.svd(new[:3, :3])
        new[:3, :3] = u @ vt
        placed.append(PlacedObject(asset=o.asset, world_from_asset=new, support=o.support))
    return Scene(camera=scene.camera, room=scene.room, objects=tuple(placed))


adopt_settled = settled_scene


#: A movable object overlapping anything by more than this at t = 0 cannot stand where it was put.
START_PENETRATION_LIMIT_M = 1e-3
#: ... a soft body (a flex pillow on a bed: its contacts start inside their margin and it sags)
#: by more than this.
DEFORMABLE_START_PENETRATION_M = 0.01


def unstable_objects(verdict: PhysicsVerdict, scene: Scene, config: LayoutConfig) -> dict[str, str]:
    """The movable objects that did not stay at rest in the settle simulation, or that started
    it overlapping something by more than START_PENETRATION_LIMIT_M, with one line saying why
    (object name -> reason)."""
    out = {}
    for v in verdict.objects:
        if v.fixed:
            continue
        o = scene.object(v.name)
        soft = o.asset.kind is AssetKind.DEFORMABLE
        if v.start_penetration_m > (DEFORMABLE_START_PENETRATION_M if soft else START_PENETRATION_LIMIT_M):
            # Overlapping at t = 0 (with static geometry the solver could not move it clear of,
            # e.g. collision legs over an object left where seen): not physically standing there.
            out[v.name] = f"reached {v.start_penetration_m * 1000:.0f} mm into its neighbours at the start of the settle simulation"
        elif o.asset.kind is AssetKind.DEFORMABLE:
            if v.drift_m > max(config.stable_drift_m, DEFORMABLE_SAG_FRACTION * float(o.asset.size_m[2])):
                out[v.name] = f"slid {v.drift_m * 100:.0f} cm in the {config.settle_s:g} s settle simulation"
        elif v.drift_m > config.stable_drift_m or v.rotation_deg > config.stable_rotation_deg:
            how = "toppled" if v.toppled else ("turned" if v.drift_m <= config.stable_drift_m else "moved")
            out[v.name] = f"{how} ({v.drift_m * 100:.1f} cm, {v.rotation_deg:.0f} deg) in the {config.settle_s:g} s settle simulation"
    return out


#: An object that settled at most this far (and turned at most RESEAT_MAX_DEG) and came to rest
#: (its last 0.2 s within RESEAT_REST_M) is re-seated where it came to rest, not made background.
RESEAT_MAX_DRIFT_M = 0.05
RESEAT_MAX_DEG = 20.0
RESEAT_REST_M = 0.002


def _settle_motion(name: str, tracks: dict[str, Trajectory], scene: Scene, v: ObjectVerdict) -> tuple[float, float]:
    """How far (m) and how much (deg) object ``name`` moved in the settle simulation, relative to
    the object it rests on when that one moved too (a pillow carried by a bed that settled 4 cm
    moved 4 cm less than its track says): its end pose against where its support's motion alone
    would have carried it. Objects on the floor, a wall or the background: their own motion."""
    t, parent = tracks[name], tracks.get(scene.object(name).support)
    if parent is None or len(parent.times_s) != len(t.times_s):
        return v.drift_m, v.rotation_deg
    carried = _body_pose(parent, -1) @ np.linalg.inv(_body_pose(parent, 0)) @ _body_pose(t, 0)
    end = _body_pose(t, -1)
    cos = (np.trace(carried[:3, :3].T @ end[:3, :3]) - 1.0) / 2.0
    return float(np.linalg.norm(end[:3, 3] - carried[:3, 3])), float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def reseatable(verdict: PhysicsVerdict, unstable: dict[str, str], scene: Scene) -> dict[str, str]:
    """The objects of ``unstable`` that settled a little and came to rest (a pot completed with a
    rounded bottom tipping 5 degrees onto its rim, a chair on legs settling a centimetre, an
    overlap of a few millimetres pushed apart, a pillow riding on a bed that settled): re-seated
    where they came to rest instead of being made background. The motion is measured against
    the support's (``_settle_motion``). Returns name -> reason ("re-seated where it came to rest ...")."""
    tracks = {t.name: t for t in verdict.trajectories}
    out = {}
    for v in verdict.objects:
        t = tracks.get(v.name)
        if v.name not in unstable or v.fixed or v.toppled or t is None or len(t.times_s) < 3:
            continue
        drift_m, turn_deg = _settle_motion(v.name, tracks, scene, v)
        if drift_m > RESEAT_MAX_DRIFT_M or turn_deg > RESEAT_MAX_DEG:
            continue
        tail = t.positions_m[t.times_s >= t.times_s[-1] - 0.2]
        if len(tail) >= 2 and float(np.linalg.norm(tail[-1] - tail[0])) > RESEAT_REST_M:
            continue  # still moving at the end: not at rest anywhere
        on = "" if (drift_m, turn_deg) == (v.drift_m, v.rotation_deg) else f" on its {scene.object(v.name).support}"
        out[v.name] = f"re-seated where it came to rest in the settle simulation ({drift_m * 100:.1f} cm, {turn_deg:.0f} deg{on}; {unstable[v.name]})"
    return out


#: Objects that came to rest within this distance of a re-seated one (their boxes at the settled
#: poses) are re-seated with it.
SETTLED_TOGETHER_M = 0.02


def _world_box(bounds: np.ndarray, world_from_asset: np.ndarray) -> np.ndarray:
    """The world axis-aligned box (2, 3) around the asset box ``bounds`` (2, 3) posed by ``world_from_asset``."""
    lo, hi = bounds
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    w = corners @ world_from_asset[:3, :3].T + world_from_asset[:3, 3]
    return np.stack([w.min(axis=0), w.max(axis=0)])


def _near(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether boxes ``a`` and ``b`` (2, 3) are within SETTLED_TOGETHER_M of each other."""
    return bool(np.all(a[0] <= b[1] + SETTLED_TOGETHER_M) and np.all(b[0] <= a[1] + SETTLED_TOGETHER_M))


def settled_together(scene: Scene, verdict: PhysicsVerdict, reseat: set[str], stay: set[str]) -> set[str]:
    """The movable objects outside ``reseat`` and ``stay`` that came to rest against a re-seated
    one (or against one of these, in turn): their boxes at the settled poses within
    SETTLED_TOGETHER_M. Re-seating an object alone puts its settled pose beside its neighbours'
    seen poses, which the settle did not check (a bed that settled 4 cm, re-seated, reaching
    2 mm into the night stand left where it was seen); the group keeps the contacts it settled
    into. ``stay``: objects that keep their poses (those becoming background)."""
    moving = {t.name for t in verdict.trajectories}  # fixed furniture has no trajectory
    boxes = {o.name: _world_box(asset_bounds(o.asset), o.world_from_asset) for o in settled_scene(scene, verdict).objects}
    free = [n for n in sorted(boxes) if n in moving and n not in reseat and n not in stay]
    group, added = set(reseat), set()
    grew = True
    while grew:
        grew = False
        for n in free:
            if n in added:
                continue
            if any(_near(boxes[n], boxes[m]) for m in group):
                group.add(n)
                added.add(n)
                grew = True
    return added


#: An object counts as moving once it is this far (or ONSET_DEG turned) from where it started.
ONSET_M = 0.005
ONSET_DEG = 2.0


def _onset_index(t: Trajectory) -> int | None:
    """The first sample at which the body is ONSET_M or ONSET_DEG from its start (None: never)."""
    q0 = t.quats_wxyz[0]
    turned = np.degrees(2.0 * np.arccos(np.clip(np.abs(t.quats_wxyz @ q0), 0.0, 1.0)))
    moving = (np.linalg.norm(t.positions_m - t.positions_m[0], axis=1) > ONSET_M) | (turned > ONSET_DEG)
    return int(np.argmax(moving)) if moving.any() else None


def knocked(verdict: PhysicsVerdict, scene: Scene, candidates: set[str], causes: set[str]) -> set[str]:
    """The objects of ``candidates`` that began to move only once one of ``causes`` (objects about
    to be made background), moving before them, had come within SETTLED_TOGETHER_M of them (a
    door seen as a 2.2 m shelf falling onto the sofa beside it): they may stand where seen once
    that one is held still, so they are checked again with it made background, not given up with
    it. (Physics cannot say which was pushed: the earlier mover is taken as the cause.) Objects
    that overlapped something at the start are never knocked: their own pose is wrong."""
    tracks = {t.name: t for t in verdict.trajectories}
    start_overlap = {v.name for v in verdict.objects if v.start_penetration_m > START_PENETRATION_LIMIT_M}
    onset = {n: _onset_index(tracks[n]) for n in candidates | causes if n in tracks}
    onset = {n: k for n, k in onset.items() if k is not None}
    bounds = {o.name: asset_bounds(o.asset) for o in scene.objects}
    placed = {o.name: o.world_from_asset for o in scene.objects}

    def box_at(name: str, k: int) -> np.ndarray:
        t = tracks[name]
        return _world_box(bounds[name], _body_pose(t, k) @ np.linalg.inv(_body_pose(t, 0)) @ placed[name])

    out = set()
    for n, k in sorted(onset.items()):
        if n not in candidates or n in start_overlap:
            continue
        mine = box_at(n, k)
        for m, j in onset.items():
            if m == n or m not in causes or j >= k or k >= len(tracks[m].times_s):
                continue
            if _near(mine, box_at(m, k)):
                out.add(n)
                break
    return out


def reseat_objects(layout: LayoutResult, verdict: PhysicsVerdict, reasons: dict[str, str]) -> LayoutResult:
    """``layout`` with the objects named in ``reasons`` moved to where they came to rest in the
    settle simulation (``settled_scene``, for those objects only); their placements add the
    reason and count the settle in their displacement."""
    settled = {o.name: o for o in settled_scene(layout.scene, verdict).objects}
    objects = tuple(settled[o.name] if o.name in reasons else o for o in layout.scene.objects)
    scene = dataclasses.replace(layout.scene, objects=objects)
    before = {o.name: o.world_from_asset for o in layout.scene.objects}
    placements = []
    for p in layout.placements:
        if p.name in reasons:
            moved = float(np.linalg.norm(settled[p.name].world_from_asset[:3, 3] - before[p.name][:3, 3]))
            p = dataclasses.replace(p, displacement_m=p.displacement_m + moved, reason="; ".join(x for x in (p.reason, reasons[p.name]) if x))
        placements.append(p)
    return dataclasses.replace(layout, scene=scene, placements=tuple(placements))


def make_background(layout: LayoutResult, reasons: dict[str, str]) -> LayoutResult:
    """``layout`` with the objects named in ``reasons`` made part of the static background where
    they are (``layout.background.absorb``); what rested on them now rests on the background.
    Their placements say why (the reason, then "kept where seen as static background")."""
    from layout.background import absorb

    scene = layout.scene
    bg = scene.room.background
    if bg is None:
        from scene_builder.model import Background, TriangleMesh

        bg = Background(TriangleMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)), np.zeros(0, dtype=bool))
    kept = []
    for o in scene.objects:
        if o.name in reasons:
            bg = absorb(bg, o.name, o.asset, o.world_from_asset)
        else:
            kept.append(dataclasses.replace(o, support="background") if o.support in reasons else o)
    room = dataclasses.replace(scene.room, background=bg)
    new_scene = Scene(camera=scene.camera, room=room, objects=tuple(kept))
    support = tuple(
        dataclasses.replace(e, parent="background") if e.parent in reasons else e for e in layout.support if e.child not in reasons
    )
    placements = tuple(
        dataclasses.replace(p, became_background=True, displacement_m=0.0, yaw_change_deg=0.0, lowered_m=0.0, support="none",
                            reason=f"{reasons[p.name]}: kept where seen as static background")
        if p.name in reasons
        else (dataclasses.replace(p, support="background") if p.support in reasons else p)
        for p in layout.placements
    )
    return dataclasses.replace(layout, scene=new_scene, support=support, placements=placements)
