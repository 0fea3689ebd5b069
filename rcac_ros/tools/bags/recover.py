"""Salvaging a bag cut by a crash, or damaged, into a new bag (``rcac inspect --recover``).

:func:`recover` salvages what is intact (complete mcap chunks read by the ``mcap`` library's
stream reader; the committed sqlite transactions) into a new bag, written by
:class:`rcac_ros.tools.bags.writer.BagWriter`, and says what was lost
(:func:`format_recovery`).
"""

import datetime
import os
import sqlite3

from rcac_ros.errors import BagError
from rcac_ros.tools.bags.verify import mcap_scan, metadata_counts, read_metadata, Report, \
    sqlite_check
from rcac_ros.tools.bags.writer import bag_metadata, BagWriter, Topic, typestore_jazzy, \
    write_metadata_file


def _mcap_salvage_indexed(file_path, report, on_message):
    """Copy every chunk whose CRC checks, through the summary's chunk index.

    For a file whose footer and summary are intact (damage in the data section): a damaged
    chunk is skipped, and the chunks after it are kept. Returns False when the summary is
    unusable (a file cut by a crash), for the linear scan of :func:`.verify.mcap_scan`.
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
    expected = metadata_counts(info)
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
                problem = mcap_scan(file_path, report, copy, strict=False)
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
            sqlite_check(os.path.join(out, rel), report, strict=False)
        typestore = typestore_jazzy()
        rows = []
        for topic, (msgtype, _channel) in report.types.items():
            t = Topic(0, topic, msgtype, qos.get(topic, []), typestore.hash_rihs01(msgtype))
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
        write_metadata_file(out, {"rosbag2_bagfile_information": meta})
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
