"""The ROS interface contract shared by the nodes, the recorder, the inspector and the demo.

Names, quality of service and the lockstep tag of an effort message, in one place.
Topic names are relative, so they follow the node namespace and remappings. This module
imports neither rclpy nor numba at import time: the bag inspector uses it offline.
"""

CONTROLLER_NODE = "rcac_controller"
SIMULATOR_NODE = "rcac_simulator"

#: sensor_msgs/JointState, published by the simulator (or a real arm's driver)
JOINT_STATES = "joint_states"
#: std_msgs/Float64MultiArray, efforts in the order of the controller's ``joints`` parameter;
#: what a ros2_control JointGroupEffortController named ``effort_controller`` accepts
EFFORT_COMMANDS = "effort_controller/commands"
#: trajectory_msgs/JointTrajectory, desired motion (controller-private topic)
JOINT_TRAJECTORY = "~/joint_trajectory"
#: std_msgs/Float64MultiArray, theta_hat with layout dims ("link", n), ("parameter", 13)
PARAMETER_ESTIMATES = "~/parameter_estimates"
#: std_msgs/Float64MultiArray, the joint estimates (parameter joint_friction, doc/design.md §7)
#: with layout dims ("joint", n), ("armature,damping,friction", 3), in the model's joint order
FRICTION_ESTIMATES = "~/friction_estimates"
#: std_msgs/Float64, the prediction error E of eq 24 of the first channel (joint 1 by default)
PREDICTION_ERROR = "~/prediction_error"
#: std_msgs/Float64MultiArray, every channel's prediction error E_c (m values), one layout
#: dimension of size m labelled with the channel names (:func:`channels_label`)
PREDICTION_ERRORS = "~/prediction_errors"
#: std_msgs/Float64MultiArray, q - q_d per joint (rad), in the order of ``joints``
TRACKING_ERROR = "~/tracking_error"
#: sensor_msgs/JointState, the desired q_d, qd_d (effort = qdd_d) the controller used
DESIRED_STATE = "~/desired_state"
#: geometry_msgs/InertiaStamped, published by the simulator at start-up and at each change of
#: its payload parameters: the payload held by the last link (mass 0: none), stamped with the
#: sim time of the first step that carries it, ``frame_id`` the last joint's name (the frame
#: of the link it moves); reliable, transient local, depth 10 (a late reader gets the last
#: ten, the current one last)
PAYLOAD = "~/payload"
#: diagnostic_msgs/DiagnosticArray
DIAGNOSTICS = "/diagnostics"
#: rosgraph_msgs/Clock, published by the simulator
CLOCK = "/clock"


def resolve(topic, node=CONTROLLER_NODE, namespace=""):
    """The absolute name of ``topic`` for node ``node`` in ``namespace``, by the ROS 2 rules
    without remappings (offline: a bag's topic names): ``~/x`` -> ``<namespace>/<node>/x``,
    ``x`` -> ``<namespace>/x``, ``/x`` unchanged. A node has ``Node.resolve_topic_name``."""
    ns = namespace.rstrip("/")
    if topic.startswith("~/"):
        return f"{ns}/{node}/{topic[2:]}"
    return topic if topic.startswith("/") else f"{ns}/{topic}"


def channels_label(names):
    """The label of ``~/prediction_errors``'s dimension: the channel names, comma-separated
    (``"joint1,power"``; ``joint<k>`` is the model's k-th joint, 1-based)."""
    return ",".join(names)


def channel_names(label):
    """The channel names of a ``~/prediction_errors`` label (:func:`channels_label`)."""
    return [name for name in label.split(",") if name]


# ------------------------------------------------------------------ quality of service
#: keep-last depth of the control topics: reliable, keep-last 10, what ros2_control uses (a
#: best-effort publisher would deliver nothing to ros2_control's reliable subscribers)
DEPTH = 10
#: the same, keep-last 1000, for the topics a recorder or a test reads (2 s at 500 Hz): a slow
#: subscriber catches up instead of losing samples. Depth does not affect QoS compatibility.
MONITOR_DEPTH = 1000


def qos(depth=DEPTH, reliable=True, transient_local=False):
    """A keep-last ``rclpy.qos.QoSProfile`` (rclpy is imported only when this is called);
    ``transient_local``: a late reader gets the writer's last ``depth`` messages."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE if reliable
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if transient_local
                      else DurabilityPolicy.VOLATILE)


# ------------------------------------------------------------------ effort tag
#: label of the single dimension of an effort message; in lockstep the controller appends
#: ``" stamp=SEC.NANOSEC"`` (the stamp of the state it answers) or ``" watchdog"``.
#: Consumers that ignore the layout (ros2_control) are unaffected.
EFFORT_LABEL = "joint"
_STAMP = " stamp="
_WATCHDOG = " watchdog"


def effort_label(stamp=None, watchdog=False):
    """The label of an effort message's dimension.

    ``stamp`` (a builtin_interfaces/Time) tags the effort as the answer to that state;
    ``watchdog`` tags a safe effort sent because no state arrived.
    """
    if watchdog:
        return EFFORT_LABEL + _WATCHDOG
    if stamp is not None:
        return f"{EFFORT_LABEL}{_STAMP}{stamp.sec}.{stamp.nanosec:09d}"
    return EFFORT_LABEL


def is_watchdog_effort(raw):
    """Whether a serialised effort message (the bytes of a ``raw=True`` subscription) is
    tagged watchdog, without deserialising it: the label lies within its first 96 bytes."""
    return _WATCHDOG.strip().encode() in bytes(raw[:96])


def effort_tag(label):
    """Read an effort label: ``("stamp", ns)``, ``("watchdog", None)`` or ``None`` (untagged)."""
    if label.endswith(_WATCHDOG):
        return ("watchdog", None)
    if _STAMP in label:
        sec, _, nsec = label.split(_STAMP, 1)[1].partition(".")
        try:
            return ("stamp", int(sec) * 1_000_000_000 + int(nsec))
        except ValueError:
            return None
    return None
