"""The FollowJointTrajectory action server, through a real action client over DDS.

The server drives a small trajectory-following plant (:class:`Plant`): it follows the
parsed goal exactly like the controller's ``~/joint_trajectory`` path (``parse_trajectory``
then ``ActiveTrajectory``), on its own clock of 2 ms per tick, with a tracking error the
test chooses. Each outcome is checked against a closed form: the linear interpolation of
the goal's points, the time at which an exponentially decaying error enters the goal
tolerance, the tick at which an offset appears.

Needs control_msgs: an installed one (apt: ``ros-jazzy-control-msgs``) or, on the pip-only
path, the subset built at test set-up from ``test/ros/interfaces`` (``conftest.py``). Only
where neither imports (no C compiler for the build) do these tests skip, with the reason;
the test of the fallback always runs.
"""

import math
import time

import interface_build
import numpy as np
import pytest

from test_nodes_support import ros_context, spin_until

rclpy = pytest.importorskip("rclpy")

from builtin_interfaces.msg import Duration as DurationMsg  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.node import Node  # noqa: E402
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint  # noqa: E402

from rcac_ros.nodes.fjt import server as fjt  # noqa: E402
from rcac_ros.nodes.msgs.trajectory import ActiveTrajectory  # noqa: E402

needs_control_msgs = pytest.mark.skipif(
    fjt.FollowJointTrajectory is None,
    reason=f"{fjt.UNAVAILABLE}; {interface_build.BUILD_ERROR or 'the test build did not load'}:"
           " an apt install has"
           " ros-jazzy-control-msgs, this one has neither it nor a C compiler for the test"
           " build (test/ros/interface_build.py)")

JOINTS = ["a", "b", "c"]
Q0 = np.array([0.1, -0.2, 0.3])
TICK = 2_000_000            # ns: the plant's clock advances 2 ms per tick
NS = 1_000_000_000


class Plant(Node):
    """A trajectory sink that tracks the desired state with a chosen error.

    ``error(t_s, since_end_s)`` gives ``q - q_d`` (an (n,) array); velocities track exactly.
    Time advances one ``TICK`` per timer tick, whatever the wall clock does.
    """

    joint_names = JOINTS

    def __init__(self, context, error=None, refuse=None):
        super().__init__("plant", context=context)
        self.error = error or (lambda t, late: np.zeros(3))
        self.refuse = refuse
        self.t_ns = 10 * NS
        self.active = None
        self.hold_q = Q0.copy()
        self.q = Q0.copy()
        self.holds = []             # plant times of hold()
        self.ended = []             # plant times at which update() ended a goal
        self.server = fjt.create_server(self, self)
        self.create_timer(0.002, self.tick)

    # the sink interface
    def refusal(self):
        return self.refuse

    def check(self, parsed):
        """The plant has no limits: every parsed goal passes."""

    def now_ns(self):
        return self.t_ns

    def follow(self, parsed):
        self.active = ActiveTrajectory(parsed, self.t_ns, self.hold_q, np.zeros(3))
        return self.active

    def hold(self):
        self.holds.append(self.t_ns)
        self.active, self.hold_q = None, self.q.copy()

    def tick(self):
        self.t_ns += TICK
        if self.active is None:
            q_d, qd_d, qdd_d = self.hold_q, np.zeros(3), np.zeros(3)
        else:
            q_d, qd_d, qdd_d = self.active.sample(self.t_ns)
        end = None if self.active is None else \
            self.active.start_ns + self.active.times[-1] * NS
        t = (self.t_ns - self.active.start_ns) / NS if self.active else 0.0
        late = 0.0 if end is None else max(self.t_ns - end, 0.0) / NS
        self.q = q_d + self.error(t, late)
        running = self.server.active
        self.server.update(self.t_ns, self.q, qd_d.copy(), q_d, qd_d, qdd_d)
        if running and not self.server.active:
            self.ended.append(self.t_ns)        # the plant time at which the goal ended


