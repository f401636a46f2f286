"""Many logs, one method, on Dask distributed (the library side of ``gfimu batch``).

:func:`run_one` is the task a worker runs for one log: :func:`gfimu.pipeline.estimate_log`,
then the estimate written atomically to its own folder, returning one summary row
(never raising: a broken log is a row with status ``failed`` and its message).
:func:`run_batch` sends the logs to a Dask scheduler (an existing one, or a
``LocalCluster`` started here) and gathers the rows as they finish. Workers need
the logs and the output folder on a shared file system.
"""

from __future__ import annotations

import os
import time
import traceback
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from .errors import GfimuError, MissingExtraError

SUMMARY_COLUMNS = ("log", "output", "status", "samples", "seconds", "omega_rmse_radps", "warnings", "message")


@dataclass(frozen=True)
class BatchResult:
    """Outcome of :func:`run_batch`: one row per log, in the order given."""

    rows: tuple[dict, ...]
    scheduler: str

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.rows if r["status"] != "ok"]

    def summary_csv(self) -> str:
        """The rows as CSV (``summary.csv``)."""
        import csv
        import io

        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
        writer.writeheader()
        for r in self.rows:
            writer.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in SUMMARY_COLUMNS})
        return buf.getvalue()


RESERVED_NAMES = ("summary.csv",)
"""Names in the output folder a log's folder cannot take (the summary is written there)."""

NAME_JOIN = "__"
"""Joins the parts of a log's path into its output folder's name when its folder name alone is not unique."""


def _path_parts(log: str | Path) -> tuple[str, ...]:
    try:
        p = Path(log).resolve()
    except (OSError, RuntimeError):  # a loop of symbolic links: its own row says so (run_one)
        p = Path(os.path.abspath(log))
    return tuple(part for part in p.parts if part not in ("/", "")) or ("log",)


def output_folders(logs: Iterable[str | Path], out_dir: str | Path) -> list[Path]:
    """``out_dir/<name>`` per log, every name different and none of :data:`RESERVED_NAMES`.

    A log's name is its folder's name; logs whose folder names are the same (``a/log``, ``b/log``) take
    as many parts of their whole (resolved) path as make them differ, joined by :data:`NAME_JOIN`
    (``a__log``, ``b__log``), so that a name never depends on the order of the logs and never takes
    another log's name. The same log given twice, or names that the whole paths cannot tell apart, are
    refused (:class:`~gfimu.io.errors.OutputError`) before any work: two results never go to one folder.
    """
    from .io.errors import OutputError

    logs = list(logs)
    parts = [_path_parts(log) for log in logs]
    first: dict[tuple[str, ...], int] = {}
    for i, p in enumerate(parts):
        if p in first:
            raise OutputError(f"LOG {logs[i]}: the same log as {logs[first[p]]} (given twice); its estimate would "
                              f"be written twice to one folder of --out {out_dir}")
        first[p] = i
    depth = [1] * len(logs)

    def name(i: int) -> str:
        return NAME_JOIN.join(parts[i][-depth[i]:])

    while True:
        groups: dict[str, list[int]] = {}
        for i in range(len(logs)):
            groups.setdefault(name(i), []).append(i)
        clash = [(n, g) for n, g in groups.items() if len(g) > 1 or n in RESERVED_NAMES or n.startswith(".")]
        if not clash:
            break
        grown = False
        for n, g in clash:
            for i in g:
                if depth[i] < len(parts[i]):
                    depth[i] += 1
                    grown = True
        if not grown:
            n, g = clash[0]
            shown = " and ".join(str(logs[i]) for i in g)
            raise OutputError(f"--out {out_dir}: {shown} would be written to one folder {n!r} (or a name the output "
                              "folder keeps); give the logs folders of different names")
    return [Path(out_dir) / name(i) for i in range(len(logs))]


def run_one(log_dir: str, output_csv: str, method: str, options: dict, calibration: str | None) -> dict:
    """Estimate one log and write its estimate; the summary row (status ok or failed)."""
    from . import io as gio
    from .io.outputs import check_output_within, write_output
    from .pipeline import estimate_log, score

    row = {"log": str(log_dir), "output": str(output_csv), "status": "failed", "samples": None, "seconds": None,
           "omega_rmse_radps": None, "warnings": "", "message": ""}
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            inputs = [log_dir] + ([calibration] if calibration else [])
            target = Path(output_csv)
            check_output_within(target.parent.parent, Path(target.parent.name) / target.name, inputs, "--out")
            target.parent.mkdir(parents=True, exist_ok=True)
            out = check_output_within(target.parent.parent, Path(target.parent.name) / target.name, inputs, "--out")
            run = estimate_log(log_dir, method, _one_process(method, options), calibration)
            write_output(out, gio.motion_csv_chunks(run.motion))
        rmse = score(run)
        row.update(status="ok", samples=run.samples, omega_rmse_radps=None if rmse is None else f"{rmse:.6g}",
                   warnings=" | ".join([str(w.message) for w in caught] + list(run.report.warnings)))
    except Exception as exc:  # noqa: BLE001 - a broken log is reported, the others go on
        message = str(exc) or type(exc).__name__
        if not isinstance(exc, (GfimuError, OSError)):  # not raised on purpose: a bug, named as one
            message = (f"internal error: {type(exc).__name__}: {message} "
                       f"({traceback.format_exc(limit=1).splitlines()[-1]})")
        row.update(output="", message=" ".join(message.split()))  # no estimate of this run to point at
        folder = Path(output_csv).parent
        if not folder.is_symlink() and folder.is_dir() and not any(folder.iterdir()):  # leave no empty folder behind a failed log
            folder.rmdir()
    row["seconds"] = f"{time.perf_counter() - t0:.3f}"
    return row


