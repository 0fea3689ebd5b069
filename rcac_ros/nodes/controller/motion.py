"""The controller's desired motion: what its control step samples and its trajectory
sources drive (doc/nodes.md).

:class:`ControllerMotion` owns the :class:`~rcac_ros.nodes.msgs.trajectory.DesiredMotion`
and the limiter of the desired state (doc/failsafe.md), which starts again with every new
motion. The ``~/joint_trajectory`` topic and the FollowJointTrajectory server (it is that
server's sink, :class:`~rcac_ros.nodes.fjt.server.FollowJointTrajectoryServer`) start or
stop trajectories through :meth:`~ControllerMotion.follow` and
:meth:`~ControllerMotion.hold`, in the controller's executor thread only.
"""

from rcac_ros.nodes.msgs.trajectory import DesiredMotion


class ControllerMotion:
    """The desired ``(q_d, qd_d, qdd_d)`` of a controller, limited, and what changes it.

    Parameters
    ----------
    paper : mapping or None
        The paper's motion (keywords of :class:`~rcac_ros.core.trajectory.PaperTrajectory`);
        ``None``: a hold until a trajectory arrives.
    start : ndarray (n,) or None
        Where the motion starts (model order); ``None``: the state measured at its first step.
    joint_names : sequence of str
        The model's joints (the order of every array).
    limiter : DesiredLimiter
        The limiter of the desired state (reset when the motion starts again).
    check_goal : callable
        ``check_goal(parsed, now_ns)``: raise for a trajectory beyond the model's limits.
    now_ns : callable
        The time base of trajectories.
    is_running : callable
        ``is_running()``: whether the controller is active.
    position : callable
        ``position()``: the latest valid measured position, or ``None`` before one.
    """

    def __init__(self, *, paper, start, joint_names, limiter, check_goal, now_ns, is_running,
                 position):
        self.paper, self.start, self.joint_names = paper, start, joint_names
        self.limiter, self.check_goal, self.now_ns = limiter, check_goal, now_ns
        self.is_running, self.position = is_running, position
        self.restart()

    def restart(self, at_arm=False):
        """The motion starts again from ``start`` (``at_arm``: from the measured state)."""
        self._desired = DesiredMotion(self.paper, None if at_arm else self.start)
        self.limiter.reset()                # the new motion starts at the measured state

    @property
    def active(self):
        """The trajectory being followed (:class:`ActiveTrajectory`), or ``None``."""
        return self._desired.active

    def sample(self, t_ns, q):
        """The limited desired ``(q_d, qd_d, qdd_d)`` at ``t_ns`` (``q``: the measured one)."""
        return self.limiter(*self._desired.sample(t_ns, q))

    # ------------------------------------------------------------------ the sources'
    def refusal(self):
        """``None`` when a trajectory can start now, else the reason."""
        if not self.is_running():
            return "the controller is not active"
        return None if self.position() is not None else "no joint state received yet"

    def check(self, parsed):
        """The model's limits, as for ``~/joint_trajectory`` (the server checks the end)."""
        self.check_goal(parsed, None)

    def follow(self, parsed):
        """Follow a parsed trajectory (:func:`parse_trajectory`) from the desired state now.

        Returns the :class:`ActiveTrajectory`, or ``None`` (nothing started) when not active
        or before the first joint state.
        """
        if not self.is_running():
            return None
        started = self._desired.follow(parsed, self.now_ns(), self.position())
        return self._desired.active if started else None

    def hold(self):
        """Stop any trajectory and hold the measured position (``False``: not active, or no
        state yet)."""
        q = self.position() if self.is_running() else None
        if q is None:
            return False
        self._desired.hold(q)
        return True
