"""The controller node in-process: bad input, watchdog, parameters, trajectories, velocities."""

import math
import threading
import types

import numpy as np
import pytest

from test_nodes_support import (JOINTS, NS, PAPER_Q0, Probe, ros_context, spin_until,
                                two_link_urdf)

from rclpy.parameter import Parameter  # noqa: E402  (after the importorskip in support)
from sensor_msgs.msg import JointState  # noqa: E402
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint  # noqa: E402

from rcac_ros.core.model import css_arm, PAPER_GAINS  # noqa: E402
from rcac_ros.core.composite import RecursiveCompositeController  # noqa: E402
from rcac_ros.core.trajectory import PaperTrajectory  # noqa: E402
from rcac_ros.errors import ConfigError  # noqa: E402
from rcac_ros.nodes.controller.node import ControllerNode  # noqa: E402

H_NS = 2_000_000


def make(ctx, executor, **params):
    # the watchdog only where a test sets it: its default 20 ms trips between two messages
    # on a loaded machine, and a trip changes the answer to some inputs by design (a stamp
    # going backwards after a trip is a restart, accepted)
    params.setdefault("state_timeout", 1.0)
    node = ControllerNode(context=ctx, parameter_overrides=[
        Parameter(k, value=v) for k, v in params.items()])
    probe = Probe(ctx)
    executor.add_node(node)
    executor.add_node(probe)
    assert spin_until(executor, lambda: probe.pub_state.get_subscription_count() > 0)
    return node, probe


def answered(probe, t_ns):
    label = f"stamp={t_ns // NS}.{t_ns % NS:09d}"
    return any(label in lab for lab, _ in probe.efforts)


def send(executor, publish, done):
    """Publish until `done()`: a message sent before discovery has matched both ends can be
    lost, and a repeat of the first state is answered, not stepped."""
    for _ in range(40):
        publish()
        if spin_until(executor, done, timeout=0.5):
            return True
    return False


def feed(executor, probe, k0, count, q=PAPER_Q0, qd=None):
    """Publish states k0..k0+count-1 one at a time, each answered before the next."""
    for k in range(k0, k0 + count):
        for _ in range(40):     # re-send if lost in discovery: a repeat is answered, not stepped
            probe.state(k * H_NS, q, np.zeros(7) if qd is None else qd)
            if spin_until(executor, lambda: answered(probe, k * H_NS), timeout=0.5):
                break
        assert answered(probe, k * H_NS), f"no effort for {k}"
    return k0 + count


def bad_messages():
    """One malformed JointState per kind (and the text the warning must contain)."""
    good = dict(name=list(JOINTS), position=list(PAPER_Q0), velocity=[0.0] * 7)

    def js(**changes):
        fields = dict(good)
        fields.update(changes)
        return JointState(**fields)
    nan = list(PAPER_Q0)
    nan[2] = math.nan
    inf = [0.0] * 7
    inf[4] = math.inf
    return [
        ("nan", js(position=nan)),
        ("nan", js(velocity=inf)),
        ("length", js(position=list(PAPER_Q0[:5]))),
        ("length", js(velocity=[0.0] * 3)),
        ("names", js(name=["a", "b", "c", "d", "e", "f", "g"])),      # unknown only
        ("names", js(name=JOINTS[:6], position=list(PAPER_Q0[:6]), velocity=[0.0] * 6)),
        ("names", js(name=["joint1"] * 7)),
        ("empty", JointState()),
    ]


def test_malformed_states_are_rejected_and_control_recovers():
    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex)
        k = feed(ex, probe, 0, 20)
        for kind, msg in bad_messages():
            probe.state(k * H_NS, PAPER_Q0, np.zeros(7))
            assert spin_until(ex, lambda: answered(probe, k * H_NS))
            k += 1
            n_before = len(probe.efforts)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(k * H_NS, NS)
            probe.pub_state.publish(msg)
            assert spin_until(ex, lambda: node._throttle.counts.get(kind, 0) > 0), kind
            # the bad message produced no effort (allow the watchdog's tags only)
            assert all("stamp=" not in lab for lab, _ in probe.efforts[n_before:]), kind
        # a stamp going backwards
        probe.state((k - 5) * H_NS, PAPER_Q0, np.zeros(7))
        assert spin_until(ex, lambda: node._throttle.counts.get("stamp", 0) > 0)
        # control recovers
        k = feed(ex, probe, k, 10)
        for kind in ("nan", "length", "names", "empty", "stamp"):
            assert spin_until(ex, lambda: probe.warned(f"rejected ({kind})")), kind
        assert all(np.all(np.isfinite(d)) for _, d in probe.efforts)
        assert node.diagnostics().values  # diagnostics still build


