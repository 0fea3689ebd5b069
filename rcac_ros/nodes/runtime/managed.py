"""A managed (``rclpy.lifecycle``) node with the start-up rules of :class:`RcacNode`.

The standard services ``~/get_state`` and ``~/change_state`` (and the other lifecycle
services) drive it:

* configure: every parameter of the table declared and checked, the robot loaded (from
  ``description_topic`` when set), then the subclass's ``_configure(values)``; a bad
  parameter makes the transition fail: the node stays ``unconfigured`` and logs why (an
  ERROR line naming the parameter, on /rosout), and :attr:`config_error` keeps it;
* activate / deactivate: the subclass's ``_activate()`` / ``_deactivate()`` (lifecycle
  publishers are enabled / disabled around them);
* cleanup: everything configure made is destroyed (:meth:`keep` registers it); the
  declared parameters stay;
* shutdown: cleanup, then :func:`rcac_ros.nodes.runtime.base.run` returns (exit 0).

``autostart`` (a row of the table, default true) configures and activates at start-up,
so ``ros2 run`` is one step; a bad parameter then refuses the start (one line, exit 2) as
the plain nodes do. With ``description_topic`` the node waits ``unconfigured`` until the
description arrives, then (with ``autostart``) configures and activates.
"""

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock, ClockType
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn

from rcac_ros import topics
from rcac_ros.errors import ConfigError, RcacError
from rcac_ros.nodes.runtime.base import declare, declare_parameters, QOS
from rcac_ros.nodes.runtime.description import subscribe_description
from rcac_ros.nodes.runtime.diagnosed import RcacNodeMixin
from rcac_ros.nodes.runtime.rclpy_private import (change_state_service, lifecycle_state,
                                                  release_state_machine)
from rcac_ros.nodes.runtime.stats import Throttle

SUCCESS = TransitionCallbackReturn.SUCCESS
FAILURE = TransitionCallbackReturn.FAILURE


