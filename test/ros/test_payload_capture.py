"""A payload grasped and released at run time over real DDS (doc/nodes.md, "Payload").

The simulator node runs in its own process in lockstep with this test, which answers every
joint state with the same torques and sets the payload parameters through the node's
parameter services (what ``ros2 param set`` does). Reference: the built-in simulator of the
core, offline, holding the payload from the step the node's ``~/payload`` message names and
releasing it at the step of the next one; the states received must be that run's, bit for bit
up to the float rounding of the messages. Refused values come back with a one-line reason
naming the parameter, and the states go on matching the reference (the plant unchanged).
"""

import importlib.util
import math

import numpy as np
import pytest

from test_nodes_support import JOINTS, NS, PAPER_Q0, ros_context, spin_until, start, stop

from geometry_msgs.msg import InertiaStamped  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.parameter_client import AsyncParameterClient  # noqa: E402
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from rcac_ros.core import Simulator  # noqa: E402
from rcac_ros.core.model import css_arm_preset  # noqa: E402
from rcac_ros.core.payload import Payload  # noqa: E402

H = 0.002
STEPS = 500
#: constant torques, inside the preset's limits (2000 N m on joints 1-4, 500 N m on 5-7)
TAU = np.array([300.0, -200.0, 150.0, 100.0, 40.0, -30.0, 20.0])
MASS, COM, INERTIA = 1000.0, [0.1, 0.5, 1.5], [60.0, 70.0, 80.0, 1.0, -2.0, 3.0]
DEEP = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5000,
                  reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: refused values (parameter, value, the start of the reason)
BAD = [("payload.mass", -5.0, "payload.mass: must be >= 0"),
       ("payload.mass", math.nan, "payload.mass: must be finite"),
       ("payload.com", [0.0, 0.0, 500.0], "payload.com: 500 m from the last link's frame"),
       ("payload.com", [0.0, 1.0], "payload.com: expected 3 values"),
       ("payload.inertia", [1.0, 1.0, 5.0, 0.0, 0.0, 0.0], "payload.inertia: not a body")]


class Arm(Node):
    """Answers every joint state with TAU, records the states, the payload messages and the
    simulator's diagnostics, and asks for parameter changes at given states."""

    def __init__(self, context, requests):
        super().__init__("payload_probe", context=context)
        self.states, self.payloads, self.diagnostics, self.results = [], [], [], {}
        self.requests = dict(requests)          # state number -> [Parameter]
        self.client = AsyncParameterClient(self, "rcac_simulator")
        self.pub = self.create_publisher(Float64MultiArray, "effort_controller/commands", DEEP)
        self.create_subscription(JointState, "joint_states", self.on_state, DEEP)
        self.create_subscription(InertiaStamped, "/rcac_simulator/payload",
                                 self.payloads.append, LATCHED)
        self.create_subscription(DiagnosticArray, "/diagnostics", self.on_diagnostics, DEEP)

    def on_state(self, msg):
        k = round((msg.header.stamp.sec * NS + msg.header.stamp.nanosec) / (H * NS))
        self.states.append((k, np.array(msg.position)))
        if k in self.requests:
            self.results[k] = self.client.set_parameters(self.requests.pop(k))
        self.pub.publish(Float64MultiArray(data=TAU.tolist()))

    def on_diagnostics(self, msg):
        for status in msg.status:
            if status.name.startswith("rcac_simulator"):
                self.diagnostics.append({kv.key: kv.value for kv in status.values})


def reference(capture_at, release_at):
    """The states 0..STEPS of the offline plant, payload held over [capture_at, release_at)."""
    sim = Simulator(css_arm_preset(), q0=PAPER_Q0)
    qs = [sim.q.copy()]
    for k in range(STEPS):
        if k == capture_at:
            sim.set_payload(Payload(MASS, COM, INERTIA))
        if k == release_at:
            sim.set_payload(Payload())
        qs.append(sim.step(TAU)[0].copy())
    return np.array(qs)


ENGINES = ["builtin", pytest.param("mujoco", marks=pytest.mark.skipif(
    importlib.util.find_spec("mujoco") is None, reason="mujoco not installed"))]


@pytest.mark.parametrize("engine", ENGINES)
def test_a_capture_a_refused_value_and_a_release_over_dds(engine):
    """On either engine (MuJoCo's plant agrees with the built-in one to rounding,
    test/core/test_payload.py), the reference is the built-in simulator."""
    capture = [Parameter("payload.com", value=COM), Parameter("payload.inertia", value=INERTIA),
               Parameter("payload.mass", value=MASS)]
    bad = [Parameter(name, value=value) for name, value, _ in BAD]
    with ros_context() as (ctx, executor):
        arm = Arm(ctx, {100: capture, 250: bad, 350: [Parameter("payload.mass", value=0.0)]})
        executor.add_node(arm)
        sim = start("simulator_node", "mode:=lockstep", f"engine:={engine}",
                    f"duration:={STEPS * H}", "lockstep_timeout:=5.0", "diagnostics_period:=0.05",
                    # at most half real time: the payload is held for 0.5 s of wall time at
                    # least, ten diagnostics periods
                    "lockstep_max_speed:=0.5")
        try:
            assert spin_until(executor, lambda: sim.poll() is not None, timeout=120.0)
            spin_until(executor, lambda: all(f.done() for f in arm.results.values()), 10.0)
        finally:
            code, out = stop(sim)
    assert code == 0, out
    assert "lockstep misses 0, late efforts 0" in out, out
    # the three changes of the capture, in one request: each accepted, the plant changed once,
    # at the next step
    for r in arm.results[100].result().results:
        assert r.successful, r.reason
    refused = arm.results[250].result().results
    for (name, _, reason), r in zip(BAD, refused):
        assert not r.successful, name
        assert r.reason.startswith(reason) and "\n" not in r.reason, r.reason
    assert arm.results[350].result().results[0].successful
    masses = [(m.inertia.m, round((m.header.stamp.sec * NS + m.header.stamp.nanosec) / (H * NS)))
              for m in arm.payloads]
    # at start-up (none), the capture, the release
    assert [m for m, _ in masses] == [0.0, MASS, 0.0], masses
    held = [m for m in arm.payloads if m.inertia.m == MASS][0]
    assert [held.inertia.com.x, held.inertia.com.y, held.inertia.com.z] == COM
    assert [held.inertia.ixx, held.inertia.iyy, held.inertia.izz, held.inertia.ixy,
            held.inertia.ixz, held.inertia.iyz] == INERTIA
    assert held.header.frame_id == JOINTS[-1]
    capture_at, release_at = masses[1][1], masses[2][1]
    assert 100 <= capture_at < release_at < STEPS
    ref = reference(capture_at, release_at)
    assert len(arm.states) >= STEPS * 0.9
    for k, q in arm.states:
        np.testing.assert_allclose(q, ref[k], rtol=0, atol=1e-9, err_msg=f"state {k}")
    # the payload made a difference the states show (the arm without it ends elsewhere)
    free = reference(STEPS, STEPS)
    assert np.abs(free[-1] - ref[-1]).max() > 1e-4
    # logged and in the diagnostics
    assert f"payload: {MASS:g} kg" in out and "payload: released at step" in out, out
    held_diag = [d for d in arm.diagnostics if d.get("payload_mass") == f"{MASS:g}"]
    assert held_diag and held_diag[-1]["payload_changes"] == "1"
    assert arm.diagnostics[-1]["payload_mass"] == "0"
