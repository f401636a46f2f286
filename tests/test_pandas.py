"""pandas bridge: Log and Motion to and from DataFrames, exact round trips, columns as in the CSV formats."""

from __future__ import annotations

import numpy as np
import pytest

pd = pytest.importorskip("pandas")

from gfimu import io as gio  # noqa: E402
from gfimu.array import paper001_array  # noqa: E402
from gfimu.errors import MissingExtraError  # noqa: E402
from gfimu.log import Log  # noqa: E402
from gfimu.motion import Motion  # noqa: E402
from gfimu.simulate import simulate  # noqa: E402


@pytest.fixture(scope="module")
def log():
    # Lu, Tsai & Lin 2010's array: 2-axis accelerometers, a gyroscope and an inclinometer, so every reading column
    return simulate("turntable", array=paper001_array(), duration_s=0.2, seed=2)


def test_log_round_trip_is_exact_with_the_imu_csv_columns(log, tmp_path):
    df = log.to_dataframe()
    assert df.index.name == "timestamp_ns" and df.index.dtype == np.int64
    np.testing.assert_array_equal(df.index.to_numpy(), log.timestamps_ns)
    # the columns of imu.csv, in its order, without their units
    gio.write_imu_csv(log, tmp_path / "imu.csv")
    header = (tmp_path / "imu.csv").read_text().splitlines()[0].split(",")
    assert [f"{c} [{df.attrs['units'][c]}]" for c in df.columns] == header[1:]
    assert list(df.columns[-5:]) == ["w_x", "w_y", "w_z", "tilt_x", "tilt_y"]
    np.testing.assert_array_equal(df["w_z"].to_numpy(), log.gyro_b_radps[:, 2])
    back = Log.from_dataframe(df, log.array)
    np.testing.assert_array_equal(back.timestamps_ns, log.timestamps_ns)
    np.testing.assert_array_equal(back.accel_mps2, log.accel_mps2)
    np.testing.assert_array_equal(back.gyro_b_radps, log.gyro_b_radps)
    np.testing.assert_array_equal(back.tilt_rad, log.tilt_rad)
    # extra columns are ignored; a missing one is named
    df2 = df.assign(extra=1.0)
    np.testing.assert_array_equal(Log.from_dataframe(df2, log.array).accel_mps2, log.accel_mps2)
    with pytest.raises(ValueError, match="column 'tilt_y' is missing"):
        Log.from_dataframe(df.drop(columns="tilt_y"), log.array)
    with pytest.raises(ValueError, match="integer timestamps in nanoseconds"):
        Log.from_dataframe(df.set_index(df.index * 1e-9), log.array)


def test_motion_round_trip_is_exact_with_sigma(log, tmp_path):
    truth = log.truth
    rng = np.random.default_rng(0)
    motion = truth.replace(sigma={"omega_b_radps": rng.random((len(truth), 3))})
    df = motion.to_dataframe()
    gio.write_motion_csv(motion, tmp_path / "m.csv")
    header = (tmp_path / "m.csv").read_text().splitlines()[0].split(",")
    assert [f"{c} [{df.attrs['units'][c]}]" for c in df.columns] == header[1:]
    assert df.columns[-3:].tolist() == ["sigma_w_x", "sigma_w_y", "sigma_w_z"]
    assert "q_w" in df.columns and df.attrs["units"]["w_x"] == "rad s^-1"
    back = Motion.from_dataframe(df)
    np.testing.assert_array_equal(back.timestamps_ns, motion.timestamps_ns)
    for name in motion.available():
        np.testing.assert_array_equal(getattr(back, name), getattr(motion, name))
    np.testing.assert_array_equal(back.sigma["omega_b_radps"], motion.sigma["omega_b_radps"])
    assert back.available() == motion.available() and set(back.sigma) == {"omega_b_radps"}
    with pytest.raises(ValueError, match="column 'dw_y' is missing"):
        Motion.from_dataframe(df.drop(columns="dw_y"))
    # only what is present: an estimate of ω alone gives three columns
    only = Motion(motion.timestamps_ns, omega_b_radps=motion.omega_b_radps).to_dataframe()
    assert only.columns.tolist() == ["w_x", "w_y", "w_z"]


def test_a_missing_pandas_is_named_with_its_extra(log, monkeypatch):
    import builtins

    real = builtins.__import__

    def no_pandas(name, *args, **kwargs):
        if name == "pandas":
            raise ImportError("no pandas")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_pandas)
    with pytest.raises(MissingExtraError, match=r"Log.to_dataframe needs pandas.*gfimu\[pandas\]"):
        log.to_dataframe()
    with pytest.raises(MissingExtraError, match=r"Motion.to_dataframe needs pandas"):
        log.truth.to_dataframe()


def test_a_datetime_index_is_read_as_nanoseconds_since_the_epoch(log):
    """A DatetimeIndex (as pandas.to_datetime(df["time"], unit="ns") makes) is ns since the epoch; with a
    time zone, the same instant in UTC; a missing time (NaT) is refused by row."""
    df = log.to_dataframe()
    t0 = 1_700_000_000_123_456_789
    naive = df.set_index(pd.to_datetime(df.index.to_numpy() + t0, unit="ns"))
    back = Log.from_dataframe(naive, log.array)
    np.testing.assert_array_equal(back.timestamps_ns, log.timestamps_ns + t0)
    np.testing.assert_array_equal(back.accel_mps2, log.accel_mps2)
    zoned = naive.tz_localize("UTC").tz_convert("Europe/Berlin")
    np.testing.assert_array_equal(Log.from_dataframe(zoned, log.array).timestamps_ns, log.timestamps_ns + t0)
    micro = naive.set_index(naive.index.as_unit("us"))  # coarser storage: the same instants, truncated to us
    np.testing.assert_array_equal(Log.from_dataframe(micro, log.array).timestamps_ns,
                                  (log.timestamps_ns + t0) // 1000 * 1000)
    motion = log.truth.to_dataframe()
    motion = motion.set_index(pd.to_datetime(motion.index.to_numpy() + t0, unit="ns"))
    np.testing.assert_array_equal(Motion.from_dataframe(motion).timestamps_ns, log.truth.timestamps_ns + t0)
    with_nat = naive.index.to_numpy().copy()
    with_nat[3] = np.datetime64("NaT")
    with pytest.raises(ValueError, match="missing time \\(NaT\\) at row 3"):
        Log.from_dataframe(naive.set_index(pd.DatetimeIndex(with_nat)), log.array)
