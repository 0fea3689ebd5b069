"""Monte Carlo campaign files: the schema, its validation, the sampling and one run.

A campaign (YAML, see ``doc/campaigns.md``) is a ``scenario`` (the fixed part) and
``vary`` (the distributions or grids of the varied quantities)::

    name: robustness
    seed: 2026
    samples: 100            # random draws per grid cell
    scenario:
      model: css_arm        # css_arm | panda
      law: composite        # direct | composite | slotine_li
      trajectory: {type: paper, reading: velocity}
      duration: 5.0
      engine: builtin       # builtin | mujoco: the plant (doc/plants.md)
      gains: {K_D: 1.0e4, Lambda: 1.0, P: 100.0, gamma: 0.1, lam: 10.0, h: 0.002}
    vary:
      noise_q: {uniform: {low: 0.0, high: 1.0e-4}}
      delay: {choice: [0, 1, 2]}
      K_D: {normal: {mean: 1.0e4, std: 2.0e3, low: 1.0e3}}
      law: {grid: [direct, composite]}

Runs: the grids make a Cartesian product of cells; run ``i`` is in cell
``i % cells`` and its random draws come from ``numpy.random.default_rng([seed, i, 0])``
(inputs) and ``[seed, i, 1]`` (sensor noise, initial-estimate error), so every run
is reproducible from (campaign, index) alone, whatever ran before it or where. With
``paired: true`` the draws come from ``[seed, i // cells, 0]`` and ``[seed, i // cells,
1]`` instead: the runs of one sample draw the same inputs in every grid cell (a paired
comparison of the grid's values).
"""

import copy
import functools
import itertools
import json
import math
import time

import numpy as np

from rcac_ros.core import PAPER_GAINS, PAPER_Q0, PaperTrajectory, SinusoidTrajectory, css_arm
from rcac_ros.core.law_options import BARRIER_C
from rcac_ros.core.model import theta_from_inertia
from rcac_ros.errors import ConfigError, read_yaml
from rcac_ros.plants import check_engine, ENGINES
from rcac_ros.tools.closed_loop import (attach_payload, closed_loop, perturbed_estimates,
                                        run_metrics)
from rcac_ros.tools.scenarios import (AMPLITUDE, controller, FREQUENCY, gains_for, load_panda,
                                      READY)
from rcac_ros.tools.scenarios import GAINS as PANDA_GAINS

LAWS = ("direct", "composite", "slotine_li", "composite_friction")
#: the law's geometry (doc/design.md §8): "natural" is the natural geometry with its default
#: metric (the barrier), "natural_log_det" and "natural_barrier" name the metric
GEOMETRIES = ("euclidean", "natural", "natural_log_det", "natural_barrier")
#: The columns that differ from one execution of a run to the next (everything else is equal).
TIMING = ("wall_time_s", "cpu_time_s")
MODELS = ("css_arm", "panda", "ur5", "xarm7")
DISTRIBUTIONS = ("normal", "uniform", "loguniform", "choice", "grid")

#: quantity -> (kind, size): kind "float" (>= 0 unless in POSITIVE), "int" (>= 0),
#: "law", "channels"; size 1 or 3 (a vector, columns _x _y _z or _xx _yy _zz).
QUANTITIES = {
    "law": ("law", 1),
    "geometry": ("geometry", 1),
    "K_D": ("float", 1), "Lambda": ("float", 1), "P": ("float", 1), "gamma": ("float", 1),
    "lam": ("float", 1),
    "channels": ("channels", 1),
    "noise_q": ("float", 1), "noise_qd": ("float", 1),
    "delay": ("int", 1),
    "payload_mass": ("float", 1), "payload_com": ("signed", 3),
    "payload_inertia": ("float", 3),
    "estimate_error": ("float", 1),
    "start_mass_scale": ("float", 1), "start_com_shift": ("signed", 3),
    "trajectory_scale": ("float", 1),
    # the plant's joint terms, per joint (doc/design.md §7), and the gain of the joint
    # estimates of composite_friction
    "joint_damping": ("float", 7), "joint_friction": ("float", 7), "joint_armature": ("float", 7),
    "P_friction": ("float", 1),     # absent: the library's default (doc/design.md §7)
    # c of the barrier metric (geometries natural and natural_barrier, doc/design.md §8)
    "barrier_c": ("float", 1),
}
#: Quantities drawn once per sample, the same in every grid cell (paired comparisons).
PAIRED = ("joint_damping", "joint_friction", "joint_armature")
POSITIVE = ("K_D", "Lambda", "P", "lam", "trajectory_scale", "P_friction", "start_mass_scale",
            "barrier_c")
