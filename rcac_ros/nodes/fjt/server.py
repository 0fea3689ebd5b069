"""The ``control_msgs/action/FollowJointTrajectory`` server (MoveIt's way to send a trajectory).

control_msgs is not a wheel on PyPI. On an apt ROS install ``ros-jazzy-control-msgs`` provides
it; where it does not import, :data:`UNAVAILABLE` says why and :func:`create_server` logs that
in one line and returns ``None`` (the ``~/joint_trajectory`` topic still works).

A goal feeds the controller the same parsed trajectory as the ``~/joint_trajectory`` topic
(:func:`rcac_ros.nodes.msgs.trajectory.parse_trajectory`, followed through the sink's
``follow``).
The behaviour is that of ros2_controllers' joint_trajectory_controller (JTC, Jazzy):

* **Goal.** Rejected (the reason is logged) by JTC's rules
  (:func:`rcac_ros.nodes.fjt.goal.validate_goal`: the sink cannot follow, the trajectory
  fails the topic's checks or has already ended, multi-DOF) and for a tolerance that names
  an unknown joint or is negative other than -1
  (:func:`rcac_ros.nodes.fjt.tolerances.goal_tolerances`).
* **Accepted.** A goal still running is aborted (``INVALID_GOAL``, "preempted by a newer
  goal"), then the controller follows the new trajectory.
* **Every control step** (:meth:`FollowJointTrajectoryServer.update`). Feedback (desired,
  actual, error = desired - actual) at most every ``feedback_period`` s, then the tolerance
  checks (:func:`rcac_ros.nodes.fjt.tolerances.step_outcome`): a path tolerance exceeded
  aborts (``PATH_TOLERANCE_VIOLATED``) and the controller holds its current position; after
  the end, every joint inside the goal tolerance succeeds (``SUCCESSFUL``); still outside
  it ``goal_time_tolerance`` s after the end aborts (``GOAL_TOLERANCE_VIOLATED``) and holds.
* **Cancel.** Accepted for the running goal: the controller holds, the goal ends CANCELED.

The goal, cancel and accepted callbacks run in the node's executor, the control step that
calls :meth:`FollowJointTrajectoryServer.update` in the executor (timer mode) or in the state
input's thread (lockstep), one at a time (the node's lock,
:mod:`rcac_ros.nodes.runtime.serial`). The execute coroutine only waits for the outcome
that ``update`` (or a cancel, a newer goal, :meth:`FollowJointTrajectoryServer.abort`)
decides; a guard condition wakes the executor to finish it at once.
"""

from builtin_interfaces.msg import Duration as DurationMsg, Time as TimeMsg
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future
from trajectory_msgs.msg import JointTrajectoryPoint

from rcac_ros.nodes.fjt.goal import validate_goal
from rcac_ros.nodes.fjt.tolerances import goal_tolerances, step_outcome, Tolerances
from rcac_ros.nodes.msgs.trajectory import TrajectoryRejected

try:
    from control_msgs.action import FollowJointTrajectory
    from rclpy.type_support import check_for_type_support
    from rosidl_generator_py.import_type_support_impl import UnsupportedTypeSupport
    try:
        check_for_type_support(FollowJointTrajectory)
        UNAVAILABLE = None
    except UnsupportedTypeSupport as err:        # the Python part without its libraries
        FollowJointTrajectory = None
        UNAVAILABLE = f"control_msgs type support does not load ({err})"
except ImportError as err:
    FollowJointTrajectory = None
    UNAVAILABLE = f"control_msgs does not import ({err})"

#: The action's name, relative to the node (``/rcac_controller/follow_joint_trajectory``).
ACTION = "~/follow_joint_trajectory"
_NS = 1_000_000_000


class _Goal:
    """The running goal: its handle, tolerances (model order), end time and outcome."""

    def __init__(self, handle, tol, start_ns, times):
        self.handle = handle
        self.tol = tol
        self.start_ns = start_ns
        self.end_ns = start_ns + round(times[-1] * _NS)
        self.times = times
        self.outcome = Future()     # (state, Result): set once, awaited by the execute task
        self.next_feedback = None


