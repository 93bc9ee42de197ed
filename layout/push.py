"""The push probe: a force-limited pusher drives into one side of a movable object.

The pusher (``probe/pusher``, added by :func:`layout.probe_base.load_probe_model`) is a box
paddle on three slide joints driven by position servos limited to ``PUSHER_FORCE_N`` (100 N),
and it collides with everything: the pushed object, its neighbours, walls, the floor, the
background. It starts ``APPROACH_GAP_M`` behind the object's side and its commanded position
advances at ``PUSH_SPEED_M_S`` (never more than 1.25 x force limit / stiffness, 6 mm at 100 N,
ahead of the paddle: held back, it pushes with its full force and does not lunge when the object
breaks free) until the paddle has advanced ``PUSH_TRAVEL_M`` past first contact, or for ``STALL_S`` longer
than that would take, or once it has pressed at its force limit for ``HELD_S`` without advancing
``HELD_M``: an object too heavy for the force limit, or pushed against a neighbour or a wall,
stops it there. The paddle is then pulled back and parked, and the scene settles for
``POST_SETTLE_S``.

Direction (:func:`plan_push`): one of the four horizontal face directions of the object's body
frame; preferred, one with at least ``MIN_CLEARANCE_M`` of free space ahead (found by sliding its
collision geometry there), support under its centre of mass after the push, no neighbour beside
it that the push would drag, and room for the paddle behind it; among those the one with the
most free space. When no side has all of these the object is pushed anyway, toward its side with
room for the paddle and the most free space ahead, and the simulation says what happens.

Where (:func:`push_object`): on an upright face at the lowest height up to its centre of mass and
below the height at which the push would tip it over its leading bottom edge before it slides,
on the line through its centre of mass, else across its extent where the paddle meets it; the
first such start where the paddle touches nothing (smaller paddles are tried where a big one
does not fit). With no start free, the push fails: no room for the pusher behind it.

What is fair (:func:`push_failures`, the bar of issues 15 and 26): the object moves
``PUSH_MOVE_M`` (2-10 cm) and tilts at most ``PUSH_TILT_MAX_DEG``; every other object moves less
than ``OTHERS_MAX_M`` (1 cm) at any time, whether the object or the paddle touched it; objects
resting on the pushed one (directly or on each other, from the contacts at rest) may ride along
or stay where they are (a pillow pulled from under a sofa's overhang leaves the sofa), but must
not fall: none sinks more than ``CARRIED_DROP_M`` (5 cm) or tilts past ``layout.verify.TOPPLE_DEG``
(their slip relative to the pushed object is reported). A failure says why: no room for the
pusher, the pusher stopped by something else, blocked by what it was pushed against (the
largest force against the push), too heavy for the force limit (its weight times the friction
of its support against the limit), moved too far, tilted, others moved. Soft bodies (a flex) are
pushed and tracked too: their position is their vertices' centroid, they have no tilt, and their
start is found from their vertices (rays pass through a flex).
"""

from __future__ import annotations

import numpy as np

from layout.probe_base import (
    PARK_Z_M,
    PUSHER,
    PUSHER_FORCE_N,
    PUSHER_HALF_THICKNESS_M,
    PUSHER_JOINTS,
    PUSHER_KP_N_M,
    RIDER_NORMAL_Z,
    Objects,
    cast,
    points,
    settle,
    settled,
)
from scene_builder.errors import InputError
from scene_builder.model import PushPlan, PushResult

__all__ = ["plan_and_push", "plan_push", "push_failures", "push_object"]

PUSH_SPEED_M_S = 0.05
PUSH_TRAVEL_M = 0.06
LEAD_FACTOR = 1.25  # the commanded position runs at most this x (force limit / kp) ahead of the paddle
STALL_S = 1.0  # a push is given up this long after it should have finished
HELD_S = 0.5  # ... or once the paddle has pressed at its force limit this long without advancing
HELD_M = 0.003  # (this far)
APPROACH_M = 0.05  # the paddle gives up if it touches nothing this far past its start gap
WITHDRAW_S = 0.3
APPROACH_GAP_M = 0.01  # the pusher starts this far from the object's surface
PUSHER_ROOM_M = 0.04  # free space the paddle needs behind the object: its thickness, the gap, 1 cm
MIN_CLEARANCE_M = 0.10  # free space needed ahead: the push travel, the settle and a margin
CLEARANCE_CAP_M = 0.3  # free space is measured up to this far
CLEARANCE_STEP_M = 0.01
BLOCK_DEPTH_M = 0.002
DRAG_COS = 0.5  # a push must leave a side-touching neighbour at least 60 deg off its contact normal
NEAR_M = 0.01  # a neighbour this close beside an object counts as touching it (a push swerves;
# the layout leaves 2 mm between neighbours)
SUPPORT_DROP_M = 0.03  # a bottom point is supported by anything within this below it
SUPPORT_MARGIN_M = 0.03  # support is checked this much beyond the push travel
SUPPORT_INSET_M = 0.01  # the centre of mass must stay this far inside the support polygon
UPRIGHT_NZ = 0.3  # a face whose normal is within ~17 deg of horizontal is upright enough to push
POST_SETTLE_S = 1.0
RESIST_MIN_N = 5.0  # a contact pressing against the push with less than this does not block it
HIT_MIN_N = 1.0  # what the paddle touches with less than this is not reported
# What counts as a good push (``push_failures``; the bar).
PUSH_MOVE_M = (0.02, 0.10)
PUSH_TILT_MAX_DEG = 10.0
OTHERS_MAX_M = 0.01
CARRIED_DROP_M = 0.05
SIDES = ("front (+x)", "left (+y)", "back (-x)", "right (-y)")  # of the object's body frame


