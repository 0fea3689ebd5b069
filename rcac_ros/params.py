"""Every parameter of the two nodes, in one declarative table.

Each :class:`Param` row gives a parameter's name, type, default, range, whether it can be
changed at run time, and its description. The table drives:

the declaration (:func:`rcac_ros.nodes.runtime.base.declare_parameters`); the validation
at start-up and in the on-set callbacks (:func:`check`: one line naming the parameter); the
check of a parameters file (:func:`~rcac_ros.nodes.runtime.paramcheck.check_file_params`);
``doc/parameters.md`` (``python -m rcac_ros.params_doc``).
To add a parameter, add a row here and read it in the node. No rclpy, no compiled kernels.
"""

from dataclasses import dataclass
import math
import re

import numpy as np

from rcac_ros.core.law_options import FRICTION_ADAPTATIONS, FRICTION_FORGETTING
from rcac_ros.core.model import PAPER_GAINS, PRESETS
from rcac_ros.errors import ConfigError
from rcac_ros.plants import ENGINES

#: the ROS parameter types a row may have
TYPES = ("bool", "integer", "double", "string", "double_array", "string_array", "integer_array")

#: upper bound of the "any positive number" ranges
BIG = 1e12


@dataclass(frozen=True)
class Param:
    """One node parameter.

    Parameters
    ----------
    name, type : str
        The ROS name (``paper.period`` is ``paper: {period: ...}`` in YAML); :data:`TYPES`.
    default : object
        The value when the user gives none; ``None``: unset (the node then derives one,
        as said in the description).
    description : str
        One line, with the unit.
    lo, hi : float, optional
        Inclusive range (declared in the descriptor; every entry of an array).
    strict, choices : bool, tuple of str
        The value must also be ``> lo`` (a period, a gain); the values a string may take.
    read_only : bool
        False: may be changed at run time (``ros2 param set``).
    per_joint : bool
        An array of 1 (broadcast) or n values, in the order of ``joints``.
    size : int, optional
        The exact length of an array.
    syntax : callable, optional
        ``syntax(name, value)`` raises :class:`ConfigError` (the syntax of ``channels``, a
        topic name, CPU numbers; what needs the robot is checked at configure).
    """

    name: str
    type: str
    default: object
    description: str
    lo: float = None
    hi: float = None
    strict: bool = False
    choices: tuple = ()
    read_only: bool = True
    per_joint: bool = False
    size: int = None
    syntax: object = None

    @property
    def constraints(self):
        """The ``additional_constraints`` text of the descriptor."""
        parts = []
        if self.choices:
            parts.append(" | ".join(self.choices))
        if self.strict:
            parts.append(f"> {self.lo:g}")
        if self.per_joint:
            parts.append("1 or n values")
        if self.size:
            parts.append(f"{self.size} values")
        return "; ".join(parts)


def _channels_syntax(name, value):
    """The syntax of ``channels`` (the joint numbers are checked against n at configure)."""
    from rcac_ros.core.law_options import parse_channels
    from rcac_ros.errors import GainError
    try:
        parse_channels(list(value), None)
    except GainError as err:
        raise ConfigError(f"{name}: {str(err).partition(': ')[2]}") from None


#: a ROS 2 topic name: absolute, relative or private (``~``, ``~/x``), of tokens of letters,
#: digits, '_' and the substitutions ``{node}``, ``{ns}``, ``{namespace}``, not starting with
#: a digit
_SUB = r"\{(?:node|ns|namespace)\}"
_TOKEN = rf"(?:[A-Za-z_]|{_SUB})(?:\w|{_SUB})*"
TOPIC_NAME = re.compile(rf"~|(?:/|~/)?{_TOKEN}(?:/{_TOKEN})*", re.ASCII)


def _topic_syntax(name, value):
    """Empty, or a valid topic name (rclpy would raise at the subscription)."""
    if value and not TOPIC_NAME.fullmatch(value):
        raise ConfigError(f"{name}: {value!r} is not a valid topic name (tokens of letters, "
                          "digits and '_' not starting with a digit, separated by '/')")


def _cpus_syntax(name, value):
    """CPU numbers are >= 0 (whether the machine has them is best effort, at start)."""
    if any(v < 0 for v in value):
        raise ConfigError(f"{name}: CPU numbers must be >= 0, got {list(value)}")


