"""Plants: the arm a closed loop drives, built-in or on an independent physics engine.

``engine`` names the plant (doc/plants.md):

- ``builtin``: :class:`rcac_ros.core.simulator.Simulator` (the package's own articulated-body
  algorithm integrated by RK4, the torque held over the period);
- ``mujoco``: :class:`rcac_ros.plants.mujoco_plant.MujocoPlant`, the same arm in MuJoCo,
  generated from the :class:`~rcac_ros.core.model.RobotModel` (joint damping, rotor inertia
  and MuJoCo's own dry friction, the friction loss constraint).

Both have the same interface (``step``, ``reset``, ``q``, ``qd``, ``t``, ``applied``, ``dt``,
``effort_limit``, ``model``). This package may import the core; the nodes and the tools
import it. MuJoCo is optional: it is imported only when the ``mujoco`` engine is asked for,
and its absence is a one-line :class:`~rcac_ros.errors.DependencyError`.
"""

import numpy as np

from rcac_ros.errors import ConfigError

#: The plant engines, the first the default.
ENGINES = ("builtin", "mujoco")


def check_engine(engine, label="engine"):
    """``engine`` if it names a plant, else :class:`ConfigError` in one line naming ``label``."""
    if not isinstance(engine, str) or engine not in ENGINES:
        raise ConfigError(f"{label}: expected one of {', '.join(ENGINES)}, got {engine!r}")
    return engine


def make_plant(model, engine="builtin", **kwargs):
    """The plant of ``model`` on ``engine`` (keyword arguments of the plant's constructor).

    Parameters
    ----------
    model : RobotModel
        The true arm.
    engine : str
        One of :data:`ENGINES`.
    **kwargs
        ``dt``, ``q0``, ``qd0``, ``substeps``, ``effort_limit`` (both engines); the MuJoCo
        plant's own options (:class:`~rcac_ros.plants.mujoco_plant.MujocoPlant`).

    Raises
    ------
    ConfigError
        An unknown engine.
    DependencyError
        ``mujoco`` asked for and not installed.
    """
    check_engine(engine)
    if engine == "mujoco":
        from .mujoco_plant import MujocoPlant
        return MujocoPlant(model, **kwargs)
    from rcac_ros.core.simulator import Simulator
    return Simulator(model, **kwargs)


def with_joint_terms(model, damping=0.0, friction=0.0, armature=0.0):
    """``model`` with the same ``damping``, ``friction`` and ``armature`` on every joint
    (``RobotModel.replace``; doc/design.md §7)."""
    n = model.n
    return model.replace(damping=np.full(n, float(damping)), friction=np.full(n, float(friction)),
                         armature=np.full(n, float(armature)))
