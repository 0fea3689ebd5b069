"""The schema of a Monte Carlo campaign file and its validation (``rcac sweep``).

The keys of a campaign (doc/campaigns.md), the quantities it may vary and their
distributions; :func:`validate` checks a parsed file and answers a bad key or value with
one line naming it (:class:`rcac_ros.errors.ConfigError`); :func:`load` reads and checks a
file. Sampling and one run are :mod:`.campaign`'s.
"""

import math

import numpy as np

from rcac_ros.core import PAPER_GAINS
from rcac_ros.core.pseudo_inertia import BARRIER_C
from rcac_ros.errors import ConfigError, read_yaml
from rcac_ros.plants import check_engine, ENGINES
from rcac_ros.tools.runs.scenarios import AMPLITUDE, FREQUENCY, READY
from rcac_ros.tools.runs.scenarios import GAINS as PANDA_GAINS

LAWS = ("direct", "composite", "slotine_li", "composite_friction")
#: the law's geometry (doc/design.md §8): "natural" is the natural geometry with its default
#: metric (the barrier), "natural_log_det" and "natural_barrier" name the metric
GEOMETRIES = ("euclidean", "natural", "natural_log_det", "natural_barrier")
#: The columns that differ from one execution of a run to the next (everything else is equal).
TIMING = ("wall_time_s", "cpu_time_s")
MODELS = ("css_arm", "panda")
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
    "P_friction": ("float", 1),
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
    defaults = dict(offset=READY, amplitude=AMPLITUDE, frequency=FREQUENCY) \
        if model == "panda" else {}
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
                 joint_friction=[0.0] * 7, joint_armature=[0.0] * 7, P_friction=30.0,
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
            out["scenario"]["adapt_all"] and model != "panda"):
        fail("scenario.adapt_all", "expected true or false (panda only: P on every link)")
    engine = check_engine(sc.get("engine", ENGINES[0]), "scenario.engine")
    if engine != ENGINES[0]:         # recorded only when not the default: older results resume
        out["scenario"]["engine"] = engine
    vary = mapping(doc.get("vary") or {}, "vary", tuple(QUANTITIES))
    out["vary"] = {q: check_spec(q, vary[q], f"vary.{q}") for q in QUANTITIES if q in vary}
    return out


def load(path):
    """Read and validate a campaign file (ConfigError naming the key on any problem)."""
    return validate(read_yaml(path), str(path))