def _riders(m, d, objects: Objects, name: str) -> set[str]:
    """Objects resting on ``name``, directly or on each other (from the contacts at rest)."""
    on: dict[str, set[str]] = {}
    own = objects.contact_owners(d)
    movable = set(objects.names)
    for i in range(d.ncon):
        a, b = objects.owners[own[i, 0]], objects.owners[own[i, 1]]
        if a not in movable or b not in movable or a == b:
            continue
        nz = float(d.contact.frame[i, 2])  # contact normal, from side 0 toward side 1
        if nz > RIDER_NORMAL_Z:
            on.setdefault(a, set()).add(b)  # b rests on a
        elif nz < -RIDER_NORMAL_Z:
            on.setdefault(b, set()).add(a)
    out: set[str] = set()
    todo = [name]
    while todo:
        for r in sorted(on.get(todo.pop(), ())):
            if r not in out and r != name:
                out.add(r)
                todo.append(r)
    return out


def _face_directions(d, objects: Objects, name: str) -> list[np.ndarray]:
    """The four horizontal face directions of the body frame (+x, +y, -x, -y; unit, z = 0); of a
    soft body, its vertices' principal horizontal axes."""
    if name in objects.root:
        x = d.xmat[objects.root[name]].reshape(3, 3)[:, 0].copy()
    else:
        xy = objects.vertices(d, name)[:, :2]
        _, _, vt = np.linalg.svd(xy - xy.mean(axis=0), full_matrices=False)
        x = np.array([vt[0, 0], vt[0, 1], 0.0]) * (1.0 if vt[0, 0] + 1e-9 * vt[0, 1] >= 0 else -1.0)
    x[2] = 0.0
    if np.linalg.norm(x) < 1e-6:  # lying on its side: the world axes
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.array([-x[1], x[0], 0.0])
    return [x, y, -x, -y]


def _clearance(m, d, objects: Objects, movers: set[str], direction: np.ndarray) -> float:
    """Free space ahead along the horizontal unit ``direction``: the pushed object and what rides
    on it are slid there in CLEARANCE_STEP_M steps (kinematics and MuJoCo's own collision
    detection on a copy of the state, no dynamics) until one of their collision geoms reaches
    BLOCK_DEPTH_M into anything else with a contact normal more than 45 deg from vertical (a
    wall, the background, a neighbour: resting contacts on the floor or a support do not block).
    Exact for the real (non-convex, multi-piece) shapes, unlike rays over the front face."""
    import mujoco

    d2 = mujoco.MjData(m)
    d2.qpos[:] = d.qpos
    d2.mocap_pos[:] = d.mocap_pos
    d2.mocap_quat[:] = d.mocap_quat
    moving_ids = [objects.index[n] for n in sorted(movers)]
    s = 0.0
    while s < CLEARANCE_CAP_M - 1e-9:
        s = min(s + CLEARANCE_STEP_M, CLEARANCE_CAP_M)
        objects.shift(d2, d, sorted(movers), s * direction[:2])
        mujoco.mj_kinematics(m, d2)
        mujoco.mj_flex(m, d2)
        mujoco.mj_collision(m, d2)
        n = d2.ncon
        if not n:
            continue
        moving = np.isin(objects.contact_owners(d2), moving_ids)
        one_side = moving[:, 0] ^ moving[:, 1]
        lateral = np.abs(d2.contact.frame[:n, 2]) < RIDER_NORMAL_Z
        deep = d2.contact.dist[:n] < -BLOCK_DEPTH_M
        if np.any(one_side & lateral & deep):
            return s - CLEARANCE_STEP_M
    return CLEARANCE_CAP_M