def _robot(node):
    """The robot description rows both nodes share."""
    order = "effort commands" if node == "controller" else "efforts and joint states"
    return (
        Param("model", "string", "css_arm",
              f"robot model: a preset ({', '.join(PRESETS)}), a YAML model file or a URDF file"),
        Param("robot_description", "string", "",
              "URDF XML string or URDF file path; when set it replaces 'model'"),
        Param("base_link", "string", "", "URDF chain start (empty: the root link)"),
        Param("tip_link", "string", "", "URDF chain end (empty: the single leaf)"),
        Param("gravity", "double_array", None,
              "gravity in the base frame, m/s^2 (unset: the model's own)", size=3),
        Param("joints", "string_array", None,
              f"joint names, in the order of the {order} (unset: the model's)"),
        Param("description_topic", "string", "",
              "take the URDF from this transient-local std_msgs/String topic (e.g. "
              "/robot_description, as robot_state_publisher offers it) and wait for it; "
              "empty: 'robot_description' or 'model'", syntax=_topic_syntax),
    )


def _effort_limit():
    return Param("effort_limit", "double_array", None,
                 "efforts are clipped to +-effort_limit, N m, in joints order (unset: the "
                 "model's)", lo=0.0, hi=math.inf, strict=True, per_joint=True)


def _constraint(name, default, text):
    """``constraints.<name>``: a default tolerance of FollowJointTrajectory goals, >= 0."""
    return Param(f"constraints.{name}", "double", default, f"FollowJointTrajectory: {text}",
                 lo=0.0, hi=BIG)


def _zero_or_more(name, text):
    """A double >= 0 of the adaptation law, 0 by default (what 0 means: in ``text``)."""
    return Param(name, "double", 0.0, text, lo=0.0, hi=BIG)


def _realtime(loop):
    """The rows of a node's opt-in real-time options (:mod:`rcac_ros.nodes.runtime.realtime`);
    ``loop`` names the thread that paces the node."""
    return (
        Param("realtime.priority", "integer", 0,
              f"SCHED_FIFO priority of the {loop}, the process's other threads (DDS, "
              "inputs) one below (best effort, a warning if refused); 0: off", lo=0, hi=99),
        Param("realtime.lock_memory", "bool", False,
              "mlockall the process's memory (best effort)"),
        Param("realtime.cpus", "integer_array", None,
              f"CPU affinity of the {loop} (best effort; unset: any CPU)",
              syntax=_cpus_syntax),
        Param("realtime.cpu_dma_latency", "integer", -1,
              "hold /dev/cpu_dma_latency at this many us while running (0: the shallowest "
              "idle state; best effort); -1: off", lo=-1, hi=100_000),
    )


def _diagnostics_period():
    return Param("diagnostics_period", "double", 1.0, "diagnostics period, s (steady clock)",
                 lo=0.0, hi=3600.0, strict=True)


def _strict_parameters():
    return Param("strict_parameters", "bool", False,
                 "refuse to start on a parameter no row declares or a file gives twice "
                 "(default: a warning naming it, with the nearest name)")


