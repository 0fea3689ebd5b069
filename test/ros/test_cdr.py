"""The hand-written CDR of ``rcac_ros/nodes/msgs/cdr.py`` against two other implementations:
rclpy's (its serialiser and deserialiser) and rosbags' (a pure-Python one), and the
JointState read from bytes against the reading of the deserialised message."""

import math
import struct

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from builtin_interfaces.msg import Time  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from rosbags.typesys import get_typestore, Stores  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import (Float64, Float64MultiArray, MultiArrayDimension,  # noqa: E402
                          MultiArrayLayout)

from rcac_ros.nodes.msgs import cdr  # noqa: E402
from rcac_ros.nodes.msgs.joint_state import JointStateReader, StateRejected  # noqa: E402

STORE = get_typestore(Stores.ROS2_JAZZY)
EDGES = [0.0, -0.0, 1.0, -2.5, 5e-324, 2.2250738585072014e-308, 1.7976931348623157e308,
         -1.7976931348623157e308, math.inf, -math.inf, math.nan]
RNG = np.random.default_rng(7)


def values(n):
    """``n`` doubles: the edge values first, then random ones of every magnitude."""
    edge = np.array(EDGES[:n])
    rest = RNG.standard_normal(n - edge.size) * 10.0 ** RNG.integers(-300, 300, n - edge.size)
    return np.concatenate([edge, rest])


def bits(x):
    """Doubles as their bytes: NaN equal to NaN, -0.0 unequal to 0.0."""
    return np.asarray(x, dtype="<f8").tobytes()


def same_as_rclpy(ours, msg):
    """Our bytes are rosbags' serialisation of the same message, byte for byte (its padding
    is zero, as ours), and rclpy's in every byte but padding: rclpy's buffer holds whatever
    its padding bytes held, and may be a few bytes longer (sized by an upper bound)."""
    theirs = serialize_message(msg)
    assert len(ours) <= len(theirs) < len(ours) + 16
    differ = [i for i in range(len(ours)) if ours[i] != theirs[i]]
    assert all(ours[i] == 0 for i in differ), differ


def rosbags_bytes(msg, typename):
    """rosbags' serialisation of the message, built field by field as rosbags' own type."""
    T = STORE.types
    if typename.endswith("Float64"):
        theirs = T[typename](data=msg.data)
    elif typename.endswith("Float64MultiArray"):
        dims = [T["std_msgs/msg/MultiArrayDimension"](label=d.label, size=d.size, stride=d.stride)
                for d in msg.layout.dim]
        theirs = T[typename](layout=T["std_msgs/msg/MultiArrayLayout"](
            dim=dims, data_offset=msg.layout.data_offset), data=np.array(msg.data, float))
    else:
        stamp = T["builtin_interfaces/msg/Time"](sec=msg.header.stamp.sec,
                                                 nanosec=msg.header.stamp.nanosec)
        theirs = T[typename](
            header=T["std_msgs/msg/Header"](stamp=stamp, frame_id=msg.header.frame_id),
            name=list(msg.name), position=np.array(msg.position, float),
            velocity=np.array(msg.velocity, float), effort=np.array(msg.effort, float))
    return bytes(STORE.serialize_cdr(theirs, typename))


def assert_multiarray(data, msg):
    back = deserialize_message(data, Float64MultiArray)
    assert back.layout == msg.layout
    assert bits(back.data) == bits(msg.data)
    bag = STORE.deserialize_cdr(data, "std_msgs/msg/Float64MultiArray")
    assert [(d.label, d.size, d.stride) for d in bag.layout.dim] \
        == [(d.label, d.size, d.stride) for d in msg.layout.dim]
    assert bag.layout.data_offset == msg.layout.data_offset
    assert bits(bag.data) == bits(msg.data)
    assert data == rosbags_bytes(msg, "std_msgs/msg/Float64MultiArray")
    same_as_rclpy(data, msg)


@pytest.mark.parametrize("n", [0, 1, 2, 7, 13])
@pytest.mark.parametrize("label", ["", "j", "jo", "joi", "joint", "joint stamp=0.002000000",
                                   "joint stamp=12345.999999999", "joint watchdog", "é"])
def test_the_effort_reads_back_as_the_message(n, label):
    x = values(n)
    size = max(n, 1)
    ours = cdr.one_dim_array(label, size, x)
    msg = Float64MultiArray(layout=MultiArrayLayout(dim=[MultiArrayDimension(
        label=label, size=size, stride=size)], data_offset=0), data=x.tolist())
    assert_multiarray(ours, msg)


@pytest.mark.parametrize("shape", [(0,), (1,), (3,), (7,), (7, 13), (2, 3)])
def test_a_fixed_layout_reads_back_as_the_message(shape):
    dims = [("link", shape[0], int(np.prod(shape))), ("parameter", 13, 13)][:len(shape)]
    if len(shape) == 1:
        dims = [("joint1,power", shape[0], shape[0])]
    write = cdr.MultiArrayWriter(dims)
    x = values(int(np.prod(shape))).reshape(shape)
    msg = Float64MultiArray(layout=MultiArrayLayout(dim=[MultiArrayDimension(
        label=a, size=b, stride=c) for a, b, c in dims]), data=x.ravel().tolist())
    for _ in range(2):                      # the writer is reused: the same bytes again
        assert_multiarray(write(x), msg)


