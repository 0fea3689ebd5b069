"""rosbag2 bags that survive a crash: the writer (doc/tools.md, "rcac inspect").

Writing (:class:`BagWriter`):

- mcap through the ``mcap`` library's writer: chunks carry real CRCs (zlib CRC-32 of the
  uncompressed data) and the data section a CRC in its DataEnd record; schemas are
  ``ros2msg`` definitions and channels carry the offered QoS profiles and the type hash, as
  rosbag2's mcap plugin writes them, so rosbags, ``mcap-ros2-support``, Foxglove and
  PlotJuggler read the files.
- sqlite3 through Python's ``sqlite3`` with rosbag2's schema (version 4); a rollback journal
  (rosbags opens a bag ``immutable``, so a WAL would be ignored by readers).
- Every ``flush_period`` seconds (default 0.5 s) the open mcap chunk is finished and
  written, or the sqlite transaction committed, and ``metadata.yaml`` is rewritten (first at
  open) with the counts so far and ``custom_data.rcac_state: recording``. A ``kill -9`` of the
  recorder therefore loses at most the last period (under 1 s). :meth:`BagWriter.close` writes the
  summary and ``rcac_state: closed``.

Reading is in :mod:`.verify` (:func:`~.verify.verify`), salvaging in :mod:`.recover`.
"""

import os
import sqlite3
import time

import yaml

from rcac_ros.errors import ConfigError

#: rosbag2 metadata version written (Jazzy)
METADATA_VERSION = 9
#: the ROS distribution written in metadata.yaml (and sqlite's schema table)
ROS_DISTRO = "jazzy"
#: seconds between two flushes (mcap chunk, sqlite commit, metadata.yaml): a crash loses at
#: most this, plus what DDS had not yet delivered
FLUSH_PERIOD = 0.5
STORAGES = ("mcap", "sqlite3")
#: custom_data key telling a bag being written (or cut by a crash) from a closed one
STATE_KEY = "rcac_state"

_SQLITE_SCHEMA = """
CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);
CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL,
                      metadata TEXT NOT NULL);
CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
                    serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL,
                    type_description_hash TEXT NOT NULL);
CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT NULL,
                                 encoding TEXT NOT NULL,
                                 encoded_message_definition TEXT NOT NULL,
                                 type_description_hash TEXT NOT NULL);
CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
                      timestamp INTEGER NOT NULL, data BLOB NOT NULL);
CREATE INDEX timestamp_idx ON messages (timestamp ASC);
"""


# ----------------------------------------------------------------------------- QoS
_QOS_FIELDS = ("history", "reliability", "durability", "liveliness")


