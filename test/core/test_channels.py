"""Prediction channels: "all" is Slotine-Li computed recursively; every channel is exact."""

import numpy as np
import pytest
from chains import exact_run as true_parameters_run, random_chain, track

from rcac_ros.core import (GainError, PaperTrajectory, RecursiveCompositeController, Simulator,
                           SinusoidTrajectory, SlotineLiCompositeController, css_arm)
from rcac_ros.core.channels import parse_channels
from rcac_ros.core.model import PAPER_Q0

Q0 = np.array(PAPER_Q0)


def panda():
    from rcac_ros.tools.runs.scenarios import find_panda_urdf, load_panda
    if find_panda_urdf() is None:
        pytest.skip("example-robot-data not installed")
    return load_panda()


def rel_err(a, b):
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def equal_to_slotine_li(model, q0, traj, steps, **gains):
    """Closed loops of channels="all" and Slotine-Li, each on its own plant; the worst
    relative differences of efforts, estimates and prediction errors over all steps."""
    a = RecursiveCompositeController(model, channels="all", **gains)
    b = SlotineLiCompositeController(model, **gains)
    sa, sb = Simulator(model, q0=q0), Simulator(model, q0=q0)
    worst = dict(tau=0.0, theta=0.0, E=0.0)
    for k in range(steps):
        q_d, qd_d, qdd_d = traj(k * a.h)
        ta = a.step(sa.q, sa.qd, q_d, qd_d, qdd_d)
        tb = b.step(sb.q, sb.qd, q_d, qd_d, qdd_d)
        worst["tau"] = max(worst["tau"], rel_err(ta, tb))
        worst["theta"] = max(worst["theta"], rel_err(a.theta_hat, b.theta_hat))
        worst["E"] = max(worst["E"], float(np.max(np.abs(a.E - b.E))
                                           / max(1.0, np.max(np.abs(b.y)))))
        sa.step(ta)
        sb.step(tb)
    moved = np.max(np.abs(a.theta_hat - (gains.get("theta_hat0", 0.0))))
    return worst, moved


@pytest.mark.parametrize("update", ["implicit", "explicit"])
def test_all_channels_equal_slotine_li_on_the_css_arm(update):
    """2 s of closed loop, paper gains (explicit: a gain the explicit step keeps stable)."""
    gains = dict(P=100.0) if update == "implicit" else dict(P=0.005)
    traj = PaperTrajectory(Q0, reading="position", amplitude=0.2, period=4.0)
    worst, moved = equal_to_slotine_li(css_arm(), Q0, traj, 1000, update=update, **gains)
    assert max(worst.values()) < 1e-9, worst
    assert moved > 1e-3                                   # it did adapt


@pytest.mark.parametrize("update", ["implicit", "explicit"])
def test_all_channels_equal_slotine_li_on_the_panda_with_gravity(update):
    from rcac_ros.tools.runs.scenarios import AMPLITUDE, FREQUENCY, GAINS, READY, gains_for
    model = panda()
    # the explicit step diverges at the demo's rho = 30 (as Slotine-Li's does): rho = 0.3
    gains = gains_for(model, adapt_all=True,
                      **dict(GAINS, rho=GAINS["rho"] if update == "implicit" else 0.3))
    gains["theta_hat0"] = 0.7 * model.theta()
    traj = SinusoidTrajectory(np.array(READY), AMPLITUDE, FREQUENCY)
    worst, moved = equal_to_slotine_li(model, np.array(READY), traj, 1000, update=update,
                                       **gains)
    assert max(worst.values()) < 1e-9, worst
    assert moved > 1e-3


def test_all_channels_equal_slotine_li_on_a_random_chain_with_dense_gains():
    rng = np.random.default_rng(21)
    model = random_chain(rng, 5, gravity=(0.0, -9.81, 0.0))
    A = rng.normal(size=(13, 13))
    q0 = rng.normal(size=5) * 0.5
    traj = PaperTrajectory(q0, reading="position", amplitude=0.3, period=3.0)
    worst, moved = equal_to_slotine_li(model, q0, traj, 1000, K_D=np.diag(rng.uniform(20, 60, 6)),
                                       P=A @ A.T / 13 + np.eye(13), gamma=0.5, lam=20.0)
    assert max(worst.values()) < 1e-9, worst
    assert moved > 1e-3


def exact_run(model, h, steps, channels, traj, q0):
    """theta_hat = theta, adaptation off (P = 1e-12): the worst |E_c| / max |y_c| per channel."""
    ratio, ymax, ctrl = true_parameters_run(model, h, steps, channels, traj, q0, applied=True)
    assert np.allclose(ctrl.theta_hat, model.theta(), rtol=1e-9)
    return ratio, ymax


