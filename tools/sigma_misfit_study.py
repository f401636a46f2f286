#!/usr/bin/env python3
"""Why the fixed-lag smoother's σ is wide on the MIMU4444 recordings, and why weighting its misfit is no cure.

Both smoothers scale σ by the variance factor s² of the parity residual (the readings' misfit the
states cannot fit, :mod:`gfimu.smoother.solve.sigma_scale`). On a log the model check finds inconsistent
the batch smoother weighs that residual by its robust loss (Cauchy at 2σ, as its solve does); the
fixed-lag smoother, whose update does not re-weigh, takes it unweighted. This prints, per recording
given (``data.bin``, converted with ``gfimu convert mimu4444``; moving rows, |ω_ref| > 2 rad/s,
reference valid):

- s² of the unweighted parity residual at the fixed-lag states and at the batch states (the same
  readings): equal if the excess is not the stream's own estimate error (second order in it);
- s² weighted by the check's robust loss;
- the fixed-lag smoother's 1σ / 2σ shares per axis against the reference lined up in time (as
  ``gfimu evaluate --estimate-time-offset``; the board's gyros lag its accelerometers by 1.3 ms), with
  σ scaled as it is and with the misfit weighted as the batch smoother weighs it, and the batch
  smoother's;

then the same two fixed-lag rows on a simulated log whose misfit is isotropic and heavy-tailed
(random3d, 2.5 cm cube, 0.05 m/s², 200 Hz, 10 s, 1 % of the readings off by ±1 m/s²) against its truth.

    python3 tools/sigma_misfit_study.py ../shared/data/mimu4444/exp_1/data.bin [--seconds 120]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))


@contextmanager
def captured():
    """Record the inputs of both smoothers' σ scaling: the batch's (accel, states, noise, robust) and the
    stream's per emitted row (accel, state, noise)."""
    from gfimu.smoother.batch import engine as batch
    from gfimu.smoother.solve import sigma_scale as ss

    seen = {"batch": None, "stream": []}
    calibrated, scaled = batch.calibrated_sigma, ss.RunningSigmaScale.scaled

    def batch_in(array, accel, states, sd, noise, robust=None, **kw):
        seen["batch"] = (np.array(accel), np.array(states[:, :9]), np.array(noise), robust)
        return calibrated(array, accel, states, sd, noise, robust, **kw)

    def stream_in(self, accel, state, sd, noise, *args, **kwargs):
        seen["stream"].append((np.array(accel), np.array(state[:9]), np.array(noise)))
        return scaled(self, accel, state, sd, noise, *args, **kwargs)

    with mock.patch.object(batch, "calibrated_sigma", batch_in), mock.patch.object(ss.RunningSigmaScale, "scaled", stream_in):
        yield seen


@contextmanager
def weighted_stream(loss):
    """The fixed-lag smoother's misfit weighted by ``loss`` ((name, threshold)) in its σ scaling."""
    from gfimu.smoother.solve import sigma_scale as ss

    scaled = ss.RunningSigmaScale.scaled

    def weighted(self, accel, state, sd, noise, *args, **kwargs):
        self.robust = loss
        return scaled(self, accel, state, sd, noise, *args, **kwargs)

    with mock.patch.object(ss.RunningSigmaScale, "scaled", weighted):
        yield


def motion_of(method: str, log):
    from gfimu.methods import make_estimator

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return make_estimator(method, compute_sigma=True).estimate(log).motion


def shares(err: np.ndarray, sd: np.ndarray) -> str:
    ok = np.all(np.isfinite(err) & np.isfinite(sd), axis=1)
    c1 = np.mean(np.abs(err[ok]) < sd[ok], axis=0)
    c2 = np.mean(np.abs(err[ok]) < 2 * sd[ok], axis=0)
    return " / ".join(f"{100 * a:.0f}-{100 * b:.0f}" for a, b in zip(c1, c2)) + " %"