def test_unknown_extra_joints_and_order_are_handled():
    """Extra joints are ignored and the order is by name: same effort as the plain message."""
    q = PAPER_Q0 + 0.01
    with ros_context() as (ctx, ex):
        _, probe = make(ctx, ex)
        assert send(ex, lambda: probe.state(0, q, np.zeros(7)), lambda: answered(probe, 0))
        ref = probe.efforts[-1][1]
    with ros_context() as (ctx, ex):
        _, probe = make(ctx, ex)
        perm = [3, 0, 6, 1, 5, 2, 4]
        names = ["gripper"] + [JOINTS[i] for i in perm]
        msg = JointState(name=names, position=[0.5] + [q[i] for i in perm],
                         velocity=[math.nan] + [0.0] * 7)
        assert send(ex, lambda: probe.pub_state.publish(msg), lambda: answered(probe, 0))
        np.testing.assert_allclose(probe.efforts[-1][1], ref, rtol=1e-12, atol=1e-9)


def test_nothing_compiles_while_active():
    """Every path of the active loop runs a kernel compiled before activation: adapting,
    frozen (``~/set_adaptation``, the starvation guard), ``K_D`` scaled (the guard), a
    trajectory through the command limiter, adapting again. numba's compiler never runs
    while the node is active (the node's own count of numba's compile events)."""
    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex, trajectory="topic")
        pub = probe.create_publisher(JointTrajectory, "/rcac_controller/joint_trajectory", 10)
        assert spin_until(ex, lambda: pub.get_subscription_count() > 0)
        k = feed(ex, probe, 0, 5)
        node.adaptation.freeze(node.adaptation.USER, True)
        k = feed(ex, probe, k, 5)
        node.ctrl.scale_K_D(0.5)
        node.adaptation.freeze(node.adaptation.STARVED, True)
        k = feed(ex, probe, k, 5)
        msg = _trajectory(JOINTS, [0.1, 0.3], [PAPER_Q0 + 0.1, PAPER_Q0 - 0.05])
        assert send(ex, lambda: pub.publish(msg), lambda: node.motion.active is not None)
        k = feed(ex, probe, k, 20)
        node.ctrl.scale_K_D(1.0)
        for reason in (node.adaptation.USER, node.adaptation.STARVED):
            node.adaptation.freeze(reason, False)
        k = feed(ex, probe, k, 5)
        assert node.running and node.compile_watch.count == 0
        assert node.diagnostics().values  # diagnostics still build


def test_a_failed_compile_under_autostart_ends_the_node(monkeypatch):
    """The law's kernel fails to compile: activation is refused and the autostarted node
    finishes with exit code 1 (``run()`` ends the process), instead of idling inactive."""
    def fail(self):
        raise RuntimeError("no compiler here")
    monkeypatch.setattr(RecursiveCompositeController, "compile", fail)
    with ros_context() as (ctx, ex):
        node = ControllerNode(context=ctx)
        ex.add_node(node)
        assert spin_until(ex, lambda: node.finished)
        assert node.exit_code == 1 and not node.running
        assert node.kernels.status == "failed" and "no compiler here" in node.kernels.error


def test_a_cleanup_while_compiling_skips_what_is_left():
    """``KernelWarmup.close`` (configure's cleanup) waits for the part being compiled and
    runs none of the rest."""
    from rcac_ros.nodes.controller.compiling import KernelWarmup
    started, release, ran = threading.Event(), threading.Event(), []
    ctrl = types.SimpleNamespace(compile=lambda: (started.set(), release.wait(10.0)))
    limiter = types.SimpleNamespace(warm=lambda: ran.append("limiter"))
    log = types.SimpleNamespace(info=ran.append, error=ran.append)
    warmup = KernelWarmup(ctrl, limiter, log, after=[lambda: ran.append("after")])
    assert started.wait(10.0)
    threading.Timer(0.2, release.set).start()
    warmup.close()
    # it said it waits, and ran nothing after the part being compiled
    assert ran == ["cleanup: waiting for the kernel being compiled to finish"]
    assert warmup.status == "failed" and "cleaned up" in warmup.error


