"""The laws' options that a boundary checks before any kernel is imported.

The command line, the nodes' parameters and the campaign files check these options with
numpy alone: this module imports no numba and no module that defines a kernel. The
controllers use the same functions and values (:mod:`rcac_ros.core.channels` and
:mod:`rcac_ros.core.pseudo_inertia` re-export them).

- ``channels``: the prediction channels of the composite law (doc/design.md §4),
  :func:`parse_channels`;
- ``barrier_c``: the metric ``"barrier"`` of the natural geometry (doc/design.md §8),
  :data:`BARRIER_C` and :data:`BARRIER_C_MIN`;
- ``P_friction``: the joint terms' gain (doc/design.md §7), default :data:`P_FRICTION`;
- ``friction_adaptation``, ``friction_forgetting``: least squares on the joint terms
  (doc/design.md §7), :func:`friction_adaptation_option`, :data:`FRICTION_FORGETTING`.
"""

import numpy as np

from rcac_ros.errors import GainError

#: default c of the metric "barrier" (doc/design.md §8, "Choice of c": the paired campaign's
#: best median with its worst sample under 2x, of 100, 300, 1e3, 3e3, 1e4)
BARRIER_C = 1000.0
#: smallest c: far below it, H / (c k_i) overflows to Inf in the kernel
BARRIER_C_MIN = 1e-6

#: default ``P_friction``: the joint terms' gain scaled from each joint's feedback at the
#: first posture (:func:`rcac_ros.core.joint_friction.feedback_scaled_gain`)
P_FRICTION = "feedback"

#: the joint terms' gains: fixed (the default) or least squares
FRICTION_ADAPTATIONS = ("gradient", "least_squares")
#: default ``lambda_0`` (1/s) of the joint terms' bounded-gain forgetting: a memory of
#: ``1 / lambda_0 = 2`` s, about one period of a manipulator's slowest motions (0.5 Hz)
FRICTION_FORGETTING = 0.5

#: The value of ``channels`` that gives every joint.
ALL = "all"


def parse_channels(value, n):
    """Validate ``channels``: ``[1]``, ``"all"``, ``"power"``, ``"1,power"`` or a list of those.

    Parameters
    ----------
    value : int, str or sequence of int/str
        Joint numbers are 1-based; ``"power"`` is the energy channel; ``"all"`` is 1..n.
    n : int or None
        Number of joints; None checks the syntax only (``"all"`` stays ``"all"``).

    Returns
    -------
    tuple
        The channels in order, each an ``int`` in 1..n or ``"power"``.

    Raises
    ------
    GainError
        One line naming ``channels`` and the bad entry.
    """
    items = value.split(",") if isinstance(value, str) else value
    if isinstance(items, (int, np.integer)):
        items = [items]
    try:
        items = list(items)
    except TypeError:
        raise GainError(f"channels: expected joint numbers, 'power' or 'all', got {value!r}") \
            from None
    joints = "joint number" if n is None else f"joint number (1..{n})"
    out = []
    for item in items:
        if isinstance(item, str):
            word = item.strip().lower()
            if word == ALL:
                out.extend([ALL] if n is None else range(1, n + 1))
                continue
            if word == "power":
                out.append("power")
                continue
            if not word.lstrip("+").isdigit():
                raise GainError(f"channels: {item!r} is not a {joints}, 'power' or 'all'")
            item = int(word)
        if isinstance(item, (bool, np.bool_)) or not isinstance(item, (int, np.integer)):
            raise GainError(f"channels: {item!r} is not a {joints}, 'power' or 'all'")
        if item < 1:
            raise GainError(f"channels: joint {item}: joints are numbered from 1")
        if n is not None and item > n:
            raise GainError(f"channels: joint {item} is out of range 1..{n}")
        out.append(int(item))
    if not out:
        raise GainError("channels: empty (give at least one joint number, 'power' or 'all')")
    dup = sorted({str(c) for c in out if out.count(c) > 1})
    if dup:
        raise GainError(f"channels: listed twice: {', '.join(dup)}")
    return tuple(out)


def friction_adaptation_option(value, geometry, joint_friction=True):
    """Validate ``friction_adaptation`` for ``geometry``; None gives the default,
    ``"gradient"``. ``"least_squares"`` only in the Euclidean geometry (the natural one's
    joint terms adapt in the positive orthant's geometry, doc/design.md §8).

    Raises
    ------
    GainError
        One line naming ``friction_adaptation`` and the value.
    """
    if value is None:
        return "gradient"
    if value not in FRICTION_ADAPTATIONS:
        raise GainError(f"friction_adaptation: expected 'least_squares' or 'gradient', "
                        f"got {value!r}")
    if value == "least_squares" and not joint_friction:
        raise GainError("friction_adaptation: 'least_squares' needs joint_friction=True")
    if value == "least_squares" and geometry == "natural":
        raise GainError("friction_adaptation: 'least_squares' needs geometry='euclidean' "
                        "(the natural geometry's joint terms use 'gradient', doc/design.md §8)")
    return value
