"""Where the fixed-lag method's time goes, push by push, as ``gfimu estimate --method fixed-lag`` runs it.

Runs the method's own path (its screening, then :class:`gfimu.smoother.stream.session.StreamSession` fed
row by row) on a log and prints, from the CPU time of the stream's own thread (``time.thread_time``: a
busy machine stretches wall time, not this):

- the CPU of the whole run (every thread, and the process the later model choices are made in);
- the stream's thread: all of it, the call that made the first model choice, and the cost per sample over
  the second half of the log (a steady state, between choices): its mean, and the median over the samples of
  the cost per sample of their call (the log goes to the stream in blocks, :meth:`StreamSession.push_block
  <gfimu.smoother.stream.session.StreamSession.push_block>`, as ``gfimu estimate`` hands it);
- what that means for a live stream: the rate the stream's thread keeps up with in steady state.

Each run is a fresh process with one BLAS thread, as the command line runs (a second BLAS thread spins
on a core and counts in the CPU of the run).

``--baseline DIR`` runs another checkout's package on the same log in the same loop, alternating, and
prints each figure's ratio (this checkout over that one), medians over ``--runs``::

    python3 tools/stream_cost.py LOG
    python3 tools/stream_cost.py --simulate-s 60 --baseline ../gfimu-before --runs 3
    python3 tools/stream_cost.py --cell impacts-20kHz --duration-s 6
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent


def measure(log_dir: str) -> dict:
    """The figures of one run in this process (the package on ``sys.path``)."""
    import time

    import numpy as np

    from gfimu.io import read_log
    from gfimu.methods import make_estimator
    from gfimu.smoother.stream import session as ss

    log = read_log(log_dir)
    est = make_estimator("fixed-lag")
    screened, _ = est.screen(log)
    calls: list[tuple[int, int, float]] = []  # (first sample, samples, thread CPU [s]) of each call
    push, push_block = ss.StreamSession.push, getattr(ss.StreamSession, "push_block", None)  # (none: an older checkout)

    def timed(self, *a, **k):
        t = time.thread_time()
        out = push(self, *a, **k)
        calls.append((-1, 1, time.thread_time() - t))
        return out

    def timed_block(self, times_ns, accel, start, stop):
        t = time.thread_time()
        end, out = push_block(self, times_ns, accel, start, stop)
        calls.append((start, end - start, time.thread_time() - t))
        return end, out

    import resource

    def children_cpu() -> float:
        r = resource.getrusage(resource.RUSAGE_CHILDREN)
        return r.ru_utime + r.ru_stime

    ss.StreamSession.push = timed
    if push_block is not None:
        ss.StreamSession.push_block = timed_block
    try:
        cpu0, child0, wall0 = time.process_time(), children_cpu(), time.perf_counter()
        est.result(screened)  # (its model choices' process ended and waited for at the stream's end)
        cpu = time.process_time() - cpu0 + children_cpu() - child0
        wall = time.perf_counter() - wall0
    finally:
        ss.StreamSession.push = push
        if push_block is not None:
            ss.StreamSession.push_block = push_block
    # a block's calls (push_block, which pushes a sample it cannot take on its own: that push is inside it)
    blocks = [(i, m, d) for i, m, d in calls if i >= 0] or [(k, 1, d) for k, (_, _, d) in enumerate(calls)]
    n = sum(m for _, m, _ in blocks)
    later = [(m, d) for i, m, d in blocks if i >= n // 2]
    per_sample = np.array([d / m for m, d in later])
    weights = np.array([m for m, _ in later], dtype=float)
    order = np.argsort(per_sample)
    median = float(per_sample[order][np.searchsorted(np.cumsum(weights[order]), 0.5 * weights.sum())])
    return {"samples": n, "rate_hz": float(log.rate_hz), "cpu_s": cpu, "wall_s": wall,
            "pushes_s": float(sum(d for _, _, d in blocks)), "first_choice_s": float(max(d for _, _, d in blocks)),
            "calls": len(blocks),
            "steady_mean_us": 1e6 * float(sum(d for _, d in later) / sum(m for m, _ in later)),
            "steady_median_us": 1e6 * median}


def run_in(package: Path | None, log_dir: str) -> dict:
    """:func:`measure` in a fresh process of ``package`` (None: this checkout)."""
    env = dict(os.environ)
    root = package if package is not None else HERE.parent
    env["PYTHONPATH"] = str(root)
    env["PYTHONSAFEPATH"] = "1"
    for variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(variable, "1")  # one BLAS thread, as the command line sets it (gfimu/cli/__init__.py)
    code = f"import json, sys; sys.path.insert(0, {str(HERE)!r}); import stream_cost; print(json.dumps(stream_cost.measure({log_dir!r})))"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", nargs="?", help="a log folder (default: a simulated cube, --simulate-s)")
    ap.add_argument("--simulate-s", type=float, default=60.0, help="simulated cube log length [s] at 500 Hz (default 60)")
    ap.add_argument("--cell", help="the log of this regime-matrix cell (tools/regime_matrix.py), e.g. impacts-20kHz")
    ap.add_argument("--duration-s", type=float, help="with --cell: its length [s] (default: the cell's)")
    ap.add_argument("--baseline", type=Path, help="another gfimu checkout, run in the same loop")
    ap.add_argument("--runs", type=int, default=1, help="rounds of the loop; medians are shown (default 1)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        log_dir = args.log
        if log_dir is None and args.cell:
            sys.path.insert(0, str(HERE))
            import regime_matrix as rm

            cell = rm.named_cell(args.cell, args.duration_s or None)
            if cell is None:
                ap.error(f"--cell: no cell {args.cell!r}; tools/regime_matrix.py --list names them")
            log_dir = str(rm.build_log(cell, Path(tmp))[0])
        elif log_dir is None:
            log_dir = str(Path(tmp) / "cube")
            subprocess.run([sys.executable, "-m", "gfimu", "simulate", "random3d", "--out", log_dir, "--duration-s",
                            f"{args.simulate_s:g}", "--rate-hz", "500", "--seed", "0", "--quiet"], check=True)
        runs: dict[str, list[dict]] = {"now": [], "baseline": []}
        for _ in range(max(args.runs, 1)):
            runs["now"].append(run_in(None, log_dir))
            if args.baseline:
                runs["baseline"].append(run_in(args.baseline, log_dir))

    def median(rows: list[dict], key: str) -> float:
        vals = sorted(r[key] for r in rows)
        return vals[len(vals) // 2]

    first = runs["now"][0]
    print(f"{log_dir}: {first['samples']} samples at {first['rate_hz']:g} Hz; medians of {len(runs['now'])} run(s)")
    rows = [("CPU of the whole run [s]", "cpu_s", 1.0), ("stream thread, all calls [s]", "pushes_s", 1.0),
            ("the call that made the first choice [s]", "first_choice_s", 1.0),
            ("calls (blocks of samples, and samples one by one)", "calls", 1.0),
            ("per sample, second half, mean [µs]", "steady_mean_us", 1.0),
            ("per sample, second half, median [µs]", "steady_median_us", 1.0)]
    head = "| figure | now |" + (" baseline | now ÷ baseline |" if args.baseline else "")
    print(head)
    print("|---|---|" + ("---|---|" if args.baseline else ""))
    for label, key, _ in rows:
        now = median(runs["now"], key)
        line = f"| {label} | {now:.3g} |"
        if args.baseline:
            base = median(runs["baseline"], key)
            line += f" {base:.3g} | {now / base:.2f} |"
        print(line)
    now = median(runs["now"], "steady_mean_us")
    print(f"steady state: the stream's thread keeps up with {1e6 / now:,.0f} samples/s "
          f"({1e6 / now / first['rate_hz']:.1f}x this log's rate)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
