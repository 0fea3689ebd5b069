"""What the controller and simulator nodes share (they never import each other).

Start-up (every parameter of the table declared and checked, the robot loaded, or nothing
left behind), the QoS profiles, diagnostics, on-set parameter checks, and :func:`run`: the
``main`` of a node (clean start-up refusal with one line and exit 2, clean shutdown on
SIGINT/SIGTERM). Throttled warnings and compute-time statistics:
:mod:`rcac_ros.nodes.runtime.stats`.
"""

import sys
import time
import traceback

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              ParameterUninitializedException)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from rcac_ros import params, topics
from rcac_ros.core.load import load_model
from rcac_ros.core.urdf import model_from_urdf
from rcac_ros.errors import ConfigError, RcacError, first_line
from rcac_ros.nodes.runtime import gcwatch, interrupt, startargs
from rcac_ros.nodes.runtime.description import wait_for_description
from rcac_ros.nodes.runtime.diagnosed import RcacNodeMixin
from rcac_ros.nodes.runtime.pacing import spin_node_once
from rcac_ros.nodes.runtime.rclpy_private import parameter_overrides
from rcac_ros.nodes.runtime.realtime import Realtime
from rcac_ros.nodes.runtime.stats import Throttle

#: reliable, keep-last 10: the control topics (what ros2_control uses)
QOS = topics.qos()
#: reliable, keep-last 1000: the topics a recorder or a test reads
QOS_MONITOR = topics.qos(topics.MONITOR_DEPTH)


# ------------------------------------------------------------------ parameters
def declare(node, p):
    """Declare the parameter of row ``p`` (:mod:`rcac_ros.params`); return its checked value.

    Returns ``None`` for a row without default that the user left unset.

    Raises
    ------
    ConfigError
        If the value given by the user has the wrong type or is invalid; the message
        names the parameter.
    """
    desc = ParameterDescriptor(description=p.description, read_only=p.read_only,
                               additional_constraints=p.constraints)
    if p.lo is not None and p.type == "integer":
        desc.integer_range = [IntegerRange(from_value=int(p.lo), to_value=int(p.hi), step=0)]
    elif p.lo is not None and p.type == "double":
        desc.floating_point_range = [FloatingPointRange(from_value=float(p.lo),
                                                        to_value=float(p.hi), step=0.0)]
    default = Parameter.Type[p.type.upper()] if p.default is None else p.default
    try:
        if not node.has_parameter(p.name):     # a managed node configures more than once
            node.declare_parameter(p.name, default, desc)
        value = node.get_parameter(p.name).value
    except InvalidParameterTypeException as err:
        raise ConfigError(f"{p.name}: wrong type, expected {p.type} "
                          f"({first_line(err)})") from None
    except InvalidParameterValueException:
        raise ConfigError(params.out_of_range(p)) from None
    except ParameterUninitializedException:
        if p.default is not None and p.name in parameter_overrides(node):    # given as []
            raise ConfigError(f"{p.name}: empty ([]); leave it out for its default") \
                from None
        return None
    if p.type.endswith("_array"):
        value = list(value)         # rclpy gives array.array for double arrays
    return params.check(p, value)


def declare_parameters(node, rows, description=None):
    """Declare every row of a node's table (:mod:`rcac_ros.params`) and load its robot.

    ``description`` (URDF XML received on ``description_topic``) replaces
    ``robot_description`` when given.

    Returns
    -------
    values : dict
        name -> checked value (``None``: unset).
    model : RobotModel
        ``robot_description`` (URDF XML or a file path) when it is set, else ``model``
        (a preset, a YAML or a URDF file), with ``gravity`` if given.
    joints : tuple of str
        The joint order of the node's messages (``joints``, default the model's).

    Raises
    ------
    ConfigError
        Naming the parameter whose value is invalid or could not be turned into a model.
    """
    values = {p.name: declare(node, p) for p in rows}
    urdf = description or values["robot_description"]
    which = "description_topic" if description else \
        "robot_description" if urdf else "model"
    try:
        if urdf:
            model = model_from_urdf(urdf, base_link=values["base_link"] or None,
                                    tip_link=values["tip_link"] or None)
        else:
            model = load_model(values["model"])
    except RcacError as err:
        raise ConfigError(f"{which}: {err}") from None
    except Exception as err:  # noqa: BLE001 - any parser failure is a bad parameter
        raise ConfigError(f"{which}: cannot load ({first_line(err)})") from None
    if values["gravity"] is not None:
        model = model.replace(gravity=list(values["gravity"]))
    return values, model, _joints(values["joints"], model)


def _joints(joints, model):
    if joints is None:
        return tuple(model.joint_names)
    if len(set(joints)) != len(joints):
        raise ConfigError(f"joints: duplicate names in {list(joints)}")
    if set(joints) != set(model.joint_names):
        raise ConfigError(f"joints: {list(joints)} does not match the model's joints "
                          f"{list(model.joint_names)}")
    return tuple(joints)


def joint_order(model, joints):
    """The index arrays between the model's joint order and the messages' (``joints``).

    Returns
    -------
    out : ndarray of int (n,)
        Model order -> message order: ``q[out]`` lists ``q`` in ``joints`` order.
    order : ndarray of int (n,)
        Message order -> model order: ``x[order]`` lists a ``joints``-ordered ``x`` in the
        model's order.
    """
    return (np.array([model.joint_names.index(j) for j in joints]),
            np.array([joints.index(j) for j in model.joint_names]))


