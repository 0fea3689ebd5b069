"""The stable range of K_D against a delayed effort, offline (``rcac bench delay-margin``).

Timer mode answers a state up to a period old (doc/failsafe.md, "Starved machine"). This runs a
closed loop without ROS (core simulator + controller) with the effort applied ``d`` periods
late, ``d`` = 0 (lockstep), 1, 2 by default, for a grid of gains, and reports the tracking
RMS over the second half of the run (``inf``: diverged, NaN or |qd| > 100 rad/s). With
``predict`` the state is first predicted over the delay with the model and the efforts in
flight (what ``timer.lookahead`` does). Two arms (``model``):

* ``css_arm``: the paper's arm, motion and gains, the gain varied being K_D (``K_Di = K_D
  I6``);
* ``panda``: the Panda of ``rcac payload-demo`` (gravity on, its sinusoids about "ready",
  its gains), the gain varied being ``kappa`` (``K_Di = kappa M_i``), link 7 adapting;
* ``ur5``: the UR5 of example-robot-data (gravity on, sinusoids about a bent posture, the
  URDF's own inertias as estimates), the gain varied being K_D (``K_Di = K_D I6``, as the
  paper's).

:func:`check_margins` (``--check``) checks the delay margin the controller derives at
configure against the delayed loop itself, arm by arm: holding the arm's posture from
:data:`OFFSET` off it, the loop must settle with the effort 0.7 margin late (its error
below a tenth of the start's after :data:`CHECK_DURATION`) and must not 1.5 margin late
(above half the start's, or diverged). A stability check: tracking a motion, a late effort
also lags the motion, a cost that is not instability (the tracking RMS above shows it).

``adapt=False`` freezes the adaptation of eq 24 (what the starvation guard does). Each row
also gives the delay margin the starvation guard takes by default for those gains
(:func:`~rcac_ros.nodes.controller.starvation.feedback_margin`, doc/failsafe.md "Starved
machine").
"""

import numpy as np

from rcac_ros.core.model import css_arm, PAPER_GAINS, PAPER_Q0
from rcac_ros.core.composite import RecursiveCompositeController
from rcac_ros.core.simulator import rk4_kernel, Simulator
from rcac_ros.core.trajectory import PaperTrajectory, SinusoidTrajectory
from rcac_ros.nodes.controller.starvation import feedback_margin

GAINS = (1e3, 3e3, 1e4, 2e4, 3e4, 5e4, 1e5)
#: kappa of the Panda (1/s): the payload demo's is 100
PANDA_GAINS = (10.0, 30.0, 100.0, 300.0)
#: K_D of the UR5 (N m s/rad, K_Di = K_D I6): its wrist's small inertia makes the delay
#: margin of a given K_D about 3000x shorter than the CSS arm's
UR5_GAINS = (0.3, 1.0, 3.0, 10.0)
#: the UR5's posture (rad): elbow and wrist bent, away from the singularities
UR5_Q0 = (0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0)
#: the UR5's sinusoids: amplitude (rad) and frequency (Hz) per joint
UR5_MOTION = ((0.3, 0.25, 0.3, 0.3, 0.4, 0.3), (0.2, 0.25, 0.3, 0.22, 0.35, 0.28))
DELAYS = (0, 1, 2)
MODELS = ("css_arm", "panda", "ur5")
#: the rows of ``--check``: (arm, gain); two URDF arms (two gains each, the margins of each
#: pair 3x apart) and the paper's arm
CHECKS = (("panda", 30.0), ("panda", 100.0), ("ur5", 1.0), ("ur5", 3.0),
          ("css_arm", 3e3), ("css_arm", 1e4))
#: the delays of the check, in margins (the loop is stable at the first, not at the second)
WITHIN, BEYOND = 0.7, 1.5
#: rad: the check's start, off the posture it holds, on every joint
OFFSET = 0.05
#: s of the check's runs: five time constants 1/Lambda of the paper's position loop
CHECK_DURATION = 5.0


