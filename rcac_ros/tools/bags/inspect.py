"""``rcac inspect``: verify and summarise a bag of the package's topics, compute metrics, plot.

The bag (or the single bag in a folder) is first verified (:func:`.verify.verify`: CRCs, counts,
sqlite's integrity check); a damaged or cut bag is one line and exit 2, and ``--recover``
salvages it (:func:`.recover.recover`). The summary starts with the header ``ros2 bag info``
prints, then lists every topic (type, count, rate from the message stamps) and the bag's
duration. The metrics are those of ``rcac experiment`` that the bag allows (tracking errors,
estimate errors against the model's true parameters, prediction error, torques) plus the loop
timing (period between joint states, latency from a joint state to the effort that answers
it), from the publishers' send stamps when the bag holds them.

Times on the plots are simulated time: a joint state carries it in its header;
the controller's outputs take the header stamp of the ``desired_state`` published
in the same callback (nearest receive stamp), else that of the latest joint
state received before them.
"""
import json
import os

import numpy as np

from rcac_ros import topics
from rcac_ros.errors import ConfigError
from rcac_ros.tools.args import node_name, output_dir, positive_int
from rcac_ros.tools.bags.recover import default_recovered_path, format_recovery, recover
from rcac_ros.tools.bags.verify import bag_info, find_bag, Report
from rcac_ros.tools.bags.analyse import analyse, joint_names, load_truth, notes
from rcac_ros.tools.bags.read import format_summary, read_bag, summary


