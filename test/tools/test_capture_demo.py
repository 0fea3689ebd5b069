"""``rcac capture-demo``'s figures against closed forms, its slowed motion against the inverse
dynamics, and its arguments refused in one line before anything runs."""

import numpy as np
import pytest

from rcac_ros.tools.cli import main
from rcac_ros.tools.demos.capture import EFFORT_SHARE, cube_inertia, slowdown, truth
from rcac_ros.tools.demos.capture_figures import effort_figures, recovery_time


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


def test_the_figures_cut_the_same_samples_from_stamps_and_from_k_h():
    """A bag's times (``sec + 1e-9 nsec``) and an offline loop's (``k h``) round apart (step
    858 of 2 ms: 1.7160000000000002 against 1.716); with an error that grows to the end of
    the phase, the two must still give the same figures."""
    from rcac_ros.tools.demos.capture_figures import figures
    h_ns, steps = 2_000_000, 1000
    ns = np.arange(steps) * h_ns
    from_stamps = ns // 1_000_000_000 + (ns % 1_000_000_000) * 1e-9
    from_k_h = np.arange(steps) * 0.002
    assert from_stamps[858] != from_k_h[858]            # the case: they do round apart
    at, release = from_stamps[502], from_stamps[858]
    e = np.outer(np.arange(steps, dtype=float), [1e-4, 2e-4])     # largest at the end
    tau = np.outer(np.arange(steps, dtype=float), [1.0, 0.5])
    theta = np.tile(np.arange(13.0), (steps, 1))
    truth = np.arange(13.0) + 1.0
    got = [figures((t, e), (t, tau), (t, theta), at, release, truth, np.array([2e3, 2e3]))
           for t in (from_stamps, from_k_h)]
    assert got[0]["peak_error_norm_after_rad"] == pytest.approx(np.linalg.norm(e[857]),
                                                                rel=1e-15)
    for key in ("rms_error_before_rad", "peak_error_norm_after_rad", "max_effort_nm",
                "steps_at_limit", "mass_estimate_end_kg"):
        assert got[0][key] == pytest.approx(got[1][key], rel=1e-12), key


def test_effort_figures_find_the_first_step_at_a_limit():
    t = np.arange(5) * 0.5
    tau = np.array([[1.0, 0.0], [2.0, 5.0], [4.0, 10.0], [1.0, 10.0], [0.0, 0.0]])
    fig = effort_figures((t, tau), np.array([4.0, 20.0]), 0.0, 10.0)
    assert fig["limit_first_reached_s"] == 1.0 and fig["limit_first_reached_joint"] == 1
    assert fig["steps_at_limit"] == 1 and fig["max_effort_over_limit"] == 1.0
    assert effort_figures((t, tau), np.array([8.0, 20.0]), 0.0, 10.0)[
        "limit_first_reached_s"] is None


def test_effort_figures_of_a_phase_without_efforts_say_so():
    """A phase with no effort sample (a run cut short) gives no maximum and no limit
    reached, rather than an error."""
    t, tau = np.arange(10) * 0.1, np.ones((10, 2))
    fig = effort_figures((t, tau), np.array([4.0, 20.0]), 5.0, 6.0)
    assert np.isnan(fig["max_effort_nm"]) and fig["limit_first_reached_s"] is None
    assert fig["steps_at_limit"] == 0


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
     "rcac capture-demo: error: --inertia: not a body"),
    (["--com", "100", "0", "0"], "rcac capture-demo: error: --com: 100 m from the last link"),
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


def test_a_short_capture_over_ros_equals_the_same_loop_offline(tmp_path):
    """A 2 s run, grasped at 1 s and released at 1.5 s, over DDS: the bag holds both changes
    (each a few steps after its request at most: the request goes out when the tool reads
    the sim time), and the ROS run's figures equal those of the composite law offline with
    the changes at the bag's times (lockstep runs the node's loop exactly: the same
    controller, the same plant)."""
    import json
    import os
    import subprocess
    import sys
    pytest.importorskip("domain_coordinator")
    out = tmp_path / "capture"
    proc = subprocess.run([sys.executable, "-m", "rcac_ros.tools.cli", "capture-demo",
                           "--duration", "2", "--at", "1", "--release", "1.5", "--quiet",
                           "--out", str(out)], env=dict(os.environ, PYTHONUNBUFFERED="1"),
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    doc = json.loads((out / "capture.json").read_text())
    changes = doc["ros"]["payload_changes"]
    assert [c["mass"] for c in changes] == [0.0, 1000.0, 0.0], proc.stdout[-3000:]
    assert 1.0 <= changes[1]["t"] < 1.5 <= changes[2]["t"] < 2.0, changes
    sim_log = (out / "logs" / "simulator.log").read_text()
    held = [line for line in sim_log.splitlines() if "finished" in line or "miss" in line]
    for phase in ("capture", "release"):
        ros, offline = doc["ros"][phase], doc["offline"]["composite"][phase]
        # (not the efforts: the node clips its command at the limit, offline the plant clips
        # what the law asks; both report the clipped torque to the law)
        for key in ("rms_error_before_rad", "peak_error_norm_after_rad",
                    "mass_estimate_end_kg", "first_moment_relative_error_end"):
            # the figures pass through CDR doubles unchanged; the offline loop is the same
            # arithmetic: agreement to rounding
            assert ros[key] == pytest.approx(offline[key], rel=1e-9, abs=1e-12), \
                (phase, key, held, proc.stdout[-3000:])
        assert ros["goals"]["no_watchdog_trip"] is True
    for name in ("capture.md", "capture_ros.png", "capture_laws.png"):
        assert (out / name).is_file()


def test_a_bag_without_the_controllers_answers_is_named_with_its_log(tmp_path, capsys):
    """A bag with the simulator's clock only (no answer of the controller recorded): one
    error that names what is missing and quotes the controller's log, exit 1."""
    from rosbags.typesys import get_typestore, Stores
    from rcac_ros.tools.bags.writer import BagWriter
    store = get_typestore(Stores.ROS2_JAZZY)
    Clock = store.types["rosgraph_msgs/msg/Clock"]
    Time = store.types["builtin_interfaces/msg/Time"]
    w = BagWriter(str(tmp_path / "bag"), "mcap", flush_period=1e9)
    w.add_topic("/clock", "rosgraph_msgs/msg/Clock")
    for k in range(10):
        raw = store.serialize_cdr(Clock(clock=Time(sec=0, nanosec=k * 2_000_000)),
                                  "rosgraph_msgs/msg/Clock")
        w.write("/clock", 10**18 + k, bytes(raw), sequence=k + 1)
    w.close()
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "controller.log").write_text("[ERROR] the control step raised\n")
    assert main(["capture-demo", "--bag", str(tmp_path / "bag"), "--quiet"]) == 1
    err = capsys.readouterr().err
    first = err.splitlines()[0]
    assert first.startswith("rcac capture-demo: error: the bag holds no tracking_error and no "
                            "parameter_estimates of the controller"), err
    assert "'/clock': 10" in first and "the control step raised" in err
