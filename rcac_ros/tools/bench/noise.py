"""``rcac bench noise``: are the estimates bounded with noisy sensors? (10-minute runs)

The paper's experiment (CSS arm, paper gains, ``theta_hat(0) = 0``, the velocity reading
repeated for the whole run) with white Gaussian measurement noise on what the controller
reads: ``sigma = 1e-4 rad`` on q and ``1e-3 rad/s`` on qd (the plant is noise-free). Each
law runs in these variants:

``clean``
    no noise: the reference. What the plain law does without noise is learning, not drift,
    so the noise's effect is ``||theta_hat - theta_hat_clean||``, same law, same time.
``plain``
    noise, the law as it is.
``dead zone``
    noise, a dead zone sized from the declared noise level (:func:`dead_zones`) and the
    projection mass >= 0.
``sigma``
    noise, the fixed sigma-modification toward ``theta_0 = theta_hat(0) = 0``
    (:data:`SIGMA_FIXED`).
``switching``
    noise, the switching sigma-modification (:data:`SIGMA_SWITCHING`) with each link's
    ``M_0`` from a declared bound on its parameters (:data:`M0_FACTOR`).

Per second it records ``||theta_hat||``, ``||theta_hat - theta||`` and the deviation from
the clean run; per run the tracking RMS (whole run, last minute) and a growth criterion on
each series (:func:`growth`). Writes ``noise.json`` and ``noise.png``.
"""

import json
import os
from statistics import NormalDist

import numpy as np

from rcac_ros.core import PAPER_GAINS, PAPER_Q0, PaperTrajectory, css_arm
from rcac_ros.tools.progress import Progress

SIGMA_Q, SIGMA_QD = 1e-4, 1e-3
#: law -> channels
LAWS = {"paper": [1], "4,6": [4, 6], "all": "all"}
VARIANTS = ("clean", "plain", "dead zone", "sigma", "switching")
#: sigma_0 of the fixed leakage: with the paper's P = 100 I, a time constant
#: 1 / (sigma_0 P) = 1 s
SIGMA_FIXED = 0.01
#: sigma_0 of the switching leakage, 0.1 s where it is full (beyond 2 M_0)
SIGMA_SWITCHING = 0.1
#: M_0i = this x ||theta_i - theta_0i|| per link: the user declares each link's parameter
#: size to within 50 % (theta_0 = theta_hat(0) = 0 here)
M0_FACTOR = 1.5
#: a series still grows if its least-squares slope over the last half, times that half's
#: length, exceeds this share of its mean over the last half
GROWTH_TOL = 0.05


def noisy(rng, q, qd):
    return q + SIGMA_Q * rng.standard_normal(q.shape), qd + SIGMA_QD * rng.standard_normal(q.shape)


def s_noise(Lambda):
    """Standard deviation of the noise in ``s_j = qd_j - qd_rj = (qd_j - qd_dj) + Lambda_j
    (q_j - q_dj)``: ``sqrt(sigma_qd^2 + Lambda_j^2 sigma_q^2)``, the largest over j."""
    return float(np.sqrt(SIGMA_QD ** 2 + np.max(Lambda) ** 2 * SIGMA_Q ** 2))


def dead_zone_factor(n, steps):
    """``k`` such that noise alone exceeds ``k`` standard deviations in ``max_j |.|`` (n
    independent Gaussians) about once in ``steps`` steps: ``Phi^-1(1 - 1 / (2 n steps))``.

    A dead zone stops drift only above the disturbance's bound (Ioannou & Sun, ch. 8);
    Gaussian noise has none, so this is the bound it crosses once per run."""
    return NormalDist().inv_cdf(1.0 - 1.0 / (2.0 * n * steps))


