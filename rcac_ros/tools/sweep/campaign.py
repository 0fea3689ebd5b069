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
import time

import numpy as np

from rcac_ros.core import PAPER_Q0, PaperTrajectory, SinusoidTrajectory, css_arm
from rcac_ros.core.identifiability import inertia_about_com
from rcac_ros.core.model import theta_from_inertia
from rcac_ros.core.pseudo_inertia import lambda_min
from rcac_ros.errors import ConfigError
from rcac_ros.plants import ENGINES
from rcac_ros.tools.runs.closed_loop import (attach_payload, closed_loop, perturbed_estimates,
                                             run_metrics)
from rcac_ros.tools.runs.scenarios import controller, gains_for, load_panda

from rcac_ros.tools.sweep.schema import (DISTRIBUTIONS, GEOMETRIES, LAWS, load,  # noqa: F401
                                         MODEL_DEFAULTS, MODELS, PAIRED, QUANTITIES,
                                         SUFFIXES, TIMING, validate)


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
    return load_panda()


def controller_for(campaign, inputs, model, theta_hat0=None):
    """The controller of one run (``channels`` passed only when given; ``theta_hat0`` at
    construction, where the natural geometry matches its gain, doc/design.md §8)."""
    sc = campaign["scenario"]
    law = inputs["law"]
    g = dict(K_D=inputs["K_D"], Lambda=inputs["Lambda"], P=inputs["P"],
             gamma=0.0 if law == "direct" else inputs["gamma"], lam=inputs["lam"], h=sc["h"])
    friction = dict(joint_friction=True, P_friction=inputs["P_friction"]) \
        if law == "composite_friction" else {}
    if sc["model"] == "panda":
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
    amplitude = np.broadcast_to(np.array(tr["amplitude"]), model.n) * scale
    trajectory = SinusoidTrajectory(np.broadcast_to(np.array(tr["offset"]), model.n),
                                    amplitude, np.broadcast_to(np.array(tr["frequency"]),
                                                               model.n))
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
