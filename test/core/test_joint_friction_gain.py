"""The default gain of the joint terms, ``P_f,i = beta_f D_eff,i(q_0) w`` at the first measured
posture, ``D_eff,i = 1 / (D^-1)_ii`` the joint's feedback with the other joints free
(doc/design.md §7 "Joint terms without per-arm tuning"): the feedback against a closed form
and against the mass matrix, the effective feedback against the Schur complement and its
bound, and the properties the gain is for: an arm scaled in mass, with its feedback, has the
same closed loop, and an arm whose joints are strongly coupled (the CSS arm) stays stable."""

import numpy as np
import pytest
from chains import frictional

from rcac_ros.core import (PaperTrajectory, RecursiveCompositeController,
                           SlotineLiCompositeController, Simulator, css_arm)
from rcac_ros.core.crba import mass_matrix
from rcac_ros.core.joint_friction import (BETA_FRICTION, BETA_FRICTION_ALL, TERM_WEIGHTS,
                                          effective_feedback, feedback_matrix,
                                          feedback_scaled_gain, joint_feedback)
from rcac_ros.core.model import PAPER_Q0
from rcac_ros.errors import GainError


def last_joint_inertia(model):
    """``H_nn``: the last link's inertia about its joint axis (the local z axis), the same at
    every posture: ``z^T (I_c + m (|c|^2 1 - c c^T)) z``."""
    m, c, I_c = model.mass[-1], model.com[-1], model.inertia[-1]
    return I_c[2, 2] + m * (c[0] ** 2 + c[1] ** 2)


def test_the_gain_is_beta_times_the_effective_feedback_at_the_first_state():
    """With ``K_D = k I6`` on every link, the last joint turns only the last frame, about an
    axis through its origin: a unit rotation and no velocity of the origin, ``D_nn = k``; the
    gain is ``beta w / (D^-1)_ii`` of the first state's feedback."""
    model = css_arm((0.0, 0.0, -9.81))
    q0 = np.array(PAPER_Q0) + 0.3
    ctrl = RecursiveCompositeController(model, K_D=300.0, joint_friction=True)
    ctrl.step(q0, np.zeros(7), q0, np.zeros(7), np.zeros(7))
    assert joint_feedback(model, ctrl.K_D, q0)[-1] == pytest.approx(300.0, rel=1e-12)
    D = feedback_matrix(model, ctrl.K_D, q0)
    expected = BETA_FRICTION * np.outer(1.0 / np.diag(np.linalg.inv(D)), TERM_WEIGHTS)
    np.testing.assert_allclose(ctrl.P_friction, expected, rtol=1e-10)
    np.testing.assert_allclose(ctrl.P_friction, feedback_scaled_gain(model, ctrl.K_D, q0),
                               rtol=1e-12)
    # the posture matters (joint 1's feedback grows with the arm's reach): the gain is the
    # first state's, not the zero posture's
    assert not np.allclose(ctrl.P_friction[0],
                           feedback_scaled_gain(model, ctrl.K_D, np.zeros(7))[0])


@pytest.mark.parametrize("options, beta", [
    (dict(channels="all"), BETA_FRICTION_ALL),
    (dict(channels=list(range(1, 8)) + ["power"]), BETA_FRICTION_ALL),
    (dict(channels="all", update="explicit"), BETA_FRICTION),
    (dict(channels="all", gamma=0.0), BETA_FRICTION),
    (dict(channels=list(range(1, 7))), BETA_FRICTION),
    (dict(), BETA_FRICTION),
])
def test_beta_is_the_channels_one_only_when_every_joint_has_an_implicit_channel(options, beta):
    """``beta_f`` = 100 s needs every joint's own channel, stepped implicitly and weighted
    (``gamma > 0``); any other law keeps 30 s (doc/design.md §7)."""
    model = css_arm((0.0, 0.0, -9.81))
    q0 = np.array(PAPER_Q0)
    ctrl = RecursiveCompositeController(model, K_D=300.0, joint_friction=True, **options)
    ctrl.step(q0, np.zeros(7), q0, np.zeros(7), np.zeros(7))
    np.testing.assert_allclose(ctrl.P_friction, feedback_scaled_gain(model, ctrl.K_D, q0, beta),
                               rtol=1e-12)


@pytest.mark.parametrize("options", [{}, dict(update="explicit"), dict(gamma=0.0)])
def test_slotine_li_takes_the_gain_of_channels_all(options):
    """Slotine-Li is ``channels="all"`` step by step (doc/design.md §8): with the default gain
    too, whatever its update and ``gamma``."""
    model = css_arm((0.0, 0.0, -9.81))
    q0 = np.array(PAPER_Q0)
    gains = dict(K_D=300.0, joint_friction=True, **options)
    ours = RecursiveCompositeController(model, channels="all", **gains)
    theirs = SlotineLiCompositeController(model, **gains)
    for ctrl in (ours, theirs):
        ctrl.step(q0, np.zeros(7), q0, np.zeros(7), np.zeros(7))
    np.testing.assert_allclose(theirs.P_friction, ours.P_friction, rtol=1e-12)