def qos_dicts(profiles):
    """rosbag2 (metadata v9) dictionaries of rclpy QoS profiles.

    Parameters
    ----------
    profiles : iterable of rclpy.qos.QoSProfile
        Typically ``info.qos_profile`` of ``node.get_publishers_info_by_topic(topic)``.

    Returns
    -------
    list of dict
        The layout of ``offered_qos_profiles`` in ``metadata.yaml`` (Jazzy).
    """
    out = []
    for p in profiles:
        d = {}
        for field in _QOS_FIELDS:
            d[field] = getattr(p, field).name.lower()
        d["depth"] = int(p.depth)
        for field in ("deadline", "lifespan", "liveliness_lease_duration"):
            ns = getattr(p, field).nanoseconds
            d[field] = {"sec": int(ns // 1_000_000_000), "nsec": int(ns % 1_000_000_000)}
        d["avoid_ros_namespace_conventions"] = bool(p.avoid_ros_namespace_conventions)
        out.append({k: d[k] for k in ("history", "depth", "reliability", "durability",
                                      "deadline", "lifespan", "liveliness",
                                      "liveliness_lease_duration",
                                      "avoid_ros_namespace_conventions")})
    return out


def qos_text(dicts):
    """The QoS profiles as the YAML string stored in mcap channels and sqlite topics."""
    return yaml.safe_dump(dicts, default_flow_style=False, sort_keys=False).strip() \
        if dicts else ""


# ----------------------------------------------------------------------------- writing
class Topic:
    __slots__ = ("id", "name", "msgtype", "qos", "digest", "count", "first", "last")

    def __init__(self, tid, name, msgtype, qos, digest):
        self.id, self.name, self.msgtype, self.qos, self.digest = tid, name, msgtype, qos, digest
        self.count, self.first, self.last = 0, None, None


def typestore_jazzy():
    from rosbags.typesys import get_typestore, Stores
    return get_typestore(Stores.ROS2_JAZZY)


class BagWriter:
    """Write a rosbag2 bag (mcap or sqlite3) that a crash cuts short instead of destroying.

    Parameters
    ----------
    path : str
        Bag directory to create; it must not exist.
    storage : {"mcap", "sqlite3"}
    flush_period : float
        Seconds between two flushes of the data and ``metadata.yaml``.
    compression : {"zstd", "none"}
        mcap chunk compression.

    Notes
    -----
    Not thread-safe: call from one thread (the recorder's executor).
    """

    def __init__(self, path, storage="mcap", flush_period=FLUSH_PERIOD, compression="zstd"):
        if storage not in STORAGES:
            raise ConfigError(f"storage: expected one of {STORAGES}, got {storage!r}")
        self.path = os.path.abspath(path)
        if os.path.exists(self.path):
            raise ConfigError(f"out: {self.path} already exists; rosbag2 needs a new directory")
        os.makedirs(self.path)
        self.storage = storage
        self.flush_period = float(flush_period)
        name = os.path.basename(self.path.rstrip(os.sep))
        self.file_name = f"{name}_0.{'mcap' if storage == 'mcap' else 'db3'}"
        self.file_path = os.path.join(self.path, self.file_name)
        self.topics = {}            # name -> Topic
        self._types = {}            # msgtype -> schema id (mcap) / True (sqlite)
        self._typestore = typestore_jazzy()
        self._closed = False
        self._next_flush = time.monotonic() + self.flush_period
        self.flushes = 0
        if storage == "mcap":
            from mcap.writer import CompressionType, Writer
            self._file = open(self.file_path, "xb")
            comp = CompressionType.ZSTD if compression == "zstd" else CompressionType.NONE
            # chunks are finished by time (flush), the size is only an upper bound
            self._mcap = Writer(self._file, chunk_size=4 * 1024 * 1024, compression=comp,
                                enable_crcs=True, enable_data_crcs=True)
            self._mcap.start(profile="ros2", library="rcac_ros (mcap-python)")
        else:
            self._db = sqlite3.connect(self.file_path, isolation_level="DEFERRED")
            # a second of data stays in the page cache: the db file only changes at commit
            self._db.execute("PRAGMA cache_size=-65536")
            self._db.executescript(_SQLITE_SCHEMA)
            self._db.execute("INSERT INTO schema VALUES (4, ?)", (ROS_DISTRO,))
            self._db.commit()
        self.write_metadata()

    # -- topics and messages
    def add_topic(self, name, msgtype, qos=()):
        """Register a topic; ``qos`` are the publishers' offered profiles (:func:`qos_dicts`).

        Returns
        -------
        int
            The topic's id, for :meth:`write`.
        """
        if name in self.topics:
            raise ConfigError(f"topic: {name} is already in the bag")
        digest = self._typestore.hash_rihs01(msgtype)
        qtext = qos_text(list(qos))
        if self.storage == "mcap":
            if msgtype not in self._types:
                msgdef, _ = self._typestore.generate_msgdef(msgtype, ros_version=2)
                self._types[msgtype] = self._mcap.register_schema(
                    name=msgtype, encoding="ros2msg", data=msgdef.encode())
            tid = self._mcap.register_channel(
                topic=name, message_encoding="cdr", schema_id=self._types[msgtype],
                metadata={"offered_qos_profiles": qtext, "topic_type_hash": digest})
        else:
            if msgtype not in self._types:
                msgdef, _ = self._typestore.generate_msgdef(msgtype, ros_version=2)
                self._db.execute(
                    "INSERT INTO message_definitions (topic_type, encoding, "
                    "encoded_message_definition, type_description_hash) VALUES (?, ?, ?, ?)",
                    (msgtype, "ros2msg", msgdef, digest))
                self._types[msgtype] = True
            tid = len(self.topics) + 1
            self._db.execute("INSERT INTO topics VALUES (?, ?, ?, ?, ?, ?)",
                             (tid, name, msgtype, "cdr", qtext, digest))
        self.topics[name] = Topic(tid, name, msgtype, list(qos), digest)
        return name

    def write(self, name, stamp, data, publish_time=None, sequence=0):
        """Write one serialised (CDR) message of topic ``name`` stamped ``stamp`` (ns)."""
        t = self.topics[name]
        if self.storage == "mcap":
            self._mcap.add_message(t.id, stamp, data,
                                   stamp if publish_time is None else publish_time,
                                   sequence & 0xFFFFFFFF)
        else:
            self._db.execute("INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)",
                             (t.id, stamp, data))
        t.count += 1
        if t.first is None or stamp < t.first:
            t.first = stamp
        if t.last is None or stamp > t.last:
            t.last = stamp

    def tick(self, now=None):
        """Flush when ``flush_period`` has passed since the last flush; True if it did."""
        now = time.monotonic() if now is None else now
        if now < self._next_flush or self._closed:
            return False
        self.flush()
        self._next_flush = now + self.flush_period
        return True

    def flush(self):
        """Make everything written so far survive a crash of this process, then metadata."""
        if self.storage == "mcap":
            self._mcap.flush()     # finishes the open chunk (with its CRC) and writes it
        else:
            self._db.commit()
        self.flushes += 1
        self.write_metadata()

    @property
    def message_count(self):
        return sum(t.count for t in self.topics.values())

    def metadata(self, state):
        """The ``rosbag2_bagfile_information`` dictionary (rosbag2 metadata version 9)."""
        return bag_metadata(self.storage, self.file_name, self.topics.values(), state)

    def write_metadata(self, state="recording"):
        write_metadata_file(self.path, self.metadata(state))

    def close(self):
        """Write the summary (mcap) or commit (sqlite3), then the final metadata.yaml."""
        if self._closed:
            return
        self._closed = True
        meta = self.metadata("closed")
        text = yaml.safe_dump(meta["rosbag2_bagfile_information"], sort_keys=False)
        if self.storage == "mcap":
            self._mcap.add_metadata("rosbag2", {"serialized_metadata": text,
                                                "ROS_DISTRO": ROS_DISTRO})
            self._mcap.finish()
            self._file.close()
        else:
            self._db.execute("INSERT INTO metadata (metadata_version, metadata) VALUES (?, ?)",
                             (METADATA_VERSION, text))
            self._db.commit()
            self._db.close()
        write_metadata_file(self.path, meta)


def bag_metadata(storage, file_name, topics, state):
    """rosbag2 metadata (version 9) of topics with ``count``, ``first``, ``last`` stamps."""
    topics = list(topics)
    stamps = [s for t in topics for s in (t.first, t.last) if s is not None]
    start = min(stamps) if stamps else 0
    duration = (max(stamps) - start) if stamps else 0
    count = sum(t.count for t in topics)
    return {"rosbag2_bagfile_information": {
        "version": METADATA_VERSION,
        "storage_identifier": storage,
        "duration": {"nanoseconds": int(duration)},
        "starting_time": {"nanoseconds_since_epoch": int(start)},
        "message_count": int(count),
        "topics_with_message_count": [
            {"topic_metadata": {"name": t.name, "type": t.msgtype,
                                "serialization_format": "cdr",
                                "offered_qos_profiles": list(t.qos),
                                "type_description_hash": t.digest},
             "message_count": int(t.count)} for t in topics],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [file_name],
        "files": [{"path": file_name,
                   "starting_time": {"nanoseconds_since_epoch": int(start)},
                   "duration": {"nanoseconds": int(duration)},
                   "message_count": int(count)}],
        "custom_data": {STATE_KEY: state},
        "ros_distro": ROS_DISTRO,
    }}


def write_metadata_file(path, meta):
    """Write ``metadata.yaml`` atomically (a crash leaves the previous version)."""
    tmp = os.path.join(path, "metadata.yaml.tmp")
    with open(tmp, "w") as f:
        yaml.safe_dump(meta, f, sort_keys=False)
    os.replace(tmp, os.path.join(path, "metadata.yaml"))
