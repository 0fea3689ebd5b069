"""``rcac friction-demo``: the Panda learns its joints' armature, viscous and Coulomb friction.

The plant is the built-in simulator with the joint terms of doc/design.md §7 inside the
law's model class: the Panda of example-robot-data with armature 0.1 kg m^2, damping 0.5
N m s/rad and Coulomb friction 0.5 N m (``tanh(qd / v_c)``, v_c = 0.1 rad/s) on every joint,
the values of the MuJoCo scenario of ``rcac compare``. The law is the recursive composite
law with ``joint_friction=True``, every channel (``channels="all"``), the library's default
joint gain (doc/design.md §7) and ``hold_compensation=True`` (``--no-hold-compensation``: the
plain hold), starting from zero joint estimates; the links are the URDF's, the last
adapting from it as in the payload demo (every one with ``--adapt-links``, none with
``--links-known``). The desired motion excites every joint in both directions: a sinusoid of
0.4 rad per joint about the "ready" posture, 0.35-0.55 Hz (peak speeds 0.9-1.4 rad/s).

Known limit: joint 1's armature and link 1's inertia about the joint 1 axis enter the
dynamics only as their sum (the base joint's axis is fixed), so with ``--adapt-links`` the
armature of joint 1 is not identifiable alone; by default only the last link adapts.

Writes ``metrics.json`` and ``friction_estimates.png`` (estimates against the truth).
"""

import argparse
import json
import os

import numpy as np

from rcac_ros.core import SinusoidTrajectory
from rcac_ros.core.law_options import FRICTION_ADAPTATIONS, P_FRICTION
from rcac_ros.tools.args import output_dir, positive_float
from rcac_ros.tools.runs.scenarios import GAINS, READY, gains_for, load_panda

#: The true joint terms of every joint: armature kg m^2, damping N m s/rad, friction N m.
TRUTH = (0.1, 0.5, 0.5)
#: The excitation: amplitude (rad) and frequency (Hz) of each joint's sinusoid.
AMPLITUDE = (0.4,) * 7
FREQUENCY = (0.35, 0.4, 0.45, 0.38, 0.5, 0.42, 0.55)
#: The goals (relative error after the run): armature and viscous 10 %, Coulomb 15 %.
GOALS = (0.10, 0.10, 0.15)
NAMES = ("armature", "damping", "friction")


def run_friction_demo(duration=30.0, adapt_links=False, channels="all",
                      P_friction=P_FRICTION, record_every=25, links_known=False,
                      friction_adaptation="gradient", hold_compensation=True):
    """The closed loop; returns ``(t, friction_hat history (k, n, 3), truth (n, 3), rms)``.
    ``links_known``: no link adapts (every link the URDF's, the truth)."""
    from rcac_ros.core import RecursiveCompositeController, Simulator
    if adapt_links and links_known:
        raise ValueError("adapt_links and links_known: choose one")
    rigid = load_panda()
    plant = rigid.replace(armature=TRUTH[0], damping=TRUTH[1], friction=TRUTH[2])
    traj = SinusoidTrajectory(np.array(READY), AMPLITUDE, FREQUENCY)
    gains = gains_for(rigid, adapt_all=adapt_links, **GAINS)
    if links_known:
        gains["P"][-1] = gains["P"][0]              # the fixed law's gain: no link adapts
    ctrl = RecursiveCompositeController(
        rigid, channels=channels, joint_friction=True, P_friction=P_friction,
        friction_adaptation=friction_adaptation, hold_compensation=hold_compensation,
        **gains)
    q0, qd0, _ = traj(0.0)
    sim = Simulator(plant, dt=ctrl.h, q0=q0, qd0=qd0)
    steps = int(round(duration / ctrl.h))
    ts, hist, sq = [], [], 0.0
    for k in range(steps):
        q_d, qd_d, qdd_d = traj(k * ctrl.h)
        sq += float(np.mean(np.square(sim.q - q_d)))
        sim.step(ctrl.step(sim.q, sim.qd, q_d, qd_d, qdd_d))
        ctrl.set_applied_torque(sim.applied)
        if (k + 1) % record_every == 0:
            ts.append((k + 1) * ctrl.h)
            hist.append(ctrl.friction_hat)
    return np.array(ts), np.array(hist), plant.joint_terms(), float(np.sqrt(sq / steps))


