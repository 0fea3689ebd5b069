"""What both kinds of node (plain :class:`~rcac_ros.nodes.base.RcacNode` and managed
:class:`~rcac_ros.nodes.managed.ManagedNode`) share: on-set checks against the parameter
table and the periodic diagnostics."""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult

from rcac_ros import params
from rcac_ros.errors import ConfigError


class RcacNodeMixin:
    """Parameter checks and diagnostics of both nodes (plain or managed): uses ``_rows``
    (name -> :class:`rcac_ros.params.Param`), ``model``, ``_pub_diag``, ``diagnostics()``."""

    def _check_parameters(self, changed):
        """On-set callback: validate against the table (a subclass applies them post-set)."""
        for p in changed:
            row = self._rows.get(p.name)
            if row is None:
                continue                # rclpy's own (use_sim_time, ...)
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
        """A DiagnosticStatus of this node from a ``{key: value}`` dict."""
        return DiagnosticStatus(level=level, name=f"{self.get_name()}: {name}", message=message,
                                hardware_id=self.model.name,
                                values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])
