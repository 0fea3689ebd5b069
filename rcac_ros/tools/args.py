"""argparse ``type=`` helpers: every number on the ``rcac`` command line is checked when parsed.

A bad value stops the command before anything runs, with one line naming the option and exit
code 2 (``cli.py`` makes argparse's errors one line)::

    $ rcac experiment --duration -5
    rcac experiment: error: argument --duration: must be > 0, got '-5'

Every numeric helper rejects NaN and infinities; a file that must exist (``--urdf``) is
checked by :func:`existing_file`, a path the command writes by :func:`output_dir` or
:func:`output_file` (a run never ends on a path it cannot write). Checks that relate two
options (``--jump`` before ``--duration``) belong to the subcommand's ``run``, which raises
the package's ``ConfigError``.
"""

import argparse
import math
import os
import re
import tempfile


def _parse(text, kind):
    try:
        return kind(text)
    except ValueError:
        what = "an integer" if kind is int else "a number"
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None


def finite_float(text):
    """A finite number (any sign)."""
    value = _parse(text, float)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def positive_float(text):
    """A finite number > 0 (durations, gains, periods)."""
    value = finite_float(text)
    if value <= 0.0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return value


def non_negative_float(text):
    """A finite number >= 0 (a time within the run, a weight that may be off)."""
    value = finite_float(text)
    if value < 0.0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text!r}")
    return value


def positive_int(text):
    """An integer >= 1 (counts, 1-based indices)."""
    value = _parse(text, int)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text!r}")
    return value


def non_negative_int(text):
    """An integer >= 0."""
    value = _parse(text, int)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}")
    return value


def existing_file(text):
    """The path of an existing file (a model, a URDF): checked before anything is loaded."""
    if not os.path.isfile(text):
        what = "a directory" if os.path.isdir(text) else "no such file"
        raise argparse.ArgumentTypeError(f"{what}: {text!r}")
    return text


def check_period(h, duration):
    """``--h`` against ``--duration``: a ``ConfigError`` if the control period is longer than
    the run (it would take no step)."""
    if h > duration:
        from rcac_ros.errors import ConfigError
        raise ConfigError(f"--h: the control period ({h:g} s) is longer than the run "
                          f"(--duration {duration:g} s)")


def _writable(path):
    """The nearest existing directory at or above ``path`` accepts a new entry (tried with a
    temporary directory, removed at once: a permission bit does not say it for root or for a
    file system such as /proc)."""
    probe = os.path.abspath(path)
    while not os.path.lexists(probe):
        probe = os.path.dirname(probe)
    if not os.path.isdir(probe):
        raise argparse.ArgumentTypeError(f"not a directory: {probe!r}")
    try:
        tempfile.TemporaryDirectory(prefix=".rcac-check-", dir=probe).cleanup()
    except OSError as err:
        raise argparse.ArgumentTypeError(f"cannot write in {probe!r} ({err.strerror})") \
            from None


def output_dir(text):
    """A directory the command writes into (made if missing): checked before anything runs,
    so a run never ends on a path it cannot write."""
    if not text:
        raise argparse.ArgumentTypeError("an empty path")
    if os.path.lexists(text) and not os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"exists and is not a directory: {text!r}")
    _writable(text)
    return text


class OutputFile(str):
    """A path :func:`output_file` checked; ``rcac`` makes its directory before the command
    runs (``cli.main``)."""


def output_file(text):
    """A file the command writes (``--json``, ``--plot``): an existing file (``/dev/null``
    too) must be writable, a new one's directory must be one the command can make or write
    in; checked before anything runs."""
    if not text:
        raise argparse.ArgumentTypeError("an empty path")
    if os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"a directory: {text!r}")
    if os.path.lexists(text):
        if not os.access(text, os.W_OK):
            raise argparse.ArgumentTypeError(f"not writable: {text!r}")
    else:
        _writable(os.path.dirname(os.path.abspath(text)))
    return OutputFile(text)


#: a ROS 2 node name, with its namespace if any: tokens of letters, digits and underscores,
#: none starting with a digit, joined by single slashes
NODE_NAME = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")


def node_name(text):
    """A node's name, with its namespace if any (``arm/rcac_controller``; a leading ``/``
    dropped): its topics' names are made from it."""
    if not NODE_NAME.fullmatch(text):
        raise argparse.ArgumentTypeError(
            f"not a ROS node name: {text!r} (letters, digits and '_', no token starting with "
            "a digit, '/' between namespace and name)")
    return text.lstrip("/")


def add_engine_argument(parser):
    """``--engine builtin|mujoco``: the plant the closed loop drives (doc/plants.md)."""
    from rcac_ros.plants import ENGINES
    parser.add_argument("--engine", choices=ENGINES, default=None,
                        help="the plant: builtin (the package's own dynamics) or mujoco (the "
                             "same arm in MuJoCo; needs the mujoco package) (default builtin)")


def add_gain_arguments(parser, gains, texts):
    """One ``--NAME`` option per controller gain, its default and its check.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    gains : dict
        Default value of each gain, by name.
    texts : sequence of (str, str)
        ``(name, help)`` in the order of ``--help``; ``gamma`` (the prediction-error
        weight, 0 for the direct law) may be 0, every other gain must be > 0.
    """
    for name, text in texts:
        parser.add_argument(f"--{name}", type=non_negative_float if name == "gamma"
                            else positive_float, default=gains[name],
                            help=f"{text} (default {gains[name]:g})")
