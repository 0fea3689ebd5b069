"""The controller's fail-safe parameters and guards, in one object (issue 9).

:class:`ControllerGuards` declares the parameters of the guards of
:mod:`rcac_ros.nodes.guards` and of the real-time options of
:mod:`rcac_ros.nodes.realtime`, and holds the objects the node's hooks call.
"""

import numpy as np
from rclpy.parameter import Parameter

from rcac_ros.nodes.common import declare, positive
from rcac_ros.nodes.guards import (check_goal, DesiredLimiter, MAX_STATE_BYTES,
                                   MAX_TRAJECTORY_BYTES)
from rcac_ros.nodes.realtime import RealtimeOptions

BIG = 1e12


class ControllerGuards:
    """Declare the fail-safe parameters of ``node`` and build its guards.

    Parameters
    ----------
    node : rclpy.node.Node
    model : RobotModel
        Its position and velocity limits bound the accepted trajectories.
    h : float
        The control period, s.
    effort_limit : ndarray (n,)
        The node's effort limits (model order): a warning names the unbounded joints.
    """

    def __init__(self, node, model, h, effort_limit):
        self.model = model
        free = [model.joint_names[i] for i in np.flatnonzero(~np.isfinite(effort_limit))]
        if free:
            node.get_logger().warning(
                f"no effort limit for joints {free} (neither the model nor effort_limit "
                "gives one): their efforts are not bounded")
        self.max_state_bytes = declare(
            node, "max_state_bytes", MAX_STATE_BYTES, "JointState messages larger than this "
            "(serialised) are refused before deserialising, bytes; 0: no cap", lo=0,
            hi=2 ** 31 - 1)
        self.max_trajectory_bytes = declare(
            node, "max_trajectory_bytes", MAX_TRAJECTORY_BYTES, "JointTrajectory messages "
            "larger than this are refused before deserialising, bytes; 0: no cap", lo=0,
            hi=2 ** 31 - 1)
        self.stamp_max_jump = positive("stamp.max_jump", declare(
            node, "stamp.max_jump", 1.0, "a state stamp further ahead than this (beyond the "
            "steady time elapsed since the last one) is refused, s", lo=0.0, hi=BIG))
        self.stamp_restart_count = declare(
            node, "stamp.restart_count", 10, "this many consecutive consistent states "
            "against the reference (a restart, a clock jump) replace it, even before the "
            "watchdog trips", lo=1, hi=1_000_000)
        dq = positive("desired.max_position_step", declare(
            node, "desired.max_position_step", 0.01, "the desired position moves at most "
            "this much per control period, rad (and its velocity is bounded by it / h)",
            lo=0.0, hi=BIG))
        dqd = positive("desired.max_velocity_step", declare(
            node, "desired.max_velocity_step", 1.0, "the desired velocity changes at most "
            "this much per control period, rad/s", lo=0.0, hi=BIG))
        self.limiter = DesiredLimiter(dq, dqd, h, model.n)
        cpus = declare(node, "realtime.cpus", Parameter.Type.INTEGER_ARRAY,
                       "CPU affinity of the control thread (unset: any CPU)")
        self.realtime = RealtimeOptions(
            priority=declare(node, "realtime.priority", 0, "SCHED_FIFO priority of the "
                             "control thread (best effort); 0: off", lo=0, hi=99),
            lock_memory=declare(node, "realtime.lock_memory", False,
                                "mlockall the process memory (best effort)"),
            cpus=cpus or (),
            dma_latency_us=declare(node, "realtime.cpu_dma_latency", -1,
                                   "hold /dev/cpu_dma_latency at this many us while running "
                                   "(0: shallowest idle state; best effort); -1: off",
                                   lo=-1, hi=100_000))

    def check_goal(self, parsed, now_ns):
        """Refuse a parsed trajectory (:func:`rcac_ros.nodes.guards.check_goal`)."""
        start_ns, times, pos, vel, _ = parsed
        m = self.model
        check_goal(start_ns, times, pos, vel, now_ns, m.position_lower, m.position_upper,
                   m.velocity_limit)
