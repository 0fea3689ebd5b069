"""The node guards alone (no ROS): stamps, sizes, goals, desired-state limits, params files."""

import numpy as np
import pytest

from rcac_ros.errors import ConfigError
from rcac_ros.nodes.safety.guards import check_end, check_goal, DesiredLimiter, oversize, Rejected
from rcac_ros.nodes.runtime.paramcheck import (check_params_files, foreign_sections,
                                               load_params_file, unknown_parameters)
from rcac_ros.nodes.safety.state_guards import SafeStop, StampGate

MS = 1_000_000
S = 1_000_000_000


def stream(gate, stamps, t0=0, period=2 * MS, stale=False):
    """Feed stamps received one period apart (steady time); return the verdicts."""
    return [gate.check(s, t0 + k * period, stale) for k, s in enumerate(stamps)]


def test_stamps_moving_forward_are_accepted():
    gate = StampGate()
    assert set(stream(gate, [k * 2 * MS for k in range(100)])) == {"ok"}
    # a lockstep simulator faster than real time (10 x) still passes
    gate = StampGate()
    assert set(stream(gate, [k * 20 * MS for k in range(100)])) == {"ok"}


def test_one_future_stamp_is_refused_and_does_not_poison():
    gate = StampGate(max_jump=1.0)
    stamps = [k * 2 * MS for k in range(10)] + [10_000 * S] + [k * 2 * MS for k in range(11, 30)]
    verdicts = stream(gate, stamps)
    assert verdicts[10] == "stamp future"
    assert set(verdicts[:10] + verdicts[11:]) == {"ok"}
    assert gate.last == 29 * 2 * MS


def test_a_first_stamp_in_the_future_is_replaced_after_restart_count():
    gate = StampGate(restart_count=5)
    verdicts = stream(gate, [10_000 * S] + [k * 2 * MS for k in range(1, 20)])
    assert verdicts[1:5] == ["stamp"] * 4 and verdicts[5] == "restart"
    assert set(verdicts[6:]) == {"ok"}
    assert gate.restarts == 1


def test_restart_is_accepted_at_once_when_the_watchdog_tripped():
    gate = StampGate(restart_count=50)
    stream(gate, [S + k * 2 * MS for k in range(10)])
    # the simulator restarted: silence (stale), then stamps from 0
    assert gate.check(0, 5 * S, stale=True) == "restart"
    assert gate.check(2 * MS, 5 * S + 2 * MS) == "ok"


def test_restart_without_watchdog_needs_consecutive_consistent_stamps():
    gate = StampGate(restart_count=10)
    stream(gate, [5 * S + k * 2 * MS for k in range(10)])
    verdicts = stream(gate, [k * 2 * MS for k in range(12)], t0=S)
    assert verdicts[:9] == ["stamp"] * 9 and verdicts[9] == "restart"
    assert verdicts[10:] == ["ok", "ok"]


def test_isolated_old_or_shuffled_stamps_never_restart():
    gate = StampGate(restart_count=3)
    stream(gate, [5 * S + k * 2 * MS for k in range(10)])
    # old stamps that do not form an increasing run: each refused
    olds = [S, 0, S, 0, S, 0]
    assert stream(gate, olds, t0=S) == ["stamp"] * 6
    assert gate.restarts == 0


def test_size_cap():
    oversize(100, 100, "state")
    oversize(10 ** 9, 0, "state")           # 0: no cap
    with pytest.raises(Rejected) as err:
        oversize(101, 100, "state")
    assert err.value.kind == "size" and "max_state_bytes" in str(err.value)


def goal(**kw):
    n = 2
    args = dict(start_ns=None, times=np.array([1.0, 2.0]), pos=np.zeros((2, n)), vel=None,
                now_ns=10 * S, lower=np.full(n, -1.0), upper=np.full(n, 1.0),
                vmax=np.full(n, 0.5))
    args.update(kw)
    return check_goal(**args)


def test_goal_checks():
    goal()
    goal(start_ns=9 * S)                    # ends at 11 s: still running
    with pytest.raises(Rejected) as err:
        goal(start_ns=7 * S)                # ended at 9 s
    assert err.value.kind == "past"
    goal(start_ns=7 * S, now_ns=None)       # the end left to the caller (the FJT server)
    with pytest.raises(Rejected) as err:
        goal(pos=np.array([[0.0, 0.0], [0.0, 1.5]]))
    assert err.value.kind == "position limit" and "points[1].positions[1]" in str(err.value)
    with pytest.raises(Rejected) as err:
        goal(vel=np.array([[0.0, -0.6], [0.0, 0.0]]))
    assert err.value.kind == "velocity limit"
    # unbounded models accept anything finite
    goal(pos=np.full((2, 2), 1e6), lower=np.full(2, -np.inf), upper=np.full(2, np.inf))


def test_end_check():
    """JTC's rule, the one check of the topic and the FollowJointTrajectory server."""
    times = np.array([1.0, 2.0])
    check_end(None, times, 10 * S)          # no stamp: starts now, never in the past
    check_end(8 * S, times, 10 * S)         # ends exactly now: accepted (before now is refused)
    with pytest.raises(Rejected) as err:
        check_end(7 * S, times, 10 * S)     # ended at 9 s
    assert err.value.kind == "past" and "ends 1.000 s in the past" in str(err.value)


