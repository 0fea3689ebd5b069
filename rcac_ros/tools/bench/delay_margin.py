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
  its gains), the gain varied being ``kappa`` (``K_Di = kappa M_i``), link 7 adapting.

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
DELAYS = (0, 1, 2)
MODELS = ("css_arm", "panda")


def closed_loop(model_name, gain, adapt=True):
    """``(model, controller, trajectory, q0)`` of ``model_name`` at ``gain`` (K_D or kappa)."""
    if model_name == "css_arm":
        model = css_arm()
        q0 = np.array(PAPER_Q0)
        gains = {k: v for k, v in PAPER_GAINS.items() if k != "K_D"}
        ctrl = RecursiveCompositeController(model, K_D=gain, **gains)
        traj = PaperTrajectory(q0)
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
        gains = GAINS if model_name == "css_arm" else PANDA_GAINS
    name = "K_D" if model_name == "css_arm" else "kappa"
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
        ax.set_title(("CSS arm, paper's motion" if model_name == "css_arm" else
                      "Panda, payload demo's motion") + ": missing points diverged")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        save(fig, plot_path, 110)
        if verbose:
            print(f"wrote {plot_path}")
    return out
