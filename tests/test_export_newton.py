"""NVIDIA Newton as an independent consumer of the USD: it loads the stage on the CPU and agrees
with MuJoCo on the MJCF about masses, joint limits, resting positions and a door pushed open.

Tolerances: masses 1e-5 relative (USD stores float32), limits 1e-6, resting positions 2 mm after
0.5 s, door angle 5 degrees after the same torque pulse. First run compiles Warp kernels (about a
minute per solver); the cache lives under the repository's ignored ``.cache/warp``.
"""

from __future__ import annotations


import numpy as np
import pytest

from exporters import write_mjcf, write_usd
from tests.conftest import load_newton_model
from tests.fixtures_scenes import DOOR_RANGE_RAD, DRAWER_RANGE_M, boxes_scene, cabinet_scene

pytestmark = [pytest.mark.newton, pytest.mark.slow]
DT = 0.002


def _mujoco(path):
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(path))
    return model, mujoco.MjData(model)


def test_door_pushed_open_matches_mujoco(newton, tmp_path):
    import mujoco

    scene = cabinet_scene(is_fixed=True)
    model = load_newton_model(newton, write_usd(scene, tmp_path))
    mj, data = _mujoco(write_mjcf(scene, tmp_path))

    labels = list(model.body_label)
    for name, body in (("cabinet", "body"), ("cabinet/door", "door"), ("cabinet/drawer", "drawer")):
        i = labels.index(f"/World/Objects/cabinet/{body}")
        assert model.body_mass.numpy()[i] == pytest.approx(mj.body(name).mass[0], rel=1e-5)
    jl = list(model.joint_label)
    door_j = jl.index("/World/Objects/cabinet/Joints/door_joint")
    drawer_j = jl.index("/World/Objects/cabinet/Joints/drawer_joint")
    qd_start = model.joint_qd_start.numpy()
    lower, upper = model.joint_limit_lower.numpy(), model.joint_limit_upper.numpy()
    door_dof, drawer_dof = qd_start[door_j], qd_start[drawer_j]
    np.testing.assert_allclose([lower[door_dof], upper[door_dof]], DOOR_RANGE_RAD, atol=1e-6)
    np.testing.assert_allclose([lower[drawer_dof], upper[drawer_dof]], DRAWER_RANGE_M, atol=1e-6)
    np.testing.assert_allclose([lower[door_dof], upper[door_dof]], mj.joint("cabinet/door/joint").range, atol=1e-6)

    # 3 N*m on the door for 0.4 s, then let it swing against its damping and friction for 1.6 s.
    def torque(step: int) -> float:
        return 3.0 if step * DT < 0.4 else 0.0

    solver = newton.solvers.SolverFeatherstone(model, angular_damping=0.0)
    pipeline = newton.CollisionPipeline(model)
    s0, s1, control, contacts = model.state(), model.state(), model.control(), None
    contacts = pipeline.contacts()
    f = np.zeros(model.joint_dof_count, np.float32)
    q_start = model.joint_q_start.numpy()[door_j]
    for step in range(1000):
        f[door_dof] = torque(step)
        control.joint_f.assign(f)
        s0.clear_forces()
        pipeline.collide(s0, contacts)
        solver.step(s0, s1, control, contacts, DT)
        s0, s1 = s1, s0
    newton_angle = float(s0.joint_q.numpy()[q_start])

    jd = mj.joint("cabinet/door/joint")
    for step in range(1000):
        data.qfrc_applied[:] = 0.0
        data.qfrc_applied[jd.dofadr[0]] = torque(step)
        mujoco.mj_step(mj, data)
    mujoco_angle = float(data.qpos[jd.qposadr[0]])
    assert 0.5 < mujoco_angle < DOOR_RANGE_RAD[1] + 0.01  # it really moved
    assert abs(np.degrees(newton_angle - mujoco_angle)) < 5.0, (newton_angle, mujoco_angle)


def test_boxes_rest_where_mujoco_rests_them(newton, tmp_path):
    import mujoco

    scene = boxes_scene()
    model = load_newton_model(newton, write_usd(scene, tmp_path))
    mj, data = _mujoco(write_mjcf(scene, tmp_path))
    free = [o for o in scene.objects if not o.asset.is_fixed]
    labels = list(model.body_label)
    assert sorted(labels) == sorted(f"/World/Objects/{o.name}" for o in free)  # the counter is static
    solver = newton.solvers.SolverXPBD(model)
    pipeline = newton.CollisionPipeline(model)
    s0, s1, control = model.state(), model.state(), model.control()
    contacts = pipeline.contacts()
    for _ in range(250):
        s0.clear_forces()
        pipeline.collide(s0, contacts)
        solver.step(s0, s1, control, contacts, DT)
        s0, s1 = s1, s0
    for _ in range(250):
        mujoco.mj_step(mj, data)
    body_q = s0.body_q.numpy()
    for o in free:
        i = labels.index(f"/World/Objects/{o.name}")
        assert model.body_mass.numpy()[i] == pytest.approx(o.asset.mass_kg, rel=1e-5)
        # Newton's body origin is the object prim's origin, the asset frame, like MuJoCo's body.
        newton_pos = body_q[i, :3]
        mujoco_pos = data.xpos[mj.body(o.name).id]
        np.testing.assert_allclose(newton_pos, mujoco_pos, atol=2e-3, err_msg=o.name)
        np.testing.assert_allclose(newton_pos, o.world_from_asset[:3, 3], atol=2e-3, err_msg=o.name)
