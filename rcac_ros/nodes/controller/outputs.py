"""The controller node's publishers: the effort command and the monitor topics.

Arrays arrive in model order and leave in the order of the ``joints`` parameter. In
lockstep each effort is tagged with the stamp of the state it answers
(:func:`rcac_ros.topics.effort_label`); in timer mode one message object is reused.
They are lifecycle publishers: silent unless the node is active.
"""

import numpy as np
from rclpy.duration import Duration
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension, MultiArrayLayout

from rcac_ros import topics
from rcac_ros.nodes.runtime.base import QOS, QOS_MONITOR
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
        self._friction_layout = MultiArrayLayout(dim=[
            MultiArrayDimension(label="joint", size=n, stride=3 * n),
            MultiArrayDimension(label="armature,damping,friction", size=3, stride=3)])
        self._theta_layout = MultiArrayLayout(dim=[
            MultiArrayDimension(label="link", size=n, stride=13 * n),
            MultiArrayDimension(label="parameter", size=13, stride=13)])
        m = len(channels)
        self._channel_layout = MultiArrayLayout(dim=[MultiArrayDimension(
            label=topics.channels_label(channels), size=m, stride=m)])
        self._joint_layout = MultiArrayLayout(dim=[
            MultiArrayDimension(label="joint", size=n, stride=n)])
        # timer mode reuses its messages (publish serialises at once)
        self._effort_layout = effort_layout(n)
        self._watchdog_layout = effort_layout(n, watchdog=True)
        self._timer_msg = Float64MultiArray(layout=self._effort_layout)
        self._desired_msg = JointState(name=list(joints))
        #: lockstep: the last answer sent (re-sent when the same state comes again)
        self.last_answer = None

    def effort(self, values, stamp=None, watchdog=False):
        """Publish efforts given in ``joints`` order (zeros if any is NaN/Inf)."""
        values = np.asarray(values, dtype=float)
        if not np.all(np.isfinite(values)):      # never publish NaN/Inf
            values = np.zeros_like(values)
        if not self._tagged:                     # untagged: one message object, reused
            msg = self._timer_msg
            msg.layout = self._watchdog_layout if watchdog else self._effort_layout
            msg.data = values.tolist()
            self._effort.publish(msg)
            return
        msg = Float64MultiArray(layout=effort_layout(self.n, stamp, watchdog),
                                data=values.tolist())
        self._effort.publish(msg)
        if not watchdog:
            self.last_answer = msg

    def answer_again(self):
        """Publish the last answer again (lockstep: the same state came twice)."""
        self._effort.publish(self.last_answer)

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
        out = self._out
        self._theta.publish(Float64MultiArray(layout=self._theta_layout,
                                              data=theta_hat.ravel().tolist()))
        if self._friction is not None and friction_hat is not None:
            self._friction.publish(Float64MultiArray(layout=self._friction_layout,
                                                     data=friction_hat.ravel().tolist()))
        self._e.publish(Float64(data=float(E[0])))   # the first channel (joint 1 by default)
        self._es.publish(Float64MultiArray(layout=self._channel_layout, data=E.tolist()))
        self._track.publish(Float64MultiArray(layout=self._joint_layout,
                                              data=(q - q_d)[out].tolist()))
        ds = self._desired_msg
        ds.position = q_d[out].tolist()
        ds.velocity = qd_d[out].tolist()
        ds.effort = qdd_d[out].tolist()
        ds.header.stamp = stamp if stamp is not None else self._node.get_clock().now().to_msg()
        self._desired.publish(ds)
        self._state.publish(ds.header.stamp, q_d[out], qd_d[out], qdd_d[out], q[out], qd[out],
                            tau[out])

    def zero_effort(self, timeout=0.5):
        """Publish one zero effort (tagged watchdog) and wait up to ``timeout`` s for delivery."""
        self._effort.publish(Float64MultiArray(layout=effort_layout(self.n, watchdog=True),
                                               data=[0.0] * self.n))
        self._effort.wait_for_all_acked(Duration(seconds=timeout))
