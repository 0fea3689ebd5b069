"""rosbag2 bags that say clearly when they are damaged: finding, reading, verifying.

:func:`verify` uses the format's own checks through the ``mcap`` library (chunk and
data-section CRCs, the summary's statistics) or sqlite (``PRAGMA integrity_check``), and
compares the message counts with ``metadata.yaml``. A problem raises :class:`BagError` with
one line naming it (:class:`CutBagError` for a bag a crash left unclosed, which
:func:`rcac_ros.tools.bags.recover.recover` salvages). The bags are written by
:class:`rcac_ros.tools.bags.writer.BagWriter`.
"""

import datetime
import os
import sqlite3

import yaml

from rcac_ros.errors import BagError, CutBagError
from rcac_ros.tools.bags.writer import STATE_KEY, STORAGES


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


def metadata_counts(info):
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


def mcap_scan(file_path, report, on_message=None, strict=True, recording=False):
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


def sqlite_check(file_path, report, strict=True):
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
            mcap_scan(file_path, report, on_message, recording=state == "recording")
        else:
            sqlite_check(file_path, report)
    expected = metadata_counts(info)
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