def test_watchdog_publishes_safe_effort_and_recovers():
    safe = [1.0, -2.0, 3.0, 0.0, 0.5, 0.0, -1.0]
    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex, state_timeout=0.05, safe_effort=safe)
        k = feed(ex, probe, 0, 10)
        n_before = len(probe.efforts)
        # no more states: the safe effort follows, tagged "watchdog"
        assert spin_until(ex, lambda: any(lab.endswith("watchdog")
                                          for lab, _ in probe.efforts[n_before:]))
        wd = [d for lab, d in probe.efforts[n_before:] if lab.endswith("watchdog")]
        np.testing.assert_array_equal(wd[0], safe)
        status = {kv.key: kv.value for kv in node.diagnostics().values}
        assert status["watchdog"] == "tripped" and int(status["watchdog_trips"]) == 1
        assert spin_until(ex, lambda: probe.warned("watchdog")), [m.msg for m in probe.logs]
        # the state returns: control resumes
        feed(ex, probe, k, 5)
        status = {kv.key: kv.value for kv in node.diagnostics().values}
        assert status["watchdog"] == "ok"
        assert not np.allclose(probe.efforts[-1][1], safe)


def test_diagnostics_sum_the_input_threads_errors():
    """The failed takes, buffer allocations and callback exceptions of the inputs' side threads
    (``nodes/runtime/rawtake.py``) reach the diagnostics, summed by kind."""
    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex, trajectory="topic")
        status = {kv.key: kv.value for kv in node.diagnostics().values}
        assert status["input_errors_take"] == "0" and status["input_errors_callback"] == "0"
        assert status["input_errors_alloc"] == "0"
        assert len(node.inputs) == 2                    # the states and the trajectories
        node.inputs.append(types.SimpleNamespace(errors={"take": 2, "alloc": 3, "callback": 1}))
        node.inputs.append(types.SimpleNamespace(errors={"callback": 4}))
        status = {kv.key: kv.value for kv in node.diagnostics().values}
        assert status["input_errors_take"] == "2" and status["input_errors_callback"] == "5"
        assert status["input_errors_alloc"] == "3"


def test_lockstep_watchdog_trip_restarts_the_filters_only_after_a_lost_state():
    """Lockstep: after a stall with no state lost (the next stamp follows) the filters of
    eqs 21-24 go on, as in the offline loop; after states were lost they restart."""
    traj = PaperTrajectory(PAPER_Q0)
    rng = np.random.default_rng(5)
    states = [(traj(k * H_NS * 1e-9)[0] + rng.normal(0.0, 1e-4, 7), rng.normal(0.0, 1e-3, 7))
              for k in range(18)]
    states[0] = (PAPER_Q0, np.zeros(7))         # the desired motion starts at the first state
    answers = {}

    def answer(ks):
        for k in ks:
            probe.state(k * H_NS, *states[k])
            assert spin_until(ex, lambda: answered(probe, k * H_NS), timeout=5.0), k
            answers[k] = probe.efforts[-1][1]

    def stall():
        trips = node.watchdog.trips
        assert spin_until(ex, lambda: node.watchdog.trips > trips)

    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex, state_timeout=0.05)
        feed(ex, probe, 0, 1, *states[0])          # state 0 (re-sent until discovery is done)
        answers[0] = probe.efforts[-1][1]
        answer(range(1, 8))
        stall()
        answer(range(8, 12))                        # state 8 follows state 7: nothing lost
        stall()
        answer(range(14, 18))                       # states 12 and 13 lost

    def offline(restarts):
        ctrl = RecursiveCompositeController(css_arm(), **dict(PAPER_GAINS, h=H_NS * 1e-9))
        taus = {}
        for k in answers:
            if k in restarts:
                ctrl.restart_filters()
            tau = ctrl.step(*states[k], *traj(k * H_NS * 1e-9))
            limit = node.config.effort_limit                # the preset's
            taus[k] = np.clip(tau, -limit, limit)
            ctrl.set_applied_torque(taus[k])
        return np.array([taus[k] for k in answers])

    got = np.array(list(answers.values()))
    np.testing.assert_allclose(got, offline({14}), rtol=0, atol=1e-9)
    # and the test tells the choices apart: a restart at 8 too, or none at 14, differ
    assert np.max(np.abs(got - offline({8, 14}))) > 1e-3
    assert np.max(np.abs(got - offline(set()))) > 1e-3


def test_watchdog_default_is_zero_in_timer_mode():
    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex, mode="timer", state_timeout=0.05)
        # timer mode: efforts (untagged) follow the state at the rate
        assert send(ex, lambda: probe.state(0, PAPER_Q0, np.zeros(7)),
                    lambda: any(lab == "joint" for lab, _ in probe.efforts))
        assert spin_until(ex, lambda: node.watchdog.tripped and node.watchdog.trips == 1)
        assert spin_until(ex, lambda: probe.efforts[-1][0].endswith("watchdog"))
        n_before = len(probe.efforts)
        assert spin_until(ex, lambda: len(probe.efforts) > n_before + 3)
        for lab, d in probe.efforts[n_before - 1:]:
            assert lab.endswith("watchdog")
            np.testing.assert_array_equal(d, np.zeros(7))


