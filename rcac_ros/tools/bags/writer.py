"""rosbag2 bags that survive a crash, and that say clearly when they are damaged.

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

Reading (:func:`verify`, :func:`recover`): verification uses the format's own checks through
the ``mcap`` library (chunk and data-section CRCs, the summary's statistics) or sqlite
(``PRAGMA integrity_check``), and compares the message counts with ``metadata.yaml``. A
problem raises :class:`BagError` with one line naming it. :func:`recover` salvages what is
intact (complete mcap chunks read by the ``mcap`` library's stream reader; the committed
sqlite transactions) into a new bag and says what was lost.
"""

import datetime
import os
import sqlite3
import time

import yaml

from rcac_ros.errors import BagError, ConfigError, CutBagError

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
class _Topic:
    __slots__ = ("id", "name", "msgtype", "qos", "digest", "count", "first", "last")

    def __init__(self, tid, name, msgtype, qos, digest):
        self.id, self.name, self.msgtype, self.qos, self.digest = tid, name, msgtype, qos, digest
        self.count, self.first, self.last = 0, None, None


def _typestore():
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
        self.topics = {}            # name -> _Topic
        self._types = {}            # msgtype -> schema id (mcap) / True (sqlite)
        self._typestore = _typestore()
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
        self.topics[name] = _Topic(tid, name, msgtype, list(qos), digest)
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
        _write_metadata_file(self.path, self.metadata(state))

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
        _write_metadata_file(self.path, meta)


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


def _write_metadata_file(path, meta):
    """Write ``metadata.yaml`` atomically (a crash leaves the previous version)."""
    tmp = os.path.join(path, "metadata.yaml.tmp")
    with open(tmp, "w") as f:
        yaml.safe_dump(meta, f, sort_keys=False)
    os.replace(tmp, os.path.join(path, "metadata.yaml"))


# ----------------------------------------------------------------------------- finding
def _storage_files(path):
    try:
        return sorted(f for f in os.listdir(path) if f.endswith((".mcap", ".db3")))
    except OSError:
        return []


def is_bag(path):
    """A rosbag2 directory: metadata.yaml, or storage files whose recorder died before
    writing it (rosbags writes it only at close)."""
    return os.path.isfile(os.path.join(path, "metadata.yaml")) or bool(_storage_files(path))


def find_bag(path):
    """The bag at ``path``, or the single bag below it (a demo's output folder).

    Raises
    ------
    BagError
        No bag at or below ``path``, or several (they are named).
    """
    if not os.path.exists(path):
        raise BagError(f"bag: {path} does not exist")
    if not os.path.isdir(path):
        raise BagError(f"bag: {path} is not a rosbag2 directory (give the folder that holds "
                       "metadata.yaml)")
    if is_bag(path):
        return path
    found = []
    for root, dirs, _files in os.walk(path):
        dirs.sort()
        if is_bag(root):
            found.append(root)
            dirs[:] = []          # a bag does not hold bags
    if not found:
        raise BagError(f"bag: no rosbag2 bag (a folder with metadata.yaml) in {path}")
    if len(found) > 1:
        names = ", ".join(os.path.relpath(f, path) for f in found)
        raise BagError(f"bag: {path} holds {len(found)} bags ({names}); name one")
    return found[0]


# ----------------------------------------------------------------------------- verifying
def read_metadata(path, allow_missing=False):
    """``rosbag2_bagfile_information`` of the bag at ``path`` (one-line errors).

    A bag whose storage files have no metadata.yaml (a recorder killed before writing it)
    raises :class:`CutBagError`, or with ``allow_missing`` gets metadata that only names the
    files (for :func:`recover`).
    """
    meta_path = os.path.join(path, "metadata.yaml")
    files = _storage_files(path)
    if not os.path.exists(meta_path) and files:
        if not allow_missing:
            raise CutBagError(f"bag: {path} has {', '.join(files)} but no metadata.yaml (the "
                              f"recorder was killed?); run `rcac inspect --recover {path}`")
        return {"storage_identifier": "mcap" if files[0].endswith(".mcap") else "sqlite3",
                "relative_file_paths": files, "topics_with_message_count": []}
    try:
        with open(meta_path) as f:
            doc = yaml.safe_load(f)
        info = doc["rosbag2_bagfile_information"]
        info["relative_file_paths"]
        info["storage_identifier"]
    except (OSError, yaml.YAMLError, KeyError, TypeError) as err:
        raise BagError(f"bag: {meta_path} is unreadable or not rosbag2 metadata "
                       f"({type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''})"
                       ) from err
    return info


