"""The figure doc/compare/consistency/payload_natural_gain.png (doc/design.md §8, "Why the
natural law tracks the payload worse"). Run from the repository root::

    PYTHONPATH=$PWD python doc/compare/consistency/payload_natural_gain.py

The payload scenario of ``rcac compare`` (link 7 adapting from the URDF's inertials, a 2 kg
payload at 5 s) with the paper's channel: the Euclidean law, the natural law, and the
Euclidean law whose gain is the natural law's gain at the start, ``P_eff(theta_hat0)``
(the natural law's gain frozen, without its geometry). Left: the largest joint error.
Right: along directions of link 7's pseudo-inertia, the natural gain ``k J_hat G J_hat``
over the Euclidean ``P`` as the estimates move (the ratio ``d^T P_eff d / d^T P d`` with
``d`` a unit change of J's mass, first-moment and second-moment entries, and the payload's
change of J).
"""
import matplotlib
import numpy as np

from rcac_ros.core.pseudo_inertia import (_entries, matched_gain, natural_gains_into, nu_gain,
                                          pseudo_inertia)
from rcac_ros.tools.closed_loop import closed_loop
from rcac_ros.tools.demos import compare
from rcac_ros.tools.scenarios import controller

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend)

#: 13-parameter directions of J's entries (theta -> J is linear: d_theta solves J(d) = E).
DIRECTIONS = {"mass": (3, 3), "h_x": (0, 3), "h_y": (1, 3), "h_z": (2, 3),
              "Sigma_xx": (0, 0), "Sigma_zz": (2, 2)}


def theta_of(J):
    """The least-norm 13 parameters whose pseudo-inertia is ``J`` (4x4 symmetric)."""
    A = np.array([_entries(pseudo_inertia(e)) for e in np.eye(13)]).T      # 10 x 13
    return np.linalg.lstsq(A, _entries(J), rcond=None)[0]


def theta_direction(i, j):
    """The 13 parameters whose J is the symmetric unit matrix at (i, j)."""
    E = np.zeros((4, 4))
    E[i, j] = E[j, i] = 1.0
    return theta_of(E)


def natural_gain(theta, k, P):
    """P_eff(theta) (n, 13, 13) of the natural law with gains k, P (doc/design.md §8)."""
    out = np.empty((len(theta), 169))
    natural_gains_into(np.ascontiguousarray(theta), k, nu_gain(P).reshape(len(P), 9), out)
    G = out.reshape(-1, 13, 13)
    return 0.5 * (G + G.transpose(0, 2, 1))


def run(sc, kind, extra, duration):
    ctrl = controller(kind, sc.model, dict(sc.gains, **extra))
    rows = []
    r = closed_loop(ctrl, sc.trajectory, duration, plant=sc.plant, q0=sc.q0, qd0=sc.qd0,
                    events=((sc.jump, sc.loaded),), check_estimates=True,
                    observer=lambda k, c, sim: rows.append(c.theta_hat[-1].copy()))
    return r["t"], np.max(np.abs(r["q"] - r["q_d"]), axis=1), np.array(rows)


def main(duration=20.0, path="doc/compare/consistency/payload_natural_gain.png"):
    sc = compare.payload_scenario()
    P, th0 = sc.gains["P"], sc.gains["theta_hat0"]
    k = matched_gain(P, th0)
    frozen = P.copy()
    frozen[-1] = natural_gain(th0, k, P)[-1]
    runs = {"Euclidean (paper)": run(sc, "rcac", {}, duration),
            "natural (paper_natural)": run(sc, "rcac", dict(geometry="natural"), duration),
            "Euclidean, P = P_eff(theta_hat0)": run(sc, "rcac", dict(P=frozen), duration)}
    fig, axes = plt.subplots(1, 2, figsize=(14, 4.5))
    for label, (t, err, _) in runs.items():
        axes[0].semilogy(t, err + 1e-9, lw=0.7, label=label)
        print(f"{label}: max |e| {err.max():.3g} rad")
    t, _, th7 = runs["natural (paper_natural)"]
    dirs = {name: theta_direction(*ij) for name, ij in DIRECTIONS.items()}
    dirs["payload's change of J"] = theta_of(pseudo_inertia(sc.theta_end[-1] - th0[-1]))
    every = 25
    thetas = np.repeat(th0[None], len(th7[::every]), axis=0)
    thetas[:, -1] = th7[::every]
    gains = np.array([natural_gain(th, k, P)[-1] for th in thetas])
    for name, d in dirs.items():
        ratio = np.einsum("i,tij,j->t", d, gains, d) / (d @ P[-1] @ d)
        axes[1].semilogy(t[::every], ratio, lw=1.0, label=name)
        print(f"{name}: natural / Euclidean gain {ratio[0]:.3g} at the start, "
              f"{ratio[-1]:.3g} at the end")
    axes[0].set_title("max_j |q_j - q_d,j| (rad), payload scenario")
    axes[1].set_title("link 7: natural gain / Euclidean P along J's entries "
                      "(natural run's estimates)")
    for ax in axes:
        ax.axvline(sc.jump, color="grey", lw=0.6)
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[1].axhline(1.0, color="k", lw=0.8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
