"""The laws with joint friction and rotor inertia (doc/design.md §7): exact with the true
parameters, channels="all" equals Slotine-Li, the option off changes nothing."""

import numpy as np
import pytest
from chains import (exact_run as true_parameters_run, frictional, frictional_chain, track,
                    worst_difference)

from rcac_ros.core import (GainError, InputError, PaperTrajectory, RecursiveCompositeController,
                           Simulator, SlotineLiCompositeController, css_arm)
from rcac_ros.core.composite_fused import is_paper_law
from rcac_ros.core.joint_friction import ROTOR_TOLERANCE, joint_rates
from rcac_ros.core.model import PAPER_Q0

Q0 = np.array(PAPER_Q0)


def exact_run(model, plant, h, steps, channels, traj, **options):
    """The true parameters, adaptation off (tiny gains): the worst |E_c| / max |y_c|."""
    return true_parameters_run(model, h, steps, channels, traj, Q0, plant=plant, **options)[0]


@pytest.mark.parametrize("gravity", [(0.0, 0.0, 0.0), (0.0, 0.0, -9.81)])
def test_every_channel_stays_exact_with_the_true_joint_terms(gravity):
    """With theta, friction_hat true on a plant with joint friction, every channel's E is at
    the level the rigid law has on the rigid plant along the same motion (the O(h^2) error
    of the holds, test_channels.py): the joint terms add psi_f != 0 to joint 1's channel,
    so it too is second order now (h / 2 divides it by about 4)."""
    rigid = css_arm(gravity)
    model = frictional(rigid)
    traj = PaperTrajectory(Q0, reading="position", amplitude=0.3, period=4.0)   # reverses
    blind = exact_run(rigid, rigid, 0.002, 1500, ["all", "power"], traj)
    opts = dict(joint_friction=True, P_friction=1e-12)
    coarse = exact_run(model, model, 0.002, 1500, ["all", "power"], traj, **opts)
    fine = exact_run(model, model, 0.001, 3000, ["all", "power"], traj, **opts)
    assert coarse.max() < 2.0 * blind.max(), (coarse, blind)       # 2.6e-4 vs 2.2e-4
    assert np.all(coarse / fine > 3.5), (coarse, coarse / fine)
    # the check can fail: the friction-blind law on the same plant predicts badly
    blind = exact_run(model, model, 0.002, 1500, ["all", "power"], traj)
    assert np.all(blind > 10.0 * coarse), (blind, coarse)


@pytest.mark.parametrize("update", ["implicit", "explicit"])
def test_all_channels_equal_slotine_li_with_joint_friction(update):
    """Closed loops on a frictional random chain with gravity, both laws from zero joint
    estimates: efforts, estimates (link and joint) and E equal to 1e-9 at every step."""
    model, q0, traj = frictional_chain()
    gains = dict(K_D=30.0, P=1.0 if update == "implicit" else 0.01, gamma=0.5, lam=20.0,
                 joint_friction=True, friction_hat0=np.zeros((5, 3)),
                 P_friction=(0.5, 5.0, 5.0) if update == "implicit" else 0.05, update=update)
    a = RecursiveCompositeController(model, channels="all", **gains)
    b = SlotineLiCompositeController(model, **gains)
    worst = worst_difference(a, b, model, q0, traj)
    assert worst < 1e-9, worst
    assert np.max(np.abs(b.friction_hat)) > 1e-3            # the joint terms did adapt


def test_option_off_and_the_joint_torque():
    """joint_friction=False has no joint estimates; with it, the effort adds
    Y_f friction_hat and the rotor's feedback -rho a_hat s_q to the rigid law's effort (the
    link terms are unchanged)."""
    model = frictional(css_arm())
    rigid = RecursiveCompositeController(model, theta_hat0=model.theta())
    assert rigid.friction_hat is None and not rigid.joint_friction
    aware = RecursiveCompositeController(model, theta_hat0=model.theta(), joint_friction=True)
    np.testing.assert_array_equal(aware.friction_hat, model.joint_terms())
    q, qd = Q0, np.linspace(-0.5, 0.5, 7)
    q_d, qd_d, qdd_d = Q0 + 0.01, qd + 0.02, np.full(7, 0.3)
    t0 = rigid.step(q, qd, q_d, qd_d, qdd_d)
    t1 = aware.step(q, qd, q_d, qd_d, qdd_d)
    qd_r = qd_d - (q - q_d)
    qdd_r = qdd_d - (qd - qd_d)
    rho = np.minimum(joint_rates(model, aware.K_D, q)[0], 2.0 / (ROTOR_TOLERANCE * aware.h))
    expected = (model.armature * qdd_r + model.damping * qd_r
                + model.friction * np.tanh(qd / model.friction_velocity)
                - rho * model.armature * (qd - qd_r))
    np.testing.assert_allclose(t1 - t0, expected, rtol=1e-12, atol=1e-9)