@pytest.mark.parametrize("x", EDGES + [0.1, -1e-300])
def test_a_float64_reads_back_as_the_message(x):
    ours = cdr.float64(x)
    assert bits(deserialize_message(ours, Float64).data) == bits(x)
    assert bits(STORE.deserialize_cdr(ours, "std_msgs/msg/Float64").data) == bits(x)
    assert ours == rosbags_bytes(Float64(data=x), "std_msgs/msg/Float64")
    same_as_rclpy(ours, Float64(data=x))


def joint_state(names, frame, stamp, position, velocity, effort):
    msg = JointState(name=list(names), position=list(position), velocity=list(velocity),
                     effort=list(effort))
    msg.header.frame_id = frame
    msg.header.stamp = Time(sec=stamp[0], nanosec=stamp[1])
    return msg


JOINT_CASES = [
    (["joint1", "joint2", "joint3", "joint4", "joint5", "joint6", "joint7"], "", 7, 7, 7),
    (["joint1", "joint2", "joint3", "joint4", "joint5", "joint6", "joint7"], "", 7, 7, 0),
    (["a"], "x", 1, 0, 0),
    (["ab", "c"], "base", 0, 0, 2),
    (["shoulder", "elbow", "wrist"], "arm", 3, 0, 3),
    (["ü", "b"], "", 2, 2, 0),
    ([], "", 0, 0, 0),
]


@pytest.mark.parametrize("names, frame, p, v, e", JOINT_CASES)
@pytest.mark.parametrize("stamp", [(0, 0), (1, 2_000_000), (-5, 999_999_999),
                                   (2**31 - 1, 2**32 - 1)])
def test_a_joint_state_reads_back_as_the_message(names, frame, p, v, e, stamp):
    arrays = values(max(p + v + e, 1))
    pos, vel, eff = arrays[:p], arrays[p:p + v], arrays[p + v:p + v + e]
    msg = joint_state(names, frame, stamp, pos, vel, eff)
    ours = cdr.JointStateWriter(names, frame)(cdr.Stamp(*stamp), pos, vel, eff)
    back = deserialize_message(ours, JointState)
    assert back.header == msg.header and back.name == msg.name
    for field in ("position", "velocity", "effort"):
        assert bits(getattr(back, field)) == bits(getattr(msg, field))
    bag = STORE.deserialize_cdr(ours, "sensor_msgs/msg/JointState")
    assert (bag.header.stamp.sec, bag.header.stamp.nanosec) == stamp
    assert bag.header.frame_id == frame and list(bag.name) == names
    assert bits(bag.position) == bits(pos) and bits(bag.velocity) == bits(vel)
    assert bits(bag.effort) == bits(eff)
    assert ours == rosbags_bytes(msg, "sensor_msgs/msg/JointState")
    same_as_rclpy(ours, msg)


# ------------------------------------------------------------------ reading
MODEL = ["joint1", "joint2", "joint3"]


def state(k, names=("joint3", "joint1", "joint2"), frame="", velocity=True, effort=0,
          position=None):
    q = np.array([0.1, 0.2, 0.3]) * k if position is None else np.asarray(position, float)
    return joint_state(names, frame, divmod(k * 2_000_000, 10**9), q,
                       -q if velocity else [], np.full(effort, 7.0))


def old_path(reader, data):
    """The reading of the deserialised message, with its stamp."""
    msg = deserialize_message(data, JointState)
    q, qd = reader.read(msg)
    return (msg.header.stamp.sec, msg.header.stamp.nanosec), q, qd


def assert_same(got, want):
    stamp, q, qd = got
    assert (stamp.sec, stamp.nanosec) == want[0]
    assert bits(q) == bits(want[1]) and q.dtype == want[1].dtype and q.flags.writeable
    assert (qd is None) == (want[2] is None)
    if qd is not None:
        assert bits(qd) == bits(want[2]) and qd.flags.writeable


@pytest.mark.parametrize("frame", ["", "w", "world"])
@pytest.mark.parametrize("velocity, effort", [(True, 0), (False, 0), (True, 3), (False, 3)])
def test_a_known_state_is_read_from_its_bytes_as_from_its_message(frame, velocity, effort):
    reader, reference = JointStateReader(MODEL), JointStateReader(MODEL)
    first = serialize_message(state(1, frame=frame, velocity=velocity, effort=effort))
    assert reader.read_known(first) is None         # nothing known yet
    reader.read(deserialize_message(first, JointState), first)
    for k in range(2, 6):
        data = serialize_message(state(k, frame=frame, velocity=velocity, effort=effort))
        got = reader.read_known(data)
        assert got is not None
        assert_same(got, old_path(reference, data))
    # the velocities come and go: both are read from the bytes
    data = serialize_message(state(6, frame=frame, velocity=not velocity, effort=effort))
    assert_same(reader.read_known(data), old_path(reference, data))