#: The controller node's parameters (``config/controller.yaml``).
CONTROLLER = _robot("controller") + (
    Param("autostart", "bool", True,
          "configure and activate at start-up (false: stay unconfigured until "
          "~/change_state)"),
    Param("mode", "string", "lockstep",
          "timing: 'lockstep' (one step per JointState, simulator) or 'timer' (rate Hz on "
          "the node clock, real arms)", choices=("lockstep", "timer")),
    Param("rate", "double", 1.0 / PAPER_GAINS["h"],
          "control rate, Hz (h = 1/rate; in lockstep it must match the simulator's dt)",
          lo=1.0, hi=1e5),
    Param("K_D", "double", PAPER_GAINS["K_D"], "link feedback gain K_Di = K_D I6 (eq 19)",
          lo=0.0, hi=BIG, strict=True),
    Param("Lambda", "double", PAPER_GAINS["Lambda"], "Lambda of eq 18, 1/s",
          lo=0.0, hi=BIG, strict=True),
    Param("P", "double", PAPER_GAINS["P"], "adaptation gain P_i = P I13 (eq 24)",
          lo=0.0, hi=BIG, strict=True),
    Param("gamma", "double", PAPER_GAINS["gamma"],
          "weight of the prediction error (eq 24); 0 = direct adaptive law", lo=0.0, hi=BIG),
    Param("lambda", "double", PAPER_GAINS["lam"],
          "bandwidth of the filter lambda/(p+lambda), rad/s", lo=0.0, hi=BIG, strict=True),
    # prediction channels, discretisation, least squares, robust adaptation (doc/nodes.md,
    # "Choosing the prediction channels"; doc/design.md §6)
    Param("channels", "string_array", ("1",),
          "predicted filtered torques (eqs 21-24): joint numbers (1-based) and 'power', or "
          "['all'] (= 1..n, Slotine-Li's information); ['1'] is the paper's law; "
          "doc/nodes.md", syntax=_channels_syntax),
    Param("update", "string", "implicit",
          "discretisation of the prediction-error term: 'implicit' (backward Euler, stable "
          "for any gain) or 'explicit' (forward Euler)", choices=("implicit", "explicit")),
    Param("adaptation", "string", "gradient",
          "adaptation gain: 'gradient' (P_i fixed, the paper's), 'least_squares' (bounded-"
          "gain forgetting) or 'least_squares_prediction' (least squares on E only)",
          choices=("gradient", "least_squares", "least_squares_prediction")),
    _zero_or_more("forgetting",
                  "least squares: forgetting rate lambda_0 of the bounded-gain forgetting, 1/s"),
    Param("P_max", "double", None,
          "least squares: bound k_0 on every trace(P_i) (unset: each link's trace(P_i(0)))",
          lo=0.0, hi=BIG, strict=True),
    _zero_or_more("dead_zone_s", "no adaptation from the tracking term while max_j |qd_j - "
                  "qd_rj| <= this, rad/s (0: no dead zone)"),
    _zero_or_more("dead_zone_E", "no adaptation from channel c while |E_c| <= this (N m; W "
                  "for 'power'; 0: no dead zone)"),
    Param("theta_bounds", "string", "none",
          "projection of theta_hat after each step: 'none' or 'mass' (every link mass >= 0)",
          choices=("none", "mass")),
    _zero_or_more("leakage", "sigma_0 of the leakage -P_i sigma_i (theta_hat_i - theta_0i) "
                  "toward the initial estimates (sigma-modification; bounds the estimates "
                  "under sensor noise; needs h * leakage * lambda_max(P) < 1; 0: none)"),
    _zero_or_more("leakage_bound", "M_0 of the switching leakage (every link): none while "
                  "||theta_hat_i - theta_0i|| <= M_0, full beyond 2 M_0 (0: leak always)"),
    Param("geometry", "string", "euclidean",
          "adaptation geometry: 'euclidean' (eq 24 as written) or 'natural' (every link's "
          "estimates stay a physical body at every step, pseudo-inertia J > 0; with "
          "adaptation 'gradient' or 'least_squares'; doc/design.md §8)",
          choices=("euclidean", "natural")),
    Param("natural_gain", "double", None,
          "geometry 'natural': gain k_i of every link (unset: matched to P at the start, "
          "doc/design.md §8)", lo=0.0, hi=BIG, strict=True),
    Param("natural_metric", "string", "auto",
          "geometry 'natural': 'barrier' (the barrier -log det J plus the Euclidean quadratic: "
          "a gain never above P), 'log_det' (k_i times the inverse Hessian of -log det J) or "
          "'auto' ('barrier' with adaptation 'gradient', 'log_det' with 'least_squares'; "
          "doc/design.md §8)", choices=("auto", "barrier", "log_det")),
    Param("barrier_c", "double", None,
          "natural_metric 'barrier': c, the quadratic's curvature over the barrier's at the "
          "start (unset: 1000, doc/design.md §8)", lo=1e-6, hi=BIG),
    Param("joint_friction", "bool", False,
          "also estimate each joint's armature, viscous and Coulomb friction "
          "(doc/design.md §7), published on ~/friction_estimates"),
    Param("P_friction", "double_array", None,
          "adaptation gains of the joint terms (armature, damping, friction), 3 values > 0 "
          "(unset: each joint's scaled from its feedback at the first state, growing with "
          "its rotor, doc/design.md §7)"),
    Param("friction_adaptation", "string", "gradient",
          "gain of the joint terms: 'gradient' (P_friction fixed) or 'least_squares' (from "
          "P_friction down, geometry 'euclidean'; doc/design.md §7)",
          choices=FRICTION_ADAPTATIONS),
    Param("hold_compensation", "bool", False,
          "extrapolate eq 20's model torque m (feedback excluded) to the middle of the period "
          "the effort is held for, tau_k + (m_k - m_k-1) / 2: removes the hold's half-period "
          "lag (doc/design.md §6)"),
    Param("friction_forgetting", "double", FRICTION_FORGETTING,
          "friction_adaptation 'least_squares': forgetting rate lambda_0, 1/s",
          lo=0.0, hi=BIG),
    Param("trajectory", "string", "paper",
          "desired motion: 'paper' (built-in Section 4 motion) or 'topic' (~/joint_trajectory)",
          choices=("paper", "topic")),
    Param("paper.reading", "string", "velocity",
          "reading of the paper's motion: 'velocity' or 'position'",
          choices=("velocity", "position")),
    Param("paper.amplitude", "double", 5.0 * math.pi / 180.0, "amplitude A (rad/s or rad)",
          lo=0.0, hi=BIG),
    Param("paper.period", "double", 20.0, "period of the paper's motion, s",
          lo=0.0, hi=BIG, strict=True),
    Param("paper.q0", "double_array", None,
          "start of the paper's motion, rad (unset: the first state received)", per_joint=True),
    Param("state_timeout", "double", 0.02,
          "watchdog: safe effort after this long without a valid state (steady clock), s",
          lo=0.0, hi=1.0, strict=True, read_only=False),
    Param("watchdog.replan_after", "double", 0.5,
          "after this long of safe effort (the arm not controlled), control resumes with the "
          "motion restarted from the measured state (a followed trajectory is aborted), s",
          lo=0.0, hi=BIG),
    Param("safe_effort", "double_array", None,
          "effort sent by the watchdog, N m, in joints order (unset: zero)", per_joint=True),
    _effort_limit(),
    Param("velocity_filter_cutoff", "double", 50.0,
          "cut-off of the velocity estimate used when JointState has no velocities, Hz",
          lo=0.0, hi=BIG, strict=True),
    Param("monitor_decimation", "integer", 1, "publish estimates and errors every k-th step",
          lo=1, hi=1_000_000, read_only=False),
    # the defaults of FollowJointTrajectory goals (JTC's constraints, one value for all joints)
    _constraint("trajectory", 0.0, "default path position tolerance, rad (0: not checked)"),
    _constraint("goal", 0.0, "default goal position tolerance, rad (0: not checked)"),
    _constraint("stopped_velocity_tolerance", 0.01,
                "default goal velocity tolerance, rad/s (0: not checked)"),
    _constraint("goal_time", 0.0, "default goal_time_tolerance, s (0: no time limit)"),
    Param("initial_estimates", "string", "zero",
          "theta_hat(0): 'zero' (the paper's), 'model' (the model's own parameters), "
          "'nominal' (the model made a body and halved, doc/design.md §8) or the path of a "
          "file written by ~/save_estimates; with geometry 'natural' 'zero' (not a body) "
          "means 'nominal'"),
    Param("estimates_file", "string", "",
          "~/save_estimates writes the estimates here (YAML), and the physically consistent "
          "links as URDF inertials next to it (.inertial.urdf)", read_only=False),
    _diagnostics_period(),
    # fail-safe (doc/failsafe.md): rcac_ros.nodes.safety.guards, .state_guards, .realtime
    Param("max_state_bytes", "integer", 65_536,
          "JointStates larger than this (serialised) are refused before deserialising, "
          "bytes; 0: no cap", lo=0, hi=2 ** 31 - 1),
    Param("max_trajectory_bytes", "integer", 1_048_576,
          "JointTrajectories larger than this (serialised) are refused before deserialising, "
          "bytes; 0: no cap", lo=0, hi=2 ** 31 - 1),
    Param("stamp.max_jump", "double", 1.0,
          "a state stamp further ahead of the last accepted one than the steady time elapsed "
          "plus this is refused, s", lo=0.0, hi=BIG, strict=True),
    Param("stamp.restart_count", "integer", 10,
          "this many consecutive consistent states that the last accepted stamp refuses (a "
          "restart, a clock jump) replace it, even before the watchdog trips", lo=1,
          hi=1_000_000),
    Param("desired.max_position_step", "double", 0.01,
          "the desired position moves at most this much per control period, rad (its "
          "velocity is bounded by this / h)", lo=0.0, hi=BIG, strict=True),
    Param("desired.max_velocity_step", "double", 1.0,
          "the desired velocity changes at most this much per control period, rad/s",
          lo=0.0, hi=BIG, strict=True),
    *_realtime("control thread"),
    Param("timer.lookahead", "double", None,
          "timer mode: predict the state this long beyond its age at the tick, from the "
          "model and the effort being applied (RK4), s; unset: no prediction (the effort "
          "answers a state up to a period old)", lo=0.0, hi=1.0),
    Param("timer.phase_offset", "double", None,
          "timer mode on the steady clock: lock the ticks to this long after each joint "
          "state's arrival, s (a phase-locked loop: the state waits for the tick at most "
          "this long instead of up to a period); unset: the ticks keep their own phase",
          lo=0.0, hi=1.0),
    Param("starvation.delay_margin", "double", None,
          "timer mode: past this smoothed delay (state age plus the previous effort held "
          "beyond a period) K_D is scaled down by margin/delay and adaptation frozen until "
          "the delay has stayed within it for starvation.recover_after, s; unset: "
          "derived at configure from the model and the gains, at paper.q0 (or the zero "
          "position): phase margin / crossover of the feedback's most delay-sensitive "
          "mode, less h/2 (doc/failsafe.md, section Delay margin per arm); 0: no guard",
          lo=0.0, hi=1.0),
    Param("starvation.recover_after", "double", 1.0,
          "the smoothed delay stays within the margin this long before the nominal gains "
          "and adaptation return, s", lo=0.0, hi=BIG),
    Param("starvation.min_scale", "double", 0.02,
          "the smallest scale of K_D the starvation guard applies", lo=0.0, hi=1.0,
          strict=True),
    _strict_parameters(),
)

