"""A node's ROS arguments at start-up: its parameters files and ROS arguments checked, then
rclpy initialised with them; a bad argument or file is one line on stderr (doc/failsafe.md,
"parameters")."""

import re
import sys

import rclpy
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from rcac_ros.errors import RcacError, first_line
from rcac_ros.nodes.runtime import paramcheck


def rcl_message(err):
    """rcl's refusal of an argument, without its C source locations and empty inner error."""
    text = first_line(err)
    for prefix in ("Failed to parse ROS arguments: ", "failed to initialize rcl: "):
        text = text.removeprefix(prefix)
    text = re.sub(r",? at /\S+:\d+", "", text.replace(". Error: error not set", ""))
    return text.replace("Couldn't parse", "cannot parse")


def init(args, prog):
    """Check the ``--params-file`` files and the ROS arguments of ``args`` (rcl parses them
    without logging), then ``rclpy.init(args)`` with the signals left to Python. True; or False
    after one line ``prog: error: ...`` on stderr."""
    try:
        paramcheck.check_params_files(args)     # a malformed file: one line, not an RCLError
        remove_ros_args(args)                   # rcl refuses here without a log line
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RcacError as err:
        text = first_line(err)
    except _rclpy.RCLError as err:
        text = rcl_message(err)
    except _rclpy.UnknownROSArgsError as err:
        text = (f"unknown ROS arguments {first_line(err)} (a value with spaces needs quotes: "
                "-p 'name:=a b')")
    else:
        return True
    print(f"{prog}: error: {text}", file=sys.stderr, flush=True)
    return False
