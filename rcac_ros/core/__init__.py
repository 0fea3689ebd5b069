"""rcac_ros.core: the pure core (numpy + numba, never rclpy).

Model (constant) and state (per step) are kept apart, as in Pinocchio:
:class:`RobotModel` is immutable; controllers and the simulator own their state.
"""

from rcac_ros.errors import ConfigError, GainError, InputError, ModelError, RcacError
from .model import (PAPER_GAINS, PAPER_Q0, PARAMETER_NAMES, PRESETS, RobotModel, css_arm,
                    theta_from_inertia)
from .urdf import model_from_urdf
from .load import load_model
from .aba import forward_dynamics
from .crba import mass_matrix
from .kinematics import energy, forward_kinematics
from .composite import RecursiveCompositeController
from .slotine_li import SlotineLiCompositeController
from .regressor import (coriolis_gravity_regressor, link_matrices, link_regressor,
                        mass_regressor)
from .rnea import inverse_dynamics
from .simulator import Simulator
from .trajectory import PaperTrajectory, PolynomialTrajectory, SinusoidTrajectory

__all__ = [
    "RcacError", "ModelError", "ConfigError", "GainError", "InputError",
    "RobotModel", "css_arm", "theta_from_inertia", "PARAMETER_NAMES", "PAPER_GAINS", "PAPER_Q0",
    "PRESETS", "model_from_urdf", "load_model",
    "link_regressor", "mass_regressor", "coriolis_gravity_regressor", "link_matrices",
    "inverse_dynamics", "mass_matrix", "forward_dynamics", "forward_kinematics", "energy",
    "RecursiveCompositeController", "SlotineLiCompositeController", "Simulator",
    "PaperTrajectory", "SinusoidTrajectory", "PolynomialTrajectory",
]
