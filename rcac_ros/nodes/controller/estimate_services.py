"""The operator's estimate services of the controller (std_srvs).

* ``~/reset_estimates`` (Trigger): ``theta_hat`` back to the ``initial_estimates``, the
  filters restarted;
* ``~/set_adaptation`` (SetBool): ``false`` freezes the adaptation of eq 24 (the estimates
  are held and still used), ``true`` resumes it, unless the starvation guard holds it
  frozen too (then it resumes when the machine recovers:
  :class:`~rcac_ros.nodes.controller.freeze.AdaptationFreeze`);
* ``~/save_estimates`` (Trigger): writes the estimates to the parameter ``estimates_file``
  (YAML; with ``joint_friction`` the joint terms too) and the physically consistent links
  as URDF ``<inertial>`` blocks next to it (the joint terms as ``<dynamics>``)
  (:mod:`rcac_ros.nodes.controller.estimates`); the response names both files and every
  link left out, with the reason.

They exist while the node is configured (inactive or active).
"""

from std_srvs.srv import SetBool, Trigger

from rcac_ros.nodes.controller import estimates
from rcac_ros.nodes.controller.freeze import AdaptationFreeze


class EstimateServices:
    """The three services on ``node`` (which has ``ctrl``, ``model``, ``config``).

    Parameters
    ----------
    node : rclpy.node.Node
        The controller: ``node.ctrl`` (the core controller), ``node.adaptation``
        (:class:`AdaptationFreeze`), ``node.model``, ``node.config.theta0`` and ``.friction0``
        (the initial estimates, model order), ``node.config.urdf_links`` (or ``None``), and the
        parameter ``estimates_file``.
    """

    def __init__(self, node):
        self.node = node
        self.services = [
            node.create_service(Trigger, "~/reset_estimates", self._reset),
            node.create_service(SetBool, "~/set_adaptation", self._set_adaptation),
            node.create_service(Trigger, "~/save_estimates", self._save)]

    def destroy(self):
        """Remove the services (cleanup)."""
        for srv in self.services:
            self.node.destroy_service(srv)
        self.services = []

    def _reset(self, request, response):
        node = self.node
        node.ctrl.reset(node.config.theta0, node.config.friction0)
        response.success = True
        response.message = f"estimates reset to the initial estimates " \
                           f"({node.get_parameter('initial_estimates').value})"
        node.get_logger().info(response.message)
        return response

    def _set_adaptation(self, request, response):
        node = self.node
        node.adaptation.freeze(AdaptationFreeze.USER, not request.data)
        response.success = True
        if not request.data:
            response.message = "adaptation frozen: the estimates are held (and still used)"
        elif node.ctrl.adapting:
            response.message = "adaptation resumed"
        else:
            response.message = "adaptation: the freeze of set_adaptation is lifted; still " \
                "frozen by the starvation guard until the control loop's delay recovers"
        node.get_logger().info(response.message)
        return response

    def _save(self, request, response):
        node = self.node
        path = node.get_parameter("estimates_file").value
        if not path:
            response.success = False
            response.message = "estimates_file: not set (set the parameter to a .yaml path)"
            return response
        try:
            yaml_path, urdf, problems = estimates.save(
                path, node.ctrl.theta_hat, node.model.joint_names, node.model.name,
                node.config.urdf_links, friction=node.ctrl.friction_hat)
        except OSError as err:
            response.success = False
            response.message = f"estimates_file: cannot write {path!r} ({err.strerror})"
            return response
        n = node.model.n
        response.success = True
        response.message = (f"saved the estimates of {n} links to {yaml_path}; URDF inertials "
                            f"of {n - len(problems)} links to {urdf}")
        if problems:
            response.message += "; not physical, left out of the URDF: " + "; ".join(problems)
        node.get_logger().info(response.message)
        return response