def _metadata_counts(info):
    return {t["topic_metadata"]["name"]: int(t.get("message_count", 0))
            for t in info.get("topics_with_message_count") or []}


class Report:
    """What :func:`verify` checked, or what :func:`recover` salvaged.

    Attributes
    ----------
    storage : str
    counts : dict
        topic -> messages in the file(s).
    chunks : int
        Complete mcap chunks (0 for sqlite3).
    checks : list of str
        The checks that passed.
    lost : list of str
        What could not be salvaged (recover).
    """

    def __init__(self, path, storage):
        self.path, self.storage = path, storage
        self.counts, self.chunks, self.checks, self.lost = {}, 0, [], []
        self.types = {}
        self.start = self.end = None

    @property
    def message_count(self):
        return sum(self.counts.values())

    def stamp(self, t):
        self.start = t if self.start is None else min(self.start, t)
        self.end = t if self.end is None else max(self.end, t)


def _mcap_scan(file_path, report, on_message=None, strict=True, recording=False):
    """Scan an mcap file record by record with the ``mcap`` library, checking CRCs.

    With ``strict`` False, stop quietly at the first damaged or incomplete record (recovery)
    and return the error text; else raise :class:`BagError`: :class:`CutBagError` when the
    file ends inside a record and ``recording`` (metadata.yaml was never closed).
    """
    from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Schema, Statistics
    from mcap.stream_reader import breakup_chunk, StreamReader

    schemas, channels = {}, {}
    stats, footer, data_end = None, None, False
    name = os.path.basename(file_path)
    if not os.path.isfile(file_path):
        raise BagError(f"bag: {file_path} is missing")
    size = os.path.getsize(file_path)
    offset, error, at_eof = 0, None, False
    with open(file_path, "rb") as f:
        try:
            for record in StreamReader(f, emit_chunks=True, validate_crcs=True).records:
                records = [record]
                if isinstance(record, Chunk):
                    records = breakup_chunk(record, validate_crc=True)
                    report.chunks += 1
                for rec in records:
                    if isinstance(rec, Schema):
                        schemas[rec.id] = rec
                    elif isinstance(rec, Channel):
                        channels[rec.id] = rec
                        report.counts.setdefault(rec.topic, 0)
                        schema = schemas.get(rec.schema_id)
                        report.types[rec.topic] = (schema.name if schema else "", rec)
                    elif isinstance(rec, Message):
                        topic = channels[rec.channel_id].topic
                        report.counts[topic] += 1
                        report.stamp(rec.log_time)
                        if on_message is not None:
                            on_message(channels[rec.channel_id], schemas, rec)
                    elif isinstance(rec, Statistics):
                        stats = rec
                    elif isinstance(rec, DataEnd):
                        data_end = True
                    elif isinstance(rec, Footer):
                        footer = rec
                offset = f.tell()
        except Exception as err:  # noqa: BLE001 - McapError, struct.error, zstd, Overflow...
            error, at_eof = err, f.tell() >= size
    if error is not None:
        if at_eof:
            text = f"{name} ends inside a record after byte {offset} (no footer)"
        else:
            first = str(error).splitlines()[0] if str(error) else type(error).__name__
            text = f"{name}: damaged record after byte {offset}: {first}"
        if not strict:
            return text
        if at_eof and recording and footer is None:
            raise CutBagError(_cut_text(file_path, text)) from error
        raise BagError(f"bag: {text}; the file is corrupt (rcac inspect --recover salvages "
                       "the intact chunks before it)") from error
    if footer is None:
        text = f"{name}: no footer"
        if strict:
            raise CutBagError(_cut_text(file_path, text))
        return text
    if strict and stats is not None:
        by_topic = {}
        for cid, n in stats.channel_message_counts.items():
            by_topic[channels[cid].topic] = by_topic.get(channels[cid].topic, 0) + n
        for topic, n in report.counts.items():
            if by_topic.get(topic, 0) != n:
                raise BagError(f"bag: {name}: {topic} holds {n} messages, its summary says "
                               f"{by_topic.get(topic, 0)}")
        report.checks.append("summary statistics")
    report.checks.append(f"{report.chunks} chunk CRCs")
    if data_end:
        report.checks.append("data section CRC")
    return None


