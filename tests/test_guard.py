"""The smoothers' guard (gfimu.smoother.guard): where the smoother fits the readings worse than its model
allows against the per-sample ML estimate, the span is found, reported, and by default answered per sample.

The log: a 5 cm cube (0.07 m/s²) turning smoothly at 2-4 rad/s, 3 s at 250 Hz, with a 12 Hz burst of
4 rad/s over 1.40-1.60 s (samples 350-399). The default smoother (process noise by marginal likelihood)
follows the burst; a smoother held to a fixed jerk density of 5 rad/s²/√s cannot, and misfits it."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.estimators.ml import MLEstimator
from gfimu.io.log_dir import write_log
from gfimu.log import Log
from gfimu.motion import Motion
from gfimu.rigid_body import quadratic_terms
from gfimu.smoother import guard
from gfimu.smoother.batch.engine import BatchSmootherEstimator
from gfimu.smoother.stream.fixed_lag import FixedLagEstimator

RATE_HZ, BURST = 250.0, slice(350, 400)
STIFF = dict(auto_model=False, tune_process_noise=False, omega_dot_random_walk_radps2_per_sqrt_s=5.0)
"""A smoother too stiff for the burst."""


def burst_log(seed: int = 0) -> Log:
    arr = cube_array(0.025, noise_std_mps2=0.07)
    t = np.arange(int(RATE_HZ * 3.0)) / RATE_HZ
    rates = np.array([[3.0, 0.5, 0.3], [2.5, 0.4, np.pi / 2], [1.0, 0.3, 0.0]])  # amplitude, Hz, phase per axis
    w = np.stack([a * np.sin(2 * np.pi * f * t + p) for a, f, p in rates], 1) + [0.0, 0.0, 2.0]
    wd = np.stack([a * 2 * np.pi * f * np.cos(2 * np.pi * f * t + p) for a, f, p in rates], 1)
    t0, width, freq, amp = 1.4, 0.2, 12.0, 4.0
    inside = (t >= t0) & (t < t0 + width)
    phase = np.pi * (t - t0) / width
    env = np.where(inside, np.sin(phase) ** 2, 0.0)
    denv = np.where(inside, 2 * np.sin(phase) * np.cos(phase) * np.pi / width, 0.0)
    s, ds = np.sin(2 * np.pi * freq * (t - t0)), 2 * np.pi * freq * np.cos(2 * np.pi * freq * (t - t0))
    d = np.array([1.0, -0.5, 0.3]) / np.linalg.norm([1.0, -0.5, 0.3])
    w = w + amp * (env * s)[:, None] * d
    wd = wd + amp * (denv * s + env * ds)[:, None] * d
    f = np.tile([0.3, -0.2, 9.81], (t.size, 1))
    S = arr.structure_matrix()
    y = np.hstack([f, wd, quadratic_terms(w)]) @ S.T + np.random.default_rng(seed).normal(0.0, 0.07, (t.size, S.shape[0]))
    ts = np.round(t * 1e9).astype(np.int64)
    return Log(arr, ts, y, truth=Motion(ts, omega_b_radps=w, omega_dot_b_radps2=wd, specific_force_b_mps2=f),
               source="burst")


@pytest.fixture(scope="module")
def case():
    """The log, its per-sample ML estimate, and the default smoother's estimate with the guard off and on."""
    log = burst_log()
    off = BatchSmootherEstimator(guard="off").estimate(log)
    on = BatchSmootherEstimator().estimate(log)
    return log, MLEstimator().estimate_motion(log), off, on


def _logs_given(monkeypatch, method: str) -> list:
    """The lengths of the logs given to ``MLEstimator.<method>`` from now on (the method still runs)."""
    calls = []
    real = getattr(MLEstimator, method)

    def counted(self, lg, *args, **kwargs):
        calls.append(len(lg))
        return real(self, lg, *args, **kwargs)

    monkeypatch.setattr(MLEstimator, method, counted)
    return calls


def _error(motion, log, sl=slice(None)):
    return np.linalg.norm(motion.omega_b_radps[sl] - log.truth.omega_b_radps[sl], axis=1)


