"""Which objects the layout leaves where they were seen as static background, and the background
they make: a body whose pad under it would reach into another body or that reaches into a wall
is unsupported (left where seen); static bodies that cage a movable one are cut back; the
absorbed objects join the background, with a pad under every body resting on it and the
collision boxes of the observed structure carved clear of the rest. Called by
:func:`layout.solver.solve_layout_with_stats`."""

from __future__ import annotations

import dataclasses

import numpy as np

from layout.background import absorb, carve, clip_pad, column_boxes, observed_structure
from layout.bodies import Body
from layout.geometry import swept_part_boxes
from layout.pushes import Solver
from layout.support import BACKGROUND, BLOCKED_PAD_REASON, UNSUPPORTED, pad_box, pad_frame
from scene_builder.model import AssetKind, Background, Plane, TriangleMesh


def _pad_frame(b: Body, legs_pending: bool = False) -> tuple[np.ndarray, float, float, float, np.ndarray]:
    """The pad under ``b`` (``layout.support.pad_frame``) where ``b`` rests: at its bottom, less
    its legs when they are still to be made (``legs_pending``)."""
    return pad_frame(b, b.bottom_m - (b.legs_m if legs_pending else 0.0))


def _obstacles(b: Body, bodies: list[Body]) -> list[np.ndarray]:
    """World vertices of every collision piece of the bodies other than ``b``."""
    return [p.verts_rel_m + o.position_m for o in bodies if o is not b for p in o.pieces]


def _pad_blocked(b: Body, bodies: list[Body], legs_pending: bool = False) -> bool:
    """Whether the pad under ``b`` (resting on the background) reaches into another body's
    pieces (their plan outlines, within its height band)."""
    rect, yaw, z_lo, z_hi, _ = _pad_frame(b, legs_pending)
    return clip_pad(rect, yaw, b.position_m, z_lo, z_hi, _obstacles(b, bodies), np.zeros(2), 0.0, probe=True) is None


def _clipped_pad(b: Body, bodies: list[Body], legs_pending: bool = False) -> np.ndarray | None:
    """The pad rectangle under ``b`` cut back clear of the other bodies' pieces with its centre
    of mass still held over it (``layout.background.clip_pad``), or None where no cut does."""
    from layout.support import support_inset_m

    rect, yaw, z_lo, z_hi, com = _pad_frame(b, legs_pending)
    return clip_pad(rect, yaw, b.position_m, z_lo, z_hi, _obstacles(b, bodies), com, support_inset_m(b))


def pad_blockers(b: Body, bodies: list[Body]) -> list[int]:
    """Indices of the bodies whose pieces reach into the pad under ``b`` (legs still to be made):
    :func:`_pad_blocked` asked of each other body alone."""
    return [k for k, o in enumerate(bodies) if o is not b and _pad_blocked(b, [b, o], legs_pending=True)]


def unsupport_blocked_pads(bodies: list[Body]) -> set[str]:
    """A body resting on the background whose pad would reach into another body (one placed
    after it in the support graph, e.g. overlapping it from the side) gets its pad cut back clear
    of it (``layout.background.clip_pad``, keeping its centre of mass over the pad); furniture on
    legs for which no cut does stands on legs down to the floor instead (a desk over a cabinet
    seen under it); only then is it left where it was seen (``UNSUPPORTED``), like any object
    with nothing under it; what rests on it then rests on the background. Called before the legs
    are made (``Body.legs_m`` still to come). Returns the names of the bodies now on the floor."""
    from layout.support import FLOOR, LEGS_MAX_DROP_M, STANDS_ON_LEGS

    to_floor = set()
    for b in bodies:
        if b.parent != BACKGROUND or not _pad_blocked(b, bodies, legs_pending=True):
            continue
        clipped = _clipped_pad(b, bodies, legs_pending=True)
        if clipped is not None:
            b.pad_rect_m = clipped
            continue
        if b.asset.label in STANDS_ON_LEGS and 0.0 < b.bottom_m <= LEGS_MAX_DROP_M:
            b.parent, b.support_surface, b.legs_m, b.pad_bottom_m, b.pad_rect_m, b.step_face = FLOOR, -1, b.bottom_m, None, None, None
            to_floor.add(b.name)
            continue
        b.parent = UNSUPPORTED
        b.unsupported_reason = BLOCKED_PAD_REASON
    return to_floor


