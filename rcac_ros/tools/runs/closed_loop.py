"""The one closed-loop simulation: a controller driving a simulated arm along a trajectory.

:func:`closed_loop` closes the loop between any controller of :mod:`rcac_ros.core`
(``step``, ``set_applied_torque``, ``theta_hat``, ``E``, ``reset``) and a plant: the
:class:`~rcac_ros.core.Simulator` (RK4, torque held over the period, clipped to the
effort limit) or, with ``engine="mujoco"``, the same arm in MuJoCo
(:mod:`rcac_ros.plants`, doc/plants.md), with what a Monte Carlo campaign varies:

- the true plant apart from the controller's model (a payload attached from the
  start: :func:`attach_payload`), and plant changes at given times (``events``: a
  payload grasped at ``t = jump``);
- Gaussian sensor noise on the measured ``q`` and ``qd``;
- a measurement delay of a whole number of control periods (the controller sees the
  sample taken ``delay`` periods ago; the first sample is held until then);
- the initial estimates ``theta_hat(0)`` (:func:`perturbed_estimates`).

It returns the time series and :func:`run_metrics` summarises them. A run that
produces NaN/Inf, or whose tracking error exceeds ``error_limit``, stops there and
is marked diverged (with ``strict``, NaN/Inf raises instead); ``check_estimates``
also stops it at the first period whose estimates or prediction errors are not
finite. An ``observer`` sees the controller after every period (what a caller
records beyond the time series), and the time spent in ``controller.step`` alone is
returned. ``rcac experiment``, ``rcac payload-demo``, ``rcac compare`` and
``rcac sweep`` all run this loop.
"""

import math
import time
from collections import deque

import numpy as np

from rcac_ros.core import RcacError, theta_from_inertia
from rcac_ros.errors import ConfigError
from rcac_ros.plants import make_plant
from rcac_ros.tools.runs import metrics

#: Divergence is checked every this many control periods.
CHECK_EVERY = 25


def attach_payload(model, mass, com, inertia, link=None):
    """``model`` with a rigid payload added to one link (default: the last).

    The 13 parameters of eq 13 are linear in (mass, first moment, inertia about the
    frame origin), so the loaded link's parameters are the sum of the link's and the
    payload's; mass, centre of mass and inertia about it follow from that sum.

    Parameters
    ----------
    model : RobotModel
    mass : float
        Payload mass, kg (0 returns ``model`` unchanged).
    com : array_like (3,)
        Payload centre of mass in the link's frame, m.
    inertia : array_like (3, 3)
        Payload inertia about its centre of mass, link axes, kg m^2.
    link : int, optional
        Index of the carrying link.
    """
    if mass == 0.0:
        return model
    i = model.n - 1 if link is None else int(link)
    th = model.theta()[i] + theta_from_inertia(mass, com, inertia)
    m = th[0]
    c = th[1:4] / m
    # the inertia about the frame origin, I_o = I_c + m (|c|^2 1 - c c^T), is additive:
    # diagonal I_o,aa = theta[10 + a] + the two other m c_k^2 (theta[4:7]),
    # off-diagonal I_o,ab = -theta[7:10]; then back to the combined centre of mass
    inertia_o = np.diag(th[10:13] + th[4:7].sum() - th[4:7])
    for (a, b), k in (((0, 1), 7), ((0, 2), 8), ((1, 2), 9)):
        inertia_o[a, b] = inertia_o[b, a] = -th[k]
    inertia_c = inertia_o - m * (c @ c * np.eye(3) - np.outer(c, c))
    masses, coms, inertias = model.mass.copy(), model.com.copy(), model.inertia.copy()
    masses[i], coms[i], inertias[i] = m, c, inertia_c
    return model.replace(mass=masses, com=coms, inertia=inertias)


def perturbed_estimates(base, scale, relative_error, rng):
    """``base + relative_error * |scale| * N(0, 1)`` elementwise: an initial-estimate error.

    Parameters
    ----------
    base : ndarray (n, 13)
        The estimates without error (zero as in the paper, or the nominal parameters).
    scale : ndarray (n, 13)
        Size of each parameter (the nominal ``theta``).
    relative_error : float
        Standard deviation relative to ``|scale|``.
    rng : numpy.random.Generator
    """
    if relative_error == 0.0:
        return np.array(base, dtype=float)
    return base + relative_error * np.abs(scale) * rng.standard_normal(np.shape(base))


