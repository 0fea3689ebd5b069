"""``scale_K_D``: the degraded gain of a starved machine (doc/failsafe.md, "Starved machine")."""

import numpy as np
import pytest

from rcac_ros.core import PaperTrajectory, RecursiveCompositeController, Simulator, css_arm
from rcac_ros.errors import GainError

Q0 = np.array([0.3, np.pi / 2, np.pi / 3, -2 * np.pi / 3, np.pi / 3, np.pi / 2, 0.3])


def run(ctrl, model, steps=400, scale_at=None):
    """Efforts and estimates of a closed loop on the paper's motion."""
    sim = Simulator(model, q0=Q0)
    traj = PaperTrajectory(Q0)
    out = []
    for k in range(steps):
        if scale_at is not None and k == scale_at[0]:
            ctrl.scale_K_D(scale_at[1])
        tau = ctrl.step(sim.q, sim.qd, *traj(k * 0.002))
        out.append(tau)
        sim.step(tau)
    return np.array(out), ctrl.theta_hat


@pytest.mark.parametrize("factor", [0.3, 0.02])
def test_scaled_K_D_is_the_law_built_with_the_smaller_gain(factor):
    model = css_arm()
    scaled = RecursiveCompositeController(model, K_D=1e4)
    scaled.scale_K_D(factor)
    built = RecursiveCompositeController(model, K_D=1e4 * factor)
    tau_s, th_s = run(scaled, model)
    tau_b, th_b = run(built, model)
    np.testing.assert_allclose(tau_s, tau_b, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(th_s, th_b, rtol=1e-12, atol=1e-12)
    assert scaled.K_D_scale == factor
    np.testing.assert_array_equal(scaled.K_D, RecursiveCompositeController(model).K_D)


def test_scale_back_to_one_is_the_nominal_law_again():
    model = css_arm()
    a = RecursiveCompositeController(model)
    a.scale_K_D(0.1)
    a.scale_K_D(1.0)
    tau_a, _ = run(a, model, 100)
    tau_b, _ = run(RecursiveCompositeController(model), model, 100)
    np.testing.assert_array_equal(tau_a, tau_b)


@pytest.mark.parametrize("bad", [0.0, -0.5, 1.5, np.nan, "x"])
def test_scale_outside_the_unit_interval_is_refused(bad):
    with pytest.raises(GainError, match="factor"):
        RecursiveCompositeController(css_arm()).scale_K_D(bad)
