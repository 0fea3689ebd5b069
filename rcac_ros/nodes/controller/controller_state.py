"""``~/controller_state``: reference, feedback, error and output per joint, as JointStates.

joint_trajectory_controller publishes control_msgs/JointTrajectoryControllerState; that
package is not installable from the wheels, so the same content goes out as four
sensor_msgs/JointState topics under ``~/controller_state/``, labelled by joint name (any
plotting tool that knows JointState shows them):

* ``reference``: position ``q_d``, velocity ``qd_d``, effort ``qdd_d`` (the desired
  acceleration, as on ``~/desired_state``);
* ``feedback``: position ``q``, velocity ``qd`` (measured or estimated);
* ``error``: ``q_d - q``, ``qd_d - qd`` (JTC's sign: reference minus feedback);
* ``output``: effort ``tau``, the command sent (after clipping).

All four carry the same stamp (the state's in lockstep), so they pair up sample by sample.
"""

from sensor_msgs.msg import JointState

from rcac_ros.nodes.msgs.cdr import JointStateWriter
from rcac_ros.nodes.runtime.base import QOS_MONITOR
from rcac_ros.nodes.runtime.rclpy_private import byte_sender

#: the sub-topics of ``~/controller_state``
PARTS = ("reference", "feedback", "error", "output")
TOPIC = "~/controller_state"


class ControllerStatePublisher:
    """Four JointState publishers on a node, their messages written as CDR bytes
    (:class:`~rcac_ros.nodes.msgs.cdr.JointStateWriter`).

    Parameters
    ----------
    node : rclpy.node.Node
    joints : sequence of str
        The joint names, in the order of the arrays given to :meth:`publish`.
    create : callable, optional
        The node's publisher factory (``node.create_lifecycle_publisher`` for a managed node).
    """

    def __init__(self, node, joints, create=None):
        create = create or node.create_publisher
        self.publishers = [create(JointState, f"{TOPIC}/{part}", QOS_MONITOR) for part in PARTS]
        self._sends = [byte_sender(pub) for pub in self.publishers]
        self._write = JointStateWriter(joints)

    def publish(self, stamp, q_d, qd_d, qdd_d, q, qd, tau):
        """Publish one sample; arrays in the constructor's joint order, ``stamp`` a Time msg
        (``sec``, ``nanosec``)."""
        write = self._write
        ref, fb, err, out = self._sends
        ref(write(stamp, q_d, qd_d, qdd_d))
        fb(write(stamp, q, qd))
        err(write(stamp, q_d - q, qd_d - qd))
        out(write(stamp, effort=tau))
