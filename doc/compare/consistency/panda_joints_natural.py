"""doc/compare/consistency/panda_joints_natural.png (doc/design.md §8, "Unmodelled joint
effects"): run from the repository root,
PYTHONPATH=$PWD python doc/compare/consistency/panda_joints_natural.py"""
import numpy as np, matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
from rcac_ros.tools.demos import compare as C
from rcac_ros.tools.closed_loop import closed_loop
from rcac_ros.core.pseudo_inertia import pseudo_inertia
runs = {}
laws = dict(C.LAWS)
cases = [("panda_rigid", "paper"), ("panda_rigid", "paper_natural"),
         ("panda_friction", "paper"), ("panda_friction", "paper_natural"),
         ("panda_joints", "paper"), ("panda_joints", "paper_natural"),
         ("panda_joints", "paper_natural_friction")]
for scn, law in cases:
    sc = C.SCENARIOS[scn]()
    ctrl = C.make_controller(sc, law, laws)
    lam0 = np.linalg.eigvalsh(pseudo_inertia(ctrl.theta_hat))[:, -1]
    grow = []
    def obs(k, c, sim):
        grow.append(np.max(np.linalg.eigvalsh(pseudo_inertia(c.theta_hat))[:, -1] / lam0))
    run = closed_loop(ctrl, sc.trajectory, 20.0, plant=sc.plant, q0=sc.q0, qd0=sc.qd0,
                      check_estimates=True, engine=sc.engine, observer=obs)
    e = np.max(np.abs(run["q"] - run["q_d"]), axis=1)
    t = run["t"]
    ok = np.isfinite(e)
    rms = np.sqrt(np.mean(np.square((run["q"] - run["q_d"])[ok])))
    print(scn, law, run["status"], "t_end %.3f" % t[-1], "rms %.3g" % rms, "max growth %.3g" % np.nanmax(grow), flush=True)
    runs[(scn, law)] = (t, e, np.array(grow[:len(t)]))
fig, ax = plt.subplots(2, 3, figsize=(14, 7), sharex=True)
for j, scn in enumerate(("panda_rigid", "panda_friction", "panda_joints")):
    for (s, law), (t, e, g) in runs.items():
        if s != scn: continue
        ax[0, j].semilogy(t, e, label=law, lw=0.7)
        ax[1, j].semilogy(t[:len(g)], g, label=law, lw=0.7)
    ax[0, j].set_title(scn)
    ax[0, j].set_ylim(1e-6, 1e2)
    ax[1, j].set_ylim(0.5, 1e12)
    ax[1, j].set_xlabel("t (s)")
ax[0, 0].set_ylabel("max_i |q_i - q_d,i| (rad)")
ax[1, 0].set_ylabel("max_i lambda_max(J_hat_i) / at start")
ax[0, 2].legend(fontsize=8); ax[1, 2].legend(fontsize=8)
fig.tight_layout()
fig.savefig("doc/compare/consistency/panda_joints_natural.png", dpi=90)
