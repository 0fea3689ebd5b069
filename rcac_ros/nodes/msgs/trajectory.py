"""Sampling a trajectory_msgs/JointTrajectory the way joint_trajectory_controller does.

* ``header.stamp == 0`` means "start now"; otherwise the trajectory starts at the stamp.
* Points are reordered by ``joint_names`` into the controller's joint order.
* Before the first point, the motion goes from the state held when the message
  arrived to the first point; between points the segment is linear (positions
  only), cubic (positions and velocities) or quintic (positions, velocities and
  accelerations), chosen per segment from what both ends give.
* After the last point the last position is held (zero velocity and acceleration).

:class:`DesiredMotion` is the controller's desired motion: the paper's, or the topic's
trajectories after a hold. Pure numpy: no rclpy types beyond reading the message fields.
"""

import numpy as np

from rcac_ros.core.trajectory import PaperTrajectory
from rcac_ros.errors import InputError


class TrajectoryRejected(InputError):
    """A JointTrajectory that cannot be followed; ``kind`` says why (for the warning)."""

    def __init__(self, kind, text):
        super().__init__(text)
        self.kind = kind


def _duration_ns(d):
    return int(d.sec) * 1_000_000_000 + int(d.nanosec)


def parse_trajectory(msg, joints):
    """Check a JointTrajectory; return ``(start_ns, times_s, pos, vel, acc)`` in ``joints`` order.

    ``start_ns`` is ``None`` for "start now"; ``vel``/``acc`` are ``None`` when the points do
    not give them (every point must give the same fields).

    Raises
    ------
    TrajectoryRejected
        On an empty message, unknown/missing/duplicate joint names, wrong lengths,
        NaN/Inf, or times that do not increase.
    """
    names = list(msg.joint_names)
    if not names or not msg.points:
        raise TrajectoryRejected("empty", "joint_names and points must not be empty")
    if len(set(names)) != len(names):
        raise TrajectoryRejected("names", f"duplicate joint names {names}")
    unknown = sorted(set(names) - set(joints))
    if unknown:
        raise TrajectoryRejected("names", f"unknown joints {unknown}")
    missing = [j for j in joints if j not in names]
    if missing:
        raise TrajectoryRejected("names", f"missing joints {missing}")
    order = [names.index(j) for j in joints]
    m = len(names)
    has_vel = len(msg.points[0].velocities) > 0
    has_acc = len(msg.points[0].accelerations) > 0
    if has_acc and not has_vel:
        raise TrajectoryRejected("length", "accelerations given without velocities")
    times, pos, vel, acc = [], [], [], []
    for k, pt in enumerate(msg.points):
        if len(pt.positions) != m:
            raise TrajectoryRejected("length", f"points[{k}].positions: expected {m} values, "
                                     f"got {len(pt.positions)}")
        for field, want, out in (("velocities", has_vel, vel), ("accelerations", has_acc, acc)):
            got = len(getattr(pt, field))
            if got != (m if want else 0):
                raise TrajectoryRejected("length", f"points[{k}].{field}: expected "
                                         f"{m if want else 0} values, got {got}")
            if want:
                out.append(np.asarray(getattr(pt, field), dtype=float)[order])
        pos.append(np.asarray(pt.positions, dtype=float)[order])
        times.append(_duration_ns(pt.time_from_start) * 1e-9)
    times = np.asarray(times)
    pos = np.asarray(pos)
    vel = np.asarray(vel) if has_vel else None
    acc = np.asarray(acc) if has_acc else None
    for label, arr in (("positions", pos), ("velocities", vel), ("accelerations", acc),
                       ("time_from_start", times)):
        if arr is not None and not np.all(np.isfinite(arr)):
            raise TrajectoryRejected("nan", f"{label}: contains NaN or Inf")
    if times[0] < 0.0 or np.any(np.diff(times) <= 0.0):
        raise TrajectoryRejected("time", "time_from_start must be >= 0 and strictly increasing")
    start = _duration_ns(msg.header.stamp)
    return (None if start == 0 else start), times, pos, vel, acc


def segment(t, T, p0, p1, v0=None, v1=None, a0=None, a1=None):
    """Sample one segment of duration ``T`` at ``t`` in [0, T]: linear, cubic or quintic.

    Returns
    -------
    (q, qd, qdd) : arrays
    """
    if T <= 0.0:
        z = np.zeros_like(p1)
        return p1.copy(), (z if v1 is None else v1.copy()), (z if a1 is None else a1.copy())
    if v0 is None or v1 is None:            # linear (positions only)
        qd = (p1 - p0) / T
        return p0 + qd * t, qd, np.zeros_like(p0)
    if a0 is None or a1 is None:            # cubic Hermite
        c0, c1 = p0, v0
        c2 = (3.0 * (p1 - p0) - (2.0 * v0 + v1) * T) / T ** 2
        c3 = (-2.0 * (p1 - p0) + (v0 + v1) * T) / T ** 3
        return (c0 + t * (c1 + t * (c2 + t * c3)), c1 + t * (2.0 * c2 + 3.0 * t * c3),
                2.0 * c2 + 6.0 * c3 * t)
    c0, c1, c2 = p0, v0, 0.5 * a0           # quintic Hermite
    d = p1 - p0 - v0 * T - 0.5 * a0 * T ** 2
    e = v1 - v0 - a0 * T
    f = a1 - a0
    c3 = (10.0 * d - 4.0 * e * T + 0.5 * f * T ** 2) / T ** 3
    c4 = (-15.0 * d + 7.0 * e * T - f * T ** 2) / T ** 4
    c5 = (6.0 * d - 3.0 * e * T + 0.5 * f * T ** 2) / T ** 5
    q = c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * c5))))
    qd = c1 + t * (2.0 * c2 + t * (3.0 * c3 + t * (4.0 * c4 + t * 5.0 * c5)))
    qdd = 2.0 * c2 + t * (6.0 * c3 + t * (12.0 * c4 + t * 20.0 * c5))
    return q, qd, qdd


