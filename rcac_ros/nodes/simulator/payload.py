"""The simulator's payload held by the last link (a part of :class:`~.node.SimulatorNode`).

``payload.mass``, ``payload.com`` and ``payload.inertia`` are checked as a whole
(:mod:`rcac_ros.core.payload`: a refusal is the one-line reason of the parameter result, the
plant unchanged), applied at the next step, logged, in the diagnostics and published on
``~/payload`` (doc/nodes.md, "Payload").
"""

from builtin_interfaces.msg import Time as TimeMsg
from geometry_msgs.msg import InertiaStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from rcac_ros.core.payload import inertia_values, Payload
from rcac_ros.errors import RcacError

NS = 1_000_000_000

#: the payload parameters (a change of any is checked with the others' values)
PAYLOAD_PARAMETERS = ("payload.mass", "payload.com", "payload.inertia")
#: ``~/payload``: reliable, transient local, the last few changes
QOS_PAYLOAD = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)


class PayloadParameters:
    """The payload parameters of :class:`~.node.SimulatorNode` (a mixin: it reads the node's
    ``sim``, ``k``, ``dt``, ``dt_ns``, ``model``, ``_reach``, ``_pub_payload`` and sets
    ``_pending_payload``, ``payload_changes``)."""

    def _payload_from(self, values):
        """The :class:`Payload` of the three parameters' ``values`` (ConfigError if bad)."""
        return Payload(values["payload.mass"], list(values["payload.com"]),
                       list(values["payload.inertia"]), reach=self._reach)

    def _check_parameters(self, changed):
        """The table's checks, then the payload's as a whole (the other two parameters at
        their current values): a refusal leaves the plant unchanged."""
        result = super()._check_parameters(changed)
        if not result.successful or not any(p.name in PAYLOAD_PARAMETERS for p in changed):
            return result
        try:
            self._payload_from(self._payload_values(changed))
        except RcacError as err:
            result.successful, result.reason = False, str(err)
        return result

    def _payload_values(self, changed):
        values = {name: self.get_parameter(name).value for name in PAYLOAD_PARAMETERS}
        values.update({p.name: p.value for p in changed if p.name in PAYLOAD_PARAMETERS})
        return values

    def _on_parameters_set(self, changed):
        if any(p.name in PAYLOAD_PARAMETERS for p in changed):
            self._pending_payload = self._payload_from(self._payload_values(()))

    def _apply_payload(self):
        """Put the pending payload into the plant (before the step that carries it)."""
        payload, self._pending_payload = self._pending_payload, None
        self.sim.set_payload(payload)
        self.payload_changes += 1
        t = self.k * self.dt
        if payload.attached:
            self.get_logger().info(
                f"payload: {payload.mass:g} kg at {payload.com.tolist()} m, inertia "
                f"{inertia_values(payload.inertia).tolist()} kg m^2, held from step {self.k} "
                f"(t = {t:.3f} s)")
        else:
            self.get_logger().info(f"payload: released at step {self.k} (t = {t:.3f} s)")
        self._publish_payload()

    def _publish_payload(self):
        payload = self.sim.payload
        stamp_ns = self.k * self.dt_ns
        msg = InertiaStamped()
        msg.header.stamp = TimeMsg(sec=stamp_ns // NS, nanosec=stamp_ns % NS)
        msg.header.frame_id = self.model.joint_names[-1]
        inertia = msg.inertia
        inertia.m = float(payload.mass)
        inertia.com.x, inertia.com.y, inertia.com.z = (float(v) for v in payload.com)
        I = payload.inertia
        inertia.ixx, inertia.iyy, inertia.izz = float(I[0, 0]), float(I[1, 1]), float(I[2, 2])
        inertia.ixy, inertia.ixz, inertia.iyz = float(I[0, 1]), float(I[0, 2]), float(I[1, 2])
        self._pub_payload.publish(msg)
