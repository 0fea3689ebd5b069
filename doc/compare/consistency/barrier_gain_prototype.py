"""A prototype, not part of the package (doc/design.md §8, "Why the natural law tracks the
payload worse"): the natural law's gain replaced by that of the potential

    psi(theta) = -(1 / (c k)) log det J(theta) + 1/2 theta^T P^-1 theta

(the log-det barrier plus the Euclidean law's quadratic), whose gain, the inverse Hessian

    P_mix(theta_hat) = (A^T H(J_hat) A / (c k) + P^-1)^-1  <=  P

(``A``: theta -> J's 10 entries, ``H``: the Hessian of -log det J in them) is the Euclidean
law's away from the boundary of the cone and the barrier's near it. Run on the Slotine-Li
law, whose natural geometry takes explicit gains (``natural_gains_into``, here replaced),
with its retraction unchanged. Run from the repository root::

    PYTHONPATH=$PWD python doc/compare/consistency/barrier_gain_prototype.py [samples]

Prints the payload scenario (Slotine-Li, natural, P_mix with c = 1, 100, 1e4) and, on the
first ``samples`` paired samples of campaigns/consistency.yaml (default 8), the RMS ratio to
the Euclidean law per sample. Python gains: seconds per run.
"""
import sys

import numpy as np

import rcac_ros.core.slotine_li as slotine_li
from rcac_ros.core.pseudo_inertia import _entries, _unpack, lambda_min, pseudo_inertia
from rcac_ros.tools.closed_loop import closed_loop, run_metrics
from rcac_ros.tools.demos import compare
from rcac_ros.tools.scenarios import controller
from rcac_ros.tools.sweep import campaign as cp

A = np.array([_entries(pseudo_inertia(e)) for e in np.eye(13)]).T           # 10 x 13
BASIS = [_unpack(e) for e in np.eye(10)]
NATURAL = slotine_li.natural_gains_into


def barrier_gains(c, P):
    """A replacement of ``natural_gains_into``: ``P_mix`` per link (module docstring)."""
    P_inv = np.linalg.inv(P)

    def gains_into(theta, k, P_nu, out):
        for i in range(theta.shape[0]):
            J_inv = np.linalg.inv(pseudo_inertia(theta[i]))
            JE = [J_inv @ a for a in BASIS]
            H = np.array([[np.sum(x * y.T) for y in JE] for x in JE])   # tr(J^-1 a J^-1 b)
            out[i] = np.linalg.inv(A.T @ H @ A / (c * k[i]) + P_inv[i]).ravel()
    return gains_into


def run(ctrl, c=None, **kwargs):
    """One closed loop with the natural gains (c None) or P_mix; its run_metrics and the
    smallest lambda_min(J_hat_i) over the run."""
    slotine_li.natural_gains_into = NATURAL if c is None else barrier_gains(c, ctrl.P)
    try:
        r = closed_loop(ctrl, **kwargs)
    finally:
        slotine_li.natural_gains_into = NATURAL
    return run_metrics(r), float(lambda_min(r["theta_hat"]).min())


def payload():
    sc = compare.payload_scenario()
    loop = dict(trajectory=sc.trajectory, duration=20.0, plant=sc.plant, q0=sc.q0, qd0=sc.qd0,
                events=((sc.jump, sc.loaded),), check_estimates=True)
    cases = [("slotine_li", {}, None), ("slotine_li_natural", dict(geometry="natural"), None)]
    cases += [(f"barrier c = {c:g}", dict(geometry="natural"), c) for c in (1.0, 100.0, 1e4)]
    for label, extra, c in cases:
        ctrl = controller("slotine_li", sc.model, dict(sc.gains, **extra))
        m, lam = run(ctrl, c, **loop)
        est, true = ctrl.theta_hat[-1], sc.theta_end[-1]
        print(f"payload {label:20s} RMS {m['rms_tracking_error']:.3g} rad, min lambda_min "
              f"{lam:.3g}, payload |m~| {abs(est[0] - true[0]):.3g} kg, |h~| "
              f"{np.linalg.norm(est[1:4] - true[1:4]):.3g} kg m")


def campaign(samples):
    c = cp.load("campaigns/consistency.yaml")
    c["scenario"]["fixed"]["law"] = "slotine_li"
    ratios = {"natural": [], "barrier c = 100": []}
    for s in range(samples):
        _, ctrl, kw = cp.setup(c, 2 * s)
        base = run(ctrl, None, **kw)[0]["rms_tracking_error"]
        for label, cc in (("natural", None), ("barrier c = 100", 100.0)):
            _, ctrl, kw = cp.setup(c, 2 * s + 1)
            m, lam = run(ctrl, cc, **kw)
            ratios[label].append(m["rms_tracking_error"] / base)
            print(f"sample {s} {label}: RMS ratio {ratios[label][-1]:.3g} ({m['status']}, "
                  f"min lambda_min {lam:.3g})")
    for label, r in ratios.items():
        print(f"campaign, {label}: median RMS ratio {np.median(r):.3g} "
              f"[{min(r):.3g}, {max(r):.3g}] over {samples} paired samples")


if __name__ == "__main__":
    payload()
    campaign(int(sys.argv[1]) if len(sys.argv) > 1 else 8)
