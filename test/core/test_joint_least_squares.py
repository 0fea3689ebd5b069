"""Least squares on the joint terms (doc/design.md §7; its 3x3 information update is in
test_least_squares.py): the diagonal law without information, the bound P_f <= P_friction,
freezing, the options, and the identification."""

import numpy as np
import pytest
from chains import frictional_chain, worst_difference

from rcac_ros.core import GainError, RecursiveCompositeController, Simulator
from rcac_ros.core.composite_kernels import friction_step_kernel


def laws(gamma, **options):
    model, q0, traj = frictional_chain()
    gains = dict(K_D=30.0, P=1.0, gamma=gamma, lam=20.0, channels="all", joint_friction=True,
                 friction_hat0=np.zeros((5, 3)), P_friction=(0.5, 5.0, 5.0))
    gains.update(options)
    ls = RecursiveCompositeController(model, friction_adaptation="least_squares", **gains)
    fixed = RecursiveCompositeController(model, friction_adaptation="gradient", **gains)
    return ls, fixed, model, q0, traj


def test_without_information_least_squares_is_the_diagonal_law():
    """gamma = 0 (the direct law): no channel informs the gain, so P_f stays P_friction and
    both laws give the same efforts and estimates (to rounding of sqrt(P)^2)."""
    ls, fixed, model, q0, traj = laws(0.0)
    gains = []
    worst = worst_difference(ls, fixed, model, q0, traj,
                             each_step=lambda c: gains.append(ls.friction_gain))
    assert worst < 1e-12, worst
    expected = np.array([np.diag((0.5, 5.0, 5.0))] * 5)
    assert np.allclose(gains[-1], expected, rtol=1e-14, atol=0.0)
    assert ls._entry is friction_step_kernel      # never the paper law's fused body


@pytest.mark.parametrize("forgetting", [0.0, 5.0])
def test_information_lowers_the_gain_never_above_P_friction(forgetting):
    """With the channels the gain falls below P_friction (in the Loewner order) and, with
    forgetting too, never rises above it; the two laws differ."""
    ls, fixed, model, q0, traj = laws(0.5, friction_forgetting=forgetting)
    P0 = np.diag((0.5, 5.0, 5.0))
    lowest = []

    def check(_):
        P = ls.friction_gain
        for Pi in P:
            assert np.allclose(Pi, Pi.T, rtol=0.0, atol=1e-15 * np.abs(Pi).max())
            assert np.linalg.eigvalsh(Pi).min() > 0.0
            assert np.linalg.eigvalsh(P0 - Pi).min() > -1e-13 * 5.0
        lowest.append(np.trace(P, axis1=1, axis2=2).min())

    worst = worst_difference(ls, fixed, model, q0, traj, each_step=check)
    assert min(lowest) < 0.99 * 10.5               # the information lowered it
    assert worst > 1e-3


def test_largest_eigenvalue_of_a_symmetric_3x3():
    """The closed form against numpy's eigvalsh: random, diagonal, all equal with
    off-diagonals below the underflow of p^3, and a double largest eigenvalue."""
    from rcac_ros.core.joint_friction import largest_eigenvalue
    rng = np.random.default_rng(42)
    cases = [np.diag((1.0, 1.0, 1.0)), np.diag((0.2, 3.0, 1.0)),
             np.diag((2.0, 2.0, 2.0)) + 1e-120 * (np.ones((3, 3)) - np.eye(3))]
    for _ in range(200):
        A = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-3, 3)
        cases.append(A @ A.T)
    for A in cases:
        got = largest_eigenvalue(A[0, 0], A[0, 1], A[0, 2], A[1, 1], A[1, 2], A[2, 2])
        ref = np.linalg.eigvalsh(A).max()
        assert got == pytest.approx(ref, rel=1e-12, abs=1e-14 * np.abs(A).max())
    # a double largest eigenvalue (a first Potter step from Q = I): acos near 1 keeps half
    # the digits, sqrt(eps) ~ 1.5e-8
    for v in ((1.0, 2.0, 3.0), (1.0, 1.0, 1.0), (0.0, 0.3, -2.0)):
        v = np.asarray(v) / np.linalg.norm(v)
        A = np.eye(3) - 0.5 * np.outer(v, v)
        got = largest_eigenvalue(A[0, 0], A[0, 1], A[0, 2], A[1, 1], A[1, 2], A[2, 2])
        assert got == pytest.approx(1.0, rel=1.5e-8)


def test_a_frozen_law_holds_its_joint_gain():
    ls, _, model, q0, traj = laws(0.5)
    sim = Simulator(model, q0=q0)
    for k in range(300):
        sim.step(ls.step(sim.q, sim.qd, *traj(k * 0.002)))
    ls.set_adaptation(False)
    P, fh = ls.friction_gain, ls.friction_hat
    for k in range(300, 600):
        sim.step(ls.step(sim.q, sim.qd, *traj(k * 0.002)))
    assert np.array_equal(ls.friction_gain, P) and np.array_equal(ls.friction_hat, fh)


@pytest.mark.parametrize("options, match", [
    (dict(friction_adaptation="newton"), "friction_adaptation: expected"),
    (dict(friction_adaptation="least_squares", geometry="natural"), "needs geometry"),
    (dict(friction_forgetting=-1.0), "friction_forgetting"),
    (dict(joint_friction=False, friction_adaptation="least_squares"), "needs joint_friction"),
])
def test_bad_options_are_one_line_errors(options, match):
    model, _, _ = frictional_chain()
    options = dict(dict(joint_friction=True), **options)
    with pytest.raises(GainError, match=match) as err:
        RecursiveCompositeController(model, **options)
    assert "\n" not in str(err.value)


def test_the_paper_law_with_least_squares_runs_the_general_kernel():
    """The paper's fused kernel has the diagonal gain only: with the joint least squares
    the paper's law (channel 1) runs the general kernel, and its joint 1 gain falls."""
    from rcac_ros.core.composite_fused import paper_friction_step
    model, q0, traj = frictional_chain()
    opts = dict(K_D=30.0, P=1.0, gamma=0.5, lam=20.0, joint_friction=True,
                P_friction=(0.5, 5.0, 5.0))
    ls = RecursiveCompositeController(model, friction_adaptation="least_squares", **opts)
    fixed = RecursiveCompositeController(model, **opts)
    assert ls._entry is friction_step_kernel and fixed._entry is paper_friction_step
    sim = Simulator(model, q0=q0)
    for k in range(200):
        sim.step(ls.step(sim.q, sim.qd, *traj(k * 0.002)))
    P = ls.friction_gain
    assert np.trace(P[0]) < 0.99 * 10.5                     # joint 1: channel 1 informs it
    np.testing.assert_allclose(P[1:], np.array([np.diag((0.5, 5.0, 5.0))] * 4), rtol=1e-12)


def test_the_panda_learns_its_joint_terms_with_its_links_known():
    """``rcac friction-demo``'s plant and motion, every link known, every channel, 20 s from
    zero joint estimates: least squares brings every armature and damping within the demo's
    10 % and every Coulomb term within its 15 % (tools.md, friction-demo)."""
    from rcac_ros.tools.demos.friction import GOALS, run_friction_demo
    from rcac_ros.tools.runs.scenarios import find_panda_urdf
    if find_panda_urdf() is None:
        pytest.skip("example-robot-data not installed")
    _, hist, truth, _ = run_friction_demo(20.0, links_known=True, record_every=10000,
                                          friction_adaptation="least_squares")
    worst = (np.abs(hist[-1] - truth) / truth).max(axis=0)
    assert np.all(worst <= np.array(GOALS)), worst
