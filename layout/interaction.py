"""Interaction probes on the exported MJCF: a force-limited push of every movable object and
doors / drawers pulled open.

What a robot would do first with a twin: push an object a few centimetres and open a door. Both
run in MuJoCo on ``scene.xml`` as written (naming conventions of DEVELOPERS.md: root body ``NAME``
with free joint ``NAME/free``, articulation joints ``NAME/PART/joint``, collision geoms in
group 3), after a short settle (``PRE_SETTLE_S``) so that every measurement starts from rest.

Push (:mod:`layout.push`: :func:`plan_push`, :func:`push_object`, :func:`push_failures`): a paddle
on slide joints driven by position servos limited to 100 N, colliding with everything, driven at
5 cm/s into one side of each movable object, 6 cm past first contact. Every movable object is
pushed; one that cannot be (no room for the pusher, blocked by a neighbour or a wall, too heavy
for the force limit) is a failure with its reason.

Door / drawer (:func:`open_joint`): a pull at the handle (the part's ``*handle`` child body, else
its edge farthest from the hinge axis), tangential to the swing for a hinge and along the axis
for a slide, applied through ``xfrc_applied``; like a hand it pulls with at most ``force_n`` and
eases off above ``PULL_SPEED`` (so it neither slams the part into its stop nor lets go while
the part is slow). Measured: travel, backtracking, excursion beyond the joint range, and how far
the carcass moved.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from layout.probe_base import PRE_SETTLE_S, PUSHER, PUSHER_FORCE_N, Objects, as_model, load_probe_model, points, settle, settled
from layout.push import PUSH_MOVE_M, PUSH_SPEED_M_S, PUSH_TRAVEL_M, MIN_CLEARANCE_M, plan_and_push, plan_push, push_failures, push_object
from scene_builder.errors import InputError
from scene_builder.model import JointProbe, PushPlan, PushResult

__all__ = [
    "FULL_OPEN_FRACTION", "MIN_CLEARANCE_M", "PRE_SETTLE_S", "PUSHER", "PUSHER_FORCE_N", "PUSH_MOVE_M", "PUSH_SPEED_M_S", "PUSH_TRAVEL_M",
    "fixed_objects", "interaction_problems", "joint_summary", "opens_fully", "joint_names", "load_probe_model", "open_joint", "plan_push", "probe_lines", "probe_scene",
    "push_failures", "push_object",
]

PULL_N = 10.0  # a hand's pull; raised for joints that need more (friction, gravity: see _pull_force)
PULL_SPEED = {"hinge": 1.0, "slide": 0.25}  # rad/s, m/s: the hand pulls at most this fast
PULL_S = 3.0
#: The pull is strong enough to open the joint's whole range in this share of PULL_S against its
#: damping (``_pull_force``), and lasts at least this many times what the range takes at the
#: hand's speed (the hand eases off towards PULL_SPEED).
OPEN_WITHIN_PULL = 0.5
PULL_TIME_MARGIN = 2.0
RELEASE_S = 0.5
# What counts as a good opening (``interaction_problems``; the bar).
OPEN_MIN_FRACTION = 0.5
LIMIT_TOLERANCE = {"hinge": np.radians(2.0), "slide": 0.005}
BACKTRACK_TOLERANCE = {"hinge": np.radians(1.0), "slide": 0.002}
CARCASS_MAX_M = 0.01
#: A door or drawer opens *fully* when it travels this share of its range (within LIMIT_TOLERANCE
#: of its limits, its carcass still): the measure of issue 24's probe over every built front.
FULL_OPEN_FRACTION = 0.9


def joint_names(model) -> tuple[str, ...]:
    """Names of the articulation joints (hinge or slide, limited, named ``NAME/PART/joint``)."""
    import mujoco

    m = as_model(model, False)
    kinds = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    return tuple(sorted(
        m.joint(j).name for j in range(m.njnt)
        if int(m.jnt_type[j]) in kinds and m.joint(j).name.endswith("/joint") and m.joint(j).name.count("/") >= 2 and m.jnt_limited[j]
    ))


def _subtree(m, body: int) -> list[int]:
    out = []
    for b in range(m.nbody):
        a = b
        while a > 0 and a != body:
            a = int(m.body_parentid[a])
        if a == body:
            out.append(b)
    return out


def _handle_local(m, d, objects: Objects, jid: int, body: int, kind: str) -> np.ndarray:
    """The pull point in the part's body frame: its handle's centre of mass, else (hinge) the
    middle of its edge farthest from the axis, else (slide) its centre of mass."""
    rot, pos = d.xmat[body].reshape(3, 3), d.xpos[body]
    handles = [b for b in _subtree(m, body) if b != body and "handle" in m.body(b).name.rsplit("/", 1)[-1]]
    if handles:
        p = d.xipos[sorted(handles, key=lambda b: m.body(b).name)[0]]
    elif kind == "hinge":
        geoms = np.flatnonzero((m.geom_bodyid == body) & objects.colliding)
        pts = points(m, d, geoms) if len(geoms) else d.xipos[body][None]
        a, anchor = d.xaxis[jid], d.xanchor[jid]
        r = pts - anchor
        dist = np.linalg.norm(r - np.outer(r @ a, a), axis=1)
        p = pts[dist >= 0.95 * dist.max()].mean(axis=0)
    else:
        p = d.xipos[body]
    return rot.T @ (np.asarray(p) - pos)


def _pull_force(m, d, jid: int, body: int, kind: str, p: np.ndarray, span: float) -> float:
    """PULL_N, or 1.5 x what the joint resists at the pull point: its dry friction, the part's
    weight, and its damping at the speed that opens ``span`` (the joint's travel to its far
    limit) in OPEN_WITHIN_PULL of the pull (a 12 kg oven drawer damped at 25 N s/m crept 58 %
    of its 0.58 m under 10 N: a hand pulls a heavy drawer harder)."""
    a = d.xaxis[jid]
    dof = int(m.jnt_dofadr[jid])
    weight = float(m.body_subtreemass[body]) * 9.81
    friction = float(m.dof_frictionloss[dof])
    viscous = float(m.dof_damping[dof]) * min(PULL_SPEED[kind], span / (OPEN_WITHIN_PULL * PULL_S))
    if kind == "slide":
        need = friction + viscous + weight * abs(float(a[2]))
    else:
        r = p - d.xanchor[jid]
        lever = max(float(np.linalg.norm(r - (r @ a) * a)), 1e-3)
        rc = d.subtree_com[body] - d.xanchor[jid]
        com_lever = float(np.linalg.norm(rc - (rc @ a) * a))
        need = (friction + viscous + weight * com_lever * float(np.sqrt(max(0.0, 1.0 - a[2] ** 2)))) / lever
    return max(PULL_N, 1.5 * need)


def open_joint(model, joint: str, force_n: float | None = None, pull_s: float | None = None, release_s: float = RELEASE_S) -> JointProbe:
    """Pull articulation ``joint`` (``NAME/PART/joint``) of ``model`` (a scene.xml path or an
    MjModel) open for ``pull_s`` seconds, release it for ``release_s``, and measure its motion
    (:class:`~scene_builder.model.JointProbe`). ``force_n`` defaults to :func:`_pull_force`;
    ``pull_s`` to PULL_S, or PULL_TIME_MARGIN times what the joint's range takes at the hand's
    speed when that is longer (a 0.58 m oven drawer)."""
    import mujoco

    m, d = settled(model, False)
    jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint)
    if jid < 0:
        raise InputError(f"interaction probe: no joint {joint!r} in the model (articulation joints: {', '.join(joint_names(m)) or 'none'})")
    jt = int(m.jnt_type[jid])
    kind = {int(mujoco.mjtJoint.mjJNT_HINGE): "hinge", int(mujoco.mjtJoint.mjJNT_SLIDE): "slide"}.get(jt)
    if kind is None or not m.jnt_limited[jid]:
        raise InputError(f"interaction probe: joint {joint!r} is not a limited hinge or slide joint")
    objects = Objects(m)
    body = int(m.jnt_bodyid[jid])
    root = int(m.body_rootid[body])
    lo, hi = (float(v) for v in m.jnt_range[jid])
    adr, dof = int(m.jnt_qposadr[jid]), int(m.jnt_dofadr[jid])
    q0 = float(d.qpos[adr])
    sign = 1.0 if hi - q0 >= q0 - lo else -1.0
    local = _handle_local(m, d, objects, jid, body, kind)
    p0 = d.xpos[body] + d.xmat[body].reshape(3, 3) @ local
    span = abs((hi if sign > 0 else lo) - q0)  # travel to the far limit
    force = float(force_n) if force_n is not None else _pull_force(m, d, jid, body, kind, p0, span)
    vcap = PULL_SPEED[kind]
    if pull_s is None:
        pull_s = max(PULL_S, PULL_TIME_MARGIN * span / vcap)
    base = d.xpos[root].copy()
    times, qs, carcass = [float(d.time)], [q0], [0.0]

    def record() -> None:
        times.append(float(d.time))
        qs.append(float(d.qpos[adr]))
        carcass.append(float(np.linalg.norm(d.xpos[root] - base)))

    def pull() -> None:
        p = d.xpos[body] + d.xmat[body].reshape(3, 3) @ local
        if kind == "slide":
            direction = sign * d.xaxis[jid]
        else:
            r = p - d.xanchor[jid]
            t = np.cross(d.xaxis[jid], r)
            direction = sign * t / max(float(np.linalg.norm(t)), 1e-9)
        v = sign * float(d.qvel[dof])
        f = force * float(np.clip(2.0 * (1.0 - v / vcap), 0.0, 1.0)) * direction
        d.xfrc_applied[body, :3] = f
        d.xfrc_applied[body, 3:] = np.cross(p - d.xipos[body], f)

    steps = int(round(pull_s / float(m.opt.timestep)))
    for _ in range(steps):
        pull()
        mujoco.mj_step(m, d)
        record()
    n_pull = len(qs)
    d.xfrc_applied[body] = 0.0
    settle(m, d, release_s, record)
    q = np.array(qs)
    s = sign * q[:n_pull]
    travel = float(s[-1] - sign * q0)
    return JointProbe(
        joint=joint,
        object=joint.split("/")[0],
        kind=kind,
        range=(lo, hi),
        start=q0,
        open_sign=sign,
        force_n=force,
        travel=travel,
        open_fraction=travel / span if span > 0 else 0.0,
        backtrack=float(np.max(np.maximum.accumulate(s) - s)),
        limit_violation=float(max(0.0, np.max(lo - q), np.max(q - hi))),
        final=float(q[-1]),
        body_displacement_m=float(max(carcass)),
        times_s=np.array(times),
        positions=q,
    )


def interaction_problems(pushes: tuple[PushResult, ...] = (), joints: tuple[JointProbe, ...] = ()) -> tuple[str, ...]:
    """One line per probe that misses the bar: a push fails for the reasons of
    :func:`layout.push.push_failures` (its object moves 2-10 cm, tilts at most 10 deg, every other
    object moves under 1 cm, what rides on it stays; no room for the pusher, blocked, too heavy);
    a joint opens at least OPEN_MIN_FRACTION of its range without backtracking, stays within its
    range (LIMIT_TOLERANCE) and its carcass moves under CARCASS_MAX_M (1 cm)."""
    out = [f"push {p.name}: {why}" for p in pushes for why in push_failures(p)]
    for j in joints:
        unit = lambda v, k=j.kind: _joint_unit(k, v)  # noqa: E731
        if j.open_fraction < OPEN_MIN_FRACTION:
            out.append(f"open {j.joint}: opened {unit(j.travel)} ({j.open_fraction:.0%} of its range)")
        if j.backtrack > BACKTRACK_TOLERANCE[j.kind]:
            out.append(f"open {j.joint}: went back {unit(j.backtrack)} while pulled")
        if j.limit_violation > LIMIT_TOLERANCE[j.kind]:
            out.append(f"open {j.joint}: {unit(j.limit_violation)} beyond its range")
        if j.body_displacement_m >= CARCASS_MAX_M:
            out.append(f"open {j.joint}: {j.object} moved {j.body_displacement_m * 100:.1f} cm")
    return tuple(out)


def opens_fully(j: JointProbe) -> bool:
    """Whether a pulled door or drawer opened fully: FULL_OPEN_FRACTION of its range, without
    backtracking, within its limits (LIMIT_TOLERANCE) and with its carcass still (CARCASS_MAX_M)."""
    return (j.open_fraction >= FULL_OPEN_FRACTION and j.backtrack <= BACKTRACK_TOLERANCE[j.kind]
            and j.limit_violation <= LIMIT_TOLERANCE[j.kind] and j.body_displacement_m < CARCASS_MAX_M)


def fixed_objects(model) -> tuple[str, ...]:
    """Names of the objects of a scene model welded to the room (root body ``NAME`` of the world
    with no ``NAME/free`` joint: built-in runs and fixed furniture), sorted."""
    import mujoco

    m = as_model(model, False)
    free = {m.joint(j).name for j in range(m.njnt) if int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE)}
    names = {m.body(b).name for b in range(1, m.nbody) if int(m.body_parentid[b]) == 0}
    return tuple(sorted(n for n in names if n and "/" not in n and f"{n}/free" not in free))


def joint_summary(joints: tuple[JointProbe, ...], fixed: tuple[str, ...] = ()) -> dict[str, int]:
    """How many of the pulled doors and drawers opened fully (:func:`opens_fully`), over all and
    over those of ``fixed`` objects (built-ins)."""
    on_fixed = [j for j in joints if j.object in set(fixed)]
    return {"joints": len(joints), "opened_fully": sum(opens_fully(j) for j in joints),
            "fixed_joints": len(on_fixed), "fixed_opened_fully": sum(opens_fully(j) for j in on_fixed)}


def probe_scene(mjcf_path: Path, force_n: float = PUSHER_FORCE_N) -> tuple[tuple[PushPlan, ...], tuple[PushResult, ...], tuple[JointProbe, ...]]:
    """Every probe of a scene: the push plan of each free object and a push of each with at
    most ``force_n`` (in the planned direction, whether the planner found a good side or not),
    and every articulation joint pulled open."""
    m = load_probe_model(mjcf_path)
    plans, pushes = plan_and_push(m, force_n=force_n)
    joints = tuple(open_joint(m, j) for j in joint_names(m))
    return plans, pushes, joints


def _joint_unit(kind: str, v: float) -> str:
    return f"{np.degrees(v):.1f} deg" if kind == "hinge" else f"{v * 100:.1f} cm"


def probe_lines(plans: tuple[PushPlan, ...], pushes: tuple[PushResult, ...], joints: tuple[JointProbe, ...], fixed: tuple[str, ...] = ()) -> tuple[str, ...]:
    """One human-readable line per probe (what ``scene-builder check --interact`` prints), and a
    last line with the share of doors and drawers that opened fully (:func:`joint_summary`;
    ``fixed``: the objects welded to the room, whose joints are counted apart)."""
    out = []
    plan = {p.name: p for p in plans}
    for r in pushes:
        failures = push_failures(r)
        verdict = "FAILED: " + "; ".join(failures) if failures else "ok"
        forecast = f" (planner: {plan[r.name].reason})" if r.name in plan and plan[r.name].reason else ""
        if r.not_started:
            out.append(f"push {r.name}: {verdict}{forecast}")
            continue
        carried = f"; carried {', '.join(n for n, _ in r.carried)}" if r.carried else ""
        out.append(
            f"push {r.name}: {verdict}: moved {r.displacement_m * 100:.1f} cm ({r.along_m * 100:.1f} cm along "
            f"({r.direction_xy[0]:+.2f}, {r.direction_xy[1]:+.2f}), {r.clearance_m * 100:.0f} cm free ahead), tilt {r.tilt_deg:.1f} deg, "
            f"pusher force up to {r.max_force_n:.0f} of {r.force_limit_n:.0f} N, others at most {r.max_other_m * 1000:.1f} mm{carried}{forecast}"
        )
    for j in joints:
        out.append(
            f"open {j.joint}: {j.kind} opened {_joint_unit(j.kind, j.travel)} of {_joint_unit(j.kind, abs(j.range[1] - j.range[0]))} "
            f"({j.open_fraction:.0%}) under {j.force_n:.0f} N, {_joint_unit(j.kind, j.limit_violation)} beyond its range, "
            f"{j.object} moved {j.body_displacement_m * 1000:.1f} mm"
        )
    if joints:
        s = joint_summary(joints, fixed)
        line = (f"doors and drawers: {s['opened_fully']} of {s['joints']} open fully ({FULL_OPEN_FRACTION:.0%} of their range or more) "
                f"within their limits with the carcass still")
        if s["fixed_joints"]:
            line += f"; on built-in and fixed furniture {s['fixed_opened_fully']} of {s['fixed_joints']}"
        out.append(line)
    return tuple(out)