def closed_loop(model_name, gain, adapt=True):
    """``(model, controller, trajectory, q0)`` of ``model_name`` at ``gain`` (K_D or kappa)."""
    if model_name == "css_arm":
        model = css_arm()
        q0 = np.array(PAPER_Q0)
        gains = {k: v for k, v in PAPER_GAINS.items() if k != "K_D"}
        ctrl = RecursiveCompositeController(model, K_D=gain, **gains)
        traj = PaperTrajectory(q0)
    elif model_name == "ur5":
        model = load_ur5()
        q0 = np.array(UR5_Q0)
        gains = {k: v for k, v in PAPER_GAINS.items() if k != "K_D"}
        ctrl = RecursiveCompositeController(model, K_D=gain, theta_hat0=model.theta(), **gains)
        traj = SinusoidTrajectory(q0, *UR5_MOTION)
    else:
        from rcac_ros.tools.runs.scenarios import (AMPLITUDE, FREQUENCY, GAINS as PANDA, gains_for,
                                                   load_panda, READY)
        model = load_panda()
        q0 = np.array(READY)
        ctrl = RecursiveCompositeController(model, **gains_for(model, **dict(PANDA,
                                                                             kappa=gain)))
        traj = SinusoidTrajectory(q0, AMPLITUDE, FREQUENCY)
    ctrl.set_adaptation(adapt)
    return model, ctrl, traj, q0


def load_ur5():
    """example-robot-data's UR5 (``ur5_robot.urdf``, base to ``tool0``), gravity on."""
    from rcac_ros.core.urdf import model_from_urdf
    from rcac_ros.errors import ConfigError
    from rcac_ros.tools.runs.robots import example_robot_urdf
    path = example_robot_urdf("ur_description/urdf/ur5_robot.urdf")
    if path is None:
        raise ConfigError("example-robot-data's ur5_robot.urdf not found (the 'robots' extra: "
                          "pip install 'rcac_ros[robots]')")
    return model_from_urdf(path)


