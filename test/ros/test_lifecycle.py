"""The managed controller, driven through its real lifecycle services from another process."""

import contextlib
import os
import time

import numpy as np

from test_nodes_support import (DEEP, H_NS, PAPER_Q0, Probe, ros_context, spin_until, start,
                                stop)

from lifecycle_msgs.msg import State, Transition  # noqa: E402
from lifecycle_msgs.srv import ChangeState, GetState  # noqa: E402
from rcl_interfaces.msg import Log  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import String  # noqa: E402

NODE = "/rcac_controller"
#: what robot_state_publisher offers on /robot_description
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class Lifecycle:
    """A lifecycle_msgs client of the controller, on the probe node."""

    def __init__(self, probe, executor):
        self.ex = executor
        self.get = probe.create_client(GetState, f"{NODE}/get_state")
        self.change = probe.create_client(ChangeState, f"{NODE}/change_state")
        assert spin_until(executor, lambda: self.get.service_is_ready()
                          and self.change.service_is_ready(), timeout=60.0)

    def call(self, client, request, resend=None):
        """Call and wait for the answer (60 s); every ``resend`` s, send the request again
        (an idempotent one): the server's answer goes out on a writer that matches the
        client's reader on its own, and can be lost while the first call is being matched."""
        end = time.monotonic() + 60.0
        while True:
            future = client.call_async(request)
            left = end - time.monotonic()
            wait = left if resend is None else min(resend, left)
            if spin_until(self.ex, future.done, timeout=max(wait, 0.0)):
                return future.result()
            assert time.monotonic() < end, "no answer within 60 s"

    def state(self):
        return self.call(self.get, GetState.Request(), resend=5.0).current_state.id

    def transition(self, tid):
        return self.call(self.change, ChangeState.Request(
            transition=Transition(id=tid))).success


def answered(probe, t_ns):
    label = f"stamp={t_ns // 1_000_000_000}.{t_ns % 1_000_000_000:09d}"
    return any(label in lab for lab, _ in probe.efforts)


def feed(ex, probe, k0, count):
    """States k0 .. k0+count-1, each re-sent until answered (discovery may drop one)."""
    for k in range(k0, k0 + count):
        for _ in range(40):
            probe.state(k * H_NS, PAPER_Q0 + 0.01, np.zeros(7))
            if spin_until(ex, lambda: answered(probe, k * H_NS), timeout=0.5):
                break
        assert answered(probe, k * H_NS), f"no effort for state {k}"
    return k0 + count


def silent(ex, probe, k0, count=20):
    """Send states for about 1 s; return how many efforts came back."""
    before = len(probe.efforts)
    for k in range(k0, k0 + count):
        probe.state(k * H_NS, PAPER_Q0 + 0.01, np.zeros(7))
        spin_until(ex, lambda: False, timeout=0.05)
    return len(probe.efforts) - before


@contextlib.contextmanager
def managed_controller(*params):
    """A probe and a controller process with its lifecycle client: ``(executor, probe, process,
    Lifecycle)``; the process is stopped at the end and must end cleanly (exit 0, no traceback)."""
    with ros_context() as (ctx, ex):
        probe = Probe(ctx)
        ex.add_node(probe)
        ctrl = start("controller_node", *params)
        try:
            yield ex, probe, ctrl, Lifecycle(probe, ex)
        finally:
            code, out = stop(ctrl)
    assert code == 0, out
    assert "Traceback" not in out