def _touching(m, d, objects: Objects, name: str, riders: set[str]) -> list[tuple[str, np.ndarray]]:
    """Free objects beside ``name`` at rest (not riders): touching it, or within NEAR_M of its
    side (a push that swerves a little closes that gap and drags them by friction); (neighbour,
    horizontal unit normal from ``name`` toward it), one per contact or near pair of geoms."""
    import mujoco

    out = []
    own = objects.contact_owners(d)
    movable = set(objects.names)
    for i in range(d.ncon):
        if float(d.contact.dist[i]) > BLOCK_DEPTH_M or abs(float(d.contact.frame[i, 2])) >= RIDER_NORMAL_Z:
            continue
        a, b = objects.owners[own[i, 0]], objects.owners[own[i, 1]]
        if name not in (a, b) or a == b:
            continue
        other, n = (b, np.array(d.contact.frame[i, :3])) if a == name else (a, -np.array(d.contact.frame[i, :3]))
        if other not in movable or other in riders:
            continue
        n[2] = 0.0
        out.append((other, n / max(float(np.linalg.norm(n)), 1e-9)))
    mine = objects.geoms(name)
    others = [g for g in np.flatnonzero(objects.colliding) if objects.geom_object[g] not in ("", name) and objects.geom_object[g] not in riders]
    fromto = np.zeros(6)
    for g0 in mine:
        for g1 in others:
            gap = float(np.linalg.norm(d.geom_xpos[g0] - d.geom_xpos[g1])) - float(m.geom_rbound[g0] + m.geom_rbound[g1])
            if gap > NEAR_M:
                continue
            dist = mujoco.mj_geomDistance(m, d, int(g0), int(g1), NEAR_M, fromto)
            n = fromto[3:] - fromto[:3]
            if not 0.0 < dist <= NEAR_M or abs(n[2]) >= RIDER_NORMAL_Z * np.linalg.norm(n):
                continue
            n[2] = 0.0
            out.append((str(objects.geom_object[g1]), n / max(float(np.linalg.norm(n)), 1e-9)))
    return out


def _supported(m, d, objects: Objects, pts: np.ndarray, com: np.ndarray, shift: np.ndarray, accept) -> bool:
    """Whether the object would still stand with its points moved by ``shift``: rays down from
    its bottom points (those within 2 cm of its lowest, at most 256) find support within
    SUPPORT_DROP_M, and its centre of mass lies at least SUPPORT_INSET_M inside the convex hull
    of the supported ones (its support polygon)."""
    from scipy.spatial import ConvexHull, QhullError

    bottom = float(pts[:, 2].min())
    base = pts[pts[:, 2] < bottom + 0.02]
    if len(base) > 256:
        base = base[np.linspace(0, len(base) - 1, 256).astype(int)]
    down = np.array([0.0, 0.0, -1.0])
    held = [p[:2] + shift[:2] for p in base
            if np.isfinite(cast(m, d, objects, np.array([p[0] + shift[0], p[1] + shift[1], bottom + 0.01]), down, accept, cap=0.01 + SUPPORT_DROP_M))]
    if len(held) < 3:
        return False
    try:
        hull = ConvexHull(np.array(held))
    except QhullError:  # collinear: a knife edge
        return False
    c = com[:2] + shift[:2]
    return bool(np.all(hull.equations[:, :2] @ c + hull.equations[:, 2] <= -SUPPORT_INSET_M))


