"""The default gain of the joint terms, ``P_f,i = beta_f D_ii(q_0) w`` at the first measured
posture, ``D_ii`` the joint's feedback (doc/design.md §7 "Joint terms without per-arm
tuning"): its value against a closed form and against the mass matrix, and the property it
is for: an arm scaled in mass, with its feedback, has the same closed loop."""

import numpy as np
import pytest

from rcac_ros.core import RecursiveCompositeController, Simulator, css_arm
from rcac_ros.core.crba import mass_matrix
from rcac_ros.core.joint_friction import (BETA_FRICTION, TERM_WEIGHTS, feedback_scaled_gain,
                                          joint_feedback)
from rcac_ros.core.model import PAPER_Q0
from rcac_ros.errors import GainError


def last_joint_inertia(model):
    """``H_nn``: the last link's inertia about its joint axis (the local z axis), the same at
    every posture: ``z^T (I_c + m (|c|^2 1 - c c^T)) z``."""
    m, c, I_c = model.mass[-1], model.com[-1], model.inertia[-1]
    return I_c[2, 2] + m * (c[0] ** 2 + c[1] ** 2)


def test_the_gain_is_beta_times_the_joint_feedback_at_the_first_state():
    """With ``K_D = k I6`` on every link, the last joint turns only the last frame, about an
    axis through its origin: a unit rotation and no velocity of the origin, ``D_nn = k``."""
    model = css_arm((0.0, 0.0, -9.81))
    q0 = np.array(PAPER_Q0) + 0.3
    ctrl = RecursiveCompositeController(model, K_D=300.0, joint_friction=True)
    ctrl.step(q0, np.zeros(7), q0, np.zeros(7), np.zeros(7))
    np.testing.assert_allclose(ctrl.P_friction, feedback_scaled_gain(model, ctrl.K_D, q0),
                               rtol=1e-12)
    np.testing.assert_allclose(ctrl.P_friction[-1],
                               BETA_FRICTION * 300.0 * np.array(TERM_WEIGHTS), rtol=1e-12)
    # the posture matters (joint 1's feedback grows with the arm's reach): the gain is the
    # first state's, not the zero posture's
    assert not np.allclose(ctrl.P_friction[0],
                           feedback_scaled_gain(model, ctrl.K_D, np.zeros(7))[0])


def test_the_feedback_of_link_inertias_is_the_mass_matrix():
    """``sum_j J_j^T M_j J_j = M(q)`` (the rigid arm's kinetic energy): ``K_Dj = M_j``
    gives the diagonal of the composite-rigid-body mass matrix."""
    from rcac_ros.tools.runs.scenarios import spatial_inertia
    model = css_arm((0.0, 0.0, -9.81))
    M = np.array([spatial_inertia(model.mass[i], model.com[i], model.inertia[i])
                  for i in range(model.n)])
    for q in (np.zeros(7), np.array(PAPER_Q0) + 0.7):
        np.testing.assert_allclose(joint_feedback(model, M, q), np.diag(mass_matrix(model, q)),
                                   rtol=1e-10)


def test_a_named_gain_other_than_inertia_is_refused():
    with pytest.raises(GainError, match="P_friction"):
        RecursiveCompositeController(css_arm(), joint_friction=True, P_friction="uniform")


def scaled_run(c, P_friction, steps=1500):
    """The direct law (gamma = 0) with the joint terms, links known, on the CSS arm with every
    mass, inertia and joint term times ``c`` and ``K_D`` times ``c``: ``q`` and
    ``friction_hat / c`` over the run."""
    rng = np.random.default_rng(3)
    rigid = css_arm((0.0, 0.0, -9.81))
    rigid = rigid.replace(mass=c * rigid.mass, inertia=c * rigid.inertia)
    plant = rigid.replace(armature=c * rng.uniform(0.05, 0.2, 7),
                          damping=c * rng.uniform(1.0, 5.0, 7),
                          friction=c * rng.uniform(0.5, 2.0, 7))
    q0 = np.array(PAPER_Q0)
    amp = rng.uniform(0.2, 0.5, 7)
    ctrl = RecursiveCompositeController(rigid, K_D=c * 300.0, Lambda=5.0, P=1e-12, gamma=0.0,
                                        theta_hat0=rigid.theta(), joint_friction=True,
                                        friction_hat0=np.zeros((7, 3)), P_friction=P_friction)
    sim = Simulator(plant, q0=q0)
    qs, fs = [], []
    for k in range(steps):
        t = k * 0.002
        x = (q0 + amp * np.sin(2.0 * t), 2.0 * amp * np.cos(2.0 * t),
             -4.0 * amp * np.sin(2.0 * t))
        sim.step(ctrl.step(sim.q, sim.qd, *x))
        qs.append(sim.q.copy())
        fs.append(ctrl.friction_hat / c)
    return np.array(qs), np.array(fs)


def test_an_arm_scaled_in_mass_has_the_same_closed_loop_with_the_default_gain():
    """Every torque of the plant, the feedback and the joint terms' truth times c: with a
    gain proportional to the inertia, ``q(t)`` is the same and the estimates are c times the
    same (equal to rounding); a gain the same for every arm does not have that property (the
    check can fail)."""
    q1, f1 = scaled_run(1.0, "feedback")
    q5, f5 = scaled_run(5.0, "feedback")
    assert np.max(np.abs(q1 - q5)) < 1e-9, np.max(np.abs(q1 - q5))
    assert np.max(np.abs(f1 - f5)) < 1e-9 * max(1.0, np.max(np.abs(f1)))
    assert np.max(np.abs(f1[-1])) > 1e-2                 # the joint terms did adapt
    u1, _ = scaled_run(1.0, (0.3, 3.0, 3.0))
    u5, _ = scaled_run(5.0, (0.3, 3.0, 3.0))
    assert np.max(np.abs(u1 - u5)) > 1e-6, np.max(np.abs(u1 - u5))