def test_every_transition_through_the_lifecycle_services():
    with managed_controller("autostart:=false", "state_timeout:=1.0") as (ex, probe, ctrl, lc):
        assert lc.state() == State.PRIMARY_STATE_UNCONFIGURED
        # configure: parameters, model, kernels; no effort yet
        assert lc.transition(Transition.TRANSITION_CONFIGURE)
        assert lc.state() == State.PRIMARY_STATE_INACTIVE
        assert spin_until(ex, lambda: probe.subs["efforts"].get_publisher_count() > 0,
                          timeout=60.0)
        assert spin_until(ex, lambda: probe.pub_state.get_subscription_count() > 0,
                          timeout=60.0)
        assert silent(ex, probe, 0) == 0                # inactive: silence
        # activate: efforts answer the states
        assert lc.transition(Transition.TRANSITION_ACTIVATE)
        assert lc.state() == State.PRIMARY_STATE_ACTIVE
        k = feed(ex, probe, 100, 5)
        assert not np.allclose(probe.efforts[-1][1], 0.0)
        # deactivate: exactly one zero effort, then silence
        n = len(probe.efforts)
        assert lc.transition(Transition.TRANSITION_DEACTIVATE)
        assert lc.state() == State.PRIMARY_STATE_INACTIVE
        assert spin_until(ex, lambda: any("stamp=" not in lab
                                          for lab, _ in probe.efforts[n:]), timeout=10.0)
        assert silent(ex, probe, k) == 0
        # (an answer to a state re-sent during discovery may precede it: stamped)
        after = [d for lab, d in probe.efforts[n:] if "stamp=" not in lab]
        assert len(after) == 1 and "stamp=" not in probe.efforts[-1][0]
        np.testing.assert_array_equal(after[0], np.zeros(7))
        # activate again: control resumes
        assert lc.transition(Transition.TRANSITION_ACTIVATE)
        k = feed(ex, probe, k + 100, 3)
        assert lc.transition(Transition.TRANSITION_DEACTIVATE)
        # cleanup: back to unconfigured, the effort publisher is gone
        assert lc.transition(Transition.TRANSITION_CLEANUP)
        assert lc.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert spin_until(ex, lambda: not [
            i for i in probe.get_publishers_info_by_topic("/effort_controller/commands")
            if i.node_name == "rcac_controller"], timeout=30.0)
        # configure again (a fresh start), then shut down: the process ends cleanly
        assert lc.transition(Transition.TRANSITION_CONFIGURE)
        assert lc.state() == State.PRIMARY_STATE_INACTIVE
        assert lc.transition(Transition.TRANSITION_INACTIVE_SHUTDOWN)
        ctrl.wait(timeout=30.0)


def test_an_error_in_configure_leaves_it_unconfigured_and_says_why():
    with managed_controller("autostart:=false",
                            "model:=/nonexistent/arm.yaml") as (ex, probe, ctrl, lc):
        assert not lc.transition(Transition.TRANSITION_CONFIGURE)
        assert lc.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert spin_until(ex, lambda: any(
            m.level >= Log.ERROR and m.name.endswith("rcac_controller")
            and "model: no such file" in m.msg for m in probe.logs), timeout=30.0)
        assert ctrl.poll() is None                       # still there, still managed
        assert not lc.transition(Transition.TRANSITION_ACTIVATE)     # not from unconfigured
        assert lc.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert lc.transition(Transition.TRANSITION_UNCONFIGURED_SHUTDOWN)
        ctrl.wait(timeout=30.0)


def test_the_tools_wait_for_the_activation_not_for_the_publishers():
    """The publishers of a configured, inactive controller are visible; the tools' wait
    (what the demo does before starting a lockstep simulator) holds until the activation."""
    from rcac_ros.tools.launch import wait_until_active
    with managed_controller("autostart:=false") as (ex, probe, ctrl, lc):
        assert not wait_until_active(probe, ex, "rcac_controller", timeout=0.5)
        assert lc.transition(Transition.TRANSITION_CONFIGURE)
        assert spin_until(ex, lambda: probe.subs["efforts"].get_publisher_count() > 0,
                          timeout=60.0)
        assert not wait_until_active(probe, ex, "rcac_controller", timeout=1.0)
        assert not wait_until_active(probe, ex, "rcac_controller", timeout=30.0,
                                     alive=lambda: False)
        assert lc.transition(Transition.TRANSITION_ACTIVATE)
        assert wait_until_active(probe, ex, "rcac_controller", timeout=30.0)
        assert lc.transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
        ctrl.wait(timeout=30.0)