def _cut_text(path, what):
    bag = os.path.dirname(path)
    return (f"bag: {what} (the recorder was killed?); run `rcac inspect --recover {bag}` "
            "to salvage the complete chunks")


def _sqlite_check(file_path, report, strict=True):
    if not os.path.isfile(file_path):
        raise BagError(f"bag: {file_path} is missing")
    name = os.path.basename(file_path)
    journal = file_path + "-journal"
    if strict and os.path.exists(journal) and os.path.getsize(journal) > 0:
        raise CutBagError(f"bag: {name} has an unfinished transaction ({os.path.basename(journal)}"
                          f", the recorder was killed?); run `rcac inspect --recover "
                          f"{os.path.dirname(file_path)}` to roll it back")
    uri = f"file:{file_path}?mode=ro" if strict else f"file:{file_path}"
    try:
        db = sqlite3.connect(uri, uri=True)
        try:
            result = db.execute("PRAGMA integrity_check").fetchall()
            if result != [("ok",)]:
                text = " ".join(" ".join(r[0] for r in result[:3]).split())
                text = text.replace("*** in database main *** ", "")
                raise BagError(f"bag: {name} fails sqlite's integrity check: {text}")
            rows = db.execute("SELECT t.name, t.type, COUNT(m.id), MIN(m.timestamp), "
                              "MAX(m.timestamp) FROM topics t LEFT JOIN messages m "
                              "ON m.topic_id = t.id GROUP BY t.id").fetchall()
        finally:
            db.close()
    except sqlite3.DatabaseError as err:
        raise BagError(f"bag: {name}: sqlite error: {err}") from err
    for topic, msgtype, n, lo, hi in rows:
        report.counts[topic] = int(n)
        report.types[topic] = (msgtype, None)
        if lo is not None:
            report.stamp(lo)
            report.stamp(hi)
    report.checks.append("sqlite integrity check")


def verify(path, on_message=None):
    """Check a bag with what its format offers; raise :class:`BagError` naming the problem.

    Parameters
    ----------
    path : str
        Bag directory.
    on_message : callable, optional
        mcap: called as ``on_message(channel, schemas, message)`` (``mcap.records``) for every
        message while scanning (the publishers' send stamps and sequence numbers).

    Returns
    -------
    Report
        The counts found and the checks that passed.

    Raises
    ------
    CutBagError
        The bag was not closed (no mcap footer, a hot sqlite journal, or ``metadata.yaml``
        still says ``recording`` with fewer messages than the file holds).
    BagError
        A CRC mismatch, a damaged record, a failed integrity check, or message counts that
        differ from ``metadata.yaml``.
    """
    info = read_metadata(path)
    storage = info["storage_identifier"]
    if storage not in STORAGES:
        raise BagError(f"bag: storage {storage!r} in {path}/metadata.yaml is not one of "
                       f"{STORAGES}")
    report = Report(path, storage)
    state = (info.get("custom_data") or {}).get(STATE_KEY)
    for rel in info["relative_file_paths"]:
        file_path = os.path.join(path, rel)
        if storage == "mcap":
            _mcap_scan(file_path, report, on_message, recording=state == "recording")
        else:
            _sqlite_check(file_path, report)
    expected = _metadata_counts(info)
    for topic, n in report.counts.items():
        want = expected.get(topic)
        if want is None:
            raise BagError(f"bag: {topic} ({n} messages) is not listed in metadata.yaml")
        if want != n:
            if state == "recording" and n >= want:
                raise CutBagError(f"bag: {path} was not closed (metadata.yaml says recording, "
                                  f"the recorder was killed?); run `rcac inspect --recover "
                                  f"{path}`")
            raise BagError(f"bag: {topic} holds {n} messages, metadata.yaml says {want}")
    missing = set(expected) - set(report.counts)
    if missing:
        raise BagError(f"bag: metadata.yaml lists {sorted(missing)[0]}, absent from the files")
    if state == "recording":
        raise CutBagError(f"bag: {path} was not closed (metadata.yaml says recording, the "
                          f"recorder was killed?); run `rcac inspect --recover {path}`")
    report.checks.append("message counts against metadata.yaml")
    return report


def _size_text(n):
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{n} B"
        n /= 1024.0


