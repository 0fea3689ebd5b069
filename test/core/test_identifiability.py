"""Identifiability report: excitation rank against the regressor's known rank, consistency."""

import numpy as np
import pytest

from rcac_ros.core import (InputError, PaperTrajectory, RecursiveCompositeController, Simulator,
                           css_arm, link_regressor, theta_from_inertia)
from rcac_ros.core.identifiability import Excitation, consistency, inertia_about_com
from rcac_ros.core.model import PAPER_Q0, rpy_matrix


def test_excitation_rank_of_random_regressor_rows_is_the_regressor_rank():
    """Rows of Y(Vdot_r, V_r, w) with w_r != w span 11 dimensions, with V_r = V 10
    (doc/design.md §2): the accumulated Sigma's numerical rank says so."""
    rng = np.random.default_rng(41)
    for same, expected in ((False, 11), (True, 10)):
        exc = Excitation(1, 0.002)
        for _ in range(200):
            Vd, Vr = rng.normal(size=(2, 6))
            w = Vr[3:] if same else rng.normal(size=3)
            exc.add(link_regressor(Vd, Vr, w, rng.normal(size=3))[:, None, :])
        rep = exc.report()[0]
        assert rep["identifiable_combinations"] == expected
        assert rep["sigma_max"] > 0 and rep["condition"] > 1e6   # the rest is unexcited


def test_excitation_rejects_rows_of_another_chain():
    with pytest.raises(InputError, match="W: expected shape"):
        Excitation(2, 0.002).add(np.zeros((1, 3, 13)))


def test_excitation_matches_numpy_sum():
    rng = np.random.default_rng(42)
    W = rng.normal(size=(20, 3, 4, 13))
    exc = Excitation(4, 0.5)
    for w in W:
        exc.add(w)
    ref = 0.5 * np.einsum("kcia,kcib->iab", W, W)
    assert np.allclose(exc.sigma, ref, rtol=1e-12)


def test_consistency_of_true_and_broken_parameters():
    rng = np.random.default_rng(43)
    good = []
    for _ in range(5):
        Q = rpy_matrix(rng.uniform(-3, 3, 3))
        a, b = rng.uniform(0.1, 1.0, 2)
        c = rng.uniform(abs(a - b) + 0.01, a + b - 0.01)
        com = rng.normal(size=3) * 0.2
        I = Q @ np.diag([a, b, c]) @ Q.T
        theta = theta_from_inertia(2.0, com, I)
        m, c_hat, I_c = inertia_about_com(theta)
        assert m == pytest.approx(2.0) and np.allclose(c_hat, com) and np.allclose(I_c, I)
        good.append(theta)
    assert all(r["consistent"] for r in consistency(good))
    bad = np.array(good)
    bad[0, 0] = -1.0                          # negative mass
    bad[1, 10:13] = [0.1, 0.1, 5.0]           # moments that break the triangle inequality
    bad[2, 10] = -50.0                        # I_c not positive definite
    rep = consistency(bad)
    assert not rep[0]["mass_positive"]
    assert rep[1]["mass_positive"] and not rep[1]["triangle"]
    assert not rep[2]["inertia_pd"]
    assert rep[3]["consistent"] and rep[4]["consistent"]


def test_more_channels_excite_more_combinations_on_the_paper_run():
    """Joint 1 alone informs the last links in fewer directions than all channels do."""
    model = css_arm()
    q0 = np.array(PAPER_Q0)
    traj = PaperTrajectory(q0)
    ranks = {}
    for channels in ([1], "all"):
        ctrl = RecursiveCompositeController(model, channels=channels)
        exc = Excitation(model.n, ctrl.h)
        sim = Simulator(model, q0=q0)
        for k in range(1500):
            sim.step(ctrl.step(sim.q, sim.qd, *traj(k * ctrl.h)))
            exc.add(ctrl.W)
        ranks[str(channels)] = sum(r["identifiable_combinations"] for r in exc.report())
    assert ranks["all"] > ranks["[1]"]