# ------------------------------------------------------------------ node
class RcacNode(RcacNodeMixin, Node):
    """The start-up of a plain node: read and check every parameter, or leave nothing behind.

    ``RcacNode(name, **kwargs)``: ``kwargs`` go to :class:`rclpy.node.Node` (``context``,
    ``parameter_overrides``, ...); an invalid parameter raises :class:`ConfigError` naming
    it. A subclass names its rows of the parameter table in ``PARAMETERS`` and implements
    ``_read_parameters(values)``, ``diagnostics()`` (a DiagnosticStatus, published every
    ``diagnostics_period`` s of the steady clock) and ``on_interrupt()``. It finds the robot
    in ``model``, the joint order of its messages in ``joints``; ``finished`` and
    ``exit_code`` tell :func:`run` when and how to stop. With a ``description_topic`` row
    set, it waits for the robot description first. (The controller is managed:
    :class:`rcac_ros.nodes.runtime.managed.ManagedNode`.)
    """

    #: the node's rows of :mod:`rcac_ros.params`
    PARAMETERS = ()

    def __init__(self, name, **kwargs):
        super().__init__(name, **kwargs)
        self.finished = False
        self.exit_code = 0
        try:
            topic = [declare(self, p) for p in self.PARAMETERS if p.name == "description_topic"]
            xml = wait_for_description(self, topic[0], SingleThreadedExecutor) \
                if topic and topic[0] else None
            values, self.model, self.joints = declare_parameters(self, self.PARAMETERS, xml)
            self._out, self._order = joint_order(self.model, self.joints)
            self._read_parameters(values)
            self._check_unknown_parameters(values["strict_parameters"])
        except BaseException:       # a bad parameter, or an interrupt (SIGTERM) at start-up
            self.destroy_node()     # leave no half-built node (and its rosout logger) behind
            raise
        self._throttle = Throttle(self.get_logger())
        self._rows = {p.name: p for p in self.PARAMETERS}
        self.add_on_set_parameters_callback(self._check_parameters)
        self._pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, QOS)
        self.create_timer(values["diagnostics_period"], self._publish_diagnostics,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))


# ------------------------------------------------------------------ main
#: s a node stays after its shutdown transition, serving its executor, so that DDS delivers
#: what it wrote last (the transition's answer)
SHUTDOWN_LINGER = 0.5


def _fatal(node, prog):
    """An exception no part of the node caught (being handled): its traceback in the node's
    log, then what an interrupt does (the controller's zero effort: the arm must not keep
    the last effort); returns the exit code, 1."""
    text = traceback.format_exc().rstrip()
    print(f"{prog}: fatal: {text}", file=sys.stderr, flush=True)
    if node is not None:
        node.get_logger().fatal(f"a callback raised; the node stops:\n{text}")
        try:
            node.on_interrupt()
        except Exception:               # noqa: BLE001 -- already failing: report, exit
            print(f"{prog}: the stop failed too: {traceback.format_exc()}", file=sys.stderr)
    return 1


def run(node_factory, prog, args=None):
    """Run one node until it finishes, SIGINT/SIGTERM, or an external shutdown.

    A node with a ``loop`` attribute (a :class:`DeadlineLoop`) is paced by it; otherwise
    the executor is spun. The node's ``on_interrupt()`` runs after an interrupt (the
    controller publishes a zero effort there), and after an exception that no part of the
    node caught (logged with its traceback; exit code 1). A :class:`RcacError` at start-up (a
    bad parameter) prints one line naming the parameter and returns 2. Returns the exit code.
    """
    args = sys.argv if args is None else args
    if not startargs.init(args, prog):
        return 2
    interrupt.install()
    node = rt = executor = None
    code, spinning = 0, False
    try:
        node = node_factory()
        interrupt.check()
        gcwatch.WATCH.install()             # the collector's pauses, in the diagnostics
        rt = Realtime.for_node(node)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        spinning = True
        while rclpy.ok() and not node.finished:
            spin_node_once(executor, node)
            if not node.finished:
                interrupt.check()
        if node.finished:
            # the shutdown transition's answer (and the last zero effort) are written but may
            # not be delivered yet: keep the participant a moment before destroying it (a
            # client once waited 60 s in vain for the answer of a process already gone)
            end = time.monotonic() + SHUTDOWN_LINGER
            while rclpy.ok() and time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
        code = node.exit_code
    except RcacError as err:
        if spinning:                    # not at start-up: a fault, as below
            code = _fatal(node, prog)
        else:                           # a bad parameter: one line
            print(f"{prog}: error: {err}", file=sys.stderr, flush=True)
            code = 2
    except KeyboardInterrupt:
        if node is not None and node.finished:
            code = node.exit_code       # it had stopped already (its linger was cut short)
        elif node is not None:
            node.on_interrupt()
    except ExternalShutdownException:
        pass
    except Exception:                   # noqa: BLE001 -- a fault no part of the node caught
        code = _fatal(node, prog)
    finally:
        interrupt.ignore()
        gcwatch.WATCH.close()
        if rt is not None:
            rt.release()
        if executor is not None:
            # its guard conditions now, while the context lives: the node and the executor
            # refer to each other, so the collector could otherwise destroy them after the
            # shutdown below ("Exception ignored in: Executor.__del__", a traceback at exit)
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