GAINS = ("K_D", "Lambda", "P", "gamma", "lam", "h")
SUFFIXES = {"payload_com": ("x", "y", "z"), "payload_inertia": ("xx", "yy", "zz"),
            "start_com_shift": ("x", "y", "z"),
            **{q: tuple(str(j) for j in range(1, 8)) for q in PAIRED}}

#: Per model: the default gains, where the payload's centre of mass is measured from
#: (in the last link's frame), and the initial estimates before any error.
#: css_arm: the paper's gains (K_Di = K_D I6, P_i = P I13), theta_hat(0) = 0.
#: panda: payload_demo's (K_Di = K_D M_i, P_7 = P diag(scale)^2, links 1-6 known),
#: payload from the flange, theta_hat(0) = the URDF's nominal parameters.
MODEL_DEFAULTS = {
    "css_arm": dict(gains=dict(PAPER_GAINS),
                    tool=(0.0, 0.0, 0.0), initial_estimate="zero",
                    trajectory=dict(type="paper", reading="velocity")),
    "panda": dict(gains=dict(K_D=PANDA_GAINS["kappa"], P=PANDA_GAINS["rho"],
                             **{k: PANDA_GAINS[k] for k in ("Lambda", "gamma", "lam", "h")}),
                  tool=(0.0, 0.0, 0.107), initial_estimate="nominal",
                  trajectory=dict(type="sinusoid")),
}
#: The other URDF arms of example-robot-data: the Panda's gains at their scale
#: (:func:`~rcac_ros.tools.scenarios.gains_for`, last link adapting from the URDF's), no
#: tool; the sinusoids of the Panda's motion about each arm's posture (:data:`POSTURES`).
for _arm in ("ur5", "xarm7"):
    MODEL_DEFAULTS[_arm] = dict(MODEL_DEFAULTS["panda"], tool=(0.0, 0.0, 0.0))
#: example-robot-data's URDF of each URDF arm (the Panda: :func:`load_panda`).
URDFS = {"ur5": "ur_description/urdf/ur5_robot.urdf", "xarm7": "xarm_description/urdf/xarm7.urdf"}
#: The centre of each URDF arm's sinusoids (rad): the Panda's "ready", the UR5 with its
#: forearm level and wrist down, the xArm7 with its elbow and wrist bent.
POSTURES = {"panda": READY, "ur5": (0.0, -1.2, 1.4, -1.8, -1.57, 0.0),
            "xarm7": (0.0, -0.3, 0.0, 1.0, 0.0, 1.3, 0.0)}
SCENARIO_KEYS = ("model", "law", "trajectory", "duration", "gains", "substeps", "error_limit",
                 "initial_estimate", "payload_time", "engine", "adapt_all")
TOP_KEYS = ("name", "seed", "samples", "paired", "scenario", "vary")
TRAJECTORY_KEYS = {"paper": ("type", "reading", "amplitude", "period"),
                   "sinusoid": ("type", "offset", "amplitude", "frequency")}


def fail(key, message):
    """The one-line error of a campaign file, naming the key."""
    raise ConfigError(f"{key}: {message}")


