"""``hold_compensation`` (doc/design.md §6 "The hold"): the effort extrapolated to the middle
of its zero-order hold; the sampled loop becomes second order in h."""

import numpy as np
from chains import exact_run, random_chain, sine_motion

from rcac_ros.core import InputError, RecursiveCompositeController, Simulator
from rcac_ros.core.joint_friction import feedback_matrix


def chain():
    rng = np.random.default_rng(3)
    model = random_chain(rng, 5)
    q0 = rng.uniform(-1.0, 1.0, 5)
    return model, sine_motion(q0, rng.uniform(0.3, 0.8, 5))


def test_the_effort_is_eq20_with_its_model_torque_extrapolated_to_the_middle_of_the_hold():
    """The direct law (gamma = 0: the held torque feeds no estimate) on the same states:
    ``tau_k + (m_k - m_k-1) / 2`` with ``m = tau + D(q) (qd - qd_r)`` eq 20 without its
    feedback (``D = sum_j J_j^T K_Dj J_j``, :func:`feedback_matrix`); the first step and the
    one after a restart of the filters as computed."""
    model, traj = chain()
    gains = dict(K_D=30.0, Lambda=2.0, P=1.0, gamma=0.0, lam=20.0)
    plain = RecursiveCompositeController(model, **gains)
    held = RecursiveCompositeController(model, hold_compensation=True, **gains)
    rng = np.random.default_rng(5)
    prev = None
    for k in range(60):
        x = traj(k * 0.002)
        q, qd = x[0] + 0.01 * rng.normal(size=5), x[1] + 0.1 * rng.normal(size=5)
        if k == 40:
            plain.restart_filters()
            held.restart_filters()
            prev = None
        tau, out = plain.step(q, qd, *x), held.step(q, qd, *x)
        qd_r = x[1] - 2.0 * (q - x[0])
        m = tau + feedback_matrix(model, plain.K_D, q) @ (qd - qd_r)
        want = tau if prev is None else tau + 0.5 * (m - prev)
        np.testing.assert_allclose(out, want, rtol=0.0, atol=1e-12 * np.abs(tau).max())
        assert prev is None or np.abs(out - tau).max() > 1e-9 * np.abs(tau).max()
        prev = m
    assert np.array_equal(plain.theta_hat, held.theta_hat)


def tracking_rms(model, traj, h, hold):
    """The true parameters, adaptation off: the RMS tracking error from 1 s to 3 s."""
    ctrl = RecursiveCompositeController(model, K_D=30.0, P=1e-12, gamma=0.0, lam=20.0, h=h,
                                        theta_hat0=model.theta(), hold_compensation=hold)
    x = traj(0.0)
    sim = Simulator(model, dt=h, q0=x[0], qd0=x[1])
    err = []
    for k in range(int(round(3.0 / h))):
        x = traj(k * h)
        if k * h >= 1.0:
            err.append(sim.q - x[0])
        sim.step(ctrl.step(sim.q, sim.qd, *x))
    return float(np.sqrt(np.mean(np.square(err))))


def test_the_compensated_loop_is_second_order_in_h():
    """With the true parameters the only tracking error is the sampling's: the plain hold's
    half-period lag makes it O(h) (halving h halves it), the compensated hold O(h^2)
    (halving h quarters it)."""
    model, traj = chain()
    plain = [tracking_rms(model, traj, h, False) for h in (0.004, 0.002, 0.001)]
    held = [tracking_rms(model, traj, h, True) for h in (0.004, 0.002, 0.001)]
    for a, b in zip(plain, plain[1:]):
        assert 1.7 < a / b < 2.3, plain
    for a, b in zip(held, held[1:]):
        assert 3.5 < a / b < 4.5, held
    assert held[1] < 0.1 * plain[1], (held, plain)


def test_the_paper_law_compensated_runs_the_general_kernel():
    """The paper's fused kernels hold eq 20 plainly: with the compensated hold its law runs
    the general kernel, frozen or adapting."""
    from rcac_ros.core.composite_fused import paper_step
    from rcac_ros.core.composite_kernels import rcac_step_kernel
    model, _ = chain()
    held = RecursiveCompositeController(model, hold_compensation=True)
    assert held._entry is rcac_step_kernel
    assert RecursiveCompositeController(model)._entry is paper_step
    held.set_adaptation(False)
    assert held._entry is rcac_step_kernel


def test_the_filters_see_the_torque_held():
    """The prediction channels filter the extrapolated torque, the one the arm receives: at
    the true parameters every E stays at the plain hold's level (with eq 20's own torque in
    y instead, the channels would miss the half-period difference)."""
    model, traj = chain()
    q0 = traj(0.0)[0]
    runs = [exact_run(model, 0.002, 1500, ["all", "power"], traj, q0, K_D=30.0,
                      hold_compensation=hold)[0] for hold in (False, True)]
    assert runs[1].max() < 2.0 * runs[0].max(), runs


def stays_finite(model, traj, K_D, hold):
    ctrl = RecursiveCompositeController(model, K_D=K_D, P=1e-12, gamma=0.0, h=0.002,
                                        theta_hat0=model.theta(), hold_compensation=hold)
    x = traj(0.0)
    sim = Simulator(model, dt=0.002, q0=x[0], qd0=x[1])
    try:
        for k in range(1000):
            sim.step(ctrl.step(sim.q, sim.qd, *traj(k * 0.002)))
    except InputError:                      # a state with NaN/Inf: the loop diverged
        return False
    return bool(np.all(np.isfinite(sim.q)))


def test_the_feedback_gain_limit_is_the_plain_holds():
    """The feedback is not extrapolated: over feedback gains on both sides of the sampled
    loop's limit, the compensated hold is stable exactly where the plain hold is."""
    model, traj = chain()
    plain, held = zip(*[(stays_finite(model, traj, K_D, False), stays_finite(model, traj, K_D,
                                                                             True))
                        for K_D in (100.0, 200.0, 300.0, 1000.0)])
    assert plain == held and any(plain) and not all(plain), (plain, held)