def calibrate_E(model, channels, seconds=2.0, seed=1):
    """Standard deviation of each E_c under noise alone (true parameters, no adaptation,
    2 s), the largest: E has no closed-form noise level (it depends on W and theta_hat)."""
    from rcac_ros.core import RecursiveCompositeController, Simulator
    rng = np.random.default_rng(seed)
    q0 = np.array(PAPER_Q0)
    traj = PaperTrajectory(q0)
    ctrl = RecursiveCompositeController(model, theta_hat0=model.theta(), channels=channels,
                                        **dict(PAPER_GAINS, P=1e-12))
    sim = Simulator(model, dt=ctrl.h, q0=q0)
    E = []
    for k in range(int(seconds / ctrl.h)):
        q, qd = noisy(rng, sim.q, sim.qd)
        sim.step(ctrl.step(q, qd, *traj(k * ctrl.h)))
        E.append(ctrl.E)
    return float(np.max(np.std(E[50:], axis=0)))


def dead_zones(model, channels, steps):
    """The dead zones of the ``dead zone`` variant: ``k`` noise standard deviations each."""
    k = dead_zone_factor(model.n, steps)
    Lambda = np.broadcast_to(PAPER_GAINS["Lambda"], (model.n,))
    return dict(dead_zone_s=k * s_noise(Lambda), dead_zone_E=k * calibrate_E(model, channels),
                theta_bounds="mass")


def options(model, channels, variant, steps):
    """The controller options of a variant."""
    if variant == "dead zone":
        return dead_zones(model, channels, steps)
    if variant == "sigma":
        return dict(leakage=SIGMA_FIXED)
    if variant == "switching":
        m0 = M0_FACTOR * np.linalg.norm(model.theta(), axis=1)
        return dict(leakage=SIGMA_SWITCHING, leakage_bound=m0.tolist())
    return {}


