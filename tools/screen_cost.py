"""What the readings' screening costs a log with isolated spikes: the whole-log rule (what the batch smoother
screens with, :func:`gfimu.readings.screen_log`) against the stream's rule applied to the log row by row
(what ``gfimu estimate --method fixed-lag`` and ``gfimu live`` screen with, :func:`gfimu.readings.screen_stream`).

The stream decides its readings a block at a time (:data:`gfimu.readings.STREAM_BLOCK_S`: one sample at
62.5 Hz) and passes a stretch as it is where the whole-log rule replaces nothing within its reach; around a
replaced reading every block is decided on its own buffer. A spike every ``--spike-every`` samples (added to
one channel, ``--spike-mps2``) makes more of the log such stretches. Both rules run in this process, one after
the other, ``--runs`` times (medians); the figures are seconds and their ratio, with the blocks the stream
decided on their buffers and the readings each rule replaced::

    python3 tools/screen_cost.py                              # a simulated 62.5 Hz log, 10 min
    python3 tools/screen_cost.py LOG --spike-every 150       # a log folder, with a spike every 150 samples
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))


def with_spikes(log, every: int, size_mps2: float, column: int = 0):
    """``log`` with ``size_mps2`` added to one reading of ``column`` every ``every`` samples (0: none)."""
    if every <= 0:
        return log
    accel = log.accel_mps2.copy()
    accel[every // 2::every, column] += size_mps2
    return log.replace(accel_mps2=accel)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", nargs="?", help="log folder (default: a simulated random3d log, --rate-hz, --duration-s)")
    ap.add_argument("--rate-hz", type=float, default=62.5, help="simulated log's rate [Hz] (default 62.5)")
    ap.add_argument("--duration-s", type=float, default=600.0, help="simulated log's length [s] (default 600)")
    ap.add_argument("--spike-every", type=int, default=150,
                    help="a spike every this many samples (0: none; default 150)")
    ap.add_argument("--spike-mps2", type=float, default=60.0, help="the spikes' size [m/s^2] (default 60)")
    ap.add_argument("--runs", type=int, default=3, help="rounds; medians are shown (default 3)")
    args = ap.parse_args(argv)

    from gfimu import readings
    from gfimu.io.log_dir import read_log

    if args.log:
        log = read_log(args.log)
        what = f"{args.log}: {len(log)} samples at {log.rate_hz:.6g} Hz"
    else:
        from gfimu.simulate import simulate

        log = simulate("random3d", duration_s=args.duration_s, rate_hz=args.rate_hz, seed=0)
        what = f"simulated random3d: {len(log)} samples at {args.rate_hz:g} Hz"
    dirty = with_spikes(log, args.spike_every, args.spike_mps2)
    decided = []
    original = readings.StreamScreen._decide

    def counted(self, upto):
        decided.append(upto)
        return original(self, upto)

    readings.StreamScreen._decide = counted
    whole_s, stream_s = [], []
    with tempfile.TemporaryDirectory():
        readings.screen_stream(dirty.select(slice(0, min(len(dirty), 2000))))  # (the kernels loaded once)
        for _ in range(max(args.runs, 1)):
            t0 = time.perf_counter()
            _, whole = readings.screen_log(dirty)
            t1 = time.perf_counter()
            decided.clear()
            _, stream = readings.screen_stream(dirty)
            t2 = time.perf_counter()
            whole_s.append(t1 - t0)
            stream_s.append(t2 - t1)
    w, s = statistics.median(whole_s), statistics.median(stream_s)
    blocks = -(-len(dirty) // readings.stream_block_samples(dirty.rate_hz))
    print(what + (f"; a {args.spike_mps2:g} m/s^2 spike every {args.spike_every} samples" if args.spike_every > 0 else
                  "; no spike added") + f"; medians of {max(args.runs, 1)} run(s)")
    print(f"whole-log rule {w:.3f} s; stream rule {s:.3f} s ({s / w:.1f}x); the stream decided "
          f"{len(decided)} of {blocks} blocks on their own buffers; replaced {whole.count} (whole log), "
          f"{stream.count} (stream)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
