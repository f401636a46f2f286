"""``gfimu live --array ARRAY.toml --source SRC --out DEST``: estimates from a live stream of readings.

Sources: ``-`` (imu.csv rows on standard input, the header line first),
``udp://HOST:PORT`` (one imu.csv data row per datagram, columns in the order
imu.csv has for the array), ``tcp://HOST:PORT`` and ``serial:///dev/ttyUSB0?baud=N``
(MIMU4444 binary packets, decoded by the ``convert mimu4444`` reader). Each estimate
row (``gfimu estimate`` columns for ω, ω̇, f) is written and flushed as its sample
leaves the lag window. EOF, SIGINT and SIGTERM end the run cleanly: the window is
flushed, everything estimated is written and a summary goes to standard error.
"""

from __future__ import annotations

import argparse
import queue
import signal
import socket
import sys
import threading
import time
from pathlib import Path
from urllib.parse import parse_qs, urlparse

from . import CLIError
from .options import positive


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "live", help="estimate ω live from readings on standard input, UDP, TCP or a serial port (fixed-lag smoother)",
        description="Run the fixed-lag smoother on a live stream and write estimate rows as each sample leaves the "
                    "lag window (same columns as gfimu estimate). Late or repeated samples are dropped and counted; "
                    "time going back by more than 1 s restarts the window (a clock reset); a bad row is reported "
                    "and skipped; if the input outruns the smoother the oldest queued samples are dropped.")
    p.add_argument("--array", required=True, metavar="ARRAY.toml", help="the array (as in a log folder)")
    p.add_argument("--source", required=True, metavar="SRC",
                   help="'-' (imu.csv rows on standard input, header first), udp://HOST:PORT (one data row per "
                        "datagram), tcp://HOST:PORT or serial:///dev/ttyUSB0?baud=N (MIMU4444 packets)")
    p.add_argument("--out", required=True, metavar="DEST", help="estimate CSV to write, or - for standard output")
    p.add_argument("--lag-s", type=positive("s"), default=0.2, help="lag of the smoother [s] (default 0.2)")
    p.add_argument("--rate-hz", type=positive("Hz"), default=None,
                   help="nominal sample rate [Hz] (default: rate_hz of array.toml; needed when it has none)")
    p.add_argument("--option", "-O", action="append", default=[], metavar="KEY=VALUE",
                   help="fixed-lag option (gfimu estimate --method fixed-lag --list-options)")
    p.add_argument("--queue", type=int, default=5000, metavar="N",
                   help="samples held while the smoother is busy before the oldest are dropped (default 5000)")
    p.add_argument("--status-s", type=positive("s"), default=5.0, help="status line every this many s (default 5)")
    p.add_argument("--quiet", "-q", action="store_true", default=argparse.SUPPRESS,
                   help="no status lines; the summary at the end stays (default: off)")
    p.set_defaults(func=run)


STEADY_AFTER_S = 10.0
"""Latency is also summarised for samples arriving this long after the first [s]: past the start,
where the first seconds are held while the process noise is chosen on them."""


def _text_rows(source: str, stop: threading.Event):
    """(text row, where) from standard input or UDP datagrams."""
    if source == "-":
        for lineno, line in enumerate(sys.stdin, start=1):
            if stop.is_set():
                return
            if line.strip():
                yield line, f"line {lineno}"
        return
    url = urlparse(source)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:  # room for a few seconds of datagrams while the process is descheduled (the kernel may cap it)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    except OSError:
        pass
    try:
        sock.bind((url.hostname or "0.0.0.0", url.port or 0))
    except OSError as exc:
        raise CLIError(f"--source {source}: cannot bind: {exc.strerror or exc}") from None
    sock.settimeout(0.2)
    count = 0
    try:
        while not stop.is_set():
            try:
                data, _ = sock.recvfrom(65536)
            except socket.timeout:
                continue
            count += 1
            text = data.decode("utf-8", "replace")
            if text.strip() == "EOF":  # an explicit end of stream
                return
            yield text, f"datagram {count}"
    finally:
        sock.close()


def _mimu_rows(source: str, array, stop: threading.Event):
    """(timestamp_ns, accel_row, None) from MIMU4444 packets over TCP or a serial port."""
    from ..io.readers.mimu4444 import StreamDecoder

    url = urlparse(source)
    if url.scheme == "tcp":
        try:
            conn = socket.create_connection((url.hostname, url.port), timeout=10)
        except OSError as exc:
            raise CLIError(f"--source {source}: cannot connect: {exc.strerror or exc}") from None
        conn.settimeout(0.2)

        def read():
            try:
                return conn.recv(65536) or None
            except socket.timeout:
                return b""
        close = conn.close
    else:
        try:
            import serial
        except ImportError:
            raise CLIError("serial sources need pyserial: pip install 'gfimu[serial]'") from None
        baud = int(parse_qs(url.query).get("baud", ["115200"])[0])
        try:
            port = serial.Serial(url.path, baudrate=baud, timeout=0.2)
        except (OSError, serial.SerialException) as exc:
            raise CLIError(f"--source {source}: cannot open: {exc}") from None

        def read():
            return port.read(4096)
        close = port.close
    decoder = StreamDecoder()
    try:
        while not stop.is_set():
            chunk = read()
            if chunk is None:
                return
            for t_ns, accel in decoder.feed(chunk):
                yield t_ns, accel, None
    finally:
        close()


