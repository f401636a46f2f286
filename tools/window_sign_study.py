#!/usr/bin/env python3
"""The sign of ω across the batch smoother's solve windows, on the 30-min vehicle cell of the regime matrix.

Builds the cell's log (``tools/regime_matrix.py``: 50 Hz, 0.3 m cube, slow yaw) and prints:

- the whole log with the default batch smoother, with and without the sign taken across windows
  (``gfimu.smoother.batch.engine._align_signs``): ω RMSE and wrong-sign share against the truth, and the
  windows that are solved again;
- for each window still holding samples on the wrong sign, and for the window of ``--window-at``: its
  cost and wrong samples solved from its own initial states, and solved from them turned to the
  truth's sign (what the readings' own objective says of the two branches).

    python3 tools/window_sign_study.py                    # about 1 minute on one core
    python3 tools/window_sign_study.py --keep DIR         # the log is left in DIR
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import regime_matrix  # noqa: E402

from gfimu import io as gio  # noqa: E402
from gfimu.methods import make_estimator  # noqa: E402
from gfimu.smoother.batch import engine as batch  # noqa: E402
from gfimu.smoother.model.layout import OMEGA  # noqa: E402
from gfimu.smoother.tuning.evidence import tuned_problem  # noqa: E402

CELL = "vehicle-50Hz-30min"
MOVING_RADPS = 0.1
"""Samples whose true |ω| exceeds this count for the wrong-sign share (the regime matrix's rule)."""


def wrong(omega: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Samples turning faster than :data:`MOVING_RADPS` whose estimate points against the truth."""
    return (np.sum(omega * truth, axis=1) < 0) & (np.linalg.norm(truth, axis=1) > MOVING_RADPS)


def whole_log(log, align: bool) -> tuple[np.ndarray, list[int], float]:
    """(ω, windows solved again, CPU s) of the default batch smoother, in this process."""
    aligned: list[int] = []
    original = batch._align_signs

    def spy(context, outcomes):
        done = original(context, outcomes) if align else []
        aligned.extend(done)
        return done

    batch._align_signs = spy
    try:
        t0 = time.process_time()
        motion = make_estimator("smoother", workers=1).estimate(log).motion
        return motion.omega_b_radps, aligned, time.process_time() - t0
    finally:
        batch._align_signs = original


def one_window(log, sl: slice) -> str:
    """The window's cost and wrong samples from its own initial states and from them turned to the truth's sign."""
    opt = make_estimator("smoother")
    part = log.select(sl)
    truth = log.truth.omega_b_radps[sl]
    problem, x0 = tuned_problem(part, opt.model_groups, [], None, opt.tune_span_s)
    own = batch.solve_window(problem, x0, opt.batch)
    turned = x0.copy()
    sign = np.where(np.sum(turned[:, OMEGA] * truth, axis=1) < 0, -1.0, 1.0)
    turned[:, OMEGA] *= sign[:, None]
    right = batch.solve_window(problem, turned, opt.batch)
    return (f"samples {sl.start}..{sl.stop - 1} ({sl.start / log.rate_hz:.1f}-{sl.stop / log.rate_hz:.1f} s): "
            f"from its own start cost {own.cost:.6g}, {int(wrong(own.states[:, OMEGA], truth).sum())} wrong; "
            f"from the truth's sign cost {right.cost:.6g}, {int(wrong(right.states[:, OMEGA], truth).sum())} wrong")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", metavar="DIR", help="write the log into DIR and leave it there")
    ap.add_argument("--window-at", type=float, default=650.0, metavar="S",
                    help="also study the solve window holding this time [s] (default 650: the turn of 647-666 s)")
    args = ap.parse_args(argv)
    cell = regime_matrix.cells_selected(False, CELL)[0]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.keep) if args.keep else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / CELL
        if not path.exists():
            regime_matrix.build_log(cell, folder)
        log = gio.read_log(path)
    truth = log.truth.omega_b_radps
    moving = np.linalg.norm(truth, axis=1) > MOVING_RADPS
    print(f"{CELL}: {len(log)} samples at {log.rate_hz:g} Hz, {int(moving.sum())} turning faster than {MOVING_RADPS} rad/s")
    omega = None
    for align in (False, True):
        omega, aligned, cpu = whole_log(log, align)
        rmse = float(np.sqrt(np.mean(np.sum((omega - truth) ** 2, axis=1))))
        share = 100.0 * wrong(omega, truth)[moving].mean()
        print(f"  sign across windows {'on ' if align else 'off'}: ω RMSE {rmse:.4f} rad/s, wrong sign {share:.2f} %, "
              f"windows solved again {[w + 1 for w in aligned]}, CPU {cpu:.1f} s")
    opt = make_estimator("smoother")
    windows = batch.window_slices(len(log), log.rate_hz, opt.window_s, opt.overlap_s)
    bad = wrong(omega, truth)
    studied = set()
    at = int(round(args.window_at * log.rate_hz))
    for w, (sl, keep, _) in enumerate(windows):
        if bad[keep].any() or (keep.start <= at < keep.stop):
            studied.add(w)
    for w in sorted(studied):
        sl, keep, _ = windows[w]
        print(f"  window {w + 1} of {len(windows)}, {int(bad[keep].sum())} kept samples on the wrong sign (with the "
              f"sign across windows): {one_window(log, sl)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
