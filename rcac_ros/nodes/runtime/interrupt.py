"""SIGINT and SIGTERM in a node process: the first one starts the clean shutdown of
:func:`rcac_ros.nodes.runtime.base.run`, later ones are ignored, and none is lost.

Python runs a signal handler in the main thread between two bytecodes, wherever they are.
When that is inside a finalizer (``__del__``) or a collector callback, the
``KeyboardInterrupt`` the handler raises is printed as "Exception ignored" and dropped; a
node that then ignored the later signals would run on, deaf to every stop. The handler
therefore also records the request, and :func:`check` (called by ``run`` after the node is
built and after every spin) raises it again.
"""

import signal

_requested = [False]


def install():
    """Handle SIGINT and SIGTERM in Python (rclpy's handlers would shut the context down
    before the controller could publish its final zero effort)."""
    _requested[0] = False
    signal.signal(signal.SIGINT, _handler)
    signal.signal(signal.SIGTERM, _handler)


def ignore():
    """Ignore both signals (the shutdown is under way: nothing may cut it short); a request
    recorded so far is spent."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    _requested[0] = False


def check():
    """Raise ``KeyboardInterrupt`` if a signal came whose exception was dropped."""
    if _requested[0]:
        raise KeyboardInterrupt


def _handler(signum, frame):
    if _requested[0]:
        return                  # one interrupt starts the clean shutdown; later ones wait for it
    _requested[0] = True
    raise KeyboardInterrupt
