"""The controller's ``~/joint_trajectory`` topic (``trajectory: topic``).

It feeds the controller's desired motion
(:class:`~rcac_ros.nodes.controller.motion.ControllerMotion`) through its ``follow`` and
``hold``, and changes it only in the node's executor thread (the control thread), where
the FollowJointTrajectory server, the motion's other source, also runs: the message is
deserialised, parsed and checked (size cap, joints, times, the model's limits, an end in
the past) in its own thread (:class:`~rcac_ros.nodes.runtime.inputs.SideInput`,
doc/failsafe.md); only the result crosses over, through a guard condition whose callback
runs in the executor. There it starts (or, empty, holds) the motion and aborts a running
goal, as a goal does in the action server's callbacks.
"""

from collections import deque

from trajectory_msgs.msg import JointTrajectory

from rcac_ros import topics
from rcac_ros.nodes.runtime.base import QOS
from rcac_ros.nodes.safety.guards import Rejected
from rcac_ros.nodes.runtime.inputs import SideInput
from rcac_ros.nodes.msgs.trajectory import parse_trajectory, TrajectoryRejected

_HOLD = None        # the parsed form of an empty trajectory: hold the position


class TrajectoryInput:
    """``~/joint_trajectory`` of a controller: checked aside, applied in its executor.

    Parameters
    ----------
    node : rclpy.node.Node
        Where the subscription and the guard condition live (rclpy's API only).
    joint_names : sequence of str
        The model's joints.
    guards : ControllerGuards
        ``max_trajectory_bytes`` and ``check_goal`` (the model's limits).
    warn : callable
        ``warn(kind, text)``: a throttled warning.
    motion : ControllerMotion
        What the trajectories drive: its ``follow(parsed)`` and ``hold()`` (falsy: not
        started) and ``now_ns()``, the time base of trajectories.
    replaced : callable
        ``replaced(text)``: a new trajectory replaced any action goal.
    """

    def __init__(self, node, *, joint_names, guards, warn, motion, replaced):
        self.node = node
        self.joint_names, self.guards, self.warn = joint_names, guards, warn
        self.motion, self.replaced = motion, replaced
        self._pending = deque(maxlen=1)     # the latest checked trajectory (atomic ops)
        self._wake = node.create_guard_condition(self._apply)
        self._side = SideInput(
            node, JointTrajectory, topics.JOINT_TRAJECTORY, QOS, self._on_message,
            guards.max_trajectory_bytes, "trajectory", self._warn)

    @property
    def errors(self):
        """Failed takes, buffer allocations and callback exceptions of the side thread, by
        kind."""
        return self._side.errors

    def _warn(self, kind, text):
        self.warn(f"trajectory {kind}", text)

    def _on_message(self, msg):
        """Side thread: parse and check, then hand over to the executor."""
        parsed = _HOLD              # as JTC: an empty trajectory holds the position
        if msg.points:
            try:
                parsed = parse_trajectory(msg, self.joint_names)
                self.guards.check_goal(parsed, self.motion.now_ns())
            except (TrajectoryRejected, Rejected) as err:
                return self._warn(err.kind, str(err))
        self._pending.append(parsed)        # a newer one replaces one not yet applied
        self._wake.trigger()

    def _apply(self):
        """Executor thread: follow (or hold) the handed-over trajectory."""
        try:
            parsed = self._pending.popleft()
        except IndexError:
            return
        started = self.motion.hold() if parsed is _HOLD else self.motion.follow(parsed)
        if not started:
            return self._warn("early", "no joint state received yet")
        self.replaced("replaced by a ~/joint_trajectory message")

    def close(self):
        """Stop the side thread and remove the guard condition (cleanup)."""
        self._side.close()
        self.node.destroy_guard_condition(self._wake)
