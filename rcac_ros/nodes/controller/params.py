"""The controller's parameters, read at configure (rows of :data:`rcac_ros.params.CONTROLLER`).

:func:`read_parameters` turns the checked values into a frozen :class:`ControllerConfig`
(orders, timing, desired motion, limits, the initial estimates
(:mod:`rcac_ros.nodes.controller.estimates`)) and the core controller, with the gains and
their per-joint overrides ``gains.<joint>.<gain>`` (:mod:`rcac_ros.nodes.controller.gains`).
The node keeps both; nothing here sets anything on it.
"""

import dataclasses
from types import MappingProxyType

import numpy as np

from rcac_ros import params
from rcac_ros.core.channels import parse_channels
from rcac_ros.core.composite import RecursiveCompositeController
from rcac_ros.core.joint_friction import P_FRICTION
from rcac_ros.errors import ConfigError, RcacError
from rcac_ros.nodes.runtime.base import declare, joint_order
from rcac_ros.nodes.runtime.rclpy_private import parameter_overrides
from rcac_ros.nodes.controller.estimates import (initial_estimates, initial_joint_terms,
                                                 urdf_child_links)
from rcac_ros.nodes.fjt.tolerances import Tolerances
from rcac_ros.nodes.controller.gains import parse_overrides, per_joint_gains


@dataclasses.dataclass(frozen=True, eq=False)
class ControllerConfig:
    """The controller's parameters as the node uses them (doc/nodes.md, "Parameters").

    Frozen, its arrays read-only (copies of what it is given). The run-time parameters
    (``state_timeout``, ``monitor_decimation``) take effect as a new config
    (:meth:`changed`). Arrays are in the model's joint order unless said.
    """

    mode: str                   #: ``lockstep`` or ``timer``
    h: float                    #: the control period, s (``1 / rate``)
    out: np.ndarray             #: model -> message (``joints``) order (:func:`joint_order`)
    order: np.ndarray           #: message -> model order
    trajectory_source: str      #: ``paper`` or ``topic`` (``trajectory``)
    paper: object               #: the paper's motion (keywords of PaperTrajectory), or None
    paper_q0: object            #: its start ``paper.q0``, ndarray (n,), or None (measured)
    state_timeout: float        #: s without a valid state before the safe effort
    effort_limit: np.ndarray    #: (n,) |tau| bound
    safe_effort: np.ndarray     #: (n,) the watchdog's effort, message order, within limits
    velocity_cutoff: float      #: ``velocity_filter_cutoff``, Hz
    tolerances: Tolerances      #: FollowJointTrajectory's defaults (``constraints.*``)
    publish_every: int          #: monitors every this many steps (``monitor_decimation``)
    theta0: np.ndarray          #: (n, 13) the initial estimates
    friction0: object           #: (n, 3) the joint terms' initial estimates, or None
    urdf_links: object          #: (links, rotations) of the URDF, or None (estimates.save)
    channel_names: tuple        #: the label of each prediction channel, the order of ``E``
    phase_offset_ns: object     #: timer mode's ``timer.phase_offset`` in ns, or None

    def __post_init__(self):
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, np.ndarray):
                object.__setattr__(self, field.name, _frozen(value))
        if self.paper is not None:
            object.__setattr__(self, "paper", MappingProxyType(dict(self.paper)))
        if self.urdf_links is not None:
            links, rotations = self.urdf_links
            object.__setattr__(self, "urdf_links",
                               (tuple(links), tuple(_frozen(r) for r in rotations)))

    def changed(self, parameters):
        """This config with the run-time parameters among ``parameters`` (checked rclpy
        Parameters: ``state_timeout``, ``monitor_decimation``) applied."""
        update = {}
        for p in parameters:
            if p.name == "state_timeout":
                update["state_timeout"] = float(p.value)
            elif p.name == "monitor_decimation":
                update["publish_every"] = int(p.value)
        return dataclasses.replace(self, **update) if update else self


def _frozen(arr):
    """A read-only copy of ``arr``."""
    arr = np.array(arr)
    arr.flags.writeable = False
    return arr


