"""Mass properties computed from geometry, and joint damping / friction derived from them.

* Solid parts: mass = density x volume, centre of mass and inertia tensor by exact integration
  over the closed triangle mesh (trimesh's ``mass_properties``: divergence theorem over signed
  tetrahedra, exact for a closed mesh).
* Thin-walled (hollow) parts: the surface-density integral of a shell of thickness ``t``: the
  mass per area is ``density * t`` and mass, first and second moments are integrated exactly
  over each triangle (closed-form triangle moments). Error vs the exact outer-minus-inner solid
  is O(t / L) (a hollow 1 m box with 18 mm walls: mass within 0.1 %, inertia within 2 %).

Joint resistance (:func:`joint_resistance`) is derived so that doors, drawers and lids stay
where they are put on a floor that is not perfectly level:

* gravity load on the joint, worst case over gravity directions within ``tilt_rad`` of -Z:
  revolute (axis ``a`` through anchor ``p``, centre of mass ``c``, ``w = a x (c - p)``):
  ``tau_g = m g |w| cos(max(0, beta - tilt))`` where ``beta`` is the angle between ``w`` and the
  vertical line (for a vertical hinge ``beta = 90 deg`` so ``tau_g = m g r sin(tilt)``; for a
  horizontal lid hinge ``beta = 0`` and ``tau_g = m g r``, the laptop-hinge case);
  prismatic: ``F_g = m g cos(max(0, gamma - tilt))``, ``gamma`` the angle of the axis to the
  vertical line;
* dry friction (MuJoCo ``frictionloss``) = ``safety x`` that load (static friction must exceed
  the load for the part to stay put);
* viscous damping for a time constant ``T``: ``c = I_axis / T`` (revolute, ``I_axis`` the moment
  of inertia about the hinge line) or ``c = m / T`` (prismatic), so a part pushed to speed
  ``v`` coasts about ``v T`` before stopping;
* effort limit: what a hand can push plus the gravity load: ``max(4 x friction, 20 N x lever)``;
* counterbalance spring (revolute, given the joint's range): where gravity turns the part further
  open as it opens (an oven's or a dishwasher's door, hinged at its bottom: the torque grows from
  nothing when closed to ``m g r`` when level), the hinge carries a torsion spring toward the rest
  pose, as real ones do, of stiffness ``k`` (N m/rad) minimising the largest net torque
  ``max_q |tau_g(q) - k q|`` over the range; the friction then holds that residual, so the door
  stays at any angle it is put at instead of falling open and slamming into its stop (measured:
  a 12 kg oven door pulled open hit its stop at 1.4 rad/s and bounced back 1.6 degrees). For a
  bottom-hinged door opening 1.5 rad, ``k = 0.75 m g r`` and the residual is ``0.12 m g r``.
  Where gravity closes the part (a lid) or does not turn it (a vertical hinge), ``k = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scene_builder.model import Inertial, JointType, TriangleMesh

__all__ = [
    "GRAVITY_M_S2",
    "mass_properties",
    "shell_mass_properties",
    "surface_shell_mass_properties",
    "inward_offset",
    "combine_inertials",
    "is_mass_distribution",
    "second_moments",
    "too_small",
    "MIN_SIMULATED",
    "joint_resistance",
    "JointResistance",
]

GRAVITY_M_S2 = 9.81


def _trimesh(mesh):
    import trimesh

    if isinstance(mesh, trimesh.Trimesh):
        return mesh
    return trimesh.Trimesh(np.asarray(mesh.vertices_m), np.asarray(mesh.faces), process=False)


#: Each principal second moment of a part (``int x_i^2 dm`` along a principal axis) is at least
#: this share of its largest principal moment of inertia. A flat part (a lamp's shade, a panel
#: seen edge-on, one voxel thick) has a second moment near 0 across it, and the exact integral's
#: round-off can make it negative: A + B < C, which MuJoCo rejects. Raising it to 1e-5 of the
#: largest moment (the thickness of a 1 m plate counted as 4.5 mm) changes no moment by more than
#: 1e-5 of the largest, and leaves the tensor 10 x the data model's margin
#: (``scene_builder.arrays.INERTIA_MARGIN``) inside the triangle inequality.
SECOND_MOMENT_FLOOR = 1e-5


def second_moments(inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(principal second moments (3,) ``int x_i^2 dm`` in kg m^2, principal axes (3, 3) as
    columns) of a symmetric inertia tensor about the centre of mass: ``S_i = tr(I) / 2 - I_i``.
    A mass distribution has every ``S_i >= 0`` (the triangle inequality of the moments)."""
    moments, axes = np.linalg.eigh(0.5 * (inertia + inertia.T))
    return 0.5 * moments.sum() - moments, axes


