"""The controller node's publishers: the effort command and the monitor topics.

Arrays arrive in model order and leave in the order of the ``joints`` parameter. In
lockstep each effort is tagged with the stamp of the state it answers
(:func:`rcac_ros.topics.effort_label`). The messages of each step are written as CDR bytes
(:mod:`~rcac_ros.nodes.msgs.cdr`) and published as such
(:func:`~rcac_ros.nodes.runtime.rclpy_private.byte_sender`). They are lifecycle
publishers: silent unless the node is active.
"""

import numpy as np
from rclpy.duration import Duration
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension, MultiArrayLayout

from rcac_ros import topics
from rcac_ros.nodes.msgs import cdr
from rcac_ros.nodes.runtime.base import QOS, QOS_MONITOR
from rcac_ros.nodes.runtime.rclpy_private import byte_sender
from rcac_ros.nodes.controller.controller_state import ControllerStatePublisher


def effort_layout(n, stamp=None, watchdog=False):
    """The layout of an effort message: one dimension of size ``n``, tagged (:mod:`topics`)."""
    return MultiArrayLayout(dim=[MultiArrayDimension(label=topics.effort_label(stamp, watchdog),
                                                     size=n, stride=n)], data_offset=0)


class ControllerOutputs:
    """Publishers of ``effort_controller/commands`` and of the controller's private topics.

    Parameters
    ----------
    node : rclpy.node.Node
    joints : sequence of str
        The joint order of the messages.
    out : ndarray of int
        Model order -> ``joints`` order.
    tagged : bool
        Lockstep: tag each effort with the stamp of the state it answers.
    channels : sequence of str
        The prediction channels' names (``joint1``, ``power``, ...), the order of ``E``.

    The publishers are the managed node's lifecycle publishers (enabled while active);
    :meth:`destroy` removes them (cleanup).
    """

    def __init__(self, node, joints, out, tagged, channels=("joint1",), joint_friction=False):
        n = len(joints)
        self.n = n
        self._node = node
        self._out = out
        self._tagged = tagged
        create = node.create_lifecycle_publisher
        self._effort = create(Float64MultiArray, topics.EFFORT_COMMANDS, QOS)
        self._theta = create(Float64MultiArray, topics.PARAMETER_ESTIMATES, QOS_MONITOR)
        self._e = create(Float64, topics.PREDICTION_ERROR, QOS_MONITOR)
        self._es = create(Float64MultiArray, topics.PREDICTION_ERRORS, QOS_MONITOR)
        self._track = create(Float64MultiArray, topics.TRACKING_ERROR, QOS_MONITOR)
        self._desired = create(JointState, topics.DESIRED_STATE, QOS_MONITOR)
        self._state = ControllerStatePublisher(node, joints, create)
        self._friction = create(Float64MultiArray, topics.FRICTION_ESTIMATES, QOS_MONITOR) \
            if joint_friction else None
        self._send_effort = byte_sender(self._effort)
        self._send = {name: byte_sender(pub) for name, pub in (
            ("theta", self._theta), ("e", self._e), ("es", self._es), ("track", self._track),
            ("desired", self._desired), ("friction", self._friction)) if pub is not None}
        self._friction_bytes = cdr.MultiArrayWriter(
            [("joint", n, 3 * n), ("armature,damping,friction", 3, 3)])
        self._theta_bytes = cdr.MultiArrayWriter([("link", n, 13 * n), ("parameter", 13, 13)])
        m = len(channels)
        self._channel_bytes = cdr.MultiArrayWriter([(topics.channels_label(channels), m, m)])
        self._joint_bytes = cdr.MultiArrayWriter([("joint", n, n)])
        self._desired_bytes = cdr.JointStateWriter(joints)
        #: lockstep: the last answer sent, its bytes (sent again when the same state comes)
        self.last_answer = None

    def effort(self, values, stamp=None, watchdog=False):
        """Publish efforts given in ``joints`` order (zeros if any is NaN/Inf); tagged with
        ``stamp`` in lockstep."""
        values = np.asarray(values, dtype=float)
        if not np.isfinite(values).all():       # never publish NaN/Inf
            values = np.zeros_like(values)
        data = cdr.one_dim_array(
            topics.effort_label(stamp if self._tagged else None, watchdog), self.n, values)
        self._send_effort(data)
        if self._tagged and not watchdog:
            self.last_answer = data

    def answer_again(self):
        """Publish the last answer again (lockstep: the same state came twice)."""
        self._send_effort(self.last_answer)

    def destroy(self):
        """Destroy every publisher (the node's cleanup)."""
        for pub in [self._effort, self._theta, self._e, self._es, self._track, self._desired] \
                + self._state.publishers + ([self._friction] if self._friction else []):
            self._node.destroy_lifecycle_publisher(pub)

    def monitors(self, theta_hat, E, q, qd, q_d, qd_d, qdd_d, tau, stamp=None,
                 friction_hat=None):
        """Publish the estimates (and the joint estimates, with ``joint_friction``), E
        (channel 1's, and every channel's), the tracking error, the desired state and
        ``~/controller_state`` (arrays in model order)."""
        out, send = self._out, self._send
        send["theta"](self._theta_bytes(theta_hat))
        if self._friction is not None and friction_hat is not None:
            send["friction"](self._friction_bytes(friction_hat))
        send["e"](cdr.float64(float(E[0])))     # the first channel (joint 1 by default)
        send["es"](self._channel_bytes(E))
        send["track"](self._joint_bytes((q - q_d)[out]))
        stamp = stamp if stamp is not None else self._node.get_clock().now().to_msg()
        q_d, qd_d, qdd_d = q_d[out], qd_d[out], qdd_d[out]
        send["desired"](self._desired_bytes(stamp, q_d, qd_d, qdd_d))
        self._state.publish(stamp, q_d, qd_d, qdd_d, q[out], qd[out], tau[out])

    def zero_effort(self, timeout=0.5):
        """Publish one zero effort (tagged watchdog) and wait up to ``timeout`` s for delivery."""
        self._effort.publish(Float64MultiArray(layout=effort_layout(self.n, watchdog=True),
                                               data=[0.0] * self.n))
        self._effort.wait_for_all_acked(Duration(seconds=timeout))
