"""Live sources of readings: standard input, UDP, TCP and serial ports.

A source turns a stream of bytes into :class:`Reading` items (one sample:
timestamp, accelerometer row, gyro row or None) and :class:`BadRow` items (a
row that could not be read, with where and why); it never raises on bad
data, only when it cannot be opened (:class:`SourceError`). It ends when the
stream ends or ``stop`` is set, and says why in :attr:`Source.ended` (and,
for a broken stream, :attr:`Source.failure`). :func:`gfimu.live.run` reads
it on a thread of its own.

Text sources read imu.csv rows, by the header rules of imu.csv
(:func:`gfimu.io.tables.parse_header`: the same timestamp units, column
names and unit conversions) and the timestamp rule of imu.csv
(:func:`gfimu.io.units.timestamp_ns`: exact decimal, 64-bit nanoseconds):

- ``-``: standard input, the header line first;
- ``udp://HOST:PORT``: one data row per datagram, in the column order of
  imu.csv for the array (:func:`default_header`), or a header datagram
  (starting with ``#``) first; a datagram ``EOF`` ends the stream.

Binary sources read MIMU4444 packets (:class:`gfimu.io.mimu4444_packets.StreamDecoder`):

- ``tcp://HOST:PORT``: connecting to the board's server;
- ``serial:///dev/ttyUSB0?baud=N``: a serial port (needs pyserial).

A line longer than :data:`gfimu.io.tables.MAX_LINE_BYTES` is skipped as a bad
row without being held in memory.
"""

from __future__ import annotations

import os
import select
import socket
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from types import SimpleNamespace
from urllib.parse import parse_qs, urlparse

import numpy as np

from .tables import (MAX_LINE_BYTES, TIMESTAMP_HEADER, _missing_imu_columns, column_factor, find_column, imu_columns,
                     parse_header)
from .units import TIME_UNITS_NS, UNITS, timestamp_ns

from ..errors import InputError, MissingExtraError

POLL_S = 0.2
"""How often a waiting source looks at its ``stop`` event [s]."""

DATAGRAMS_AT_ONCE = 1024
"""At most this many waiting datagrams are read and parsed as one batch (:meth:`UdpSource.batches`)."""


class SourceError(InputError):
    """A source that cannot be opened or is not understood (the message names it)."""


@dataclass(frozen=True)
class Reading:
    """One sample: timestamp [ns], accelerometer row [m/s²] (array column order), gyro row [rad/s] or None."""

    timestamp_ns: int
    accel: np.ndarray
    gyro: np.ndarray | None = None


@dataclass(frozen=True)
class BadRow:
    """A row that could not be read: ``where`` (line or datagram number) and ``reason``."""

    where: str
    reason: str


@dataclass(frozen=True)
class SourceNote:
    """Something the source saw that the user should hear of (the stream goes on): ``message``."""

    message: str


def default_header(array) -> str:
    """The imu.csv header of ``array`` (the column order of rows that come without a header, e.g. UDP)."""
    return ",".join([TIMESTAMP_HEADER] + [f"{name} [{UNITS[kind][0]}]" for name, kind in imu_columns(array)])