def tracking_rms(K_D, delay, predict=False, duration=10.0, model_name="css_arm", adapt=True):
    """Tracking RMS (rad, norm over the joints, second half) with the effort ``delay`` late
    (``K_D``: the gain of ``model_name``, :func:`closed_loop`)."""
    model, ctrl, traj, q0 = closed_loop(model_name, K_D, adapt)
    h = ctrl.h
    sim = Simulator(model, dt=h, q0=q0)
    g = np.asarray(model.gravity, float)
    in_flight = [np.zeros(model.n)] * delay
    errors = []
    for k in range(round(duration / h)):
        q, qd = sim.q, sim.qd
        if predict:
            for tau in in_flight:
                q, qd = rk4_kernel(model.packed, g, q, qd, tau, h, 1)
        tau = ctrl.step(q, qd, *traj((k + (delay if predict else 0)) * h))
        if not np.all(np.isfinite(tau)) or np.max(np.abs(sim.qd)) > 100.0:
            return np.inf
        in_flight.append(tau)
        sim.step(in_flight.pop(0))
        errors.append(np.linalg.norm(sim.q - traj((k + 1) * h)[0]))
    e = np.asarray(errors[len(errors) // 2:])
    return float(np.sqrt(np.mean(e ** 2)))


def run_delay_margin(gains=None, delays=DELAYS, duration=10.0, plot_path=None, verbose=True,
                     model_name="css_arm", adapt=True, predict=True):
    """The table ``{(gain, delay, predict): RMS}``, printed, and optionally plotted.

    ``gains``: default :data:`GAINS` (CSS arm) or :data:`PANDA_GAINS`; ``predict=False``
    leaves out the runs with the prediction.
    """
    if gains is None:
        gains = {"css_arm": GAINS, "panda": PANDA_GAINS, "ur5": UR5_GAINS}[model_name]
    name = "kappa" if model_name == "panda" else "K_D"
    out = {}
    for K_D in gains:
        for d in delays:
            for p in ((False, True) if d and predict else (False,)):
                out[(K_D, d, p)] = tracking_rms(K_D, d, p, duration, model_name, adapt)
        if verbose:
            _, ctrl, _, q0 = closed_loop(model_name, K_D)
            margin = feedback_margin(ctrl, q0)
            cells = "  ".join(f"d={d}{'+pred' if p else ''}: {out[(K_D, d, p)]:.3g}"
                              for (kd, d, p) in out if kd == K_D)
            print(f"{name} {K_D:8g}  margin {margin * 1e3:.3g} ms  {cells}", flush=True)
    if plot_path:
        from rcac_ros.tools.plots import plt, save
        fig, ax = plt.subplots(figsize=(7, 4))
        for d in delays:
            for p in ((False, True) if d and predict else (False,)):
                y = [out[(kd, d, p)] for kd in gains]
                y = [v if np.isfinite(v) else np.nan for v in y]
                ax.loglog(gains, y, "o-" if not p else "s--",
                          label=f"delay {d} period(s)" + (", predicted" if p else ""))
        if model_name == "css_arm":
            ax.axvline(PAPER_GAINS["K_D"], color="grey", lw=0.8, ls=":")
        ax.set_xlabel(name)
        ax.set_ylabel("tracking RMS, second half (rad)")
        ax.set_title({"css_arm": "CSS arm, paper's motion", "panda": "Panda, payload demo's "
                      "motion", "ur5": "UR5, sinusoids"}[model_name] + ": missing points diverged")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        save(fig, plot_path, 110)
        if verbose:
            print(f"wrote {plot_path}")
    return out


def holding_error(model_name, gain, delay, duration=CHECK_DURATION, offset=OFFSET):
    """The loop holding the arm's posture ``q0`` (``q_d = q0``, at rest) from ``offset`` rad
    off it on every joint, the effort ``delay`` periods late, adaptation frozen: the norm of
    the position error at the start and its RMS over the last tenth (``inf``: diverged)."""
    model, ctrl, _, q0 = closed_loop(model_name, gain, adapt=False)
    h = ctrl.h
    sim = Simulator(model, dt=h, q0=q0 + offset)
    zero = np.zeros(model.n)
    in_flight = [zero] * delay
    errors = []
    for _ in range(round(duration / h)):
        tau = ctrl.step(sim.q, sim.qd, q0, zero, zero)
        if not np.all(np.isfinite(tau)) or np.max(np.abs(sim.qd)) > 100.0:
            return offset * np.sqrt(model.n), np.inf
        in_flight.append(tau)
        sim.step(in_flight.pop(0))
        errors.append(np.linalg.norm(sim.q - q0))
    e = np.asarray(errors[-len(errors) // 10:])
    return offset * np.sqrt(model.n), float(np.sqrt(np.mean(e ** 2)))


def check_margins(checks=CHECKS, json_path=None, verbose=True):
    """Check the derived delay margin against the delayed closed loop, arm by arm.

    For each ``(arm, gain)`` of ``checks``: the margin the starvation guard derives at
    configure (:func:`~rcac_ros.nodes.controller.starvation.feedback_margin` at the arm's
    posture), then :func:`holding_error` with the effort ``d`` periods late, ``d`` = 0,
    ``floor(WITHIN margin / h)`` and ``ceil(BEYOND margin / h)``. The derivation holds on a
    row if the loop settles at the first two delays (the final error below a tenth of the
    start's) and not at the third (above half the start's, or diverged). The delays between
    the second and the third are run too, for the measured edge: the first at which the loop
    does not settle.

    Returns
    -------
    list of dict
        One per row: ``arm``, ``gain_name``, ``gain``, ``margin_ms``, ``margin_periods``,
        ``delays`` (periods), ``start`` and ``final`` (rad; ``None``: diverged),
        ``edge_periods`` (``None``: settles up to the third delay), ``holds``.
    """
    rows = []
    for arm, gain in checks:
        _, ctrl, _, q0 = closed_loop(arm, gain, adapt=False)
        margin = feedback_margin(ctrl, q0)
        periods = margin / ctrl.h
        delays = (0, max(1, int(WITHIN * periods)), int(np.ceil(BEYOND * periods)))
        runs = [holding_error(arm, gain, d) for d in delays]
        start = runs[0][0]
        final = [f for _, f in runs]
        holds = bool(final[0] < 0.1 * start and final[1] < 0.1 * start
                     and not final[2] <= 0.5 * start)
        # the measured edge: the first delay, in periods, at which the loop does not settle
        edge = next((d for d in range(delays[1] + 1, delays[2] + 1)
                     if not holding_error(arm, gain, d)[1] < 0.1 * start), None)
        rows.append({"arm": arm, "gain_name": "kappa" if arm == "panda" else "K_D",
                     "gain": gain, "margin_ms": margin * 1e3, "delays": list(delays),
                     "start": start, "final": [f if np.isfinite(f) else None for f in final],
                     "edge_periods": edge, "margin_periods": periods, "holds": holds})
        if verbose:
            cells = "  ".join(f"d={d}: {f:.3g}" for d, f in zip(delays, final))
            print(f"{arm:8s} {rows[-1]['gain_name']:5s} {gain:<7g} margin {margin * 1e3:6.3g} ms "
                  f"({periods:4.1f} periods)  final error (from {start:.3g} rad) {cells}  "
                  f"does not settle from {edge} periods  {'holds' if holds else 'FAILS'}",
                  flush=True)
    if json_path:
        import json
        with open(json_path, "w") as f:
            json.dump({"within": WITHIN, "beyond": BEYOND, "offset_rad": OFFSET,
                       "duration_s": CHECK_DURATION, "rows": rows}, f, indent=2)
    return rows