def run(args) -> int:
    from .. import io as gio
    from ..methods import make_estimator
    from ..io.outputs import check_output
    from ..live import ESTIMATE_HEADER, LiveInputError, LiveSession, default_header, imu_row_parser
    from .options import check_method_options, parse_options

    array, rate_hz = gio.load_array_toml(args.array)
    rate_hz = args.rate_hz or rate_hz
    if rate_hz is None:
        raise CLIError(f"{args.array} states no rate_hz: give --rate-hz")
    scheme = "-" if args.source == "-" else urlparse(args.source).scheme
    if scheme not in ("-", "udp", "tcp", "serial"):
        raise CLIError(f"--source {args.source}: expected -, udp://HOST:PORT, tcp://HOST:PORT or serial://DEVICE")
    out_path = check_output(args.out, [args.array], "--out", stdout=True)
    options = parse_options(args.option)
    options["lag_s"] = args.lag_s
    check_method_options("fixed-lag", options)
    estimator = make_estimator("fixed-lag", **options)
    reason = estimator.applicable(array)
    if reason:
        raise CLIError(f"{args.array}: {reason}")
    session = LiveSession(array, estimator, rate_hz)
    stop = threading.Event()

    def on_signal(signum, frame):
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    out = sys.stdout if out_path is None else open(Path(out_path), "w", encoding="utf-8", newline="")
    q: queue.Queue = queue.Queue(maxsize=max(int(args.queue), 1))
    errors: list[BaseException] = []

    def report(message: str) -> None:
        print(f"gfimu live: {message}", file=sys.stderr, flush=True)

    def reader():
        try:
            if scheme in ("-", "udp"):
                parse = None
                for text, where in _text_rows(args.source, stop):
                    if parse is None:
                        header = text if (scheme == "-" or text.lstrip().startswith("#")) else default_header(array)
                        parse = imu_row_parser(array, header)
                        if header is text:
                            continue
                    try:
                        item = parse(text)
                    except LiveInputError as exc:
                        session.stats.bad_rows += 1
                        report(f"warning: {where} skipped: {exc}")
                        continue
                    _put(item)
            else:
                for item in _mimu_rows(args.source, array, stop):
                    _put(item)
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread
            errors.append(exc)
        finally:
            q.put(None)

    def _put(item):
        item = (item, time.perf_counter())  # with its arrival time, for the latency
        while True:
            try:
                q.put_nowait(item)
                return
            except queue.Full:  # the smoother falls behind: drop the oldest waiting sample
                try:
                    q.get_nowait()
                    session.stats.overrun_dropped += 1
                except queue.Empty:
                    pass

    arrival: dict[int, float] = {}
    latency: list[float] = []
    try:
        out.write(ESTIMATE_HEADER + "\n")
        out.flush()
        thread = threading.Thread(target=reader, daemon=True)
        thread.start()
        last_status = time.monotonic()
        while True:
            try:
                item = q.get(timeout=0.2)
            except queue.Empty:
                if stop.is_set() and not thread.is_alive():
                    break
                item = False
            if item is None:
                break
            if item is not False:
                sample, arrived = item
                arrival[int(sample[0])] = arrived
                rows = session.push(*sample)
                if rows:
                    out.writelines(rows)
                    out.flush()
                    now = time.perf_counter()
                    for row in rows:  # arrival of a sample -> its estimate written
                        t = arrival.pop(int(row.split(",", 1)[0]), None)
                        if t is not None:
                            latency.append((t, now - t))
                    if len(arrival) > 100_000:  # samples that never left (dropped): forget the oldest
                        for key in list(arrival)[:50_000]:
                            del arrival[key]
                    if len(latency) > 200_000:
                        del latency[:100_000]
            if not getattr(args, "quiet", False) and time.monotonic() - last_status >= args.status_s:
                last_status = time.monotonic()
                p50, p99, _ = session.stats.percentiles_ms()
                report(f"{session.stats.samples_in} in, {session.stats.samples_out} out, lag {args.lag_s:g} s, "
                       f"processing p50 {p50:.2f} ms p99 {p99:.2f} ms, {session.stats.overrun_dropped} dropped, "
                       f"{session.stats.late_or_repeated} late, {session.stats.bad_rows} bad")
        out.writelines(session.flush())
        out.flush()
    finally:
        if out is not sys.stdout:
            out.close()
        for s, h in old.items():
            signal.signal(s, h)
    if errors and not isinstance(errors[0], (KeyboardInterrupt, SystemExit)):
        exc = errors[0]
        if isinstance(exc, CLIError):
            raise exc
        if isinstance(exc, LiveInputError):
            raise CLIError(f"--source {args.source}: {exc}")
        raise exc
    summary = session.stats.summary()
    if latency:
        import numpy as np

        pairs = np.asarray(latency)
        lat = pairs[:, 1] * 1e3
        summary += (f"; latency arrival -> estimate written (lag {args.lag_s:g} s + processing) p50 "
                    f"{np.percentile(lat, 50):.1f} ms, p99 {np.percentile(lat, 99):.1f} ms, max {lat.max():.1f} ms")
        # after the start, where the first seconds wait for the one-time choice of the process noise
        steady = lat[pairs[:, 0] > pairs[0, 0] + STEADY_AFTER_S]
        if steady.size:
            summary += (f"; after the first {STEADY_AFTER_S:g} s: p50 {np.percentile(steady, 50):.1f} ms, "
                        f"p99 {np.percentile(steady, 99):.1f} ms, max {steady.max():.1f} ms")
    report(summary)
    return 0
