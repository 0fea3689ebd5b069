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
    """The three services of a controller: what they read and what they call, nothing more.

    Parameters
    ----------
    node : rclpy.node.Node
        Where the services live (rclpy's API only).
    ctrl : RecursiveCompositeController
        The core controller (its estimates).
    adaptation : AdaptationFreeze
        ``~/set_adaptation`` holds its own reason, :attr:`AdaptationFreeze.USER`.
    model : RobotModel
        ``joint_names``, ``name`` and ``n``, for the files.
    theta0, friction0 : ndarray or None
        The initial estimates, model order (``friction0``: the joint terms', or ``None``).
    initial : str
        The parameter ``initial_estimates``, named in ``~/reset_estimates``' answer.
    urdf_links : tuple or None
        The URDF's links (:func:`~rcac_ros.nodes.controller.estimates.save`).
    estimates_file : callable
        ``estimates_file()``: the parameter ``estimates_file`` now (a run-time parameter).
    log : rclpy logger
        One line an answer.
    """

    def __init__(self, node, *, ctrl, adaptation, model, theta0, friction0, initial,
                 urdf_links, estimates_file, log):
        self.node = node
        self.ctrl, self.adaptation, self.model = ctrl, adaptation, model
        self.theta0, self.friction0, self.initial = theta0, friction0, initial
        self.urdf_links, self.estimates_file, self.log = urdf_links, estimates_file, log
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
        self.ctrl.reset(self.theta0, self.friction0)
        response.success = True
        response.message = f"estimates reset to the initial estimates ({self.initial})"
        self.log.info(response.message)
        return response

    def _set_adaptation(self, request, response):
        self.adaptation.freeze(AdaptationFreeze.USER, not request.data)
        response.success = True
        if not request.data:
            response.message = "adaptation frozen: the estimates are held (and still used)"
        elif self.ctrl.adapting:
            response.message = "adaptation resumed"
        else:
            why = {AdaptationFreeze.STARVED: "the starvation guard until the control loop's "
                   "delay recovers", AdaptationFreeze.RECOVERING: "the recovery after a spell "
                   "until the effort is within its limits"}
            response.message = "adaptation: the freeze of set_adaptation is lifted; still " \
                "frozen by " + " and ".join(why[r] for r in sorted(self.adaptation.reasons))
        self.log.info(response.message)
        return response

    def _save(self, request, response):
        path = self.estimates_file()
        if not path:
            response.success = False
            response.message = "estimates_file: not set (set the parameter to a .yaml path)"
            return response
        try:
            yaml_path, urdf, problems = estimates.save(
                path, self.ctrl.theta_hat, self.model.joint_names, self.model.name,
                self.urdf_links, friction=self.ctrl.friction_hat)
        except OSError as err:
            response.success = False
            response.message = f"estimates_file: cannot write {path!r} ({err.strerror})"
            return response
        n = self.model.n
        response.success = True
        response.message = (f"saved the estimates of {n} links to {yaml_path}; URDF inertials "
                            f"of {n - len(problems)} links to {urdf}")
        if problems:
            response.message += "; not physical, left out of the URDF: " + "; ".join(problems)
        self.log.info(response.message)
        return response
