"""The controller's parameters, read at configure (rows of :data:`rcac_ros.params.CONTROLLER`).

Sets the node's attributes: orders, timing, desired motion, limits, the gains with their
per-joint overrides ``gains.<joint>.<gain>`` (:mod:`rcac_ros.nodes.controller.gains`), the initial
estimates (:mod:`rcac_ros.nodes.controller.estimates`) and the core controller.
"""

import numpy as np

from rcac_ros import params
from rcac_ros.core.channels import parse_channels
from rcac_ros.core.composite import RecursiveCompositeController
from rcac_ros.errors import ConfigError, RcacError
from rcac_ros.nodes.runtime.base import declare
from rcac_ros.nodes.runtime.rclpy_private import parameter_overrides
from rcac_ros.nodes.controller.estimates import (initial_estimates, initial_joint_terms,
                                                 urdf_child_links)
from rcac_ros.nodes.fjt.tolerances import Tolerances
from rcac_ros.nodes.controller.gains import parse_overrides, per_joint_gains


def read_parameters(node, v):
    """Apply the checked values ``v`` (name -> value) to the controller ``node``; build its
    core controller (``node.ctrl``) and warm its kernels up.

    Raises
    ------
    ConfigError
        Naming the parameter (an unknown joint in ``gains.<joint>.<gain>``, a bad
        ``initial_estimates`` file, gains the core refuses).
    """
    n = node.model.n
    node._out = np.array([node.model.joint_names.index(j) for j in node.joints])
    node._order = np.array([node.joints.index(j) for j in node.model.joint_names])
    node.mode = v["mode"]
    node.h = 1.0 / v["rate"]
    node.trajectory_source = v["trajectory"]
    node.paper = None if v["trajectory"] != "paper" else dict(
        reading=v["paper.reading"], amplitude=v["paper.amplitude"], period=v["paper.period"])
    q0 = params.per_joint("paper.q0", v["paper.q0"], n, None)
    node.paper_q0 = None if q0 is None else q0[node._order]   # joints -> model order
    node.state_timeout = v["state_timeout"]
    limit = params.per_joint("effort_limit", v["effort_limit"], n, None)
    node.effort_limit = (node.model.effort_limit.copy() if limit is None
                         else limit[node._order])
    node.safe_effort = np.clip(params.per_joint("safe_effort", v["safe_effort"], n, 0.0),
                               -node.effort_limit[node._out], node.effort_limit[node._out])
    node.velocity_cutoff = v["velocity_filter_cutoff"]
    node.tolerances = Tolerances(
        path_position=v["constraints.trajectory"], goal_position=v["constraints.goal"],
        stopped_velocity=v["constraints.stopped_velocity_tolerance"],
        goal_time=v["constraints.goal_time"])
    node.publish_every = v["monitor_decimation"]
    gains = per_joint_gains(v, _gain_overrides(node), node.model.joint_names)
    spec = v["initial_estimates"]
    if v["geometry"] == "natural" and spec == "zero":   # not a body: doc/design.md §8
        spec = "nominal"
    node.theta0 = initial_estimates(spec, node.model)
    node.friction0 = initial_joint_terms(v["initial_estimates"], node.model) \
        if v["joint_friction"] else None
    node.urdf_links = urdf_child_links(node._description or v["robot_description"],
                                       node.model.joint_names)
    try:
        channels = parse_channels(list(v["channels"]), n)
    except RcacError as err:            # already "channels: ..."
        raise ConfigError(str(err)) from None
    try:
        node.ctrl = RecursiveCompositeController(
            node.model, K_D=gains["K_D"], Lambda=gains["Lambda"], P=gains["P"],
            gamma=v["gamma"], lam=v["lambda"], h=node.h, theta_hat0=node.theta0,
            joint_friction=v["joint_friction"], friction_hat0=node.friction0,
            P_friction=list(v["P_friction"]), **adaptation_options(v, channels))
    except RcacError as err:
        raise ConfigError(f"gains: {err}") from None
    node.channel_names = channel_names(channels)
    z = np.zeros(n)             # warm up: one compiled step, so the first real one is not slow
    node.ctrl.step(z, z, z, z, z)
    node.ctrl.reset(node.theta0, node.friction0)


def adaptation_options(v, channels):
    """The core controller's adaptation options from the checked parameters ``v``
    (doc/nodes.md, "Parameters")."""
    return dict(channels=channels, update=v["update"], adaptation=v["adaptation"],
                forgetting=v["forgetting"], P_max=v["P_max"], dead_zone_s=v["dead_zone_s"],
                dead_zone_E=v["dead_zone_E"],
                theta_bounds=None if v["theta_bounds"] == "none" else v["theta_bounds"],
                leakage=v["leakage"], leakage_bound=v["leakage_bound"],
                geometry=v["geometry"], natural_gain=v["natural_gain"])


def channel_names(channels):
    """The label of each prediction channel: ``joint<k>`` (the model's k-th joint) or
    ``power``; the order of ``E``."""
    return tuple("power" if c == "power" else f"joint{c}" for c in channels)


def _gain_overrides(node):
    """``gains.<joint>.<gain>`` given to the node (JTC style): declared and checked."""
    names = [k for k in parameter_overrides(node) if k.startswith(params.GAINS_PREFIX)]
    values = {name: declare(node, params.gain_override(name)) for name in names}
    return parse_overrides(values, node.model.joint_names)