def goal_msg(names, times, positions, path=(), goal=(), goal_time=0.0, stamp_ns=0):
    g = fjt.FollowJointTrajectory.Goal()
    g.trajectory = JointTrajectory(joint_names=list(names))
    g.trajectory.header.stamp.sec, g.trajectory.header.stamp.nanosec = divmod(stamp_ns, NS)
    for t, p in zip(times, positions):
        g.trajectory.points.append(JointTrajectoryPoint(
            positions=[float(x) for x in p],
            time_from_start=DurationMsg(sec=int(t), nanosec=round((t % 1) * NS))))
    from control_msgs.msg import JointTolerance
    g.path_tolerance = [JointTolerance(name=n, position=float(p)) for n, p in path]
    g.goal_tolerance = [JointTolerance(name=n, position=float(p)) for n, p in goal]
    g.goal_time_tolerance = DurationMsg(sec=int(goal_time), nanosec=round((goal_time % 1) * NS))
    return g


class Client:
    """An action client on its own node; collects feedback per goal."""

    def __init__(self, ctx, executor):
        self.node = Node("planner", context=ctx)
        self.executor = executor
        executor.add_node(self.node)
        self.client = ActionClient(self.node, fjt.FollowJointTrajectory,
                                   "/plant/follow_joint_trajectory")
        assert spin_until(executor, lambda: self.client.server_is_ready(), 20.0)

    def send(self, goal):
        """Send; return ``(handle, feedback list)`` once accepted or rejected."""
        feedback = []
        fut = self.client.send_goal_async(goal, feedback_callback=lambda m: feedback.append(
            m.feedback))
        assert spin_until(self.executor, fut.done, 20.0)
        return fut.result(), feedback

    def result(self, handle, timeout=30.0):
        fut = handle.get_result_async()
        assert spin_until(self.executor, fut.done, timeout)
        return fut.result().status, fut.result().result


def setup(ctx, executor, **plant_kwargs):
    plant = Plant(ctx, **plant_kwargs)
    executor.add_node(plant)
    return plant, Client(ctx, executor)


def linear(times, points, q_start, t):
    """Piecewise-linear interpolation from ``q_start`` at 0 through ``points`` (closed form)."""
    ts = np.concatenate([[0.0], times])
    qs = np.vstack([q_start, points])
    return np.array([np.interp(t, ts, qs[:, j]) for j in range(qs.shape[1])])


@needs_control_msgs
def test_goal_is_followed_with_feedback_and_succeeds():
    """Joints given in another order; the feedback's desired is the linear interpolation."""
    from action_msgs.msg import GoalStatus
    times = [0.5, 1.0]
    pts = np.array([[0.5, 0.0, -0.5], [0.6, 0.1, -0.4]])        # in JOINTS order
    order = [2, 0, 1]
    with ros_context() as (ctx, ex):
        plant, client = setup(ctx, ex)
        handle, feedback = client.send(goal_msg([JOINTS[i] for i in order], times,
                                                pts[:, order]))
        assert handle.accepted
        status, result = client.result(handle)
        assert status == GoalStatus.STATUS_SUCCEEDED
        assert result.error_code == result.SUCCESSFUL, result.error_string
        # success at the first tick at or after the end (q tracks exactly)
        end = plant.active.start_ns + 1.0 * NS
        assert end <= plant.ended[0] < end + TICK
        # every 50 ms of plant time over 1 s: 21 sent (the first may go out before the
        # client's feedback subscription has matched)
        assert 10 <= len(feedback) <= 21
        for fb in feedback:
            assert list(fb.joint_names) == JOINTS
            t = fb.desired.time_from_start.sec + fb.desired.time_from_start.nanosec * 1e-9
            np.testing.assert_allclose(fb.desired.positions, linear(times, pts, Q0, t),
                                       atol=1e-12)
            np.testing.assert_allclose(fb.error.positions, 0.0, atol=1e-12)
        assert plant.holds == []            # it ends on the last point, not on a hold


