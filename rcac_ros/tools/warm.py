"""Compile the numba kernels into their cache once, in two processes at a time.

The kernels compile when a law is first stepped (:mod:`rcac_ros.core._jit`), into the
user's cache directory, keyed on the package's compiled sources and numba's version. This
tool compiles all of them ahead, so that no later process compiles: run it once after an
install (``make setup`` and ``make test`` do; after ``pip install`` or ``colcon build``:
``python -m rcac_ros.tools.warm``).

The work is split in two processes that compile different kernels at the same time:

- ``recursive``: the recursive law's general kernel (any channels and options, with and
  without the joint terms) and the natural geometry's steps, the Slotine-Li law's too;
- ``others``: everything else: the paper's law's fused kernel (Euclidean, natural, with the
  joint terms), the Slotine-Li law, dynamics, kinematics, the simulator, the
  identifiability accumulator, the command limiter and the effort clip.

Usage: ``python -m rcac_ros.tools.warm [--jobs N] [GROUP ...]`` (each group in its own
process, ``N`` at a time, default 2). Prints one line per group with its time. Exit code 1 if
a group failed (its error is printed); the cache is then only partly filled, and whatever
is missing compiles on first use, as without this tool.
"""

import argparse
import functools
import subprocess
import sys
import tempfile
import time

from rcac_ros.errors import ConfigError
from rcac_ros.tools.args import positive_int

GROUPS = ("recursive", "others")


def _step_each(cls, model, variants):
    import numpy as np
    z = np.zeros(model.n)
    q = np.full(model.n, 0.1)
    for kwargs in variants:
        cls(model, **kwargs).compile().step(q, z, q, z, z)


def warm_recursive():
    """The recursive law's general kernel, with and without the joint terms, the natural
    geometry's and least squares' helpers that its controller calls, and the Slotine-Li
    law's natural geometry (the two groups take about the same time)."""
    from rcac_ros.core import RecursiveCompositeController, SlotineLiCompositeController, css_arm
    model = css_arm()
    _step_each(RecursiveCompositeController, model, (
        {"channels": "all"}, {"channels": "all", "joint_friction": True},
        {"geometry": "natural", "channels": "all"},
        {"geometry": "natural", "adaptation": "least_squares"},
        {"geometry": "natural", "joint_friction": True, "channels": "all"}))
    _step_each(SlotineLiCompositeController, model, (
        {"geometry": "natural"}, {"geometry": "natural", "natural_metric": "log_det"},
        {"geometry": "natural", "joint_friction": True}))


def warm_others():
    """Everything else: the paper's law's fused kernel, the Slotine-Li law, dynamics,
    kinematics, the simulator, the identifiability accumulator, the command limiter and the
    effort clip."""
    import numpy as np
    from rcac_ros.core import (RecursiveCompositeController, Simulator,
                               SlotineLiCompositeController, css_arm, energy, forward_dynamics,
                               forward_kinematics, inverse_dynamics, mass_matrix)
    from rcac_ros.core.identifiability import Excitation
    from rcac_ros.nodes.safety.guards import DesiredLimiter, EffortClip
    model = css_arm()
    _step_each(RecursiveCompositeController, model, (
        {}, {"joint_friction": True}, {"geometry": "natural"}))
    _step_each(SlotineLiCompositeController, model, ({}, {"joint_friction": True}))
    z = np.zeros(model.n)
    q = np.full(model.n, 0.1)
    inverse_dynamics(model, q, z, z)
    mass_matrix(model, q)
    forward_dynamics(model, q, z, z)
    forward_kinematics(model, q)
    energy(model, q, z)
    Simulator(model, dt=0.002).step(z)
    Excitation(model.n, 0.002).add(np.zeros((1, model.n, 13)))
    DesiredLimiter(0.01, 0.1, 0.002, model.n).warm()
    EffortClip(np.ones(model.n), np.arange(model.n)).warm()


WARMERS = {"recursive": warm_recursive, "others": warm_others}


def run_group(name):
    """Run one group here; return (seconds, None) or (seconds, error text)."""
    t0 = time.monotonic()
    try:
        WARMERS[name]()
    except Exception as exc:  # reported; the other group still warms
        return time.monotonic() - t0, f"{type(exc).__name__}: {exc}"
    return time.monotonic() - t0, None


def warm(groups=GROUPS, jobs=2, log=None):
    """Run ``groups`` in their own processes, ``jobs`` at a time; True if all of them ran.

    ``log`` (default ``print``) gets one line per group with its time, and the error of a
    group that failed (what that group did not compile compiles on first use instead)."""
    log = log or (lambda text: print(text, flush=True))
    t0 = time.monotonic()
    log(f"warm: compiling the numba kernels into their cache ({', '.join(groups)}, "
        f"{min(jobs, len(groups))} at a time; a first run takes minutes, later ones seconds)")
    ok = True
    pending, running = list(groups), {}
    while pending or running:
        while pending and len(running) < jobs:
            name = pending.pop(0)
            output = tempfile.TemporaryFile(mode="w+")     # never a pipe nobody reads yet
            running[name] = (time.monotonic(), output, subprocess.Popen(
                [sys.executable, "-m", "rcac_ros.tools.warm", "--child", name],
                stdout=output, stderr=subprocess.STDOUT, text=True))
        time.sleep(0.1)
        for name, (start, output, proc) in list(running.items()):
            if proc.poll() is None:
                continue
            output.seek(0)
            out = output.read().strip().splitlines()
            output.close()
            del running[name]
            seconds = time.monotonic() - start
            if proc.returncode == 0:
                log(f"warm: {name} ready in {seconds:.0f} s")
            else:
                ok = False
                log(f"warm: {name} failed after {seconds:.0f} s: "
                    f"{out[-1] if out else 'exit code ' + str(proc.returncode)}")
    log(f"warm: done in {time.monotonic() - t0:.0f} s")
    return ok


@functools.cache
def warm_once():
    """:func:`warm` at most once per process: what starts the nodes calls it first (the ROS
    benches), since two nodes compiling at once take longer than they are waited for."""
    return warm()


def add_arguments(parser):
    """``rcac warm``'s (and ``python -m rcac_ros.tools.warm``'s) options."""
    parser.add_argument("groups", nargs="*", metavar="GROUP",
                        help=f"of {', '.join(GROUPS)} (default: all)")
    parser.add_argument("--jobs", type=positive_int, default=2,
                        help="processes at a time (default 2)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)


def run(args, error=None):
    """Run the groups of ``args``; 0 if all compiled, 1 if one failed. An unknown group is
    ``error(text)`` (the parser's), else a :class:`~rcac_ros.errors.ConfigError`."""
    groups = list(dict.fromkeys(args.groups)) or list(GROUPS)
    unknown = [g for g in groups if g not in GROUPS]
    if unknown:
        text = f"unknown group {unknown[0]!r} (choose from {', '.join(GROUPS)})"
        if error is not None:
            error(text)
        raise ConfigError(text)
    if args.child:              # one group, in this process: its error on stdout
        seconds, failure = run_group(groups[0])
        if failure:
            print(failure, flush=True)
        return 1 if failure else 0
    return 0 if warm(groups, args.jobs) else 1


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m rcac_ros.tools.warm",
                                     description=__doc__.splitlines()[0])
    add_arguments(parser)
    return run(parser.parse_args(argv), parser.error)


if __name__ == "__main__":
    sys.exit(main())