class RowParser:
    """imu.csv data rows (text) to :class:`Reading` for ``array``, given the header line; columns in any
    order, units converted (``[g]``, ``[deg s^-1]``, ``[us]``…) or refused, as imu.csv. A bad header raises
    :class:`~gfimu.io.errors.LogFormatError` naming ``name`` and ``line``; a bad row raises ValueError
    (:meth:`parse`)."""

    def __init__(self, array, header: str, name: str, line: int = 1, keep_gross_errors: bool = False):
        self.keep_gross_errors = bool(keep_gross_errors)
        columns, time_unit = parse_header(header.strip().lstrip("\ufeff"), name, line)
        names = [n for n, _ in columns]
        _missing_imu_columns(SimpleNamespace(names=names, path=name), array, "the array")
        wanted = imu_columns(array)
        self.index = [find_column(names, n, name, line) for n, _ in wanted]
        self.factor = np.array([column_factor(columns, i, kind, name, line) for i, (_, kind) in zip(self.index, wanted)])
        self.scale = TIME_UNITS_NS[time_unit]
        self.accel_unit = (columns[self.index[0]][1] if self.index and array.n_axes else None) or "m s^-2"
        """The unit the first accelerometer column is read under (named by the plausibility check)."""
        self.width = len(columns)
        self.n_acc = array.n_axes
        self.gyro = array.gyroscope is not None

    def parse(self, row: str) -> Reading:
        cells = row.strip().split(",")
        if len(cells) != self.width:
            raise ValueError(f"{len(cells)} fields, the header has {self.width}")
        t = timestamp_ns(cells[0], self.scale)
        values = []
        for i in self.index:
            tok = cells[i].strip()
            try:
                values.append(float(tok))
            except ValueError:
                raise ValueError(f"field {i + 1} {tok!r} is not a number") from None
        v = np.array(values) * self.factor
        if self.keep_gross_errors:
            return Reading(t, v[:self.n_acc], v[self.n_acc:self.n_acc + 3] if self.gyro else None)
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            i = self.index[int(bad[0])]
            raise ValueError(f"field {i + 1} {cells[i].strip()!r} is not finite")
        from ..readings import GYRO_OUT_OF_RANGE_RADPS, OUT_OF_ANY_RANGE_MPS2

        limit = np.full(v.size, GYRO_OUT_OF_RANGE_RADPS)
        limit[:self.n_acc] = OUT_OF_ANY_RANGE_MPS2
        huge = np.flatnonzero(np.abs(v) > limit)
        if huge.size:  # no sensor reads it (1e308 overflows the smoother)
            k = int(huge[0])
            what = "accelerometer" if k < self.n_acc else "gyroscope"
            raise ValueError(f"field {self.index[k] + 1} {cells[self.index[k]].strip()!r} is beyond any {what}'s range "
                             f"(±{limit[k]:g} {'m/s²' if k < self.n_acc else 'rad/s'})")
        return Reading(t, v[:self.n_acc], v[self.n_acc:self.n_acc + 3] if self.gyro else None)

    def parse_many(self, rows: list[tuple[str, str]]) -> list[Reading | BadRow]:
        """:meth:`parse` of each ``(where, text)`` row, as a :class:`Reading` or a :class:`BadRow` naming ``where``:
        the same readings (the same numbers, bit for bit) and the same reasons, the numbers of all the rows
        converted and checked at once. A row that does not read cleanly is handed to :meth:`parse` for its
        reason."""
        out: list[Reading | BadRow | None] = [None] * len(rows)
        good: list[int] = []
        times: list[int] = []
        values: list[float] = []
        index, width, scale = self.index, self.width, self.scale
        for k, (where, text) in enumerate(rows):
            cells = text.strip().split(",")
            try:
                if len(cells) != width:
                    raise ValueError
                tok = cells[0].strip()
                # up to 18 digits of integer nanoseconds read as they are (exact and within 64 bits, as
                # timestamp_ns reads them); any other token by its rule
                t = (int(tok) if scale == 1 and len(tok) <= 18 and tok.isdigit() and tok.isascii()
                     else timestamp_ns(tok, scale))
                row = [float(cells[i]) for i in index]
            except (ValueError, OverflowError):
                out[k] = _parsed(self, text, where)
                continue
            good.append(k)
            times.append(t)
            values.extend(row)
        if good:
            v = np.array(values, dtype=float).reshape(len(good), len(index)) * self.factor
            fault = np.zeros(len(good), bool)
            if not self.keep_gross_errors:
                from ..readings import GYRO_OUT_OF_RANGE_RADPS, OUT_OF_ANY_RANGE_MPS2

                limit = np.full(len(index), GYRO_OUT_OF_RANGE_RADPS)
                limit[:self.n_acc] = OUT_OF_ANY_RANGE_MPS2
                with np.errstate(invalid="ignore"):
                    fault = ~np.isfinite(v).all(axis=1) | (np.abs(v) > limit).any(axis=1)
            n_acc, gyro = self.n_acc, self.gyro
            for j, k in enumerate(good):
                if fault[j]:
                    out[k] = _parsed(self, rows[k][1], rows[k][0])
                else:
                    out[k] = Reading(times[j], v[j, :n_acc], v[j, n_acc:n_acc + 3] if gyro else None)
        return out


