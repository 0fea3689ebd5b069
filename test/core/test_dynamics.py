"""Inverse dynamics, mass matrix and forward dynamics against Pinocchio and closed forms."""

import numpy as np
import pytest
from chains import random_chain, to_pin

from rcac_ros.core import (css_arm, energy, forward_dynamics, forward_kinematics,
                           inverse_dynamics, mass_matrix, RobotModel)

pin = pytest.importorskip("pinocchio")
RTOL = 1e-9


def rel(a, b):
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


def models():
    rng = np.random.default_rng(7)
    out = [("css g=0", css_arm()), ("css g", css_arm((0.0, 0.0, -9.81))),
           ("css g tilted", css_arm((1.0, -2.0, -9.0)))]
    for n in (1, 2, 5, 12, 30):
        out.append((f"random n={n} g", random_chain(rng, n)))
        out.append((f"random n={n} g=0", random_chain(rng, n, gravity=(0.0, 0.0, 0.0))))
    return out


@pytest.mark.parametrize("label,model", models(), ids=[m[0] for m in models()])
def test_against_pinocchio(label, model):
    pm = to_pin(model)
    data = pm.createData()
    rng = np.random.default_rng(model.n)
    for _ in range(5):
        q, qd, qdd, tau = rng.normal(size=(4, model.n)) * np.array([[3.0], [2.0], [5.0], [50.0]])
        assert rel(inverse_dynamics(model, q, qd, qdd), pin.rnea(pm, data, q, qd, qdd)) < RTOL
        M = mass_matrix(model, q)
        Mp = pin.crba(pm, data, q)
        Mp = np.triu(Mp) + np.triu(Mp, 1).T
        assert rel(M, Mp) < RTOL
        assert np.allclose(M, M.T, rtol=0, atol=1e-12 * np.abs(M).max())
        assert np.linalg.eigvalsh(M).min() > 0.0
        assert rel(forward_dynamics(model, q, qd, tau), pin.aba(pm, data, q, qd, tau)) < RTOL


def test_forward_inverts_inverse():
    model = css_arm((0.0, 0.0, -9.81))
    rng = np.random.default_rng(3)
    q, qd, qdd = rng.normal(size=(3, 7))
    tau = inverse_dynamics(model, q, qd, qdd)
    assert rel(forward_dynamics(model, q, qd, tau), qdd) < 1e-10


def test_single_link_pendulum_closed_form():
    """One link about z, gravity along -y of the base: tau = (Izz + m r^2) qdd + m g r cos q."""
    m, r, izz, g = 2.0, 0.7, 0.3, 9.81
    model = RobotModel([[0.0, 0.0, 0.0]], [np.eye(3)], [m], [[r, 0.0, 0.0]],
                       [np.diag([0.1, 0.25, izz])], gravity=(0.0, -g, 0.0))
    for q, qd, qdd in ((0.3, 1.2, -0.4), (-2.0, 0.0, 3.0), (1.0, -5.0, 0.0)):
        expected = (izz + m * r * r) * qdd + m * g * r * np.cos(q)
        assert inverse_dynamics(model, [q], [qd], [qdd])[0] == pytest.approx(expected, rel=1e-12)
        assert mass_matrix(model, [q])[0, 0] == pytest.approx(izz + m * r * r, rel=1e-12)


def test_two_link_planar_closed_form():
    """The textbook planar two-link arm (point masses at the link ends, thin links)."""
    m1, m2, l1, l2, g = 1.5, 0.8, 0.9, 0.6, 9.81
    tiny = np.diag([1e-9, 1e-9, 1e-9])
    model = RobotModel([[0.0, 0.0, 0.0], [l1, 0.0, 0.0]], [np.eye(3), np.eye(3)], [m1, m2],
                       [[l1, 0.0, 0.0], [l2, 0.0, 0.0]], [tiny, tiny], gravity=(0.0, -g, 0.0))
    q1, q2, d1, d2, a1, a2 = 0.4, -0.9, 0.7, -1.1, 0.3, 2.0
    c2, s2 = np.cos(q2), np.sin(q2)
    M11 = m1 * l1 ** 2 + m2 * (l1 ** 2 + 2 * l1 * l2 * c2 + l2 ** 2)
    M12 = m2 * (l1 * l2 * c2 + l2 ** 2)
    M22 = m2 * l2 ** 2
    h = -m2 * l1 * l2 * s2
    G1 = (m1 + m2) * l1 * g * np.cos(q1) + m2 * g * l2 * np.cos(q1 + q2)
    G2 = m2 * g * l2 * np.cos(q1 + q2)
    tau1 = M11 * a1 + M12 * a2 + h * (2 * d1 * d2 + d2 ** 2) + G1
    tau2 = M12 * a1 + M22 * a2 - h * d1 ** 2 + G2
    tau = inverse_dynamics(model, [q1, q2], [d1, d2], [a1, a2])
    assert tau == pytest.approx([tau1, tau2], rel=1e-6)   # the 1e-9 inertias
    M = mass_matrix(model, [q1, q2])
    assert M == pytest.approx(np.array([[M11, M12], [M12, M22]]), rel=1e-6)


