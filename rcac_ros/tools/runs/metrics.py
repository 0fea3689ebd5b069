"""Every figure of merit of the tools, defined once.

``rcac experiment`` computes them from its arrays, ``rcac inspect`` from a bag, the payload
demo and the ROS benchmark from their own runs; all call these functions, so a figure
with the same name means the same thing everywhere. Errors are ``q - q_d`` (rad),
estimates ``theta_hat`` of shape (T, n, 13), torques in N m.
"""

import numpy as np

#: seconds at the end of a run for ``rms_tracking_error_last_5s``
LAST_WINDOW = 5.0


def rms(x):
    """Root mean square of every entry of ``x``."""
    return float(np.sqrt(np.mean(np.square(x))))


def window_rms(t, e, start, stop):
    """RMS of the errors ``e`` (T, n) over all joints for ``start <= t < stop``."""
    sel = (t >= start) & (t < stop)
    return rms(e[sel])


def tracking(t, e, last=LAST_WINDOW):
    """``rms_tracking_error``, ``max_tracking_error`` and ``rms_tracking_error_last_5s``."""
    return {"rms_tracking_error": rms(e),
            "max_tracking_error": float(np.max(np.abs(e))),
            "rms_tracking_error_last_5s": rms(e[t >= t[-1] - last])}


def estimates(theta_hat, theta_true):
    """Norm of ``theta_hat - theta`` at the start and the end, all links and the last one."""
    err = np.asarray(theta_hat) - theta_true
    return {"parameter_error_norm_start": float(np.linalg.norm(err[0])),
            "parameter_error_norm_end": float(np.linalg.norm(err[-1])),
            f"link{err.shape[1]}_parameter_error_norm_end": float(np.linalg.norm(err[-1, -1]))}


def prediction(E):
    """``final_abs_prediction_error``: |E| of eq 24 at the last step (the largest channel's)."""
    return {"final_abs_prediction_error": float(np.max(np.abs(np.asarray(E)[-1])))}


def torque(tau):
    """``max_abs_torque`` over every joint and step."""
    return {"max_abs_torque": float(np.max(np.abs(tau)))}


def percentiles(x, prefix, unit="ms"):
    """``{prefix}_p50_{unit}``, ``_p99_`` and ``_max_`` of ``x`` (``None`` each when empty)."""
    x = np.asarray(x, dtype=float)
    keys = (f"{prefix}_p50_{unit}", f"{prefix}_p99_{unit}", f"{prefix}_max_{unit}")
    if x.size == 0:
        return dict.fromkeys(keys)
    return dict(zip(keys, (float(np.percentile(x, 50)), float(np.percentile(x, 99)),
                           float(np.max(x)))))
