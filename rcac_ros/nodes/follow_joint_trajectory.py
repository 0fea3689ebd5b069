"""The ``control_msgs/action/FollowJointTrajectory`` server (MoveIt's way to send a trajectory).

control_msgs is not a wheel on PyPI. On an apt ROS install ``ros-jazzy-control-msgs`` provides
it; where it does not import, :data:`UNAVAILABLE` says why and :func:`create_server` logs that
in one line and returns ``None`` (the ``~/joint_trajectory`` topic still works).

A goal feeds the controller the same parsed trajectory as the ``~/joint_trajectory`` topic
(:func:`rcac_ros.nodes.trajectory_msg.parse_trajectory`, followed through the sink's
``follow``).
The behaviour is that of ros2_controllers' joint_trajectory_controller (JTC, Jazzy):

* **Goal.** Rejected (the reason is logged) when the sink cannot follow (not active, no
  joint state yet), when the trajectory fails the topic's checks, when its stamped end is
  already in the past, for a multi-DOF trajectory or component tolerances, and for a
  tolerance that names an unknown joint or is negative other than -1.
* **Accepted.** A goal still running is aborted (``INVALID_GOAL``, "preempted by a newer
  goal"), then the controller follows the new trajectory.
* **Every control step** (:meth:`FollowJointTrajectoryServer.update`). Feedback (desired,
  actual, error = desired - actual) at most every ``feedback_period`` s. Before the last
  point's time, a path tolerance exceeded aborts (``PATH_TOLERANCE_VIOLATED``) and the
  controller holds its current position. After it, every joint inside the goal tolerance
  succeeds (``SUCCESSFUL``); still outside it ``goal_time_tolerance`` s after the end
  aborts (``GOAL_TOLERANCE_VIOLATED``) and holds. A ``goal_time_tolerance`` of 0 waits for
  the goal tolerance without a time limit, as JTC does.
* **Cancel.** Accepted for the running goal: the controller holds, the goal ends CANCELED.

Tolerance values follow control_msgs/JointTolerance: ``0`` takes the server's default,
``-1`` removes the check, ``> 0`` is the tolerance. Position and velocity are checked;
the measured state has no acceleration, so acceleration tolerances are accepted and not
checked. Defaults (:class:`Tolerances`) are JTC's: no path tolerance, goal velocity
0.01 (``stopped_velocity_tolerance``), no goal position tolerance, no time limit.

Everything runs in the node's single-threaded executor: the goal, cancel and accepted
callbacks, the control step that calls :meth:`FollowJointTrajectoryServer.update`, and the
execute coroutine, which only waits for the outcome that ``update`` (or a cancel, a newer
goal, :meth:`FollowJointTrajectoryServer.abort`) decides.
"""

from dataclasses import dataclass
import math

from builtin_interfaces.msg import Duration as DurationMsg, Time as TimeMsg
import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future
from trajectory_msgs.msg import JointTrajectoryPoint

from rcac_ros.nodes.trajectory_msg import parse_trajectory, TrajectoryRejected

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
_ERASE = -1.0
_NS = 1_000_000_000


@dataclass(frozen=True)
class Tolerances:
    """The server's default tolerances, one value for every joint (JTC's ``constraints``).

    Parameters
    ----------
    path_position, path_velocity : float
        Path tolerances, rad (rad/s); 0: not checked.
    goal_position : float
        Goal position tolerance, rad; 0: not checked.
    stopped_velocity : float
        Goal velocity tolerance, rad/s (JTC's ``stopped_velocity_tolerance``).
    goal_time : float
        Seconds after the last point within which the goal tolerance must hold; 0: no limit.
    """

    path_position: float = 0.0
    path_velocity: float = 0.0
    goal_position: float = 0.0
    stopped_velocity: float = 0.01
    goal_time: float = 0.0


class GoalRejected(TrajectoryRejected):
    """A goal that cannot be followed (``kind`` says why)."""


def _resolve(default, value, field):
    """control_msgs/JointTolerance: 0 the default, -1 no check, > 0 the value (0 = no check)."""
    if value > 0.0:
        return float(value)
    if abs(value - _ERASE) < 1e-6:
        return 0.0
    if value < 0.0 or not math.isfinite(value):
        raise GoalRejected("tolerance", f"{field}: must be > 0, 0 (default) or -1 (no "
                           f"check), got {value}")
    return default


def _limits(values):
    """Tolerance -> limit for ``abs(error) > limit``: 0 (not checked) becomes inf."""
    arr = np.asarray(values, dtype=float)
    return np.where(arr > 0.0, arr, np.inf)