@pytest.mark.parametrize("tolerance, aborts", [(0.05, True), (0.2, False), (-1.0, False)])
@needs_control_msgs
def test_path_tolerance_aborts_at_the_violation(tolerance, aborts):
    """Joint b leaves the path by 0.1 rad from t = 0.1 s: aborted there iff 0.1 > tolerance."""
    from action_msgs.msg import GoalStatus
    err = (lambda t, late: np.array([0.0, 0.1 if t >= 0.1 else 0.0, 0.0]))
    with ros_context() as (ctx, ex):
        plant, client = setup(ctx, ex, error=err)
        handle, _ = client.send(goal_msg(JOINTS, [0.3], [[0.2, 0.2, 0.2]],
                                         path=[("b", tolerance)]))
        start = plant.active.start_ns
        status, result = client.result(handle)
        if not aborts:
            assert status == GoalStatus.STATUS_SUCCEEDED, result.error_string
            return
        assert status == GoalStatus.STATUS_ABORTED
        assert result.error_code == result.PATH_TOLERANCE_VIOLATED
        assert "b position error" in result.error_string and "a position" not in \
            result.error_string
        # aborted at the first tick with t >= 0.1 s, and held there
        assert plant.holds and 0.1 * NS <= plant.holds[0] - start < 0.1 * NS + TICK


@pytest.mark.parametrize("goal_time, succeeds", [(0.3, True), (0.05, False)])
@needs_control_msgs
def test_goal_time_tolerance(goal_time, succeeds):
    """After the end the error decays as 0.1 exp(-late / 0.05): inside 0.01 at 0.05 ln 10 s."""
    from action_msgs.msg import GoalStatus
    err = (lambda t, late: np.full(3, 0.1 * math.exp(-late / 0.05)))
    enter = 0.05 * math.log(10.0)                     # 0.115 s
    with ros_context() as (ctx, ex):
        plant, client = setup(ctx, ex, error=err)
        handle, _ = client.send(goal_msg(JOINTS, [0.2], [[0.2, 0.2, 0.2]],
                                         goal=[(j, 0.01) for j in JOINTS],
                                         goal_time=goal_time))
        end = plant.active.start_ns + 0.2 * NS
        status, result = client.result(handle)
        if succeeds:
            assert status == GoalStatus.STATUS_SUCCEEDED, result.error_string
            assert plant.holds == []
            return
        assert status == GoalStatus.STATUS_ABORTED
        assert result.error_code == result.GOAL_TOLERANCE_VIOLATED
        late = (plant.holds[0] - end) / NS
        assert goal_time < late <= goal_time + TICK / NS + 1e-9
        assert late < enter                                # it would have got there later


@needs_control_msgs
def test_success_time_is_when_the_error_enters_the_goal_tolerance():
    from action_msgs.msg import GoalStatus
    err = (lambda t, late: np.full(3, 0.1 * math.exp(-late / 0.05)))
    enter = 0.05 * math.log(10.0)
    with ros_context() as (ctx, ex):
        plant, client = setup(ctx, ex, error=err)
        handle, _ = client.send(goal_msg(JOINTS, [0.2], [[0.2, 0.2, 0.2]],
                                         goal=[(j, 0.01) for j in JOINTS], goal_time=1.0))
        end = plant.active.start_ns + 0.2 * NS
        status, _ = client.result(handle)
        assert status == GoalStatus.STATUS_SUCCEEDED
        assert enter <= (plant.ended[0] - end) / NS < enter + TICK / NS


@needs_control_msgs
def test_cancel_holds_and_ends_canceled():
    from action_msgs.msg import GoalStatus
    with ros_context() as (ctx, ex):
        plant, client = setup(ctx, ex)
        handle, feedback = client.send(goal_msg(JOINTS, [5.0], [[1.0, 1.0, 1.0]]))
        assert spin_until(ex, lambda: len(feedback) >= 2)
        cancel = handle.cancel_goal_async()
        assert spin_until(ex, cancel.done)
        assert len(cancel.result().goals_canceling) == 1
        status, _ = client.result(handle)
        assert status == GoalStatus.STATUS_CANCELED
        assert len(plant.holds) == 1 and plant.active is None
        # it holds where it was, well short of the goal
        assert np.all(np.abs(plant.hold_q - Q0) < 0.5)