class Source:
    """A stream of readings; :meth:`batches` yields lists of :class:`Reading`, :class:`BadRow` and
    :class:`SourceNote` until the stream ends or ``stop`` is set. After it: :attr:`ended` says why, :attr:`failure` is a message when the
    stream broke (a connection reset) and None otherwise."""

    name = "source"

    def __init__(self, array):
        self.array = array
        self.ended = "not started"
        self.failure: str | None = None
        self.accel_unit: str | None = None
        """The unit of the accelerometer columns, once known (a text source's header)."""
        self.keep_gross_errors = False
        """True: a text row whose readings are not finite or beyond any sensor's range is passed on, for the
        screening downstream to replace (:class:`gfimu.readings.StreamScreen`); False: it is a bad row."""

    def batches(self, stop: threading.Event) -> Iterator[list[Reading | BadRow | SourceNote]]:
        """The stream's items in lists, each what came in one read (a chunk of text, the datagrams waiting, the
        packets of a chunk), in order: read and parsed at once, so that a fast stream costs a Python call per read
        rather than per sample."""
        raise NotImplementedError

    def close(self) -> None:
        """Release the socket or port (also when :meth:`batches` was never run)."""


class _TextRows:
    """Rows of text from chunks of bytes: lines no longer than :data:`MAX_LINE_BYTES` (a longer one is
    reported once and skipped, nothing of it held beyond that)."""

    def __init__(self):
        self.buffer = b""
        self.discarding = False
        self.line = 0

    def feed(self, chunk: bytes) -> Iterator[tuple[int, bytes | None]]:
        """(line number, line bytes without its end) — or (line number, None) for a line too long."""
        data = self.buffer + chunk if self.buffer else chunk
        start = 0
        while True:
            end = data.find(b"\n", start)
            if end < 0:
                break
            self.line += 1
            if self.discarding:
                self.discarding = False
            elif end - start > MAX_LINE_BYTES:
                yield self.line, None
            else:
                yield self.line, data[start:end]
            start = end + 1
        rest = data[start:]
        if len(rest) > MAX_LINE_BYTES and not self.discarding:
            self.discarding = True
            yield self.line + 1, None
        self.buffer = b"" if self.discarding else rest

    def tail(self) -> Iterator[tuple[int, bytes | None]]:
        """The last line when the stream ends without a line end."""
        if self.buffer and not self.discarding:
            self.line += 1
            yield self.line, self.buffer
        self.buffer = b""


def _decode(raw: bytes) -> str:
    return raw.decode("utf-8", "replace").rstrip("\r")


TOO_LONG = f"line longer than {MAX_LINE_BYTES} bytes (a binary stream?); skipped to its end"


class StdinSource(Source):
    """imu.csv text on a file descriptor (standard input by default): the header line first, then one
    sample per line; empty lines are skipped. Reads with a timeout, so that ``stop`` ends it even on an
    open pipe that sends nothing."""

    def __init__(self, array, fd: int = 0, name: str = "standard input"):
        super().__init__(array)
        self.fd = fd
        self.name = name

    def _chunks(self, stop: threading.Event) -> Iterator[bytes]:
        while not stop.is_set():
            try:
                ready, _, _ = select.select([self.fd], [], [], POLL_S)
            except (OSError, ValueError):  # not selectable (a file on some systems): read on
                ready = [self.fd]
            if not ready:
                continue
            chunk = os.read(self.fd, 1 << 16)
            if not chunk:
                self.ended = "end of input"
                return
            yield chunk
        self.ended = "stopped"

    def batches(self, stop: threading.Event) -> Iterator[list[Reading | BadRow | SourceNote]]:
        rows = _TextRows()
        parser = None

        def chunks():
            for chunk in self._chunks(stop):
                yield list(rows.feed(chunk))
            if self.ended == "end of input":
                yield list(rows.tail())

        for lines in chunks():
            batch = _Batch(parser)
            for line, raw in lines:
                where = f"line {line}"
                if raw is None:
                    batch.add(BadRow(where, TOO_LONG))
                    continue
                text = _decode(raw)
                if not text.strip():
                    continue
                if parser is None:
                    parser = batch.parser = RowParser(self.array, text, self.name, line, self.keep_gross_errors)
                    self.accel_unit = parser.accel_unit
                    continue
                batch.row(where, text)
            items = batch.done()
            if items:
                yield items


