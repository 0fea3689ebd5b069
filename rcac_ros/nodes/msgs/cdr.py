"""CDR bytes of the controller's per-step messages, written and read without message objects.

The controller publishes its effort and monitors as serialised bytes
(:func:`~rcac_ros.nodes.runtime.rclpy_private.byte_sender`) and reads a JointState whose
frame and joint names it knows from the bytes (:class:`~rcac_ros.nodes.msgs.joint_state.
JointStateReader`): rclpy's message objects check every element of a list assigned to them
in Python, which costs more than the control law's step.

The encoding is rmw_fastrtps's: XCDR1 little endian (the encapsulation header ``00 01 00
00``), each primitive aligned to its size counted from the end of that header, a sequence
as its ``uint32`` count then its elements, a string as a sequence of its UTF-8 bytes with a
terminating NUL; an empty sequence of doubles is not aligned to 8. Padding bytes are zero
(rclpy's hold what its buffer held), and the bytes end at the last field (rclpy's buffer
may be a few bytes longer: it is sized by an upper bound).
"""

import struct
from collections import namedtuple

import numpy as np

#: the encapsulation header: XCDR1, little endian, no options
HEADER = b"\x00\x01\x00\x00"
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_F64 = struct.Struct("<d")
_DIM_TAIL = struct.Struct("<IIII")      # size, stride; then data_offset, the data's count
_ZEROS = bytes(8)

#: a builtin_interfaces/Time read from bytes (its fields only)
Stamp = namedtuple("Stamp", "sec nanosec")


def _doubles(values):
    """``values`` as little-endian float64 bytes (C order)."""
    return np.ascontiguousarray(values, dtype="<f8").tobytes()


class _Writer:
    """Fields appended at a position counted from the end of the encapsulation header."""

    __slots__ = ("parts", "pos")

    def __init__(self, pos=0):
        self.parts, self.pos = [], pos

    def raw(self, data):
        self.parts.append(data)
        self.pos += len(data)

    def align(self, size):
        pad = -self.pos % size
        if pad:
            self.raw(_ZEROS[:pad])

    def u32(self, value):
        self.align(4)
        self.raw(_U32.pack(value))

    def string(self, text):
        data = text.encode() + b"\0"
        self.u32(len(data))
        self.raw(data)

    def strings(self, texts):
        self.u32(len(texts))
        for text in texts:
            self.string(text)

    def doubles(self, values):
        data = _doubles(values)
        self.u32(len(data) // 8)
        if data:
            self.align(8)
            self.raw(data)

    def bytes(self):
        return b"".join(self.parts)


def float64(value):
    """std_msgs/Float64."""
    return HEADER + _F64.pack(value)


def one_dim_array(label, size, values):
    """std_msgs/Float64MultiArray with one dimension ``label`` of ``size`` (its stride too;
    data_offset 0): the effort command."""
    data = _doubles(values)
    n = len(data) // 8
    text = label.encode() + b"\0"
    pos = 8 + len(text)             # the dimensions' count, the label's length, the label
    pad = -pos % 4
    pad8 = -(pos + pad + 16) % 8 if n else 0
    return b"".join((HEADER, _U32.pack(1), _U32.pack(len(text)), text, _ZEROS[:pad],
                     _DIM_TAIL.pack(size, size, 0, n), _ZEROS[:pad8], data))


class MultiArrayWriter:
    """std_msgs/Float64MultiArray with a fixed layout.

    Parameters
    ----------
    dims : sequence of (str, int, int)
        ``(label, size, stride)`` of each dimension.
    data_offset : int
    """

    def __init__(self, dims, data_offset=0):
        w = _Writer()
        w.u32(len(dims))
        for label, size, stride in dims:
            w.string(label)
            w.u32(size)
            w.u32(stride)
        w.u32(data_offset)
        self._head, self._pos = HEADER + w.bytes(), w.pos

    def __call__(self, values):
        """The message with ``values`` (flattened in C order) as its data."""
        data = _doubles(values)
        pad = -(self._pos + 4) % 8 if data else 0
        return b"".join((self._head, _U32.pack(len(data) // 8), _ZEROS[:pad], data))


class JointStateWriter:
    """sensor_msgs/JointState with fixed joint names and frame.

    Parameters
    ----------
    names : sequence of str
    frame_id : str
    """

    def __init__(self, names, frame_id=""):
        w = _Writer(8)                      # after the stamp
        w.string(frame_id)
        w.strings(list(names))
        self._names, self._pos = w.bytes(), w.pos

    def __call__(self, stamp, position=(), velocity=(), effort=()):
        """The message at ``stamp`` (``sec``, ``nanosec``) with these arrays."""
        w = _Writer(self._pos)
        w.doubles(position)
        w.doubles(velocity)
        w.doubles(effort)
        return b"".join((HEADER, _STAMP.pack(stamp.sec, stamp.nanosec), self._names, *w.parts))


# ------------------------------------------------------------------ reading a JointState
def names_layout(data):
    """Where the frame and the joint names of a serialised JointState lie: ``(end, count,
    spans)``, ``end`` the index in ``data`` where the names end, ``count`` how many there are
    and ``spans`` the ``(start, stop)`` ranges of their bytes from index 12 (the frame's
    length) to ``end`` without the padding between them (a publisher's padding bytes may
    differ from message to message). ``None`` if the bytes end before the names (a message
    that deserialised has them)."""
    size, spans = len(data), []
    start = 12                              # header 4, stamp 8: the frame's length

    def aligned(pos):                       # to 4, a span ending before any padding
        nonlocal start
        pad = -(pos - 4) % 4
        if pad:
            spans.append((start, pos))
            start = pos + pad
        return pos + pad

    if 16 > size:
        return None
    pos = aligned(16 + _U32.unpack_from(data, 12)[0])      # the frame
    if pos + 4 > size:
        return None
    count = _U32.unpack_from(data, pos)[0]
    pos += 4
    for _ in range(count):
        pos = aligned(pos)
        if pos + 4 > size:
            return None
        pos += 4 + _U32.unpack_from(data, pos)[0]
    if pos > size:
        return None
    spans.append((start, pos))
    return pos, count, spans


def joint_arrays(data, pos, m):
    """Stamp, positions and velocities of a serialised JointState whose names (``m`` of them)
    end at ``pos``: ``(Stamp, position, velocity)``, the arrays read-only views of ``data``
    (``velocity`` ``None`` when the message has none); ``None`` when the message is not such
    a one: a count of positions other than ``m``, of velocities other than 0 or ``m``, or
    bytes that end before its efforts do."""
    size = len(data)
    pos += -(pos - 4) % 4
    arrays = []
    for field in range(3):
        if pos + 4 > size:
            return None
        count = _U32.unpack_from(data, pos)[0]
        if (field == 0 and count != m) or (field == 1 and count not in (0, m)):
            return None
        pos += 4
        if count:
            pos += -(pos - 4) % 8
            if pos + 8 * count > size:
                return None
            if field < 2:
                arrays.append(np.frombuffer(data, "<f8", count, pos))
            pos += 8 * count
        elif field < 2:
            arrays.append(None)
    return Stamp(*_STAMP.unpack_from(data, 4)), arrays[0], arrays[1]