@needs_control_msgs
def test_newer_goal_preempts_the_running_one():
    from action_msgs.msg import GoalStatus
    with ros_context() as (ctx, ex):
        plant, client = setup(ctx, ex)
        first, feedback = client.send(goal_msg(JOINTS, [5.0], [[1.0, 1.0, 1.0]]))
        assert spin_until(ex, lambda: len(feedback) >= 1)
        second, _ = client.send(goal_msg(JOINTS, [0.2], [[0.0, 0.0, 0.0]]))
        assert second.accepted
        status, result = client.result(first)
        assert status == GoalStatus.STATUS_ABORTED
        assert result.error_code == result.INVALID_GOAL
        assert "preempted" in result.error_string
        status, result = client.result(second)
        assert status == GoalStatus.STATUS_SUCCEEDED
        np.testing.assert_allclose(plant.q, 0.0, atol=1e-12)


@needs_control_msgs
def test_invalid_goals_are_rejected():
    with ros_context() as (ctx, ex):
        plant, client = setup(ctx, ex)
        bad = [
            goal_msg(["a", "b", "x"], [0.2], [[0, 0, 0]]),                  # unknown joint
            goal_msg(["a", "b"], [0.2], [[0, 0]]),                          # missing joint
            goal_msg(JOINTS, [0.2, 0.1], [[0, 0, 0], [1, 1, 1]]),           # time goes back
            goal_msg(JOINTS, [0.2], [[0, 0, 0]], path=[("x", 0.1)]),        # tolerance joint
            goal_msg(JOINTS, [0.2], [[0, 0, 0]], goal=[("a", -2.0)]),       # illegal value
            goal_msg(JOINTS, [0.2], [[0, 0, 0]], stamp_ns=5 * NS),          # ended in the past
        ]
        for goal in bad:
            handle, _ = client.send(goal)
            assert not handle.accepted
        plant.refuse = "not active"
        handle, _ = client.send(goal_msg(JOINTS, [0.2], [[0, 0, 0]]))
        assert not handle.accepted
        plant.refuse = None
        handle, _ = client.send(goal_msg(JOINTS, [0.2], [[0, 0, 0]],
                                         stamp_ns=plant.t_ns + NS))         # in the future
        assert handle.accepted
        assert client.result(handle)[1].error_code == 0


def test_without_control_msgs_the_server_is_off_with_one_line(monkeypatch):
    """Runs everywhere: without control_msgs, create_server logs why and returns None."""
    monkeypatch.setattr(fjt, "FollowJointTrajectory", None)
    monkeypatch.setattr(fjt, "UNAVAILABLE", fjt.UNAVAILABLE or "control_msgs does not import")
    lines = []

    class Logger:
        def info(self, text):
            lines.append(text)

    class Owner:
        def get_logger(self):
            return Logger()

    assert fjt.create_server(Owner(), sink=None) is None
    assert len(lines) == 1 and "ros-jazzy-control-msgs" in lines[0]
    assert "does not import" in lines[0] or "type support" in lines[0]


# ---------------------------------------------------------------------- the real controller
H_NS = 2_000_000
#: the goal: every joint by AMPLITUDE rad in 2 s (points at 0, 1, 2 s). The controller's
#: css_arm preset clips efforts to CSS_EFFORT_LIMIT (2000 N m, 500 N m at the wrist); with
#: the paper's gains and theta_hat(0) = 0 this motion needs at most ~700 N m (joint 2), so
#: the arm follows it unclipped (0.1 rad in 0.4 s needed 2e5 N m: clipped, it never arrived)
AMPLITUDE = 0.01
TARGET_T = [0.0, 1.0, 2.0]
GOAL_TOLERANCE = 0.001          # rad: a tenth of the motion
START_STEP = 20                 # the goal is stamped to start at this step


def _arm_goal(q0, start_ns, **tolerances):
    """From the held q0 (at its first point, t = 0) to q0 + AMPLITUDE in 2 s, stamped."""
    pts = [q0, q0 + AMPLITUDE / 2, q0 + AMPLITUDE]
    vel = [np.zeros(7), np.full(7, AMPLITUDE / TARGET_T[-1]), np.zeros(7)]
    traj = JointTrajectory(joint_names=[f"joint{i}" for i in range(1, 8)])
    traj.header.stamp.sec, traj.header.stamp.nanosec = divmod(start_ns, NS)
    for t, p, v in zip(TARGET_T, pts, vel):
        sec, nanosec = divmod(round(t * NS), NS)
        traj.points.append(JointTrajectoryPoint(
            positions=[float(x) for x in p], velocities=[float(x) for x in v],
            time_from_start=DurationMsg(sec=sec, nanosec=nanosec)))
    goal = goal_msg([], [], [], **tolerances)
    goal.trajectory = traj
    return goal


