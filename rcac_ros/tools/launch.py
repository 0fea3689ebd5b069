"""Child node processes and the in-process ROS context of the tools.

The demo and the ROS benchmark start the package's nodes as child processes (the installed
executables, else ``python -m``), each in its own session with its output in a log file, on
an isolated ``ROS_DOMAIN_ID``, and always stop them, even on Ctrl-C. They and the recorder
spin their own rclpy context without rclpy's signal handlers (:func:`init_context`,
:class:`StopFlag`). rclpy is imported only inside the functions that need it.
"""

import ctypes
import os
import signal
import subprocess
import sys
import time

from rcac_ros.errors import ConfigError, RcacError

#: node -> (executable, module, params file)
NODES = {
    "controller": ("controller", "rcac_ros.nodes.controller.node", "controller.yaml"),
    "simulator": ("simulator", "rcac_ros.nodes.simulator.node", "simulator.yaml"),
}


class NodeFailed(RcacError):
    """A child node exited early, or the run made no progress."""


def config_file(name):
    """Path of a shipped config file: the installed share directory, else the source tree."""
    candidates = []
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.append(os.path.join(get_package_share_directory("rcac_ros"), "config", name))
    except Exception:  # noqa: BLE001 - not installed with colcon: use the source tree
        pass
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))     # rcac_ros/
    candidates.append(os.path.join(os.path.dirname(package), "config", name))  # source tree
    candidates.append(os.path.join(sys.prefix, "share", "rcac_ros", "config", name))  # pip
    for path in candidates:
        if os.path.isfile(path):
            return path
    raise ConfigError(f"config: cannot find {name} (looked in {', '.join(candidates)})")


def node_command(node, params=None, overrides=None):
    """Command line of a node: the installed executable, else ``python -m``.

    Parameters
    ----------
    node : {"controller", "simulator"}
    params : str, optional
        Parameters file; default the shipped ``config/<node>.yaml``.
    overrides : dict, optional
        ``-p name:=value`` overrides.

    Returns
    -------
    list of str
    """
    exe, module, yaml_name = NODES[node]
    cmd = None
    candidates = [os.path.join(os.path.dirname(sys.executable), exe)]
    try:
        from ament_index_python.packages import get_package_prefix
        candidates.insert(0, os.path.join(get_package_prefix("rcac_ros"), "lib", "rcac_ros",
                                          exe))
    except Exception:  # noqa: BLE001 - not in an ament index
        pass
    for path in candidates:
        if os.path.isfile(path) and os.access(path, os.X_OK):
            cmd = [path]
            break
    if cmd is None:
        cmd = [sys.executable, "-m", module]
    cmd += ["--ros-args", "--params-file", params or config_file(yaml_name)]
    for key, value in (overrides or {}).items():
        cmd += ["-p", f"{key}:={_param_text(value)}"]
    return cmd


def _param_text(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_param_text(v) for v in value) + "]"
    return str(value)


#: ``prctl(2)`` of the C library (Linux), else None
try:
    _PRCTL = ctypes.CDLL(None, use_errno=True).prctl if sys.platform.startswith("linux") \
        else None
except (OSError, AttributeError):
    _PRCTL = None
PR_SET_PDEATHSIG = 1


def ends_with_parent():
    """A ``preexec_fn`` for :class:`subprocess.Popen`: the child is sent SIGTERM when the
    process that started it ends, however it ends (Ctrl-C, ``kill``, ``kill -9``, a crash),
    so no node or load process outlives its tool and goes on publishing. None where the
    system has no ``PR_SET_PDEATHSIG`` (the children then end with :meth:`Child.stop`
    only). The signal follows the thread that started the child: start children from the
    thread that outlives them (the tools' main thread)."""
    if _PRCTL is None:
        return None
    parent = os.getpid()

    def preexec():
        _PRCTL(PR_SET_PDEATHSIG, int(signal.SIGTERM))
        if os.getppid() != parent:      # the parent ended before the call
            os.kill(os.getpid(), signal.SIGTERM)
    return preexec


def spawn(cmd, **kwargs):
    """``subprocess.Popen(cmd, **kwargs)`` for a process that must end with its tool
    (:func:`ends_with_parent`)."""
    return subprocess.Popen(cmd, preexec_fn=ends_with_parent(), **kwargs)


