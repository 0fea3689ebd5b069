"""Shared test helpers: random valid chains and the Pinocchio reference model of a RobotModel,
closed loops run twice to compare two laws, the MuJoCo skip marker.

A plain module, not a conftest: ``test/ros`` has a conftest of its own, and two modules
named ``conftest`` cannot both be imported by name.
"""

import importlib.util

import numpy as np
import pytest


def to_pin(model):
    """Build the Pinocchio model of ``model`` (same frames: placement (R_fix, p), then RZ)."""
    pin = pytest.importorskip("pinocchio")
    pm = pin.Model()
    parent = 0
    for i in range(model.n):
        placement = pin.SE3(np.array(model.R_fix[i]), np.array(model.p[i]))
        parent = pm.addJoint(parent, pin.JointModelRZ(), placement, model.joint_names[i])
        inertia = pin.Inertia(float(model.mass[i]), np.array(model.com[i]),
                              np.array(model.inertia[i]))
        pm.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
    pm.gravity.linear = np.array(model.gravity)
    pm.armature = np.array(model.armature)    # used by Pinocchio's RNEA, CRBA and ABA
    return pm


def random_chain(rng, n, gravity=(0.0, 0.0, -9.81)):
    """A random physically valid chain of ``n`` revolute joints."""
    from rcac_ros.core.model import RobotModel, rpy_matrix
    p = rng.uniform(-0.5, 0.5, size=(n, 3))
    R = np.array([rpy_matrix(rng.uniform(-np.pi, np.pi, 3)) for _ in range(n)])
    mass = rng.uniform(0.5, 5.0, n)
    com = rng.uniform(-0.2, 0.2, size=(n, 3))
    inertia = []
    for _ in range(n):
        Q = rpy_matrix(rng.uniform(-np.pi, np.pi, 3))
        a, b = rng.uniform(0.05, 0.5, 2)
        c = rng.uniform(abs(a - b) + 0.01, a + b)      # triangle inequality holds
        inertia.append(Q @ np.diag([a, b, c]) @ Q.T)
    return RobotModel(p, R, mass, com, np.array(inertia), gravity)


#: skip a test that needs MuJoCo (the optional extra rcac_ros[mujoco]), and only that test
needs_mujoco = pytest.mark.skipif(importlib.util.find_spec("mujoco") is None,
                                  reason="mujoco not installed (the extra rcac_ros[mujoco])")


def exact_run(model, h, steps, channels, traj, q0, plant=None, applied=False, **options):
    """The true parameters, adaptation off (P = 1e-12), along ``traj`` on ``plant`` (default
    ``model``) from ``q0``; ``applied``: the simulator's clipped torque is fed back to the
    filters (``set_applied_torque``).

    Returns
    -------
    tuple
        ``(worst |E_c| / max |y_c|, max |y_c|, controller)``, per channel.
    """
    from rcac_ros.core import RecursiveCompositeController, Simulator
    ctrl = RecursiveCompositeController(model, P=1e-12, h=h, theta_hat0=model.theta(),
                                        channels=channels, **options)
    sim = Simulator(model if plant is None else plant, dt=h, q0=q0)
    E, y = [], []
    for k in range(steps):
        tau = ctrl.step(sim.q, sim.qd, *traj(k * h))
        E.append(ctrl.E)
        y.append(ctrl.y)
        sim.step(tau)
        if applied:
            ctrl.set_applied_torque(sim.applied)
    E, y = np.abs(E), np.abs(y)
    return E.max(axis=0) / y.max(axis=0), y.max(axis=0), ctrl


def track(ctrl, model, traj, steps, q0, h=0.002):
    """Close the loop of ``ctrl`` on the built-in simulator from rest at ``q0`` for
    ``steps`` periods of ``traj``: ``(efforts (steps, n), theta_hat, E)`` at the end."""
    from rcac_ros.core import Simulator
    sim = Simulator(model, q0=q0)
    taus = []
    for k in range(steps):
        taus.append(ctrl.step(sim.q, sim.qd, *traj(k * h)))
        sim.step(taus[-1])
    return np.array(taus), ctrl.theta_hat, ctrl.E


def sine_motion(q0, amp):
    """``q0 + amp sin(2 t)`` with its velocity and acceleration: a trajectory ``t -> (q_d,
    qd_d, qdd_d)``."""
    return lambda t: (q0 + amp * np.sin(2.0 * t), 2.0 * amp * np.cos(2.0 * t),
                      -4.0 * amp * np.sin(2.0 * t))


def worst_difference(a, b, model, q0, traj, with_E=True, each_step=None):
    """Controllers ``a`` and ``b`` in closed loop, 1000 steps of 2 ms, each on its own
    simulator of ``model`` from ``q0``, along ``traj``: the largest relative difference of
    their efforts and estimates (link, and joint where they have them), and (``with_E``) of
    their prediction errors relative to ``max(1, max |y|)``. ``each_step(b)`` runs after
    every step's comparison."""
    from rcac_ros.core import Simulator
    sa, sb = Simulator(model, q0=q0), Simulator(model, q0=q0)
    worst = 0.0
    for k in range(1000):
        x = traj(k * 0.002)
        ta, tb = a.step(sa.q, sa.qd, *x), b.step(sb.q, sb.qd, *x)
        for u, v in ((ta, tb), (a.theta_hat, b.theta_hat), (a.friction_hat, b.friction_hat)):
            if v is None:                                  # no joint terms
                continue
            worst = max(worst, np.max(np.abs(u - v)) / max(np.max(np.abs(v)), 1e-300))
        if with_E:
            worst = max(worst, np.max(np.abs(a.E - b.E)) / max(1.0, np.max(np.abs(b.y))))
        if each_step is not None:
            each_step(b)
        sa.step(ta)
        sb.step(tb)
    return worst


def frictional(model, seed=0, scale=1.0):
    """``model`` with armature, damping and Coulomb friction on every joint."""
    rng = np.random.default_rng(seed)
    n = model.n
    return model.replace(armature=scale * rng.uniform(0.5, 2.0, n),
                         damping=scale * rng.uniform(10.0, 50.0, n),
                         friction=scale * rng.uniform(5.0, 20.0, n))


def frictional_chain():
    """A random 5-joint chain with gravity and small joint terms, and a sine motion about a
    random start: ``(model, q0, trajectory)``, the same at every call."""
    rng = np.random.default_rng(3)
    model = frictional(random_chain(rng, 5), scale=0.05)
    q0 = rng.uniform(-1.0, 1.0, 5)
    amp = rng.uniform(0.3, 0.8, 5)
    return model, q0, sine_motion(q0, amp)
