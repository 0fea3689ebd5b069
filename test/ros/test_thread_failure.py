"""No silent thread death (doc/failsafe.md, "Thread failures"): a fault injected in each
place the nodes run code of their own.

* The input reader's loop (``nodes/runtime/rawtake.py``, outside a callback): logged with its
  traceback, counted (``"thread"``, diagnostics ``input_errors_thread``), and the loop
  starts again: the samples published after it still arrive.
* The controller's control step (an exception that is not the law's own ``RcacError``): the
  safe effort answers instead, ``control_errors`` counts it, one log line with the
  traceback, and control resumes once the fault is gone.
* A callback that no part of the node guards (a controller process: timer mode's tick, in
  the executor; lockstep's watchdog, in its own thread): the node logs the traceback, sends
  its zero effort (the arm must not keep its last effort), and exits 1.

The faults are injected from the test (a wrapped wait set, a wrapped core step, a wrapped
watchdog in a child process); the code under test is the package's own.
"""

import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from test_nodes_support import (H_NS, JOINTS, PAPER_Q0, Probe, ros_context, ROOT, spin_until,
                                stop)
from test_rawtake import Inbox, Log, raw_reader, SMALL

from rclpy.parameter import Parameter  # noqa: E402

from rcac_ros.nodes.controller.node import ControllerNode  # noqa: E402
from rcac_ros.nodes.runtime import rawtake  # noqa: E402


class FailingRclpy:
    """rclpy's C extension whose wait sets raise in ``wait``, the first ``fail`` times."""

    def __init__(self, real, fail):
        self.real, self.left = real, fail

    def WaitSet(self, *args):               # noqa: N802 -- rclpy's name
        return FailingWaitSet(self, self.real.WaitSet(*args))


class FailingWaitSet:
    def __init__(self, owner, wait_set):
        self._owner, self._ws = owner, wait_set

    def wait(self, timeout):
        if self._owner.left:
            self._owner.left -= 1
            raise RuntimeError("injected wait failure")
        return self._ws.wait(timeout)

    def __getattr__(self, name):
        return getattr(self._ws, name)


def test_a_fault_of_the_readers_loop_is_logged_counted_and_the_loop_starts_again(monkeypatch):
    monkeypatch.setattr(rawtake, "_rclpy", FailingRclpy(rawtake._rclpy, 2))
    inbox, log = Inbox(), Log()
    with raw_reader(inbox, 0, log) as (reader, publish):
        # both injected faults come at once (the reader waits from its start), each ends
        # the loop; the third loop serves the samples
        deadline = time.monotonic() + 10.0
        while reader.errors["thread"] < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        publish(SMALL, SMALL)
        assert inbox.wait(lambda b: len(b.data) == 2)
        assert reader._thread.is_alive()
        assert reader.errors == {"take": 0, "alloc": 0, "callback": 0, "thread": 2}
    assert len(log.lines) == 1, log.lines       # one line for one exception type
    assert log.lines[0].startswith("test input: the reader's loop raised; it starts again")
    assert "Traceback" in log.lines[0] and "RuntimeError: injected wait failure" in log.lines[0]


class FailingStep:
    """A core controller's ``step`` that raises ``ZeroDivisionError`` while ``failing``."""

    def __init__(self, step):
        self.step, self.failing, self.calls = step, False, 0

    def __call__(self, *args):
        if self.failing:
            self.calls += 1
            raise ZeroDivisionError("injected step failure")
        return self.step(*args)


def answer(probe, executor, k):
    """Publish the state at period ``k`` (moving at 0.5 rad/s off the motion, which starts at
    rest: the law's effort is not zero) until answered; the answer's data."""
    label = f"stamp={k * H_NS // 1_000_000_000}.{k * H_NS % 1_000_000_000:09d}"
    for _ in range(40):
        probe.state(k * H_NS, PAPER_Q0, np.full(7, 0.5))
        if spin_until(executor, lambda: any(label in lab for lab, _ in probe.efforts),
                      timeout=0.5):
            return next(d for lab, d in probe.efforts if label in lab)
    raise AssertionError(f"no answer to {k}")


