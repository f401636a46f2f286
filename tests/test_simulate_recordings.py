"""Real-motion scenarios from the recordings shipped with GTSAM (EuRoC, KITTI)."""

import numpy as np
import pytest

from gfimu import rotations
from gfimu.datasets import gtsam_recordings as rec
from gfimu.simulate import SensorErrors, simulate
from gfimu.simulate.scenarios import smooth_recording


@pytest.fixture(scope="module")
def euroc():
    return rec.load_euroc()


@pytest.fixture(scope="module")
def kitti():
    return rec.load_kitti()


def test_euroc_recording(euroc):
    assert euroc.times_s.shape == (6001,) and euroc.omega_radps.shape == (6001, 3)
    assert euroc.rate_hz == pytest.approx(200.0, rel=1e-3)
    assert euroc.duration_s == pytest.approx(30.0, abs=1e-6)
    still = euroc.times_s < 1.0  # the MAV rests at the start: |f| ≈ g, x axis up
    assert np.linalg.norm(euroc.specific_force_mps2[still].mean(axis=0)) == pytest.approx(9.81, abs=0.2)
    assert np.argmax(np.abs(euroc.specific_force_mps2[still].mean(axis=0))) == 0
    assert np.abs(euroc.omega_radps[still].mean(axis=0)).max() < 0.1


def test_kitti_recording(kitti):
    assert kitti.omega_radps.shape == (46968, 3)
    assert kitti.rate_hz == pytest.approx(100.0, rel=1e-2)
    seg = kitti.longest_segment()
    assert seg.times_s[0] == 0.0 and seg.times_s.size == 46967  # the lone first row is dropped
    assert np.max(np.diff(seg.times_s)) < 0.05
    assert np.median(np.linalg.norm(seg.specific_force_mps2, axis=1)) == pytest.approx(9.81, abs=0.3)


def test_missing_or_malformed_recording_is_reported(tmp_path):
    with pytest.raises(FileNotFoundError, match="gtsam"):
        rec.load_euroc(tmp_path / "nope.csv")
    bad = tmp_path / "bad.csv"
    bad.write_text("row_type,t_rel,gx,gy,gz,ax,ay,az\nimu,0,0,0,0,0,0,9.8\nimu,0.005,0,x,0,0,0,9.8\n")
    with pytest.raises(ValueError, match="line 3"):
        rec.load_euroc(bad)
    bad.write_text("Time dt accelX\n0 0 1\n")
    with pytest.raises(ValueError, match="header must contain"):
        rec.load_kitti(bad)


def test_smoothing_spline_keeps_the_band_and_removes_noise():
    t = np.arange(0.0, 10.0, 0.005)
    gains = np.array([1.0, 0.5, -2.0])
    signal = np.sin(2 * np.pi * t)[:, None] * gains
    inner = slice(200, -200)
    clean = smooth_recording(t, signal, bandwidth_hz=20.0)
    np.testing.assert_allclose(clean(t)[inner], signal[inner], atol=1e-4)
    np.testing.assert_allclose(clean.derivative()(t)[inner], 2 * np.pi * np.cos(2 * np.pi * t)[inner, None] * gains,
                               atol=2e-3)
    noise = np.random.default_rng(0).normal(0, 0.05, signal.shape)
    smoothed_noise = smooth_recording(t, noise, bandwidth_hz=20.0)(t)[inner]
    assert np.std(smoothed_noise) < 0.5 * 0.05  # 20 Hz of the 100 Hz band (200 Hz sampling) kept


@pytest.mark.parametrize("scenario,loader,rate", [("euroc", rec.load_euroc, 200.0), ("kitti", rec.load_kitti, 100.0)])
def test_recorded_scenarios_replay_the_recording(scenario, loader, rate):
    log = simulate(scenario, noise=SensorErrors.none(), duration_s=20.0)
    assert log.rate_hz == pytest.approx(rate)
    r = loader().longest_segment()
    tr = log.truth
    t = log.times_s[10:-10]

    def at(x):
        return np.stack([np.interp(t, r.times_s, x[:, j]) for j in range(3)], axis=1)

    # truth ω is the (bias-removed for EuRoC) recorded gyro, smoothed: differences at the noise level
    bias = r.omega_radps[r.times_s <= 1.0].mean(axis=0) if scenario == "euroc" else 0.0
    d_w = tr.omega_b_radps[10:-10] - (at(r.omega_radps) - bias)
    assert np.sqrt(np.mean(d_w**2)) < 0.05
    # f: EuRoC's MAV vibrates (about 1 m/s² above 20 Hz), which the smoothing removes without bias
    d_f = tr.specific_force_b_mps2[10:-10] - at(r.specific_force_mps2)
    assert np.sqrt(np.mean(d_f**2)) < 1.0
    assert np.abs(d_f.mean(axis=0)).max() < 0.05
    # starts level: the first attitude maps the measured f onto the world vertical
    up = rotations.matrix_from_quaternion(tr.quaternion_wb[0]) @ tr.specific_force_b_mps2[0]
    np.testing.assert_allclose(up[:2], 0.0, atol=1e-12)
    assert up[2] > 0
    # gravity-free acceleration stays vehicle-like (the attitude does not drift away)
    assert np.percentile(np.linalg.norm(tr.accel_b_mps2, axis=1), 95) < 4.0


def test_recorded_scenario_options():
    a = simulate("euroc", noise=SensorErrors.none(), duration_s=2.0, start_s=10.0, rate_hz=400.0)
    b = simulate("euroc", noise=SensorErrors.none(), duration_s=4.0, start_s=8.0, rate_hz=400.0)
    # same real ω at the same recording time, whatever the window (up to the spline fit's edges)
    np.testing.assert_allclose(a.truth.omega_b_radps[100:-100], b.truth.omega_b_radps[900:1500], atol=2e-3)
    raw = simulate("euroc", noise=SensorErrors.none(), duration_s=2.0, still_s=0.0)
    auto = simulate("euroc", noise=SensorErrors.none(), duration_s=2.0)
    offset = raw.truth.omega_b_radps - auto.truth.omega_b_radps  # the gyro bias removed, a constant
    r = rec.load_euroc()
    np.testing.assert_allclose(offset, np.tile(r.omega_radps[r.times_s <= 1.0].mean(axis=0), (len(raw), 1)),
                               atol=1e-9)