#: per-joint gain overrides of the controller: ``gains.<joint>.<gain>`` (JTC style)
GAINS_PREFIX = "gains."


def gain_override(name):
    """The row of a per-joint gain override ``gains.<joint>.<gain>`` (the gain's own range)."""
    gain = name.rpartition(".")[2]
    return Param(name, "double", None, f"per-joint override of {gain} (the link moved by "
                 "that joint for K_D and P)", lo=0.0, hi=BIG, strict=True)


#: The simulator node's parameters (``config/simulator.yaml``).
SIMULATOR = _robot("simulator") + (
    Param("mode", "string", "lockstep",
          "'lockstep' (step when the effort for the last state arrives) or 'realtime' "
          "(steady-clock timer)", choices=("lockstep", "realtime")),
    Param("dt", "double", PAPER_GAINS["h"], "integration (and control) period, s",
          lo=0.0, hi=10.0, strict=True),
    Param("engine", "string", ENGINES[0],
          "the plant: 'builtin' (the package's own dynamics, RK4) or 'mujoco' (the same arm "
          "in MuJoCo, joint friction as MuJoCo's friction loss; needs the mujoco package); "
          "doc/plants.md", choices=ENGINES),
    Param("substeps", "integer", 1, "integrator steps per dt (RK4 on both engines)",
          lo=1, hi=1000),
    Param("duration", "double", 0.0,
          "stop (exit 0) after this much sim time, s; 0 = run forever", lo=0.0, hi=1e9),
    Param("lockstep_timeout", "double", 0.5,
          "lockstep: wait this long (wall time) for the effort, then hold the previous one "
          "and count a miss, s", lo=0.0, hi=3600.0, strict=True),
    Param("lockstep_max_speed", "double", 0.0,
          "lockstep: at most this many times real time (wall clock), so that a recorder "
          "keeps up; 0 = as fast as the controller answers", lo=0.0, hi=1e6),
    Param("wait_for_controller", "bool", True,
          "start only once a node subscribes to joint_states and publishes efforts"),
    Param("min_subscribers", "integer", 1,
          "with wait_for_controller: also wait for this many joint_states subscribers "
          "(2: the controller and a recorder)", lo=1, hi=1000),
    Param("q0", "double_array", None,
          "initial positions, rad, in joints order (unset: the paper's q0 for css_arm, "
          "else zero)", per_joint=True),
    Param("qd0", "double_array", None,
          "initial velocities, rad/s, in joints order (unset: zero)", per_joint=True),
    Param("position_noise", "double", 0.0,
          "std dev of the noise added to published positions, rad", lo=0.0, hi=1e6),
    Param("velocity_noise", "double", 0.0,
          "std dev of the noise added to published velocities, rad/s", lo=0.0, hi=1e6),
    Param("noise_seed", "integer", 0, "seed of the measurement noise", lo=0, hi=2 ** 31 - 1),
    Param("publish_velocity", "bool", True,
          "fill JointState.velocity (false: positions only)"),
    _effort_limit(),
    # a payload held by the last link (doc/nodes.md, "Payload"; rcac_ros/core/payload.py)
    Param("payload.mass", "double", 0.0,
          "mass of a payload held by the last link, kg, finite and >= 0; 0: none (setting it "
          "at run time is a capture, 0 a release: the plant changes at the next step)",
          read_only=False),
    Param("payload.com", "double_array", (0.0, 0.0, 0.0),
          "the payload's centre of mass in the last link's frame, m (within the arm's length "
          "of that frame's origin)", size=3, read_only=False),
    Param("payload.inertia", "double_array", (0.0,) * 6,
          "the payload's inertia about its centre of mass, last link's axes, kg m^2: Ixx Iyy "
          "Izz Ixy Ixz Iyz (a body: positive semi-definite, I1 + I2 >= I3; zeros: a point "
          "mass)", size=6, read_only=False),
    *_realtime("stepping thread"),
    _diagnostics_period(),
    _strict_parameters(),
)