@pytest.mark.parametrize("gravity", [(0.0, 0.0, 0.0), (0.0, 0.0, -9.81)])
def test_every_channel_is_exact_with_the_true_parameters(gravity):
    """theta_hat = theta, no adaptation, the paper's motion. Joint 1 (axis fixed, parallel to
    gravity: sum psi theta = 0 and phi theta is piecewise linear, so the first-order hold is
    exact): rounding level. Every other channel, power included: the O(h^2) error of the
    holds (channels.py), shown by its convergence: h / 2 divides it by about 4."""
    model = css_arm(gravity)
    traj = PaperTrajectory(Q0)
    coarse, ymax = exact_run(model, 0.002, 1500, ["all", "power"], traj, Q0)
    fine, _ = exact_run(model, 0.001, 3000, ["all", "power"], traj, Q0)
    assert np.all(ymax > 1.0), ymax
    assert coarse[0] < 1e-11, coarse                      # 3e-13 measured
    assert np.all(coarse < 1e-5), coarse                  # 2e-6 at most, measured
    # each channel: at rounding level, or second order (power without gravity is exact: the
    # mean-power hold and the first-order hold of the kinetic energy are one interpolation)
    assert np.all((coarse < 1e-11) | (coarse / fine > 3.5)), (coarse, coarse / fine)
    assert (coarse[7] < 1e-11) == (gravity[2] == 0.0)


def test_power_channel_alone_detects_a_wrong_model():
    """The check can fail: with theta_hat off by 10% the power channel's E is large."""
    model = css_arm((0.0, 0.0, -9.81))
    traj = PaperTrajectory(Q0, reading="position")
    ctrl = RecursiveCompositeController(model, P=1e-12, theta_hat0=0.9 * model.theta(),
                                        channels="power")
    sim = Simulator(model, q0=Q0)
    worst = 0.0
    for k in range(500):
        sim.step(ctrl.step(sim.q, sim.qd, *traj(k * 0.002)))
        worst = max(worst, abs(ctrl.E[0]) / max(1.0, abs(ctrl.y[0])))
    assert worst > 1e-2


def test_default_is_the_paper_law_and_joint_one_channel():
    """channels=[1] (default), 1, "1" and [1] give identical runs; E has one entry."""
    model = css_arm()
    traj = PaperTrajectory(Q0)
    runs = []
    for channels in ((1,), 1, "1", [1]):
        kwargs = {} if channels == (1,) else dict(channels=channels)
        ctrl = RecursiveCompositeController(model, **kwargs)
        sim = Simulator(model, q0=Q0)
        for k in range(200):
            sim.step(ctrl.step(sim.q, sim.qd, *traj(k * 0.002)))
        assert ctrl.E.shape == (1,) and ctrl.channels == (1,)
        runs.append(ctrl.theta_hat)
    for r in runs[1:]:
        assert np.array_equal(r, runs[0])


def test_fused_paper_step_equals_the_general_kernel():
    """The paper's law runs a fused body (``paper_step``); a dead zone on s too small to act
    sends the same law through the general channel kernel, and so does
    ``use_fused_kernel(False)``: the three runs are bit-identical."""
    model = css_arm()
    traj = PaperTrajectory(Q0, reading="position")       # a 2 rad error: s never near 0
    runs = []
    for kwargs in ({}, dict(dead_zone_s=1e-300), None):
        ctrl = RecursiveCompositeController(model, **(kwargs or {}))
        if kwargs is None:
            ctrl.use_fused_kernel(False)
        runs.append(track(ctrl, model, traj, 500, Q0))
    for run in runs[1:]:
        for a, b in zip(runs[0], run):
            assert np.array_equal(a, b)


@pytest.mark.parametrize("options", [{"natural_metric": "log_det"}, {},
                                     {"natural_metric": "barrier", "P": np.diag(
                                         np.linspace(50.0, 150.0, 13)) + 1.0}])
def test_fused_paper_natural_step_equals_the_general_kernel(options):
    """The paper's law in the natural geometry runs the fused body too
    (``paper_natural_step``), with either metric and a diagonal or a full ``P``: bit for bit
    the general kernel's run (efforts, estimates, E and the retraction's step length at
    every step), from a 0.5 rad error."""
    from rcac_ros.core import composite_fused
    model = css_arm()
    traj = PaperTrajectory(Q0)
    runs = []
    for fused in (True, False):
        ctrl = RecursiveCompositeController(model, geometry="natural", **options)
        ctrl.use_fused_kernel(fused)
        assert (ctrl._entry is composite_fused.paper_natural_step) == fused
        sim = Simulator(model, q0=Q0 + 0.5)
        out = []
        for k in range(500):
            out.append(ctrl.step(sim.q, sim.qd, *traj(k * 0.002)))
            out += [ctrl.theta_hat, ctrl.E, np.array([ctrl.retraction_length])]
            sim.step(out[-4])
        runs.append(out)
    assert all(np.array_equal(a, b) for a, b in zip(*runs))
    assert min(float(x[0]) for x in runs[0][3::4]) > 0.0


