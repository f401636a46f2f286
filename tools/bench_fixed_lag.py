#!/usr/bin/env python3
"""Update latency and memory of the streaming fixed-lag smoother (method "fixed-lag").

1. Latency: simulated random 3-D motion (cube array, half edge 0.05 m,
   0.07 m/s² per axis) at ``--rate-hz`` with ``--lag-s`` for ``--duration-s``
   (default 600 s: ten minutes of stream); every ``push`` is timed (wall clock
   and this thread's CPU time); prints median, 90th and 99th percentiles and
   maximum in steady state (every push after the one-time push that chooses
   the process noise on the first ``tune_window_s`` of data and catches up
   with the buffered samples, which is printed apart), the ω RMSE of the
   smoothed output and of the batch smoother on the first minute.
   ``--profile N`` prints the N top entries of a cProfile of the steady state.
2. End to end: ``gfimu estimate --method fixed-lag`` on a written 60 s log
   (``--e2e-duration-s``) in a fresh process, start-up included: samples/s.
3. Memory: a long stream generated on the fly (smooth multi-sine motion
   computed chunk by chunk, never held whole), RSS sampled along the way;
   prints RSS after the first minute of data and at the end, the growth,
   peak RSS and the most keys / factor slots gtsam held.

    python3 tools/bench_fixed_lag.py [--duration-s 600] [--memory-duration-s 600] [--engine numpy|gtsam]
                                     [--profile 15] [--json bench_fixed_lag.json]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import pstats
import subprocess
import tempfile
import os
import platform
import resource
import sys
import time
from pathlib import Path

for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")  # one BLAS thread, as the command line runs (set before numpy loads)

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gfimu.array import cube_array  # noqa: E402
from gfimu.simulate import simulate  # noqa: E402
from gfimu.smoother.batch.engine import BatchSmootherEstimator  # noqa: E402
from gfimu.smoother.stream.fixed_lag import FixedLagEstimator  # noqa: E402


def rss_mb() -> float:
    """Resident set size of this process now [MB] (Linux /proc)."""
    with open("/proc/self/statm") as fh:
        pages = int(fh.read().split()[1])
    return pages * resource.getpagesize() / 2**20


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class SineMotion:
    """ω(t), ω̇(t), f(t): sums of sines (|ω| up to a few rad/s), evaluated chunk by chunk."""

    def __init__(self, seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        self.a_w = rng.uniform(0.5, 2.0, (3, 4))
        self.f_w = rng.uniform(0.1, 2.0, (3, 4))
        self.p_w = rng.uniform(0, 2 * np.pi, (3, 4))
        self.a_f = rng.uniform(0.5, 3.0, (3, 3))
        self.f_f = rng.uniform(0.1, 2.0, (3, 3))
        self.p_f = rng.uniform(0, 2 * np.pi, (3, 3))

    def __call__(self, t: np.ndarray):
        ph = 2 * np.pi * self.f_w[None] * t[:, None, None] + self.p_w[None]
        w = np.sum(self.a_w * np.sin(ph), axis=2)
        dw = np.sum(self.a_w * 2 * np.pi * self.f_w * np.cos(ph), axis=2)
        f = np.sum(self.a_f * np.sin(2 * np.pi * self.f_f[None] * t[:, None, None] + self.p_f[None]), axis=2)
        f[:, 2] += 9.80665
        return w, dw, f


def latency_run(args) -> dict:
    array = cube_array(0.05, 0.07)
    log = simulate("random3d", array, rate_hz=args.rate_hz, duration_s=args.duration_s, seed=0)
    est = FixedLagEstimator(lag_s=args.lag_s, engine=args.engine)
    sm = est.smoother(array, args.rate_hz)
    lat_ns = np.empty(len(log), dtype=np.int64)
    cpu_ns = np.empty(len(log), dtype=np.int64)
    # outputs go to a preallocated array (holding 300,000 result objects would make Python's garbage
    # collector walk them all now and then, inside a timed push)
    w = np.full((len(log), 3), np.nan)
    index = {int(t): j for j, t in enumerate(log.timestamps_ns)}

    def keep(states) -> None:
        for s in states:
            w[index[s.timestamp_ns]] = s.omega_b_radps

    clock, cpu_clock = time.perf_counter_ns, time.thread_time_ns
    t_all = time.perf_counter()
    load_before = os.getloadavg()[0]
    for i in range(len(log)):
        t0, c0 = clock(), cpu_clock()
        upd = sm.push(log.timestamps_ns[i], log.accel_mps2[i])
        cpu_ns[i] = cpu_clock() - c0
        lat_ns[i] = clock() - t0
        keep(upd.smoothed)
    wall = time.perf_counter() - t_all
    keep(sm.flush())
    n_min = min(len(log), int(round(60.0 * args.rate_hz)))
    rmse = float(np.sqrt(np.mean(np.sum((w[:n_min] - log.truth.omega_b_radps[:n_min]) ** 2, axis=1))))
    batch = BatchSmootherEstimator().estimate(log.select(slice(0, n_min))).motion
    rmse_batch = float(np.sqrt(np.mean(np.sum((batch.omega_b_radps - log.truth.omega_b_radps[:n_min]) ** 2, axis=1))))
    n_tune = int(round(est.tune_window_s * args.rate_hz))
    tuning_push_ms = float(lat_ns[n_tune - 1] * 1e-6) if sm.tuning is not None and n_tune <= len(lat_ns) else None
    steady = slice(n_tune, None) if tuning_push_ms is not None else slice(0, None)
    ms = lat_ns[steady] * 1e-6  # steady state: after the one-time tuning push
    cpu_ms = cpu_ns[steady] * 1e-6
    return {
        "engine": args.engine, "latency_max_including_tuning_push_ms": float(lat_ns.max() * 1e-6),
        "updates_over_20_ms": int(np.sum(ms > 20.0)), "updates_over_2_ms": int(np.sum(ms > 2.0)),
        "cpu_max_ms": float(cpu_ms.max()), "steady_state_updates": int(ms.size),
        "tuning_push_ms": tuning_push_ms, "tuning_push_sample": n_tune - 1 if tuning_push_ms is not None else None,
        "cpu_median_ms": float(np.median(cpu_ms)), "cpu_p90_ms": float(np.percentile(cpu_ms, 90)),
        "cpu_p99_ms": float(np.percentile(cpu_ms, 99)),
        "load_average_1min": [load_before, os.getloadavg()[0]], "cpus": os.cpu_count(),
        "samples": len(log), "rate_hz": args.rate_hz, "lag_s": args.lag_s,
        "latency_median_ms": float(np.median(ms)), "latency_p90_ms": float(np.percentile(ms, 90)),
        "latency_p99_ms": float(np.percentile(ms, 99)), "latency_max_ms": float(ms.max()),
        "samples_per_s": len(log) / wall, "omega_rmse_radps": rmse, "omega_rmse_batch_radps": rmse_batch,
    }


def memory_run(args) -> dict:
    array = cube_array(0.05, 0.07)
    motion = SineMotion(1)
    rng = np.random.default_rng(2)
    sm = FixedLagEstimator(lag_s=args.lag_s, engine=args.engine).smoother(array, args.rate_hz)
    n_total = int(round(args.memory_duration_s * args.rate_hz))
    chunk = int(round(10.0 * args.rate_hz))
    trace = []  # (seconds of data, RSS MB, keys, factor slots)
    max_keys = max_slots = 0
    n_out = 0
    sq_err = 0.0
    t_wall = time.perf_counter()
    for start in range(0, n_total, chunk):
        idx = np.arange(start, min(start + chunk, n_total))
        t = idx / args.rate_hz
        w, dw, f = motion(t)
        y = array.predict_readings(f, dw, w) + rng.normal(0.0, 0.07, (idx.size, array.n_axes))
        t_ns = np.round(t * 1e9).astype(np.int64)
        truth = {int(a): b for a, b in zip(t_ns, w)}
        for j in range(idx.size):
            for s in sm.push(t_ns[j], y[j]).smoothed:
                e = s.omega_b_radps - truth_lookup(truth, s.timestamp_ns, motion)
                sq_err += float(e @ e)
                n_out += 1
        max_keys = max(max_keys, sm.n_keys)
        max_slots = max(max_slots, sm.n_factor_slots)
        trace.append((float(t[-1]), rss_mb(), sm.n_keys, sm.n_factor_slots))
        if args.verbose:
            print(f"  {t[-1]:8.1f} s of data  RSS {trace[-1][1]:7.1f} MB  keys {sm.n_keys}  slots {sm.n_factor_slots}",
                  flush=True)
    wall = time.perf_counter() - t_wall
    for s in sm.flush():
        n_out += 1
    first = next((r for r in trace if r[0] >= 60.0), trace[0])
    return {
        "data_s": args.memory_duration_s, "samples": n_total, "wall_s": wall, "outputs": n_out,
        "rss_after_first_minute_mb": first[1], "rss_end_mb": trace[-1][1], "rss_growth_mb": trace[-1][1] - first[1],
        "peak_rss_mb": peak_rss_mb(), "max_keys": max_keys, "max_factor_slots": max_slots,
        "omega_rmse_radps": float(np.sqrt(sq_err / max(n_out - 1, 1))),
        "trace": [{"data_s": a, "rss_mb": b, "keys": c, "factor_slots": d} for a, b, c, d in trace],
    }


def profile_run(args) -> str:
    """cProfile of the steady state (after the tuning push), top ``args.profile`` entries by own time."""
    array = cube_array(0.05, 0.07)
    log = simulate("random3d", array, rate_hz=args.rate_hz, duration_s=20.0, seed=0)
    est = FixedLagEstimator(lag_s=args.lag_s, engine=args.engine)
    sm = est.smoother(array, args.rate_hz)
    n0 = int(round(est.tune_window_s * args.rate_hz)) + 10
    for i in range(n0):
        sm.push(log.timestamps_ns[i], log.accel_mps2[i])
    prof = cProfile.Profile()
    prof.enable()
    for i in range(n0, len(log)):
        sm.push(log.timestamps_ns[i], log.accel_mps2[i])
    prof.disable()
    buf = io.StringIO()
    pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(args.profile)
    return buf.getvalue()


def end_to_end_run(args) -> dict:
    """``gfimu estimate --method fixed-lag`` on a written log, in a fresh process (start-up included)."""
    from gfimu import io as gio

    array = cube_array(0.05, 0.07)
    log = simulate("random3d", array, rate_hz=args.rate_hz, duration_s=args.e2e_duration_s, seed=3)
    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    with tempfile.TemporaryDirectory() as tmp:
        gio.write_log(log, Path(tmp) / "log")
        cmd = [sys.executable, "-m", "gfimu", "estimate", str(Path(tmp) / "log"), "--method", "fixed-lag",
               "--lag-s", str(args.lag_s), "-O", f"engine={args.engine}", "--out", str(Path(tmp) / "est.csv"),
               "--no-progress"]
        t0 = time.perf_counter()
        done = subprocess.run(cmd, capture_output=True, text=True, env=env)
        wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"gfimu estimate failed: {done.stderr.strip()}")
    return {"samples": len(log), "wall_s": wall, "samples_per_s": len(log) / wall,
            "command": " ".join(["gfimu"] + cmd[3:])}


def truth_lookup(truth: dict, t_ns: int, motion: SineMotion) -> np.ndarray:
    v = truth.get(int(t_ns))
    if v is None:  # from the previous chunk
        v = motion(np.array([t_ns * 1e-9]))[0][0]
    return v


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-s", type=float, default=600.0, help="length of the latency run [s of data] (default 600)")
    ap.add_argument("--e2e-duration-s", type=float, default=60.0,
                    help="length of the log of the end-to-end command [s of data] (default 60; 0 skips it)")
    ap.add_argument("--engine", default="numpy", choices=("numpy", "gtsam"), help="window solver (default numpy)")
    ap.add_argument("--profile", type=int, default=0, help="print this many top cProfile entries (default 0: none)")
    ap.add_argument("--memory-duration-s", type=float, default=600.0, help="length of the memory run [s of data]; 0 skips it")
    ap.add_argument("--rate-hz", type=float, default=500.0)
    ap.add_argument("--lag-s", type=float, default=0.2)
    ap.add_argument("--json", default="bench_fixed_lag.json", help="where to write the results")
    ap.add_argument("--verbose", action="store_true", help="print RSS every 10 s of data during the memory run")
    args = ap.parse_args(argv)

    result = {"platform": platform.platform(), "python": platform.python_version(), "date": time.strftime("%Y-%m-%d %H:%M %Z"),
              "cpus": os.cpu_count()}
    if args.profile:
        result["profile"] = profile_run(args)
        print(f"cProfile, engine {args.engine}, steady state, top {args.profile} by own time:")
        print(result["profile"])
    lat = latency_run(args)
    print(f"fixed-lag smoother ({args.engine} engine), cube array, {args.rate_hz:g} Hz, lag {args.lag_s:g} s, "
          f"{lat['samples']} samples ({lat['samples'] / args.rate_hz / 60:.1f} min of stream); steady state: "
          f"{lat['steady_state_updates']} updates after the tuning push")
    print("| push latency median | p90 | p99 | max | updates > 2 ms | > 20 ms | samples/s | ω RMSE fixed-lag (1st min) "
          "| ω RMSE batch (1st min) |")
    print("|---|---|---|---|---|---|---|---|---|")
    print(f"| {lat['latency_median_ms']:.3f} ms | {lat['latency_p90_ms']:.3f} ms | {lat['latency_p99_ms']:.3f} ms | "
          f"{lat['latency_max_ms']:.1f} ms | {lat['updates_over_2_ms']} | {lat['updates_over_20_ms']} | "
          f"{lat['samples_per_s']:.0f} | {lat['omega_rmse_radps']:.4f} rad/s | {lat['omega_rmse_batch_radps']:.4f} rad/s |")
    print(f"CPU time per push (this thread only): median {lat['cpu_median_ms']:.3f} ms, p90 {lat['cpu_p90_ms']:.3f} ms, "
          f"p99 {lat['cpu_p99_ms']:.3f} ms, max {lat['cpu_max_ms']:.2f} ms; 1-min load average {lat['load_average_1min'][0]:.1f} -> "
          f"{lat['load_average_1min'][1]:.1f} on {lat['cpus']} CPUs (wall-clock latency includes waiting for a CPU)")
    if lat["tuning_push_ms"] is not None:
        print(f"one-time push choosing the process noise (sample {lat['tuning_push_sample']}): {lat['tuning_push_ms']:.0f} ms "
              "(tuning and batch solve of the stretch, catch-up of the buffered samples)")
    result["latency"] = lat
    if args.e2e_duration_s > 0:
        e2e = end_to_end_run(args)
        result["end_to_end"] = e2e
        print(f"\nend to end: {e2e['command']}: {e2e['samples']} samples in {e2e['wall_s']:.1f} s = "
              f"{e2e['samples_per_s']:.0f} samples/s (fresh process: start-up, reading, tuning, stream, writing)")
    if args.memory_duration_s > 0:
        mem = memory_run(args)
        result["memory"] = mem
        print()
        print(f"memory: {mem['samples']} samples ({mem['data_s']:g} s of data) streamed in {mem['wall_s']:.0f} s")
        print("| RSS after 1 min of data | RSS at end | growth | peak RSS | max keys | max factor slots | ω RMSE |")
        print("|---|---|---|---|---|---|---|")
        print(f"| {mem['rss_after_first_minute_mb']:.1f} MB | {mem['rss_end_mb']:.1f} MB | {mem['rss_growth_mb']:+.1f} MB | "
              f"{mem['peak_rss_mb']:.1f} MB | {mem['max_keys']} | {mem['max_factor_slots']} | "
              f"{mem['omega_rmse_radps']:.4f} rad/s |")
    Path(args.json).write_text(json.dumps(result, indent=2))
    print(f"\nresults written to {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