class _Batch:
    """The items of one read, in order: its data rows gathered and parsed together (:meth:`RowParser.parse_many`)
    in their place among the other items."""

    def __init__(self, parser: RowParser | None):
        self.parser = parser
        self.items: list = []
        self.rows: list[tuple[str, str]] = []  # (where, text) of the data rows not parsed yet

    def row(self, where: str, text: str) -> None:
        self.rows.append((where, text))

    def add(self, item) -> None:
        """An item that is not a data row (a bad row), after the rows before it."""
        self._parse()
        self.items.append(item)

    def _parse(self) -> None:
        if self.rows:
            self.items += self.parser.parse_many(self.rows)
            self.rows = []

    def done(self) -> list:
        self._parse()
        return self.items


def _parsed(parser: RowParser, text: str, where: str) -> Reading | BadRow:
    try:
        return parser.parse(text)
    except (ValueError, OverflowError) as exc:
        return BadRow(where, str(exc))


class UdpSource(Source):
    """One imu.csv data row per datagram (columns in :func:`default_header`'s order, unless a header
    datagram starting with ``#`` comes first); a datagram ``EOF`` ends the stream."""

    def __init__(self, array, host: str, port: int, name: str):
        super().__init__(array)
        self.name = name
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:  # room for a few seconds of datagrams while the process is descheduled (the kernel may cap it)
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        except OSError:
            pass
        try:
            self.sock.bind((host, port))
        except OSError as exc:
            self.sock.close()
            raise SourceError(f"--source {name}: cannot bind: {exc.strerror or exc}") from None
        self.sock.settimeout(POLL_S)

    def _waiting(self) -> list[bytes]:
        """The datagrams waiting on the socket, up to :data:`DATAGRAMS_AT_ONCE`, without blocking."""
        out = []
        self.sock.setblocking(False)
        try:
            while len(out) < DATAGRAMS_AT_ONCE:
                out.append(self.sock.recv(65536))
        except OSError:  # none waiting (or a failure, which the next blocking read meets and reports)
            pass
        finally:
            self.sock.settimeout(POLL_S)
        return out

    def batches(self, stop: threading.Event) -> Iterator[list[Reading | BadRow | SourceNote]]:
        parser = None
        count = 0
        while not stop.is_set():
            try:
                data, _ = self.sock.recvfrom(65536)
                datagrams = [data] + self._waiting()
            except socket.timeout:
                continue
            except OSError as exc:
                self.ended, self.failure = "receive failed", f"{self.name}: {exc.strerror or exc}"
                return
            batch = _Batch(parser)
            for data in datagrams:
                count += 1
                text = _decode(data).strip()
                if text == "EOF":  # an explicit end of stream
                    items = batch.done()
                    if items:
                        yield items
                    self.ended = "EOF datagram"
                    return
                where = f"datagram {count}"
                if parser is None:
                    if text.startswith("#"):  # a header that cannot be read ends the session (exit 2)
                        parser = batch.parser = RowParser(self.array, text, f"{self.name} {where}",
                                                          keep_gross_errors=self.keep_gross_errors)
                        self.accel_unit = parser.accel_unit
                        continue
                    parser = batch.parser = RowParser(self.array, default_header(self.array), self.name,
                                                      keep_gross_errors=self.keep_gross_errors)
                if not text:
                    batch.add(BadRow(where, "empty datagram"))
                    continue
                batch.row(where, text)
            items = batch.done()
            if items:
                yield items
        self.ended = "stopped"

    def close(self) -> None:
        self.sock.close()