def test_forward_kinematics_matches_pinocchio():
    model = css_arm()
    pm = to_pin(model)
    data = pm.createData()
    q = np.random.default_rng(1).normal(size=7)
    pin.forwardKinematics(pm, data, q)
    R, o = forward_kinematics(model, q)
    for i in range(7):
        assert np.allclose(R[i], data.oMi[i + 1].rotation, atol=1e-12)
        assert np.allclose(o[i], data.oMi[i + 1].translation, atol=1e-12)


def test_energy_rate_is_power():
    """dE/dt = qd . tau for the free dynamics: a check of energy() against forward dynamics."""
    rng = np.random.default_rng(5)
    model = random_chain(rng, 6)
    q, qd, tau = rng.normal(size=(3, 6))
    qdd = forward_dynamics(model, q, qd, tau)
    eps = 1e-5
    e_plus = sum(energy(model, q + eps * qd, qd + eps * qdd))
    e_minus = sum(energy(model, q - eps * qd, qd - eps * qdd))
    assert (e_plus - e_minus) / (2 * eps) == pytest.approx(qd @ tau, rel=1e-6)


# ---------------------------------------------------------------- joint terms (doc/design.md §7)
def with_joint_terms(model, seed):
    """``model`` with random armature, damping and Coulomb friction on every joint."""
    rng = np.random.default_rng(seed)
    return model.replace(armature=rng.uniform(0.05, 0.6, model.n),
                         damping=rng.uniform(0.1, 2.0, model.n),
                         friction=rng.uniform(0.1, 1.0, model.n), friction_velocity=0.07)


def friction_torque(model, qd):
    return model.damping * qd + model.friction * np.tanh(qd / model.friction_velocity)


@pytest.mark.parametrize("label,model", models(), ids=[m[0] for m in models()])
def test_joint_terms_against_pinocchio(label, model):
    """Pinocchio's armature in RNEA, CRBA and ABA; it has no friction, so the closed form
    ``damping qd + friction tanh(qd / v_c)`` is added to its RNEA and taken off ABA's torque."""
    model = with_joint_terms(model, model.n)
    pm = to_pin(model)
    data = pm.createData()
    rng = np.random.default_rng(model.n + 1)
    for _ in range(5):
        q, qd, qdd, tau = rng.normal(size=(4, model.n)) * np.array([[3.0], [0.3], [5.0], [50.0]])
        tf = friction_torque(model, qd)
        assert rel(inverse_dynamics(model, q, qd, qdd), pin.rnea(pm, data, q, qd, qdd) + tf) \
            < 1e-12
        Mp = pin.crba(pm, data, q)
        assert rel(mass_matrix(model, q), np.triu(Mp) + np.triu(Mp, 1).T) < 1e-12
        assert rel(forward_dynamics(model, q, qd, tau), pin.aba(pm, data, q, qd, tau - tf)) \
            < 1e-12


def test_joint_terms_forward_inverts_inverse():
    model = with_joint_terms(css_arm((0.0, 0.0, -9.81)), 11)
    rng = np.random.default_rng(4)
    q, qd, qdd = rng.normal(size=(3, 7)) * 0.2
    tau = inverse_dynamics(model, q, qd, qdd)
    assert rel(forward_dynamics(model, q, qd, tau), qdd) < 1e-10


def test_zero_joint_terms_leave_every_function_unchanged():
    """Explicit zeros give the same floats as the default model (the rigid arithmetic)."""
    model = css_arm((0.0, 0.0, -9.81))
    zero = model.replace(armature=0.0, damping=[0.0] * 7, friction=0.0, friction_velocity=0.3)
    assert not zero.has_joint_terms and with_joint_terms(model, 1).has_joint_terms
    rng = np.random.default_rng(8)
    q, qd, a = rng.normal(size=(3, 7))
    assert np.array_equal(inverse_dynamics(zero, q, qd, a), inverse_dynamics(model, q, qd, a))
    assert np.array_equal(mass_matrix(zero, q), mass_matrix(model, q))
    assert np.array_equal(forward_dynamics(zero, q, qd, a), forward_dynamics(model, q, qd, a))


def test_joint_terms_are_dissipative():
    """With no torque and g = 0, the energy (armature included) never grows: the friction
    torque opposes the velocity."""
    model = with_joint_terms(css_arm(), 3)
    rng = np.random.default_rng(9)
    q, qd = rng.normal(size=(2, 7))
    qdd = forward_dynamics(model, q, qd, np.zeros(7))
    # dE/dt with E = 1/2 qd^T M(q) qd (armature in M): qd^T M qdd + 1/2 qd^T Mdot qd
    eps = 1e-6
    states = ((q + eps * qd, qd + eps * qdd), (q - eps * qd, qd - eps * qdd))
    e = [0.5 * v @ mass_matrix(model, x) @ v for x, v in states]
    rate = (e[0] - e[1]) / (2 * eps)
    assert rate == pytest.approx(-qd @ friction_torque(model, qd), rel=1e-6)