def number(value, key, minimum=None, strict=False, integer=False):
    """A finite number (YAML's ``1e4`` arrives as a string: accepted if it parses)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        fail(key, f"expected a number, got {type(value).__name__} {value!r}")
    try:
        v = float(value)
    except ValueError:
        fail(key, f"expected a number, got {value!r}")
    if not math.isfinite(v):
        fail(key, f"must be finite, got {value!r}")
    if integer and v != int(v):
        fail(key, f"expected an integer, got {value!r}")
    if minimum is not None and (v < minimum or (strict and v == minimum)):
        fail(key, f"must be {'>' if strict else '>='} {minimum:g}, got {value!r}")
    return int(v) if integer else v


def mapping(value, key, allowed, required=()):
    """``value`` as a dict with only ``allowed`` keys and all ``required`` ones."""
    if not isinstance(value, dict):
        fail(key, f"expected a mapping, got {type(value).__name__}")
    for k in value:
        if k not in allowed:
            fail(f"{key}.{k}" if key else str(k),
                 f"unknown key (allowed: {', '.join(allowed)})")
    for k in required:
        if k not in value:
            fail(f"{key}.{k}" if key else k, "missing")
    return value


def check_value(name, value, key):
    """A value of quantity ``name`` (a fixed value, a choice or a grid item), normalised."""
    kind, size = QUANTITIES[name]
    if kind in ("law", "geometry"):
        allowed = LAWS if kind == "law" else GEOMETRIES
        if value not in allowed:
            fail(key, f"expected one of {', '.join(allowed)}, got {value!r}")
        return value
    if kind == "channels":               # the controller checks the names and the joint range
        def channel(c):
            return isinstance(c, str) or (isinstance(c, int) and not isinstance(c, bool)
                                          and c >= 1)
        if channel(value):
            return value
        if isinstance(value, list) and value and all(channel(c) for c in value):
            return list(value)
        fail(key, "expected joint numbers (>= 1), a channel name ('all', 'power') or a list "
             f"of those, got {value!r}")
    if kind == "int":
        return number(value, key, minimum=0, integer=True)
    minimum = None if kind == "signed" else 0.0
    strict = name in POSITIVE
    if size == 1:
        return number(value, key, minimum, strict)
    if not isinstance(value, list) or len(value) != size:
        fail(key, f"expected a list of {size} numbers, got {value!r}")
    return [number(v, f"{key}[{j}]", minimum, strict) for j, v in enumerate(value)]


def bounds(value, name, key, minimum=None, strict=False):
    """A distribution parameter: a number or, for a vector quantity, 3 numbers."""
    size = QUANTITIES[name][1]
    if size > 1 and isinstance(value, list):
        if len(value) != size:
            fail(key, f"expected a number or a list of {size}, got {value!r}")
        return [number(v, f"{key}[{j}]", minimum, strict) for j, v in enumerate(value)]
    return number(value, key, minimum, strict)


def check_spec(name, spec, key):
    """One ``vary`` entry: exactly one distribution, its parameters checked."""
    if not isinstance(spec, dict) or len(spec) != 1:
        fail(key, f"expected one of {', '.join(DISTRIBUTIONS)} (a one-key mapping), got "
             f"{spec!r}")
    (dist, params), = spec.items()
    sub = f"{key}.{dist}"
    if dist not in DISTRIBUTIONS:
        fail(sub, f"unknown distribution (allowed: {', '.join(DISTRIBUTIONS)})")
    kind = QUANTITIES[name][0]
    if dist in ("choice", "grid"):
        if not isinstance(params, list):
            fail(sub, f"expected a list of values, got {type(params).__name__}")
        if not params:
            fail(sub, "empty list")
        return {dist: [check_value(name, v, f"{sub}[{j}]") for j, v in enumerate(params)]}
    if kind in ("law", "geometry", "channels", "int"):
        fail(sub, f"{name} takes choice or grid, not {dist}")
    if dist == "normal":
        p = mapping(params, sub, ("mean", "std", "low", "high"), ("mean", "std"))
        out = {"mean": bounds(p["mean"], name, f"{sub}.mean"),
               "std": bounds(p["std"], name, f"{sub}.std", minimum=0.0)}
        for b in ("low", "high"):
            if b in p:
                out[b] = bounds(p[b], name, f"{sub}.{b}")
    else:
        positive = dist == "loguniform"
        p = mapping(params, sub, ("low", "high"), ("low", "high"))
        out = {b: bounds(p[b], name, f"{sub}.{b}", 0.0 if positive else None, positive)
               for b in ("low", "high")}
        if np.any(np.asarray(out["low"]) > np.asarray(out["high"])):
            fail(f"{sub}.high", f"must be >= low, got {out['high']!r} < {out['low']!r}")
    return {dist: out}


def check_trajectory(value, model):
    """The scenario's trajectory mapping, with the model's defaults."""
    key = "scenario.trajectory"
    if isinstance(value, str):
        value = {"type": value}
    mapping(value, key, ("type", "reading", "amplitude", "period", "offset", "frequency"))
    kind = value.get("type", MODEL_DEFAULTS[model]["trajectory"]["type"])
    if kind not in TRAJECTORY_KEYS:
        fail(f"{key}.type", f"expected paper or sinusoid, got {kind!r}")
    mapping(value, key, TRAJECTORY_KEYS[kind])
    out = dict(type=kind)
    if kind == "paper":
        reading = value.get("reading", "velocity")
        if reading not in ("velocity", "position"):
            fail(f"{key}.reading", f"expected velocity or position, got {reading!r}")
        out.update(reading=reading,
                   amplitude=number(value.get("amplitude", 5.0 * math.pi / 180.0),
                                    f"{key}.amplitude"),
                   period=number(value.get("period", 20.0), f"{key}.period", 0.0, True))
        return out
    defaults = dict(offset=POSTURES[model], amplitude=AMPLITUDE, frequency=FREQUENCY) \
        if model in POSTURES else {}
    for k in ("offset", "amplitude", "frequency"):
        if k not in value and k not in defaults:
            fail(f"{key}.{k}", f"missing (no default for {model})")
        v = value.get(k, defaults.get(k))
        items = v if isinstance(v, (list, tuple)) else [v]
        out[k] = [number(x, f"{key}.{k}", 0.0 if k == "frequency" else None)
                  for x in items]
    return out


def validate(doc, source="campaign"):
    """A campaign document checked and normalised (every default filled in).

    Raises
    ------
    ConfigError
        One line naming the offending key: unknown key, wrong type, negative std or
        bound, empty grid, missing field.
    """
    if doc is None:
        fail(source, "empty file")
    mapping(doc, "", TOP_KEYS, ("seed", "scenario"))
    out = {"name": str(doc.get("name", "campaign")),
           "seed": number(doc["seed"], "seed", 0, integer=True),
           "samples": number(doc.get("samples", 1), "samples", 1, integer=True)}
    paired = doc.get("paired", False)
    if not isinstance(paired, bool):
        fail("paired", f"expected true or false, got {paired!r}")
    if paired:                  # recorded only when set: older results resume
        out["paired"] = True
    sc = mapping(doc["scenario"], "scenario", SCENARIO_KEYS + tuple(
        q for q in QUANTITIES if q not in GAINS and q != "law"), ("model",))
    model = sc["model"]
    if model not in MODELS:
        fail("scenario.model", f"expected one of {', '.join(MODELS)}, got {model!r}")
    defaults = MODEL_DEFAULTS[model]
    gains = dict(defaults["gains"])
    for k, v in mapping(sc.get("gains", {}), "scenario.gains", GAINS).items():
        gains[k] = number(v, f"scenario.gains.{k}", 0.0, k != "gamma")
    fixed = dict(law=check_value("law", sc.get("law", "composite"), "scenario.law"),
                 **{k: gains[k] for k in GAINS if k != "h"},
                 channels=None, noise_q=0.0, noise_qd=0.0, delay=0, payload_mass=0.0,
                 payload_com=[0.0, 0.0, 0.0], payload_inertia=[0.0, 0.0, 0.0],
                 estimate_error=0.0, trajectory_scale=1.0, joint_damping=[0.0] * 7,
                 joint_friction=[0.0] * 7, joint_armature=[0.0] * 7, P_friction=None,
                 geometry="euclidean", start_mass_scale=1.0, start_com_shift=[0.0, 0.0, 0.0],
                 barrier_c=BARRIER_C)
    for q in QUANTITIES:
        if q in sc and q != "law":
            fixed[q] = check_value(q, sc[q], f"scenario.{q}")
    estimate = sc.get("initial_estimate", defaults["initial_estimate"])
    if estimate not in ("zero", "nominal"):
        fail("scenario.initial_estimate", f"expected zero or nominal, got {estimate!r}")
    out["scenario"] = dict(
        model=model, h=gains["h"], fixed=fixed, initial_estimate=estimate,
        trajectory=check_trajectory(sc.get("trajectory", defaults["trajectory"]), model),
        duration=number(sc.get("duration", 5.0), "scenario.duration", 0.0, True),
        substeps=number(sc.get("substeps", 1), "scenario.substeps", 1, integer=True),
        error_limit=number(sc.get("error_limit", 1.0), "scenario.error_limit", 0.0, True),
        payload_time=number(sc.get("payload_time", 0.0), "scenario.payload_time", 0.0),
        adapt_all=sc.get("adapt_all", False))
    if not isinstance(out["scenario"]["adapt_all"], bool) or (
            out["scenario"]["adapt_all"] and model not in POSTURES):
        fail("scenario.adapt_all", "expected true or false (URDF arms only: P on every "
             "link)")
    engine = check_engine(sc.get("engine", ENGINES[0]), "scenario.engine")
    if engine != ENGINES[0]:         # recorded only when not the default: older results resume
        out["scenario"]["engine"] = engine
    vary = mapping(doc.get("vary") or {}, "vary", tuple(QUANTITIES))
    out["vary"] = {q: check_spec(q, vary[q], f"vary.{q}") for q in QUANTITIES if q in vary}
    return out


def load(path):
    """Read and validate a campaign file (ConfigError naming the key on any problem)."""
    return validate(read_yaml(path), str(path))


def with_overrides(campaign, samples=None, duration=None):
    """A copy of a validated campaign with the command line's ``--samples``/``--duration``."""
    out = copy.deepcopy(campaign)
    if samples is not None:
        out["samples"] = int(samples)
    if duration is not None:
        out["scenario"]["duration"] = float(duration)
    return out