def goal_tolerances(goal, joints, defaults):
    """The goal's tolerances in ``joints`` order, each an (n,) limit array (inf: unchecked).

    Returns
    -------
    dict
        ``path_q``, ``path_v``, ``goal_q``, ``goal_v`` (arrays) and ``goal_time`` (s, 0:
        no limit).

    Raises
    ------
    GoalRejected
        A tolerance for an unknown joint, twice for one joint, or with an illegal value.
    """
    n = len(joints)
    out = {"path_q": [defaults.path_position] * n, "path_v": [defaults.path_velocity] * n,
           "goal_q": [defaults.goal_position] * n, "goal_v": [defaults.stopped_velocity] * n}
    for field, (kq, kv) in (("path_tolerance", ("path_q", "path_v")),
                            ("goal_tolerance", ("goal_q", "goal_v"))):
        seen = set()
        for k, tol in enumerate(getattr(goal, field)):
            where = f"{field}[{k}]"
            if tol.name not in joints:
                raise GoalRejected("names", f"{where}.name: unknown joint {tol.name!r}")
            if tol.name in seen:
                raise GoalRejected("names", f"{where}.name: joint {tol.name!r} given twice")
            seen.add(tol.name)
            i = joints.index(tol.name)
            out[kq][i] = _resolve(out[kq][i], tol.position, f"{where}.position")
            out[kv][i] = _resolve(out[kv][i], tol.velocity, f"{where}.velocity")
            _resolve(0.0, tol.acceleration, f"{where}.acceleration")     # checked, not used
    d = goal.goal_time_tolerance
    goal_time = _resolve(defaults.goal_time, d.sec + d.nanosec * 1e-9, "goal_time_tolerance")
    return {**{k: _limits(v) for k, v in out.items()}, "goal_time": goal_time}


def _violations(err_q, err_v, lim_q, lim_v, joints):
    """One line naming every joint outside its tolerance, or ``None``."""
    bad = []
    for label, err, lim in (("position", err_q, lim_q), ("velocity", err_v, lim_v)):
        for i in np.flatnonzero(np.abs(err) > lim):
            bad.append(f"{joints[i]} {label} error {err[i]:.4g} (tolerance {lim[i]:.4g})")
    return "; ".join(bad) if bad else None


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
        ``follow(parsed)``: follow the output of ``parse_trajectory`` as the topic does
        and return the :class:`~rcac_ros.nodes.trajectory_msg.ActiveTrajectory`; ``hold()``:
        stop and hold the current position. The sink calls :meth:`update` every control
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
        """Parse and check a goal; return ``(parsed, tolerances)`` or raise GoalRejected."""
        refusal = self._sink.refusal()
        if refusal is not None:
            raise GoalRejected("state", refusal)
        mdof = goal.multi_dof_trajectory
        if mdof.joint_names or mdof.points:
            raise GoalRejected("multi_dof", "multi_dof_trajectory: not supported (must be "
                               "empty)")
        if goal.component_path_tolerance or goal.component_goal_tolerance:
            raise GoalRejected("tolerance", "component tolerances: not supported (multi-DOF "
                               "joints only)")
        parsed = parse_trajectory(goal.trajectory, self._joints)
        start_ns, times = parsed[0], parsed[1]
        if start_ns is not None:
            end_ns = start_ns + round(times[-1] * _NS)
            now = self._sink.now_ns()
            if end_ns < now:
                raise GoalRejected("old_header", f"trajectory.header.stamp: the trajectory "
                                   f"ended {(now - end_ns) * 1e-9:.3f} s ago")
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
        Result = FollowJointTrajectory.Result
        if t_ns < g.end_ns:
            bad = _violations(err_q, err_v, g.tol["path_q"], g.tol["path_v"], self._joints)
            if bad is not None:
                self._finish(Result.PATH_TOLERANCE_VIOLATED, f"path tolerance: {bad}")
            return
        bad = _violations(err_q, err_v, g.tol["goal_q"], g.tol["goal_v"], self._joints)
        late = (t_ns - g.end_ns) * 1e-9
        if bad is None:
            self._finish(Result.SUCCESSFUL, f"goal reached {late:.3f} s after the "
                         "trajectory's end", state="succeeded", hold=False)
        elif g.tol["goal_time"] > 0.0 and late > g.tol["goal_time"]:
            self._finish(Result.GOAL_TOLERANCE_VIOLATED, f"goal tolerance still violated "
                         f"{late:.3f} s after the end (goal_time_tolerance "
                         f"{g.tol['goal_time']:g} s): {bad}")

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


def create_server(node, sink, **kwargs):
    """A :class:`FollowJointTrajectoryServer`, or ``None`` (one log line) without control_msgs."""
    if FollowJointTrajectory is None:
        node.get_logger().info(f"FollowJointTrajectory action off: {UNAVAILABLE}; on an apt "
                               "install, ros-jazzy-control-msgs provides it")
        return None
    return FollowJointTrajectoryServer(node, sink, **kwargs)
