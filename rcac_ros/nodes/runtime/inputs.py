"""Inputs received off the control thread, and size caps checked before deserialising.

The control loop (500 Hz) must never wait for the parsing of a large input (doc/failsafe.md,
"starvation"). :class:`SideInput` subscribes on a helper node and takes in its own thread
without the interpreter lock (:mod:`~rcac_ros.nodes.runtime.rawtake`): a sample above the
cap is never turned into Python objects, one within it is deserialised and checked there,
and only the result is handed over (one attribute assignment, atomic under the GIL). The
process's interpreter switch interval is lowered so that a Python loop in that thread yields
the interpreter to the control thread within half a millisecond.

:func:`capped` wraps a raw (serialised) subscription callback: the byte count is
checked first, and only a message within the cap is deserialised.
"""

import sys

from rclpy.node import Node
from rclpy.serialization import deserialize_message

from rcac_ros.nodes.runtime.rawtake import RawReader
from rcac_ros.nodes.safety.guards import oversize, Rejected

#: the interpreter switch interval of a node process with a side thread, s (default 5 ms:
#: 2.5 periods at 500 Hz)
SWITCH_INTERVAL = 0.0005


def capped(msg_type, cap, what, callback, reject):
    """A raw-subscription callback: size check, then ``callback(deserialised message)``.

    ``reject(kind, text)`` is called for a message above ``cap`` bytes (0: no cap).
    """
    def on_raw(data):
        try:
            oversize(len(data), cap, what)
        except Rejected as err:
            return reject(err.kind, str(err))
        return callback(deserialize_message(data, msg_type))
    return on_raw


class SideInput:
    """A subscription served in its own thread, taken without the interpreter lock.

    The subscription lives on a helper node that no executor spins; a
    :class:`~rcac_ros.nodes.runtime.rawtake.RawReader` waits and takes in its own thread through
    ``rcl`` with the lock released, checks the size on the taken bytes, and deserialises only
    a message within the cap (doc/failsafe.md, "Oversized inputs").

    Parameters
    ----------
    owner : rclpy.node.Node
        The node whose topic it is: the name is resolved and remapped as the owner's
        (``~/x`` is ``/<owner>/x``).
    msg_type, topic, qos :
        As for ``create_subscription``.
    callback : callable
        Called in the side thread with each message within the cap.
    cap : int
        Size cap in bytes (0: none); above it ``reject(kind, text)`` is called instead.
    what : str
        Name of the input in the rejection text (``max_<what>_bytes`` is the parameter).
    reject : callable
        ``reject(kind, text)``: a message above the cap or that does not deserialise.
    prefault : bool
        The reader's buffer allocated and mapped at its bound from the start
        (:class:`~rcac_ros.nodes.runtime.rawtake.RawReader`).
    fast : callable, optional
        ``fast(data)``: given each sample's bytes within the cap first; True if it took the
        sample, else the sample is deserialised and ``callback(msg, data)`` is called
        (without ``fast``: ``callback(msg)``).

    A failed take, a failed allocation of the take's buffer or an exception of ``callback``
    is counted (:attr:`errors`), the first of each kind logged with ``owner``'s logger, and
    the thread goes on.
    """

    def __init__(self, owner, msg_type, topic, qos, callback, cap, what, reject,
                 prefault=False, fast=None):
        # the owner's name, namespace and remappings (its own, and the process's), once: the
        # side node applies no rule of its own
        self.topic = topic = owner.resolve_topic_name(topic)
        self.node = Node(f"{owner.get_name()}_{what}_input", namespace=owner.get_namespace(),
                         context=owner.context, start_parameter_services=False,
                         enable_rosout=False, use_global_arguments=False)
        self.subscription = self.node.create_subscription(
            msg_type, topic, lambda _: None, qos, raw=True)
        self._closed = False

        def on_oversize(nbytes):
            try:
                oversize(nbytes, cap, what)
            except Rejected as err:
                reject(err.kind, str(err))

        def on_bytes(data):
            if fast is not None and fast(data):
                return None
            try:
                msg = deserialize_message(data, msg_type)
            except Exception as err:        # noqa: BLE001 -- malformed CDR from the wire
                return reject("malformed", f"{what}: {len(data)} bytes do not deserialise "
                              f"({err})")
            return callback(msg) if fast is None else callback(msg, data)

        sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL))
        self._reader = RawReader(self.subscription, owner.context, on_bytes, on_oversize, cap,
                                 f"{what} input", owner.get_logger(), prefault=prefault,
                                 events=self.subscription.event_handlers)

    @property
    def errors(self):
        """Failed takes, buffer allocations and callback exceptions of the thread, by kind
        (``RawReader.errors``)."""
        return self._reader.errors

    @property
    def received_ns(self):
        """The DDS receive stamp of the sample in the callback (ns, system clock;
        ``RawReader.received_ns``)."""
        return self._reader.received_ns

    @property
    def native_id(self):
        """The thread's native id."""
        return self._reader.native_id

    def close(self):
        """Stop the thread and destroy the helper node (once)."""
        if self._closed:
            return
        self._closed = True
        self._reader.close()
        self.node.destroy_node()