def variance_factor(array, accel, states, noise, robust, rows) -> float:
    from gfimu.smoother.solve.sigma_scale import parity

    p, rank, _ = parity(array, accel, states, noise, robust)
    ok = rows & np.all(np.isfinite(p), axis=1)
    return float(np.sum(p[ok] ** 2) / np.sum((p.shape[1] - rank)[ok]))


def recording(path: Path, seconds: float | None, loss) -> None:
    from sigma_coverage import aligned, moving_recording

    with tempfile.TemporaryDirectory() as tmp:
        got = moving_recording(path, Path(tmp), seconds)
    if isinstance(got, str):
        print(f"{path}: convert failed: {got}")
        return
    log, reference, rows = got
    with captured() as seen:
        fixed = motion_of("fixed-lag", log)
        batch = motion_of("smoother", log)
    accel, s_states, s_noise = (np.array([r[j] for r in seen["stream"]]) for j in range(3))
    b_accel, b_states, b_noise, b_robust = seen["batch"]
    with weighted_stream(b_robust or loss):
        fixed_w = motion_of("fixed-lag", log)
    name = f"{path.parent.name}/{path.name}"
    print(f"\n{name}: {len(log)} samples, {int(rows.sum())} moving; batch misfit loss {b_robust}")
    print(f"  s² unweighted, moving rows: at the fixed-lag states {variance_factor(log.array, accel, s_states, s_noise, None, rows):.3f}, "
          f"at the batch states {variance_factor(log.array, accel, b_states, s_noise, None, rows):.3f}; "
          f"weighted ({(b_robust or loss)[0]} {(b_robust or loss)[1]:g}): "
          f"{variance_factor(log.array, accel, s_states, s_noise, b_robust or loss, rows):.3f}")
    print("  shares < 1σ - < 2σ per axis (x / y / z), against the reference lined up in time:")
    for label, motion in (("fixed-lag, σ as scaled", fixed), ("fixed-lag, misfit weighted", fixed_w),
                          ("batch smoother", batch)):
        w, sd, offset = aligned(motion, motion.sigma["omega_b_radps"], reference, rows)
        print(f"    {label:28s} {shares((w - reference.omega_b_radps)[rows], sd[rows])} (offset {offset * 1e3:+.2f} ms)")


def spikes(loss) -> None:
    from gfimu.array import cube_array
    from gfimu.simulate import simulate

    log = simulate("random3d", array=cube_array(0.025, noise_std_mps2=0.05), rate_hz=200.0, duration_s=10.0, seed=4)
    rng = np.random.default_rng(7)
    a = log.accel_mps2.copy()
    hit = rng.random(a.shape) < 0.01
    a[hit] += rng.choice([-1.0, 1.0], int(hit.sum()))
    log = replace(log, accel_mps2=a)
    truth = log.truth.omega_b_radps
    print("\nrandom3d with 1 % of the readings off by ±1 m/s² (20σ), against the truth:")
    for label, ctx in (("fixed-lag, σ as scaled", None), ("fixed-lag, misfit weighted", loss)):
        with (weighted_stream(ctx) if ctx else mock.patch.dict({})):
            motion = motion_of("fixed-lag", log)
        print(f"    {label:28s} {shares(motion.omega_b_radps - truth, motion.sigma['omega_b_radps'])}")
    motion = motion_of("smoother", log)
    print(f"    {'batch smoother':28s} {shares(motion.omega_b_radps - truth, motion.sigma['omega_b_radps'])}")


def main(argv=None) -> int:
    from gfimu.smoother.tuning.model_choice import ROBUST_THRESHOLD

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recordings", nargs="*", type=Path, help="MIMU4444 data.bin files")
    ap.add_argument("--seconds", type=float, default=None, help="only the first this many seconds of each")
    args = ap.parse_args(argv)
    loss = ("cauchy", ROBUST_THRESHOLD)
    for path in args.recordings:
        recording(path, args.seconds, loss)
    spikes(loss)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
