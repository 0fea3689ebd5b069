"""~/controller_state (JTC-like, labelled by joint name), empty trajectory = hold, gains."""

import numpy as np
import pytest

from test_nodes_controller import feed, H_NS, make
from test_nodes_support import DEEP, JOINTS, NS, PAPER_Q0, ros_context, spin_until

from builtin_interfaces.msg import Duration  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint  # noqa: E402

from rcac_ros.errors import ConfigError  # noqa: E402
from rcac_ros.nodes.controller.node import ControllerNode  # noqa: E402

PARTS = ("reference", "feedback", "error", "output")


def ns(stamp):
    return stamp.sec * NS + stamp.nanosec


def test_controller_state_pairs_reference_feedback_error_output():
    order = [JOINTS[i] for i in (3, 1, 0, 2, 6, 5, 4)]
    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex, joints=order)
        got = {part: {} for part in PARTS}
        subs = [probe.create_subscription(
            JointState, f"/rcac_controller/controller_state/{part}",
            lambda m, part=part: got[part].__setitem__(ns(m.header.stamp), m), DEEP)
            for part in PARTS]
        assert spin_until(ex, lambda: all(s.get_publisher_count() > 0 for s in subs))
        rng = np.random.default_rng(3)
        sent = {}
        for k in range(30):
            q, qd = PAPER_Q0 + rng.normal(0, 0.01, 7), rng.normal(0, 0.1, 7)
            sent[k * H_NS] = (q, qd)
            feed(ex, probe, k, 1, q=q, qd=qd)
        assert spin_until(ex, lambda: all(len(got[p]) >= 25 for p in PARTS))
        efforts = {lab.split("stamp=")[1]: d for lab, d in probe.efforts if "stamp=" in lab}
        perm = [JOINTS.index(j) for j in order]
        checked = 0
        for t, fb in got["feedback"].items():
            if not all(t in got[p] for p in PARTS):
                continue
            ref, err, out = got["reference"][t], got["error"][t], got["output"][t]
            for msg in (ref, fb, err, out):
                assert list(msg.name) == order                 # labelled by joint name
            q, qd = sent[t]
            np.testing.assert_array_equal(fb.position, q[perm])
            np.testing.assert_array_equal(fb.velocity, qd[perm])
            np.testing.assert_allclose(err.position, np.subtract(ref.position, fb.position),
                                       atol=1e-15)
            np.testing.assert_allclose(err.velocity, np.subtract(ref.velocity, fb.velocity),
                                       atol=1e-15)
            np.testing.assert_array_equal(out.effort, efforts[f"{t // NS}.{t % NS:09d}"])
            checked += 1
        assert checked >= 25


def test_empty_trajectory_holds_the_current_position():
    with ros_context() as (ctx, ex):
        node, probe = make(ctx, ex, trajectory="topic")
        ref = []
        probe.create_subscription(JointState, "/rcac_controller/controller_state/reference",
                                  ref.append, DEEP)
        pub = probe.create_publisher(JointTrajectory, "/rcac_controller/joint_trajectory", 10)
        assert spin_until(ex, lambda: pub.get_subscription_count() > 0)
        k = feed(ex, probe, 0, 3)
        target = PAPER_Q0 + 0.3
        move = JointTrajectory(joint_names=JOINTS, points=[
            JointTrajectoryPoint(positions=target.tolist(), time_from_start=Duration(sec=1))])
        for _ in range(20):
            pub.publish(move)
            if spin_until(ex, lambda: node.motion.active is not None, timeout=1.0):
                break
        here = PAPER_Q0 + 0.05                  # where the arm is when the empty one comes
        k = feed(ex, probe, k, 10, q=here)
        n = len(ref)
        pub.publish(JointTrajectory())
        assert spin_until(ex, lambda: node.motion.active is None, timeout=10.0)
        k = feed(ex, probe, k, 20, q=here)
        assert spin_until(ex, lambda: len(ref) >= n + 20)
        for msg in ref[-10:]:
            np.testing.assert_array_equal(msg.position, here)
            np.testing.assert_array_equal(msg.velocity, np.zeros(7))


def test_per_joint_gains_reach_the_core_and_unknown_joints_are_refused():
    with ros_context() as (ctx, ex):
        node, _ = make(ctx, ex, **{"gains.joint7.K_D": 2.0e3, "gains.joint2.Lambda": 3.0,
                                   "gains.joint1.P": 5.0})
        np.testing.assert_array_equal(node.ctrl.K_D[6], 2.0e3 * np.eye(6))
        np.testing.assert_array_equal(node.ctrl.K_D[0], 1e4 * np.eye(6))
        np.testing.assert_array_equal(node.ctrl.Lambda, [1.0, 3.0, 1, 1, 1, 1, 1])
        np.testing.assert_array_equal(node.ctrl.P[0], 5.0 * np.eye(13))
        assert node.get_parameter("gains.joint7.K_D").value == 2.0e3
    with ros_context() as (ctx, ex):            # declared by the gains reader: not unknown
        node, _ = make(ctx, ex, strict_parameters=True, **{"gains.joint7.K_D": 2.0e3})
        np.testing.assert_array_equal(node.ctrl.K_D[6], 2.0e3 * np.eye(6))
    with ros_context() as (ctx, _):
        with pytest.raises(ConfigError) as err:
            ControllerNode(context=ctx, parameter_overrides=[
                Parameter("gains.wirst.K_D", value=2.0e3)])
        assert str(err.value).startswith("gains.wirst.K_D: unknown joint 'wirst'")
