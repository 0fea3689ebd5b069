"""Compile the numba kernels into their cache once, in two processes at a time.

numba caches each kernel next to its source (``cache=True``), keyed on the source file's
modification time and size, so a new checkout compiles them on its first use: about 2.5 min
of one core on a 2-core machine, most of it the recursive law's step kernels
(:mod:`rcac_ros.core.composite_kernels`, :mod:`rcac_ros.core.composite_fused`, compiled
when :mod:`rcac_ros.core` is imported).
``make test`` and ``rcac demo`` run this first, so the tests and the nodes load them
instead of compiling them (and a node does not compile for minutes at its start).

The work is split in two processes that compile different kernels at the same time:

- ``recursive``: ``import rcac_ros.core`` (the recursive law's general kernels, compiled
  eagerly at import: most of the time), then one step of its variants;
- ``others``: everything else (dynamics, kinematics, the simulator, the Slotine-Li law and
  the natural geometry's helpers, the identifiability accumulator, the command guards),
  then the recursive law's fused kernels (:mod:`rcac_ros.core.composite_fused`). This
  process imports those modules without running ``rcac_ros/core/__init__.py``, which would
  compile the general kernels a second time beside the first process; what the first
  process then needs of the second's it loads from the cache.

Usage: ``python -m rcac_ros.tools.warm [--jobs N] [GROUP ...]`` (each group in its own
process, ``N`` at a time, default 2). Prints one line per group with its time. Exit code 1 if
a group failed (its error is printed); the cache is then only partly filled, and whatever
is missing compiles on first use, as without this tool.
"""

import argparse
import functools
import importlib
import os
import subprocess
import sys
import time
import types

GROUPS = ("recursive", "others")


def _core_without_init():
    """Make ``rcac_ros.core``'s submodules importable without its ``__init__`` (which imports
    the recursive law and so compiles its kernels)."""
    if "rcac_ros.core" in sys.modules:
        return
    import rcac_ros
    stub = types.ModuleType("rcac_ros.core")
    stub.__path__ = [os.path.join(os.path.dirname(rcac_ros.__file__), "core")]
    sys.modules["rcac_ros.core"] = stub


def warm_recursive():
    """The recursive law's step kernels (eager, at import), then one step of its variants."""
    import numpy as np
    from rcac_ros.core import RecursiveCompositeController, css_arm
    model = css_arm()
    z = np.zeros(model.n)
    q = np.full(model.n, 0.1)
    # one variant per kernel: the natural metric is a run-time scalar, so either metric
    # compiles the same kernels
    for kwargs in ({}, {"joint_friction": True}, {"geometry": "natural"},
                   {"geometry": "natural", "channels": "all"},
                   {"geometry": "natural", "adaptation": "least_squares"},
                   {"geometry": "natural", "joint_friction": True}):
        RecursiveCompositeController(model, **kwargs).step(q, z, q, z, z)


def warm_others():
    """Everything but the recursive law's general kernels, without importing them: dynamics,
    kinematics, the simulator, the Slotine-Li law and the natural geometry's helpers, the
    identifiability accumulator, the command guards, then the fused kernels."""
    _core_without_init()
    import numpy as np

    def core(name):
        return importlib.import_module(f"rcac_ros.core.{name}")

    model = core("model").css_arm()
    z = np.zeros(model.n)
    q = np.full(model.n, 0.1)
    core("rnea").inverse_dynamics(model, q, z, z)
    core("crba").mass_matrix(model, q)
    core("aba").forward_dynamics(model, q, z, z)
    core("kinematics").forward_kinematics(model, q)
    core("kinematics").energy(model, q, z)
    core("simulator").Simulator(model, dt=0.002).step(z)
    core("identifiability").Excitation(model.n, 0.002).add(np.zeros((1, model.n, 13)))
    slotine_li = core("slotine_li")
    for kwargs in ({}, {"joint_friction": True}, {"geometry": "natural"},
                   {"geometry": "natural", "natural_metric": "log_det"},
                   {"geometry": "natural", "joint_friction": True}):
        slotine_li.SlotineLiCompositeController(model, **kwargs).step(q, z, q, z, z)
    from rcac_ros.nodes.safety.guards import DesiredLimiter
    limiter = DesiredLimiter(0.01, 0.1, 0.002, model.n)
    limiter(z, z, z)
    limiter(q, z, z)
    core("composite_fused")             # the recursive law's fused kernels (eager)


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
            running[name] = (time.monotonic(), subprocess.Popen(
                [sys.executable, "-m", "rcac_ros.tools.warm", "--child", name],
                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True))
        time.sleep(0.1)
        for name, (start, proc) in list(running.items()):
            if proc.poll() is None:
                continue
            out = proc.stdout.read().strip().splitlines()
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


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m rcac_ros.tools.warm",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("groups", nargs="*", metavar="GROUP",
                        help=f"of {', '.join(GROUPS)} (default: all)")
    parser.add_argument("--jobs", type=int, default=2, help="processes at a time (default 2)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    groups = list(dict.fromkeys(args.groups)) or list(GROUPS)
    unknown = [g for g in groups if g not in GROUPS]
    if unknown:
        parser.error(f"unknown group {unknown[0]!r} (choose from {', '.join(GROUPS)})")
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    if args.child:              # one group, in this process: its error on stdout
        seconds, error = run_group(groups[0])
        if error:
            print(error, flush=True)
        return 1 if error else 0
    return 0 if warm(groups, args.jobs) else 1


if __name__ == "__main__":
    sys.exit(main())