class Loop:
    """The controller node (trajectory: topic) in lockstep with the core simulator.

    While the test waits (discovery, a goal's answer), :meth:`wait` re-sends the last state:
    the controller answers a repeat without stepping.

    The watchdog reads the steady clock: a loaded machine can hold the test's process (the
    node runs in it) for longer than ``state_timeout`` (at most 1 s as a parameter) between
    two states, and a trip restarts the filters, so the closed loop is not the deterministic
    one compared. The watchdog has tests of its own; here its timeout is set beyond any
    stall on the node's object, and the run asserts it never tripped.
    """

    def __init__(self, ctx, ex, **params):
        from rclpy.parameter import Parameter
        from test_nodes_support import PAPER_Q0, Probe
        from rcac_ros.core.model import css_arm
        from rcac_ros.core.simulator import Simulator
        from rcac_ros.nodes.controller.node import ControllerNode
        params = dict(trajectory="topic", state_timeout=1.0, **params)
        self.node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter(name, value=value) for name, value in params.items()])
        self.node.watchdog.state_timeout = math.inf     # no trip on a stalled process
        self.probe = Probe(ctx, record=("efforts",))
        self.ex = ex
        ex.add_node(self.node)
        ex.add_node(self.probe)
        assert spin_until(ex, lambda: self.probe.pub_state.get_subscription_count() > 0)
        self.sim = Simulator(css_arm(), dt=H_NS / NS, q0=PAPER_Q0)
        self.qs = []
        self.efforts = []           # per step, as received (joints order = model order)
        self.last = None            # (stamp, q, qd) of the last state sent
        self.client = ActionClient(self.probe, fjt.FollowJointTrajectory,
                                   "/rcac_controller/follow_joint_trajectory")
        self.feedback = []

    def step(self, k):
        """Publish state k, wait for its effort, integrate one step."""
        label = f"stamp={k * H_NS // NS}.{k * H_NS % NS:09d}"
        found = []

        def answer():
            found.extend(d for lab, d in self.probe.efforts[-3:] if label in lab)
            return bool(found)
        self.last = (k * H_NS, self.sim.q.copy(), self.sim.qd.copy())
        for _ in range(40):     # re-sent if lost in discovery: a repeat is not stepped
            self.probe.state(*self.last)
            if spin_until(self.ex, answer, timeout=0.5):
                break
        assert found, f"no effort for step {k}"
        self.qs.append(self.sim.q.copy())
        self.efforts.append(found[0])
        self.sim.step(found[0])

    def wait(self, cond, timeout=20.0):
        """Spin until ``cond()`` (within ``timeout`` s), re-sending the last state every
        0.1 s."""
        end = time.monotonic() + timeout
        while not spin_until(self.ex, cond, timeout=0.1):
            if time.monotonic() > end:
                return False
            if self.last is not None:
                self.probe.state(*self.last)
        return True

    def send(self, goal):
        """Send a goal; return its ClientGoalHandle (accepted or not)."""
        assert self.wait(self.client.server_is_ready)
        sent = self.client.send_goal_async(goal, feedback_callback=lambda m: self.feedback.append(
            m.feedback))
        assert self.wait(sent.done)
        return sent.result()


