"""FollowJointTrajectory tolerances: the defaults, a goal's, and the check at every step.

Values follow control_msgs/JointTolerance: ``0`` takes the server's default, ``-1`` removes
the check, ``> 0`` is the tolerance. Position and velocity are checked; the measured state
has no acceleration, so acceleration tolerances are accepted and not checked. Defaults
(:class:`Tolerances`) are joint_trajectory_controller's (JTC, Jazzy): no path tolerance,
goal velocity 0.01 (``stopped_velocity_tolerance``), no goal position tolerance, no time
limit.

:func:`step_outcome` is JTC's rule at each control step: before the last point's time, a
path tolerance exceeded aborts; after it, every joint inside the goal tolerance succeeds,
and still outside it ``goal_time_tolerance`` s after the end aborts (0: no time limit).
Pure numpy, no rclpy: the goal is read by its fields.
"""

from dataclasses import dataclass
import math

import numpy as np

from rcac_ros.nodes.fjt.goal import GoalRejected

_ERASE = -1.0


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


def step_outcome(tol, end_ns, t_ns, err_q, err_v, joints):
    """The running goal's outcome at ``t_ns``, JTC's rules (see the module's docstring).

    Parameters
    ----------
    tol : dict
        The goal's limits (:func:`goal_tolerances`).
    end_ns, t_ns : int
        The trajectory's end (its last point) and now, on the sink's time base.
    err_q, err_v : ndarray (n,)
        desired - actual, ``joints`` order.
    joints : list of str
        Joint names, for the text.

    Returns
    -------
    tuple or None
        ``None`` while the goal runs on, else ``(code, text)``: ``code`` names the
        FollowJointTrajectory.Result constant, ``"SUCCESSFUL"``,
        ``"PATH_TOLERANCE_VIOLATED"`` or ``"GOAL_TOLERANCE_VIOLATED"``.
    """
    if t_ns < end_ns:
        bad = _violations(err_q, err_v, tol["path_q"], tol["path_v"], joints)
        return None if bad is None else ("PATH_TOLERANCE_VIOLATED", f"path tolerance: {bad}")
    bad = _violations(err_q, err_v, tol["goal_q"], tol["goal_v"], joints)
    late = (t_ns - end_ns) * 1e-9
    if bad is None:
        return "SUCCESSFUL", f"goal reached {late:.3f} s after the trajectory's end"
    if tol["goal_time"] > 0.0 and late > tol["goal_time"]:
        return "GOAL_TOLERANCE_VIOLATED", (f"goal tolerance still violated {late:.3f} s "
                                           f"after the end (goal_time_tolerance "
                                           f"{tol['goal_time']:g} s): {bad}")
    return None