@pytest.mark.parametrize("offset", [None, 0.0005])
def test_timer_ticks_lock_to_the_state_arrival_plus_the_phase_offset(offset):
    """timer.phase_offset: the loop's deadlines move to the newest state's arrival (steady
    clock) plus the offset, modulo the period; unset, they keep their own phase."""
    extra = {} if offset is None else {"timer.phase_offset": offset}
    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex, mode="timer", **extra)
        assert send(ex, lambda: probe.state(0, PAPER_Q0, np.zeros(7)),
                    lambda: any(lab == "joint" for lab, _ in probe.efforts))
        arrived = node.states.received      # no state after this one
        phase = (node.loop.next_ns - arrived) % H_NS
        ticks = node.counts.steps
        assert spin_until(ex, lambda: node.counts.steps > ticks + 40)
        if offset is None:
            assert node.phase_error_ns == 0 and (node.loop.next_ns - arrived) % H_NS == phase
        else:
            err = (node.loop.next_ns - arrived - round(offset * 1e9) + H_NS // 2) % H_NS \
                - H_NS // 2
            assert abs(err) <= 0.01 * H_NS, err
            assert abs(node.phase_error_ns) <= 0.01 * H_NS


def test_phase_offset_of_a_period_or_more_is_refused():
    with ros_context() as (ctx, _):
        with pytest.raises(ConfigError) as err:
            ControllerNode(context=ctx, parameter_overrides=[
                Parameter("mode", value="timer"), Parameter("timer.phase_offset", value=0.002)])
        assert str(err.value).startswith("timer.phase_offset: must be < one period")


@pytest.mark.parametrize("name, value", [
    ("K_D", -1.0), ("P", 0.0), ("Lambda", -0.5), ("gamma", -0.1), ("lambda", 0.0),
    ("rate", 0.0), ("state_timeout", -1.0), ("safe_effort", [0.0, 1.0, 2.0]),
    ("effort_limit", [1.0] * 6), ("effort_limit", [-1.0]), ("model", "no_such_arm"),
    ("model", "/nonexistent/arm.yaml"), ("joints", ["joint1", "joint2"]),
    ("joints", JOINTS[:6] + ["elbow"]), ("mode", "fast"), ("trajectory", "spline"),
    ("paper.q0", [0.0] * 3), ("gravity", [0.0, 9.81]), ("K_D", 10000),
])
def test_invalid_parameter_is_refused_naming_it(name, value):
    with ros_context() as (ctx, _):
        with pytest.raises(ConfigError) as err:
            ControllerNode(context=ctx, parameter_overrides=[Parameter(name, value=value)])
        assert str(err.value).startswith(name + ":"), str(err.value)
        assert "\n" not in str(err.value)


def test_joints_parameter_orders_the_efforts():
    order = [JOINTS[i] for i in (6, 5, 4, 3, 2, 1, 0)]
    with ros_context() as (ctx, ex):
        _, probe = make(ctx, ex)
        assert send(ex, lambda: probe.state(0, PAPER_Q0 + 0.02, np.zeros(7)),
                    lambda: answered(probe, 0))
        ref = probe.efforts[-1][1]
    with ros_context() as (ctx, ex):
        _, probe = make(ctx, ex, joints=order)
        assert send(ex, lambda: probe.state(0, PAPER_Q0 + 0.02, np.zeros(7)),
                    lambda: answered(probe, 0))
        np.testing.assert_allclose(probe.efforts[-1][1], ref[::-1], rtol=1e-12)


def test_velocity_estimate_without_velocities():
    """Positions only: the filtered estimate follows the true velocity of a known motion."""
    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex)
        worst = 0.0
        for k in range(400):
            t = k * 0.002
            assert send(ex, lambda: probe.state(k * H_NS, PAPER_Q0 + 0.1 * np.sin(2.0 * t)),
                        lambda: answered(probe, k * H_NS))
            if t > 0.2:
                worst = max(worst, np.max(np.abs(node.states.qd - 0.2 * np.cos(2.0 * t))))
        # first-order lag at 50 Hz and the half-step delay of the difference: ~1e-3 rad/s
        assert worst < 5e-3