def is_mass_distribution(inertia: np.ndarray) -> bool:
    """Whether ``inertia`` (3, 3), finite, can be a body's (every principal second moment >= 0 up
    to :data:`SECOND_MOMENT_FLOOR` of the largest moment: round-off, not a folded mesh)."""
    inertia = np.asarray(inertia, dtype=np.float64)
    if not np.all(np.isfinite(inertia)):
        return False
    s, _ = second_moments(inertia)
    largest = float(s.sum() - s.min())
    return largest > 0.0 and float(s.min()) >= -SECOND_MOMENT_FLOOR * largest


#: MuJoCo simulates no moving body whose mass or a principal moment is under mjMINVAL (1e-15 kg,
#: kg m^2): a part lighter than 1000 x that (a speck of a few tenths of a millimetre) is too small
#: to simulate (:func:`too_small`), and generation builds something else for it.
MIN_SIMULATED = 1e-12


def too_small(inertial: Inertial) -> bool:
    """Whether MuJoCo could not simulate a body of these mass properties (see :data:`MIN_SIMULATED`)."""
    return inertial.mass_kg < MIN_SIMULATED or float(np.linalg.eigvalsh(inertial.inertia_kg_m2).min()) < MIN_SIMULATED


def _make_inertial(mass_kg: float, com_m: np.ndarray, inertia: np.ndarray) -> Inertial:
    """The Inertial of an integrated tensor, its principal second moments raised to
    :data:`SECOND_MOMENT_FLOOR` of the largest moment (round-off of a flat part). A tensor no
    body can have (a second moment below minus that: a mesh folded over itself) is a geometry
    bug, not something to paper over: ValueError."""
    inertia = np.asarray(inertia, dtype=np.float64)
    if not (np.isfinite(mass_kg) and mass_kg > 0 and np.all(np.isfinite(com_m)) and is_mass_distribution(inertia)):
        raise ValueError(f"mass properties: mass {mass_kg:.3g} kg and inertia {np.round(inertia, 12).tolist()} are no body's; "
                         "the mesh must be closed, non-degenerate and not fold over itself")
    s, axes = second_moments(inertia)
    s = np.maximum(s, SECOND_MOMENT_FLOOR * float(s.sum() - s.min()))
    return Inertial(float(mass_kg), com_m, axes @ np.diag(s.sum() - s) @ axes.T)


def mass_properties(mesh, density_kg_m3: float) -> Inertial:
    """Exact mass, centre of mass and inertia (about the COM, mesh axes) of a closed solid mesh.

    mesh: :class:`TriangleMesh` or ``trimesh.Trimesh``, watertight, outward-facing (positive volume).
    Raises ValueError when the mesh is not watertight or its volume is not positive.
    """
    tm = _trimesh(mesh)
    if not tm.is_watertight:
        raise ValueError("mass_properties: mesh is not watertight; mass needs a closed surface")
    props = tm.mass_properties
    volume = float(props["volume"])
    if not volume > 0:
        raise ValueError(f"mass_properties: mesh volume is {volume:.3g} m^3; faces must point outward")
    # trimesh's density scales mass and inertia linearly: integrate with unit density, scale here.
    mass = density_kg_m3 * volume
    com = np.asarray(props["center_mass"], dtype=np.float64)
    inertia = np.asarray(props["inertia"], dtype=np.float64) * (density_kg_m3 / float(props["density"]))
    return _make_inertial(mass, com, inertia)


def surface_shell_mass_properties(mesh, density_kg_m3: float, thickness_m: float) -> Inertial:
    """Mass properties of a thin shell of ``thickness_m`` spread over the surface of ``mesh``.

    Exact integration of the surface density ``density * thickness`` over each triangle: for a
    triangle with vertices a, b, c and area A, ``int x dA = A (a + b + c) / 3`` and
    ``int x x^T dA = A / 12 (sum_i v_i v_i^T + s s^T)`` with ``s = a + b + c``. Over-estimates
    the mass by O(t / L) because the whole thickness sits on the outer surface.
    """
    tm = _trimesh(mesh)
    if thickness_m <= 0:
        raise ValueError(f"shell_mass_properties: thickness must be positive, got {thickness_m}")
    tri = np.asarray(tm.triangles, dtype=np.float64)  # (F, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)  # (F,)
    sigma = density_kg_m3 * thickness_m
    total_area = float(area.sum())
    if not total_area > 0:
        raise ValueError("shell_mass_properties: mesh has no area")
    mass = sigma * total_area
    s = tri.sum(axis=1)  # (F, 3)
    com = sigma * (area[:, None] * s / 3.0).sum(axis=0) / mass
    second = sigma * (
        np.einsum("f,fij,fik->jk", area, tri, tri) + np.einsum("f,fj,fk->jk", area, s, s)
    ) / 12.0  # int x x^T dm about the origin
    second_com = second - mass * np.outer(com, com)
    inertia = np.trace(second_com) * np.eye(3) - second_com
    return _make_inertial(mass, com, inertia)