class MimuSource(Source):
    """MIMU4444 packets from TCP (``tcp://HOST:PORT``) or a serial port (``serial://DEVICE?baud=N``)."""

    def __init__(self, array, url, name: str):
        super().__init__(array)
        self.name = name
        if url.scheme == "tcp":
            if not url.hostname or not url.port:
                raise SourceError(f"--source {name}: expected tcp://HOST:PORT")
            try:
                self.conn = socket.create_connection((url.hostname, url.port), timeout=10)
            except OSError as exc:
                raise SourceError(f"--source {name}: cannot connect: {exc.strerror or exc}") from None
            self.conn.settimeout(POLL_S)
            self.port = None
        else:
            try:
                baud = int(parse_qs(url.query).get("baud", ["115200"])[0])
            except ValueError:
                raise SourceError(f"--source {name}: baud must be an integer") from None
            if not 0 < baud <= 100_000_000:
                raise SourceError(f"--source {name}: baud={baud} is no baud rate (a positive number of bits per "
                                  "second, e.g. baud=115200)")
            try:
                import serial
            except ImportError:
                raise MissingExtraError(f"--source {name}: a serial port", "pyserial", "serial") from None
            try:
                self.port = serial.Serial(url.path, baudrate=baud, timeout=POLL_S)
            except (OSError, serial.SerialException) as exc:
                raise SourceError(f"--source {name}: cannot open: {exc}") from None
            self.conn = None

    def _read(self) -> bytes | None:
        """Bytes (b"" when none came in time), None at the end of the stream."""
        if self.conn is None:
            return self.port.read(4096)
        try:
            return self.conn.recv(65536) or None
        except socket.timeout:
            return b""

    def batches(self, stop: threading.Event) -> Iterator[list[Reading | BadRow | SourceNote]]:
        from .mimu4444_packets import StreamDecoder

        decoder = StreamDecoder()
        skipped = received = 0
        while not stop.is_set():
            try:
                chunk = self._read()
            except OSError as exc:  # ConnectionResetError, a serial port unplugged
                self.ended = "connection lost"
                self.failure = f"{self.name}: {_os_words(exc)}"
                return
            if chunk is None:
                self.ended = "end of stream (closed by the other side)"
                return
            batch: list = [Reading(t_ns, accel, None) for t_ns, accel in decoder.feed(chunk)]
            disorder = decoder.disorder()
            if disorder is not None:
                batch.append(SourceNote(f"{self.name}: {disorder}"))
            received += len(chunk)
            if decoder.skipped_bytes > skipped:  # bytes that are no packet: a bad row per stretch of them
                batch.append(BadRow(f"byte {received}", f"{decoder.skipped_bytes - skipped} byte(s) that are no "
                                                        "MIMU4444 packet"))
                skipped = decoder.skipped_bytes
            if batch:
                yield batch
        self.ended = "stopped"

    def close(self) -> None:
        (self.conn if self.conn is not None else self.port).close()


def _os_words(exc: OSError) -> str:
    if isinstance(exc, ConnectionResetError):
        return "connection reset by the other side"
    return exc.strerror or str(exc) or type(exc).__name__


SCHEMES = ("-", "udp", "tcp", "serial")


def open_source(spec: str, array) -> Source:
    """The source named by ``spec`` (``-``, ``udp://HOST:PORT``, ``tcp://HOST:PORT``,
    ``serial://DEVICE?baud=N``) for ``array``; :class:`SourceError` when it is not understood or cannot be
    opened."""
    if spec == "-":
        return StdinSource(array)
    url = urlparse(spec)
    if url.scheme not in SCHEMES:
        raise SourceError(f"--source {spec}: expected -, udp://HOST:PORT, tcp://HOST:PORT or serial://DEVICE")
    if url.scheme == "udp":
        try:
            port = url.port
        except ValueError:
            raise SourceError(f"--source {spec}: the port is not a number from 0 to 65535") from None
        if not port:
            raise SourceError(f"--source {spec}: give the port to listen on, udp://HOST:PORT (e.g. udp://0.0.0.0:5005)")
        return UdpSource(array, url.hostname or "0.0.0.0", port, spec)
    try:
        url.port
    except ValueError:
        raise SourceError(f"--source {spec}: the port is not a number from 0 to 65535") from None
    return MimuSource(array, url, spec)