def summarise(hist, truth):
    """Final relative errors per joint and term, and whether each goal is met."""
    rel = np.abs(hist[-1] - truth) / truth
    worst = rel.max(axis=0)
    return {"final_estimates": hist[-1].tolist(), "relative_error": rel.tolist(),
            "worst_relative_error": dict(zip(NAMES, worst.tolist())),
            "goals": dict(zip(NAMES, GOALS)),
            "met": dict(zip(NAMES, (bool(w <= g) for w, g in zip(worst, GOALS))))}


def plot(t, hist, truth, path, title):
    from rcac_ros.tools.plots import plt as mpl     # matplotlib with the Agg backend
    fig, axes = mpl.subplots(1, 3, figsize=(16, 4.2))
    for c, ax in enumerate(axes):
        for j in range(hist.shape[1]):
            ax.plot(t, hist[:, j, c], lw=0.9, label=f"joint {j + 1}")
        ax.axhline(truth[0, c], color="k", ls="--", lw=1.0, label="truth")
        ax.axhspan(truth[0, c] * (1 - GOALS[c]), truth[0, c] * (1 + GOALS[c]), color="0.85",
                   zorder=0, label=f"goal ±{GOALS[c]:.0%}")
        ax.set_title(NAMES[c])
        ax.set_xlabel("t [s]")
        ax.set_ylim(0.0, 2.0 * truth[0, c])
    axes[0].legend(fontsize=7, ncol=2)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    mpl.close(fig)


def add_arguments(parser):
    parser.add_argument("--duration", type=positive_float, default=30.0, help="seconds")
    links = parser.add_mutually_exclusive_group()
    links.add_argument("--adapt-links", action="store_true",
                       help="the links adapt too, from the URDF's nominal parameters")
    links.add_argument("--links-known", action="store_true",
                       help="no link adapts (the URDF's are the plant's)")
    parser.add_argument("--friction-adaptation", choices=FRICTION_ADAPTATIONS,
                        default="gradient", help="the joint terms' gain (doc/design.md §7)")
    parser.add_argument("--hold-compensation", action=argparse.BooleanOptionalAction,
                        default=True, help="efforts extrapolated to the middle of their "
                        "hold (doc/design.md §6; default on)")
    parser.add_argument("--out", type=output_dir, default="results/friction",
                        help="output directory")


def run(args):
    t, hist, truth, rms = run_friction_demo(args.duration, args.adapt_links,
                                            links_known=args.links_known,
                                            friction_adaptation=args.friction_adaptation,
                                            hold_compensation=args.hold_compensation)
    report = summarise(hist, truth)
    report.update(duration_s=args.duration, adapt_links=args.adapt_links,
                  links_known=args.links_known, friction_adaptation=args.friction_adaptation,
                  hold_compensation=args.hold_compensation,
                  rms_error_rad=rms, P_friction=P_FRICTION, channels="all")
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "metrics.json"), "w", encoding="utf-8") as f:
        json.dump(report, f, indent=2)
    links = "links adapting" if args.adapt_links else \
        "links known" if args.links_known else "last link adapting"
    if args.friction_adaptation != "gradient":
        links += f", joint terms by {args.friction_adaptation.replace('_', ' ')}"
    if not args.hold_compensation:
        links += ", plain hold"
    plot(t, hist, truth, os.path.join(args.out, "friction_estimates.png"),
         f"Panda, built-in simulator with tanh friction: joint estimates ({links}, "
         f"channels='all', {args.duration:g} s)")
    print(f"{'joint':>5s} " + " ".join(f"{n:>10s}" for n in NAMES) + "   (estimate / truth "
          f"{TRUTH})")
    for j, row in enumerate(hist[-1]):
        print(f"{j + 1:5d} " + " ".join(f"{v:10.4f}" for v in row))
    for name in NAMES:
        w, g = report["worst_relative_error"][name], report["goals"][name]
        print(f"worst {name:9s} error {w:7.1%}  (goal {g:.0%}: "
              f"{'met' if w <= g else 'NOT met'})")
    return 0
