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

from rcac_ros.nodes.runtime.base import QOS_MONITOR

#: the sub-topics of ``~/controller_state``
PARTS = ("reference", "feedback", "error", "output")
TOPIC = "~/controller_state"


class ControllerStatePublisher:
    """Four JointState publishers on a node, one message object each (reused).

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
        self._msgs = [JointState(name=list(joints)) for _ in PARTS]

    def publish(self, stamp, q_d, qd_d, qdd_d, q, qd, tau):
        """Publish one sample; arrays in the constructor's joint order, ``stamp`` a Time msg."""
        ref, fb, err, out = self._msgs
        ref.position, ref.velocity, ref.effort = q_d.tolist(), qd_d.tolist(), qdd_d.tolist()
        fb.position, fb.velocity = q.tolist(), qd.tolist()
        err.position, err.velocity = (q_d - q).tolist(), (qd_d - qd).tolist()
        out.effort = tau.tolist()
        for pub, msg in zip(self.publishers, self._msgs):
            msg.header.stamp = stamp
            pub.publish(msg)
