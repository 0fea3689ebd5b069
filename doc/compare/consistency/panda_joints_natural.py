"""The figure doc/compare/consistency/panda_joints_natural.png (doc/design.md §8,
"Unmodelled joint effects"). Run from the repository root::

    PYTHONPATH=$PWD python doc/compare/consistency/panda_joints_natural.py
"""
import matplotlib
import numpy as np

from rcac_ros.core.pseudo_inertia import pseudo_inertia
from rcac_ros.tools.closed_loop import closed_loop
from rcac_ros.tools.demos import compare

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend)

CASES = [("panda_rigid", "paper"), ("panda_rigid", "paper_natural"),
         ("panda_friction", "paper"), ("panda_friction", "paper_natural"),
         ("panda_joints", "paper"), ("panda_joints", "paper_natural"),
         ("panda_joints", "paper_natural_friction")]


def run_case(scenario, law, duration=20.0):
    """One closed loop: time, the largest joint error, the largest growth of
    lambda_max(J_hat_i) over its start."""
    sc = compare.SCENARIOS[scenario]()
    ctrl = compare.make_controller(sc, law, dict(compare.LAWS))
    lam0 = np.linalg.eigvalsh(pseudo_inertia(ctrl.theta_hat))[:, -1]
    growth = []

    def observe(k, c, sim):
        growth.append(np.max(np.linalg.eigvalsh(pseudo_inertia(c.theta_hat))[:, -1] / lam0))

    run = closed_loop(ctrl, sc.trajectory, duration, plant=sc.plant, q0=sc.q0, qd0=sc.qd0,
                      check_estimates=True, engine=sc.engine, observer=observe)
    err = run["q"] - run["q_d"]
    ok = np.isfinite(err)
    print(scenario, law, run["status"], f"t_end {run['t'][-1]:.3f}",
          f"rms {np.sqrt(np.mean(np.square(err[ok]))):.3g}",
          f"max growth {np.nanmax(growth):.3g}", flush=True)
    return run["t"], np.max(np.abs(err), axis=1), np.array(growth[:len(run["t"])])


def main():
    runs = {case: run_case(*case) for case in CASES}
    fig, ax = plt.subplots(2, 3, figsize=(14, 7), sharex=True)
    for j, scenario in enumerate(("panda_rigid", "panda_friction", "panda_joints")):
        for (s, law), (t, e, g) in runs.items():
            if s == scenario:
                ax[0, j].semilogy(t, e, label=law, lw=0.7)
                ax[1, j].semilogy(t[:len(g)], g, label=law, lw=0.7)
        ax[0, j].set_title(scenario)
        ax[0, j].set_ylim(1e-6, 1e2)
        ax[1, j].set_ylim(0.5, 1e12)
        ax[1, j].set_xlabel("t (s)")
    ax[0, 0].set_ylabel("max_i |q_i - q_d,i| (rad)")
    ax[1, 0].set_ylabel("max_i lambda_max(J_hat_i) / at start")
    ax[0, 2].legend(fontsize=8)
    ax[1, 2].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig("doc/compare/consistency/panda_joints_natural.png", dpi=90)


if __name__ == "__main__":
    main()
