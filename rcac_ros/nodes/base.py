"""Helpers shared by the controller and simulator nodes (they never import each other).

Parameters, model loading, the lockstep tag of an effort message, throttled
warnings and the ``main`` wrapper (clean start-up refusal, clean shutdown).
"""

import math
import signal
import sys
import time

import numpy as np
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
import rclpy
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              ParameterUninitializedException)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import MultiArrayDimension, MultiArrayLayout

from rcac_ros import topics
from rcac_ros.core.load import load_model
from rcac_ros.core.model import PRESETS
from rcac_ros.core.urdf import model_from_urdf
from rcac_ros.errors import ConfigError, RcacError
from rcac_ros.nodes.pacing import spin_node_once


# ------------------------------------------------------------------ parameters
def declare(node, name, default, description, *, lo=None, hi=None, read_only=True,
            constraints=""):
    """Declare one parameter with a descriptor and return its value (``None`` if unset).

    ``default`` is a value, or a :class:`rclpy.parameter.Parameter.Type` for a parameter
    that has no default (its value is then ``None`` unless the user sets it).
    ``lo``/``hi`` give a floating-point or integer range (inclusive).

    Raises
    ------
    ConfigError
        If the value given by the user has the wrong type or is out of range; the
        message names the parameter.
    """
    desc = ParameterDescriptor(description=description, read_only=read_only,
                               additional_constraints=constraints)
    if lo is not None or hi is not None:
        if isinstance(default, int) and not isinstance(default, bool):
            desc.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
        else:
            desc.floating_point_range = [FloatingPointRange(from_value=float(lo),
                                                            to_value=float(hi), step=0.0)]
    try:
        node.declare_parameter(name, default, desc)
        value = node.get_parameter(name).value
    except InvalidParameterTypeException as err:
        want = default.name.lower() if isinstance(default, Parameter.Type) \
            else type(default).__name__
        raise ConfigError(f"{name}: wrong type, expected {want} ({_first_line(err)})") from None
    except InvalidParameterValueException:
        raise ConfigError(f"{name}: value out of range [{lo:g}, {hi:g}]") from None
    except ParameterUninitializedException:
        return None
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f"{name}: must be finite, got {value}")
    return value


def _first_line(err):
    return str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__


def positive(name, value, strict=True):
    """Raise :class:`ConfigError` unless ``value`` is > 0 (or >= 0 when not ``strict``)."""
    if (strict and not value > 0.0) or (not strict and not value >= 0.0):
        raise ConfigError(f"{name}: must be {'>' if strict else '>='} 0, got {value}")
    return value


def per_joint(name, value, n, default, strict_positive=False, nonnegative=False):
    """A double-array parameter: 1 (broadcast) or ``n`` finite values; ``default`` if unset."""
    if value is None:
        return None if default is None else np.array(np.broadcast_to(default, (n,)), float)
    arr = np.asarray(list(value), dtype=float)
    if arr.size == 1:
        arr = np.full(n, arr[0])
    if arr.shape != (n,):
        raise ConfigError(f"{name}: expected 1 or {n} values (one per joint), got {len(value)}")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name}: contains NaN or Inf")
    if strict_positive and np.any(arr <= 0.0):
        raise ConfigError(f"{name}: every value must be > 0, got {arr.tolist()}")
    if nonnegative and np.any(arr < 0.0):
        raise ConfigError(f"{name}: every value must be >= 0, got {arr.tolist()}")
    return arr


def declare_model(node):
    """Declare ``model``, ``robot_description``, ``base_link``, ``tip_link``, ``gravity``.

    Returns
    -------
    RobotModel
        ``robot_description`` (URDF XML or a file path) wins when it is set; otherwise
        ``model`` is a preset name (:data:`PRESETS`) or a YAML file.

    Raises
    ------
    ConfigError
        Naming the parameter whose value could not be turned into a model.
    """
    name = declare(node, "model", "css_arm",
                   f"robot model: a preset ({', '.join(PRESETS)}) or a YAML model file")
    urdf = declare(node, "robot_description", "",
                   "URDF XML string or URDF file path; when set it replaces 'model'")
    base = declare(node, "base_link", "", "URDF chain start (empty: the root link)")
    tip = declare(node, "tip_link", "", "URDF chain end (empty: the single leaf)")
    gravity = declare(node, "gravity", Parameter.Type.DOUBLE_ARRAY,
                      "gravity in the base frame, m/s^2 (unset: the model's own)")
    which = "robot_description" if urdf else "model"
    try:
        if urdf:
            model = model_from_urdf(urdf, base_link=base or None, tip_link=tip or None)
        else:
            model = load_model(name)
    except RcacError as err:
        raise ConfigError(f"{which}: {err}") from None
    except Exception as err:  # noqa: BLE001 - any parser failure is a bad parameter
        raise ConfigError(f"{which}: cannot load ({_first_line(err)})") from None
    if gravity is not None:
        if len(gravity) != 3:
            raise ConfigError(f"gravity: expected 3 values, got {len(gravity)}")
        if not np.all(np.isfinite(gravity)):
            raise ConfigError("gravity: contains NaN or Inf")
        model = model.replace(gravity=list(gravity))
    return model