def _closed_loop(via, steps, **tolerances):
    """The trajectory, stamped to start at step START_STEP, goes through ``via`` ("topic"
    or "action") at step 5. Returns the simulated positions and the efforts per step, the
    goal's ``(status, result, feedback)`` for the action, and whether the controller holds.
    """
    from test_nodes_support import PAPER_Q0
    with ros_context() as (ctx, ex):
        loop = Loop(ctx, ex)
        node, outcome = loop.node, None
        for k in range(5):
            loop.step(k)
        goal = _arm_goal(PAPER_Q0, START_STEP * H_NS, **tolerances)
        if via == "topic":
            pub = loop.probe.create_publisher(JointTrajectory,
                                              "/rcac_controller/joint_trajectory", 10)
            assert loop.wait(lambda: pub.get_subscription_count() > 0)
            for _ in range(20):
                pub.publish(goal.trajectory)
                if loop.wait(lambda: node.motion.active is not None, timeout=1.0):
                    break
        else:
            handle = loop.send(goal)
            assert handle.accepted
            result = handle.get_result_async()
        assert node.motion.active is not None
        for k in range(5, steps):
            loop.step(k)
        assert node.watchdog.trips == 0
        if via == "action":
            assert spin_until(ex, result.done, 20.0)
            outcome = (result.result().status, result.result().result, loop.feedback)
        held = node.motion.active is None
    return np.array(loop.qs), np.array(loop.efforts), outcome, held


@needs_control_msgs
def test_controller_goal_gives_the_topic_trajectory_step_for_step():
    """Same stamped trajectory by goal and by topic: the same closed loop, to the bit."""
    from action_msgs.msg import GoalStatus
    from test_nodes_support import PAPER_Q0
    from rcac_ros.core.model import CSS_EFFORT_LIMIT
    goal_time = 0.2
    # to the end of the goal time: success or GOAL_TOLERANCE_VIOLATED is decided by then
    steps = START_STEP + round((TARGET_T[-1] + goal_time) * NS / H_NS) + 10
    by_topic, tau_topic, _, _ = _closed_loop("topic", steps)
    by_goal, tau_goal, (status, result, feedback), held = _closed_loop(
        "action", steps, goal=[(f"joint{i}", GOAL_TOLERANCE) for i in range(1, 8)],
        goal_time=goal_time)
    np.testing.assert_array_equal(by_goal, by_topic)
    np.testing.assert_array_equal(tau_goal, tau_topic)
    # the arm followed the goal, the efforts were never clipped to the preset's limits
    assert np.all(np.abs(tau_goal) < np.array(CSS_EFFORT_LIMIT))
    assert status == GoalStatus.STATUS_SUCCEEDED, result.error_string
    assert result.error_code == result.SUCCESSFUL
    assert feedback and list(feedback[-1].joint_names) == [f"joint{i}" for i in range(1, 8)]
    assert not held                                     # success keeps the last point
    # the arm is there: within the goal tolerance of the last point
    assert np.max(np.abs(by_goal[-1] - (PAPER_Q0 + AMPLITUDE))) < GOAL_TOLERANCE


@needs_control_msgs
def test_controller_path_violation_aborts_and_holds():
    """A path tolerance no real tracking meets: aborted as the motion starts, then held."""
    from action_msgs.msg import GoalStatus
    # to the goal's midpoint (1 s), where the desired motion has moved AMPLITUDE / 2
    qs, _, (status, result, _), held = _closed_loop(
        "action", START_STEP + round(TARGET_T[1] * NS / H_NS), path=[("joint3", 1e-9)])
    assert status == GoalStatus.STATUS_ABORTED
    assert result.error_code == result.PATH_TOLERANCE_VIOLATED
    assert "joint3 position error" in result.error_string
    assert held
    # held: the arm stops near where it was when aborted (step ~21), far from the midpoint
    assert np.max(np.abs(qs[-1] - qs[START_STEP + 2])) < AMPLITUDE / 10


@needs_control_msgs
def test_controller_deactivate_aborts_the_goal_and_inactive_rejects():
    from action_msgs.msg import GoalStatus
    from test_nodes_support import PAPER_Q0
    with ros_context() as (ctx, ex):
        loop = Loop(ctx, ex)
        for k in range(5):
            loop.step(k)
        handle = loop.send(_arm_goal(PAPER_Q0, 0, goal_time=0.0))
        assert handle.accepted
        result = handle.get_result_async()
        for k in range(5, 15):
            loop.step(k)
        loop.node.trigger_deactivate()
        assert spin_until(ex, result.done, 20.0)
        assert result.result().status == GoalStatus.STATUS_ABORTED
        assert result.result().result.error_code == result.result().result.INVALID_GOAL
        assert "deactivated" in result.result().result.error_string
        assert not loop.send(_arm_goal(PAPER_Q0, 0)).accepted     # inactive: rejected
        loop.node.trigger_activate()
        assert not loop.send(_arm_goal(PAPER_Q0, 0)).accepted     # no state since: rejected
        loop.step(15)
        assert loop.send(_arm_goal(PAPER_Q0, 0)).accepted


