"""Articulation templates: joints at the right edges, limits that scale, nothing overlapping."""

from __future__ import annotations

import numpy as np
import pytest

from generation.articulation import ARTICULATED_LABELS, articulated_parts
from generation.assembly import VoxelGeometry, JointSpec, PartSpec, assemble_asset
from scene_builder.model import AssetKind, JointType, ObjectAsset
from scene_builder.vocabulary import category


def _manifold(mesh, transform=None):
    import manifold3d

    v = np.array(mesh.vertices_m, dtype=np.float64)
    if transform is not None:
        v = v @ transform[:3, :3].T + transform[:3, 3]
    return manifold3d.Manifold(manifold3d.Mesh64(np.array(v, order="C"), np.array(mesh.faces, dtype=np.uint64, order="C")))


def _overlap_m3(a, b) -> float:
    return float((a ^ b).volume())


def _joint_transform(joint, q: float) -> np.ndarray:
    """Asset-frame motion of a part when its joint moves by q from rest."""
    t = np.eye(4)
    if joint.type is JointType.PRISMATIC:
        t[:3, 3] = joint.axis * q
        return t
    k = joint.axis
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    r = np.eye(3) + np.sin(q) * kx + (1 - np.cos(q)) * kx @ kx
    t[:3, :3] = r
    t[:3, 3] = joint.anchor_m - r @ joint.anchor_m
    return t


def _subtree(asset: ObjectAsset, name: str) -> list[str]:
    out = [name]
    for p in asset.parts:
        if p.parent in out and p.name not in out:
            out.append(p.name)
    return out


@pytest.fixture(scope="module")
def assets() -> dict[str, ObjectAsset]:
    return {lab: assemble_asset(f"{lab}_0", lab, articulated_parts(lab, category(lab).typical_size_m)) for lab in ARTICULATED_LABELS}


@pytest.mark.parametrize("label", ARTICULATED_LABELS)
def test_template_fits_size_and_is_articulated(assets, label):
    a = assets[label]
    assert a.kind is AssetKind.ARTICULATED
    assert a.size_m == pytest.approx(category(label).typical_size_m, abs=0.003 if label != "laptop" else 0.02)
    movable = [p for p in a.parts if p.joint is not None and p.joint.type is not JointType.FIXED]
    assert movable
    for p in a.parts:
        assert p.inertial.mass_kg > 0
        for piece in p.collision:
            assert len(piece.faces) >= 4


@pytest.mark.parametrize("label", ARTICULATED_LABELS)
def test_no_overlap_at_rest(assets, label):
    a = assets[label]
    solids = {p.name: _manifold(p.visual) for p in a.parts}
    names = sorted(solids)
    for i, n1 in enumerate(names):
        for n2 in names[i + 1 :]:
            assert _overlap_m3(solids[n1], solids[n2]) < 1e-9, (n1, n2)


@pytest.mark.parametrize("label", ARTICULATED_LABELS)
def test_opening_moves_outward_without_entering_the_body(assets, label):
    """Each moving part at its upper limit: doors and drawers move toward +X (the front), lids
    up; along the way (5 steps to the upper limit) the moved subtree does not pass through the
    root part."""
    a = assets[label]
    root = _manifold(a.root.visual)
    for p in a.parts:
        if p.joint is None or p.joint.type is JointType.FIXED:
            continue
        t = _joint_transform(p.joint, p.joint.upper)
        rest_c = p.inertial.com_m
        moved_c = t[:3, :3] @ rest_c + t[:3, 3]
        if abs(p.joint.axis[1]) > 0.9 and p.joint.anchor_m[0] < 0:  # lid hinged at the back
            assert moved_c[2] > rest_c[2] + 0.1 * a.size_m[0]
        else:
            assert moved_c[0] > rest_c[0] + 0.1 * min(a.size_m[0], a.size_m[1])
        for q in np.linspace(0.0, p.joint.upper, 6)[1:]:
            tq = _joint_transform(p.joint, float(q))
            for name in _subtree(a, p.name):
                part = next(x for x in a.parts if x.name == name)
                assert _overlap_m3(root, _manifold(part.visual, tq)) < 1e-6, (p.name, name, q)


def test_handles_rank_one_on_every_door_and_drawer(assets):
    for label in ("cabinet", "wardrobe", "drawer_unit", "refrigerator", "microwave", "oven", "dishwasher", "door"):
        a = assets[label]
        for p in a.parts:
            if p.joint is not None and p.joint.type is not JointType.FIXED:
                handles = [q for q in a.parts if q.parent == p.name]
                assert len(handles) == 1 and handles[0].affordance_rank == 1
                assert "pull" in handles[0].affordance