def growth(series):
    """Whether a per-second series still grows: ``slope x T/2`` over its last half (least
    squares), relative to its mean there, the ratio of the halves' maxima, and the exponent
    a of ``x ~ t^a`` fitted over the last half (1: a steady drift, 0.5: a random walk, 0:
    settled); not assessed under 4 samples."""
    x = np.asarray(series, dtype=float)
    if len(x) < 4:
        return {"last_half_rise": float("nan"), "max_ratio": float("nan"),
                "exponent": float("nan"), "still_growing": None}
    half = x[len(x) // 2:]
    t = np.arange(len(half), dtype=float)
    slope = np.polyfit(t, half, 1)[0]
    rel = float(slope * len(half) / max(np.mean(np.abs(half)), 1e-300))
    t_half = np.arange(len(x) // 2, len(x), dtype=float) + 1.0
    exponent = float(np.polyfit(np.log(t_half), np.log(np.maximum(half, 1e-300)), 1)[0]) \
        if np.all(half > 0.0) else float("nan")
    return {"last_half_rise": rel, "max_ratio": float(half.max() / x[:len(x) // 2].max()),
            "exponent": exponent, "still_growing": bool(rel > GROWTH_TOL)}


#: relative eigenvalue thresholds of the excitation: below 1e-8 a direction is not
#: identified at all (identifiability.RANK_TOL), below 1e-4 poorly
WEAK = (1e-8, 1e-4)


def weak_share(sigma, deviation):
    """Share of ``sum_i ||d_i||^2`` in each link's directions of excitation ``Sigma_i``
    below each threshold of :data:`WEAK` (relative to its largest eigenvalue)."""
    total = float(np.sum(deviation ** 2))
    out = {}
    for tol in WEAK:
        part = 0.0
        for S, d in zip(sigma, deviation):
            w, V = np.linalg.eigh(S)
            weak = V[:, w < tol * max(w[-1], 1e-300)]
            part += float(np.sum((weak.T @ d) ** 2))
        out[f"{tol:g}"] = part / total if total > 0.0 else float("nan")
    return out


def run_law(model, channels, duration, variant, clean=None, seed=2, progress=None):
    """One closed loop; ``clean``: the clean run's theta_hat per second (deviation).

    The clean run also accumulates the excitation of its motion, ``Sigma_i = sum h W_i^T
    W_i`` with every joint channel (Slotine-Li's information, from a frozen shadow
    controller fed the same states), returned with the estimates."""
    from rcac_ros.core import RecursiveCompositeController, Simulator
    from rcac_ros.core.identifiability import Excitation
    rng = np.random.default_rng(seed)
    q0 = np.array(PAPER_Q0)
    traj = PaperTrajectory(q0)
    h = PAPER_GAINS["h"]
    steps = int(round(duration / h))
    extra = options(model, channels, variant, steps)
    ctrl = RecursiveCompositeController(model, channels=channels, **PAPER_GAINS, **extra)
    sim = Simulator(model, dt=h, q0=q0)
    every = int(round(1.0 / h))
    theta = model.theta()
    hats, err, adapting = [], np.empty(steps), 0
    shadow = excitation = None
    if variant == "clean":
        shadow = RecursiveCompositeController(model, channels="all", **PAPER_GAINS)
        shadow.set_adaptation(False)
        excitation = Excitation(model.n, h)
    with Progress(steps, progress or "", enabled=progress is not None) as bar:
        for k in range(steps):
            q_d, qd_d, qdd_d = traj(k * h)
            err[k] = np.sqrt(np.mean((sim.q - q_d) ** 2))
            q, qd = (sim.q, sim.qd) if variant == "clean" else noisy(rng, sim.q, sim.qd)
            tau = ctrl.step(q, qd, q_d, qd_d, qdd_d)
            if shadow is not None:
                shadow.step(q, qd, q_d, qd_d, qdd_d)
                shadow.set_applied_torque(tau)
                excitation.add(shadow.W)
            sim.step(tau)
            tracking, channels_on = ctrl.adapted
            adapting += tracking or channels_on.any()
            if (k + 1) % every == 0:
                hats.append(ctrl.theta_hat)
                bar.update(k)
    hats = np.array(hats)
    out = {"theta_norm": np.linalg.norm(hats, axis=(1, 2)).tolist(),
           "theta_error": np.linalg.norm(hats - theta, axis=(1, 2)).tolist(),
           "rms": float(np.sqrt(np.mean(err ** 2))),
           "rms_last_minute": float(np.sqrt(np.mean(err[-every * 60:] ** 2))),
           "adapting_share": adapting / steps,
           "options": {k: v for k, v in extra.items()}}
    if clean is not None:
        clean_hats, sigma = clean
        out["deviation"] = np.linalg.norm(hats - clean_hats, axis=(1, 2)).tolist()
        out["deviation_weak_share"] = weak_share(sigma, hats[-1] - clean_hats[-1])
    for key in ("theta_norm", "theta_error", "deviation"):
        if key in out:
            out[key + "_growth"] = growth(out[key])
    return out, (hats, None if excitation is None else excitation.sigma)


def run_noise_bench(duration=600.0, out_dir="results/noise", progress=True, laws=None,
                    variants=VARIANTS):
    """Every law of ``laws`` (default :data:`LAWS`) in every variant; JSON and plot."""
    model = css_arm()
    laws = LAWS if laws is None else {k: LAWS[k] for k in laws}
    report = {}
    for law, channels in laws.items():
        clean = None
        for variant in ("clean",) + tuple(v for v in variants if v != "clean"):
            name = f"{law} / {variant}"
            r, hats = run_law(model, channels, duration, variant, clean=clean,
                              progress=f"{name:>20s}" if progress else None)
            if variant == "clean":
                clean = hats
            report[name] = r
            dev = r.get("deviation_growth", {}).get("exponent", float("nan"))
            weak = r.get("deviation_weak_share", {}).get(f"{WEAK[1]:g}", float("nan"))
            g = r["theta_norm_growth"]
            print(f"{name:>20s}: ||theta_hat|| end {r['theta_norm'][-1]:7.1f} (last half"
                  f" {100 * g['last_half_rise']:+5.1f} %, ~t^{g['exponent']:.2f})"
                  f"  ||theta_hat - theta|| end {r['theta_error'][-1]:7.1f}"
                  f"  from clean {r.get('deviation', [float('nan')])[-1]:7.1f} (~t^{dev:.2f},"
                  f" {100 * weak:.0f} % poorly excited)  RMS {r['rms']:.3g}, last minute"
                  f" {r['rms_last_minute']:.3g} rad  adapting"
                  f" {100 * r['adapting_share']:.0f} %", flush=True)
    os.makedirs(out_dir, exist_ok=True)
    settings = dict(duration=duration, sigma_q=SIGMA_Q, sigma_qd=SIGMA_QD,
                    sigma_fixed=SIGMA_FIXED, sigma_switching=SIGMA_SWITCHING,
                    M0_factor=M0_FACTOR, growth_tol=GROWTH_TOL,
                    theta_norm_true=float(np.linalg.norm(model.theta())))
    with open(os.path.join(out_dir, "noise.json"), "w", encoding="utf-8") as f:
        json.dump(dict(compact(report), settings=settings), f, separators=(",", ":"))
    with open(os.path.join(out_dir, "noise.md"), "w", encoding="utf-8") as f:
        f.write(table(report))
    plot(report, laws, os.path.join(out_dir, "noise.png"))
    print(f"wrote {out_dir}/noise.json, noise.md, noise.png")
    return report


#: the per-second series of a report, stored to 0.1 (norms of tens to thousands)
SERIES = ("theta_norm", "theta_error", "deviation")


def compact(report):
    """``report`` with its per-second series rounded to 0.1."""
    return {name: {k: ([round(x, 1) for x in v] if k in SERIES else v)
                   for k, v in r.items()} if name != "settings" else r
            for name, r in report.items()}


def table(report):
    """The markdown table of a report: boundedness of ``||theta_hat||`` and tracking cost."""
    rows = ["| law / variant | ‖θ̂‖ end | last half | ~t^a | still growing | ‖θ̂ − θ‖ end "
            "| from clean | of which poorly excited | RMS (rad) | RMS last min | adapting |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in report.items():
        if name == "settings":
            continue
        g = r["theta_norm_growth"]
        dev = f"{r['deviation'][-1]:.0f}" if "deviation" in r else "-"
        weak = f"{100 * r['deviation_weak_share'][f'{WEAK[1]:g}']:.0f} %" \
            if "deviation" in r else "-"
        growing = {True: "yes", False: "no"}.get(g["still_growing"], "-")   # None: too short
        rows.append(f"| {name} | {r['theta_norm'][-1]:.0f} | {100 * g['last_half_rise']:+.1f} % "
                    f"| {g['exponent']:.2f} | {growing} "
                    f"| {r['theta_error'][-1]:.0f} | {dev} | {weak} | {r['rms']:.3g} "
                    f"| {r['rms_last_minute']:.3g} | {100 * r['adapting_share']:.0f} % |")
    return "\n".join(rows) + "\n"


def plot(report, laws, path):
    """Per law (columns): ``||theta_hat - theta||`` and the deviation from the clean run."""
    from rcac_ros.tools.plots import plt, save
    fig, axes = plt.subplots(2, len(laws), figsize=(4.5 * len(laws), 7), squeeze=False,
                             sharex=True)
    styles = {"clean": ("k", "-"), "plain": ("C3", "-"), "dead zone": ("C0", "--"),
              "sigma": ("C2", "-."), "switching": ("C1", "-")}
    for col, law in enumerate(laws):
        for name, r in report.items():
            if not name.startswith(law + " / "):
                continue
            variant = name.split(" / ", 1)[1]
            color, ls = styles[variant]
            t = np.arange(1, len(r["theta_error"]) + 1) / 60.0
            axes[0, col].plot(t, r["theta_error"], color=color, ls=ls, lw=1.0,
                              label=f"{variant} (RMS {r['rms']:.2g})")
            if "deviation" in r:
                axes[1, col].plot(t, r["deviation"], color=color, ls=ls, lw=1.0, label=variant)
        axes[0, col].set_title(f"channels {law}")
        axes[0, col].set_ylabel("||theta_hat - theta||")
        axes[1, col].set_ylabel("||theta_hat - theta_hat(clean)||")
        axes[1, col].set_xlabel("time (min)")
        for ax in axes[:, col]:
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
    fig.suptitle(f"Estimates under measurement noise (q: {SIGMA_Q:g} rad, qd: "
                 f"{SIGMA_QD:g} rad/s); tracking RMS in rad")
    save(fig, path, 80)


#: ``rcac bench noise --sources``: label -> (sigma_q scale, sigma_qd scale, gamma, seed), paper law
SOURCES = {"both": (1.0, 1.0, None, 2), "both, seed 3": (1.0, 1.0, None, 3),
           "both, half": (0.5, 0.5, None, 2), "q only": (1.0, 0.0, None, 2),
           "qd only": (0.0, 1.0, None, 2), "both, gamma = 0": (1.0, 1.0, 0.0, 2)}


def _estimates(model, sq, sqd, gamma, duration, seed, label):
    """The paper law's theta_hat per second (plain), noise ``sq``, ``sqd``, gain gamma."""
    from rcac_ros.core import RecursiveCompositeController, Simulator
    rng = np.random.default_rng(seed)
    q0 = np.array(PAPER_Q0)
    traj = PaperTrajectory(q0)
    ctrl = RecursiveCompositeController(model, **dict(PAPER_GAINS, gamma=gamma))
    sim = Simulator(model, dt=ctrl.h, q0=q0)
    steps, every = int(round(duration / ctrl.h)), int(round(1.0 / ctrl.h))
    hats = []
    with Progress(steps, f"{label:>20s}") as bar:
        for k in range(steps):
            q = sim.q + sq * rng.standard_normal(model.n)
            qd = sim.qd + sqd * rng.standard_normal(model.n)
            sim.step(ctrl.step(q, qd, *traj(k * ctrl.h)))
            if (k + 1) % every == 0:
                hats.append(ctrl.theta_hat)
                bar.update(k)
    return np.array(hats)


def run_noise_sources(duration=600.0, out_dir="results/noise"):
    """Where does the paper law's drift come from? Its deviation from the clean run with
    the noise on q only, on qd only, another seed, half the noise, and gamma = 0 (the
    tracking term alone, against its own clean run). Writes ``sources.json``, ``.png``."""
    model = css_arm()
    gamma0 = PAPER_GAINS["gamma"]
    clean = {g: _estimates(model, 0.0, 0.0, g, duration, 0, f"clean, gamma = {g:g}")
             for g in (gamma0, 0.0)}
    report, final = {}, {}
    for label, (fq, fqd, gamma, seed) in SOURCES.items():
        g = gamma0 if gamma is None else gamma
        hats = _estimates(model, fq * SIGMA_Q, fqd * SIGMA_QD, g, duration, seed, label)
        dev = np.linalg.norm(hats - clean[g], axis=(1, 2))
        final[label] = (hats[-1] - clean[g][-1]).ravel()
        report[label] = {"sigma_q": fq * SIGMA_Q, "sigma_qd": fqd * SIGMA_QD, "gamma": g,
                         "seed": seed, "deviation": [round(x, 1) for x in dev.tolist()],
                         "deviation_end": float(dev[-1]),
                         "theta_norm_end": float(np.linalg.norm(hats[-1]))}
    ref = final["both"]
    for label, d in final.items():
        report[label]["cosine_with_both"] = float(d @ ref / max(
            np.linalg.norm(d) * np.linalg.norm(ref), 1e-300))
        r = report[label]
        print(f"{label:>20s}: deviation from clean {r['deviation_end']:8.1f}  cosine with "
              f"'both' {r['cosine_with_both']:+.4f}", flush=True)
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, "sources.json"), "w", encoding="utf-8") as f:
        json.dump(dict(report, settings=dict(duration=duration)), f, separators=(",", ":"))
    from rcac_ros.tools.plots import plt, save
    fig, ax = plt.subplots(figsize=(8, 4))
    for label, r in report.items():
        ax.plot(np.arange(1, len(r["deviation"]) + 1) / 60.0, r["deviation"], lw=1.0,
                label=f"{label} ({r['deviation_end']:.0f})")
    ax.set_xlabel("time (min)")
    ax.set_ylabel("||theta_hat - theta_hat(clean)||")
    ax.set_title("Paper law: which noise and which term drive the drift")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save(fig, os.path.join(out_dir, "sources.png"), 80)
    print(f"wrote {out_dir}/sources.json, sources.png")
    return report
