"""The rclpy internals the nodes need, in one place, each with the reason (rclpy 7, Jazzy).

Every other module of the package uses rclpy's public API only; where rclpy offers none
for what a node must do, the private attribute is read here, and only here.
"""


def parameter_overrides(node):
    """``{name: Parameter}`` given on the command line or in ``--params-file``, declared or
    not.

    Why: rclpy has no public accessor for overrides not declared yet. The per-joint gains
    ``gains.<joint>.<gain>`` are declared from them (as joint_trajectory_controller's), and
    keys no row declares are warned about (doc/failsafe.md, "parameters").
    """
    return node._parameter_overrides


def lifecycle_state(node):
    """The label of a lifecycle node's current state (``"unconfigured"``, ``"active"``, ...).

    Why: ``rclpy.lifecycle.LifecycleNode`` answers its state only through the
    ``~/get_state`` service, not to its own code.
    """
    return node._state_machine.current_state[1]


def change_state_service(node):
    """The lifecycle node's ``~/change_state`` service.

    Why: a transition the current state does not offer must answer ``success: false`` (as
    rclcpp does); rclpy's own callback raises out of the executor, so it is wrapped.
    """
    return node._service_change_state


def release_state_machine(node):
    """Destroy a lifecycle node's state machine after the node.

    Why: the state machine holds the node's handle; without this the node's name keeps its
    ``/rosout`` publisher in the process after ``destroy_node``.
    """
    node._state_machine.destroy_when_not_in_use()


def byte_sender(publisher):
    """``send(data)``: publish serialised bytes on ``publisher`` (a lifecycle publisher: only
    while it is enabled), what ``publisher.publish(data)`` does.

    Why: ``Publisher.publish`` reaches ``publish_raw`` through the lifecycle wrapper, the
    handle property and two type checks in Python at each call; the controller's answer
    publishes up to ten messages a step. The lifecycle switch is read from the publisher
    as its ``publish`` reads it.
    """
    impl = publisher.handle
    raw = impl.publish_raw
    managed = hasattr(publisher, "_enabled")

    def send(data):
        if managed and not publisher._enabled:
            return
        with impl:
            raw(data)
    return send
