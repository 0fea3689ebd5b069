"""``rcac friction-ros``: the joint terms over ROS 2, friction-blind and friction-aware.

Two runs of ``rcac demo`` (:func:`~rcac_ros.tools.demos.demo.run_demo`: the simulator and
the controller as two processes over real DDS, in lockstep, one bag each): the simulator on
MuJoCo (``engine: mujoco``) with the paper's arm whose joints have armature, viscous damping
and dry friction (:data:`TRUTH`, MuJoCo's friction loss for the dry friction, doc/plants.md),
the controller on the rigid arm, first as configured (friction-blind), then with
``joint_friction: true`` and nothing else (the joint terms' default gain, doc/design.md §7).
The bags are read back with rosbags; the figure holds both runs' tracking errors and the
aware run's joint estimates against the plant's values, ``metrics.json`` their RMS.

The controller publishes ``~/tracking_error`` once per ``monitor_decimation`` steps; the
figure spreads those messages evenly over the run's simulated time.
"""

import json
import os
import sys

import numpy as np

from rcac_ros import topics
from rcac_ros.tools.args import output_dir, positive_float

#: The plant's joint terms on every joint: armature kg m^2, damping N m s/rad, friction N m;
#: at the scale of the paper's arm and of its feedback ``K_D = 1e4 I6`` (the Panda-sized
#: 0.1, 0.5, 0.5 change the blind law's RMS error there by under 1 %, measured).
TRUTH = (5.0, 200.0, 100.0)
NAMES = ("armature", "damping", "friction")


def plant_model_file(path):
    """Write the paper's arm with :data:`TRUTH` on every joint as a YAML model file."""
    import yaml
    from rcac_ros.core import css_arm
    plant = css_arm().replace(armature=TRUTH[0], damping=TRUTH[1], friction=TRUTH[2])
    with open(path, "w", encoding="utf-8") as f:
        yaml.safe_dump(plant.to_dict(), f)
    return path


def bag_series(bag):
    """``(tracking errors (k, n), joint estimates (k, n, 3) or None)`` of a bag."""
    from rcac_ros.tools.bags.read import read_bag
    from rcac_ros.tools.bags.verify import find_bag
    data = read_bag(find_bag(bag))

    def values(name):
        td = data.get(topics.resolve(name))
        return None if td is None or td.count == 0 else np.array(td.values)
    err = values(topics.TRACKING_ERROR)
    est = values(topics.FRICTION_ESTIMATES)
    return err, None if est is None else est.reshape(len(est), -1, 3)


def rms(err):
    """RMS of the tracking errors; None where the bag holds none."""
    return None if err is None else float(np.sqrt(np.mean(np.square(err))))


def plot(duration, runs, path):
    from rcac_ros.tools.plots import plt
    fig, axes = plt.subplots(1, 4, figsize=(18, 4.2))
    for label, (err, _) in runs.items():
        if err is None:
            continue
        t = np.linspace(0.0, duration, len(err))
        axes[0].semilogy(t, np.linalg.norm(err, axis=1) + 1e-12, lw=0.8, label=label)
    axes[0].set_title("|q - q_d| (rad)")
    axes[0].set_xlabel("t [s]")
    axes[0].legend()
    est = runs["aware"][1]
    if est is not None:
        t = np.linspace(0.0, duration, len(est))
        for c in range(3):
            ax = axes[c + 1]
            for j in range(est.shape[1]):
                ax.plot(t, est[:, j, c], lw=0.8, label=f"joint {j + 1}")
            ax.axhline(TRUTH[c], color="k", ls="--", lw=1.0, label="plant")
            # linear up to the decade of the plant's value, logarithmic beyond: the plant's
            # line stays readable beside estimates that take up link errors (doc/tools.md)
            ax.set_yscale("symlog", linthresh=10.0 ** np.floor(np.log10(TRUTH[c])))
            ax.set_title(f"{NAMES[c]} estimate (aware)")
            ax.set_xlabel("t [s]")
        axes[1].legend(fontsize=7, ncol=2)
    fig.suptitle("Over ROS 2, MuJoCo plant with joint friction: friction-blind and "
                 "joint_friction: true")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def add_arguments(parser):
    parser.add_argument("--duration", type=positive_float, default=20.0,
                        help="simulated seconds per run (default: 20)")
    parser.add_argument("--out", "-o", type=output_dir, default="results/friction_ros",
                        help="output directory")


def run(args):
    from rcac_ros.tools.demos.demo import run_demo
    from rcac_ros.tools.launch import NodeFailed
    out = os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)
    plant = plant_model_file(os.path.join(out, "plant.yaml"))
    sim = {"engine": "mujoco", "model": plant}
    runs, bags = {}, {}
    for label, ctrl in (("blind", {}), ("aware", {"joint_friction": True})):
        try:
            bags[label] = run_demo(args.duration, os.path.join(out, label),
                                   controller_overrides=ctrl, simulator_overrides=sim,
                                   prog=f"rcac friction-ros ({label})")
        except KeyboardInterrupt:
            print(f"rcac friction-ros: interrupted; both nodes stopped; the {label} run's bag "
                  f"is closed in {os.path.join(out, label, 'bag')}", file=sys.stderr)
            return 130
        except NodeFailed as err:
            print(f"rcac friction-ros: error ({label}): {err}", file=sys.stderr)
            return 1
        runs[label] = bag_series(bags[label])
    report = {"duration_s": args.duration, "plant_joint_terms": dict(zip(NAMES, TRUTH)),
              "bags": bags,
              "rms_tracking_error_rad": {k: rms(v[0]) for k, v in runs.items()}}
    est = runs["aware"][1]
    if est is not None:
        report["final_joint_estimates"] = est[-1].tolist()
    with open(os.path.join(out, "metrics.json"), "w", encoding="utf-8") as f:
        json.dump(report, f, indent=2)
    plot(args.duration, runs, os.path.join(out, "friction_ros.png"))
    print(json.dumps(report["rms_tracking_error_rad"], indent=2))
    print(f"wrote {out}/metrics.json, {out}/friction_ros.png and the bags")
    return 0
