"""Take serialised messages without holding the interpreter lock (doc/failsafe.md).

rclpy's take (``Subscription.take_message``, also with ``raw=True``) copies the sample out of
DDS while it holds the interpreter lock: a 24 MB JointState stalls every other thread of the
process for the length of the copy (doc/failsafe.md, "Oversized inputs"). Fast DDS cannot drop
such a sample by size for a type with unbounded sequences (its reader limit is the type's
bound). :class:`RawReader` therefore waits and takes through ``rcl`` with :mod:`ctypes`, which
releases the lock for the length of each foreign call: the copy out of DDS runs beside the
control thread, and the size is checked on the taken buffer before any Python object is built
from it.

The serialised-message buffer is reused; ``rcl`` grows it to the sample's size. Grown by a
sample of up to ``max(cap, KEEP, hold)`` bytes (``hold`` default :attr:`RawReader.HOLD`, 32
MiB) it is kept, so the next large sample lands in pages already mapped, not fresh ones the
kernel must fault in and zero while the samples behind it wait; after a larger one it is
replaced by one of its initial size: between takes the reader holds at most that bound. The
initial size is ``KEEP`` bytes, or the bound with ``prefault`` (the controller's state input:
32 MiB touched at once, the first large sample no slower than the later ones; doc/failsafe.md,
"Oversized inputs"). The new buffer is allocated before the large one is freed: if that fails
(a machine short of memory), the failure is counted and the reader keeps the large buffer,
takes into it and tries again after the next take or wait (at most 50 ms later).

Errors do not stop the reader: a return code of ``rcl`` other than "taken" and "nothing to
take", a failed allocation of the initial-size buffer, and an exception raised by a callback,
are counted (:attr:`RawReader.errors`) and the first of each kind is logged (the exception with
its traceback); the thread then goes on with the next sample. An exception of the reader's own
loop (outside a callback) is counted and logged the same way and the loop starts again
(doc/failsafe.md, "Thread failures"): the thread ends only when it is closed or its context
shuts down.
"""

import ctypes
import threading
import traceback

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

RCL_RET_OK = 0
RCL_RET_SUBSCRIPTION_TAKE_FAILED = 401
#: s to wait after a failed take before the next (a lasting error must not spin the thread)
ERROR_BACKOFF = 0.001
#: the wait for a sample, ns (also the longest a failed shrink waits for its next attempt)
WAIT_NS = 50_000_000
#: s before the reader's loop starts again after it raised (a lasting fault: 10 Hz, no spin)
RESTART_BACKOFF = 0.1


class _Allocator(ctypes.Structure):
    _fields_ = [("allocate", ctypes.c_void_p), ("deallocate", ctypes.c_void_p),
                ("reallocate", ctypes.c_void_p), ("zero_allocate", ctypes.c_void_p),
                ("state", ctypes.c_void_p)]


class _Uint8Array(ctypes.Structure):        # rcl_serialized_message_t
    _fields_ = [("buffer", ctypes.POINTER(ctypes.c_uint8)), ("buffer_length", ctypes.c_size_t),
                ("buffer_capacity", ctypes.c_size_t), ("allocator", _Allocator)]


class _ErrorString(ctypes.Structure):     # rcutils_error_string_t
    _fields_ = [("str", ctypes.c_char * 1024)]


class _Gid(ctypes.Structure):
    _fields_ = [("implementation_identifier", ctypes.c_char_p), ("data", ctypes.c_uint8 * 16)]


class _MessageInfo(ctypes.Structure):       # rmw_message_info_t (Jazzy)
    _fields_ = [("source_timestamp", ctypes.c_int64), ("received_timestamp", ctypes.c_int64),
                ("publication_sequence_number", ctypes.c_uint64),
                ("reception_sequence_number", ctypes.c_uint64), ("publisher_gid", _Gid),
                ("from_intra_process", ctypes.c_bool), ("_spare", ctypes.c_uint8 * 64)]


_lib = {}


def _libraries():
    """``(rcl, rcutils)`` loaded once (already mapped by rclpy: resolved by name)."""
    if not _lib:
        rcl = ctypes.CDLL("librcl.so")
        rcutils = ctypes.CDLL("librcutils.so")
        rcl.rcl_take_serialized_message.argtypes = [
            ctypes.c_void_p, ctypes.POINTER(_Uint8Array), ctypes.POINTER(_MessageInfo),
            ctypes.c_void_p]
        rcl.rcl_take_serialized_message.restype = ctypes.c_int
        rcutils.rcutils_get_default_allocator.restype = _Allocator
        rcutils.rcutils_uint8_array_init.argtypes = [
            ctypes.POINTER(_Uint8Array), ctypes.c_size_t, ctypes.POINTER(_Allocator)]
        rcutils.rcutils_uint8_array_fini.argtypes = [ctypes.POINTER(_Uint8Array)]
        rcutils.rcutils_get_error_string.restype = _ErrorString
        rcutils.rcutils_reset_error.restype = None
        _lib.update(rcl=rcl, rcutils=rcutils)
    return _lib["rcl"], _lib["rcutils"]