def grid_cells(campaign):
    """The Cartesian product of the grids: a list of ``{quantity: value}`` (one empty cell)."""
    grids = [(q, spec["grid"]) for q, spec in campaign["vary"].items() if "grid" in spec]
    return [dict(zip([q for q, _ in grids], values))
            for values in itertools.product(*[v for _, v in grids])]


def run_count(campaign):
    """Number of runs: grid cells times samples."""
    return len(grid_cells(campaign)) * campaign["samples"]


def draw(spec, rng, size):
    """One draw of a distribution ``spec`` (not a grid)."""
    (dist, p), = spec.items()
    shape = None if size == 1 else size
    if dist == "choice":
        return copy.deepcopy(p[int(rng.integers(len(p)))])
    if dist == "normal":
        v = rng.normal(p["mean"], p["std"], shape)
        v = np.clip(v, p.get("low", -np.inf), p.get("high", np.inf))
    elif dist == "uniform":
        v = rng.uniform(p["low"], p["high"], shape)
    else:
        v = np.exp(rng.uniform(np.log(p["low"]), np.log(p["high"]), shape))
    return float(v) if size == 1 else [float(x) for x in v]


def draw_index(campaign, index):
    """The index that seeds run ``index``'s draws: ``index`` itself, or with ``paired`` its
    sample ``index // cells`` (the same draws in every grid cell)."""
    return index // len(grid_cells(campaign)) if campaign.get("paired") else index