#: node -> its rows
TABLE = {"controller": CONTROLLER, "simulator": SIMULATOR}


def row(node, name):
    """The row of ``name`` in ``node``'s table (``KeyError`` if there is none)."""
    for p in TABLE[node]:
        if p.name == name:
            return p
    raise KeyError(f"{node}: no parameter {name!r}")


def _type_ok(kind, value):
    if kind == "bool":
        return isinstance(value, bool)
    if kind == "integer":
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == "double":
        return isinstance(value, float)
    if kind == "string":
        return isinstance(value, str)
    element = {"double_array": float, "string_array": str, "integer_array": int}[kind]
    return isinstance(value, (list, tuple)) and all(
        isinstance(v, element) and not isinstance(v, bool) for v in value)


def check(p, value):
    """Validate ``value`` against row ``p``; return it (arrays as tuples).

    ``None`` is accepted for a row without default (unset).

    Raises
    ------
    ConfigError
        One line starting with the parameter's name.
    """
    if value is None and p.default is None:
        return None
    if not _type_ok(p.type, value):
        raise ConfigError(f"{p.name}: wrong type, expected {p.type}, got {value!r}")
    if p.type.endswith("_array"):
        value = tuple(value)
        if p.size is not None and len(value) != p.size:
            raise ConfigError(f"{p.name}: expected {p.size} values, got {len(value)}")
        if p.type == "double_array":
            if not all(math.isfinite(v) for v in value):
                raise ConfigError(f"{p.name}: contains NaN or Inf")
            if p.lo is not None and not all(_in_range(p, v) for v in value):
                bound = ">" if p.strict else ">="
                raise ConfigError(f"{p.name}: every value must be {bound} {p.lo:g}, got "
                                  f"{list(value)}")
        if p.syntax is not None:
            p.syntax(p.name, value)
        return value
    if p.type == "double" and not math.isfinite(value):
        raise ConfigError(f"{p.name}: must be finite, got {value}")
    if p.lo is not None and not p.lo <= value <= p.hi:
        raise ConfigError(out_of_range(p))
    if p.strict and not value > p.lo:
        raise ConfigError(f"{p.name}: must be > {p.lo:g}, got {value}")
    if p.choices and value not in p.choices:
        raise ConfigError(f"{p.name}: must be {' or '.join(repr(c) for c in p.choices)}, "
                          f"got {value!r}")
    if p.syntax is not None:
        p.syntax(p.name, value)
    return value


def out_of_range(p):
    """The message of a value of row ``p`` outside ``[lo, hi]`` (integers in full)."""
    fmt = "d" if p.type == "integer" else "g"
    return f"{p.name}: value out of range [{p.lo:{fmt}}, {p.hi:{fmt}}]"


def _in_range(p, v):
    return (v > p.lo if p.strict else v >= p.lo) and (p.hi is None or v <= p.hi)


def per_joint(name, value, n, default):
    """A checked per-joint array: 1 (broadcast) or ``n`` values; ``default`` if unset.

    Returns
    -------
    ndarray, shape (n,), or None (unset without default)
    """
    if value is None:
        return None if default is None else np.array(np.broadcast_to(default, (n,)), float)
    arr = np.asarray(list(value), dtype=float)
    if arr.size == 1:
        arr = np.full(n, arr[0])
    if arr.shape != (n,):
        raise ConfigError(f"{name}: expected 1 or {n} values (one per joint), got {len(value)}")
    return arr


def flatten(params, prefix=""):
    """``(dotted name, value)`` of every leaf of a nested ``ros__parameters`` mapping."""
    for key, value in params.items():
        if isinstance(value, dict):
            yield from flatten(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value
