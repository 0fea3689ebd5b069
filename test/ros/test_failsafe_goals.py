"""doc/failsafe.md, "goals": goals that cannot hurt the arm, against a controller process over
DDS."""

import time

from builtin_interfaces.msg import Duration
import numpy as np
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from failsafe_harness import (controller, feed, first_answer, H_NS, JOINTS, NS, PAPER_Q0,
                              session, stamp, wait)
from test_nodes_support import two_link_urdf

from rcac_ros.core.model import CSS_EFFORT_LIMIT  # noqa: E402

URDF = two_link_urdf(shoulder=(-1, 1), elbow=(-2, 2), velocity=0.5)


def trajectory(names, times, positions, velocities=None, start_ns=0):
    msg = JointTrajectory(joint_names=list(names))
    msg.header.stamp = stamp(start_ns)
    for k, t in enumerate(times):
        pt = JointTrajectoryPoint(positions=[float(x) for x in positions[k]])
        if velocities is not None:
            pt.velocities = [float(x) for x in velocities[k]]
        sec, nsec = divmod(round(t * 1e9), NS)
        pt.time_from_start = Duration(sec=sec, nanosec=nsec)
        msg.points.append(pt)
    return msg


def send(probe, msg, until, timeout=10.0):
    """Publish a trajectory (again, if lost while discovery settles) until ``until()``."""
    assert wait(lambda: probe.pub_traj.get_subscription_count() > 0, timeout=30.0)
    for _ in range(round(timeout / 0.5)):
        probe.pub_traj.publish(msg)
        if wait(until, timeout=0.5):
            return True
    return False


def test_trajectory_ending_in_the_past_is_rejected():
    with session() as probe, controller(probe, "trajectory:=topic"):
        t0 = 100 * NS
        first_answer(probe, t0)
        feed(probe, [t0 + k * H_NS for k in range(1, 10)])
        # started at 50 s, one second long: it ended 49 s ago
        msg = trajectory(JOINTS, [1.0], [PAPER_Q0 + 0.5], start_ns=50 * NS)
        assert send(probe, msg, lambda: probe.warned("rejected (trajectory past)"))
        feed(probe, [t0 + k * H_NS for k in range(10, 60)])
        assert wait(lambda: probe.answered(t0 + 59 * H_NS), timeout=5.0)
        with probe.lock:
            held = [q for _, q in probe.desired]
        np.testing.assert_allclose(held[-1], PAPER_Q0, atol=1e-12)    # no jump


def test_huge_step_gives_bounded_effort_and_desired_steps():
    """+100 rad in 1 ms on the CSS arm: was a 3.8e11 N m command."""
    limit = np.array(CSS_EFFORT_LIMIT)     # the preset's documented limits
    with session() as probe, controller(probe, "trajectory:=topic"):
        first_answer(probe, 0)
        feed(probe, [k * H_NS for k in range(1, 10)])
        msg = trajectory(JOINTS, [0.001], [PAPER_Q0 + 100.0])
        with probe.lock:
            n_desired = len(probe.desired)
        k = 10
        for _ in range(20):
            probe.pub_traj.publish(msg)
            feed(probe, [(k + j) * H_NS for j in range(25)])
            k += 25
            with probe.lock:
                moved = [q for _, q in probe.desired[n_desired:]
                         if np.max(np.abs(q - PAPER_Q0)) > 1e-9]
            if moved:
                break
        feed(probe, [(k + j) * H_NS for j in range(200)])
        assert wait(lambda: probe.answered((k + 199) * H_NS), timeout=5.0)
        with probe.lock:
            efforts = np.array([e[3] for e in probe.efforts])
            desired = np.array([q for _, q in probe.desired])
    assert moved, "the trajectory never reached the controller"
    assert np.all(np.isfinite(efforts))
    assert np.all(np.abs(efforts) <= limit + 1e-9), np.max(np.abs(efforts), axis=0)
    steps = np.max(np.abs(np.diff(desired, axis=0)))
    assert steps <= 0.01 + 1e-9, steps      # the default desired.max_position_step


def test_trajectory_outside_the_urdf_limits_is_rejected():
    with session() as probe, controller(probe, "trajectory:=topic",
                                        f"robot_description:={URDF}"):
        from sensor_msgs.msg import JointState
        names = ["shoulder", "elbow"]

        def state(t_ns):
            msg = JointState(name=names, position=[0.0, 0.0], velocity=[0.0, 0.0])
            msg.header.stamp = stamp(t_ns)
            probe.pub_state.publish(msg)
        for _ in range(40):
            state(0)
            if wait(lambda: probe.answered(0), timeout=0.3):
                break
        assert send(probe, trajectory(names, [1.0], [[1.5, 0.0]]),
                    lambda: probe.warned("rejected (trajectory position limit)"))
        assert send(probe, trajectory(names, [1.0], [[0.5, 0.0]], [[0.0, 0.8]]),
                    lambda: probe.warned("rejected (trajectory velocity limit)"))
        # within the limits: accepted (no new rejection, and the desired state starts moving)

        def rejections():
            with probe.lock:
                return sum(1 for m in probe.logs if "rejected (trajectory" in m.msg)
        rejected_before = rejections()
        probe.pub_traj.publish(trajectory(names, [1.0], [[0.5, 0.0]], [[0.0, 0.0]]))
        nxt = time.monotonic()
        for k in range(1, 200):      # a driver at 500 Hz, as ``feed``
            state(k * H_NS)
            nxt += 0.002
            time.sleep(max(0.0, nxt - time.monotonic()))
        assert wait(lambda: probe.answered(199 * H_NS), timeout=10.0)
        with probe.lock:
            last = probe.desired[-1][1]
        assert rejections() == rejected_before
        assert last[0] > 1e-3, last
