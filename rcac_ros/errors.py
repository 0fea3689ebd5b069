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


class BagError(RcacError, ValueError):
    """A bag is missing, cut short by a crash, or corrupt (the message names the problem)."""


class CutBagError(BagError):
    """A bag was not closed (its recorder was killed): ``rcac inspect --recover`` salvages it."""


def first_line(err):
    """The first line of an exception's text, or its type's name (a one-line report)."""
    return str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__


def read_yaml(path, label=None, load=None):
    """Parse the YAML file at ``path``.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    label : str, optional
        How the message names the file (default: the path).
    load : callable, optional
        ``load(stream)`` parses the open file (default :func:`yaml.safe_load`).

    Returns
    -------
    object
        The parsed document (None for an empty file).

    Raises
    ------
    ConfigError
        One line naming ``label``: the file cannot be read, or is not valid YAML (with the
        line and column of the error where YAML gives them).
    """
    import yaml      # here: importing the exceptions stays light
    label = path if label is None else label
    try:
        with open(path, "rb") as f:             # bytes: YAML reads a byte-order mark
            return (load or yaml.safe_load)(f)
    except OSError as err:
        raise ConfigError(f"{label}: cannot read ({err.strerror})") from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1} column {mark.column + 1}" if mark else ""
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise ConfigError(f"{label}: not valid YAML{where} ({problem})") from None


class DependencyError(RcacError, ImportError):
    """An optional dependency a command needs is not installed (the message names it: an
    extra of setup.py, or ROS 2)."""