def _one_process(method: str, options: dict) -> dict:
    """``options`` with the estimator's own worker processes off unless set: the logs already run in
    parallel, one per Dask worker."""
    import dataclasses

    from .methods import estimator_class

    cls = estimator_class(method)
    if "workers" not in options and dataclasses.is_dataclass(cls) and any(f.name == "workers" for f in dataclasses.fields(cls)):
        return {**options, "workers": 1}
    return options


def local_cluster(workers: int):
    """A Dask ``LocalCluster`` of ``workers`` single-threaded worker processes (one BLAS thread each).

    Dask's nannies set ``MALLOC_TRIM_THRESHOLD_=65536`` in their workers, which hands every freed block
    back to the system: the smoother's many small arrays then cost more in system calls than in arithmetic
    (a 2000-sample log: 6.4 s instead of 2.1 s). These workers keep glibc's own, adaptive threshold.
    """
    try:
        import dask
        from dask.distributed import LocalCluster
    except ImportError:
        raise MissingExtraError("a local Dask cluster", "dask.distributed", "distributed") from None

    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}) or {})
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    with dask.config.set({"distributed.nanny.pre-spawn-environ": environ}):
        return LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True, dashboard_address=None)


SCHEDULER_TIMEOUT_S = 20.0
"""Seconds to connect to a scheduler, and for it to say its first words once connected."""

_MAX_FIRST_FRAME = 1 << 26
"""A Dask peer starts with the length of its first message, a few hundred bytes; anything beyond this is not Dask."""


def check_scheduler(address: str, timeout_s: float = SCHEDULER_TIMEOUT_S) -> None:
    """Check that ``address`` (``tcp://HOST:PORT`` or ``HOST:PORT``) is a Dask scheduler before handing it to
    Dask: the connection within ``timeout_s``, then the scheduler's first bytes (a Dask peer speaks first: the
    length of its first message) within ``timeout_s`` too. A peer that accepts and never answers, or answers
    with something else (an SSH server's banner), is refused with :class:`~gfimu.errors.ResourceError` naming
    the address, instead of a wait without end or a huge allocation. Other schemes (``tls://``, ``inproc://``)
    are left to Dask."""
    import socket
    import struct
    from urllib.parse import urlparse

    from .errors import InputError, ResourceError

    text = address if "://" in address else f"tcp://{address}"
    url = urlparse(text)
    if url.scheme != "tcp":
        return
    try:
        host, port = url.hostname, url.port
    except ValueError:
        raise InputError(f"--scheduler {address}: the port is not a number from 0 to 65535") from None
    if not host or not port:
        raise InputError(f"--scheduler {address}: expected tcp://HOST:PORT")
    try:
        conn = socket.create_connection((host, port), timeout=timeout_s)
    except TimeoutError:
        raise ResourceError(f"--scheduler {address}: no connection within {timeout_s:g} s") from None
    except OSError as exc:
        raise ResourceError(f"--scheduler {address}: cannot connect: {exc.strerror or exc}") from None
    with conn:
        conn.settimeout(timeout_s)
        head = b""
        try:
            while len(head) < 8:
                chunk = conn.recv(8 - len(head))
                if not chunk:
                    raise ResourceError(f"--scheduler {address}: the peer closed the connection without a word; "
                                        "not a Dask scheduler")
                head += chunk
        except TimeoutError:
            raise ResourceError(f"--scheduler {address}: accepts connections but says nothing within {timeout_s:g} s "
                                "(a Dask scheduler speaks first); not a Dask scheduler, or a stuck one") from None
        except OSError as exc:
            raise ResourceError(f"--scheduler {address}: {exc.strerror or exc}") from None
    (length,) = struct.unpack("<Q", head)
    if length > _MAX_FIRST_FRAME:
        shown = head.decode("ascii", "replace") if head[:4].isascii() else head.hex()
        raise ResourceError(f"--scheduler {address}: answers {shown!r}..., not a Dask scheduler (an SSH or other "
                            "server on that port?)")


def run_batch(logs: list[str | Path], out_dir: str | Path, method: str = "smoother", options: dict | None = None,
              calibration: str | Path | None = None, scheduler: str | None = None, workers: int = 2,
              on_done: Callable[[dict], None] | None = None) -> BatchResult:
    """Run ``method`` on every log on Dask: on the scheduler at ``scheduler`` (``tcp://host:port``), or
    on a ``LocalCluster`` of ``workers`` single-threaded processes started here and closed after.
    ``on_done(row)`` is called as each log finishes (progress)."""
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise MissingExtraError("run_batch", "dask.distributed", "distributed") from None

    folders = output_folders(logs, out_dir)
    cluster = None
    if scheduler is None:
        cluster = local_cluster(workers)
        client = Client(cluster)
    else:
        check_scheduler(str(scheduler))
        client = Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S:g}s")
    try:
        futures, index = [], {}
        for i, (log, folder) in enumerate(zip(logs, folders)):
            fut = client.submit(run_one, str(log), str(folder / "estimate.csv"), method, dict(options or {}),
                                None if calibration is None else str(calibration), pure=False)
            futures.append(fut)
            index[fut.key] = i
        rows: list[dict | None] = [None] * len(futures)
        for fut in as_completed(futures):
            i = index[fut.key]
            try:
                row = fut.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker: the log is reported, the others go on
                row = {"log": str(logs[i]), "output": "", "status": "failed",
                       "message": f"worker failed: {type(exc).__name__}: {exc}"}
            rows[i] = row
            if on_done is not None:
                on_done(row)
        address = client.scheduler.address if client.scheduler is not None else str(scheduler)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return BatchResult(tuple(r for r in rows if r is not None), address)

