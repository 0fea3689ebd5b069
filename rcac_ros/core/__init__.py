"""rcac_ros.core: the pure core (numpy + numba, never rclpy).

Model (constant) and state (per step) are kept apart, as in Pinocchio:
:class:`RobotModel` is immutable; controllers and the simulator own their state.

Importing this package, or any of its modules, compiles nothing: each name below is
imported when first used, and a controller compiles (or loads from its cache) the kernels
of its own law when it is first stepped or :meth:`compile` d (:mod:`rcac_ros.core._jit`).
"""

import importlib

from rcac_ros.errors import ConfigError, GainError, InputError, ModelError, RcacError

#: public name -> the module that defines it
_EXPORTS = {
    "RobotModel": "model", "css_arm": "model", "theta_from_inertia": "model",
    "PARAMETER_NAMES": "model", "PAPER_GAINS": "model", "PAPER_Q0": "model", "PRESETS": "model",
    "model_from_urdf": "urdf", "load_model": "load",
    "link_regressor": "regressor", "mass_regressor": "regressor",
    "coriolis_gravity_regressor": "regressor", "link_matrices": "regressor",
    "inverse_dynamics": "rnea", "mass_matrix": "crba", "forward_dynamics": "aba",
    "forward_kinematics": "kinematics", "energy": "kinematics",
    "RecursiveCompositeController": "composite", "SlotineLiCompositeController": "slotine_li",
    "Simulator": "simulator",
    "PaperTrajectory": "trajectory", "SinusoidTrajectory": "trajectory",
    "PolynomialTrajectory": "trajectory",
}

__all__ = ["RcacError", "ModelError", "ConfigError", "GainError", "InputError", *_EXPORTS]


def __getattr__(name):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
