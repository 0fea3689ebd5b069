"""The rotor (doc/design.md §7 "The rotor"): each joint's feedback grows by ``rho_q a_fb`` and
its default gain with ``a_ref``. Against closed forms: with ``K_Dj = kappa M_j`` and
``rho_q = kappa``, the joint-space feedback is ``kappa`` times the arm's whole inertia, so
every ``s_i`` decays as ``exp(-kappa t)``, also on a joint whose rotor outweighs its link;
the gain only grows, and equals ``base + grow a_ref``."""

import numpy as np
import pytest
from chains import random_chain

from rcac_ros.core import RecursiveCompositeController, Simulator, SlotineLiCompositeController
from rcac_ros.core.joint_friction import (BETA_FRICTION, F_AREF, F_GAIN, ROTOR_TOLERANCE,
                                          TERM_WEIGHTS, effective_feedback,
                                          feedback_matrix, joint_rates)
from rcac_ros.tools.runs.scenarios import spatial_inertia

H = 0.002
KAPPA = 20.0         # <= 2 / (ROTOR_TOLERANCE h): the rotor's rate is kappa itself


def rotor_arm(seed=4):
    """A random 3-joint chain whose rotors outweigh its links 20-50x (a wrist's case)."""
    from rcac_ros.core.crba import mass_matrix
    rng = np.random.default_rng(seed)
    rigid = random_chain(rng, 3)
    m_ii = np.diag(mass_matrix(rigid, np.zeros(3)))
    return rigid, rigid.replace(armature=rng.uniform(20.0, 50.0, 3) * m_ii)


def link_feedback(model):
    """``K_Dj = kappa M_j``: the links' feedback is ``kappa`` times the rigid mass matrix."""
    return np.array([KAPPA * spatial_inertia(model.mass[i], model.com[i], model.inertia[i])
                     for i in range(model.n)])


def decay_rates(cls, rotor_feedback=True, T=0.1):
    """Exact estimates, adaptation off (gains 1e-12), a step of 0.05 rad off a fixed
    posture: the rate ``-log(|s(T)| / |s(0)|) / T`` of each joint's ``s = qd - qd_r``."""
    rigid, plant = rotor_arm()
    assert KAPPA <= 2.0 / (ROTOR_TOLERANCE * H)
    ctrl = cls(rigid, K_D=link_feedback(rigid), Lambda=5.0, P=1e-12, gamma=0.0, h=H,
               theta_hat0=rigid.theta(), joint_friction=True,
               friction_hat0=plant.joint_terms(), P_friction=1e-12)
    q_d = np.array([0.3, -0.4, 0.5])
    sim = Simulator(plant, dt=H, q0=q_d + 0.05)
    z = np.zeros(3)
    steps = int(round(T / H))
    for k in range(steps + 1):
        s = sim.qd + 5.0 * (sim.q - q_d)
        if k == 0:
            s0 = s
        if k == steps:
            break
        tau = ctrl.step(sim.q, sim.qd, q_d, z, z)
        if not rotor_feedback:          # the rotor's share -rho_q a s taken back out
            tau = tau + KAPPA * plant.armature * s
        sim.step(tau)
    return -np.log(np.abs(s) / np.abs(s0)) / T


@pytest.mark.parametrize("cls", [RecursiveCompositeController, SlotineLiCompositeController])
def test_a_joint_whose_rotor_outweighs_its_link_settles_at_the_feedback_rate(cls):
    """``(M + A) sdot = -(kappa M + kappa A) s``: every joint at ``kappa`` (to the explicit
    step's first-order error ``h kappa``); without the rotor's share (``kappa M`` alone) the
    rotor-heavy joints settle about 20x slower, so the check can fail."""
    rates = decay_rates(cls)
    np.testing.assert_allclose(rates, KAPPA, rtol=H * KAPPA)
    slow = decay_rates(cls, rotor_feedback=False)
    assert np.all(slow < 0.5 * KAPPA), slow


def test_the_rotor_rate_is_the_links_rate_within_the_tolerance():
    """``rho_q = min(D_ii / M_ii, 2 / (N h))``: ``kappa`` with ``K_Dj = kappa M_j``."""
    rigid, _ = rotor_arm()
    rho, D = joint_rates(rigid, link_feedback(rigid), np.array([0.3, -0.4, 0.5]))
    np.testing.assert_allclose(rho, KAPPA, rtol=1e-10)
    fast, _ = joint_rates(rigid, 100.0 * link_feedback(rigid), np.zeros(3))
    ctrl = RecursiveCompositeController(rigid, K_D=100.0 * link_feedback(rigid), h=H,
                                        joint_friction=True)
    ctrl.step(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(ctrl._rate, np.minimum(fast, 2.0 / (ROTOR_TOLERANCE * H)))
    assert np.all(fast > 2.0 / (ROTOR_TOLERANCE * H))      # the bound acted


def test_the_default_gain_only_grows_with_the_largest_armature_estimate():
    """Adapting from zero joint estimates on the rotor-heavy arm: at every step the gain is
    ``beta w (D_eff + rho_q a_ref)`` and never falls."""
    from rcac_ros.core import SinusoidTrajectory
    rigid, plant = rotor_arm()
    ctrl = RecursiveCompositeController(rigid, K_D=link_feedback(rigid), Lambda=5.0, P=1.0,
                                        gamma=0.0, h=H, theta_hat0=rigid.theta(),
                                        joint_friction=True, friction_hat0=np.zeros((3, 3)))
    traj = SinusoidTrajectory(np.array([0.3, -0.4, 0.5]), (0.3, 0.3, 0.3), (0.5, 0.6, 0.7))
    q0, qd0, _ = traj(0.0)
    sim = Simulator(plant, dt=H, q0=q0, qd0=qd0)
    last = np.zeros((3, 3))
    for k in range(1500):
        sim.step(ctrl.step(sim.q, sim.qd, *traj(k * H)))
        if k == 0:
            rho = joint_rates(rigid, ctrl.K_D, q0)[0]
            De = effective_feedback(feedback_matrix(rigid, ctrl.K_D, q0))
        gain = ctrl._jdata[:, F_GAIN:F_GAIN + 3]
        expected = BETA_FRICTION * np.outer(De + rho * ctrl._jdata[:, F_AREF], TERM_WEIGHTS)
        np.testing.assert_allclose(gain, expected, rtol=1e-12)
        assert np.all(gain >= last)
        last = gain.copy()
    assert np.all(ctrl._jdata[:, F_AREF] > 0.1 * plant.armature)    # it did grow