def test_reset_and_set_friction_hat():
    model = frictional(css_arm())
    ctrl = RecursiveCompositeController(model, joint_friction=True,
                                        friction_hat0=np.ones((7, 3)))
    ctrl.step(Q0, np.ones(7), Q0, np.zeros(7), np.zeros(7))
    assert not np.array_equal(ctrl.friction_hat, np.ones((7, 3)))
    ctrl.reset()
    np.testing.assert_array_equal(ctrl.friction_hat, np.ones((7, 3)))
    ctrl.set_friction_hat(np.full((7, 3), 2.0))
    np.testing.assert_array_equal(ctrl.friction_hat, np.full((7, 3), 2.0))
    ctrl.reset(friction_hat0=np.zeros((7, 3)))
    np.testing.assert_array_equal(ctrl.friction_hat, np.zeros((7, 3)))
    with pytest.raises(GainError, match="no joint terms"):
        RecursiveCompositeController(model).set_friction_hat(np.zeros((7, 3)))


@pytest.mark.parametrize("cls", [RecursiveCompositeController, SlotineLiCompositeController])
@pytest.mark.parametrize("kw,exc,match", [
    (dict(P_friction=-1.0), GainError, "P_friction: every entry must be finite and > 0"),
    (dict(P_friction=[1.0, 2.0]), GainError, "P_friction: expected a scalar, 3 values"),
    (dict(P_friction="big"), GainError, "P_friction: expected 'feedback', a scalar"),
    (dict(friction_hat0=np.zeros((7, 2))), InputError, "friction_hat0: expected shape"),
])
def test_bad_joint_options(cls, kw, exc, match):
    with pytest.raises(exc, match=match):
        cls(css_arm(), joint_friction=True, **kw)


@pytest.mark.parametrize("adaptation", ["least_squares", "least_squares_prediction"])
def test_least_squares_with_joint_terms_stays_exact(adaptation):
    """The least-squares variants carry the joint terms (on their fixed gain) through the
    same prediction: with the true parameters E is what the fixed-gain law gives."""
    model = frictional(css_arm((0.0, 0.0, -9.81)))
    traj = PaperTrajectory(Q0, reading="position", amplitude=0.3, period=4.0)
    opts = dict(joint_friction=True, P_friction=1e-12)
    fixed = exact_run(model, model, 0.002, 500, "all", traj, **opts)
    ls = exact_run(model, model, 0.002, 500, "all", traj, adaptation=adaptation,
                   forgetting=0.1, **opts)
    np.testing.assert_allclose(ls, fixed, rtol=1e-6)
    blind = exact_run(model, model, 0.002, 500, "all", traj, adaptation=adaptation)
    assert np.all(blind > 10.0 * ls)


@pytest.mark.parametrize("P", [100.0, "full"])
def test_fused_paper_law_with_vanishing_joint_terms_equals_it_without(P):
    """``paper_step`` and ``paper_friction_step`` run one fused body (``paper_law``), the
    joint terms switched on in the second. With the joint terms at zero and a gain so small
    (1e-300) that every joint product is below the rounding of the link terms' sums, the
    joint terms add exact zeros: tau, theta_hat and E are bit-identical to the law without
    them, on a full gain P (the 13x13 branch) as on the diagonal one."""
    model = css_arm((0.0, 0.0, -9.81))
    if P == "full":
        A = np.random.default_rng(4).normal(size=(7, 13, 13)) * 0.1
        P = 50.0 * (A @ A.transpose(0, 2, 1) + np.eye(13))
    traj = PaperTrajectory(Q0, reading="position")
    runs = []
    for kwargs in ({}, dict(joint_friction=True, friction_hat0=np.zeros((7, 3)),
                            P_friction=1e-300)):
        ctrl = RecursiveCompositeController(model, P=P, **kwargs)
        assert is_paper_law(ctrl._chan, ctrl._scal)          # the fused kernels
        runs.append(track(ctrl, model, traj, 300, Q0))
    for a, b in zip(*runs):
        assert np.array_equal(a, b)
    assert np.max(np.abs(runs[0][1])) > 1.0          # the law adapted (from theta_hat = 0)


def test_fused_paper_step_with_joint_terms_equals_the_general_kernel():
    """The paper's law with the joint terms runs a fused body (``paper_friction_step``); a
    dead zone on s too small to act sends it through ``friction_step_kernel``: the same law,
    summed in another order (1e-12)."""
    model = frictional(css_arm((0.0, 0.0, -9.81)))
    traj = PaperTrajectory(Q0, reading="position", amplitude=0.3, period=4.0)
    runs = []
    for kwargs in ({}, dict(dead_zone_s=1e-300)):
        ctrl = RecursiveCompositeController(model, joint_friction=True,
                                            friction_hat0=np.zeros((7, 3)), **kwargs)
        sim = Simulator(model, q0=Q0)
        taus = []
        for k in range(500):
            taus.append(ctrl.step(sim.q, sim.qd, *traj(k * 0.002)))
            sim.step(taus[-1])
        runs.append((np.array(taus), ctrl.theta_hat, ctrl.friction_hat, ctrl.E, ctrl.y))
    for a, b in zip(runs[0][:3], runs[1][:3]):
        assert np.max(np.abs(a - b)) <= 1e-12 * max(np.max(np.abs(b)), 1.0), (a, b)
    assert abs(runs[0][3] - runs[1][3]) <= 1e-12 * abs(runs[1][4]), runs   # E = W theta - y
    assert np.max(np.abs(runs[0][2])) > 1e-3