def test_limits_and_layout_scale_with_size():
    small = assemble_asset("d0", "drawer_unit", articulated_parts("drawer_unit", (0.4, 0.5, 0.4)))
    big = assemble_asset("d1", "drawer_unit", articulated_parts("drawer_unit", (0.8, 0.5, 1.2)))
    lim = lambda a: [p.joint.upper for p in a.parts if p.joint is not None and p.joint.type is JointType.PRISMATIC]  # noqa: E731
    assert len(lim(big)) > len(lim(small))  # taller unit: more drawers
    # prismatic travel = 0.8 x the carcass depth, which grows with the measured depth
    assert np.mean(lim(big)) / np.mean(lim(small)) == pytest.approx((0.8 - 0.047) / (0.4 - 0.047), rel=0.05)
    assert max(lim(small)) < 0.4
    wide = articulated_parts("cabinet", (0.5, 1.4, 0.8))
    narrow = articulated_parts("cabinet", (0.5, 0.5, 1.0))
    doors = lambda specs: [s for s in specs if s.joint is not None and s.joint.type is JointType.REVOLUTE]  # noqa: E731
    assert len(doors(wide)) == 2 and len(doors(narrow)) == 1


def test_door_friction_holds_its_weight(assets):
    for p in assets["wardrobe"].parts:
        if p.joint is not None and p.joint.type is JointType.REVOLUTE:
            m = p.inertial.mass_kg
            lever = np.linalg.norm((p.inertial.com_m - p.joint.anchor_m)[:2])
            assert p.joint.friction > m * 9.81 * lever * np.sin(np.radians(2.0))
            assert p.joint.damping > 0


def test_assemble_from_voxels_like_the_physx_backend():
    """Voxel parts (grid + voxel size + origin) become a jointed asset with computed physics."""
    body = np.zeros((20, 30, 40), dtype=bool)
    body[:, :, :] = True
    door = np.ones((2, 28, 38), dtype=bool)
    s = 0.02
    specs = [
        PartSpec("body", None, VoxelGeometry(body, s, (-0.2, -0.3, 0.0)), "particleboard", shell_thickness_m=0.018),
        PartSpec("door", "body", VoxelGeometry(door, s, (0.22, -0.28, 0.02)), "particleboard",
                 JointSpec(JointType.REVOLUTE, (0, 0, -1), (0.26, -0.28, 0.0), 0.0, 1.7), affordance_rank=1),
    ]
    a = assemble_asset("cab", "cabinet", specs)
    assert a.kind is AssetKind.ARTICULATED
    assert [p.name for p in a.parts] == ["body", "door"]
    door_part = a.parts[1]
    # mass = density x volume for the solid door (marching cubes keeps the voxel volume)
    assert door_part.inertial.mass_kg == pytest.approx(700.0 * 2 * 28 * 38 * s**3, rel=0.05)
    # the hollow body weighs its 18 mm walls, far less than a solid block
    assert a.parts[0].inertial.mass_kg < 0.25 * 700.0 * 0.4 * 0.6 * 0.8
    assert door_part.joint.friction > 0 and door_part.joint.damping > 0
    # recentred: origin at the bottom centre of the bounding box
    lo = np.min([p.visual.bounds_m[0] for p in a.parts], axis=0)
    hi = np.max([p.visual.bounds_m[1] for p in a.parts], axis=0)
    assert (lo + hi)[:2] == pytest.approx([0.0, 0.0], abs=1e-6) and lo[2] == pytest.approx(0.0, abs=1e-6)



@pytest.mark.parametrize("label", ["oven", "dishwasher"])
def test_a_door_hinged_at_its_bottom_is_counterbalanced_and_stays_where_put(assets, label):
    """An oven's or a dishwasher's door carries a spring toward closed (its hinge's counterbalance):
    k about 0.75 m g r for a 1.5 rad range, the friction holding what is left, so in MuJoCo the door
    stays at 30, 45 and 70 degrees. The control, the same door without the spring, falls open."""
    import mujoco

    from tests.test_generation_physics import hinged_part_xml

    door = next(p for p in assets[label].parts if p.joint is not None and p.joint.type is JointType.REVOLUTE)
    j = door.joint
    arm = door.inertial.com_m - j.anchor_m
    mgr = door.inertial.mass_kg * 9.81 * float(np.linalg.norm(arm - j.axis * (j.axis @ arm)))
    assert 0.6 * mgr < j.stiffness < 0.9 * mgr
    assert j.friction >= 1.5 * 0.1 * mgr  # holds the residual of the balance
    for q0 in np.radians([30.0, 45.0, 70.0]):
        drift = []
        for k in (j.stiffness, 0.0):
            model = mujoco.MjModel.from_xml_string(hinged_part_xml(door.inertial, j.friction, j.damping, axis=j.axis, anchor_m=j.anchor_m,
                                                                   range_rad=(j.lower, j.upper), stiffness=k, q0=q0))
            data = mujoco.MjData(model)
            mujoco.mj_resetDataKeyframe(model, data, 0)
            mujoco.mj_step(model, data, nstep=1000)  # 2 s
            drift.append(abs(float(data.qpos[0]) - q0))
        assert drift[0] < np.radians(1.0), (label, np.degrees(q0), np.degrees(drift[0]))
        assert drift[1] > np.radians(10.0), (label, np.degrees(q0), np.degrees(drift[1]))  # control: it falls


def test_doors_on_side_hinges_and_lids_get_no_spring(assets):
    """A vertical hinge turns no weight and a lid's weight closes it: neither has a spring."""
    for label in ("wardrobe", "cabinet", "refrigerator", "microwave", "laptop", "box_with_lid"):
        for p in assets[label].parts:
            if p.joint is not None and p.joint.type is JointType.REVOLUTE:
                assert p.joint.stiffness == 0.0, (label, p.name)