@pytest.mark.parametrize("metric", ["log_det", "barrier"])
def test_fused_natural_step_on_chains_equals_the_general_kernel(metric):
    """The fused natural law reads its links at offsets of the packed arrays: chains of 3, 9
    and 14 links, bit for bit the general kernel's run (its own path, a row per link):
    efforts, estimates and the retraction's step length at every step, along random inputs,
    then one random state held, which shortens every step (the retraction's halvings)."""
    from rcac_ros.core import composite_fused
    rng = np.random.default_rng(11)
    for n in (3, 9, 14):
        model = random_chain(rng, n)
        inputs = [tuple(rng.normal(size=(5, n)) * 0.3) for _ in range(100)]
        inputs += [tuple(rng.normal(size=(5, n)) * 0.1)] * 100
        runs = []
        for fused in (True, False):
            ctrl = RecursiveCompositeController(model, geometry="natural",
                                                natural_metric=metric)
            ctrl.use_fused_kernel(fused)
            assert (ctrl._entry is composite_fused.paper_natural_step) == fused
            out = []
            for args in inputs:
                out += [ctrl.step(*args), ctrl.theta_hat, np.array([ctrl.retraction_length])]
            runs.append(out)
        assert all(np.array_equal(a, b) for a, b in zip(*runs))
        assert min(float(x[0]) for x in runs[0][2::3]) < 1e-3


@pytest.mark.parametrize("joint_friction", [False, True])
def test_use_fused_kernel_chooses_the_kernel(monkeypatch, joint_friction):
    """use_fused_kernel(False) sends the paper's law through the general kernel (counted
    where the controller looks it up), True back through the fused one."""
    from rcac_ros.core import composite
    name = "friction_step_kernel" if joint_friction else "rcac_step_kernel"
    general = getattr(composite, name)
    calls = []

    def counted(*args):
        calls.append(1)
        return general(*args)

    monkeypatch.setattr(composite, name, counted)
    ctrl = RecursiveCompositeController(css_arm(), joint_friction=joint_friction)
    x = (Q0, np.zeros(7), Q0 + 0.01, np.zeros(7), np.zeros(7))
    ctrl.step(*x)
    assert not calls                                      # the fused kernel
    ctrl.use_fused_kernel(False)
    ctrl.step(*x)
    ctrl.set_adaptation(True)                             # the choice survives a re-choice
    ctrl.step(*x)
    assert len(calls) == 2
    ctrl.use_fused_kernel(True)
    ctrl.step(*x)
    assert len(calls) == 2


def test_joint_channels_are_independent_of_their_order():
    """[7, 1] predicts the same two filtered torques as [1, 7] (E swapped)."""
    model = css_arm()
    traj = PaperTrajectory(Q0, reading="position")
    out = []
    for channels in ([1, 7], [7, 1]):
        ctrl = RecursiveCompositeController(model, channels=channels)
        sim = Simulator(model, q0=Q0)
        for k in range(300):
            sim.step(ctrl.step(sim.q, sim.qd, *traj(k * 0.002)))
        out.append((ctrl.E, ctrl.theta_hat))
    assert np.allclose(out[0][0], out[1][0][::-1], rtol=1e-8)
    assert np.allclose(out[0][1], out[1][1], rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("value,expected", [
    ("all", (1, 2, 3)), ("power", ("power",)), ("1,power", (1, "power")),
    ([3, "power", "1"], (3, "power", 1)), (2, (2,)), (["all", "power"], (1, 2, 3, "power")),
    (" 2 , POWER ", (2, "power")),
])
def test_parse_channels(value, expected):
    assert parse_channels(value, 3) == expected


@pytest.mark.parametrize("value,match", [
    ("0", "channels: joint 0: joints are numbered from 1"),
    ([4], "channels: joint 4 is out of range 1..3"),
    ("1,speed", "channels: 'speed' is not a joint number"),
    ([], "channels: empty"),
    ("1,1", "channels: listed twice: 1"),
    ("all,2", "channels: listed twice: 2"),
    ([1.5], "channels: 1.5 is not a joint number"),
    (None, "channels: expected joint numbers"),
    ([True], "channels: True is not a joint number"),
])
def test_parse_channels_errors(value, match):
    with pytest.raises(GainError, match=match):
        parse_channels(value, 3)


def test_bad_options_raise_gain_error():
    model = css_arm()
    for kwargs, match in ((dict(channels="8"), "channels: joint 8"),
                          (dict(update="trapezoid"), "update: expected"),
                          (dict(adaptation="rls"), "adaptation: expected"),
                          (dict(forgetting=-1.0), "forgetting: must be >= 0"),
                          (dict(P_max=0.0), "P_max: must be > 0"),
                          (dict(dead_zone_E=-1.0), "dead_zone_E: must be >= 0"),
                          (dict(theta_bounds="box"), "theta_bounds: expected"),
                          (dict(theta_bounds=(1.0, 0.0)), "theta_min > theta_max"),
                          (dict(theta_bounds=(np.zeros(5), 1.0)), "theta_min: expected")):
        with pytest.raises(GainError, match=match):
            RecursiveCompositeController(model, **kwargs)
    with pytest.raises(GainError, match="update: expected"):
        SlotineLiCompositeController(model, update="x")