class FollowJointTrajectoryServer:
    """A FollowJointTrajectory action server on ``node`` that drives ``sink``.

    Parameters
    ----------
    node : rclpy.node.Node
        The node that owns the action server (the controller).
    sink : object
        What follows trajectories. It provides ``joint_names`` (model order, the order of
        the arrays given to :meth:`update`); ``refusal()``: ``None`` when it can follow a
        trajectory now, else the reason; ``now_ns()``: the time base of its trajectories;
        ``check(parsed)``: raise :class:`~rcac_ros.nodes.safety.guards.Rejected` or
        :class:`TrajectoryRejected` for a goal it must refuse (limits; the server checks
        the end itself); ``follow(parsed)``: follow the output of
        ``parse_trajectory`` as the topic does and return the
        :class:`~rcac_ros.nodes.msgs.trajectory.ActiveTrajectory`; ``hold()``: stop and hold
        the current position. The controller calls :meth:`update` every control
        step.
    name : str
        Action name.
    defaults : Tolerances
        The tolerances a goal leaves at 0.
    feedback_period : float
        Seconds (of the sink's time base) between feedback messages (JTC: 0.05).
    """

    def __init__(self, node, sink, name=ACTION, defaults=Tolerances(), feedback_period=0.05):
        if FollowJointTrajectory is None:
            raise RuntimeError(UNAVAILABLE)
        self._node = node
        self._sink = sink
        self._joints = list(sink.joint_names)
        self.defaults = defaults
        self._feedback_ns = round(feedback_period * _NS)
        self._goal = None           # the running goal
        self._started = {}          # goal id -> its _Goal, until its execute task takes it
        self._log = node.get_logger()
        # set with an outcome: the executor, perhaps waiting, resumes the execute task now
        self._wake = node.create_guard_condition(lambda: None)
        self._server = ActionServer(node, FollowJointTrajectory, name,
                                    execute_callback=self._execute,
                                    goal_callback=self._on_goal,
                                    handle_accepted_callback=self._on_accepted,
                                    cancel_callback=self._on_cancel)

    @property
    def active(self):
        """Whether a goal is running."""
        return self._goal is not None

    # ------------------------------------------------------------------ action callbacks
    def _check(self, goal):
        """Parse and check a goal; return ``(parsed, tolerances)`` or raise
        :class:`TrajectoryRejected`."""
        parsed = validate_goal(goal, self._sink, self._joints)
        return parsed, goal_tolerances(goal, self._joints, self.defaults)

    def _on_goal(self, goal):
        try:
            self._check(goal)
        except TrajectoryRejected as err:
            self._log.warning(f"FollowJointTrajectory goal rejected: {err}")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_accepted(self, handle):
        self.abort("preempted by a newer goal")
        parsed, tol = self._check(handle.request)     # cannot fail: _on_goal just passed it
        handle.execute()                               # EXECUTING before any outcome
        active = self._sink.follow(parsed)
        start_ns = self._sink.now_ns() if active is None else active.start_ns
        g = _Goal(handle, tol, start_ns, parsed[1])
        self._goal = self._started[bytes(handle.goal_id.uuid)] = g
        if active is None:          # refused after all (cannot happen in one thread)
            return self._finish(FollowJointTrajectory.Result.INVALID_GOAL,
                                "the controller could not start the trajectory", hold=False)
        self._log.info(f"FollowJointTrajectory goal accepted: {len(g.times)} points, "
                       f"{g.times[-1]:.3g} s")

    def _on_cancel(self, handle):
        g = self._goal
        if g is None or g.handle is not handle:
            return CancelResponse.REJECT
        self._finish(FollowJointTrajectory.Result.SUCCESSFUL, "canceled", state="canceled")
        return CancelResponse.ACCEPT

    async def _execute(self, handle):
        state, result = await self._started.pop(bytes(handle.goal_id.uuid)).outcome
        if state == "succeeded":
            handle.succeed()
        elif state == "canceled" and handle.is_cancel_requested:
            handle.canceled()
        else:
            handle.abort()
        return result

    # ------------------------------------------------------------------ outcome
    def _finish(self, code, text, state="aborted", hold=True):
        g, self._goal = self._goal, None
        if hold:
            self._sink.hold()
        result = FollowJointTrajectory.Result(error_code=code, error_string=text)
        g.outcome.set_result((state, result))
        self._wake.trigger()
        if state == "aborted":      # (one call site per severity: rclpy insists)
            self._log.warning(f"FollowJointTrajectory goal aborted: {text}")
        else:
            self._log.info(f"FollowJointTrajectory goal {state}: {text}")

    def abort(self, reason):
        """Abort the running goal, if any, with ``INVALID_GOAL`` (preempted, deactivated).

        The sink is not told to hold: the caller decides what follows (a newer trajectory).
        """
        if self._goal is not None:
            self._finish(FollowJointTrajectory.Result.INVALID_GOAL, reason, hold=False)

    def update(self, t_ns, q, qd, q_d, qd_d, qdd_d):
        """One control step (model order): feedback, then the tolerance checks of the goal."""
        g = self._goal
        if g is None:
            return
        err_q = q_d - q
        err_v = qd_d - qd
        if g.next_feedback is None or t_ns >= g.next_feedback:
            g.next_feedback = t_ns + self._feedback_ns
            self._feedback(g, t_ns, q, qd, q_d, qd_d, qdd_d, err_q, err_v)
        outcome = step_outcome(g.tol, g.end_ns, t_ns, err_q, err_v, self._joints)
        if outcome is not None:
            code, text = outcome
            if code == "SUCCESSFUL":
                self._finish(FollowJointTrajectory.Result.SUCCESSFUL, text, state="succeeded",
                             hold=False)
            else:
                self._finish(getattr(FollowJointTrajectory.Result, code), text)

    def _feedback(self, g, t_ns, q, qd, q_d, qd_d, qdd_d, err_q, err_v):
        t_ns = int(t_ns)
        since = max(t_ns - g.start_ns, 0)
        fb = FollowJointTrajectory.Feedback(joint_names=self._joints)
        fb.header.stamp = TimeMsg(sec=t_ns // _NS, nanosec=t_ns % _NS)
        tfs = DurationMsg(sec=since // _NS, nanosec=since % _NS)
        fb.desired = JointTrajectoryPoint(positions=q_d.tolist(), velocities=qd_d.tolist(),
                                          accelerations=qdd_d.tolist(), time_from_start=tfs)
        fb.actual = JointTrajectoryPoint(positions=q.tolist(), velocities=qd.tolist(),
                                         time_from_start=tfs)
        fb.error = JointTrajectoryPoint(positions=err_q.tolist(), velocities=err_v.tolist(),
                                        time_from_start=tfs)
        g.handle.publish_feedback(fb)

    def destroy(self):
        """Abort the running goal (the caller holds or stops) and remove the action server."""
        self.abort("the controller stopped")
        self._server.destroy()
        self._node.destroy_guard_condition(self._wake)


def create_server(node, sink, **kwargs):
    """A :class:`FollowJointTrajectoryServer`, or ``None`` (one log line) without control_msgs."""
    if FollowJointTrajectory is None:
        node.get_logger().info(f"FollowJointTrajectory action off: {UNAVAILABLE}; on an apt "
                               "install, ros-jazzy-control-msgs provides it")
        return None
    return FollowJointTrajectoryServer(node, sink, **kwargs)