def read_parameters(node, v):
    """The configuration and the core controller of the controller ``node`` (its ``model``,
    ``joints``, ``description`` and its ``gains.<joint>.<gain>`` overrides) from the checked
    values ``v`` (name -> value). Nothing is compiled here
    (:class:`~rcac_ros.nodes.controller.compiling.KernelWarmup` does it next).

    Returns
    -------
    config : ControllerConfig
    ctrl : RecursiveCompositeController

    Raises
    ------
    ConfigError
        Naming the parameter (an unknown joint in ``gains.<joint>.<gain>``, a bad
        ``initial_estimates`` file, gains the core refuses).
    """
    model = node.model
    n = model.n
    out, order = joint_order(model, node.joints)
    h = 1.0 / v["rate"]
    paper = None if v["trajectory"] != "paper" else dict(
        reading=v["paper.reading"], amplitude=v["paper.amplitude"], period=v["paper.period"])
    q0 = params.per_joint("paper.q0", v["paper.q0"], n, None)
    paper_q0 = None if q0 is None else q0[order]   # joints -> model order
    limit = params.per_joint("effort_limit", v["effort_limit"], n, None)
    effort_limit = model.effort_limit.copy() if limit is None else limit[order]
    safe_effort = np.clip(params.per_joint("safe_effort", v["safe_effort"], n, 0.0),
                          -effort_limit[out], effort_limit[out])
    tolerances = Tolerances(
        path_position=v["constraints.trajectory"], goal_position=v["constraints.goal"],
        stopped_velocity=v["constraints.stopped_velocity_tolerance"],
        goal_time=v["constraints.goal_time"])
    gains = per_joint_gains(v, _gain_overrides(node), model.joint_names)
    spec = v["initial_estimates"]
    if v["geometry"] == "natural" and spec == "zero":   # not a body: doc/design.md §8
        spec = "nominal"
    theta0 = initial_estimates(spec, model)
    friction0 = initial_joint_terms(v["initial_estimates"], model) \
        if v["joint_friction"] else None
    urdf_links = urdf_child_links(node.description or v["robot_description"],
                                  model.joint_names)
    offset = v["timer.phase_offset"]
    if offset is not None and offset >= h:
        raise ConfigError(f"timer.phase_offset: must be < one period ({h:g} s), got {offset:g}")
    try:
        channels = parse_channels(list(v["channels"]), n)
    except RcacError as err:            # already "channels: ..."
        raise ConfigError(str(err)) from None
    config = ControllerConfig(
        mode=v["mode"], h=h, out=out, order=order, trajectory_source=v["trajectory"],
        paper=paper, paper_q0=paper_q0, state_timeout=v["state_timeout"],
        effort_limit=effort_limit, safe_effort=safe_effort,
        velocity_cutoff=v["velocity_filter_cutoff"], tolerances=tolerances,
        publish_every=v["monitor_decimation"], theta0=theta0, friction0=friction0,
        urdf_links=urdf_links, channel_names=channel_names(channels),
        phase_offset_ns=None if offset is None else round(offset * 1e9))
    try:
        ctrl = RecursiveCompositeController(
            model, K_D=gains["K_D"], Lambda=gains["Lambda"], P=gains["P"],
            gamma=v["gamma"], lam=v["lambda"], h=h, theta_hat0=config.theta0,
            joint_friction=v["joint_friction"], friction_hat0=config.friction0,
            P_friction=P_FRICTION if v["P_friction"] is None else list(v["P_friction"]),
            **adaptation_options(v, channels))
    except RcacError as err:
        raise ConfigError(str(err)) from None       # names its parameter
    for name, needs in inert_options(v):
        node.get_logger().warning(f"{name}: {v[name]} changes nothing without {needs}")
    return config, ctrl


def adaptation_options(v, channels):
    """The core controller's adaptation options from the checked parameters ``v``
    (doc/nodes.md, "Parameters")."""
    return dict(channels=channels, update=v["update"], adaptation=v["adaptation"],
                forgetting=v["forgetting"], P_max=v["P_max"], dead_zone_s=v["dead_zone_s"],
                dead_zone_E=v["dead_zone_E"],
                theta_bounds=None if v["theta_bounds"] == "none" else v["theta_bounds"],
                leakage=v["leakage"], leakage_bound=v["leakage_bound"],
                geometry=v["geometry"], natural_gain=v["natural_gain"],
                natural_metric=None if v["natural_metric"] == "auto" else v["natural_metric"],
                barrier_c=v["barrier_c"], friction_adaptation=v["friction_adaptation"],
                friction_forgetting=v["friction_forgetting"],
                hold_compensation=v["hold_compensation"])


def _least_squares(v):
    return v["adaptation"].startswith("least_squares")


#: options that act only with others: (name, whether it acts, under what); a value other than
#: its default given where it does not act is named in one warning (it changes nothing)
INERT = (
    ("forgetting", _least_squares, "adaptation 'least_squares*'"),
    ("P_max", _least_squares, "adaptation 'least_squares*'"),
    ("P_friction", lambda v: v["joint_friction"], "joint_friction"),
    ("friction_forgetting", lambda v: v["joint_friction"]
     and v["friction_adaptation"] == "least_squares",
     "joint_friction and friction_adaptation 'least_squares'"),
    ("timer.lookahead", lambda v: v["mode"] == "timer", "mode 'timer'"),
    ("timer.phase_offset", lambda v: v["mode"] == "timer", "mode 'timer'"),
)


def inert_options(v):
    """The ``(name, under what it acts)`` of each option of :data:`INERT` that ``v`` (the
    checked values) sets off its default where it does not act."""
    default = {p.name: p.default for p in params.CONTROLLER}
    return [(name, needs) for name, acts, needs in INERT
            if v[name] != default[name] and not acts(v)]


def channel_names(channels):
    """The label of each prediction channel: ``joint<k>`` (the model's k-th joint) or
    ``power``; the order of ``E``."""
    return tuple("power" if c == "power" else f"joint{c}" for c in channels)


def _gain_overrides(node):
    """``gains.<joint>.<gain>`` given to the node (JTC style): declared and checked."""
    names = [k for k in parameter_overrides(node) if k.startswith(params.GAINS_PREFIX)]
    values = {name: declare(node, params.gain_override(name)) for name in names}
    return parse_overrides(values, node.model.joint_names)
