"""``rcac bench --noise``: are the estimates bounded with noisy sensors? (10-minute runs)

The paper's experiment (CSS arm, paper gains, ``theta_hat(0) = 0``, the velocity reading
repeated for the whole run) with white measurement noise on what the controller reads:
``sigma = 1e-4 rad`` on q and ``1e-3 rad/s`` on qd (the plant is noise-free). Each law
runs plain and robust: a dead zone on s and on each E_c, at three standard deviations of
what the noise alone makes of them (measured first, over 2 s with the true parameters and
no adaptation), and the projection mass >= 0. Reports ``max ||theta_hat||`` over the run
and per minute (bounded: no drift), the tracking RMS over the last minute, and the share
of steps the dead zones let adapt. Writes ``noise.json`` and ``noise.png``.
"""

import json
import os

import numpy as np

from rcac_ros.core import (PAPER_GAINS, PAPER_Q0, PaperTrajectory, RecursiveCompositeController,
                           Simulator, css_arm)
from rcac_ros.tools.progress import Progress

SIGMA_Q, SIGMA_QD = 1e-4, 1e-3
#: law -> channels
LAWS = {"paper": [1], "4,6": [4, 6], "all": "all"}


def noisy(rng, q, qd):
    return q + SIGMA_Q * rng.standard_normal(q.shape), qd + SIGMA_QD * rng.standard_normal(q.shape)


def calibrate(model, channels, seconds=2.0, seed=1):
    """Three standard deviations of ``max_j |qd_j - qd_rj|`` and of each E_c under noise alone."""
    rng = np.random.default_rng(seed)
    q0 = np.array(PAPER_Q0)
    traj = PaperTrajectory(q0)
    g = dict(PAPER_GAINS, P=1e-12)
    ctrl = RecursiveCompositeController(model, theta_hat0=model.theta(), channels=channels, **g)
    sim = Simulator(model, dt=ctrl.h, q0=q0)
    s, E = [], []
    for k in range(int(seconds / ctrl.h)):
        q_d, qd_d, qdd_d = traj(k * ctrl.h)
        q, qd = noisy(rng, sim.q, sim.qd)
        sim.step(ctrl.step(q, qd, q_d, qd_d, qdd_d))
        s.append(np.max(np.abs(qd - (qd_d - ctrl.Lambda * (q - q_d)))))
        E.append(ctrl.E)
    return 3.0 * float(np.std(s) + np.mean(s)), 3.0 * float(np.max(np.std(E[50:], axis=0)))


def run_law(model, channels, duration, robust, seed=2, progress=None):
    rng = np.random.default_rng(seed)
    q0 = np.array(PAPER_Q0)
    traj = PaperTrajectory(q0)
    extra = {}
    if robust:
        dz_s, dz_E = calibrate(model, channels)
        extra = dict(dead_zone_s=dz_s, dead_zone_E=dz_E, theta_bounds="mass")
    ctrl = RecursiveCompositeController(model, channels=channels, **PAPER_GAINS, **extra)
    sim = Simulator(model, dt=ctrl.h, q0=q0)
    steps = int(round(duration / ctrl.h))
    every = int(round(1.0 / ctrl.h))
    norm, err, adapting = [], [], 0
    with Progress(steps, progress or "", enabled=progress is not None) as bar:
        for k in range(steps):
            q_d, qd_d, qdd_d = traj(k * ctrl.h)
            err.append(np.sqrt(np.mean((sim.q - q_d) ** 2)))
            sim.step(ctrl.step(*noisy(rng, sim.q, sim.qd), q_d, qd_d, qdd_d))
            tracking, channels_on = ctrl.adapted
            adapting += tracking or channels_on.any()
            if k % every == 0:
                norm.append(float(np.linalg.norm(ctrl.theta_hat)))
                bar.update(k)
    norm = np.array(norm)
    minute = max(1, len(norm) // max(1, int(duration // 60)))
    err = np.array(err)
    return {"theta_norm": norm.tolist(),
            "max_theta_norm": float(norm.max()), "theta_norm_end": float(norm[-1]),
            "max_theta_norm_per_minute": [float(norm[i:i + minute].max())
                                          for i in range(0, len(norm), minute)],
            "rms_last_minute": float(np.sqrt(np.mean(err[-every * 60:] ** 2))),
            "adapting_share": adapting / steps, **extra}


def run_noise_bench(duration=600.0, out_dir="results/noise", progress=True):
    model = css_arm()
    report = {}
    for law, channels in LAWS.items():
        for robust in (False, True):
            name = f"{law}{' robust' if robust else ''}"
            report[name] = run_law(model, channels, duration, robust,
                                   progress=f"{name:>12s}" if progress else None)
            r = report[name]
            print(f"{name:>12s}: max ||theta_hat|| {r['max_theta_norm']:10.1f}  end "
                  f"{r['theta_norm_end']:10.1f}  RMS last minute {r['rms_last_minute']:.3g} rad"
                  f"  adapting {100 * r['adapting_share']:.0f}% of steps", flush=True)
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, "noise.json"), "w", encoding="utf-8") as f:
        json.dump(dict(report, settings=dict(duration=duration, sigma_q=SIGMA_Q,
                                             sigma_qd=SIGMA_QD)), f, indent=2)
    from rcac_ros.tools.plots import plt
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for name, r in report.items():
        ax.plot(np.arange(len(r["theta_norm"])), r["theta_norm"], lw=1.0, label=name,
                ls="--" if "robust" in name else "-")
    ax.axhline(np.linalg.norm(model.theta()), color="k", lw=0.8, label="||theta|| (true)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("||theta_hat||")
    ax.set_title(f"Estimates under measurement noise (q: {SIGMA_Q:g} rad, qd: {SIGMA_QD:g} rad/s)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "noise.png"), dpi=110)
    plt.close(fig)
    print(f"wrote {out_dir}/noise.json, noise.png")
    return report
