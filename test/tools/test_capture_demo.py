"""``rcac capture-demo``'s figures against closed forms, its slowed motion against the inverse
dynamics, and its arguments refused in one line before anything runs."""

import numpy as np
import pytest

from rcac_ros.tools.cli import main
from rcac_ros.tools.demos.capture import (EFFORT_SHARE, cube_inertia, effort_figures,
                                          recovery_time, slowdown, truth)


def test_recovery_time_of_a_burst_is_its_closed_form():
    """Error a before and after a burst of size B over [tc, tc + 2): the trailing 1 s RMS is
    within 2a once the window holds a share f <= 3 a^2 / (B^2 - a^2) of the burst, so the
    recovery is 3 - f s after tc (to one sample)."""
    dt, tc, a, B = 1e-3, 5.0, 1.0, 10.0
    t = np.arange(0.0, 12.0, dt)
    e = np.full((t.size, 2), a)
    e[(t >= tc) & (t < tc + 2.0)] = B
    got = recovery_time(t, e, tc, t[-1] + dt, reference=a)
    f = 3 * a * a / (B * B - a * a)
    assert got == pytest.approx(3.0 - f, abs=2 * dt)
    assert recovery_time(t, np.full((t.size, 2), a), tc, 12.0, reference=a) == 0.0
    e[t >= tc] = B                                     # never back: not recovered
    assert recovery_time(t, e, tc, 12.0, reference=a) is None


def test_effort_figures_find_the_first_step_at_a_limit():
    t = np.arange(5) * 0.5
    tau = np.array([[1.0, 0.0], [2.0, 5.0], [4.0, 10.0], [1.0, 10.0], [0.0, 0.0]])
    fig = effort_figures((t, tau), np.array([4.0, 20.0]), 0.0, 10.0)
    assert fig["limit_first_reached_s"] == 1.0 and fig["limit_first_reached_joint"] == 1
    assert fig["steps_at_limit"] == 1 and fig["max_effort_over_limit"] == 1.0
    assert effort_figures((t, tau), np.array([8.0, 20.0]), 0.0, 10.0)[
        "limit_first_reached_s"] is None


@pytest.mark.parametrize("mass", [1000.0, 20000.0])
def test_the_slowed_motion_needs_the_stated_share_of_the_limits(mass):
    """The paper's motion slowed by s (amplitude A / s, period 20 s * s): the inverse dynamics
    along it, computed afresh, peak at EFFORT_SHARE of a limit (zero gravity: tau / s^2)."""
    from rcac_ros.core import PAPER_Q0, PaperTrajectory, inverse_dynamics
    _, loaded, _ = truth(mass, (0.0, 0.0, 2.0), cube_inertia(mass))
    s, need = slowdown(loaded)
    assert s > 1.0 and need > EFFORT_SHARE
    base = PaperTrajectory(np.array(PAPER_Q0))
    slow = PaperTrajectory(np.array(PAPER_Q0), amplitude=base.amplitude / s,
                           period=20.0 * s)
    worst = max(np.max(np.abs(inverse_dynamics(loaded, *slow(t))) / loaded.effort_limit)
                for t in np.linspace(0.0, 20.0 * s, 4001))
    # the same instants as slowdown's 2001 samples and more: the peak between samples differs
    # by the sampling's resolution only
    assert worst == pytest.approx(EFFORT_SHARE, rel=1e-3)
    # and the position path is the paper's: the same points, later
    np.testing.assert_allclose(slow(7.0 * s)[0], base(7.0)[0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("argv, start", [
    (["--at", "40"], "rcac capture-demo: error: --at: the capture must come before the end"),
    (["--release", "5"], "rcac capture-demo: error: --release: must be after --at"),
    (["--inertia", "1", "1", "5", "0", "0", "0"],
     "rcac capture-demo: error: payload.inertia: not a body"),
    (["--bag", "/nonexistent/bag"], "rcac capture-demo: error: --bag: no such directory"),
])
def test_bad_arguments_are_one_line_and_exit_2(argv, start, capsys):
    # each is refused before the nodes start (a valid set would run them)
    assert main(["capture-demo", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(start) and "\n" not in err, err


def test_a_negative_mass_is_refused_by_the_parser(capsys):
    with pytest.raises(SystemExit) as code:
        main(["capture-demo", "--mass", "-1"])
    assert code.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "--mass" in err and "\n" not in err
