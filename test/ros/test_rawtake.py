"""The lock-free take of the side inputs (``nodes/runtime/rawtake.py``, doc/failsafe.md "Oversized
inputs"): what ``rcl`` hands over is the message as published, a sample above
the cap never reaches the callback, the buffer does not keep a large sample's size (and a
failed re-allocation of it leaves the reader a valid buffer), errors are counted and logged
once without stopping the thread, and the thread stops cleanly."""

import contextlib
import threading
import time

from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from test_nodes_support import QOS, ros_context
from rcac_ros.nodes.runtime import rawtake
from rcac_ros.nodes.runtime.inputs import SideInput
from rcac_ros.nodes.runtime.rawtake import RawReader

SMALL = JointState(name=["a", "b"], position=[1.5, -2.0])
#: about 290 kB serialised: above RawReader.KEEP
LARGE = JointState(name=[f"joint_{i}" for i in range(20_000)], position=[0.25] * 20_000)


class Log:
    """A logger that keeps its error lines."""

    def __init__(self):
        self.lines = []

    def error(self, text):
        self.lines.append(text)


class Inbox:
    """What a reader's callbacks got, thread-safe; ``raise_on`` makes ``on_bytes`` raise."""

    def __init__(self, raise_on=()):
        self.lock = threading.Lock()
        self.data, self.oversize, self.calls = [], [], 0
        self.raise_on = set(raise_on)

    def on_bytes(self, data):
        with self.lock:
            self.calls += 1
            if self.calls in self.raise_on:
                raise ValueError(f"callback failure {self.calls}")
            self.data.append(data)

    def on_oversize(self, size):
        with self.lock:
            self.oversize.append(size)

    def wait(self, done, timeout=10.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self.lock:
                if done(self):
                    return True
            time.sleep(0.01)
        return False


@contextlib.contextmanager
def raw_reader(inbox, cap, log, hold=0, prefault=False):
    """A RawReader on ``/rawtake_test`` (``hold``: 0, a grown buffer is always freed) and a
    publisher to it; yields ``(reader, publish)``."""
    with ros_context() as (ctx, _):
        node = Node("rawtake_reader", context=ctx)
        sub = node.create_subscription(JointState, "/rawtake_test", lambda _: None, QOS,
                                       raw=True)
        reader = RawReader(sub, ctx, inbox.on_bytes, inbox.on_oversize, cap, "test input", log,
                           hold, prefault)
        pub = node.create_publisher(JointState, "/rawtake_test", QOS)
        try:
            end = time.monotonic() + 20.0
            while pub.get_subscription_count() == 0 and time.monotonic() < end:
                time.sleep(0.01)

            def publish(*msgs):
                for msg in msgs:
                    pub.publish(msg)
                    time.sleep(0.02)
            yield reader, publish
        finally:
            reader.close()
            node.destroy_node()
        assert not reader._thread.is_alive()


def test_side_input_delivers_within_the_cap_and_refuses_above_it():
    with ros_context() as (ctx, _):
        owner = Node("rawtake_owner", context=ctx)
        got, refused, lock = [], [], threading.Lock()

        def on_msg(msg):
            with lock:
                got.append(msg)

        def reject(kind, text):
            with lock:
                refused.append((kind, text))
        small = JointState(name=["a", "b"], position=[1.5, -2.0])
        cap = len(serialize_message(small)) + 16
        big = JointState(name=[f"j{i}" for i in range(1000)], position=[0.0] * 1000)
        side = SideInput(owner, JointState, "/rawtake_test", QOS, on_msg, cap, "state", reject)
        pub = owner.create_publisher(JointState, "/rawtake_test", QOS)
        try:
            end = time.monotonic() + 20.0
            while pub.get_subscription_count() == 0 and time.monotonic() < end:
                time.sleep(0.01)
            for msg in (small, big, small, big, small):
                pub.publish(msg)
                time.sleep(0.02)
            end = time.monotonic() + 10.0
            while time.monotonic() < end:
                with lock:
                    if len(got) == 3 and len(refused) == 2:
                        break
                time.sleep(0.01)
        finally:
            side.close()
            owner.destroy_node()
        assert [(list(m.name), list(m.position)) for m in got] == [(["a", "b"], [1.5, -2.0])] * 3
        size = len(serialize_message(big)) - 4      # rclpy's serialize adds 4 bytes of padding
        assert [k for k, _ in refused] == ["size", "size"]
        assert all(f"above the cap of {cap}" in t for _, t in refused)
        assert all(abs(int(t.split(": ")[1].split()[0]) - size) <= 8 for _, t in refused), \
            (refused, size)
        assert not side._reader._thread.is_alive()


def test_a_buffer_grown_within_hold_is_kept_and_reused():
    """With ``hold`` above LARGE's size the grown buffer stays (the next large sample is
    copied into mapped pages), and the samples around it arrive whole."""
    large = len(serialize_message(LARGE))
    inbox, log = Inbox(), Log()
    with raw_reader(inbox, 0, log, hold=4 * large) as (reader, publish):
        assert reader.capacity == RawReader.KEEP
        publish(LARGE, SMALL)
        assert inbox.wait(lambda b: len(b.data) == 2), (len(inbox.data), inbox.oversize)
        # kept, not freed: it still holds the large sample's bytes
        assert reader.capacity >= len(inbox.data[0]) > RawReader.KEEP, reader.capacity
        got = [deserialize_message(d, JointState) for d in inbox.data]
        assert got[0].name == LARGE.name and got[1].name == SMALL.name
    assert reader.errors == {"take": 0, "alloc": 0, "callback": 0, "thread": 0} and log.lines == []


def test_a_prefaulted_buffer_starts_at_its_bound_and_stays_there():
    """``prefault``: the buffer is allocated at ``max(cap, KEEP, hold)`` before any sample
    (the first large one is copied into mapped pages), and a sample within it keeps it."""
    large = len(serialize_message(LARGE))
    inbox, log = Inbox(), Log()
    with raw_reader(inbox, 0, log, hold=4 * large, prefault=True) as (reader, publish):
        assert reader.capacity == 4 * large
        publish(LARGE, SMALL)
        assert inbox.wait(lambda b: len(b.data) == 2), (len(inbox.data), inbox.oversize)
        assert reader.capacity == 4 * large
        got = [deserialize_message(d, JointState) for d in inbox.data]
        assert got[0].name == LARGE.name and got[1].name == SMALL.name
    assert reader.errors == {"take": 0, "alloc": 0, "callback": 0, "thread": 0} and log.lines == []


def test_a_prefaulted_buffer_grown_past_its_bound_returns_to_the_bound():
    """After a sample above ``max(cap, KEEP, hold)`` a prefaulted reader gets a buffer of
    that bound back (a plain one gets KEEP bytes: the next test)."""
    large = len(serialize_message(LARGE))
    hold = (RawReader.KEEP + large) // 2        # between KEEP and LARGE's size
    inbox, log = Inbox(), Log()
    with raw_reader(inbox, 0, log, hold=hold, prefault=True) as (reader, publish):
        assert reader.capacity == hold
        publish(LARGE, SMALL)
        assert inbox.wait(lambda b: len(b.data) == 2), (len(inbox.data), inbox.oversize)
        assert inbox.wait(lambda b: reader.capacity == hold), reader.capacity
    assert reader.errors == {"take": 0, "alloc": 0, "callback": 0, "thread": 0} and log.lines == []


def test_the_buffer_is_freed_back_to_a_bound_after_a_large_sample():
    small = len(serialize_message(SMALL))
    for cap, delivered in ((small + 16, 0), (0, 1)):    # LARGE above the cap / no cap
        inbox, log = Inbox(), Log()
        with raw_reader(inbox, cap, log) as (reader, publish):
            assert reader.capacity == RawReader.KEEP
            publish(LARGE, SMALL)
            assert inbox.wait(lambda b: len(b.data) + len(b.oversize) == 2), \
                (len(inbox.data), inbox.oversize)
            assert len(inbox.oversize) == 1 - delivered
            got = [deserialize_message(d, JointState) for d in inbox.data]
            if delivered:       # taken whole into the grown buffer before it was freed
                assert len(inbox.data[0]) > RawReader.KEEP
                assert got[0].name == LARGE.name and list(got[0].position) == [0.25] * 20_000
            assert got[-1].name == SMALL.name and list(got[-1].position) == [1.5, -2.0]
            # LARGE grew the buffer past the bound; it was freed back to KEEP after it
            assert reader.capacity <= max(cap, RawReader.KEEP), reader.capacity
        assert reader.errors == {"take": 0, "alloc": 0, "callback": 0, "thread": 0}
        assert log.lines == []


def test_a_callback_exception_is_counted_logged_once_and_the_input_keeps_flowing():
    inbox, log = Inbox(raise_on={1, 3}), Log()
    with raw_reader(inbox, 0, log) as (reader, publish):
        publish(SMALL, SMALL, SMALL, SMALL)
        assert inbox.wait(lambda b: b.calls == 4)
        assert reader._thread.is_alive()
        assert len(inbox.data) == 2                     # the 2nd and the 4th
        assert reader.errors == {"take": 0, "alloc": 0, "callback": 2, "thread": 0}
    assert len(log.lines) == 1, log.lines               # one line for one exception type
    assert log.lines[0].startswith("test input: the callback raised")
    assert "Traceback" in log.lines[0] and "ValueError: callback failure 1" in log.lines[0]


class FailingRcl:
    """rcl whose ``rcl_take_serialized_message`` returns ``code`` ``count`` times first
    (the sample stays in the reader: the next take gets it)."""

    def __init__(self, rcl, code, count):
        self._rcl, self.code, self.left = rcl, code, count

    def rcl_take_serialized_message(self, *args):
        if self.left:
            self.left -= 1
            return self.code
        return self._rcl.rcl_take_serialized_message(*args)


def test_an_rcl_error_is_counted_logged_once_and_the_input_keeps_flowing(monkeypatch):
    rcl, rcutils = rawtake._libraries()
    monkeypatch.setattr(rawtake, "_libraries",
                        lambda: (FailingRcl(rcl, 1, 3), rcutils))     # RCL_RET_ERROR
    inbox, log = Inbox(), Log()
    with raw_reader(inbox, 0, log) as (reader, publish):
        publish(SMALL, SMALL)
        assert inbox.wait(lambda b: len(b.data) == 2)
        assert reader.errors == {"take": 3, "alloc": 0, "callback": 0, "thread": 0}
    assert len(log.lines) == 1, log.lines
    assert log.lines[0].startswith("test input: rcl_take_serialized_message returned 1 (")


class FailingAlloc:
    """rcutils whose ``rcutils_uint8_array_init`` returns ``RCUTILS_RET_BAD_ALLOC`` on the calls
    numbered in ``fail`` (1: the reader's first buffer); the rest is the real library's."""

    def __init__(self, rcutils, fail):
        self._rcutils, self.fail, self.calls = rcutils, set(fail), 0

    def rcutils_uint8_array_init(self, *args):
        self.calls += 1
        if self.calls in self.fail:
            return 10                       # RCUTILS_RET_BAD_ALLOC, nothing allocated
        return self._rcutils.rcutils_uint8_array_init(*args)

    def __getattr__(self, name):
        return getattr(self._rcutils, name)


def test_a_failed_reallocation_is_counted_and_the_reader_keeps_a_buffer(monkeypatch):
    """The buffer of KEEP bytes that replaces one grown by a large sample cannot be
    allocated (twice): the reader keeps the large buffer, takes the next samples into it, the
    failures are counted and the first logged, and the third attempt restores the bound."""
    rcl, rcutils = rawtake._libraries()
    fake = FailingAlloc(rcutils, fail={2, 3})
    monkeypatch.setattr(rawtake, "_libraries", lambda: (rcl, fake))
    inbox, log = Inbox(), Log()
    with raw_reader(inbox, 0, log) as (reader, publish):
        assert reader.capacity == RawReader.KEEP
        publish(LARGE, SMALL, SMALL)
        assert inbox.wait(lambda b: len(b.data) == 3 and reader.capacity <= RawReader.KEEP), \
            (len(inbox.data), reader.capacity, reader.errors, log.lines)
        assert reader._thread.is_alive()
        assert reader.errors == {"take": 0, "alloc": 2, "callback": 0, "thread": 0}
        assert fake.calls == 4                          # the first, two failed, one done
        got = [deserialize_message(d, JointState) for d in inbox.data]
        assert got[0].name == LARGE.name and list(got[0].position) == [0.25] * 20_000
        assert all(m.name == SMALL.name and list(m.position) == [1.5, -2.0] for m in got[1:])
        publish(SMALL)                                  # and the input goes on
        assert inbox.wait(lambda b: len(b.data) == 4)
    assert len(log.lines) == 1, log.lines
    assert log.lines[0].startswith(
        f"test input: rcutils_uint8_array_init of {RawReader.KEEP} bytes returned 10 ("), \
        log.lines
    assert "keeps its buffer of" in log.lines[0]


def test_a_failed_reallocation_is_tried_again_without_a_further_sample(monkeypatch):
    """No sample follows the large one whose shrink failed: the reader tries again after its
    next wait (not only after a take), so the bound holds again without more traffic."""
    rcl, rcutils = rawtake._libraries()
    fake = FailingAlloc(rcutils, fail={2})
    monkeypatch.setattr(rawtake, "_libraries", lambda: (rcl, fake))
    inbox, log = Inbox(), Log()
    with raw_reader(inbox, 0, log) as (reader, publish):
        publish(LARGE)
        assert inbox.wait(lambda b: len(b.data) == 1 and reader.capacity <= RawReader.KEEP), \
            (len(inbox.data), reader.capacity, reader.errors, log.lines)
        assert reader.errors == {"take": 0, "alloc": 1, "callback": 0, "thread": 0}
        assert fake.calls == 3
        assert reader._thread.is_alive() and len(log.lines) == 1