class RawReader:
    """Serve one ``raw=True`` subscription in its own thread, lock-free while waiting/taking.

    Parameters
    ----------
    subscription : rclpy.subscription.Subscription
        Created with ``raw=True`` on a node that no executor spins (its callback is not
        used).
    context : rclpy.context.Context
    on_bytes : callable
        ``on_bytes(data)``: called in the thread with each sample of at most ``cap`` bytes.
    on_oversize : callable
        ``on_oversize(size)``: called instead for a larger sample (no bytes are built).
    cap : int
        Bytes (0: no cap).
    hold : int
        Bytes the buffer may keep between takes once a sample grew it (default
        :attr:`HOLD`); a larger one is replaced by the initial buffer after its take.
    prefault : bool
        Allocate the buffer at its bound (``max(cap, KEEP, hold)``) at once and touch its
        pages, so that the first large sample is copied into mapped memory as the later
        ones are (the thread's other samples then wait less behind it).
    name : str
        The thread's name (and the prefix of its log lines).
    events : sequence of rclpy.event_handler.EventHandler
        The subscription's (``subscription.event_handlers``: incompatible QoS or type, logged),
        served in this thread's wait set; an executor's beside it spun (rmw_fastrtps).
    log : logger
        ``log.error(text)``: the first error of each kind (see :attr:`errors`).

    Attributes
    ----------
    errors : dict
        Counts by kind: ``"take"`` (``rcl_take_serialized_message`` returned an error; the
        sample, if any, is lost), ``"alloc"`` (the initial-size buffer that replaces
        one grown past the bound could not be allocated; the reader keeps the grown buffer,
        takes into it and tries again after the next take or wait) and ``"callback"``
        (``on_bytes`` or ``on_oversize`` raised; the reader goes on with the next sample)
        and ``"thread"`` (the reader's own loop raised, outside a callback: the wait, the
        take's bookkeeping; the loop starts again with a new wait set after
        :data:`RESTART_BACKOFF`, the samples that came meanwhile waiting in DDS's queue).
    received_ns : int
        The DDS receive stamp (ns, system clock) of the last sample taken; 0 before any.
    """

    #: bytes the buffer is allocated with, and replaced by after a sample larger than
    #: ``max(cap, KEEP, hold)`` (a bound on what the reader holds between takes)
    KEEP = 65_536
    #: bytes a grown buffer may keep between takes (the hostile flood's 24 MB state fits)
    HOLD = 33_554_432

    def __init__(self, subscription, context, on_bytes, on_oversize, cap, name, log,
                 hold=HOLD, prefault=False, events=()):
        self._rcl, self._rcutils = _libraries()
        self._sub = subscription
        self._events = list(events)
        self._context = context
        self._on_bytes, self._on_oversize, self._cap = on_bytes, on_oversize, cap
        self._bound = max(cap, self.KEEP, hold)
        self._name, self._log = name, log
        self.errors = {"take": 0, "alloc": 0, "callback": 0, "thread": 0}
        self._logged = set()
        self._msg, self._info, self.received_ns = _Uint8Array(), _MessageInfo(), 0
        self._alloc = self._rcutils.rcutils_get_default_allocator()
        self._size, self._prefault = (self._bound if prefault else self.KEEP), prefault
        if self._new_buffer(self._msg) != RCL_RET_OK:
            raise MemoryError("rcutils_uint8_array_init failed")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _new_buffer(self, msg):
        """Allocate ``msg`` with the reader's initial size (touched if prefaulted);
        ``rcutils``'s return code."""
        ret = self._rcutils.rcutils_uint8_array_init(ctypes.byref(msg), self._size,
                                                     ctypes.byref(self._alloc))
        if ret == RCL_RET_OK and self._prefault:    # mapped now, not during a sample's copy
            ctypes.memset(msg.buffer, 0, self._size)
        return ret

    @property
    def native_id(self):
        """The thread's native id (its scheduling: :mod:`~rcac_ros.nodes.runtime.realtime`)."""
        return self._thread.native_id

    @property
    def capacity(self):
        """Bytes of the serialised-message buffer held now."""
        return self._msg.buffer_capacity

    def _shrink(self):
        """Replace a buffer grown past the bound by one of the initial size (:attr:`KEEP`
        bytes, or the bound if prefaulted).

        The new buffer is allocated before the old one is freed: if the allocation fails, it
        is counted (``"alloc"``) and the reader keeps the old buffer (valid, only larger than
        the bound) until the next attempt.
        """
        small = _Uint8Array()
        ret = self._new_buffer(small)
        if ret != RCL_RET_OK:
            message = self._rcutils.rcutils_get_error_string().str.decode(errors="replace")
            self._rcutils.rcutils_reset_error()
            self._error("alloc", f"rcutils_uint8_array_init of {self._size} bytes returned "
                        f"{ret} ({message}): the reader keeps its buffer of "
                        f"{self._msg.buffer_capacity} bytes and tries again")
            return
        large, self._msg = self._msg, small
        self._rcutils.rcutils_uint8_array_fini(ctypes.byref(large))

    def _error(self, kind, text, key=None):
        """Count an error of ``kind``; log the first of each ``(kind, key)``."""
        self.errors[kind] += 1
        key = (kind, key)
        if key not in self._logged:
            self._logged.add(key)
            self._log.error(f"{self._name}: {text}\n(counted; further ones of this kind are "
                            "not logged)")

    def _take_failed(self, ret):
        """``rcl_take_serialized_message`` returned ``ret``, neither taken nor nothing to take;
        True: back off before the next wait (outside the handle, so a destroy need not wait)."""
        message = self._rcutils.rcutils_get_error_string().str.decode(errors="replace")
        self._rcutils.rcutils_reset_error()
        if self._stop.is_set() or not self._context.ok():
            return False                    # shutting down: the handle is going away
        self._error("take", f"rcl_take_serialized_message returned {ret} ({message}): the "
                    "sample, if any, is lost")
        return True

    def _take_all(self):
        """Take every sample waiting; hand over the small ones. True after a failed take."""
        with self._sub.handle:
            pointer = self._sub.handle.pointer
            while not self._stop.is_set():
                ret = self._rcl.rcl_take_serialized_message(
                    pointer, ctypes.byref(self._msg), ctypes.byref(self._info), None)
                if ret == RCL_RET_SUBSCRIPTION_TAKE_FAILED:     # nothing left
                    return False
                if ret != RCL_RET_OK:
                    return self._take_failed(ret)
                size = self._msg.buffer_length
                self.received_ns = self._info.received_timestamp
                try:
                    if self._cap and size > self._cap:
                        self._on_oversize(size)
                    else:
                        self._on_bytes(ctypes.string_at(self._msg.buffer, size))
                except Exception as err:    # noqa: BLE001 -- the input must keep flowing
                    self._error("callback", "the callback raised; the reader goes on:\n"
                                + traceback.format_exc().rstrip(), type(err))
                finally:
                    if self._msg.buffer_capacity > self._bound:
                        self._shrink()

    def _on_event(self, event):
        """A QoS event of the subscription: its handler's callback, as an executor's."""
        try:
            if (data := event.take_data()):
                event.callback(data)
        except Exception as err:    # noqa: BLE001 -- the input must keep flowing
            self._error("callback", "an event callback raised; the reader goes on:\n"
                        + traceback.format_exc().rstrip(), type(err))

    def _run(self):
        """The thread: serve the subscription; a loop that raised is logged with its
        traceback, counted (``"thread"``) and started again after :data:`RESTART_BACKOFF`."""
        while not self._stop.is_set() and self._context.ok():
            try:
                self._serve()
            except Exception as err:    # noqa: BLE001 -- the input must not end in silence
                if self._stop.is_set() or not self._context.ok():
                    return                  # the context or the handle went down
                self._error("thread", "the reader's loop raised; it starts again in "
                            f"{RESTART_BACKOFF * 1e3:g} ms:\n"
                            + traceback.format_exc().rstrip(), type(err))
                self._stop.wait(RESTART_BACKOFF)

    def _serve(self):
        """Wait and take until stopped (a new wait set each time the loop starts)."""
        wait_set = _rclpy.WaitSet(1, 0, 0, 0, 0, len(self._events), self._context.handle)
        while not self._stop.is_set() and self._context.ok():
            with self._sub.handle, self._context.handle:
                wait_set.clear_entities()
                wait_set.add_subscription(self._sub.handle)
                for event in self._events:
                    event.add_to_wait_set(wait_set)
                wait_set.wait(WAIT_NS)                  # without the lock
            if self._sub.handle.pointer in wait_set.get_ready_entities("subscription") \
                    and self._take_all():
                self._stop.wait(ERROR_BACKOFF)  # a lasting error does not spin the thread
            for event in self._events:
                if event.is_ready(wait_set):
                    self._on_event(event)
            if self._msg.buffer_capacity > self._bound:     # a failed shrink: again
                self._shrink()

    def close(self):
        """Stop the thread (the subscription is the caller's to destroy)."""
        self._stop.set()
        self._thread.join(2.0)
        if not self._thread.is_alive():
            self._rcutils.rcutils_uint8_array_fini(ctypes.byref(self._msg))
