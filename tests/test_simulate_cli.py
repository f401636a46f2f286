"""``gfimu simulate``: written logs round-trip and match the library."""

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.array import paper001_array
from gfimu.cli import main
from gfimu.simulate import SensorErrors, simulate


def test_cli_writes_a_log_equal_to_the_library_result(tmp_path, capsys):
    out = tmp_path / "rev"
    assert main(["simulate", "reversal", "--out", str(out), "--duration-s", "1", "--rate-hz", "200",
                 "--no-noise", "--no-progress"]) == 0
    assert "200 samples" in capsys.readouterr().out
    log = gio.read_log(out)
    ref = simulate("reversal", duration_s=1.0, rate_hz=200.0, noise=SensorErrors.none())
    np.testing.assert_array_equal(log.timestamps_ns, ref.timestamps_ns)
    np.testing.assert_allclose(log.accel_mps2, ref.accel_mps2, rtol=1e-15)
    for name in ref.truth.available():
        np.testing.assert_allclose(getattr(log.truth, name), getattr(ref.truth, name), rtol=1e-15, atol=1e-300)
    assert gio.format_array_toml(log.array) == gio.format_array_toml(ref.array)


def test_cli_array_choices_options_and_noise(tmp_path):
    out = tmp_path / "tt"
    assert main(["simulate", "turntable", "--out", str(out), "--array", "paper001", "--duration-s", "2",
                 "--noise-std-mps2", "0.1", "--seed", "4", "-O", "amplitude_deg=10", "--no-progress"]) == 0
    log = gio.read_log(out)
    assert log.array.n_axes == 6 and log.gyro_b_radps is not None and log.tilt_rad is not None
    np.testing.assert_array_equal(log.array.noise_std_per_axis_mps2, 0.1)
    exact = paper001_array().predict_readings(log.truth.specific_force_b_mps2, log.truth.omega_dot_b_radps2,
                                              log.truth.omega_b_radps)
    assert (log.accel_mps2 - exact).std() == pytest.approx(0.1, rel=0.05)
    assert np.abs(log.truth.omega_b_radps[:, 2]).max() == pytest.approx(np.radians(10) * 2 * np.pi, rel=1e-6)
    # an array.toml as --array, and the cube size
    out2 = tmp_path / "again"
    assert main(["simulate", "random3d", "--out", str(out2), "--array", str(out / "array.toml"),
                 "--duration-s", "0.5", "--no-progress"]) == 0
    assert gio.format_array_toml(gio.read_log(out2).array) == gio.format_array_toml(log.array)
    out3 = tmp_path / "cube"
    assert main(["simulate", "random3d", "--out", str(out3), "--half-edge-m", "0.1", "--duration-s", "0.5",
                 "--no-progress"]) == 0
    np.testing.assert_allclose(np.abs(gio.read_log(out3).array.axis_positions_m), 0.1)


@pytest.mark.parametrize("argv,message", [
    (["random3d", "--array", "nonexistent.toml"], "no such file"),
    (["random3d", "--no-noise", "--noise-std-mps2", "0.1"], "exclude"),
    (["random3d", "-O", "spin=3"], "no option"),
    (["random3d", "--duration-s", "-1"], "--duration-s"),
    (["random3d", "--array", "paper001", "--half-edge-m", "0.1"], "cube only"),
    (["random3d", "--duration-s", "0.001", "--rate-hz", "500"], "a duration of 0.001 s at 500 Hz gives 0 sample(s)"),
])
def test_cli_user_errors_exit_2_with_one_line(tmp_path, capsys, argv, message):
    assert main(["simulate", *argv, "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err and not (tmp_path / "x").exists()
