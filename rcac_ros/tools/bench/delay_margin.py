"""The stable range of K_D against a delayed effort, offline (``rcac bench delay-margin``).

Timer mode answers a state up to a period old (doc/failsafe.md, "Measured"). This runs the paper's
closed loop without ROS (core simulator + controller, the CSS arm, the paper's motion and
gains but K_D) with the effort applied ``d`` periods late, ``d`` = 0 (lockstep), 1, 2, for
a grid of K_D, and reports the tracking RMS over the second half of the run (``inf``:
diverged, NaN or |qd| > 100 rad/s). With ``predict`` the state is first predicted over
the delay with the model and the efforts in flight (what ``timer.lookahead`` does).
"""

import numpy as np

from rcac_ros.core.model import css_arm, PAPER_GAINS, PAPER_Q0
from rcac_ros.core.composite import RecursiveCompositeController
from rcac_ros.core.simulator import rk4_kernel, Simulator
from rcac_ros.core.trajectory import PaperTrajectory

GAINS = (1e3, 3e3, 1e4, 2e4, 3e4, 5e4, 1e5)
DELAYS = (0, 1, 2)


def tracking_rms(K_D, delay, predict=False, duration=10.0):
    """Tracking RMS (rad, norm over the joints, second half) with the effort ``delay`` late."""
    model = css_arm()
    h = PAPER_GAINS["h"]
    q0 = np.array(PAPER_Q0)
    sim = Simulator(model, dt=h, q0=q0)
    gains = {k: v for k, v in PAPER_GAINS.items() if k not in ("K_D", "h")}
    ctrl = RecursiveCompositeController(model, K_D=K_D, h=h, **gains)
    traj = PaperTrajectory(q0)
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


def run_delay_margin(gains=GAINS, delays=DELAYS, duration=10.0, plot_path=None, verbose=True):
    """The table ``{(K_D, delay, predict): RMS}``, printed, and optionally plotted."""
    out = {}
    for K_D in gains:
        for d in delays:
            for predict in ((False, True) if d else (False,)):
                out[(K_D, d, predict)] = tracking_rms(K_D, d, predict, duration)
        if verbose:
            cells = "  ".join(f"d={d}{'+pred' if p else ''}: {out[(K_D, d, p)]:.3g}"
                              for (kd, d, p) in out if kd == K_D)
            print(f"K_D {K_D:8.0f}  {cells}", flush=True)
    if plot_path:
        from rcac_ros.tools.plots import plt, save
        fig, ax = plt.subplots(figsize=(7, 4))
        for d in delays:
            for predict in ((False, True) if d else (False,)):
                y = [out[(kd, d, predict)] for kd in gains]
                y = [v if np.isfinite(v) else np.nan for v in y]
                ax.loglog(gains, y, "o-" if not predict else "s--",
                          label=f"delay {d} period(s)" + (", predicted" if predict else ""))
        ax.axvline(PAPER_GAINS["K_D"], color="grey", lw=0.8, ls=":")
        ax.set_xlabel("K_D")
        ax.set_ylabel("tracking RMS, second half (rad)")
        ax.set_title("CSS arm, paper's motion: missing points diverged")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        save(fig, plot_path, 110)
        if verbose:
            print(f"wrote {plot_path}")
    return out
