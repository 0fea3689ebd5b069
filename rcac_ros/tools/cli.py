"""The ``rcac`` command: one entry point, one subcommand per tool.

Each subcommand lives in its own module exposing ``add_arguments(parser)`` and
``run(args) -> int``; modules are imported only when their subcommand runs, so
``rcac --help`` stays fast and ``rcac experiment`` never imports rclpy. A module whose
options depend on its first argument (the forms of ``rcac sweep``, the benchmarks of
``rcac bench``) takes ``add_arguments(parser, argv)``, ``argv`` the words after the
subcommand. The command line is read, never rewritten.
Numbers are checked as they are parsed (the ``type=`` helpers of ``tools/args.py``); a bad
argument gives one line naming it and exit code 2, and so does a missing optional
dependency (``tools/extras.py``). A subcommand's module imports at its top only what its
parser needs, never numba, Dask, matplotlib, MuJoCo or rclpy: its arguments, and the files
they name (a campaign, a URDF, a model), are refused before any kernel is imported.
"""

import argparse
import importlib
import inspect
import sys

#: subcommand -> (module, one-line help, what it needs: extras of setup.py or "ros", or a
#: function of the parsed arguments that gives them)
SUBCOMMANDS = {
    "experiment": ("rcac_ros.tools.demos.experiment",
                   "run the paper's Section 4 experiment (both laws)", ()),
    "bench": ("rcac_ros.tools.bench.commands",
              "benchmarks: core, ros, faults, soak, delay-margin, startup, noise", ()),
    "record": ("rcac_ros.tools.bags.record", "record the package's topics into a rosbag2 bag",
               ("bags", "ros")),
    "inspect": ("rcac_ros.tools.bags.inspect", "summarise a bag and plot what it holds",
                ("bags",)),
    "demo": ("rcac_ros.tools.demos.demo",
             "simulator + controller over ROS 2, bag, summary and plots", ("bags", "ros")),
    "capture-demo": ("rcac_ros.tools.demos.capture",
                     "CSS arm grasps an unknown payload over ROS 2: bag, figures, laws, masses",
                     lambda args: () if args.no_ros else ("bags", "ros")),
    "payload-demo": ("rcac_ros.tools.demos.payload",
                     "panda with an unknown 2 kg payload attached", ()),
    "friction-demo": ("rcac_ros.tools.demos.friction",
                      "panda learning its joints' armature, viscous and Coulomb friction", ()),
    "friction-ros": ("rcac_ros.tools.demos.friction_ros",
                     "over ROS 2 on a MuJoCo plant with joint friction: blind and aware, bags, "
                     "plots", ("bags", "ros", "mujoco")),
    "sweep": ("rcac_ros.tools.sweep.commands", "Monte Carlo campaigns of closed-loop runs on Dask",
              ("sweep",)),
    "warm": ("rcac_ros.tools.warm",
             "compile every numba kernel into the user's cache once (after pip install or "
             "colcon build)", ()),
    "compare": ("rcac_ros.tools.demos.compare",
                "every adaptive law on the paper's run and the payload demo", ()),
}


class OneLineParser(argparse.ArgumentParser):
    """argparse, with each usage error on one line naming the option, and exit code 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def add_module_arguments(parser, module, argv):
    """``module.add_arguments(parser[, argv])``: ``argv`` only where the module takes it."""
    add = importlib.import_module(module).add_arguments
    if "argv" in inspect.signature(add).parameters:
        add(parser, argv)
    else:
        add(parser)


def build_parser(argv=()):
    """The parser of ``rcac``; only the subcommand named by ``argv[0]`` gets its options."""
    parser = OneLineParser(
        prog="rcac", description="rcac_ros tools: the recursive composite adaptive controller "
        "offline, over ROS 2, and its bags.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (module, help_text, _) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        if list(argv[:1]) == [name]:  # only the chosen subcommand imports its module
            add_module_arguments(p, module, list(argv[1:]))
    return parser


def make_output_dirs(args):
    """The directory of every file the command will write (``--json``, ``--plot``, checked by
    ``args.output_file``), made now rather than after the run."""
    import os
    from rcac_ros.errors import ConfigError
    from rcac_ros.tools.args import OutputFile
    for name, value in vars(args).items():
        if isinstance(value, OutputFile):
            try:
                os.makedirs(os.path.dirname(os.path.abspath(value)), exist_ok=True)
            except OSError as err:
                raise ConfigError(f"--{name}: cannot make the directory of {value!r} "
                                  f"({err.strerror})") from None


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(argv).parse_args(argv)
    from rcac_ros.errors import RcacError
    from rcac_ros.tools.extras import require
    module, _, needs = SUBCOMMANDS[args.command]
    try:
        require(*(needs(args) if callable(needs) else needs))
        make_output_dirs(args)
        return importlib.import_module(module).run(args) or 0
    except RcacError as err:
        print(f"rcac {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