def _trajectory(names, times, pos, vel=None, acc=None, stamp_ns=0):
    msg = JointTrajectory(joint_names=list(names))
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, NS)
    for i, t in enumerate(times):
        pt = JointTrajectoryPoint(positions=list(pos[i]))
        if vel is not None:
            pt.velocities = list(vel[i])
        if acc is not None:
            pt.accelerations = list(acc[i])
        pt.time_from_start.sec, pt.time_from_start.nanosec = divmod(round(t * NS), NS)
        msg.points.append(pt)
    return msg


def test_topic_trajectory_is_followed_like_jtc():
    """Cubic segments from the held state through the points, against scipy's Hermite spline."""
    from scipy import interpolate       # a test requirement (requirements-test.txt)
    from test_nodes_support import DEEP
    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex, trajectory="topic")
        desired = []
        probe.create_subscription(JointState, "/rcac_controller/desired_state", desired.append,
                                  DEEP)
        pub = probe.create_publisher(JointTrajectory, "/rcac_controller/joint_trajectory", 10)
        assert spin_until(ex, lambda: pub.get_subscription_count() > 0)
        k = feed(ex, probe, 0, 5)
        hold = PAPER_Q0.copy()
        p = np.array([hold + 0.1, hold - 0.05])
        v = np.array([np.full(7, 0.2), np.zeros(7)])
        perm = [2, 0, 1, 6, 5, 4, 3]
        msg = _trajectory([JOINTS[i] for i in perm], [0.1, 0.3], p[:, perm], v[:, perm])
        for _ in range(20):                 # the first message can be lost while discovery
            pub.publish(msg)                # settles on the subscriber's side
            if spin_until(ex, lambda: node.motion.active is not None, timeout=1.0):
                break
        assert node.motion.active is not None
        start = (k - 1) * H_NS              # "start now" = the latest state's stamp
        k = feed(ex, probe, k, 200)
        ref = interpolate.CubicHermiteSpline([0.0, 0.1, 0.3], np.vstack([hold, p]),
                                             np.vstack([np.zeros(7), v]))
        checked = 0
        for msg in desired:
            t = ((msg.header.stamp.sec * NS + msg.header.stamp.nanosec) - start) * 1e-9
            if t < 0:
                continue
            want = ref(min(t, 0.3))
            want_v = ref(min(t, 0.3), 1) if t < 0.3 else np.zeros(7)
            np.testing.assert_allclose(msg.position, want, atol=1e-9)
            np.testing.assert_allclose(msg.velocity, want_v, atol=1e-9)
            checked += 1
        assert checked > 150
        # malformed trajectories: rejected, the current one kept
        bad = [
            _trajectory(["x"] + JOINTS[1:], [0.1], [hold]),
            _trajectory(JOINTS[:6], [0.1], [hold[:6]]),
            _trajectory(JOINTS, [0.1], [np.full(7, math.nan)]),
            _trajectory(JOINTS, [0.1], [hold[:5]]),
            _trajectory(JOINTS, [0.2, 0.1], [hold, hold]),
        ]   # (an empty JointTrajectory is not malformed: it holds, see test_controller_state)
        active = node.motion.active
        for msg in bad:
            pub.publish(msg)
        assert spin_until(ex, lambda: sum(c for kind, c in node._throttle.counts.items()
                                          if kind.startswith("trajectory")) == len(bad))
        assert node.motion.active is active
        assert spin_until(ex, lambda: probe.warned("rejected (trajectory"))


URDF = two_link_urdf()


@pytest.mark.parametrize("as_file", [False, True])
def test_robot_description_gives_model_and_joint_names(tmp_path, as_file):
    """A URDF (string or path) replaces the preset; joint names and effort limits come with it."""
    description = URDF
    if as_file:
        description = str(tmp_path / "arm.urdf")
        (tmp_path / "arm.urdf").write_text(URDF)
    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex, robot_description=description, K_D=1e6)
        assert node.joints == ("shoulder", "elbow")
        # names in another order, plus a joint the model does not have; a fast motion
        msg = JointState(name=["elbow", "shoulder", "gripper"], position=[0.2, 0.1, 9.0],
                         velocity=[5.0, 5.0, 0.0])
        assert send(ex, lambda: probe.pub_state.publish(msg), lambda: answered(probe, 0))
        tau = probe.efforts[-1][1]
        assert tau.shape == (2,) and np.all(np.isfinite(tau))
        # K_D 1e6 against 5 rad/s: both efforts saturate at the URDF's limits, in joint order
        np.testing.assert_allclose(np.abs(tau), [50.0, 30.0])
