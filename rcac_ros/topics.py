"""The ROS interface contract shared by the nodes, the recorder, the inspector and the demo.

Topic names are relative, so they follow the node namespace and remappings.
"""

from rcac_ros.core.model import PARAMETER_NAMES

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
#: std_msgs/Float64, the scalar prediction error E of eq 24
PREDICTION_ERROR = "~/prediction_error"
#: std_msgs/Float64MultiArray, q - q_d per joint (rad), in the order of ``joints``
TRACKING_ERROR = "~/tracking_error"
#: sensor_msgs/JointState, the desired q_d, qd_d (effort = qdd_d) the controller used
DESIRED_STATE = "~/desired_state"
#: diagnostic_msgs/DiagnosticArray
DIAGNOSTICS = "/diagnostics"
#: rosgraph_msgs/Clock, published by the simulator
CLOCK = "/clock"

PARAMETER_LABELS = PARAMETER_NAMES


def controller_topic(name):
    """Absolute name of a controller-private topic (``~/x`` -> ``/rcac_controller/x``)."""
    return f"/{CONTROLLER_NODE}/{name[2:]}" if name.startswith("~/") else f"/{name}"
