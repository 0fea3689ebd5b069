"""The figures shared by ``rcac experiment``, ``rcac inspect`` and the demos (matplotlib, Agg)."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rcac_ros.core.model import PARAMETER_NAMES  # noqa: E402


def save(fig, path, dpi, rect=None):
    """Lay out ``fig`` (within ``rect`` if given), write it to ``path`` and close it."""
    if rect is None:
        fig.tight_layout()
    else:
        fig.tight_layout(rect=rect)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def plot_tracking_errors(t, errors, path, joint_names=None, title="Joint tracking errors"):
    """Figure 3's equivalent: ``q - q_d`` of every joint, one panel per law, side by side.

    Parameters
    ----------
    t : array_like (T,)
    errors : dict of label -> array_like (T, n)
    path : str or Path
    """
    labels = list(errors)
    fig, axes = plt.subplots(1, len(labels), figsize=(6 * len(labels), 4), sharey=True,
                             squeeze=False)
    for ax, label in zip(axes[0], labels):
        e = np.asarray(errors[label])
        names = joint_names or [f"joint {j + 1}" for j in range(e.shape[1])]
        for j in range(e.shape[1]):
            ax.plot(t[:len(e)], e[:, j], lw=0.9, label=names[j])
        ax.set_title(label)
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("q - q_d (rad)")
    axes[0][-1].legend(fontsize=7, loc="upper right", ncol=2)
    fig.suptitle(title)
    save(fig, path, 120)


def plot_parameter_estimates(t, estimates, theta_true, path, link=7, names=PARAMETER_NAMES):
    """Figure 4's equivalent: the 13 estimates of one link against their true values.

    One panel per parameter; each law is a line, the truth a dashed black line.

    Parameters
    ----------
    t : array_like (T,)
    estimates : dict of label -> array_like (T, 13)
    theta_true : array_like (13,) or None
    """
    fig, axes = plt.subplots(3, 5, figsize=(17, 8.5), sharex=True)
    axes = axes.ravel()
    for k in range(13):
        ax = axes[k]
        for label, est in estimates.items():
            est = np.asarray(est)
            ax.plot(t[:len(est)], est[:, k], lw=1.0, label=label)
        if theta_true is not None:
            ax.axhline(theta_true[k], color="k", ls="--", lw=0.9, label="true")
        ax.set_title(f"theta_{k + 1}: {names[k]}", fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes[13:]:
        ax.axis("off")
    axes[0].legend(fontsize=8)
    for ax in axes[8:13]:
        ax.set_xlabel("time (s)")
    fig.suptitle(f"Link {link} parameter estimates")
    save(fig, path, 110)


def plot_series(t, series, path, title, ylabel, logy=False, legend=None):
    """A generic figure: one panel per label, each (T,) or (T, k) series plotted against t.

    ``legend`` names the k columns (e.g. joint names); default ``joint 1..k`` when k > 1.
    With ``logy``, |y| is plotted on a log scale.
    """
    labels = list(series)
    fig, axes = plt.subplots(1, len(labels), figsize=(6 * len(labels), 4), sharey=True,
                             squeeze=False)
    for ax, label in zip(axes[0], labels):
        y = np.asarray(series[label])
        y = y[:, None] if y.ndim == 1 else y
        names = legend or [f"joint {j + 1}" for j in range(y.shape[1])]
        for j in range(y.shape[1]):
            (ax.semilogy if logy else ax.plot)(t[:len(y)], np.abs(y[:, j]) if logy else y[:, j],
                                               lw=0.9, label=names[j])
        if y.shape[1] > 1:
            ax.legend(fontsize=7, loc="upper right", ncol=2)
        ax.set_title(label)
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel(ylabel)
    fig.suptitle(title)
    save(fig, path, 120)