def _time_text(ns):
    t = datetime.datetime.fromtimestamp(ns * 1e-9)
    return f"{t.strftime('%b %e %Y %H:%M:%S')}.{ns % 1_000_000_000:09d} " \
        f"({ns // 1_000_000_000}.{ns % 1_000_000_000:09d})"


def bag_info(path):
    """The header ``ros2 bag info`` prints, from ``metadata.yaml`` and the file sizes."""
    info = read_metadata(path)
    files = info["relative_file_paths"]
    size = sum(os.path.getsize(os.path.join(path, f)) for f in files
               if os.path.isfile(os.path.join(path, f)))
    start = int(info.get("starting_time", {}).get("nanoseconds_since_epoch", 0))
    dur = int(info.get("duration", {}).get("nanoseconds", 0))
    lines = [f"Files:             {', '.join(files)}",
             f"Bag size:          {_size_text(size)}",
             f"Storage id:        {info['storage_identifier']}",
             f"ROS Distro:        {info.get('ros_distro', 'unknown')}",
             f"Duration:          {dur // 1_000_000_000}.{dur % 1_000_000_000:09d}s",
             f"Start:             {_time_text(start)}",
             f"End:               {_time_text(start + dur)}",
             f"Messages:          {info.get('message_count', 0)}"]
    first = True
    for t in info.get("topics_with_message_count") or []:
        meta = t["topic_metadata"]
        head = "Topic information: " if first else " " * 19
        lines.append(f"{head}Topic: {meta['name']} | Type: {meta['type']} | Count: "
                     f"{t.get('message_count', 0)} | Serialization Format: "
                     f"{meta.get('serialization_format', 'cdr')}")
        first = False
    lines += ["Service:           0", "Service information: "]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- recovering
def _mcap_salvage_indexed(file_path, report, on_message):
    """Copy every chunk whose CRC checks, through the summary's chunk index.

    For a file whose footer and summary are intact (damage in the data section): a damaged
    chunk is skipped, and the chunks after it are kept. Returns False when the summary is
    unusable (a file cut by a crash), for the linear scan of :func:`_mcap_scan`.
    """
    from mcap.reader import SeekingReader
    from mcap.records import Chunk, Message
    from mcap.stream_reader import breakup_chunk, StreamReader

    name = os.path.basename(file_path)
    with open(file_path, "rb") as f:
        try:
            summary = SeekingReader(f).get_summary()
        except Exception:  # noqa: BLE001 - no footer, bad summary: the linear scan decides
            return False
        if summary is None or not summary.chunk_indexes or not summary.channels:
            return False
        schemas, channels = summary.schemas, summary.channels
        for channel in channels.values():
            schema = schemas.get(channel.schema_id)
            report.counts.setdefault(channel.topic, 0)
            report.types[channel.topic] = (schema.name if schema else "", channel)
        for ci in summary.chunk_indexes:
            try:
                f.seek(ci.chunk_start_offset)
                record = next(StreamReader(f, skip_magic=True, emit_chunks=True).records)
                if not isinstance(record, Chunk):
                    raise ValueError(f"expected a chunk, found {type(record).__name__}")
                records = breakup_chunk(record, validate_crc=True)
            except Exception as err:  # noqa: BLE001 - any damage: skip this chunk
                first = str(err).splitlines()[0] if str(err) else type(err).__name__
                span = 1e-9 * (ci.message_end_time - ci.message_start_time)
                report.lost.append(f"the chunk at byte {ci.chunk_start_offset} of {name} "
                                   f"({span:.3f} s of messages): {first}")
                continue
            report.chunks += 1
            for rec in records:
                if isinstance(rec, Message) and rec.channel_id in channels:
                    channel = channels[rec.channel_id]
                    report.counts[channel.topic] += 1
                    report.stamp(rec.log_time)
                    on_message(channel, schemas, rec)
    return True


def default_recovered_path(path):
    return path.rstrip(os.sep) + "_recovered"