def test_desired_limiter_bounds_each_step_and_converges():
    h = 0.002
    lim = DesiredLimiter(0.01, 0.1, h, 2)
    z = np.zeros(2)
    lim(z, z, z)
    target = np.array([100.0, -0.005])
    qs = []
    for _ in range(20):
        q, qd, qdd = lim(target, np.array([1e3, 0.0]), np.array([1e6, 0.0]))
        qs.append(q.copy())
        assert np.all(np.abs(qdd) <= 0.1 / h + 1e-12)
    steps = np.diff(np.vstack([z] + qs), axis=0)
    assert np.all(np.abs(steps) <= 0.01 + 1e-15)
    np.testing.assert_allclose(qs[-1], [0.2, -0.005])   # 20 steps of 0.01; the small one at once
    assert lim.limited == 20
    # within the limits the desired state passes unchanged
    lim = DesiredLimiter(0.01, 0.1, h, 2)
    for k in range(5):
        q = np.full(2, 0.001 * k)
        out = lim(q, z, z)
        np.testing.assert_array_equal(out[0], q)
    assert lim.limited == 0


def test_safe_stop_counts_spells_once_and_replans_after_a_long_one():
    ms = 1_000_000
    stop = SafeStop(replan_after=0.5)
    assert stop.resume(0) is None               # no spell: nothing to resume
    assert stop.trip(10 * ms) and stop.active
    assert not any(stop.trip(t * ms) for t in range(20, 400, 10))   # the same spell
    assert stop.resume(400 * ms) == (0.39, False)   # short: the motion goes on
    assert not stop.active and stop.resume(401 * ms) is None
    assert stop.trip(1000 * ms)
    assert stop.resume(1500 * ms) == (0.5, True)    # from replan_after on: replan
    assert stop.trip(2000 * ms)
    stop.cancel()                               # (a lockstep simulator that waited)
    assert stop.resume(9000 * ms) is None
    assert (stop.spells, stop.replans) == (3, 1)


def test_a_spell_runs_from_the_laws_last_effort_and_a_stall_is_one():
    """A loop that stalled trips the watchdog only when it runs again: the arm held the last
    effort since the law's last step, which is what the spell's length must measure; a
    stall the watchdog never saw is a spell too, in timer mode only."""
    ms = 1_000_000
    stop = SafeStop(replan_after=0.5)
    stop.controlled(100 * ms)                   # the law's last effort
    assert stop.trip(8800 * ms)                 # the watchdog, once the loop runs again
    assert stop.resume(8802 * ms, stalls=True) == (pytest.approx(8.702), True)
    stop.controlled(8802 * ms)
    assert stop.resume(9301 * ms, stalls=True) is None      # within replan_after: a delay
    stop.controlled(9301 * ms)
    assert stop.resume(9900 * ms) is None       # lockstep: the simulator waited
    assert stop.resume(9900 * ms, stalls=True) == (pytest.approx(0.599), True)
    assert (stop.spells, stop.stalls, stop.replans) == (1, 1, 2)
    stop.restart()                              # activation: nothing to measure from
    assert stop.resume(20000 * ms, stalls=True) is None


def test_params_file_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("rcac_controller:\n  ros__parameters:\n    K_D: [1.0\n")
    with pytest.raises(ConfigError) as err:
        load_params_file(str(bad))
    text = str(err.value)
    assert "\n" not in text and str(bad) in text and "line" in text
    flat = tmp_path / "flat.yaml"
    flat.write_text("K_D: 3.0\n")
    with pytest.raises(ConfigError, match="ros__parameters"):
        load_params_file(str(flat))
    with pytest.raises(ConfigError, match="missing.yaml"):
        check_params_files(["--ros-args", "--params-file", str(tmp_path / "missing.yaml")])


def test_unknown_keys_get_the_nearest_name(tmp_path):
    good = tmp_path / "p.yaml"
    good.write_text("rcac_controler:\n  ros__parameters:\n    gains:\n      K_d: 1.0\n"
                    "/**:\n  ros__parameters:\n    use_sim_time: false\n")
    files = check_params_files(["--params-file", str(good)])
    assert files[str(good)]["rcac_controler"] == {"gains.K_d": 1.0}
    assert foreign_sections(files, ["rcac_controller", "rcac_simulator"]) == [
        (str(good), "rcac_controler", "rcac_controller")]
    unknown = unknown_parameters(["K_d", "use_sim_time", "rate", "zzz"], ["K_D", "rate"])
    assert unknown == [("K_d", "K_D"), ("zzz", None)]


def test_state_predictor_against_constant_acceleration():
    """One joint about its axis, torque held: q(T) = q + qd T + tau T^2 / (2 I), exactly."""
    from rcac_ros.core.model import RobotModel
    from rcac_ros.nodes.controller.lookahead import StatePredictor
    model = RobotModel([[0.0, 0.0, 0.0]], [np.eye(3)], [3.0], [[0.0, 0.0, 0.0]],
                       [np.diag([1.0, 1.0, 2.0])], (0.0, 0.0, 0.0))
    pred = StatePredictor(model, lookahead=0.002)
    pred.applied = np.array([5.0])
    q, qd = pred(np.array([0.3]), np.array([-0.1]), age_ns=1_500_000)
    T = 0.0035
    np.testing.assert_allclose(q, 0.3 - 0.1 * T + 5.0 * T ** 2 / 4.0, rtol=1e-12)
    np.testing.assert_allclose(qd, -0.1 + 5.0 * T / 2.0, rtol=1e-12)
