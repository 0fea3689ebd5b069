"""Per-joint gain overrides ``gains.<joint>.<gain>``, as joint_trajectory_controller's.

Every gain keeps its scalar parameter (``K_D``, ``Lambda``, ``P``); a parameter
``gains.<joint>.<gain>`` replaces it for one joint, and for the link that joint moves
(``K_Di`` of eq 19 and ``P_i`` of eq 24 belong to link i, keyed by its joint's name).
``gamma`` and ``lambda`` weigh the single prediction error of the whole arm: they have no
per-joint form. Pure: no rclpy.
"""

import numpy as np

from rcac_ros.errors import ConfigError
from rcac_ros.params import GAINS_PREFIX as PREFIX

#: the gains that have a per-joint (per-link) value in the core, with their size
PER_JOINT = {"K_D": 6, "Lambda": 1, "P": 13}


def parse_overrides(values, joint_names):
    """Check ``{"gains.<joint>.<gain>": value}``; return ``{gain: {joint: value}}``.

    Raises
    ------
    ConfigError
        One line naming the first bad parameter: an unknown joint, an unknown gain, a value
        that is not a finite number > 0.
    """
    out = {gain: {} for gain in PER_JOINT}
    for name in sorted(values):
        rest = name[len(PREFIX):] if name.startswith(PREFIX) else ""
        joint, _, gain = rest.rpartition(".")
        if not joint:
            raise ConfigError(f"{name}: expected {PREFIX}<joint>.<gain> (e.g. "
                              f"{PREFIX}{joint_names[-1]}.K_D)")
        if joint not in joint_names:
            raise ConfigError(f"{name}: unknown joint {joint!r} (joints: "
                              f"{', '.join(joint_names)})")
        if gain not in PER_JOINT:
            raise ConfigError(f"{name}: unknown per-joint gain {gain!r} (per-joint gains: "
                              f"{', '.join(PER_JOINT)}; gamma and lambda are global)")
        value = values[name]
        if isinstance(value, bool) or not isinstance(value, float):
            raise ConfigError(f"{name}: wrong type, expected double, got {value!r}")
        if not (np.isfinite(value) and value > 0.0):
            raise ConfigError(f"{name}: must be > 0, got {value}")
        out[gain][joint] = value
    return out


def per_joint_gains(scalars, overrides, joint_names):
    """The core's gain arguments: K_D (n, 6, 6), Lambda (n,), P (n, 13, 13).

    Parameters
    ----------
    scalars : dict
        ``{"K_D": k, "Lambda": l, "P": p}``, the scalar parameters.
    overrides : dict
        The output of :func:`parse_overrides`.
    joint_names : sequence of str
        The model's joint order (link i is moved by joint i).
    """
    out = {}
    for gain, size in PER_JOINT.items():
        per = np.array([overrides.get(gain, {}).get(j, scalars[gain]) for j in joint_names],
                       dtype=float)
        out[gain] = per if size == 1 else per[:, None, None] * np.eye(size)
    return out