class Child:
    """A node process in its own session, its output in a log file; it ends with the tool
    (:func:`ends_with_parent`)."""

    def __init__(self, name, cmd, env, log_path):
        self.name = name
        self.cmd = cmd
        self.log_path = log_path
        self._log = open(log_path, "w")
        self._log.write("$ " + " ".join(cmd) + "\n")
        self._log.flush()
        self.proc = spawn(cmd, env=env, stdout=self._log, stderr=subprocess.STDOUT,
                          stdin=subprocess.DEVNULL, start_new_session=True)

    def alive(self):
        return self.proc.poll() is None

    @property
    def returncode(self):
        return self.proc.poll()

    def stop(self, timeout=5.0):
        """SIGINT, then SIGTERM, then SIGKILL; returns the exit code."""
        for sig, wait in ((signal.SIGINT, timeout), (signal.SIGTERM, 3.0),
                          (signal.SIGKILL, 3.0)):
            if self.proc.poll() is not None:
                break
            try:
                os.killpg(self.proc.pid, sig)
            except ProcessLookupError:
                break
            try:
                self.proc.wait(wait)
            except subprocess.TimeoutExpired:
                continue
        code = self.proc.poll()
        self._log.close()
        return code

    def tail(self, lines=15):
        try:
            with open(self.log_path) as f:
                return "".join(f.readlines()[-lines:])
        except OSError:
            return ""


def child_env(domain_id):
    """The environment of a child node: domain ``domain_id``, localhost discovery, unbuffered."""
    env = os.environ.copy()
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_LOCALHOST_ONLY", None)
    env["PYTHONUNBUFFERED"] = "1"
    return env


class StopFlag:
    """Set by SIGINT / SIGTERM; restores the previous handlers on :meth:`restore`."""

    def __init__(self, signals=(signal.SIGINT, signal.SIGTERM)):
        self.signum = None
        self._previous = {}
        for sig in signals:
            self._previous[sig] = signal.signal(sig, self._handler)

    def _handler(self, signum, frame):
        if self.signum is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt  # a second Ctrl-C: stop waiting for a clean exit
        self.signum = signum

    def __bool__(self):
        return self.signum is not None

    def restore(self):
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)


def init_context(domain_id=None):
    """A fresh rclpy context without rclpy's signal handlers (ours close the bag).

    Parameters
    ----------
    domain_id : int, optional
        ROS domain; default ``ROS_DOMAIN_ID`` from the environment.

    Returns
    -------
    rclpy.context.Context
    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    ctx = rclpy.Context()
    kwargs = {} if domain_id is None else {"domain_id": int(domain_id)}
    rclpy.init(context=ctx, signal_handler_options=SignalHandlerOptions.NO, **kwargs)
    return ctx


def shut_down(children, executor=None, ctx=None):
    """Stop ``children`` (the last started first), then the executor and the context.

    Parameters
    ----------
    children : list of Child
        The node processes.
    executor : rclpy.executors.Executor, optional
    ctx : rclpy.context.Context, optional
        Either may be None (start-up failed before it was made).

    Returns
    -------
    dict
        ``{child name: exit code}``.
    """
    codes = {c.name: c.stop() for c in reversed(children)}
    if executor is not None:
        executor.shutdown()
    if ctx is not None:
        ctx.try_shutdown()
    return codes


def wait_until_active(node, executor, name, timeout=30.0, alive=None, resend=0.5):
    """Spin until the lifecycle node ``name`` reports ``active`` (its ``get_state`` service).

    A managed node's publishers exist from its configure, so seeing them is not enough to
    start what it answers: the controller activates once its kernels are loaded, which a
    loaded machine can delay by seconds, and a lockstep simulator started before then
    steps on without answers.

    Parameters
    ----------
    node : rclpy.node.Node
        The tool's node (the client is made on it and destroyed before returning).
    executor : rclpy.executors.Executor
        Executor ``node`` was added to.
    name : str
        The lifecycle node's name (``/name/get_state``).
    timeout : float
        Seconds to wait.
    alive : callable, optional
        Called while waiting; waiting stops (returning False) when it returns False.
    resend : float
        Seconds after which an unanswered request is dropped and sent again.

    Returns
    -------
    bool
        True once the node is active, False on timeout or when ``alive()`` turned False.
    """
    from lifecycle_msgs.msg import State
    from lifecycle_msgs.srv import GetState

    client = node.create_client(GetState, f"/{name}/get_state")
    deadline = time.monotonic() + timeout
    future, sent = None, 0.0
    try:
        while time.monotonic() < deadline and (alive is None or alive()):
            now = time.monotonic()
            if future is not None and not future.done() and now - sent > resend:
                # a request sent before the server's reply writer matched this client is
                # answered into the void (DDS discovery is per endpoint): ask again
                client.remove_pending_request(future)
                future = None
            if future is None and client.service_is_ready():
                future, sent = client.call_async(GetState.Request()), now
            if future is not None and future.done():
                result = future.result()
                if result is not None and result.current_state.id == State.PRIMARY_STATE_ACTIVE:
                    return True
                future = None
            executor.spin_once(timeout_sec=0.02)
        return False
    finally:
        node.destroy_client(client)