class ActiveTrajectory:
    """A parsed trajectory anchored in time, sampled like joint_trajectory_controller.

    Parameters
    ----------
    parsed : tuple
        The output of :func:`parse_trajectory`.
    now_ns : int
        Time at which the message arrived (start time when its stamp is zero).
    q, qd : ndarray (n,)
        The desired state held when the message arrived (start of the first segment).
    """

    def __init__(self, parsed, now_ns, q, qd):
        start_ns, self.times, self.pos, self.vel, self.acc = parsed
        self.start_ns = now_ns if start_ns is None else start_ns
        self.before_ns = now_ns
        self.q_before = np.array(q, dtype=float)
        self.qd_before = np.array(qd, dtype=float)

    def sample(self, now_ns):
        """Desired ``(q_d, qd_d, qdd_d)`` at ``now_ns``."""
        t = (now_ns - self.start_ns) * 1e-9
        pts = self.times
        vel, acc = self.vel, self.acc
        if t < pts[0]:
            t_before = min((self.before_ns - self.start_ns) * 1e-9, pts[0])
            zero = np.zeros_like(self.q_before)
            return segment(max(t - t_before, 0.0), pts[0] - t_before, self.q_before,
                           self.pos[0], self.qd_before, None if vel is None else vel[0],
                           zero, None if acc is None else acc[0])
        if t >= pts[-1]:
            zero = np.zeros_like(self.pos[-1])
            return self.pos[-1].copy(), zero, zero.copy()
        k = int(np.searchsorted(pts, t, side="right")) - 1
        pick = (lambda a, i: None if a is None else a[i])  # noqa: E731
        return segment(t - pts[k], pts[k + 1] - pts[k], self.pos[k], self.pos[k + 1],
                       pick(vel, k), pick(vel, k + 1), pick(acc, k), pick(acc, k + 1))


class DesiredMotion:
    """The controller's desired ``(q_d, qd_d, qdd_d)`` over time.

    It starts at the first :meth:`sample`: from ``q0`` (or the measured ``q`` then), the
    paper's motion when ``paper`` is given, else a hold of that position until
    :meth:`follow` starts a trajectory of the topic.

    Parameters
    ----------
    paper : dict, optional
        Keyword arguments of :class:`~rcac_ros.core.trajectory.PaperTrajectory`
        (``reading``, ``amplitude``, ``period``); ``None``: trajectories from the topic.
    q0 : ndarray (n,), optional
        Start position (model order); ``None``: the state measured at the first sample.
    """

    def __init__(self, paper=None, q0=None):
        self._paper_args = paper
        self._q0 = q0
        self._t0 = None         # time origin, ns
        self._paper = None
        self._hold = None       # desired state held before a topic trajectory
        #: the :class:`ActiveTrajectory` followed, if any
        self.active = None
        #: the last desired ``(q_d, qd_d)``
        self.last = None

    def sample(self, t_ns, q):
        """Desired ``(q_d, qd_d, qdd_d)`` at ``t_ns``; ``q`` is the measured position."""
        if self._t0 is None:
            self._t0 = t_ns
            q_start = q if self._q0 is None else self._q0
            zero = np.zeros_like(q_start)
            self._hold = (q_start.copy(), zero, zero.copy())
            if self._paper_args is not None:
                self._paper = PaperTrajectory(q_start, **self._paper_args)
        if self._paper is not None:
            desired = self._paper((t_ns - self._t0) * 1e-9)
        elif self.active is not None:
            desired = self.active.sample(t_ns)
        else:
            desired = self._hold
        self.last = desired[:2]
        return desired

    def hold(self, q):
        """Stop any trajectory and hold ``q`` (at rest) from now on."""
        self.active = None
        if self._t0 is not None:    # (before the first sample, that sample holds anyway)
            zero = np.zeros_like(q)
            self._hold = (np.array(q, dtype=float), zero, zero.copy())

    def follow(self, parsed, now_ns, q):
        """Follow a parsed trajectory from the last desired state (or ``q`` at rest).

        Returns False (nothing started) when there is neither yet.
        """
        if self.last is not None:
            start, rate = self.last
        elif q is not None:
            start, rate = q, np.zeros_like(q)
        else:
            return False
        self.active = ActiveTrajectory(parsed, now_ns, start, rate)
        return True