def available_memory():
    """Bytes of memory available to a new allocation (``MemAvailable`` of /proc/meminfo), or
    None where the system does not say."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def check_history(steps, per_step, available=None):
    """A one-line ``ConfigError`` if a run's history (``steps`` rows of ``per_step`` bytes)
    cannot fit in the memory available, before the run starts rather than at its end."""
    available = available_memory() if available is None else available
    need = steps * per_step
    if available is not None and need > available:
        raise ConfigError(f"duration: {steps} steps keep {need / 2**30:.3g} GiB of history, "
                          f"more than the {available / 2**30:.3g} GiB of memory available")


def closed_loop(controller, trajectory, duration, plant=None, q0=None, qd0=None,
                noise_q=0.0, noise_qd=0.0, delay=0, rng=None, theta_hat0=None, events=(),
                substeps=1, error_limit=math.inf, strict=False, check_estimates=False,
                observer=None, progress=None, progress_every=200, engine="builtin"):
    """Close the loop for ``duration`` s at the controller's period ``h``.

    Per period ``k``: the desired motion at ``t = k h``, the (noisy, delayed) measured
    state, ``tau = controller.step(...)``, the plant integrated over ``h`` with ``tau``
    held (clipped), and ``controller.set_applied_torque`` with what the arm felt.

    Parameters
    ----------
    controller : RecursiveCompositeController or SlotineLiCompositeController
    trajectory : callable
        ``t -> (q_d, qd_d, qdd_d)``.
    duration : float
        Simulated time, s (``round(duration / h) + 1`` periods).
    plant : RobotModel, optional
        The true arm (default: the controller's model).
    q0, qd0 : array_like (n,), optional
        Initial state (default: the desired position and velocity at ``t = 0``).
    noise_q, noise_qd : float or array_like (n,)
        Standard deviation of the white Gaussian noise on the measured ``q`` (rad) and
        ``qd`` (rad/s); ``rng`` draws it.
    delay : int
        Measurement delay, control periods.
    rng : numpy.random.Generator, optional
        Required when a noise level is not zero.
    theta_hat0 : array_like (n, 13), optional
        If given, the controller is reset to these estimates first.
    events : sequence of (float, RobotModel)
        Plant changes: at ``t >= time`` the plant becomes that model, state carried over.
    substeps : int
        RK4 steps of the plant per period.
    engine : str
        The plant: ``"builtin"`` (:class:`~rcac_ros.core.Simulator`) or ``"mujoco"``
        (:func:`rcac_ros.plants.make_plant`); the events' plants too.
    error_limit : float
        A run whose ``max |q - q_d|`` exceeds it (rad) stops and is marked diverged.
    strict : bool
        If True, NaN/Inf does not end the run: the error the controller or the plant raises
        when it meets them propagates (the command-line tools report it in one line).
    check_estimates : bool
        If True, every period ends with a check that ``controller.theta_hat`` and
        ``controller.E`` are finite; the first period where they are not ends the run
        (status ``"nonfinite"``; with ``strict``, an :class:`RcacError` is raised). Without
        it, estimates that blow up end the run only when they reach the torque.
    observer : callable, optional
        ``observer(k, controller, sim)``, called after every period ``k`` that completed
        (controller and plant stepped, ``set_applied_torque`` done, estimates checked if
        asked), with the plant of the true arm then in use.
    progress : str, optional
        Label of a progress line (none if None).
    progress_every : int
        The progress line is updated every this many periods.

    Returns
    -------
    dict
        ``t`` (T,), ``q``, ``qd`` (true), ``q_d``, ``tau`` (commanded), ``applied`` (T, n),
        ``theta_hat`` (T, n, 13) (before each step's update), ``E`` (T,) (or (T, m) for a
        controller with m prediction channels), ``status``
        (``"ok"``, ``"nonfinite"`` or ``"error_limit"``), ``plant`` (the final true model),
        ``effort_limit`` (n,), ``step_time`` (s of wall time spent in ``controller.step``
        over the run, the rest of the loop excluded). ``T`` is shorter than planned when
        the run diverged.
    """
    from rcac_ros.tools.progress import Progress

    h = controller.h
    steps = int(round(duration / h)) + 1
    plant = controller.model if plant is None else plant
    n = plant.n
    check_history(steps, 8 * (1 + 5 * n + 13 * n + np.size(controller.E)
                              + (2 * n if np.any(np.asarray(noise_q) != 0.0)
                                 or np.any(np.asarray(noise_qd) != 0.0) else 0)))
    if theta_hat0 is not None:
        controller.reset(theta_hat0)
    q_d0, qd_d0, _ = trajectory(0.0)
    sim = make_plant(plant, engine, dt=h, q0=q_d0 if q0 is None else q0,
                     qd0=qd_d0 if qd0 is None else qd0, substeps=substeps)
    sigma = np.array([np.broadcast_to(np.asarray(noise_q, float), n),
                      np.broadcast_to(np.asarray(noise_qd, float), n)])
    noise = None
    if np.any(sigma != 0.0):
        noise = rng.standard_normal((steps, 2, n)) * sigma
    measured = deque(maxlen=int(delay) + 1)
    pending = sorted(events, key=lambda e: e[0])
    out = dict(t=np.arange(steps) * h, q=np.empty((steps, n)), qd=np.empty((steps, n)),
               q_d=np.empty((steps, n)),
               tau=np.empty((steps, n)), applied=np.empty((steps, n)),
               theta_hat=np.empty((steps, n, 13)),
               E=np.empty((steps,) + np.shape(controller.E)))   # (T,) or (T, channels)
    status, done, spent = "ok", steps, 0.0
    with np.errstate(all="ignore"), Progress(steps, progress or "",
                                             enabled=progress is not None) as bar:
        for k in range(steps):
            t = k * h
            while pending and t >= pending[0][0] - 1e-12:
                loaded = make_plant(pending.pop(0)[1], engine, dt=h, substeps=substeps)
                loaded.reset(sim.q, sim.qd, t=sim.t)
                sim = loaded
            q_d, qd_d, qdd_d = trajectory(t)
            if noise is None:
                measured.append((sim.q, sim.qd))
            else:
                measured.append((sim.q + noise[k, 0], sim.qd + noise[k, 1]))
            q_m, qd_m = measured[0]
            out["theta_hat"][k] = controller.theta_hat
            out["q"][k], out["qd"][k], out["q_d"][k] = sim.q, sim.qd, q_d
            try:
                clock = time.perf_counter()
                tau = controller.step(q_m, qd_m, q_d, qd_d, qdd_d)
                spent += time.perf_counter() - clock
                out["tau"][k] = tau
                out["E"][k] = controller.E
                sim.step(tau)
                out["applied"][k] = sim.applied
                controller.set_applied_torque(sim.applied)
            except (RcacError, FloatingPointError):   # NaN/Inf reached the controller or plant
                if strict:
                    raise
                status, done = "nonfinite", k + 1
                for key in ("tau", "applied", "E"):
                    out[key][k] = np.nan
                break
            if check_estimates and not (np.all(np.isfinite(controller.theta_hat))
                                        and np.all(np.isfinite(controller.E))):
                if strict:
                    raise RcacError(f"theta_hat or E is not finite after t = {t:.6g} s")
                status, done = "nonfinite", k + 1
                break
            if observer is not None:
                observer(k, controller, sim)
            if k % CHECK_EVERY == CHECK_EVERY - 1 or k == steps - 1:
                start = max(0, k + 1 - CHECK_EVERY)
                worst = np.max(np.abs(out["q"][start:k + 1] - out["q_d"][start:k + 1]))
                if not strict and not (math.isfinite(worst) and np.all(np.isfinite(sim.q))):
                    status, done = "nonfinite", k + 1
                    break
                if worst > error_limit:
                    status, done = "error_limit", k + 1
                    break
            if k % progress_every == 0:
                bar.update(k)
    if done < steps:
        out = {key: v[:done] for key, v in out.items()}
    out.update(status=status, plant=sim.model, effort_limit=sim.effort_limit,
               step_time=spent)
    return out


def run_metrics(run, theta_true=None):
    """The summary of one run: the figures a campaign's results table holds.

    The figures of :mod:`rcac_ros.tools.runs.metrics` (same names, same meaning as in
    ``rcac experiment``), and what a campaign adds.

    Parameters
    ----------
    run : dict
        As returned by :func:`closed_loop`.
    theta_true : ndarray (n, 13), optional
        True parameters (default: those of the run's final plant).

    Returns
    -------
    dict
        ``rms_tracking_error``, ``max_tracking_error``, ``rms_tracking_error_last_5s``
        (rad), ``parameter_error_norm_start``/``_end`` and ``linkN_parameter_error_norm_end``
        (``||theta_hat - theta||``), ``final_abs_prediction_error`` (``|E|``, the norm
        over the channels of a multi-channel law),
        ``max_abs_torque`` (commanded), ``max_effort_ratio`` (max ``|tau| / effort_limit``,
        0 without limits), ``diverged`` (bool), ``status``, ``t_end`` (s simulated). A
        diverged run is summarised up to its last period where everything was finite.
    """
    theta = run["plant"].theta() if theta_true is None else theta_true
    with np.errstate(all="ignore"):
        e = run["q"] - run["q_d"]
        tau = np.abs(run["tau"])
        E = run["E"] if run["E"].ndim == 1 else np.linalg.norm(run["E"], axis=1)
        finite = (np.all(np.isfinite(e), axis=1) & np.all(np.isfinite(tau), axis=1)
                  & np.isfinite(E)
                  & np.all(np.isfinite(run["theta_hat"]), axis=(1, 2)))
        last = int(np.nonzero(finite)[0][-1]) + 1 if finite.any() else 1
        limit = run["effort_limit"]
        ratio = tau[:last, np.isfinite(limit)] / limit[np.isfinite(limit)]
        return {**metrics.tracking(run["t"][:last], e[:last]),
                **metrics.estimates(run["theta_hat"][:last], theta),
                **metrics.prediction(E[:last]), **metrics.torque(tau[:last]),
                "max_effort_ratio": float(np.max(ratio)) if ratio.size else 0.0,
                "diverged": run["status"] != "ok", "status": run["status"],
                "t_end": float(run["t"][-1])}
