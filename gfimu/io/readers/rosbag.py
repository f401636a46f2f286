"""ROS bags (ROS 1 ``.bag``, ROS 2 bag folders with sqlite3 or MCAP storage, bare ``.mcap`` or
``.db3`` files): the reader of ``gfimu convert rosbag``.

Each accelerometer of the given ``array.toml`` is one ``sensor_msgs/msg/Imu`` stream: the
messages of its ``topic`` when it names one, otherwise the Imu messages (on any topic) whose
``header.frame_id`` is the accelerometer's ``name``. ``linear_acceleration`` is in the frame of
``header.frame_id``, which is the sensor frame of the array: position and
``rotation_body_sensor`` in ``array.toml`` place it in the body frame B.

The streams are not synchronous: each is read at its own header stamps and interpolated
linearly onto one time base, a uniform grid at the median of the streams' median periods that
spans the overlap of all streams (from the latest first stamp to the earliest last stamp; never
extrapolated). The interpolation of stream y at a grid time t between its stamps t_k <= t <
t_{k+1} is y(t) = y_k + (t - t_k) / (t_{k+1} - t_k) (y_{k+1} - y_k). A stream whose stamps are
the grid itself is copied exactly. Linear rather than cubic: on the simulated random motion at
500 Hz both cost less than the sensor noise, and linear cannot overshoot a clipped or spiky
reading (the measured costs are in ``docs/formats.md``).

Gaps: a step of a stream's stamps over 1.5 of its median period is a gap (its missing messages
are counted in the report, with where they are). A gap up to ``max_gap_periods`` periods is
bridged by the interpolation; in a longer one the grid samples are left out, so the log holds a
time gap there, which the log format's readers and estimators treat as a break
(:meth:`gfimu.log.Log.segments`).

The pure part (:func:`align_streams`) works on arrays; only :func:`read_bag` touches files and
the ``rosbags`` package (the optional extra ``rosbag``).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from . import Conversion, Reader
from ..time_grid import common_period_ns
from ..errors import LogFormatError
from ...errors import InputError, MissingExtraError
from ...log import Log

IMU_TYPE = "sensor_msgs/msg/Imu"
GAP_FACTOR = 1.5  # a step over 1.5 median periods is a gap (as gfimu.log.Log.gaps)
MAX_GAP_PERIODS = 3.0  # default: gaps up to 3 periods (2 missing messages) are interpolated over


# --- the pure part: streams onto one time base --------------------------------------------------

@dataclass(frozen=True)
class StreamGaps:
    """Gaps of one stream: steps over ``GAP_FACTOR`` median periods."""

    period_ns: int
    start_ns: np.ndarray  # stamp before each gap
    end_ns: np.ndarray  # stamp after each gap
    missing: np.ndarray  # messages missing in each gap, round(step / period) - 1

    @property
    def n_missing(self) -> int:
        return int(self.missing.sum())


def stream_gaps(stamps_ns: np.ndarray, factor: float = GAP_FACTOR) -> StreamGaps:
    """The gaps of sorted, distinct ``stamps_ns`` (int64) relative to their median step."""
    t = np.asarray(stamps_ns, dtype=np.int64)
    dt = np.diff(t)
    period = int(round(float(np.median(dt)))) if dt.size else 0
    idx = np.nonzero(dt > factor * period)[0] if dt.size else np.zeros(0, dtype=np.int64)
    missing = np.maximum(np.rint(dt[idx] / max(period, 1)).astype(np.int64) - 1, 1)
    return StreamGaps(period, t[idx], t[idx + 1], missing)


@dataclass(frozen=True)
class Alignment:
    """Streams interpolated onto one time base."""

    timestamps_ns: np.ndarray  # (N,) the grid, with the samples inside long gaps left out
    values: tuple[np.ndarray, ...]  # per stream (N, d)
    period_ns: int
    overlap_ns: tuple[int, int]  # first and last time covered by every stream
    n_grid: int  # grid samples over the overlap, before leaving out the long gaps
    long_gaps: tuple[tuple[int, int, int], ...]  # (start_ns, end_ns, grid samples left out), merged
    max_offset_ns: int  # largest distance of a grid time from the nearest stamp of some stream


def align_streams(stamps_ns: list[np.ndarray], values: list[np.ndarray],
                  max_gap_periods: float = MAX_GAP_PERIODS) -> Alignment:
    """Linear interpolation of each stream (sorted distinct int64 ``stamps_ns[i]``, ``values[i]``
    (n_i, d_i)) onto a uniform grid at the median of the streams' median steps, over the overlap
    of all streams. Grid times strictly inside a stream's gap longer than ``max_gap_periods`` of
    that stream's median step are left out. ValueError when the streams do not overlap.
    """
    if not stamps_ns:
        raise ValueError("no stream to align")
    stamps = [np.asarray(t, dtype=np.int64) for t in stamps_ns]
    if any(t.size < 2 for t in stamps):
        raise ValueError("a stream holds fewer than 2 messages")
    periods = [float(np.median(np.diff(t))) for t in stamps]
    period = common_period_ns(periods)  # the median of the streams' median periods (io/time_grid.py)
    start = max(int(t[0]) for t in stamps)
    end = min(int(t[-1]) for t in stamps)
    if end < start + period:
        raise ValueError(f"the streams do not overlap in time (latest first stamp {start} ns, "
                         f"earliest last stamp {end} ns)")
    grid = start + period * np.arange((end - start) // period + 1, dtype=np.int64)
    keep = np.ones(grid.size, dtype=bool)
    intervals = []
    for t, p in zip(stamps, periods):
        dt = np.diff(t)
        for i in np.nonzero(dt > max_gap_periods * p)[0]:
            a, b = int(t[i]), int(t[i + 1])
            inside = (grid > a) & (grid < b)
            if inside.any():
                intervals.append((a, b))
                keep &= ~inside
    merged: list[list[int]] = []
    for a, b in sorted(intervals):
        if merged and a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    long_gaps = tuple((a, b, int(np.count_nonzero((grid > a) & (grid < b)))) for a, b in merged)
    kept = grid[keep]
    out = []
    max_offset = 0
    for t, v in zip(stamps, values):
        v = np.asarray(v, dtype=float).reshape(t.size, -1)
        # exact arithmetic for the fraction: int64 offsets from the stream's stamps
        k = np.clip(np.searchsorted(t, kept, side="right") - 1, 0, t.size - 2)
        frac = (kept - t[k]).astype(float) / (t[k + 1] - t[k]).astype(float)
        y = v[k] + frac[:, None] * (v[k + 1] - v[k])
        y[frac == 0.0] = v[k[frac == 0.0]]  # on a stamp: the reading itself
        y[frac == 1.0] = v[k[frac == 1.0] + 1]
        out.append(y)
        nearest = np.minimum(kept - t[k], t[k + 1] - kept)
        max_offset = max(max_offset, int(nearest.max()) if nearest.size else 0)
    return Alignment(kept, tuple(out), period, (start, end), int(grid.size), long_gaps, max_offset)


# --- reading the bag ----------------------------------------------------------------------------

@dataclass(frozen=True)
class ImuStream:
    """The Imu messages of one accelerometer, sorted by header stamp (duplicates dropped)."""

    source: str  # "topic /imu0" or "frame_id 'a1' on /imu"
    topics: tuple[str, ...]
    frame_ids: tuple[str, ...]
    stamps_ns: np.ndarray  # (n,) int64
    accel_mps2: np.ndarray  # (n, 3) linear_acceleration, frame of header.frame_id
    gyro_radps: np.ndarray  # (n, 3) angular_velocity, same frame
    gyro_given: np.ndarray  # (n,) angular_velocity_covariance[0] != -1 and angular_velocity finite
    accel_var_mps2: np.ndarray  # (n, 3) diagonal of linear_acceleration_covariance; nan where not given
    gyro_var_radps: np.ndarray  # (n, 3) diagonal of angular_velocity_covariance; nan where not given
    duplicates: int = 0
    out_of_order: int = 0
    stamps_from_bag: bool = False  # header stamps all zero: the bag's record times are used


def _diagonal_variance(cov: np.ndarray) -> np.ndarray:
    """(n, 3) diagonals of (n, 9) row-major covariances; nan where not given (-1 first, or all 0)."""
    diag = cov[:, [0, 4, 8]].astype(float)
    unknown = (cov[:, 0] == -1) | np.all(cov == 0, axis=1) | np.any(~np.isfinite(diag) | (diag < 0), axis=1)
    diag[unknown] = np.nan
    return diag


def _storage_of_folder(path: Path) -> Path | None:
    """The one ``.db3`` or ``.mcap`` file of a ROS 2 bag folder that has lost its ``metadata.yaml`` (None when
    ``path`` is not such a folder); LogFormatError when it holds several, which only the metadata can order."""
    if not path.is_dir() or (path / "metadata.yaml").exists():
        return None
    files = sorted(p for p in path.iterdir() if p.is_file() and p.suffix in (".db3", ".mcap"))
    if len(files) > 1:
        raise LogFormatError(f"a ROS 2 bag folder without metadata.yaml holding {len(files)} storage files "
                             f"({', '.join(p.name for p in files)}); without the metadata their order is unknown: "
                             "restore metadata.yaml (ros2 bag reindex) or give one file", path)
    return files[0] if files else None


def _check_metadata(path: Path) -> None:
    """Refuse a ROS 2 ``metadata.yaml`` that rosbags cannot read, naming the file and the key: parsed with
    bounded depth and aliases (:mod:`gfimu.io.safe_yaml`), then the keys rosbags reads checked for their types."""
    from ..safe_yaml import load_yaml

    doc, _ = load_yaml(path, "the metadata.yaml of a ROS 2 bag", extra="rosbag")
    top = "rosbag2_bagfile_information"

    def bad(key: str, expected: str, value) -> LogFormatError:
        shown = repr(value)
        shown = shown if len(shown) <= 80 else shown[:80] + "..."
        return LogFormatError(f"{key}: expected {expected}, got {shown} (not a ROS 2 bag's metadata, or damaged; "
                              "ros2 bag reindex writes it anew)", path, None, key)

    def get(node: dict, name: str, where: str, kind, expected: str):
        if name not in node:
            raise LogFormatError(f"{where}: has no {name} (not a ROS 2 bag's metadata, or damaged; ros2 bag reindex "
                                 "writes it anew)", path, None, where)
        value = node[name]
        if not isinstance(value, kind) or isinstance(value, bool):
            raise bad(f"{where}.{name}", expected, value)
        return value

    if not isinstance(doc, dict) or top not in doc:
        raise LogFormatError(f"expected the key {top} at the top (not a ROS 2 bag's metadata)", path, None, top)
    info = doc[top]
    if not isinstance(info, dict):
        raise bad(top, "a mapping", info)
    get(info, "version", top, int, "an integer")
    get(info, "storage_identifier", top, str, "text (sqlite3 or mcap)")
    files = get(info, "relative_file_paths", top, list, "a list of file names")
    for k, name in enumerate(files):
        if not isinstance(name, str):
            raise bad(f"{top}.relative_file_paths[{k}]", "a file name", name)
    get(info, "message_count", top, int, "an integer")
    get(get(info, "duration", top, dict, "a mapping"), "nanoseconds", f"{top}.duration", int, "an integer")
    get(get(info, "starting_time", top, dict, "a mapping"), "nanoseconds_since_epoch", f"{top}.starting_time", int,
        "an integer")
    for k, entry in enumerate(get(info, "topics_with_message_count", top, list, "a list of topics")):
        where = f"{top}.topics_with_message_count[{k}]"
        if not isinstance(entry, dict):
            raise bad(where, "a mapping", entry)
        get(entry, "message_count", where, int, "an integer")
        meta = get(entry, "topic_metadata", where, dict, "a mapping")
        for name in ("name", "type", "serialization_format"):
            get(meta, name, f"{where}.topic_metadata", str, "text")


def _bag_kind(path: Path) -> str:
    """What ``path`` holds, from its first bytes (or metadata.yaml); LogFormatError when not a bag."""
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            return "ROS 2 bag"
        raise LogFormatError("not a ROS bag: a folder without metadata.yaml (expected a ROS 1 .bag file, a ROS 2 "
                             "bag folder, or an .mcap or .db3 file)", path)
    with path.open("rb") as f:
        head = f.read(16)
    if head.startswith(b"#ROSBAG V2.0"):
        if path.suffix != ".bag":
            raise LogFormatError("a ROS 1 bag whose name does not end in .bag; rename it to *.bag", path)
        return "ROS 1 bag"
    if head.startswith(b"\x89MCAP"):
        if path.suffix != ".mcap":
            raise LogFormatError("an MCAP file whose name does not end in .mcap; rename it to *.mcap", path)
        return "MCAP file"
    if head.startswith(b"SQLite format 3\x00"):
        if path.suffix != ".db3":
            raise LogFormatError("an SQLite file whose name does not end in .db3; rename it to *.db3", path)
        return "ROS 2 sqlite3 file"
    if head.startswith(b"#ROSBAG"):
        version = head.split(b"\n")[0].decode("ascii", "replace")
        raise LogFormatError(f"a ROS 1 bag of an unsupported version ({version}); only V2.0 is read", path)
    raise LogFormatError("not a ROS bag (expected a ROS 1 .bag file starting with '#ROSBAG V2.0', a ROS 2 bag "
                         "folder with metadata.yaml, or an .mcap or .db3 file)", path)


@dataclass(frozen=True)
class TopicMessages:
    """The fields of one topic's Imu messages that gfimu uses, in the bag's order."""

    record_ns: np.ndarray  # (n,) int64 time the bag recorded each message
    stamp_ns: np.ndarray  # (n,) int64 header.stamp
    frame_code: np.ndarray  # (n,) int index into ``frame_ids``
    frame_ids: tuple[str, ...]
    fields: np.ndarray  # (n, 24) linear_acceleration, angular_velocity, their 9-element covariances

    def __len__(self) -> int:
        return int(self.stamp_ns.size)

    def frame(self, name: str) -> np.ndarray:
        """(n,) True where header.frame_id is ``name``, a leading ``/`` on either side ignored (tf in ROS 1
        wrote frame ids as ``/imu``; tf2 and ROS 2 write ``imu``)."""
        codes = [k for k, f in enumerate(self.frame_ids) if _frame_name(f) == _frame_name(name)]
        return np.isin(self.frame_code, codes)

    def accel_given(self) -> np.ndarray:
        """(n,) True where linear_acceleration_covariance[0] is not -1, the REP-145 mark for "not provided"."""
        return self.fields[:, 6] != -1

    def accel_finite(self) -> np.ndarray:
        """(n,) True where linear_acceleration is finite (a nan or inf is no reading)."""
        return np.isfinite(self.fields[:, 0:3]).all(axis=1)

    def gyro_given(self) -> np.ndarray:
        """(n,) True where angular_velocity_covariance[0] is not -1 and angular_velocity is finite."""
        return (self.fields[:, 15] != -1) & np.isfinite(self.fields[:, 3:6]).all(axis=1)


def _frame_name(frame_id: str) -> str:
    return frame_id[1:] if frame_id.startswith("/") else frame_id


def _messages(path: Path) -> tuple[str, dict[str, str], dict[str, TopicMessages]]:
    """(kind, {topic: msgtype}, {Imu topic: its messages}) read from the bag."""
    from array import array as packed

    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise MissingExtraError("reading ROS bags", "rosbags", "rosbag") from None
    if path.name == "metadata.yaml" and path.is_file():  # a ROS 2 bag named by its metadata: the bag is the folder
        path = path.parent
    shown = path
    storage = _storage_of_folder(path)
    if storage is not None:  # metadata.yaml lost: its one storage file is read on its own, as a bare file is
        path = storage
    kind = _bag_kind(path)
    if path.is_dir():
        _check_metadata(path / "metadata.yaml")
    if storage is not None:
        kind = f"ROS 2 bag folder without metadata.yaml ({storage.name} read on its own, as a bare {kind})"
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            topics = {name: info.msgtype for name, info in reader.topics.items()}
            imu = [c for c in reader.connections if c.msgtype == IMU_TYPE]
            rows = {c.topic: (packed("q"), packed("q"), packed("l"), {}, packed("d")) for c in imu}
            if imu:
                for conn, record_ns, raw in reader.messages(connections=imu):
                    m = reader.deserialize(raw, conn.msgtype)
                    rec, stamp, code, frames, fields = rows[conn.topic]
                    rec.append(record_ns)
                    stamp.append(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
                    code.append(frames.setdefault(m.header.frame_id, len(frames)))
                    a, w = m.linear_acceleration, m.angular_velocity
                    fields.extend((a.x, a.y, a.z, w.x, w.y, w.z))
                    fields.extend(np.asarray(m.linear_acceleration_covariance, float).reshape(9))
                    fields.extend(np.asarray(m.angular_velocity_covariance, float).reshape(9))
    except (OSError, MissingExtraError):
        raise
    except Exception as exc:  # noqa: BLE001 - a corrupt bag fails in many ways inside rosbags
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise LogFormatError(f"cannot read this {kind} (corrupt or truncated?): {text}", shown) from None
    out = {t: TopicMessages(np.array(rec, dtype=np.int64), np.array(stamp, dtype=np.int64),
                            np.array(code, dtype=np.int64), tuple(frames), np.array(fields, dtype=float).reshape(-1, 24))
           for t, (rec, stamp, code, frames, fields) in rows.items()}
    return kind, topics, out


def _stream(source: str, topics: list[str], parts: list[tuple[TopicMessages, np.ndarray]]) -> ImuStream:
    """An :class:`ImuStream` of the messages ``parts`` select (topic, boolean mask), in record order."""
    record = np.concatenate([m.record_ns[sel] for m, sel in parts])
    stamps = np.concatenate([m.stamp_ns[sel] for m, sel in parts])
    fields = np.concatenate([m.fields[sel] for m, sel in parts])
    frames = sorted({m.frame_ids[c] for m, sel in parts for c in np.unique(m.frame_code[sel])})
    by_record = np.argsort(record, kind="stable")
    stamps, record, fields = stamps[by_record], record[by_record], fields[by_record]
    from_bag = bool(stamps.size) and not np.any(stamps)
    if from_bag:
        stamps = record
    order = np.argsort(stamps, kind="stable")
    out_of_order = int(np.count_nonzero(np.diff(stamps) < 0))
    stamps = stamps[order]
    first = np.concatenate([[True], np.diff(stamps) > 0])
    f = fields[order[first]]
    return ImuStream(
        source, tuple(topics), tuple(frames), stamps[first], f[:, 0:3], f[:, 3:6],
        (f[:, 15] != -1) & np.isfinite(f[:, 3:6]).all(axis=1),
        _diagonal_variance(f[:, 6:15]), _diagonal_variance(f[:, 15:24]),
        duplicates=int(np.count_nonzero(~first)), out_of_order=out_of_order, stamps_from_bag=from_bag,
    )


def _not_given(n: int) -> str:
    return (f"{'its' if n > 1 else 'its one'} {n} message{'s' if n > 1 else ''} give linear_acceleration_covariance[0] "
            "= -1, the REP-145 mark for linear acceleration not provided")


def _message_indices(mask: np.ndarray, shown: int = 5) -> str:
    """``message index 3, 9, ...``: the first ``shown`` messages ``mask`` selects."""
    idx = np.nonzero(mask)[0]
    return f"message index {', '.join(map(str, idx[:shown].tolist()))}{', ...' if idx.size > shown else ''}"


def _dropped(topic: str, m: TopicMessages, keep: np.ndarray) -> list[str]:
    """Report line for the messages of ``topic`` that ``keep`` leaves out for not providing linear acceleration."""
    out = ~keep & ~m.accel_given()
    n = int(np.count_nonzero(out))
    if not n:
        return []
    return [f"topic {topic}: {n} of its {len(m)} message(s) dropped for linear_acceleration_covariance[0] = -1 "
            f"(not provided; {_message_indices(out)})"]


def _not_finite(topic: str, m: TopicMessages, sel: np.ndarray) -> list[str]:
    """Report line for the messages ``sel`` selects whose linear_acceleration is nan or inf (dropped)."""
    bad = sel & ~m.accel_finite()
    n = int(np.count_nonzero(bad))
    if not n:
        return []
    return [f"topic {topic}: {n} message(s) dropped for a linear_acceleration that is not finite (nan or inf; "
            f"{_message_indices(bad)})"]


def read_bag(path: str | Path, array_path: str | Path, with_gyro: bool = False,
             max_gap_periods: float = MAX_GAP_PERIODS, gyro_as_reference: str | None = None) -> Conversion:
    """The Imu streams of a bag, aligned onto one time base, as a log of the array in ``array_path``."""
    from ..array_toml import load_array_toml

    path = Path(path)
    array_path = Path(array_path)
    array, _ = load_array_toml(array_path)
    kind, topics, records = _messages(path)
    if not records:
        listed = ", ".join(f"{t} [{m}]" for t, m in sorted(topics.items())) or "none"
        raise LogFormatError(f"no {IMU_TYPE} topic in this {kind} (topics: {listed})", path)
    imu_topics = ", ".join(sorted(records))
    found = [_accelerometer_stream(i, acc, topics, records, path, array_path) for i, acc in enumerate(array.accelerometers)]
    streams = [s for s, _ in found]
    notes = [n for _, n in found]  # per accelerometer: messages and topics left out
    for acc, s in zip(array.accelerometers, streams):
        if s.stamps_ns.size < 2:
            raise LogFormatError(f"accelerometer {acc.name!r} ({s.source}): {s.stamps_ns.size} message(s) with "
                                 "distinct stamps; at least 2 are needed", path)
    ref_topic = None if gyro_as_reference is None else _reference_topic(gyro_as_reference, records, path)
    gyro_streams = [k for k, s in enumerate(streams) if s.gyro_given.all() and ref_topic not in s.topics]
    if with_gyro and not gyro_streams:
        raise LogFormatError("--with-gyro: no Imu stream of the array provides angular_velocity (its "
                             "angular_velocity_covariance[0] is -1, the ROS mark for not provided, or a message's "
                             "angular_velocity is not finite, in every stream"
                             + (f"; the messages on {ref_topic} are the reference)" if ref_topic else ")"), path)
    values = []
    for acc, s in zip(array.accelerometers, streams):
        cols = [("xyz".index(a)) for a in acc.axes]
        v = [s.accel_mps2[:, cols]]
        if with_gyro and s.gyro_given.all() and ref_topic not in s.topics:
            v.append(s.gyro_radps @ np.asarray(acc.rotation_body_sensor).T)  # angular velocity in B
        values.append(np.hstack(v))
    try:
        al = align_streams([s.stamps_ns for s in streams], values, max_gap_periods)
    except ValueError as exc:
        raise LogFormatError(f"the Imu streams of the array cannot be aligned: {exc}", path) from None
    if al.timestamps_ns.size < 2:
        raise LogFormatError("fewer than 2 samples are left on the common time base", path)
    accel = np.hstack([v[:, :len(a.axes)] for a, v in zip(array.accelerometers, al.values)])
    lines = [f"{path}: {kind}, {len(records)} Imu topic(s) ({imu_topics}) of {len(topics)} topic(s)"]
    new_accs = []
    for acc, s, note in zip(array.accelerometers, streams, notes):
        acc, acc_lines = _described_accelerometer(acc, s, note, al.timestamps_ns[0], array_path)
        new_accs.append(acc)
        lines += acc_lines
    gyro, gyroscope, gyro_lines = _log_gyro(array, streams, gyro_streams, al, with_gyro, array_path)
    lines += gyro_lines
    out_array = replace(array, accelerometers=tuple(new_accs), gyroscope=gyroscope)
    lines += _time_base_lines(al, max_gap_periods)
    reference = invalid = None
    if ref_topic is not None:
        reference, invalid, ref_lines = _gyro_reference(ref_topic, records[ref_topic], array, al.timestamps_ns,
                                                        max_gap_periods, path)
        lines += ref_lines
    log = Log(out_array, al.timestamps_ns, accel, gyro_b_radps=gyro, reference=reference, invalid_reference=invalid,
              source=str(path))
    return Conversion(log, tuple(lines))


def _accelerometer_stream(i: int, acc, topics: dict[str, str], records: dict[str, TopicMessages], path: Path,
                          array_path: Path) -> tuple[ImuStream, list[str]]:
    """The stream of accelerometer ``i`` of the array (its ``topic``, or the messages whose header.frame_id
    is its name) and the notes on the messages left out."""
    imu_topics = ", ".join(sorted(records))
    if acc.topic is None:
        return _frame_stream(acc, records, path, array_path)
    if acc.topic not in topics:
        raise LogFormatError(f"accelerometers[{i}].topic: {acc.topic!r} (accelerometer {acc.name!r}) is not "
                             f"in {path} (its Imu topics: {imu_topics})", array_path)
    if acc.topic not in records:
        raise LogFormatError(f"accelerometers[{i}].topic: {acc.topic!r} (accelerometer {acc.name!r}) holds "
                             f"{topics[acc.topic]} in {path}, not {IMU_TYPE} (its Imu topics: {imu_topics})",
                             array_path)
    m = records[acc.topic]
    if not len(m):
        raise LogFormatError(f"topic {acc.topic!r} (accelerometer {acc.name!r}) holds no message", path)
    given = m.accel_given()
    if not given.any():
        raise LogFormatError(f"topic {acc.topic!r} (accelerometer {acc.name!r}, accelerometers[{i}].topic of "
                             f"{array_path}) is not an accelerometer: {_not_given(len(m))} (message 0 is "
                             "the first)", path)
    note = _dropped(acc.topic, m, given) + _not_finite(acc.topic, m, given)
    return _stream(f"topic {acc.topic}", [acc.topic], [(m, given & m.accel_finite())]), note


def _frame_stream(acc, records: dict[str, TopicMessages], path: Path, array_path: Path) -> tuple[ImuStream, list[str]]:
    """The stream of an accelerometer that names no topic: the messages, on any Imu topic, whose
    header.frame_id is its name; and the notes on those left out."""
    imu_topics = ", ".join(sorted(records))
    hits = [(t, records[t].frame(acc.name)) for t in sorted(records)]
    hits = [(t, sel) for t, sel in hits if sel.any()]
    if not hits:
        frames = sorted({f for m in records.values() for f in m.frame_ids})
        raise LogFormatError(
            f"no Imu message has header.frame_id {acc.name!r}, the name of accelerometer {acc.name!r} of "
            f"{array_path}, which gives no topic (frame_ids in the bag: "
            f"{', '.join(repr(f) for f in frames) or 'none'}; Imu topics: {imu_topics})", path)
    no_accel = [(t, sel) for t, sel in hits if not (sel & records[t].accel_given()).any()]
    hits = [(t, sel & records[t].accel_given()) for t, sel in hits if t not in {u for u, _ in no_accel}]
    if not hits:
        t, sel = no_accel[0]
        raise LogFormatError(
            f"the Imu messages with header.frame_id {acc.name!r} (accelerometer {acc.name!r} of {array_path}) "
            f"are no accelerometer's: on {', '.join(t for t, _ in no_accel)}, "
            f"{_not_given(int(np.count_nonzero(sel)))} (message {int(np.argmax(sel))} of {t} is the first)",
            path)
    on = [t for t, _ in hits]
    note = [f"topic {t}: its {int(np.count_nonzero(sel))} message(s) with header.frame_id {acc.name!r} leave "
            "linear_acceleration out (linear_acceleration_covariance[0] = -1): not read as an accelerometer"
            for t, sel in no_accel]
    for t, sel in hits:
        note += _dropped(t, records[t], sel | ~records[t].frame(acc.name))
        note += _not_finite(t, records[t], sel)
    stream = _stream(f"frame_id {acc.name!r} on {', '.join(on)}", on,
                     [(records[t], sel & records[t].accel_finite()) for t, sel in hits])
    return stream, note


def _since(t_ns: int, t_start: int) -> str:
    return f"{(int(t_ns) - int(t_start)) * 1e-9:.3f} s"


def _described_accelerometer(acc, s: ImuStream, note: list[str], t_start: int, array_path: Path):
    """(the accelerometer, with its noise from the messages' covariance unless the array gives it; the
    report's lines on its stream: rate, gaps, duplicates, what was left out, the noise)."""
    g = stream_gaps(s.stamps_ns)
    rate = 1e9 / g.period_ns if g.period_ns else float("nan")
    line = (f"{acc.name}: {s.source} (frame_id {', '.join(repr(f) for f in s.frame_ids)}), {s.stamps_ns.size} "
            f"message(s) at {rate:.2f} Hz; {g.start_ns.size} gap(s), {g.n_missing} message(s) missing")
    if g.start_ns.size:
        shown = ", ".join(f"{g.missing[j]} at {_since(g.start_ns[j], t_start)}" for j in range(min(5, g.start_ns.size)))
        line += f" ({shown}{', ...' if g.start_ns.size > 5 else ''})"
    line += f"; {s.duplicates} duplicate stamp(s) dropped; {s.out_of_order} out of order (sorted)"
    if s.stamps_from_bag:
        line += "; header stamps all zero: the bag's record times are used"
    lines = [line] + [f"{acc.name}: {n}" for n in note]
    var = np.nanmedian(s.accel_var_mps2, axis=0) if np.any(np.isfinite(s.accel_var_mps2)) else None
    if var is not None:
        cols = ["xyz".index(a) for a in acc.axes]
        std = float(math.sqrt(float(np.mean(var[cols]))))
        if acc.noise_std_mps2 is None:
            acc = replace(acc, noise_std_mps2=std)
            lines.append(f"{acc.name}: noise_std_mps2 {std:.6g} from linear_acceleration_covariance")
        elif not math.isclose(acc.noise_std_mps2, std, rel_tol=1e-6):
            lines.append(f"{acc.name}: noise_std_mps2 {acc.noise_std_mps2:.6g} kept from {array_path} "
                         f"(linear_acceleration_covariance says {std:.6g})")
    return acc, lines


def _log_gyro(array, streams: list[ImuStream], gyro_streams: list[int], al, with_gyro: bool, array_path: Path):
    """(the log's gyroscope readings in B, the mean of the streams that give it, or None; the array's
    gyroscope; the report's lines on it)."""
    gyroscope = array.gyroscope
    if not with_gyro:
        if array.gyroscope is None:
            return None, gyroscope, []
        return None, None, [f"gyro: the [gyroscope] of {array_path} is left out of the log (no --with-gyro)"]
    from ...array import Gyroscope

    gyro = np.mean([al.values[k][:, len(array.accelerometers[k].axes):] for k in gyro_streams], axis=0)
    gvar = [np.nanmedian(streams[k].gyro_var_radps, axis=0) for k in gyro_streams
            if np.any(np.isfinite(streams[k].gyro_var_radps))]
    gstd = (float(math.sqrt(float(np.mean(gvar)) / len(gyro_streams)))
            if len(gvar) == len(gyro_streams) else None)
    if gyroscope is None or gyroscope.noise_std_radps is None:
        gyroscope = Gyroscope(gstd)
    names = [array.accelerometers[k].name for k in gyro_streams]
    lines = [f"gyro: mean angular velocity in B of {len(names)} stream(s) ({', '.join(names)}) as w_x, w_y, w_z"
             + (f"; noise_std_radps {gstd:.6g} from angular_velocity_covariance" if gstd is not None else "")]
    left = [a.name for k, a in enumerate(array.accelerometers) if not streams[k].gyro_given.all()]
    if left:
        lines.append(f"gyro: not provided (angular_velocity_covariance[0] = -1, or not finite) by "
                     f"{', '.join(left)}; a stream is used only when all its messages provide it")
    return gyro, gyroscope, lines


def _time_base_lines(al, max_gap_periods: float) -> list[str]:
    """The report's lines on the common time base and the gaps left out of it."""
    t_start = al.timestamps_ns[0]
    a, b = al.overlap_ns
    lines = [f"time base: {1e9 / al.period_ns:.2f} Hz (median of the median periods), over the overlap of all "
             f"streams ({(b - a) * 1e-9:.3f} s): {al.timestamps_ns.size} sample(s); linear interpolation on header "
             f"stamps, a grid time at most {al.max_offset_ns * 1e-6:.3f} ms from a stamp"]
    if al.long_gaps:
        shown = ", ".join(f"{_since(g0, t_start)} to {_since(g1, t_start)} ({n} sample(s))" for g0, g1, n in al.long_gaps[:5])
        lines.append(f"gaps over {max_gap_periods:g} periods: {len(al.long_gaps)}, left out as time gaps of the log: "
                     f"{shown}{', ...' if len(al.long_gaps) > 5 else ''}")
    else:
        lines.append(f"gaps over {max_gap_periods:g} periods: none")
    return lines


def _reference_topic(topic: str, records: dict[str, TopicMessages], path: Path) -> str:
    """The Imu topic ``--gyro-as-reference`` takes: ``topic``, or when empty the one Imu topic providing
    angular velocity."""
    providing = sorted(t for t, m in records.items() if m.gyro_given().any())
    if not topic:
        if len(providing) != 1:
            raise LogFormatError(f"--gyro-as-reference: {len(providing)} Imu topics provide angular_velocity "
                                 f"({', '.join(providing) or 'none'}); name the one to take: --gyro-as-reference TOPIC",
                                 path)
        return providing[0]
    if topic not in records:
        raise LogFormatError(f"--gyro-as-reference: {topic!r} is not an Imu topic of this bag (its Imu topics: "
                             f"{', '.join(sorted(records))})", path)
    if not records[topic].gyro_given().any():
        raise LogFormatError(f"--gyro-as-reference: topic {topic!r} provides no angular_velocity: "
                             f"angular_velocity_covariance[0] is -1 (not provided) in all its {len(records[topic])} "
                             "message(s)", path)
    return topic


def _gyro_reference(topic: str, m: TopicMessages, array, grid_ns: np.ndarray, max_gap_periods: float, path: Path):
    """(reference Motion on ``grid_ns``, invalid rows, report lines): the angular velocity of ``topic`` in the body
    frame, interpolated linearly onto the log's time base; rows outside its messages' span, or inside a gap of
    more than ``max_gap_periods`` of its periods, are marked not valid."""
    from ...motion import Motion

    given = m.gyro_given()
    s = _stream(f"topic {topic}", [topic], [(m, given)])
    if s.stamps_ns.size < 2:
        raise LogFormatError(f"--gyro-as-reference: topic {topic!r} holds {s.stamps_ns.size} message(s) with "
                             "angular_velocity and distinct stamps; at least 2 are needed", path)
    accs = [a for a in array.accelerometers if a.topic == topic]
    if not accs:
        frames = {_frame_name(f) for f in s.frame_ids}
        accs = [a for a in array.accelerometers if a.topic is None and _frame_name(a.name) in frames]
    rotations = [np.asarray(a.rotation_body_sensor, dtype=float) for a in accs]
    # several accelerometers on the reference's topic (or frame) with one rotation (to the 1e-9 of a rotation
    # written out in decimal): that rotation turns the gyro, whichever of them it belongs with
    if accs and all(np.allclose(r, rotations[0], rtol=0, atol=1e-9) for r in rotations[1:]):
        rotation = rotations[0]
        frame = (f"turned into the body frame by the rotation of accelerometer {accs[0].name!r}" if len(accs) == 1
                 else f"turned into the body frame by the rotation its accelerometers "
                      f"{', '.join(repr(a.name) for a in accs)} share")
    elif not accs:
        rotation = np.eye(3)
        frame = (f"its axes (frame_id {', '.join(repr(f) for f in s.frame_ids)}) taken as the body axes: no "
                 "accelerometer of the array reads this topic or frame")
    else:
        raise LogFormatError(f"--gyro-as-reference: the messages on {topic!r} carry the frame_ids of several "
                             f"accelerometers ({', '.join(a.name for a in accs)}) with different rotations; which "
                             "rotation turns them into the body frame is ambiguous", path)
    omega = s.gyro_radps @ rotation.T
    t = s.stamps_ns
    k = np.clip(np.searchsorted(t, grid_ns, side="right") - 1, 0, t.size - 2)
    frac = (grid_ns - t[k]).astype(float) / (t[k + 1] - t[k]).astype(float)
    values = omega[k] + frac[:, None] * (omega[k + 1] - omega[k])
    period = float(np.median(np.diff(t)))
    long_gap = (t[k + 1] - t[k]) > max_gap_periods * period
    invalid = (grid_ns < t[0]) | (grid_ns > t[-1]) | (long_gap & (frac > 0) & (frac < 1))
    if invalid.all():
        raise LogFormatError(f"--gyro-as-reference: the messages on {topic!r} do not overlap the accelerometers' time "
                             f"base (theirs span {t[0]} to {t[-1]} ns, the log {grid_ns[0]} to {grid_ns[-1]} ns)", path)
    values[invalid] = np.nan
    n_left = int(np.count_nonzero(~given))
    lines = [f"reference: angular velocity of {topic} ({s.stamps_ns.size} message(s) at "
             f"{1e9 / period:.2f} Hz), {frame}, interpolated onto the time base, as reference.csv w_x, w_y, w_z; "
             "not a gyroscope of the array"]
    if n_left:
        lines.append(f"reference: {n_left} message(s) of {topic} with angular_velocity_covariance[0] = -1 (not "
                     "provided) or an angular_velocity that is not finite left out")
    if invalid.any():
        lines.append(f"reference: {int(np.count_nonzero(invalid))} sample(s) outside its messages or in their gaps "
                     f"over {max_gap_periods:g} periods marked not valid")
    return Motion(grid_ns, omega_b_radps=values), (invalid if invalid.any() else None), lines


# --- reader of `gfimu convert rosbag` -------------------------------------------------------------

def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--array", required=True, metavar="ARRAY.toml",
                        help="the array (format gfimu-array/1): each accelerometer's position and rotation in the body "
                             "frame, and optionally its Imu topic (required; no default)")
    parser.add_argument("--with-gyro", action="store_true",
                        help="also write the mean angular velocity (in the body frame) of the Imu messages that "
                             "provide it (angular_velocity_covariance[0] != -1) as the log's gyroscope channels "
                             "w_x.. [rad/s] (default: off)")
    parser.add_argument("--gyro-as-reference", nargs="?", const="", default=None, metavar="TOPIC",
                        help="also write the angular velocity [rad/s] of the Imu messages on TOPIC (without TOPIC: "
                             "the one Imu topic that provides angular velocity), turned into the body frame, as "
                             "reference.csv, the angular-velocity reference of gfimu evaluate; it is then not a "
                             "gyroscope of the array (not part of --with-gyro's mean) (default: off)")
    parser.add_argument("--max-gap-periods", type=float, default=MAX_GAP_PERIODS,
                        help="a gap in a stream up to this many of its sample periods [periods] is interpolated over; "
                             f"a longer one becomes a time gap of the log (default {MAX_GAP_PERIODS:g})")


def read(path, array: str, with_gyro: bool = False, max_gap_periods: float = MAX_GAP_PERIODS,
         gyro_as_reference: str | None = None) -> Conversion:
    """The array's accelerometers from the bag's Imu messages, aligned onto one time base."""
    if not (max_gap_periods >= GAP_FACTOR and math.isfinite(max_gap_periods)):
        raise InputError(f"--max-gap-periods: expected a number >= {GAP_FACTOR:g}, got {max_gap_periods!r}")
    return read_bag(path, array, with_gyro=with_gyro, max_gap_periods=max_gap_periods,
                    gyro_as_reference=gyro_as_reference)


READER = Reader(
    name="rosbag",
    summary="ROS 1 .bag, ROS 2 bag folder (sqlite3 or MCAP) or .mcap file: sensor_msgs/msg/Imu topics as the "
            "accelerometers of --array ARRAY.toml, interpolated onto one time base (needs the rosbag extra)",
    read=read,
    add_arguments=_add_arguments,
    input_help="the bag: a ROS 1 .bag file, a ROS 2 bag folder, or an .mcap or .db3 file",
)