def test_the_panda_learns_its_joint_terms_in_20_s_with_the_default_gain():
    """``rcac friction-demo`` as shipped (the last link adapting), 20 s from zero joint
    estimates with the library's default gain: every armature and damping within the demo's
    10 % and every Coulomb term within its 15 %."""
    from rcac_ros.tools.demos.friction import GOALS, run_friction_demo
    from rcac_ros.tools.runs.scenarios import find_panda_urdf
    if find_panda_urdf() is None:
        pytest.skip("example-robot-data not installed")
    _, hist, truth, _ = run_friction_demo(20.0, record_every=10000)
    worst = (np.abs(hist[-1] - truth) / truth).max(axis=0)
    assert np.all(worst <= np.array(GOALS)), worst


def link_inertias(model):
    from rcac_ros.tools.runs.scenarios import spatial_inertia
    return np.array([spatial_inertia(model.mass[i], model.com[i], model.inertia[i])
                     for i in range(model.n)])


def test_the_feedback_of_link_inertias_is_the_mass_matrix():
    """``sum_j J_j^T M_j J_j = M(q)`` (the rigid arm's kinetic energy): ``K_Dj = M_j``
    gives the composite-rigid-body mass matrix, every entry."""
    model = css_arm((0.0, 0.0, -9.81))
    M = link_inertias(model)
    for q in (np.zeros(7), np.array(PAPER_Q0) + 0.7):
        H = mass_matrix(model, q)
        np.testing.assert_allclose(feedback_matrix(model, M, q), H, rtol=0,
                                   atol=1e-12 * np.max(np.abs(H)))
        np.testing.assert_allclose(joint_feedback(model, M, q), np.diag(H), rtol=1e-10)


def test_the_effective_feedback_is_the_schur_complement_and_is_bounded_by_n_D():
    """``1 / (D^-1)_ii = D_ii - D_io D_oo^-1 D_oi`` (o: every other joint), and
    ``diag(D_eff) <= n D``: the largest eigenvalue of ``D^-1 diag(D_eff)`` is at most n (and
    1 for decoupled joints), where ``diag(D_ii)`` is not bounded by ``n D`` (the check can
    fail: on the CSS arm at the zero posture, the paper trajectory's start, ``D^-1
    diag(D_ii)`` reaches above n)."""
    model = css_arm()
    K_D = np.array([1e4 * np.eye(6)] * 7)
    D = feedback_matrix(model, K_D, np.zeros(7))
    De = effective_feedback(D)
    for i in range(7):
        o = [j for j in range(7) if j != i]
        schur = D[i, i] - D[i, o] @ np.linalg.solve(D[np.ix_(o, o)], D[o, i])
        assert De[i] == pytest.approx(schur, rel=1e-10)
    top = np.max(np.linalg.eigvals(np.linalg.solve(D, np.diag(De))).real)
    assert 1.0 <= top <= 7.0
    assert np.max(np.linalg.eigvals(np.linalg.solve(D, np.diag(np.diag(D)))).real) > 7.0
    np.testing.assert_allclose(effective_feedback(np.diag([3.0, 5.0])), [3.0, 5.0])


def coupled_run(P_friction, steps):
    """The CSS arm (``K_D = 1e4 I6``, the paper's gains) with large joint terms in the plant,
    links known, from the trajectory's start: the largest tracking error of the run."""
    rigid = css_arm()
    plant = frictional(rigid)
    traj = PaperTrajectory(np.array(PAPER_Q0), reading="position", amplitude=0.3, period=4.0)
    ctrl = RecursiveCompositeController(rigid, theta_hat0=rigid.theta(), joint_friction=True,
                                        P_friction=P_friction)
    q0, qd0, _ = traj(0.0)
    sim = Simulator(plant, q0=q0, qd0=qd0)
    worst = 0.0
    for k in range(steps):
        q_d = traj(k * ctrl.h)
        with np.errstate(all="ignore"):
            sim.step(ctrl.step(sim.q, sim.qd, *q_d))
            worst = max(worst, float(np.max(np.abs(sim.q - q_d[0]))))
        if not worst < 1.0:
            return np.inf
    return worst


def test_strongly_coupled_joints_stay_stable_with_the_default_gain():
    """On the CSS arm at the trajectory's start, the joints share most of their inertia
    (``D^-1 diag(D_ii)`` above n): the default gain tracks within the feedback's own error
    over 2 s; the same rule on ``D_ii`` (a stiffness above the feedback along the shared
    direction) runs away within 0.2 s, so the check can fail."""
    assert coupled_run("feedback", 1000) < 1e-2
    K_D = np.array([1e4 * np.eye(6)] * 7)
    diagonal = BETA_FRICTION * np.outer(joint_feedback(css_arm(), K_D, np.zeros(7)),
                                        TERM_WEIGHTS)
    assert coupled_run(diagonal, 100) == np.inf


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