def inward_offset(mesh, thickness_m: float):
    """The surface of ``mesh`` moved inward by ``thickness_m`` (a mitred offset).

    Each vertex moves by the least-squares ``d`` with ``n_f . d = -t`` for every adjacent face
    normal ``n_f``: exact at the 3-valent corners and edges of boxes and other convex polyhedra,
    ``-t n`` on smooth regions. Returns a ``trimesh.Trimesh`` with the same faces (it may
    self-intersect where the part is thinner than ``2 t``; the caller checks its volume).
    """
    import trimesh

    tm = _trimesh(mesh)
    normals = np.asarray(tm.face_normals, dtype=np.float64)  # (F, 3)
    nn = np.einsum("fi,fj->fij", normals, normals)  # (F, 3, 3)
    a = np.zeros((len(tm.vertices), 3, 3))
    b = np.zeros((len(tm.vertices), 3))
    for k in range(3):
        np.add.at(a, tm.faces[:, k], nn)
        np.add.at(b, tm.faces[:, k], -thickness_m * normals)
    d = np.einsum("vij,vj->vi", np.linalg.pinv(a, rcond=1e-6), b)  # (V, 3)
    return trimesh.Trimesh(np.asarray(tm.vertices) + d, np.asarray(tm.faces), process=False)


def shell_mass_properties(mesh, density_kg_m3: float, thickness_m: float) -> Inertial:
    """Mass properties of a hollow part: the outer solid minus the solid bounded by the surface
    offset inward by ``thickness_m`` (exact for boxes; see :func:`inward_offset`).

    Where the inward offset is not a valid solid (part thinner than two walls, so the offset
    folds over itself), the part is treated as solid when that weighs less than the thin-shell
    surface integral, else as that integral; both are exact integrals, never placeholders.
    """
    tm = _trimesh(mesh)
    outer = mass_properties(tm, density_kg_m3)
    if thickness_m <= 0:
        raise ValueError(f"shell_mass_properties: thickness must be positive, got {thickness_m}")
    inner = inward_offset(tm, thickness_m)
    props = inner.mass_properties
    v_in = float(props["volume"])
    v_out = float(tm.volume)
    area = float(tm.area)
    # A valid inner solid has positive volume, no more than the outer one minus a full wall.
    if 0.0 < v_in < v_out - 0.5 * thickness_m * area:
        scale = density_kg_m3 / float(props["density"])
        m_in = density_kg_m3 * v_in
        c_in = np.asarray(props["center_mass"], dtype=np.float64)
        i_in = np.asarray(props["inertia"], dtype=np.float64) * scale
        mass = outer.mass_kg - m_in
        com = (outer.mass_kg * outer.com_m - m_in * c_in) / mass
        d_out, d_in = outer.com_m - com, c_in - com
        steiner = lambda m, d: m * (float(d @ d) * np.eye(3) - np.outer(d, d))  # noqa: E731
        inertia = outer.inertia_kg_m2 + steiner(outer.mass_kg, d_out) - i_in - steiner(m_in, d_in)
        # An offset that folds where the surface is bumpy can pass the volume test yet poke out
        # of the outer solid: the difference is then no mass distribution (positive definite or
        # not, its moments may break the triangle inequality: a lamp's shade did).
        if mass > 0.0 and is_mass_distribution(inertia):
            return _make_inertial(mass, com, inertia)
    surface = surface_shell_mass_properties(tm, density_kg_m3, thickness_m)
    return outer if outer.mass_kg < surface.mass_kg else surface


def combine_inertials(parts: list[Inertial]) -> Inertial:
    """Mass properties of rigidly joined parts (parallel-axis theorem), asset axes."""
    mass = sum(p.mass_kg for p in parts)
    com = sum(p.mass_kg * p.com_m for p in parts) / mass
    inertia = np.zeros((3, 3))
    for p in parts:
        d = p.com_m - com
        inertia += p.inertia_kg_m2 + p.mass_kg * (float(d @ d) * np.eye(3) - np.outer(d, d))
    return _make_inertial(mass, com, inertia)