def unsupport_in_walls(solver: Solver, max_push_m: float) -> None:
    """A movable (or wall-mounted) body reaching more than ``max_push_m`` into a wall would have
    to move that far to stand in the room: it is wall (a door, a radiator, a picture seen as an object, or a wall
    plane fitted a little off), left where it was seen as static background."""
    for k, b in enumerate(solver.bodies):
        if not len(solver.wall_n) or (b.fixed and not b.mounted) or b.parent == UNSUPPORTED:
            continue
        depth = -float(np.min(solver.wall_gaps(k)))
        if depth > max_push_m:
            b.parent = UNSUPPORTED
            b.unsupported_reason = f"reaches {depth * 100:.0f} cm into a wall"


def uncage_bodies(bodies: list[Body], absorbed: list[int], walls: tuple[Plane, ...], seen: dict[str, np.ndarray]) -> None:
    """Static bodies (``absorbed``, at their seen poses, as the background will hold them) whose
    collision cages a movable body get the pieces that hold it cut back (``layout.cage``); each
    records whom for (``Body.cut_for``)."""
    from layout.cage import CAGE_TRAVEL_M, uncage

    statics = set(absorbed)
    reach = CAGE_TRAVEL_M + 0.05
    for i, b in enumerate(bodies):
        if i in statics or b.asset.kind is AssetKind.DEFORMABLE:
            continue
        lo, hi = b.lo_rel_m + b.position_m - reach, b.hi_rel_m + b.position_m + reach
        near = []
        for k in sorted(statics):
            t = seen[bodies[k].name]
            pieces = [piece.vertices_m @ t[:3, :3].T + t[:3, 3] for part in bodies[k].asset.parts for piece in part.collision]
            if any(np.all(v.max(axis=0) > lo) and np.all(v.min(axis=0) < hi) for v in pieces):
                near.append(k)
        if not near:
            continue
        cut = uncage([p.verts_rel_m + b.position_m for p in b.pieces], [(bodies[k].asset, seen[bodies[k].name]) for k in near], walls,
                     float(np.arctan2(b.rotation[1, 0], b.rotation[0, 0])))
        for k, asset in zip(near, cut or ()):
            if asset is not bodies[k].asset:
                bodies[k].asset = asset
                bodies[k].cut_for.append(b.name)


def static_background(
    background: Background | None, bodies: list[Body], absorbed: list[int], walls: tuple[Plane, ...], seen: dict[str, np.ndarray]
) -> Background | None:
    """The background with the objects in ``absorbed`` (body indices) made part of it, a pad under
    every body resting on it, and the collision boxes of its observed structure carved clear of
    the remaining bodies."""
    if background is None:
        if not absorbed:
            return None
        # No observed surface (perception built none): the background holds just these objects.
        background = Background(TriangleMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)), np.zeros(0, dtype=bool))
    for k in absorbed:
        b = bodies[k]
        background = absorb(background, b.name, b.asset, seen[b.name])  # exactly where it was seen
    lo, hi = column_boxes(observed_structure(background, walls))
    movers = [b for k, b in enumerate(bodies) if k not in set(absorbed)]
    if movers:
        # Clear of every mover's pieces and of the room its doors swing and drawers slide in
        # (columns of the seen front of a cabinet stood 2 cm before its closed door).
        swept = [swept_part_boxes(b.asset, b.world_from_asset()) for b in movers]
        olo = np.concatenate([b.piece_lo_rel_m + b.position_m for b in movers] + [lo_ for lo_, _ in swept])
        ohi = np.concatenate([b.piece_hi_rel_m + b.position_m for b in movers] + [hi_ for _, hi_ in swept])
        lo, hi = carve(lo, hi, olo, ohi)
    centers = [(lo + hi) / 2.0]
    halves = [(hi - lo) / 2.0]
    yaws = [np.zeros(len(lo))]
    for b in movers:
        if b.parent != BACKGROUND:
            continue
        # The pad spans the object's whole plan extent (it rests on the surface seen around it,
        # hidden under all of it); unsupport_blocked_pads made sure nothing else was there, but
        # the pushes since may have moved a neighbour into it (a pillow pushed out from under a
        # bed's edge, sunrgbd_imvotenet_000005): it is cut back clear of it again.
        if _pad_blocked(b, bodies):
            clipped = _clipped_pad(b, bodies)
            if clipped is None:
                continue
            b.pad_rect_m = clipped
        c, h, yaw = pad_box(b, b.bottom_m)
        centers.append(c[None])
        halves.append(h[None])
        yaws.append(np.array([yaw]))
    return dataclasses.replace(
        background,
        box_centers_m=np.concatenate(centers),
        box_half_extents_m=np.concatenate(halves),
        box_yaws_rad=np.concatenate(yaws),
    )