def refusals():
    """Bytes that repeat the known frame and names but that the fast read must leave to the
    full one, and bytes that do not repeat them."""
    good = serialize_message(state(2))
    yield "nan", serialize_message(state(2, position=[0.1, math.nan, 0.3]))
    yield "inf velocity", serialize_message(joint_state(
        ("joint3", "joint1", "joint2"), "", (0, 4_000_000), [0.1] * 3, [0, math.inf, 0], []))
    yield "short positions", serialize_message(joint_state(
        ("joint3", "joint1", "joint2"), "", (0, 4_000_000), [0.1] * 2, [], []))
    yield "two velocities", serialize_message(joint_state(
        ("joint3", "joint1", "joint2"), "", (0, 4_000_000), [0.1] * 3, [0.0] * 2, []))
    yield "truncated", good[:-9]
    yield "efforts past the end", serialize_message(state(2, effort=2))[:-8]
    yield "other names", serialize_message(state(2, names=("joint3", "joint2", "joint1")))
    yield "other frame", serialize_message(state(2, frame="x"))
    yield "a fourth joint", serialize_message(joint_state(
        ("joint3", "joint1", "joint2", "joint4"), "", (0, 4_000_000), [0.1] * 4, [], []))
    yield "big endian", b"\x00\x00" + good[2:]


@pytest.mark.parametrize("case", [name for name, _ in refusals()])
def test_what_the_fast_read_does_not_know_is_left_to_the_full_one(case):
    data = dict(refusals())[case]
    reader = JointStateReader(MODEL)
    first = serialize_message(state(1))
    reader.read(deserialize_message(first, JointState), first)
    assert reader.read_known(data) is None


def test_a_refused_state_teaches_nothing():
    """Only a valid state's bytes are learnt: after a refused one the last valid frame and
    names are still the known ones."""
    reader = JointStateReader(MODEL)
    first = serialize_message(state(1))
    reader.read(deserialize_message(first, JointState), first)
    bad = serialize_message(state(2, names=("joint3", "joint1", "joint9")))
    with pytest.raises(StateRejected):
        reader.read(deserialize_message(bad, JointState), bad)
    assert reader.read_known(serialize_message(state(3))) is not None
    assert reader.read_known(serialize_message(state(3, names=("joint3", "joint1", "joint9")))) \
        is None


def test_names_layout_and_joint_arrays_on_rclpy_bytes():
    """Where the names end, their spans, the counts and the arrays, against the deserialised
    message, for a frame and names of every length modulo 4 (each string's padding)."""
    for frame, names in (("", ["a"]), ("w", ["ab", "abc", "abcd"]),
                         ("wor", ["abcde", "x" * 11, "yy"]), ("worl", [])):
        m = len(names)
        msg = joint_state(names, frame, (3, 4), np.arange(m) + 0.5, np.arange(m) - 0.5, [1.0])
        data = serialize_message(msg)
        end, count, spans = cdr.names_layout(data)
        assert count == m
        # the spans hold the frame's and the names' lengths and bytes, in order, nothing else
        held = b"".join(data[a:b] for a, b in spans)
        strings = [frame] + names
        want = struct.pack("<I", len(frame) + 1) + frame.encode() + b"\0" \
            + struct.pack("<I", m) + b"".join(struct.pack("<I", len(x.encode()) + 1)
                                              + x.encode() + b"\0" for x in names)
        assert held == want and spans[0][0] == 12 and spans[-1][1] == end, strings
        # what follows the names: padding to 4, then the positions' count
        assert struct.unpack_from("<I", data, end + (-(end - 4) % 4))[0] == m
        stamp, pos, vel = cdr.joint_arrays(data, end, m)
        assert stamp == (3, 4)
        assert (pos is None and vel is None and m == 0) or \
            (bits(pos) == bits(msg.position) and bits(vel) == bits(msg.velocity))
        assert cdr.joint_arrays(data, end, m + 1) is None


def test_padding_bytes_that_differ_do_not_hide_a_known_state():
    """rclpy's padding bytes hold whatever its buffer held: a known state is known by its
    frame and names, whatever its padding."""
    reader = JointStateReader(MODEL)
    first = bytearray(serialize_message(state(1, frame="w")))
    end, _, spans = cdr.names_layout(bytes(first))
    pads = [i for i in range(12, end) if not any(a <= i < b for a, b in spans)]
    assert pads
    for i in pads:
        first[i] = 0xAA
    first = bytes(first)
    reader.read(deserialize_message(first, JointState), first)
    data = bytearray(serialize_message(state(2, frame="w")))
    for i in pads:
        data[i] = 0x55
    reference = JointStateReader(MODEL)
    assert_same(reader.read_known(bytes(data)), old_path(reference, bytes(data)))
