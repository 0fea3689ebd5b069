"""Which FollowJointTrajectory goals the server accepts: joint_trajectory_controller's rules.

A goal is rejected (JTC, Jazzy) when the sink cannot follow (not active, no joint state
yet), for a multi-DOF trajectory or component tolerances, when the trajectory fails the
``~/joint_trajectory`` topic's checks
(:func:`~rcac_ros.nodes.msgs.trajectory.parse_trajectory`), when its stamped end is
already in the past (:func:`~rcac_ros.nodes.safety.guards.check_end`, the one check of the topic
and the action, made here for any sink), or when the sink refuses it (the model's limits).
A tolerance that names an unknown joint or has an illegal value is rejected by
:func:`~rcac_ros.nodes.fjt.tolerances.goal_tolerances`.
Pure: no rclpy, the goal is read by its fields.
"""

from rcac_ros.nodes.safety.guards import check_end, Rejected
from rcac_ros.nodes.msgs.trajectory import parse_trajectory, TrajectoryRejected


class GoalRejected(TrajectoryRejected):
    """A goal that cannot be followed (``kind`` says why)."""


def validate_goal(goal, sink, joints):
    """Check a goal's trajectory against JTC's rules and the sink's; return it parsed.

    Parameters
    ----------
    goal : control_msgs.action.FollowJointTrajectory.Goal
        The goal (its tolerances are :func:`~rcac_ros.nodes.fjt.tolerances.goal_tolerances`'
        business).
    sink : object
        What follows the trajectory: its ``refusal()``, ``now_ns()`` and ``check(parsed)``
        (see :class:`~rcac_ros.nodes.fjt.server.FollowJointTrajectoryServer`).
    joints : list of str
        The sink's joint order.

    Returns
    -------
    tuple
        ``parse_trajectory``'s ``(start_ns, times, pos, vel, acc)``.

    Raises
    ------
    TrajectoryRejected
        A :class:`GoalRejected`, or the topic's own rejection from ``parse_trajectory``.
    """
    refusal = sink.refusal()
    if refusal is not None:
        raise GoalRejected("state", refusal)
    mdof = goal.multi_dof_trajectory
    if mdof.joint_names or mdof.points:
        raise GoalRejected("multi_dof", "multi_dof_trajectory: not supported (must be empty)")
    if goal.component_path_tolerance or goal.component_goal_tolerance:
        raise GoalRejected("tolerance", "component tolerances: not supported (multi-DOF "
                           "joints only)")
    parsed = parse_trajectory(goal.trajectory, joints)
    try:
        check_end(parsed[0], parsed[1], sink.now_ns())
        sink.check(parsed)                  # the sink's own goal checks (limits, ...)
    except Rejected as err:
        raise GoalRejected(err.kind, str(err)) from None
    return parsed