def plot_timing(timing, path):
    """Histograms of the joint-state period and the state -> effort latency, captioned with
    the stamps they come from (see :func:`loop_timing`)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rcac_ros.tools.plots import save

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, key, title in ((axes[0], "period_ms", "period between joint states"),
                           (axes[1], "latency_ms", "joint state -> effort latency")):
        x = timing[key]
        if len(x):
            hi = np.percentile(x, 99.9) * 1.2 + 1e-3
            ax.hist(np.clip(x, 0, hi), bins=80, range=(0, hi), color="C0")
            ax.axvline(np.median(x), color="C1", ls="--",
                       label=f"median {np.median(x):.3f} ms")
            ax.axvline(np.percentile(x, 99), color="C3", ls=":",
                       label=f"p99 {np.percentile(x, 99):.3f} ms")
            ax.legend()
        ax.set_xlabel("ms")
        ax.set_ylabel("count")
        ax.set_title(title)
    if timing.get("clock") == "send":
        caption = ("From the publishers' send stamps (simulator: joint state published; "
                   "controller: effort published), same host clock.")
    else:
        caption = ("From the recorder's receive stamps: when the recorder is descheduled, the "
                   "messages queued meanwhile are stamped together,\nso a cluster near 0 ms "
                   "is the recorder catching up, not the loop.")
    fig.text(0.01, 0.01, caption, fontsize=8, va="bottom")
    save(fig, path, 110, rect=(0, 0.08, 1, 1))


def write_plots(series, out_dir, theta_true=None, names=None, link=None, label="ROS 2"):
    """Write the figures of the offline experiment from the bag's series.

    Returns
    -------
    list of str
        Paths written.
    """
    from rcac_ros.tools import plots

    os.makedirs(out_dir, exist_ok=True)
    written = []
    if "tracking_error" in series:
        t, e = series["tracking_error"]
        path = os.path.join(out_dir, "tracking_errors.png")
        plots.plot_tracking_errors(t, {label: e}, path, joint_names=names)
        written.append(path)
    if "effort" in series:
        t, tau = series["effort"]
        path = os.path.join(out_dir, "efforts.png")
        plots.plot_series(t, {label: tau}, path, "joint efforts (effort_controller/commands)",
                          "torque (N m)", legend=names)
        written.append(path)
    if "parameter_estimates" in series:
        t, est = series["parameter_estimates"]
        k = est.shape[1] - 1 if link is None else link - 1
        if not 0 <= k < est.shape[1]:
            raise ConfigError(f"link: must be in 1..{est.shape[1]}, got {link}")
        truth = None
        if theta_true is not None and theta_true.shape == est.shape[1:]:
            truth = theta_true[k]
        path = os.path.join(out_dir, f"estimates_link{k + 1}.png")
        plots.plot_parameter_estimates(t, {label: est[:, k, :]}, truth, path, link=k + 1)
        written.append(path)
    if "prediction_error" in series:
        t, pr = series["prediction_error"]
        path = os.path.join(out_dir, "prediction_error.png")
        plots.plot_series(t, {label: np.asarray(pr).reshape(-1, 1)}, path,
                          "prediction error |E| (eq 24), log scale", "|E| (N m)", logy=True)
        written.append(path)
    if "prediction_errors" in series:
        t, prs, channels = series["prediction_errors"]
        path = os.path.join(out_dir, "prediction_errors.png")
        plots.plot_series(t, {label: prs}, path,
                          "prediction error |E_c| per channel (eq 24), log scale",
                          "|E_c| (N m; W for power)", logy=True, legend=channels)
        written.append(path)
    if "timing" in series:
        path = os.path.join(out_dir, "loop_timing.png")
        plot_timing(series["timing"], path)
        written.append(path)
    return written


def inspect(path, plots_dir=None, model="css_arm", link=None,
            controller_node=topics.CONTROLLER_NODE):
    """Read, summarise and (optionally) plot a bag; write metrics.json beside the plots.

    Returns
    -------
    dict
        ``{"summary", "metrics", "plots", "metrics_path"}``.
    """
    theta_true = load_truth(model)               # a bad --model stops before the bag is read
    path = find_bag(path)
    report = Report(path, "")
    data = read_bag(path, report)
    summ = summary(data)
    summ["info"] = bag_info(path)
    summ["checks"] = list(report.checks)
    metrics, series = analyse(data, theta_true, controller_node)
    result = {"summary": summ, "metrics": metrics, "plots": [], "metrics_path": None,
              "bag": path, "notes": notes(metrics, summ)}
    if plots_dir is not None:
        result["plots"] = write_plots(series, plots_dir, theta_true, joint_names(data), link)
        result["metrics_path"] = os.path.join(plots_dir, "metrics.json")
        with open(result["metrics_path"], "w") as f:
            json.dump({"bag": os.path.abspath(path), "summary": summ, "metrics": metrics}, f,
                      indent=2)
    return result


def format_metrics(metrics):
    width = max([len(k) for k in metrics] + [1])
    lines = []
    for key, value in metrics.items():
        text = f"{value:.6g}" if isinstance(value, float) else str(value)
        lines.append(f"  {key:<{width}}  {text}")
    return "\n".join(lines)


def add_arguments(parser):
    parser.add_argument("bag", help="rosbag2 directory (or a folder holding one bag)")
    parser.add_argument("--recover", action="store_true",
                        help="salvage a bag cut by a crash or damaged (complete mcap chunks, "
                             "committed sqlite transactions) into a new bag, then inspect it")
    parser.add_argument("--recover-out", type=output_dir, default=None, metavar="DIR",
                        help="the recovered bag (default: BAG_recovered)")
    parser.add_argument("--plots", type=output_dir, default=None, metavar="DIR",
                        help="write the figures and metrics.json into DIR")
    parser.add_argument("--model", default="css_arm",
                        help="true model for the estimate errors: 'css_arm' (default, the paper's "
                             "arm), 'none', or a model YAML / URDF")
    parser.add_argument("--link", type=positive_int, default=None,
                        help="link (1-based) whose estimates are plotted (default: the last)")
    parser.add_argument("--controller-node", type=node_name, default=topics.CONTROLLER_NODE,
                        help=f"controller node name (default: {topics.CONTROLLER_NODE})")


def run(args):
    bag = args.bag
    if args.recover:
        bag = find_bag(bag)
        report = recover(bag, args.recover_out or default_recovered_path(bag))
        print(format_recovery(bag, report), flush=True)
        bag = report.path
    result = inspect(bag, args.plots, args.model, args.link, args.controller_node)
    print(format_summary(result["bag"], result["summary"]))
    if result["metrics"]:
        print("Metrics:")
        print(format_metrics(result["metrics"]))
    for line in result["notes"]:
        print(f"Note: {line}")
    for path in result["plots"]:
        print(f"wrote {path}")
    if result["metrics_path"]:
        print(f"wrote {result['metrics_path']}")
    return 0