def test_a_control_step_that_raises_sends_the_safe_effort_counts_logs_and_resumes():
    with ros_context() as (ctx, executor):
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("state_timeout", value=1.0)])     # lockstep: the answer is the effort
        probe = Probe(ctx)
        executor.add_node(node)
        executor.add_node(probe)
        assert spin_until(executor, lambda: probe.pub_state.get_subscription_count() > 0)
        failing = FailingStep(node.ctrl.step)
        node.ctrl.step = failing
        nominal = [answer(probe, executor, k) for k in range(1, 4)]
        assert all(np.any(d != 0.0) for d in nominal)       # the law's efforts
        failing.failing = True
        faulty = [answer(probe, executor, k) for k in range(4, 7)]
        safe = np.asarray(node.config.safe_effort, float)
        assert failing.calls == 3
        for d in faulty:
            np.testing.assert_array_equal(d, np.broadcast_to(safe, d.shape))
        status = {kv.key: kv.value for kv in node.diagnostics().values}
        assert status["control_errors"] == "3"
        failing.failing = False
        after = answer(probe, executor, 7)
        assert np.any(after != 0.0) and node.counts.control_errors == 3
        assert spin_until(executor, lambda: any("the control step raised" in m.msg
                                                for m in probe.logs), timeout=10.0)
        lines = [m.msg for m in probe.logs if "the control step raised" in m.msg]
        assert len(lines) == 1                      # once per exception type
        assert "Traceback" in lines[0] and "ZeroDivisionError: injected step failure" in lines[0]


#: a controller process whose watchdog raises at its 500th tick (timer mode) or 100th check
#: (lockstep mode, its own thread) with a state: about 1 s of control, outside the control
#: step, so nothing in the node guards it
CHILD = textwrap.dedent("""
    import sys
    from rcac_ros.nodes.controller import node
    from rcac_ros.nodes.runtime.base import run
    from rcac_ros.nodes.safety.watchdog import Watchdog

    METHOD, AT = sys.argv[1], int(sys.argv[2])
    original = getattr(Watchdog, METHOD)
    count = [0]

    def failing(self):
        count[0] += self.state_received() is not None
        if count[0] == AT:
            raise KeyError("injected watchdog failure")
        original(self)

    setattr(Watchdog, METHOD, failing)
    sys.exit(run(node.ControllerNode, "controller", sys.argv))
""")


WATCHDOG_FAULTS = [("timer", "ticked", 500), ("lockstep", "check", 100)]


@pytest.mark.parametrize("mode, method, at", WATCHDOG_FAULTS)
def test_an_unguarded_fault_stops_the_node_with_its_traceback_and_a_zero_effort(
        mode, method, at):
    from failsafe_harness import session, state_driver, wait
    with session() as probe:
        proc = subprocess.Popen(
            [sys.executable, "-c", CHILD, method, str(at), "--ros-args", "-p", f"mode:={mode}",
             "-p", "state_timeout:=1.0"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
        try:
            assert wait(lambda: probe.pub_state.get_subscription_count() > 0
                        and probe.sub_effort.get_publisher_count() > 0
                        or proc.poll() is not None, timeout=60.0)
            with state_driver(probe):
                assert wait(lambda: proc.poll() is not None, timeout=60.0)
            code, out = stop(proc)
        finally:
            if proc.poll() is None:
                stop(proc)
        assert code == 1, out
        assert "controller: fatal: Traceback" in out
        assert "KeyError: 'injected watchdog failure'" in out
        assert wait(lambda: probe.logged("a callback raised; the node stops"), timeout=5.0)
        with probe.lock:
            efforts = list(probe.efforts)
        # it controlled, then its last effort is the zero effort (tagged watchdog)
        assert any(not label.endswith("watchdog") for _, _, label, _ in efforts)
        _, _, label, data = efforts[-1]
        assert label.endswith("watchdog") and not np.any(data), (label, data)
        assert len(JOINTS) == data.shape[0]


def test_a_fault_after_the_effort_went_out_sends_no_second_answer():
    """The monitors raise after the step's effort was published: that effort stands (one
    answer per state in lockstep), the fault is counted."""
    with ros_context() as (ctx, executor):
        node = ControllerNode(context=ctx, parameter_overrides=[
            Parameter("state_timeout", value=1.0), Parameter("monitor_decimation", value=1)])
        probe = Probe(ctx)
        executor.add_node(node)
        executor.add_node(probe)
        assert spin_until(executor, lambda: probe.pub_state.get_subscription_count() > 0)

        def failing_monitors(*args, **kwargs):
            raise ZeroDivisionError("injected monitor failure")
        node._outputs.monitors = failing_monitors
        answers = [answer(probe, executor, k) for k in range(1, 4)]
        spin_until(executor, lambda: False, timeout=0.2)     # a second answer would be in
        assert all(np.any(d != 0.0) for d in answers)       # the law's efforts
        labels = [lab for lab, _ in probe.efforts if "stamp=" in lab]
        assert len(labels) == len(set(labels)) == 3, labels
        assert node.counts.control_errors == 3