def test_a_smoother_that_is_right_keeps_its_answer_bit_for_bit(case):
    log, _, off, on = case
    g = on.report.guard
    assert g.spans == () and g.note == "" and g.mode == "replace"
    assert g.usable > 0.8 * len(log)  # it judged most samples, and found nothing
    for name in ("omega_b_radps", "omega_dot_b_radps2", "specific_force_b_mps2"):
        assert np.array_equal(getattr(on.motion, name), getattr(off.motion, name))
    assert on.report.warnings == off.report.warnings == ()
    assert off.report.guard is None and "guard" in on.report.timings
    assert np.sqrt(np.mean(_error(on.motion, log) ** 2)) < 0.06  # and it is right: 0.05 rad/s


def test_a_corrupted_span_is_found_and_answered_per_sample(case):
    log, ml, off, _ = case
    good = off.motion
    bad = (slice(150, 200), slice(620, 670))  # 0.60-0.796 s and 2.48-2.676 s
    w = good.omega_b_radps.copy()
    for sl in bad:
        w[sl] += [1.0, 0.0, 0.0]  # q(ω) off by 2 ω_x + 1 (rad/s)², 0.1-0.3 m/s² at the sensors: 1.5-4 σ
    corrupted = good.replace(omega_b_radps=w)
    check = off.report.model_check
    found = guard.check(log, corrupted, ml, check)
    assert len(found.spans) == 2
    fixed = guard.replaced(corrupted, ml, found)
    outside = np.ones(len(log), bool)
    for span, sl_bad in zip(found.spans, bad):
        assert abs(span.start - sl_bad.start) <= 3 and abs(span.stop - (sl_bad.stop - 1)) <= 3, span
        assert span.start_s == pytest.approx(span.start / RATE_HZ) and span.samples == span.stop - span.start + 1
        assert span.excess > 30 and span.rms_ratio > 1.5
        sl = slice(span.start, span.stop + 1)
        outside[sl] = False
        # the per-sample answer, with the sign the truth has (which the smoother had around the span)
        np.testing.assert_array_equal(np.abs(fixed.omega_b_radps[sl]), np.abs(ml.omega_b_radps[sl]))
        best_sign = np.minimum(_error(ml, log, sl),
                               np.linalg.norm(-ml.omega_b_radps[sl] - log.truth.omega_b_radps[sl], axis=1))
        np.testing.assert_allclose(_error(fixed, log, sl), best_sign, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(fixed.omega_dot_b_radps2[sl], ml.omega_dot_b_radps2[sl])
    np.testing.assert_array_equal(fixed.omega_b_radps[outside], corrupted.omega_b_radps[outside])
    assert "over 2 span(s)" in found.message() and "0.60-0.80 s, 2.48-2.68 s" in found.message()
    # a sample of a span without a per-sample answer keeps the smoother's; the others are still replaced
    k = found.spans[0].start + 10
    holed = ml.replace(omega_b_radps=np.where(np.arange(len(log))[:, None] == k, np.nan, ml.omega_b_radps))
    patched = guard.replaced(corrupted, holed, found)
    np.testing.assert_array_equal(patched.omega_b_radps[k], corrupted.omega_b_radps[k])
    np.testing.assert_array_equal(np.delete(patched.omega_b_radps, k, 0), np.delete(fixed.omega_b_radps, k, 0))
    # the same span with ω flipped: the readings cannot tell ω from -ω, so neither can the guard
    w = good.omega_b_radps.copy()
    w[bad[1]] *= -1.0
    assert guard.check(log, good.replace(omega_b_radps=w), ml, check).spans == ()


@pytest.mark.parametrize("estimator", [BatchSmootherEstimator, FixedLagEstimator])
def test_guard_modes_on_a_smoother_too_stiff_for_the_burst(case, estimator):
    log, ml, _, _ = case
    warn = estimator(guard="warn", **STIFF).estimate(log)
    off = estimator(guard="off", **STIFF).estimate(log)
    rep = estimator(**STIFF).estimate(log)
    (span,) = warn.report.guard.spans
    assert abs(span.start - BURST.start) <= 3 and abs(span.stop - (BURST.stop - 1)) <= 3, span
    # warn: the smoother's answer, bit for bit, and one warning naming the span
    np.testing.assert_array_equal(warn.motion.omega_b_radps, off.motion.omega_b_radps)
    (note,) = warn.report.warnings
    assert note.startswith("fits the readings worse than the per-sample estimate over 1 span(s), 0.20 s in all "
                           f"({span.start_s:.2f}-{span.end_s:.2f} s)")
    assert "the smoother's answer is kept" in note
    # off: nothing checked, nothing said
    assert off.report.guard is None and off.report.warnings == ()
    # replace: the per-sample answer over the span, as accurate as the per-sample fit there and far better
    # than the stiff smoother
    sl = slice(span.start, span.stop + 1)
    assert rep.report.guard.spans == warn.report.guard.spans
    assert "the per-sample answer is used there" in rep.report.warnings[0]
    np.testing.assert_array_equal(np.abs(rep.motion.omega_b_radps[sl]), np.abs(ml.omega_b_radps[sl]))
    rms = lambda e: float(np.sqrt(np.mean(e**2)))  # noqa: E731
    assert rms(_error(rep.motion, log, sl)) < 0.4 < 0.7 < rms(_error(off.motion, log, sl))
    assert rms(_error(rep.motion, log, sl)) == pytest.approx(rms(np.minimum(
        _error(ml, log, sl), np.linalg.norm(-ml.omega_b_radps[sl] - log.truth.omega_b_radps[sl], axis=1))), abs=1e-12)


def test_bad_guard_value_is_named():
    with pytest.raises(ValueError, match="guard must be one of 'replace', 'warn', 'off', got 'maybe'"):
        BatchSmootherEstimator(guard="maybe")


def test_cli_warning_names_the_span(tmp_path, capsys):
    log_dir = tmp_path / "burst"
    write_log(burst_log(), log_dir, rate_hz=RATE_HZ)
    before = {p.name: p.read_bytes() for p in log_dir.iterdir()}
    out = tmp_path / "est.csv"
    cmd = [sys.executable, "-m", "gfimu", "estimate", str(log_dir), "--out", str(out), "--no-progress", "--method",
           "smoother"] + [a for k, v in STIFF.items() for a in ("-O", f"{k}={v}")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if "fits the readings worse" in ln]
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("gfimu estimate: warning: smoother: fits the readings worse than the per-sample "
                               "estimate over 1 span(s), 0.20 s in all (1.40-1.60 s): the per-sample answer is used there")
    assert "-O guard=warn keeps the smoother's" in lines[0]
    assert out.is_file() and {p.name: p.read_bytes() for p in log_dir.iterdir()} == before
    from gfimu.cli import main

    assert main(cmd[3:] + ["-O", "guard=off", "--out", str(tmp_path / "off.csv")]) == 0  # in this process
    assert "fits the readings worse" not in capsys.readouterr().err
    assert main(cmd[3:-2 * len(STIFF)] + ["-O", "guard=sometimes"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "-O guard='sometimes': expected one of 'replace', 'warn', 'off'" in err


def test_report_dict_of_a_span():
    g = guard.GuardResult("warn", (guard.GuardSpan(10, 19, 0.04, 0.076, 50.0, 2.5),), usable=100, samples=200)
    d = g.as_dict()
    assert d["spans"] == [{"start_s": 0.04, "end_s": 0.076, "first_sample": 10, "last_sample": 19, "samples": 10,
                           "excess_chi2_per_sample": 50.0, "rms_ratio": 2.5}]
    assert d["seconds"] == pytest.approx(0.036) and d["usable_samples"] == 100


def test_diagnose_lists_the_spans_of_the_smoother_it_is_given():
    import json

    from gfimu.diagnose import diagnose

    d = diagnose(burst_log(), smoother_options=STIFF)
    (span,) = d.guard["spans"]
    assert abs(span["first_sample"] - BURST.start) <= 3 and abs(span["last_sample"] - (BURST.stop - 1)) <= 3
    assert f"{span['start_s']:.2f}-{span['end_s']:.2f} s" == "1.40-1.60 s" and span["samples"] > 40
    assert json.loads(json.dumps(d.as_dict()))["guard"]["spans"][0]["first_sample"] == span["first_sample"]
    text = d.to_text()
    assert "1 span(s) where the smoother fits the readings worse than its model allows, 0.20 s in all" in text
    assert f"  1.40-1.60 s  samples {span['first_sample']}-{span['last_sample']} ({span['samples']})" in text
    assert any(w.startswith("the smoother fits the readings worse than the per-sample estimate over 1 span(s)")
               for w in d.warnings)
    assert d.verdict.startswith("USE WITH CARE")


def test_a_smoother_reading_the_gyroscope_is_not_judged():
    from gfimu.array import Gyroscope
    from gfimu.log import Log as LogClass

    log = burst_log()
    truth = log.truth.omega_b_radps
    gyro = truth + np.random.default_rng(1).normal(0.0, 0.01, truth.shape)
    arr = type(log.array)(log.array.accelerometers, log.array.name, Gyroscope(0.01))
    with_gyro = LogClass(arr, log.timestamps_ns, log.accel_mps2, gyro_b_radps=gyro, truth=log.truth, source="gyro")
    est = BatchSmootherEstimator(**STIFF).estimate(with_gyro)
    assert est.report.guard.note == "not checked: the smoother uses the gyroscope, which the per-sample fit does not"
    assert est.report.guard.spans == () and est.report.warnings == ()
    est = BatchSmootherEstimator(**STIFF, use_gyro=False).estimate(with_gyro)  # the accelerometers alone: judged
    assert est.report.guard.note == "" and len(est.report.guard.spans) == 1


@pytest.mark.parametrize("array", [cube_array(0.025), cube_array(0.05, noise_std_mps2=0.02)], ids=["cube", "cube-5cm"])
def test_omega_noise_is_the_bounds_omega_block(array):
    """The std of the per-sample ω from the 3×3 Schur complement equals the root of the trace of the ω block of
    the 9×9 Cramér-Rao bound (the expression it replaces), to rounding; inf where that bound is singular (ω = 0)
    and where it is nearly so the bound itself answers."""
    from gfimu.crb import crb_per_sample

    rng = np.random.default_rng(3)
    w = rng.normal(size=(400, 3)) * rng.choice([1e-3, 1.0, 30.0], size=(400, 1))
    w[:2] = 0.0
    w[2] = [1e-9, 0.0, 0.0]
    var = rng.uniform(0.5, 2.0, 400)
    bound = crb_per_sample(array, w, noise_std_mps2=1.0)
    with np.errstate(invalid="ignore"):
        expected = np.sqrt(np.maximum(np.trace(bound.covariance[:, 6:9, 6:9], axis1=1, axis2=2), 0.0) * var)
    expected = np.where(np.isfinite(expected) & ~bound.singular, expected, np.inf)
    got = guard.omega_noise(array, w, var)
    assert np.array_equal(np.isinf(got), np.isinf(expected)) and np.isinf(got[:2]).all()
    finite = np.isfinite(expected)
    np.testing.assert_allclose(got[finite], expected[finite], rtol=1e-10)


def test_a_short_clean_log_is_fitted_per_sample_once(monkeypatch, case):
    """On a log short enough that the model check fits every sample (here 750 < 2 × CHECK_SAMPLES), the guard
    takes that fit instead of computing it again, and finds what it finds with a fit of its own."""
    log, ml, _, on = case
    calls = _logs_given(monkeypatch, "estimate_motion")
    est = BatchSmootherEstimator().estimate(log)
    assert calls == [len(log)]
    assert est.report.guard == on.report.guard
    again = guard.check(log, est.motion, ml, est.report.model_check, "replace")
    assert again == est.report.guard and again.usable > 0.8 * len(log)


def test_replaced_rows_carry_the_per_sample_fits_own_sigma(case):
    """Where the smoother carries σ, a replaced row carries the per-sample fit's: the Cramér-Rao bound at
    its ω times the model check's noise there (σ₀² + (s |ω|)²), per axis; the rows outside keep theirs,
    and without the check the replaced rows say unknown (NaN)."""
    from gfimu.crb import crb_per_sample

    log, ml, off, _ = case
    good = off.motion
    n = len(log)
    sig = {k: np.full((n, 3), 0.01) for k in ("omega_b_radps", "omega_dot_b_radps2", "specific_force_b_mps2")}
    w = good.omega_b_radps.copy()
    w[150:200] += [1.0, 0.0, 0.0]
    corrupted = good.replace(omega_b_radps=w, sigma=sig)
    check = off.report.model_check
    found = guard.check(log, corrupted, ml, check)
    (span, *_) = found.spans
    fixed = guard.replaced(corrupted, ml, found, check, log.array)
    sel = np.arange(span.start, span.stop + 1)
    bound = crb_per_sample(log.array, ml.omega_b_radps[sel], noise_std_mps2=1.0)
    var = check.noise_floor_mps2 ** 2 + (check.noise_slope_mps2_per_radps * np.linalg.norm(ml.omega_b_radps[sel], axis=1)) ** 2
    sd = np.sqrt(np.diagonal(bound.covariance, axis1=1, axis2=2) * var[:, None])
    np.testing.assert_allclose(fixed.sigma["omega_b_radps"][sel], sd[:, 6:9], rtol=1e-12)
    np.testing.assert_allclose(fixed.sigma["omega_dot_b_radps2"][sel], sd[:, 3:6], rtol=1e-12)
    np.testing.assert_allclose(fixed.sigma["specific_force_b_mps2"][sel], sd[:, 0:3], rtol=1e-12)
    outside = np.setdiff1d(np.arange(n), np.concatenate([np.arange(s.start, s.stop + 1) for s in found.spans]))
    np.testing.assert_array_equal(fixed.sigma["omega_b_radps"][outside], 0.01)
    unknown = guard.replaced(corrupted, ml, found)
    assert np.isnan(unknown.sigma["omega_b_radps"][sel]).all()


def test_the_sigma_of_a_replaced_span_covers_its_error():
    """The stiff smoothers' burst span, answered per sample, with --sigma: no row without σ, and over four
    noise draws the share of |ω error| within 1σ and 2σ is a Gaussian's (68 %, 95 %) within the spread of
    ~600 correlated values (a missing noise term or a σ of the smoother's own would give far less)."""
    z = {BatchSmootherEstimator: [], FixedLagEstimator: []}
    for seed in range(4):
        log = burst_log(seed)
        for estimator in z:
            est = estimator(compute_sigma=True, **STIFF).estimate(log)
            (span,) = est.report.guard.spans
            sl = slice(span.start, span.stop + 1)
            s = est.motion.sigma["omega_b_radps"][sl]
            assert np.all(np.isfinite(s)) and np.all(s > 0)
            z[estimator].append(np.abs(est.motion.omega_b_radps[sl] - log.truth.omega_b_radps[sl]) / s)
    for estimator, parts in z.items():
        zz = np.concatenate(parts).ravel()
        assert 0.55 <= np.mean(zz < 1) <= 0.85, estimator
        assert 0.88 <= np.mean(zz < 2) <= 1.0, estimator


def test_a_long_clean_log_is_fitted_per_sample_once_beside_the_check(monkeypatch):
    """On a log long enough that the model check fits a subsample (more than 2 × CHECK_SAMPLES samples), the fit
    of the whole log the guard needs is made during the check, beside the subsample's (its blocks in worker
    processes), and the guard takes it: the same answer, the same guard, as with the fit made by the guard."""
    from gfimu.smoother.batch import engine
    from gfimu.smoother.tuning.model_choice import CHECK_SAMPLES

    arr = cube_array(0.025, noise_std_mps2=0.07)
    t = np.arange(2 * CHECK_SAMPLES + 500) / 1000.0
    w = np.stack([3.0 * np.sin(2 * np.pi * 0.5 * t), 2.5 * np.sin(2 * np.pi * 0.4 * t + 1.0), 2.0 + 0.0 * t], 1)
    wd = np.stack([3.0 * np.pi * np.cos(2 * np.pi * 0.5 * t), 2.0 * np.pi * np.cos(2 * np.pi * 0.4 * t + 1.0), 0.0 * t], 1)
    f = np.tile([0.3, -0.2, 9.81], (t.size, 1))
    y = (np.hstack([f, wd, quadratic_terms(w)]) @ arr.structure_matrix().T
         + np.random.default_rng(3).normal(0.0, 0.07, (t.size, arr.n_axes)))
    log = Log(arr, np.round(t * 1e9).astype(np.int64), y, source="long")
    calls = _logs_given(monkeypatch, "started")
    est = BatchSmootherEstimator(tune_process_noise=False).estimate(log)
    assert est.report.model_check.consistent and est.report.per_sample is not None
    assert calls == [len(log), CHECK_SAMPLES + 250]  # the whole log's started, then the subsample's: no third
    calls.clear()
    monkeypatch.setattr(engine, "unguarded", lambda *args: "asked not to")  # the guard fits the whole log itself
    by_guard = BatchSmootherEstimator(tune_process_noise=False).estimate(log)
    assert by_guard.report.per_sample is None and calls == [CHECK_SAMPLES + 250, len(log)]
    assert by_guard.report.guard == est.report.guard
    np.testing.assert_array_equal(by_guard.motion.omega_b_radps, est.motion.omega_b_radps)
    np.testing.assert_array_equal(by_guard.motion.specific_force_b_mps2, est.motion.specific_force_b_mps2)


def test_the_fixed_lag_guard_s_per_sample_estimate_made_beside_the_stream_is_the_guard_s_own(case, monkeypatch):
    """The fixed-lag smoother's guard reads a per-sample estimate made in a process of its own while the stream
    runs: the ML estimate of the whole log to the bit, and the same rows and guard verdict as the guard's own
    computation of it afterwards."""
    from gfimu.parallel import can_fork, cpu_count
    from gfimu.smoother.result import SmootherEstimator

    if not can_fork() or cpu_count() < 2:
        pytest.skip("the per-sample estimate is made after the stream on this machine")
    log, ml, _, _ = case
    est = FixedLagEstimator(**STIFF)
    beside = est.estimate(log)
    assert beside.report.per_sample is not None
    for name in ("omega_b_radps", "omega_dot_b_radps2", "specific_force_b_mps2"):
        assert getattr(beside.report.per_sample, name).tobytes() == getattr(MLEstimator().estimate_motion(log), name).tobytes()
    monkeypatch.setattr(FixedLagEstimator, "_per_sample_ahead", SmootherEstimator._per_sample_ahead)
    after = est.estimate(log)
    assert after.report.per_sample is None
    assert beside.motion.omega_b_radps.tobytes() == after.motion.omega_b_radps.tobytes()
    assert beside.report.guard == after.report.guard and len(beside.report.guard.spans) == 1


def test_a_log_too_long_for_its_estimate_to_be_sent_back_has_it_made_after_the_stream(case, monkeypatch):
    """Above PER_SAMPLE_AHEAD_MAX samples no process is forked for the guard's per-sample estimate: the guard
    makes it, with the same rows and verdict."""
    from gfimu.smoother.stream import fixed_lag

    log, _, _, _ = case
    est = FixedLagEstimator(**STIFF)
    beside = est.estimate(log)
    monkeypatch.setattr(fixed_lag, "PER_SAMPLE_AHEAD_MAX", len(log) - 1)
    assert est._per_sample_ahead(log) is None
    after = est.estimate(log)
    assert after.report.per_sample is None
    assert beside.motion.omega_b_radps.tobytes() == after.motion.omega_b_radps.tobytes()
    assert beside.report.guard == after.report.guard