def sample(campaign, index):
    """The inputs of run ``index``: every quantity's value (fixed, grid or drawn)."""
    cells = grid_cells(campaign)
    inputs = copy.deepcopy(campaign["scenario"]["fixed"])
    inputs.update(copy.deepcopy(cells[index % len(cells)]))
    rng = np.random.default_rng([campaign["seed"], draw_index(campaign, index), 0])
    paired = np.random.default_rng([campaign["seed"], index // len(cells), 2])
    for q in QUANTITIES:                       # canonical order, whatever the file's
        spec = campaign["vary"].get(q)
        if spec is not None and "grid" not in spec:
            inputs[q] = draw(spec, paired if q in PAIRED else rng, QUANTITIES[q][1])
    return inputs


def varied_columns(campaign):
    """The result columns holding the varied inputs."""
    return [c for q in QUANTITIES if q in campaign["vary"] for c in columns_of(q)]


def columns_of(q):
    """Result column names of quantity ``q``."""
    return [f"{q}_{s}" for s in SUFFIXES[q]] if q in SUFFIXES else [q]


def input_columns(inputs):
    """Flatten the inputs to result columns (vectors split; channels as JSON text)."""
    row = {}
    for q in QUANTITIES:
        v = inputs[q]
        if q in SUFFIXES:
            row.update(zip(columns_of(q), (float(x) for x in v)))
        elif q == "channels":
            row[q] = "" if v is None else json.dumps(v)
        elif q in ("law", "geometry"):
            row[q] = v
        elif v is None:                 # P_friction: the library's default (0: a gain is > 0)
            row[q] = 0.0
        elif q == "delay":
            row[q] = int(v)
        else:
            row[q] = float(v)
    return row


@functools.lru_cache(maxsize=None)
def nominal_model(name):
    """The controller's model of a scenario (loaded once per process)."""
    if name == "css_arm":
        return css_arm()
    if name in URDFS:
        from rcac_ros.core.urdf import model_from_urdf
        from rcac_ros.tools.robots import example_robot_urdf
        path = example_robot_urdf(URDFS[name])
        if path is None:
            raise ConfigError(f"scenario.model: {name}: example-robot-data's {URDFS[name]} "
                              "not found (the 'robots' extra: pip install 'rcac_ros[robots]')")
        return model_from_urdf(path).replace(damping=0.0, friction=0.0)
    return load_panda()


def controller_for(campaign, inputs, model, theta_hat0=None):
    """The controller of one run (``channels`` passed only when given; ``theta_hat0`` at
    construction, where the natural geometry matches its gain, doc/design.md §8)."""
    sc = campaign["scenario"]
    law = inputs["law"]
    g = dict(K_D=inputs["K_D"], Lambda=inputs["Lambda"], P=inputs["P"],
             gamma=0.0 if law == "direct" else inputs["gamma"], lam=inputs["lam"], h=sc["h"])
    friction = dict(joint_friction=True) if law == "composite_friction" else {}
    if friction and inputs["P_friction"] is not None:
        friction["P_friction"] = inputs["P_friction"]
    if sc["model"] in POSTURES:
        gamma = g["gamma"]
        g = gains_for(model, kappa=g["K_D"], Lambda=g["Lambda"], rho=g["P"], gamma=gamma,
                      lam=g["lam"], h=g["h"], adapt_all=sc["adapt_all"])
        g["gamma"] = gamma
        g.pop("theta_hat0")
    g.update(theta_hat0=theta_hat0, geometry=inputs["geometry"])
    if g["geometry"] in ("natural", "natural_barrier"):
        g.update(geometry="natural", natural_metric="barrier", barrier_c=inputs["barrier_c"])
    elif g["geometry"] == "natural_log_det":
        g.update(geometry="natural", natural_metric="log_det")
    if law == "slotine_li":
        return controller("slotine_li", model, g)
    if inputs["channels"] is not None:
        g["channels"] = inputs["channels"]
    try:
        return controller("rcac", model, dict(g, **friction))
    except TypeError as err:
        if "channels" in g:
            raise ConfigError(f"channels: this controller does not take channels ({err})") \
                from None
        raise


def trajectory_for(campaign, inputs, model):
    """The desired motion and the initial state ``(trajectory, q0, qd0)`` of one run."""
    tr = campaign["scenario"]["trajectory"]
    scale = inputs["trajectory_scale"]
    if tr["type"] == "paper":
        q0 = np.array(PAPER_Q0[:model.n]) if model.n <= len(PAPER_Q0) else np.zeros(model.n)
        return (PaperTrajectory(q0, tr["reading"], tr["amplitude"] * scale, tr["period"]),
                q0, np.zeros(model.n))

    def per_joint(v):                   # one value, or one per joint (the first n of 7)
        v = np.array(v)
        return np.broadcast_to(v if v.size == 1 else v[:model.n], model.n)
    trajectory = SinusoidTrajectory(per_joint(tr["offset"]), per_joint(tr["amplitude"]) * scale,
                                    per_joint(tr["frequency"]))
    return trajectory, None, None


def setup(campaign, index):
    """Everything one run needs: ``(inputs, controller, closed_loop keyword arguments)``."""
    sc = campaign["scenario"]
    inputs = sample(campaign, index)
    model = nominal_model(sc["model"])
    tool = np.array(MODEL_DEFAULTS[sc["model"]]["tool"])
    loaded = attach_payload(model, inputs["payload_mass"], tool + inputs["payload_com"],
                            np.diag(inputs["payload_inertia"]))
    terms = {k: np.array(inputs[f"joint_{k}"][:model.n])
             for k in ("damping", "friction", "armature")}
    joints = any(np.any(v) for v in terms.values())    # the plant's joint terms

    def plant_of(m):
        return m.replace(**terms) if joints else m
    loaded = plant_of(loaded)
    trajectory, q0, qd0 = trajectory_for(campaign, inputs, model)
    rng = np.random.default_rng([campaign["seed"], draw_index(campaign, index), 1])
    theta = model.theta()
    base = np.zeros_like(theta) if sc["initial_estimate"] == "zero" else \
        shifted_start(theta, inputs["start_mass_scale"], inputs["start_com_shift"])
    start = perturbed_estimates(base, theta, inputs["estimate_error"], rng)
    controller = controller_for(campaign, inputs, model, start)
    events = ()
    plant = loaded
    if sc["payload_time"] > 0.0:
        plant, events = plant_of(model), ((sc["payload_time"], loaded),)
    kwargs = dict(trajectory=trajectory, duration=sc["duration"], plant=plant, q0=q0, qd0=qd0,
                  noise_q=inputs["noise_q"], noise_qd=inputs["noise_qd"],
                  delay=inputs["delay"], rng=rng, events=events, substeps=sc["substeps"],
                  engine=sc.get("engine", ENGINES[0]),
                  error_limit=sc["error_limit"], theta_hat0=start)
    return inputs, controller, kwargs


def shifted_start(theta, mass_scale, com_shift):
    """Initial estimates: every link's nominal body with its mass and inertia scaled by
    ``mass_scale`` and its centre of mass moved by ``com_shift`` (m, link frame); a body
    stays a body (doc/design.md §8)."""
    from rcac_ros.core.identifiability import inertia_about_com
    if mass_scale == 1.0 and not any(com_shift):
        return theta
    out = np.empty_like(theta)
    for i, t in enumerate(theta):
        m, c, I_c = inertia_about_com(t)
        out[i] = theta_from_inertia(mass_scale * m, c + np.asarray(com_shift),
                                    mass_scale * I_c)
    return out


def simulate(campaign, index, keep_run=False):
    """Run ``index`` of a validated campaign: its results row (and the time series)."""
    t0, c0 = time.perf_counter(), time.process_time()
    inputs, controller, kwargs = setup(campaign, index)
    run = closed_loop(controller, **kwargs)
    row = {"run": int(index)}
    row.update(input_columns(inputs))
    row.update(run_metrics(run))
    row.update(consistency_metrics(run))
    row["wall_time_s"] = time.perf_counter() - t0
    row["cpu_time_s"] = time.process_time() - c0
    return (row, run) if keep_run else row


def consistency_metrics(run):
    """Whether every link's estimates were a body at every period of the run, the share of
    link-periods that were, and the smallest ``lambda_min(J(theta_hat_i))`` (doc/design.md
    §8), over the periods whose estimates are finite."""
    from rcac_ros.core.pseudo_inertia import lambda_min
    theta = run["theta_hat"]
    ok = np.all(np.isfinite(theta), axis=(1, 2))
    if not ok.any():
        return dict(consistent_every_step=False, consistent_link_steps=0.0,
                    min_lambda_min=float("nan"))
    lam = lambda_min(theta[ok])
    return dict(consistent_every_step=bool(ok.all() and (lam > 0.0).all()),
                consistent_link_steps=float(np.mean(lam > 0.0)),
                min_lambda_min=float(lam.min()))


def warm_up():
    """Load every numba kernel a run uses (one tiny run per law on the CSS arm)."""
    doc = {"seed": 0, "scenario": {"model": "css_arm", "duration": 0.01},
           "vary": {"law": {"grid": list(LAWS)}, "noise_q": {"uniform": {"low": 0.0,
                                                                         "high": 1e-6}}}}
    campaign = validate(doc)
    for i in range(run_count(campaign)):
        simulate(campaign, i)
