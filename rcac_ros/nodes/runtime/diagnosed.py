"""What both kinds of node (plain :class:`~rcac_ros.nodes.runtime.base.RcacNode` and managed
:class:`~rcac_ros.nodes.runtime.managed.ManagedNode`) share: on-set checks against the parameter
table, the periodic diagnostics, and publishers without rclpy's default event handlers."""

import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import PublisherEventCallbacks

from rcac_ros import params, topics
from rcac_ros.errors import ConfigError
from rcac_ros.nodes.runtime import gcwatch, paramcheck
from rcac_ros.nodes.runtime.rclpy_private import parameter_overrides


class RcacNodeMixin:
    """Parameter checks and diagnostics of both nodes (plain or managed): uses ``_rows``
    (name -> :class:`rcac_ros.params.Param`), ``model``, ``_pub_diag``, ``diagnostics()``."""

    #: prefixes of the given keys the node declares and checks itself as it reads them (each
    #: one used or refused): not reported as undeclared beforehand
    READ_PREFIXES = ()

    def create_publisher(self, *args, **kwargs):
        """rclpy's, without its default event handlers unless ``event_callbacks`` is given.

        rclpy gives every publisher two handlers (incompatible QoS, incompatible type) that only
        log, and its executor adds each to the wait set it rebuilds at every spin, where they
        were most of the waitables (doc/failsafe.md, "Real-time options"). The subscriber of an
        incompatible pair still reports it (its own default handlers, rclpy's and rclcpp's)."""
        kwargs.setdefault("event_callbacks", PublisherEventCallbacks(use_default_callbacks=False))
        return super().create_publisher(*args, **kwargs)

    def create_lifecycle_publisher(self, *args, **kwargs):
        """rclpy's (managed nodes), without its default event handlers, as
        :meth:`create_publisher`."""
        kwargs.setdefault("event_callbacks", PublisherEventCallbacks(use_default_callbacks=False))
        return super().create_lifecycle_publisher(*args, **kwargs)

    def _check_unknown_parameters(self, strict):
        """Warn about (``strict``: refuse) given keys that no row declares; name the nearest."""
        repeated = []
        files = paramcheck.check_params_files(sys.argv, repeated)
        fq_name = self.get_fully_qualified_name()
        shared = paramcheck.shared_keys(files, fq_name)     # the other node's, from /**
        declared = self.list_parameters([], 0).names
        others = {k for k in shared if k not in declared and not k.startswith(self.READ_PREFIXES)}
        for text, mixed in paramcheck.repeated_in(repeated, fq_name, skip=others):
            if mixed:
                raise ConfigError(f"{text}: of two types, rcl gives the node one of them by "
                                  "type, not the last; give it once")
            if strict:
                raise ConfigError(f"strict_parameters: {text}")
            self.get_logger().warning(f"{text}; the last is used")
        given = [k for k in parameter_overrides(self)
                 if not k.startswith(self.READ_PREFIXES) and k not in shared]
        unknown = paramcheck.unknown_parameters(given, declared)
        if unknown:
            text = paramcheck.describe_unknown(unknown, self.get_name())
            if strict:
                raise ConfigError(f"strict_parameters: {text}")
            self.get_logger().warning(text)
        nodes = [topics.CONTROLLER_NODE, topics.SIMULATOR_NODE, self.get_name()]
        for path, section, hint in paramcheck.foreign_sections(files, nodes):
            self.get_logger().warning(f"{path}: section '{section}' addresses no node of "
                                      f"rcac_ros (did you mean '{hint}'?)")
        for path in (path for path, sections in files.items() if not sections):
            self.get_logger().warning(f"{path}: an empty parameters file")
        missed = paramcheck.unapplied(files, self.get_name(), fq_name)
        if missed is not None:
            paths, elsewhere = missed
            self.get_logger().warning(
                f"{', '.join(paths)}: no section applies to this node ({fq_name})"
                + (f"; {', '.join(elsewhere)}: another namespace" if elsewhere else ""))

    def _check_parameters(self, changed):
        """On-set callback: validate against the table (a subclass applies them post-set)."""
        for p in changed:
            if p.name == "use_sim_time" and p.value != self.get_parameter(p.name).value:
                return SetParametersResult(
                    successful=False, reason="use_sim_time: cannot change at run time (the "
                    "watchdog and the pacing are set up for one time source): restart the node")
            row = self._rows.get(p.name)
            if row is None:
                continue                # rclpy's own
            value = p.value
            if row.type.endswith("_array") and value is not None:
                value = list(value)
            try:
                params.check(row, value)
            except ConfigError as err:
                return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _publish_diagnostics(self):
        msg = DiagnosticArray(status=[self.diagnostics()])
        msg.header.stamp = self.get_clock().now().to_msg()
        self._pub_diag.publish(msg)

    def status(self, level, name, message, values):
        """A DiagnosticStatus of this node from a ``{key: value}`` dict (plus the garbage
        collector's pauses when :func:`rcac_ros.nodes.runtime.base.run` runs the node)."""
        if gcwatch.WATCH.active:
            values = dict(values, **gcwatch.WATCH.values())
        return DiagnosticStatus(level=level, name=f"{self.get_name()}: {name}", message=message,
                                hardware_id=self.model.name,
                                values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])