class ManagedNode(RcacNodeMixin, LifecycleNode):
    """Lifecycle plumbing for a node of the package (see the module docstring).

    A subclass names its rows in ``PARAMETERS`` (with ``autostart``, ``description_topic``
    and ``diagnostics_period``) and implements ``_configure(values)``, ``_activate()``,
    ``_deactivate()`` (the last effort), ``diagnostics()`` and ``on_interrupt()``.

    Raises
    ------
    ConfigError
        With ``autostart`` and no ``description_topic``: a bad parameter (naming it).
    """

    PARAMETERS = ()

    def __init__(self, name, **kwargs):
        super().__init__(name, **kwargs)
        self.finished = False               # run(): stop (after the shutdown transition)
        self.exit_code = 0
        self.running = False                # active
        self.config_error = None            # why the last configure failed
        self._entities = []                 # (destroy, entity) made by configure
        self._description = None            # URDF XML from description_topic
        self._at_start = False              # autostart in the constructor: run() says why
        self._rows = {p.name: p for p in self.PARAMETERS}
        self._throttle = Throttle(self.get_logger())
        self._guard_change_state()
        try:
            self.autostart = declare(self, self._rows["autostart"])
            self.description_topic = declare(self, self._rows["description_topic"])
        except ConfigError:
            self.destroy_node()
            raise
        if self.description_topic:
            subscribe_description(self, self.description_topic, self._on_description)
            self.get_logger().info(f"unconfigured: waiting for the robot description on "
                                   f"{self.description_topic}")
        elif self.autostart:
            self._at_start = True
            try:
                started = self._start()
            except BaseException:           # an interrupt (SIGTERM) while configuring: the
                self.destroy_node()         # input threads it started are joined, not left
                raise                       # to die inside rcl at exit (an abort)
            self._at_start = False
            if not started:
                self.destroy_node()         # leave no half-built node behind
                raise ConfigError(self.config_error)

    def _start(self):
        """Configure and activate (once :meth:`_ready_to_activate`: a steady timer polls it
        while the node spins); ``False`` if configure failed. A failed activation ends the
        node (``finished``, exit code 1)."""
        if self.trigger_configure() != SUCCESS:
            return False

        def activate():
            if lifecycle_state(self) == "inactive" and self.trigger_activate() != SUCCESS:
                self.get_logger().fatal("autostart: activate failed; the node stops")
                self.exit_code, self.finished = 1, True

        if self._ready_to_activate():
            activate()
            return True

        def activate_when_ready():
            if self._ready_to_activate():
                timer.cancel()              # (destroyed with configure's entities)
                activate()
        timer = self.keep(self.destroy_timer, self.create_timer(
            0.05, activate_when_ready, clock=Clock(clock_type=ClockType.STEADY_TIME)))
        return True

    def _ready_to_activate(self):
        """Whether autostart may activate now (the subclass's work of configure is done)."""
        return True

    def _on_description(self, xml):
        self._description = xml
        if lifecycle_state(self) != "unconfigured":
            self.get_logger().warning("a new robot description arrived: it is used at the "
                                      "next configure (after a cleanup)")
        elif self.autostart:
            self._start()

    def _guard_change_state(self):
        """A transition that the current state does not offer answers ``success: false``
        (as rclcpp does); rclpy's own service would raise out of the executor."""
        service = change_state_service(self)
        inner = service.callback

        def change_state(request, response):
            try:
                return inner(request, response)
            except _rclpy.RCLError:
                self.get_logger().warning(
                    f"change_state: transition {request.transition.id} "
                    f"{request.transition.label!r} is not available from "
                    f"{lifecycle_state(self)!r}")
                response.success = False
                return response
        service.callback = change_state

    @property
    def description(self):
        """The URDF XML received on ``description_topic`` (``None``: none received, or no
        such topic)."""
        return self._description

    def keep(self, destroy, entity):
        """Register ``entity`` (made by configure) for ``destroy(entity)`` at cleanup."""
        self._entities.append((destroy, entity))
        return entity

    # ------------------------------------------------------------------ transitions
    def on_configure(self, state):
        """Parameters, robot, then the subclass's entities; FAILURE (unconfigured) if invalid."""
        try:
            if self.description_topic and self._description is None:
                raise ConfigError(f"description_topic: no robot description received on "
                                  f"{self.description_topic} yet")
            values, self.model, self.joints = declare_parameters(self, self.PARAMETERS,
                                                                 self._description)
            self._check_unknown_parameters(values["strict_parameters"])
            self._configure(values)
        except RcacError as err:
            self.config_error = str(err)
            if not self._at_start:          # (at start-up, run() prints the one line)
                self.get_logger().error(f"configure failed: {err}")
            self._destroy_entities()
            return FAILURE
        self.config_error = None
        self._pub_diag = self.keep(self.destroy_publisher, self.create_publisher(
            DiagnosticArray, topics.DIAGNOSTICS, QOS))
        self.keep(self.destroy_timer, self.create_timer(
            values["diagnostics_period"], self._publish_diagnostics,
            clock=Clock(clock_type=ClockType.STEADY_TIME)))
        self.add_on_set_parameters_callback(self._check_parameters)
        self.keep(self.remove_on_set_parameters_callback, self._check_parameters)
        return super().on_configure(state)

    def on_activate(self, state):
        """Enable the lifecycle publishers, then the subclass's ``_activate()``."""
        result = super().on_activate(state)
        self._activate()
        self.running = True
        return result

    def on_deactivate(self, state):
        """The subclass's ``_deactivate()`` (its last message), then silence."""
        self.running = False
        self._deactivate()
        return super().on_deactivate(state)

    def on_cleanup(self, state):
        """Destroy everything configure made (the parameters stay declared)."""
        self._destroy_entities()
        return super().on_cleanup(state)

    def on_shutdown(self, state):
        """From active: ``_deactivate()`` first. Then cleanup, and the process ends."""
        if self.running:
            self.running = False
            self._deactivate()
        self._destroy_entities()
        self.finished = True
        return SUCCESS

    def on_error(self, state):
        """An exception in a transition: everything destroyed, back to unconfigured."""
        self.running = False
        self._destroy_entities()
        self.get_logger().error("transition error: cleaned up, back to unconfigured")
        return SUCCESS

    def _destroy_entities(self):
        self.running = False
        while self._entities:
            destroy, entity = self._entities.pop()
            destroy(entity)

    def destroy_node(self):
        """Destroy what configure made, then the node and its lifecycle state machine (which
        holds the node's handle: without this, the node's name keeps its /rosout publisher
        in the process).

        What configure made goes first, whatever the state: it includes the input threads
        (:class:`~rcac_ros.nodes.runtime.inputs.SideInput`), joined here. A thread still
        waiting in ``rcl`` when the interpreter exits is ended inside C++ code, and the
        process aborts ("terminate called without an active exception", exit 134: a
        controller in timer mode stopped by SIGINT did).
        """
        self._destroy_entities()
        super().destroy_node()
        release_state_machine(self)