@needs_control_msgs
def test_controller_topic_trajectory_replaces_the_goal_in_the_executor_thread():
    """A ~/joint_trajectory message aborts the running goal and takes over. It is checked in
    its own thread, but the motion and the action server change only in the executor's
    thread (here the test's), where the goal's callbacks and the control step run too."""
    import threading
    from action_msgs.msg import GoalStatus
    from test_nodes_support import PAPER_Q0
    with ros_context() as (ctx, ex):
        loop = Loop(ctx, ex)
        node = loop.node
        pub = loop.probe.create_publisher(JointTrajectory, "/rcac_controller/joint_trajectory",
                                          10)
        assert loop.wait(lambda: pub.get_subscription_count() > 0)
        for k in range(5):
            loop.step(k)
        handle = loop.send(_arm_goal(PAPER_Q0, 0))
        assert handle.accepted
        result = handle.get_result_async()
        goal_motion = node.motion.active
        threads = []
        # both sources call the motion's follow and hold: spy on what they reach
        for name in ("follow", "hold"):
            def spy(*args, _f=getattr(node.motion, name)):
                threads.append(threading.current_thread())
                return _f(*args)
            setattr(node.motion, name, spy)
        replacement = _arm_goal(PAPER_Q0 + AMPLITUDE, 0).trajectory
        for _ in range(20):
            pub.publish(replacement)
            if loop.wait(lambda: node.motion.active is not goal_motion, timeout=1.0):
                break
        assert loop.wait(result.done)
        assert result.result().status == GoalStatus.STATUS_ABORTED
        assert result.result().result.error_code == result.result().result.INVALID_GOAL
        assert "replaced by a ~/joint_trajectory message" in result.result().result.error_string
        np.testing.assert_array_equal(node.motion.active.pos[-1],
                                      replacement.points[-1].positions)
        assert threads and all(t is threading.current_thread() for t in threads)
        empty = JointTrajectory(joint_names=[f"joint{i}" for i in range(1, 8)])
        pub.publish(empty)                  # empty: hold, in the executor thread too
        assert loop.wait(lambda: node.motion.active is None)
        assert len(threads) >= 2 and all(t is threading.current_thread() for t in threads)


@needs_control_msgs
def test_controller_outcome_decided_off_the_executor_ends_the_goal_at_once():
    """In lockstep the outcome is decided in the state input's thread: the executor, waiting
    (no state, diagnostics every 30 s), is woken and ends the goal at once."""
    import threading
    from action_msgs.msg import GoalStatus
    from test_nodes_support import PAPER_Q0
    with ros_context() as (ctx, ex):
        loop = Loop(ctx, ex, diagnostics_period=30.0)
        for k in range(5):
            loop.step(k)
        handle = loop.send(_arm_goal(PAPER_Q0, 0))
        assert handle.accepted
        result = handle.get_result_async()
        loop.step(5)
        spin_until(ex, lambda: False, timeout=0.2)      # the executor has nothing left to do
        decided = []

        def abort():                                    # as the answer to a state does
            time.sleep(0.3)                             # while the executor waits
            with loop.node.callback_lock:
                loop.node._fjt.abort("decided in another thread")
                decided.append(time.monotonic())
        other = threading.Thread(target=abort)
        other.start()
        end = time.monotonic() + 10.0
        while not result.done() and time.monotonic() < end:
            ex.spin_once(timeout_sec=3.0)
        other.join()
        assert result.done() and time.monotonic() - decided[0] < 1.0
        assert result.result().status == GoalStatus.STATUS_ABORTED
        assert "decided in another thread" in result.result().result.error_string