def _shape(m, d, objects: Objects, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) points of the object's collision geometry (a soft body's vertices, its radius
    around them ignored) and its centre of mass; (0, 3) points without collision geometry."""
    if name in objects.root:
        return points(m, d, objects.geoms(name)), d.subtree_com[objects.root[name]].copy()
    v = objects.vertices(d, name)
    return v.copy(), v.mean(axis=0)


def _plan(m, d, objects: Objects, name: str, riders: set[str], travel_m: float) -> PushPlan:
    pts, com = _shape(m, d, objects, name)
    if len(pts) == 0:
        return PushPlan(name, False, (0.0, 0.0), 0.0, "it has no collision geometry")
    skip = {name} | riders
    accept = lambda g: objects.geom_object[g] not in skip  # noqa: E731
    touching = _touching(m, d, objects, name, riders)
    tried = []
    for k, u in enumerate(_face_directions(d, objects, name)):
        clear = _clearance(m, d, objects, skip, u)
        behind = _clearance(m, d, objects, skip, -u)
        supported = _supported(m, d, objects, pts, com, (travel_m + SUPPORT_MARGIN_M) * u, accept)
        # a neighbour touching its side (or near it) is dragged along by friction unless the push leaves it
        dragged = sorted({n for n, normal in touching if float(normal @ u) > -DRAG_COS})
        if behind < PUSHER_ROOM_M:
            why = f"{behind * 100:.0f} cm behind it for the pusher"
        elif clear < MIN_CLEARANCE_M:
            why = f"{clear * 100:.0f} cm free"
        elif not supported:
            why = f"no support {(travel_m + SUPPORT_MARGIN_M) * 100:.0f} cm ahead"
        elif dragged:
            why = f"would drag {', '.join(dragged)} at (or within 1 cm of) its side"
        else:
            why = ""
        tried.append((behind < PUSHER_ROOM_M, -clear, k, u, clear, why))
    tried.sort(key=lambda t: (t[0], t[1], t[2]))
    for *_, u, clear, why in tried:
        if not why:
            return PushPlan(name, True, (float(u[0]), float(u[1])), float(clear))
    *_, u, clear, _ = tried[0]
    why = "no side to push it from: " + "; ".join(f"toward its {SIDES[t[2]]} {t[5]}" for t in sorted(tried, key=lambda t: t[2]))
    return PushPlan(name, False, (float(u[0]), float(u[1])), float(clear), why)


def plan_push(model, travel_m: float = PUSH_TRAVEL_M) -> tuple[PushPlan, ...]:
    """Push plans of every free object of ``model`` (a scene.xml path or a model from
    :func:`load_probe_model`), sorted by name, after ``PRE_SETTLE_S`` of settling."""
    m, d = settled(model, True)
    objects = Objects(m)
    return tuple(_plan(m, d, objects, n, _riders(m, d, objects, n), travel_m) for n in objects.names)


def _starts(m, d, objects: Objects, name: str, u: np.ndarray):
    """Where the paddle may meet the object, best first: (hit distance from ``back``, line,
    height, half width, half height, back) candidates (see the module docstring)."""
    perp = np.array([-u[1], u[0], 0.0])
    pts, com = _shape(m, d, objects, name)
    radius = float(m.flex_radius[objects.flex[name]]) if name in objects.flex else 0.0
    bottom, top = float(pts[:, 2].min()) - radius, float(pts[:, 2].max()) + radius
    lat = pts @ perp
    half_w = float(np.clip(0.3 * (lat.max() - lat.min()), 0.01, 0.05))
    half_h = float(np.clip(0.25 * (top - bottom), 0.01, 0.04))
    # At most half the height at which a push would tip it over its leading bottom edge before
    # it slides (it tips when height x friction > the lever of its weight), as a robot pushes a
    # tall cabinet low. Rays over the paddle's face from behind the object find where it first
    # meets it; a sloped face wedges the object against its support instead of sliding it.
    base_pts = pts[pts[:, 2] < bottom + 0.02]
    lever = max(float((base_pts @ u).max() - com @ u), 0.0)
    mu = float(np.max(m.geom_friction[objects.colliding, 0]))
    low, high = bottom + half_h + 0.005, max(bottom + half_h + 0.005, top - half_h)
    z_top = float(np.clip(min(com[2], bottom + 0.5 * lever / mu), low, high))
    back = float((pts @ u).min()) - radius - 0.05
    target = set(int(g) for g in objects.geoms(name))
    n_out = np.zeros(3)
    heights = [(float(zc), False) for zc in (np.linspace(low, z_top, 5) if z_top > low + 1e-3 else [low])]
    heights += [(float(zc), True) for zc in np.linspace(z_top, high, 6)[1:] if high > z_top + 1e-3]  # legs missed below
    # lines: through the centre of mass, the middle of its extent, then across its extent nearest
    # the centre first (a table whose collision is only its legs has nothing on the middle lines)
    across = np.linspace(float(lat.min()) + half_w, float(lat.max()) - half_w, 7) if lat.max() - lat.min() > 2 * half_w else []
    lines = [float(com @ perp), float(np.median(lat))] + sorted((float(v) for v in across), key=lambda v: (abs(v - float(com @ perp)), v))
    sizes = [(half_w, half_h)]
    while sizes[-1][0] > 0.0101 or sizes[-1][1] > 0.0101:
        sizes.append((max(0.01, 0.5 * sizes[-1][0]), max(0.01, 0.5 * sizes[-1][1])))
    found = []  # ((not upright, above the tipping height, line index, height index), hit, line, z)
    done = 0
    for li, lv in enumerate(lines):
        for zi, (zc, above) in enumerate(heights):
            if radius > 0.0:  # a soft body: its vertices within the paddle's face, the flex radius around them
                window = (np.abs(pts @ perp - lv) <= half_w + radius) & (np.abs(pts[:, 2] - zc) <= half_h + radius)
                if window.any():
                    found.append(((False, above, li, zi), float((pts[window] @ u).min()) - radius - back, lv, zc))
                continue
            hits = []
            for dl in np.linspace(-half_w, half_w, 5):
                for dz in np.linspace(-half_h, half_h, 9):  # rows 1 cm apart: a thin table top falls between coarser ones
                    origin = back * u + (lv + dl) * perp + np.array([0.0, 0.0, zc + dz])
                    t = cast(m, d, objects, origin, u, lambda g: g in target, cap=5.0, normal=n_out)
                    if np.isfinite(t):
                        hits.append((t, abs(float(n_out[2]))))
            if not hits:
                continue
            first = min(t for t, _ in hits)
            slope = max(nz for t, nz in hits if t < first + 0.005)
            found.append(((slope > UPRIGHT_NZ, above, li, zi), first, lv, zc))
        # The best starts (upright, below the tipping height) of the lines so far come before any
        # of a later line: try them before casting the rays of the next line.
        good = sorted(f for f in found if not f[0][0] and not f[0][1])
        for _, hit, line, z in good[done:]:
            for w, h in sizes:
                yield hit, line, z, w, h, back
        done = len(good)
    for _, hit, line, z in sorted(f for f in found if f[0][0] or f[0][1]):
        for w, h in sizes:
            yield hit, line, z, w, h, back


def _place_pusher(m, d, objects: Objects, ids: dict, name: str, u: np.ndarray, candidate) -> tuple[np.ndarray | None, float, list[str]]:
    """Put the paddle at ``candidate``'s start, backed off until it does not touch the object;
    (its start, how far it backed off, []) when it touches nothing else there, else (None, 0,
    what it overlaps)."""
    import mujoco

    hit, line, z, w, h, back = candidate
    perp = np.array([-u[1], u[0], 0.0])
    pg = objects.pusher_geom
    m.geom_size[pg] = [PUSHER_HALF_THICKNESS_M, w, h]
    m.geom_aabb[pg] = [0.0, 0.0, 0.0, PUSHER_HALF_THICKNESS_M, w, h]
    m.geom_rbound[pg] = float(np.linalg.norm(m.geom_size[pg]))
    start = (back + hit - APPROACH_GAP_M - PUSHER_HALF_THICKNESS_M) * u + line * perp + np.array([0.0, 0.0, z])
    # The rays sample the paddle's face: a part of the object between them (a panel of an open
    # shelf) may still reach into it there. Back off until it touches the object nowhere.
    for k in range(int(round(0.3 / APPROACH_GAP_M))):
        m.body_pos[ids["body"]] = start
        d.qpos[ids["qpos"]] = 0.0
        mujoco.mj_kinematics(m, d)
        mujoco.mj_flex(m, d)
        mujoco.mj_collision(m, d)
        g = d.contact.geom[: d.ncon]
        own = objects.contact_owners(d)
        mine = (g[:, 0] == pg) | (g[:, 1] == pg)
        others = np.where(g[:, 0] == pg, own[:, 1], own[:, 0])[mine]
        if not (others == objects.index[name]).any():
            return (start, k * APPROACH_GAP_M, []) if not len(others) else (None, 0.0, sorted({objects.owners[o] for o in others}))
        start = start - APPROACH_GAP_M * u
    return None, 0.0, [name]


def push_object(model, name: str, direction_xy=None, travel_m: float = PUSH_TRAVEL_M, speed_m_s: float = PUSH_SPEED_M_S,
                force_n: float = PUSHER_FORCE_N) -> PushResult:
    """Push free object ``name`` of ``model`` (a scene.xml path or a model from
    :func:`load_probe_model`) ``travel_m`` past first contact at ``speed_m_s`` with at most
    ``force_n`` along ``direction_xy`` (default: the direction :func:`plan_push` picks, pushable
    or not) and measure what moved (:class:`~scene_builder.model.PushResult`)."""
    m, d = settled(model, True)
    return _push(m, d, Objects(m), name, direction_xy, travel_m, speed_m_s, force_n)


def plan_and_push(model, travel_m: float = PUSH_TRAVEL_M, force_n: float = PUSHER_FORCE_N) -> tuple[tuple[PushPlan, ...], tuple[PushResult, ...]]:
    """:func:`plan_push` and a push of every free object in its planned direction (whether the
    planner found a good side or not) with at most ``force_n``, each from the same settled state
    (settled once)."""
    import copy

    m, d0 = settled(model, True)
    objects = Objects(m)
    plans = tuple(_plan(m, d0, objects, n, _riders(m, d0, objects, n), travel_m) for n in objects.names)
    pushes = tuple(_push(m, copy.copy(d0), objects, p.name, p.direction_xy if p.direction_xy != (0.0, 0.0) else (1.0, 0.0), travel_m,
                         force_n=force_n) for p in plans)
    return plans, pushes


def _push(m, d, objects: Objects, name: str, direction_xy, travel_m: float = PUSH_TRAVEL_M, speed_m_s: float = PUSH_SPEED_M_S,
          force_n: float = PUSHER_FORCE_N) -> PushResult:
    import mujoco

    if name not in objects.names:
        raise InputError(f"interaction probe: no free object {name!r} in the model (free objects: {', '.join(objects.names) or 'none'})")
    riders = _riders(m, d, objects, name)
    has_shape = len(_shape(m, d, objects, name)[0]) > 0
    movers = {name} | riders
    mass = float(sum(objects.mass(m, n) for n in movers))
    if direction_xy is None:
        plan = _plan(m, d, objects, name, riders, travel_m)
        u = np.array([plan.direction_xy[0], plan.direction_xy[1], 0.0])
        clearance = plan.clearance_m
    else:
        u = np.array([float(direction_xy[0]), float(direction_xy[1]), 0.0])
        if np.linalg.norm(u) < 1e-9:
            raise InputError("interaction probe: the push direction is zero")
        u /= np.linalg.norm(u)
        clearance = _clearance(m, d, objects, movers, u) if has_shape else 0.0
    # Its weight times the friction of what it rests on (MuJoCo's combined coefficient of its
    # resting contacts): what a push must overcome to slide it.
    moving = np.isin(objects.contact_owners(d), [objects.index[n] for n in movers])
    mu = [float(d.contact.friction[i, 0]) for i in range(d.ncon)
          if moving[i].sum() == 1 and abs(float(d.contact.frame[i, 2])) > RIDER_NORMAL_Z]
    common = dict(name=name, direction_xy=(float(u[0]), float(u[1])), clearance_m=float(clearance), speed_m_s=float(speed_m_s),
                  force_limit_n=float(force_n), mass_kg=mass, slide_force_n=mass * 9.81 * max(mu) if mu else float("nan"))
    if not has_shape:
        return PushResult(**common, height_m=float("nan"), pusher_travel_m=0.0, displacement_m=0.0, along_m=0.0, tilt_deg=0.0,
                          toppled=False, not_started="it has no collision geometry")

    ids = _pusher_ids(m)
    saved = (m.geom_size[objects.pusher_geom].copy(), m.geom_aabb[objects.pusher_geom].copy(), float(m.geom_rbound[objects.pusher_geom]),
             m.body_pos[ids["body"]].copy(), m.body_quat[ids["body"]].copy(), m.actuator_forcerange[ids["act"]].copy())
    yaw = float(np.arctan2(u[1], u[0]))
    m.body_quat[ids["body"]] = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
    m.actuator_forcerange[ids["act"]] = [-force_n, force_n]
    qpos0, qvel0 = d.qpos.copy(), d.qvel.copy()
    try:
        start, overlaps, z, backed = None, [], float("nan"), 0.0
        for candidate in _starts(m, d, objects, name, u):
            start, backed, why = _place_pusher(m, d, objects, ids, name, u, candidate)
            if start is not None:
                z = candidate[2]
                break
            overlaps = overlaps or why
        d.qpos[:], d.qvel[:] = qpos0, qvel0
        if start is None:
            m.body_pos[ids["body"]] = saved[3]
            mujoco.mj_forward(m, d)
            what = f": the paddle overlaps {', '.join(overlaps)}" if overlaps else ": the paddle meets it nowhere"
            return PushResult(**common, height_m=z, pusher_travel_m=0.0, displacement_m=0.0, along_m=0.0, tilt_deg=0.0, toppled=False,
                              not_started="no room for the pusher behind it" + what)
        m.body_pos[ids["body"]] = start
        d.qpos[ids["qpos"]] = 0.0
        d.qvel[ids["dof"]] = 0.0
        d.ctrl[ids["act"]] = 0.0
        mujoco.mj_forward(m, d)
        run = _run_push(m, d, objects, ids, name, movers, u, travel_m, speed_m_s, APPROACH_GAP_M + backed + APPROACH_M,
                        LEAD_FACTOR * force_n / PUSHER_KP_N_M)
    finally:
        (m.geom_size[objects.pusher_geom], m.geom_aabb[objects.pusher_geom], m.geom_rbound[objects.pusher_geom],
         m.body_pos[ids["body"]], m.body_quat[ids["body"]], m.actuator_forcerange[ids["act"]]) = saved
    from layout.verify import TOPPLE_DEG, _tilt_deg

    mujoco.mj_forward(m, d)
    now = {n: objects.position(d, n) for n in movers}
    delta = now[name] - run["base"][name]

    def tilt_of(n: str) -> float:  # a soft body has no frame to tilt: 0
        return _tilt_deg(run["quat"][n], d.xquat[objects.root[n]].copy()) if n in objects.root else 0.0

    tilt = tilt_of(name)
    others = tuple((n, run["moved"][n]) for n in objects.names if n not in movers)
    carried = tuple((n, float(np.linalg.norm((now[n] - run["base"][n])[:2]))) for n in sorted(riders))
    slip = tuple((n, float(np.linalg.norm((now[n] - run["base"][n] - delta)[:2]))) for n in sorted(riders))
    return PushResult(
        **common,
        height_m=z,
        pusher_travel_m=run["travelled"],
        touched=run["touched"],
        displacement_m=float(np.linalg.norm(delta[:2])),
        along_m=float(delta[:2] @ u[:2]),
        tilt_deg=tilt,
        toppled=bool(tilt > TOPPLE_DEG),
        carried=carried,
        others=others,
        max_other_m=max([v for _, v in others], default=0.0),
        max_force_n=run["max_force"],
        stalled=run["stalled"],
        resisted_by=tuple(sorted(run["resist"].items(), key=lambda kv: (-kv[1], kv[0]))),
        pusher_hit=tuple(sorted(((k, v) for k, v in run["hit"].items() if v >= HIT_MIN_N), key=lambda kv: (-kv[1], kv[0]))),
        carried_slip=slip,
        carried_drop=tuple((n, float(run["base"][n][2] - now[n][2])) for n in sorted(riders)),
        carried_tilt=tuple((n, tilt_of(n)) for n in sorted(riders)),
    )


def _pusher_ids(m) -> dict:
    import mujoco

    body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, PUSHER)
    joints = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{PUSHER}/{j}") for j in PUSHER_JOINTS]
    return dict(body=body, qpos=np.array([int(m.jnt_qposadr[j]) for j in joints]), dof=np.array([int(m.jnt_dofadr[j]) for j in joints]),
                act=np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"{PUSHER}/{j}") for j in PUSHER_JOINTS]))


def _run_push(m, d, objects: Objects, ids: dict, name: str, movers: set[str], u: np.ndarray, travel_m: float, speed_m_s: float,
              approach: float, lead_m: float) -> dict:
    """Drive the paddle from its start (see the module docstring), pull it back, park it, settle;
    what moved, what the paddle touched and what pressed against the push."""
    import mujoco

    pg = objects.pusher_geom
    me = objects.index[name]
    mover_ids = [objects.index[n] for n in movers]
    base = {n: objects.position(d, n) for n in objects.names}
    quat = {n: d.xquat[b].copy() for n, b in objects.root.items()}
    moved = {n: 0.0 for n in objects.names}
    resist: dict[str, float] = {}
    hit: dict[str, float] = {}
    f6 = np.zeros(6)
    qa, act = int(ids["qpos"][0]), int(ids["act"][0])
    dt = float(m.opt.timestep)

    def track() -> None:
        for n in objects.names:
            moved[n] = max(moved[n], float(np.linalg.norm(objects.position(d, n) - base[n])))

    def forces() -> bool:
        """Record the paddle's contacts and what presses against the push; True when the paddle
        touches the object."""
        n = d.ncon
        if not n:
            return False
        g = d.contact.geom[:n]
        own = objects.contact_owners(d)
        mover = np.isin(own, mover_ids)
        paddle = (g[:, 0] == pg) | (g[:, 1] == pg)
        side = ~paddle & (mover[:, 0] != mover[:, 1]) & (np.abs(d.contact.frame[:n, 2]) < RIDER_NORMAL_Z)
        touched = False
        for i in np.flatnonzero(paddle):
            other = int(own[i, 1] if g[i, 0] == pg else own[i, 0])
            if other == me:
                touched = True
                continue
            mujoco.mj_contactForce(m, d, int(i), f6)
            who = objects.owners[other]
            hit[who] = max(hit.get(who, 0.0), float(f6[0]))
        for i in np.flatnonzero(side):
            mujoco.mj_contactForce(m, d, int(i), f6)
            on_1 = d.contact.frame[i].reshape(3, 3).T @ f6[:3]  # what side 0 exerts on side 1, world frame
            on_mover = on_1 if mover[i, 1] else -on_1
            who = objects.owners[int(own[i, 0] if mover[i, 1] else own[i, 1])]
            resist[who] = max(resist.get(who, 0.0), float(-on_mover @ u))
        return touched

    ref, t, contact_at, t_contact, max_force = 0.0, 0.0, None, 0.0, 0.0
    limit = float(m.actuator_forcerange[act, 1])
    held_since, held_q = None, 0.0  # when (and where) the paddle last began pressing at its limit
    while True:
        q = float(d.qpos[qa])
        ref = min(ref + speed_m_s * dt, q + lead_m)
        d.ctrl[act] = ref
        mujoco.mj_step(m, d)
        t += dt
        track()
        max_force = max(max_force, abs(float(d.actuator_force[act])))
        if forces() and contact_at is None:
            contact_at, t_contact = float(d.qpos[qa]), t
        q = float(d.qpos[qa])
        if abs(float(d.actuator_force[act])) < 0.98 * limit or (held_since is not None and q - held_q > HELD_M):
            held_since = None
        elif held_since is None:
            held_since, held_q = t, q
        if held_since is not None and t - held_since >= HELD_S:
            break
        if contact_at is None and (q > approach or t > approach / speed_m_s + STALL_S):
            break
        if contact_at is not None and (q - contact_at >= travel_m or t - t_contact > travel_m / speed_m_s + STALL_S):
            break
    travelled = 0.0 if contact_at is None else float(d.qpos[qa]) - contact_at
    d.ctrl[act] = float(d.qpos[qa]) - 0.05  # pulled back 5 cm, then parked above the scene
    settle(m, d, WITHDRAW_S, track)
    m.body_pos[ids["body"]] = [0.0, 0.0, PARK_Z_M]
    d.qpos[ids["qpos"]] = 0.0
    d.qvel[ids["dof"]] = 0.0
    d.ctrl[ids["act"]] = 0.0
    settle(m, d, POST_SETTLE_S, track)
    return dict(base=base, quat=quat, moved=moved, travelled=travelled, touched=contact_at is not None, max_force=max_force, resist=resist, hit=hit,
                stalled=contact_at is not None and travelled < travel_m - 0.005)


def push_failures(r: PushResult) -> tuple[str, ...]:
    """Why a push misses the bar (see the module docstring); empty when it passes."""
    from layout.verify import TOPPLE_DEG

    if r.not_started:
        return (r.not_started,)
    out = []
    moved = f"moved {r.displacement_m * 100:.1f} cm"
    if not r.touched:
        stop = [n for n, _ in r.pusher_hit]
        out.append(f"the pusher was stopped by {', '.join(stop)} before it touched it" if stop else "the pusher never touched it")
    elif r.displacement_m < PUSH_MOVE_M[0]:
        block = [(n, f) for n, f in r.resisted_by if f >= RESIST_MIN_N]
        ahead = f"; {r.clearance_m * 100:.0f} cm free ahead" if r.clearance_m < MIN_CLEARANCE_M else ""
        if r.stalled and block:
            out.append(f"blocked by {block[0][0]} ({block[0][1]:.0f} N against the push; {moved} under {r.force_limit_n:.0f} N)")
        elif r.stalled and np.isfinite(r.slide_force_n) and r.slide_force_n >= 0.8 * r.force_limit_n:
            out.append(f"too heavy for {r.force_limit_n:.0f} N: sliding it takes about {r.slide_force_n:.0f} N ({r.mass_kg:.0f} kg; {moved}{ahead})")
        elif r.stalled:
            out.append(f"stuck under {r.force_limit_n:.0f} N ({moved}; sliding it should take about {r.slide_force_n:.0f} N{ahead})")
        else:
            out.append(f"{moved} (expected {PUSH_MOVE_M[0] * 100:.0f}-{PUSH_MOVE_M[1] * 100:.0f} cm)")
    elif r.displacement_m > PUSH_MOVE_M[1]:
        out.append(f"{moved} (expected {PUSH_MOVE_M[0] * 100:.0f}-{PUSH_MOVE_M[1] * 100:.0f} cm)")
    if r.toppled or r.tilt_deg > PUSH_TILT_MAX_DEG:
        out.append(f"{'toppled' if r.toppled else 'tilted'} ({r.tilt_deg:.0f} deg)")
    hit = {n for n, _ in r.pusher_hit}
    for n, v in sorted(r.others, key=lambda o: (-o[1], o[0])):
        if v >= OTHERS_MAX_M:
            out.append(f"{n} moved {v * 100:.1f} cm too" + (" (the pusher hit it)" if n in hit else ""))
    tilts = dict(r.carried_tilt)
    for n, drop in r.carried_drop:
        if drop > CARRIED_DROP_M or tilts.get(n, 0.0) > TOPPLE_DEG:
            out.append(f"{n}, resting on it, fell ({drop * 100:.1f} cm lower, tilted {tilts.get(n, 0.0):.0f} deg)")
    return tuple(out)
