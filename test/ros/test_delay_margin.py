"""The delay margin the controller derives per arm at configure (``controller/starvation.py``,
doc/failsafe.md "Delay margin per arm").

* ``modal_margin`` against the characteristic equation of the delayed loop: at the margin
  (plus the hold's h/2) ``det(-w^2 M + (j w D + K) e^(-j w d)) = 0`` at the crossover ``w``
  of its most delay-sensitive mode, and no mode loses its phase earlier.
* ``feedback_gains`` against a closed form: with ``K_Di = kappa M_i`` (each link's spatial
  inertia) and exact estimates, ``sum_i J_i^T K_Di J_i = kappa M``, so ``D = (kappa +
  Lambda) M`` and ``K = Lambda kappa M``.
* The margin against the delayed closed loop itself (``rcac bench delay-margin --check``): on
  the Panda, the UR5 (URDF arms) and the CSS arm the loop holding a posture settles with the
  effort 0.7 margin late and does not 1.5 margin late, and the first delay at which it does
  not settle lies within 1.5 periods above the margin.
"""

import numpy as np
import pytest

from rcac_ros.core import css_arm, RecursiveCompositeController
from rcac_ros.core.crba import mass_matrix
from rcac_ros.core.model import PAPER_Q0
from rcac_ros.nodes.controller.starvation import delay_margin, feedback_gains, modal_margin
from rcac_ros.tools.bench.delay_margin import check_margins, CHECKS, closed_loop
from rcac_ros.tools.runs.robots import example_robot_urdf
from rcac_ros.tools.runs.scenarios import spatial_inertia

H = 0.002


def characteristic(M, D, K, w, d):
    return np.linalg.det(-w ** 2 * M + (1j * w * D + K) * np.exp(-1j * w * d))


def test_a_single_velocity_loop_has_the_textbook_margin():
    # m qdd = -c qd(t - d): crossover c/m, phase margin pi/2
    m, c = 2.0, 300.0
    margin = modal_margin(np.array([[m]]), np.array([[c]]), np.zeros((1, 1)), H)
    assert margin.omega_c == pytest.approx(c / m, rel=1e-12)
    assert margin.phase_margin == pytest.approx(np.pi / 2, rel=1e-12)
    assert margin.margin == pytest.approx(np.pi / 2 / (c / m) - H / 2, rel=1e-12)


def test_the_margin_is_where_the_delayed_loop_has_a_root_on_the_imaginary_axis():
    rng = np.random.default_rng(3)
    X = rng.normal(size=(4, 4))
    M = X @ X.T + 4.0 * np.eye(4)                    # an inertia
    Y = rng.normal(size=(4, 4))
    KJ = 50.0 * (Y @ Y.T + np.eye(4))                # sum J^T K_D J
    Lam = 3.0
    D, K = KJ + Lam * M, Lam * KJ                    # the law's, scalar Lambda
    margin = modal_margin(M, D, K, H)
    d = margin.margin + H / 2                        # the continuous loop's own delay
    scale = abs(np.linalg.det(margin.omega_c ** 2 * M))
    assert abs(characteristic(M, D, K, margin.omega_c, d)) < 1e-9 * scale
    # no mode has lost its phase before: no root on the imaginary axis at a shorter delay
    # (the gain of each mode is 1 only at its own crossover, so scan each mode's)
    A = np.linalg.solve(M, D)
    for d_short in np.linspace(0.1, 0.99, 30) * d:
        for w in np.linspace(0.1, 5.0, 400) * np.max(np.abs(np.linalg.eigvals(A))):
            assert abs(characteristic(M, D, K, w, d_short)) > 1e-6 * abs(
                np.linalg.det(w ** 2 * M))


def test_the_feedback_of_inertia_scaled_gains_is_the_closed_form():
    model = css_arm()
    kappa, Lam = 40.0, 2.0
    K_D = np.array([kappa * spatial_inertia(model.mass[i], model.com[i], model.inertia[i])
                    for i in range(model.n)])
    ctrl = RecursiveCompositeController(model, K_D=K_D, Lambda=Lam, P=1e-6, gamma=1.0,
                                        lam=10.0, h=H, theta_hat0=model.theta())
    q = np.array(PAPER_Q0)
    D, K = feedback_gains(ctrl, q)
    M = mass_matrix(model, q)
    np.testing.assert_allclose(D, (kappa + Lam) * M, rtol=1e-6, atol=1e-6 * np.abs(M).max())
    np.testing.assert_allclose(K, Lam * kappa * M, rtol=1e-6,
                               atol=1e-6 * kappa * np.abs(M).max())
    # every mode the same: omega_c from omega^4 = a^2 omega^2 + b^2
    a, b = kappa + Lam, Lam * kappa
    w = np.sqrt(0.5 * (a ** 2 + np.sqrt(a ** 4 + 4 * b ** 2)))
    margin = delay_margin(ctrl, q)
    assert margin.omega_c == pytest.approx(w, rel=1e-6)
    assert margin.margin == pytest.approx(np.arctan2(a * w, b) / w - H / 2, rel=1e-6)


def test_the_derived_margin_holds_against_the_delayed_loop_on_two_urdf_arms():
    if example_robot_urdf("ur_description/urdf/ur5_robot.urdf") is None \
            or example_robot_urdf("panda_description/urdf/panda.urdf") is None:
        pytest.skip("example-robot-data is not installed")
    rows = check_margins(verbose=False)
    assert [(r["arm"], r["gain"]) for r in rows] == list(CHECKS)
    assert {r["arm"] for r in rows} >= {"panda", "ur5"}
    for r in rows:
        assert r["holds"], r
        # the measured edge (the first whole delay that does not settle) lies above the
        # margin, never below it (the margin is not optimistic), and within 1.5 periods:
        # whole periods resolve it to one, and h/2 stands for the hold
        assert r["edge_periods"] is not None, r
        assert r["edge_periods"] - 1.5 <= r["margin_periods"] <= r["edge_periods"], r
    # the margin is the arm's: the same scalar K_D (3 N m s/rad) leaves the UR5, whose wrist
    # is light, a margin over 100x shorter than the CSS arm's
    css = closed_loop("css_arm", 3.0, adapt=False)
    ur5 = closed_loop("ur5", 3.0, adapt=False)
    assert delay_margin(css[1], css[3]).margin > 100.0 * delay_margin(ur5[1], ur5[3]).margin