def declare_joints(node, model):
    """Declare ``joints`` (default: the model's joint names) and check it against the model.

    Returns
    -------
    tuple of str
        The joint order of the node's effort messages.
    """
    joints = declare(node, "joints", Parameter.Type.STRING_ARRAY,
                     "joint names, in the order of the effort commands (unset: the model's)")
    if joints is None:
        return tuple(model.joint_names)
    joints = tuple(joints)
    if len(set(joints)) != len(joints):
        raise ConfigError(f"joints: duplicate names in {list(joints)}")
    if set(joints) != set(model.joint_names):
        raise ConfigError(f"joints: {list(joints)} does not match the model's joints "
                          f"{list(model.joint_names)}")
    return joints


# ------------------------------------------------------------------ effort tag
def effort_layout(n, stamp=None, watchdog=False):
    """The layout of an effort message: one dimension of size ``n``, tagged (:mod:`topics`)."""
    return MultiArrayLayout(dim=[MultiArrayDimension(label=topics.effort_label(stamp, watchdog),
                                                     size=n, stride=n)], data_offset=0)


def stamp_ns(stamp):
    """A builtin_interfaces/Time as integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


# ------------------------------------------------------------------ warnings
class RcacNode(Node):
    """The start-up both nodes share: read and check every parameter, or leave nothing behind.

    Subclasses implement ``_read_parameters`` (raising :class:`ConfigError` naming the
    parameter); ``finished`` and ``exit_code`` tell :func:`run` when and how to stop.
    """

    def __init__(self, name, **kwargs):
        super().__init__(name, **kwargs)
        self.finished = False
        self.exit_code = 0
        try:
            self._read_parameters()
        except Exception:
            self.destroy_node()     # leave no half-built node (and its rosout logger) behind
            raise
        self._throttle = Throttle(self.get_logger())


class Throttle:
    """One warning per kind per ``period`` seconds (steady clock), with counts per kind."""

    def __init__(self, logger, period=1.0):
        self.logger = logger
        self.period = period
        self.counts = {}
        self._last = {}

    def warn(self, kind, text):
        """Count a rejection of ``kind`` and log ``text`` unless one was logged recently."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        now = time.monotonic()
        if now - self._last.get(kind, -math.inf) >= self.period:
            self._last[kind] = now
            suppressed = self.counts[kind]
            self.logger.warning(f"rejected ({kind}): {text} [{suppressed} so far]")

    @property
    def total(self):
        """Total number of rejections."""
        return sum(self.counts.values())


class Percentiles:
    """Compute-time statistics over a window (p50, p99, max) in microseconds."""

    def __init__(self):
        self._samples = []
        self.max_all = 0.0
        self._last = (math.nan, math.nan, math.nan)

    def add(self, seconds):
        """Record one sample, in seconds."""
        self._samples.append(seconds)
        self.max_all = max(self.max_all, seconds)

    def pop(self):
        """Return ``(count, p50, p99, max)`` in µs over the window, and start a new window.

        An empty window (the node is idle) repeats the figures of the last non-empty one.
        """
        if not self._samples:
            return (0,) + self._last
        arr = np.asarray(self._samples) * 1e6
        self._samples = []
        self._last = (float(np.percentile(arr, 50)), float(np.percentile(arr, 99)),
                      float(arr.max()))
        return (arr.size,) + self._last


# ------------------------------------------------------------------ main
def _raise_interrupt(signum, frame):
    # one interrupt starts the clean shutdown; later ones must not cut it short
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise KeyboardInterrupt


def run(node_factory, prog, args=None):
    """Run one node until it finishes, SIGINT/SIGTERM, or an external shutdown.

    A node with a ``loop`` attribute (a :class:`DeadlineLoop`) is paced by it; otherwise
    the executor is spun. The node's ``on_shutdown()`` runs after an interrupt (the
    controller publishes a zero effort there). A :class:`RcacError` at start-up (a bad
    parameter) prints one line naming the parameter and returns 2.

    Returns
    -------
    int
        The process exit code.
    """
    # rclpy's own SIGINT handler would shut the context down before we could publish the
    # final zero effort: handle both signals in Python instead.
    rclpy.init(args=sys.argv if args is None else args,
               signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, _raise_interrupt)
    signal.signal(signal.SIGTERM, _raise_interrupt)
    node = None
    code = 0
    try:
        node = node_factory()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while rclpy.ok() and not node.finished:
            spin_node_once(executor, node)
        code = node.exit_code
    except RcacError as err:
        print(f"{prog}: error: {err}", file=sys.stderr, flush=True)
        code = 2
    except KeyboardInterrupt:
        if node is not None:
            node.on_shutdown()
    except ExternalShutdownException:
        pass
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