def test_autostart_is_active_in_one_step_and_shutdown_from_active():
    with managed_controller("state_timeout:=1.0") as (ex, probe, ctrl, lc):
        assert spin_until(ex, lambda: lc.state() == State.PRIMARY_STATE_ACTIVE, timeout=30.0)
        assert spin_until(ex, lambda: probe.pub_state.get_subscription_count() > 0,
                          timeout=60.0)
        feed(ex, probe, 0, 3)
        # shutdown from active: one zero effort first, then the process ends
        n = len(probe.efforts)
        assert lc.transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
        ctrl.wait(timeout=30.0)
        assert spin_until(ex, lambda: any("stamp=" not in lab
                                          for lab, _ in probe.efforts[n:]), timeout=10.0)
        final = [d for lab, d in probe.efforts[n:] if "stamp=" not in lab]
        assert len(final) == 1
        np.testing.assert_array_equal(final[0], np.zeros(7))


with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "three_link.urdf"),
          encoding="utf-8") as _f:
    URDF = _f.read()


def test_description_topic_waits_unconfigured_then_both_nodes_use_it():
    with ros_context() as (ctx, ex):
        probe = Probe(ctx, record=("efforts", "logs"))
        names = []
        sub = probe.create_subscription(JointState, "/joint_states",
                                        lambda m: names.append(list(m.name)), DEEP)
        ex.add_node(probe)
        # gains for this light arm (0.4 kg hand: the paper's K_D = 1e4 is unstable at 2 ms)
        ctrl = start("controller_node", "description_topic:=/robot_description",
                     "gravity:=[0.0, 0.0, 0.0]", "K_D:=0.3", "P:=0.01")
        sim = None
        try:
            lc = Lifecycle(probe, ex)
            spin_until(ex, lambda: False, timeout=1.0)
            assert lc.state() == State.PRIMARY_STATE_UNCONFIGURED     # waiting
            pub = probe.create_publisher(String, "/robot_description", LATCHED)
            pub.publish(String(data=URDF))
            assert spin_until(ex, lambda: lc.state() == State.PRIMARY_STATE_ACTIVE,
                              timeout=60.0)
            # the simulator takes the same parameter (the latched message is already there)
            sim = start("simulator_node", "description_topic:=/robot_description",
                        "duration:=0.2", "gravity:=[0.0, 0.0, 0.0]",
                        "lockstep_timeout:=5.0")     # a loaded machine stalls for 0.1 s+
            assert spin_until(ex, lambda: len(names) > 10, timeout=90.0)
            assert names[-1] == ["shoulder", "elbow", "wrist"]
            assert spin_until(ex, lambda: sim.poll() is not None, timeout=60.0)
        finally:
            sim_code, sim_out = stop(sim) if sim is not None else (0, "")
            code, out = stop(ctrl)
            probe.destroy_subscription(sub)
    assert sim_code == 0, sim_out
    assert "finished: 100 steps" in sim_out and "lockstep misses 0" in sim_out, sim_out + out
    assert code == 0, out
    # the controller's efforts have the description's three joints (its default arm has 7)
    answers = [d for lab, d in probe.efforts if "stamp=" in lab]
    assert answers
    assert {d.shape for d in answers} == {(3,)}


def test_the_tools_wait_asks_again_when_a_reply_is_lost():
    """A reply lost on the way (the server's reply writer not yet matched to the client)
    leaves a request unanswered for good; the wait asks again instead of timing out."""
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.node import Node
    from rclpy.task import Future

    from rcac_ros.tools.launch import wait_until_active
    calls = []
    never = Future()

    async def get_state(request, response):
        calls.append(request)
        if len(calls) == 1:
            await never                                  # this reply never leaves
        response.current_state = State(id=State.PRIMARY_STATE_ACTIVE, label="active")
        return response

    with ros_context() as (ctx, ex):
        server = Node("lossy", context=ctx)
        server.create_service(GetState, "/lossy/get_state", get_state,
                              callback_group=ReentrantCallbackGroup())
        probe = Node("waiter", context=ctx)
        ex.add_node(server)
        ex.add_node(probe)
        assert wait_until_active(probe, ex, "lossy", timeout=20.0, resend=0.5)
        assert len(calls) >= 2
        never.cancel()