@dataclass(frozen=True)
class JointResistance:
    """damping: N m s/rad or N s/m; friction: N m or N; effort_limit: N m or N;
    gravity_load: the worst-case gravity torque / force the friction holds (same units);
    stiffness: N m/rad, the counterbalance spring toward the rest pose (0: none)."""

    damping: float
    friction: float
    effort_limit: float
    gravity_load: float
    stiffness: float = 0.0


def _cos_nearest(angle_to_vertical_rad: float, tilt_rad: float) -> float:
    return float(np.cos(max(0.0, angle_to_vertical_rad - tilt_rad)))


#: Angles (rad) the range is sampled at for the counterbalance, at most this far apart.
COUNTERBALANCE_STEP_RAD = np.radians(2.0)


def _counterbalance(axis: np.ndarray, com_arm_m: np.ndarray, mass_kg: float, range_rad: tuple[float, float]) -> tuple[float, float]:
    """(stiffness k >= 0 in N m/rad, the largest net torque left) of the spring toward q = 0 that
    best balances gravity over ``range_rad``: k minimises max_q |tau_g(q) - k q| (a convex
    function of k: scipy's bounded scalar minimiser), tau_g(q) the gravity torque about ``axis``
    on the centre of mass at ``com_arm_m`` from the hinge line, turned by q (Rodrigues).
    k = 0 where no spring lowers the largest torque (gravity closes the part, or does not turn it)."""
    from scipy.optimize import minimize_scalar

    lo, hi = float(min(range_rad)), float(max(range_rad))
    q = np.linspace(lo, hi, max(3, int(np.ceil((hi - lo) / COUNTERBALANCE_STEP_RAD)) + 1))
    c, s = np.cos(q)[:, None], np.sin(q)[:, None]
    arm = com_arm_m[None] * c + np.cross(axis, com_arm_m)[None] * s + axis[None] * float(axis @ com_arm_m) * (1.0 - c)
    weight = np.array([0.0, 0.0, -mass_kg * GRAVITY_M_S2])
    tau = np.cross(arm, weight) @ axis  # (Q,) the torque turning q positive

    def worst(k: float) -> float:
        return float(np.max(np.abs(tau - k * q)))

    k_max = float(np.max(np.abs(tau))) / max(float(np.max(np.abs(q))), 1e-9) * 2.0
    if k_max <= 0.0:
        return 0.0, worst(0.0)
    best = minimize_scalar(worst, bounds=(0.0, k_max), method="bounded", options={"xatol": 1e-6 * k_max})
    k = float(best.x)
    # Only a spring that clearly helps: a part gravity does not turn keeps none.
    if worst(k) > 0.9 * worst(0.0):
        return 0.0, worst(0.0)
    return k, worst(k)


def joint_resistance(
    joint_type: JointType,
    axis: np.ndarray,
    anchor_m: np.ndarray,
    inertial: Inertial,
    *,
    tilt_rad: float = np.radians(2.0),
    safety: float = 1.5,
    time_constant_s: float = 0.5,
    range_rad: tuple[float, float] | None = None,
) -> JointResistance:
    """Damping, dry friction, effort limit and (given ``range_rad``, the joint's lower and upper
    limits, which only a revolute joint's counterbalance reads) counterbalance stiffness of a
    joint carrying ``inertial`` (the moving part and everything attached to it). See the module
    docstring for the derivation."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    m = inertial.mass_kg
    if joint_type in (JointType.REVOLUTE, JointType.REVOLUTE_PRISMATIC):
        r = inertial.com_m - np.asarray(anchor_m, dtype=np.float64)
        w = np.cross(a, r)
        lever = float(np.linalg.norm(w))
        beta = float(np.arccos(min(1.0, abs(w[2]) / lever))) if lever > 1e-12 else 0.0
        load = m * GRAVITY_M_S2 * lever * _cos_nearest(beta, tilt_rad)
        r_perp = r - a * float(a @ r)
        i_axis = float(a @ inertial.inertia_kg_m2 @ a) + m * float(r_perp @ r_perp)
        damping = i_axis / time_constant_s
        stiffness = 0.0
        if range_rad is not None and lever > 1e-12:
            stiffness, residual = _counterbalance(a, r, m, range_rad)
            load = max(load, residual)
        friction = safety * load
        effort = max(4.0 * friction, 20.0 * max(lever, 0.05))
        return JointResistance(damping, friction, effort, load, stiffness)
    if joint_type is JointType.PRISMATIC:
        gamma = float(np.arccos(min(1.0, abs(a[2]))))
        load = m * GRAVITY_M_S2 * _cos_nearest(gamma, tilt_rad)
        friction = safety * load
        return JointResistance(m / time_constant_s, friction, max(4.0 * friction, 20.0), load)
    return JointResistance(0.0, 0.0, 0.0, 0.0)
