"""The ``rcac`` command: one entry point, one subcommand per tool.

Each subcommand lives in its own module exposing ``add_arguments(parser)`` and
``run(args) -> int``; modules are imported only when their subcommand runs, so
``rcac --help`` stays fast and ``rcac experiment`` never imports rclpy.
Numbers are checked as they are parsed (the ``type=`` helpers of ``tools/args.py``); a bad
argument gives one line naming it and exit code 2.
"""

import argparse
import importlib
import sys

#: subcommand -> (module, one-line help)
SUBCOMMANDS = {
    "experiment": ("rcac_ros.tools.demos.experiment",
                   "run the paper's Section 4 experiment (both laws)"),
    "bench": ("rcac_ros.tools.bench.core",
              "time the controller against Pinocchio and the baseline"),
    "record": ("rcac_ros.tools.bags.record", "record the package's topics into a rosbag2 bag"),
    "inspect": ("rcac_ros.tools.bags.inspect", "summarise a bag and plot what it holds"),
    "demo": ("rcac_ros.tools.demos.demo",
             "simulator + controller over ROS 2, bag, summary and plots"),
    "payload-demo": ("rcac_ros.tools.demos.payload",
                     "panda with an unknown 2 kg payload attached"),
    "friction-demo": ("rcac_ros.tools.demos.friction",
                      "panda learning its joints' armature, viscous and Coulomb friction"),
    "sweep": ("rcac_ros.tools.sweep.engine", "Monte Carlo campaigns of closed-loop runs on Dask"),
    "compare": ("rcac_ros.tools.demos.compare",
                "every adaptive law on the paper's run and the payload demo"),
}


class OneLineParser(argparse.ArgumentParser):
    """argparse, with each usage error on one line naming the option, and exit code 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser():
    parser = OneLineParser(
        prog="rcac", description="rcac_ros tools: the recursive composite adaptive controller "
        "offline, over ROS 2, and its bags.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (module, help_text) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(_module=module)
        if name in sys.argv[1:2]:  # only the chosen subcommand imports its module
            importlib.import_module(module).add_arguments(p)
    return parser


def main(argv=None):
    if argv is not None:
        sys.argv = [sys.argv[0]] + list(argv)
    args = build_parser().parse_args()
    from rcac_ros.errors import RcacError
    try:
        return importlib.import_module(args._module).run(args) or 0
    except RcacError as err:
        print(f"rcac {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
