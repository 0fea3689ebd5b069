"""The package's own exception classes.

Every error raised at a boundary of :mod:`rcac_ros.core` (a constructor, a
public function, a file loader) derives from :class:`RcacError`, and its
message names the offending field.
"""


class RcacError(Exception):
    """Base class of every error raised by rcac_ros."""


class ModelError(RcacError, ValueError):
    """A robot description is not physically valid (mass, inertia, frames, shapes)."""


class ConfigError(RcacError, ValueError):
    """A configuration file (YAML, URDF) is missing, malformed or incomplete."""


class GainError(RcacError, ValueError):
    """A controller gain has the wrong shape or is not (symmetric) positive definite."""


class InputError(RcacError, ValueError):
    """A run-time input (state, desired motion, torque) has a wrong shape or is not finite."""
