"""Armature and viscous damping against MuJoCo (doc/design.md §7): ``dof_armature`` and
``dof_damping``, with its joint limits, friction loss and contacts disabled.

MuJoCo is an independent implementation (its own MJCF model built here from the same
numbers, its own recursions); it is a test-only dependency of this module.
"""

import numpy as np
import pytest
from chains import random_chain

from rcac_ros.core import forward_dynamics, inverse_dynamics, mass_matrix, Simulator

mujoco = pytest.importorskip("mujoco")


def num(*values):
    return " ".join(f"{float(v):.17g}" for v in values)


def mjcf(model):
    """The chain of ``model`` as MJCF: body i at (p_i, R_fix_i), a hinge about its z axis."""
    bodies, closing = [], []
    for i in range(model.n):
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, np.ascontiguousarray(model.R_fix[i]).ravel())
        I = model.inertia[i]
        bodies.append(
            f'<body name="b{i}" pos="{num(*model.p[i])}" '
            f'quat="{num(*quat)}">'
            f'<joint name="j{i}" type="hinge" axis="0 0 1" damping="{num(model.damping[i])}" '
            f'armature="{num(model.armature[i])}"/>'
            f'<inertial pos="{num(*model.com[i])}" mass="{num(model.mass[i])}" '
            f'fullinertia="{num(I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])}"/>')
        closing.append("</body>")
    g = num(*model.gravity)
    return (f'<mujoco><compiler angle="radian"/><option gravity="{g}" timestep="0.002" '
            f'integrator="RK4"/><worldbody>{"".join(bodies)}{"".join(closing)}'
            '</worldbody></mujoco>')


def mj_model(model):
    m = mujoco.MjModel.from_xml_string(mjcf(model))
    m.opt.disableflags |= (mujoco.mjtDisableBit.mjDSBL_LIMIT
                           | mujoco.mjtDisableBit.mjDSBL_FRICTIONLOSS
                           | mujoco.mjtDisableBit.mjDSBL_CONTACT)
    return m, mujoco.MjData(m)


def chains():
    rng = np.random.default_rng(21)
    out = []
    for n in (1, 3, 7):
        base = random_chain(rng, n)
        out.append(base.replace(armature=rng.uniform(0.01, 0.5, n),
                                damping=rng.uniform(0.1, 2.0, n)))
    return out


def rel(a, b):
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


@pytest.mark.parametrize("model", chains(), ids=lambda m: f"n={m.n}")
def test_dynamics_against_mujoco(model):
    m, d = mj_model(model)
    rng = np.random.default_rng(model.n)
    for _ in range(5):
        q, qd, qdd, tau = rng.normal(size=(4, model.n)) * np.array([[2.0], [1.0], [3.0], [20.0]])
        d.qpos[:], d.qvel[:], d.qacc[:] = q, qd, qdd
        mujoco.mj_inverse(m, d)
        assert rel(inverse_dynamics(model, q, qd, qdd), d.qfrc_inverse) < 1e-9
        M = np.empty((model.n, model.n))
        mujoco.mj_fullM(m, d, M)
        assert rel(mass_matrix(model, q), M) < 1e-9
        d.qfrc_applied[:] = tau
        mujoco.mj_forward(m, d)
        assert rel(forward_dynamics(model, q, qd, tau), d.qacc) < 1e-9


def test_simulator_against_mujoco_rk4():
    """One second of open-loop torques: the simulator (RK4, 2 ms, torque held) and MuJoCo's
    RK4 at the same step give the same trajectory with armature and damping."""
    model = chains()[-1]
    m, d = mj_model(model)
    rng = np.random.default_rng(2)
    q0 = rng.normal(size=model.n) * 0.5
    sim = Simulator(model, dt=0.002, q0=q0)
    d.qpos[:] = q0
    for k in range(500):
        tau = 5.0 * np.sin(0.01 * k + np.arange(model.n))
        sim.step(tau)
        d.qfrc_applied[:] = tau
        mujoco.mj_step(m, d)
    assert np.max(np.abs(sim.q - d.qpos)) < 1e-9
    assert np.max(np.abs(sim.qd - d.qvel)) < 1e-8