def recover(path, out=None):
    """Salvage a bag cut by a crash, or damaged, into a new bag ``out``.

    mcap: every complete chunk (CRC checked) before the first damaged or missing record is
    copied, through the ``mcap`` library's stream reader and writer, into a new, closed mcap
    file. sqlite3: the database is opened read-write, which rolls back an unfinished
    transaction (sqlite's own recovery), then copied with the backup API and checked.

    Parameters
    ----------
    path : str
        The damaged bag.
    out : str, optional
        The new bag; default ``<path>_recovered``.

    Returns
    -------
    Report
        ``counts`` salvaged per topic, ``lost`` what was not.
    """
    info = read_metadata(path, allow_missing=True)
    storage = info["storage_identifier"]
    out = os.path.abspath(out or default_recovered_path(path))
    if os.path.exists(out):
        raise BagError(f"out: {out} already exists; give --recover-out a new directory")
    expected = _metadata_counts(info)
    qos = {t["topic_metadata"]["name"]: t["topic_metadata"].get("offered_qos_profiles") or []
           for t in info.get("topics_with_message_count") or []}
    report = Report(out, storage)
    if storage == "mcap":
        writer = BagWriter(out, "mcap", flush_period=1e9)
        try:
            def copy(channel, schemas, msg):
                if channel.topic not in writer.topics:
                    schema = schemas.get(channel.schema_id)
                    writer.add_topic(channel.topic, schema.name, qos.get(channel.topic, []))
                writer.write(channel.topic, msg.log_time, msg.data, msg.publish_time,
                             msg.sequence)

            for rel in info["relative_file_paths"]:
                file_path = os.path.join(path, rel)
                if _mcap_salvage_indexed(file_path, report, copy):
                    continue        # an intact summary: each chunk on its own
                problem = _mcap_scan(file_path, report, copy, strict=False)
                if problem:
                    report.lost.append(f"everything from the first damaged or cut record on "
                                       f"({problem})")
            for topic, (msgtype, _channel) in report.types.items():
                if topic not in writer.topics:
                    writer.add_topic(topic, msgtype, qos.get(topic, []))
        finally:
            writer.close()
    elif storage == "sqlite3":
        os.makedirs(out)
        for rel in info["relative_file_paths"]:
            src_path = os.path.join(path, rel)
            if not os.path.isfile(src_path):
                raise BagError(f"bag: {src_path} is missing")
            src = sqlite3.connect(src_path)     # read-write: rolls back a hot journal
            try:
                dst = sqlite3.connect(os.path.join(out, rel))
                src.backup(dst)
                dst.close()
            except sqlite3.DatabaseError as err:
                raise BagError(f"bag: {rel}: sqlite cannot read it ({err}); nothing "
                               "salvaged") from err
            finally:
                src.close()
            _sqlite_check(os.path.join(out, rel), report, strict=False)
        typestore = _typestore()
        rows = []
        for topic, (msgtype, _channel) in report.types.items():
            t = _Topic(0, topic, msgtype, qos.get(topic, []), typestore.hash_rihs01(msgtype))
            t.count = report.counts.get(topic, 0)
            rows.append(t)
        meta = bag_metadata("sqlite3", "", rows, "closed")["rosbag2_bagfile_information"]
        start = report.start or 0
        dur = (report.end - report.start) if report.start is not None else 0
        meta["starting_time"] = {"nanoseconds_since_epoch": int(start)}
        meta["duration"] = {"nanoseconds": int(dur)}
        meta["relative_file_paths"] = list(info["relative_file_paths"])
        meta["files"] = [{"path": rel, "starting_time": {"nanoseconds_since_epoch": int(start)},
                          "duration": {"nanoseconds": int(dur)},
                          "message_count": report.message_count}
                         for rel in info["relative_file_paths"]]
        _write_metadata_file(out, {"rosbag2_bagfile_information": meta})
    else:
        raise BagError(f"bag: storage {storage!r} cannot be recovered")
    for topic, want in expected.items():
        got = report.counts.get(topic, 0)
        if got < want:
            report.lost.append(f"{topic}: {want - got} of the {want} messages metadata.yaml "
                               "counted")
    return report


def format_recovery(src, report):
    """What was salvaged and what was lost, as text."""
    span = ""
    if report.start is not None:
        span = (f", {1e-9 * (report.end - report.start):.3f} s from "
                f"{datetime.datetime.fromtimestamp(report.start * 1e-9).isoformat()}")
    lines = [f"rcac inspect: recovered {src} into {report.path}: {report.message_count} "
             f"messages" + (f" in {report.chunks} complete chunks" if report.chunks else "")
             + span]
    for topic, n in sorted(report.counts.items()):
        lines.append(f"  salvaged {topic}: {n}")
    if report.lost:
        for item in report.lost:
            lines.append(f"  lost: {item}")
    else:
        lines.append("  lost: nothing the metadata counted")
    return "\n".join(lines)
