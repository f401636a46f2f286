"""Evaluation metrics against hand-computed values, and the evaluate command."""

import contextlib
import csv
import io
import json
import math

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.array import cube_array
from gfimu.cli import main
from gfimu.evaluation import EvaluationAlignmentWarning, attitude_error, evaluate, evaluate_log, tilt_error
from gfimu.log import Log
from gfimu.motion import Motion
from gfimu.rotations import matrix_from_quaternion, quaternion_from_rotation_vector, quaternion_multiply

T = np.array([0, 10, 20, 30], dtype=np.int64)
W_TRUE = np.array([[1.0, 0, 0], [0, 2, 0], [0, 0, -3], [0.05, 1, 1]])
W_EST = np.array([[-1.0, 0, 0], [0, 2.5, 0], [0, 0, -3], [-0.05, 1, 7]])
# errors: [-2, 0, 0], [0, 0.5, 0], 0, [-0.1, 0, 6]


def hand_motions():
    return Motion(T, omega_b_radps=W_EST), Motion(T, omega_b_radps=W_TRUE)


def test_omega_metrics_by_hand():
    r = evaluate(*hand_motions())
    m = r["omega"]
    assert m.n == 4 and m.n_nonfinite == 0 and m.unit == "rad s^-1" and m.quantity == "omega_b_radps"
    assert m.rmse == pytest.approx((math.sqrt(4.01 / 4), math.sqrt(0.25 / 4), 3.0), rel=1e-15)
    assert m.rmse_norm == pytest.approx(math.sqrt((4 + 0.25 + 0 + 36.01) / 4), rel=1e-15)
    assert m.median_norm == pytest.approx(1.25, rel=1e-15)
    truth_rms = math.sqrt((1 + 4 + 9 + 2.0025) / 4)  # McGinnis, Perkins & King 2012, eq. (7) denominator
    assert m.relative_rms == pytest.approx(tuple(v / truth_rms for v in m.rmse), rel=1e-15)
    # eligible (|true| > 0.1): x of row 0; y of rows 1, 3; z of rows 2, 3. Only row 0's x is wrong.
    assert m.signs.axis_sign_off_share_axis == (1.0, 0.0, 0.0)
    assert m.signs.axis_sign_off_share == 0.25
    assert m.signs.large_error_share == 0.25  # row 3: |e| = 6.0008 > 5
    assert r.n_rows == r.n_compared == 4 and r.n_invalid == 0 and r.alignment == "exact"


def test_sign_threshold_and_zero_estimates():
    est, truth = hand_motions()
    m = evaluate(est, truth, sign_threshold_radps=0.01)["omega"]
    assert m.signs.axis_sign_off_share_axis == (1.0, 0.0, 0.0)  # x of rows 0 and 3 now eligible, both wrong
    assert m.signs.axis_sign_off_share == 0.5
    zero = Motion(T, omega_b_radps=np.zeros((4, 3)))
    m = evaluate(zero, truth)["omega"]
    assert m.signs.axis_sign_off_share_axis == (1.0, 1.0, 1.0) and m.signs.axis_sign_off_share == 1.0
    small = Motion(T, omega_b_radps=np.full((4, 3), 0.05))
    m = evaluate(small, small)["omega"]
    assert all(math.isnan(v) for v in m.signs.axis_sign_off_share_axis) and math.isnan(m.signs.axis_sign_off_share)


def test_flipped_share_counts_whole_vector_sign_errors():
    # dot products est·true: -1, 5, 9, -0.0025 + 1 + 7 > 0 -> only row 0 flipped
    m = evaluate(*hand_motions())["omega"]
    assert m.signs.flipped_share == 0.25
    est, truth = hand_motions()
    m = evaluate(Motion(T, omega_b_radps=-W_TRUE), truth)["omega"]
    assert m.signs.flipped_share == 1.0 and m.signs.axis_sign_off_share == 1.0
    # a small component with the wrong sign is not a flip
    m = evaluate(Motion(T, omega_b_radps=W_TRUE * [[-1, 1, 1]]), truth)["omega"]
    assert m.signs.flipped_share == 0.25  # row 0 is pure x; row 3's x is small, its vector keeps its sign
    rows = evaluate(*hand_motions()).rows
    assert rows[0]["flipped_share"] == 0.25


def test_valid_mask_and_nonfinite_rows_are_left_out_and_counted():
    est, truth = hand_motions()
    r = evaluate(est, truth, valid=np.array([True, True, True, False]))
    m = r["omega"]
    assert r.n_invalid == 1 and r.n_compared == 3 and m.n == 3
    assert m.rmse == pytest.approx((math.sqrt(4 / 3), math.sqrt(0.25 / 3), 0.0), rel=1e-15)
    assert m.signs.large_error_share == 0.0
    w = W_EST.copy()
    w[1, 2] = np.nan
    m = evaluate(Motion(T, omega_b_radps=w), truth)["omega"]
    assert m.n == 3 and m.n_nonfinite == 1
    assert m.rmse == pytest.approx((math.sqrt(4.01 / 3), 0.0, math.sqrt(12.0)), rel=1e-15)
    assert "rows with non-finite estimates left out (omega: 1)" in evaluate(Motion(T, omega_b_radps=w), truth).summary()
    with pytest.raises(ValueError, match=r"valid must be a boolean array of shape \(4,\)"):
        evaluate(est, truth, valid=np.array([1, 1, 1, 0]))


def test_every_common_vector_quantity_is_evaluated():
    rng = np.random.default_rng(3)
    n = 200
    truth = Motion(np.arange(n), rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.normal(size=(n, 3)),
                   rng.normal(size=(n, 3)))
    offset = np.array([0.3, -0.4, 1.2])
    est = Motion(np.arange(n), omega_dot_b_radps2=truth.omega_dot_b_radps2 + offset,
                 specific_force_b_mps2=truth.specific_force_b_mps2 - offset, accel_b_mps2=None)
    r = evaluate(est, truth)
    assert r.quantities == ["omega_dot", "specific_force"]
    for name in ("omega_dot", "specific_force"):
        m = r[name]
        assert m.rmse == pytest.approx(tuple(abs(offset)), rel=1e-12)
        assert m.rmse_norm == pytest.approx(1.3, rel=1e-12) and m.median_norm == pytest.approx(1.3, rel=1e-12)
        tv = getattr(truth, {"omega_dot": "omega_dot_b_radps2", "specific_force": "specific_force_b_mps2"}[name])
        assert m.relative_rms == pytest.approx(tuple(abs(offset) / np.sqrt(np.mean(np.sum(tv**2, axis=1)))), rel=1e-12)
        assert m.signs is None
    assert r["specific_force_b_mps2"] is r["specific_force"] is r["f"]
    assert "dw" in r and "omega" not in r
    with pytest.raises(KeyError, match="no metrics for 'omega'"):
        r["omega"]
    with pytest.raises(ValueError, match=r"no quantity in common: the estimate has \['omega_b_radps'\], the truth has "
                                         r"\['omega_dot_b_radps2', 'accel_b_mps2', 'specific_force_b_mps2'\]"):
        evaluate(Motion(np.arange(n), omega_b_radps=truth.omega_b_radps), truth.replace(omega_b_radps=None))


def test_attitude_and_tilt_errors():
    rng = np.random.default_rng(4)
    n = 50
    q_true = quaternion_from_rotation_vector(rng.normal(size=(n, 3)))
    yaw = quaternion_from_rotation_vector(np.array([0.0, 0.0, 0.1]))
    q_yawed = quaternion_multiply(yaw, q_true)  # rotated about the world vertical: tilt unchanged
    np.testing.assert_allclose(np.linalg.norm(attitude_error(q_yawed, q_true), axis=1), 0.1, rtol=1e-12)
    np.testing.assert_allclose(tilt_error(q_yawed, q_true), 0.0, atol=1e-12)
    body_x = quaternion_from_rotation_vector(np.array([0.2, 0.0, 0.0]))
    q_tilted = quaternion_multiply(q_true, body_x)  # rotated about body x
    np.testing.assert_allclose(attitude_error(q_tilted, q_true), np.tile([0.2, 0.0, 0.0], (n, 1)), atol=1e-12)
    up_b = matrix_from_quaternion(q_true)[:, 2, :]  # world z in B
    expected_tilt = np.arccos(np.clip(np.cos(0.2) + (1 - np.cos(0.2)) * up_b[:, 0] ** 2, -1, 1))
    np.testing.assert_allclose(tilt_error(q_tilted, q_true), expected_tilt, atol=1e-7)
    r = evaluate(Motion(np.arange(n), quaternion_wb=-q_tilted), Motion(np.arange(n), quaternion_wb=q_true))
    assert r.quantities == ["attitude", "tilt"]
    assert r["attitude"].rmse == pytest.approx((0.2, 0.0, 0.0), abs=1e-12)
    assert r["attitude"].rmse_norm == pytest.approx(0.2, rel=1e-12) and r["attitude"].relative_rms is None
    assert r["tilt"].rmse is None
    assert r["tilt"].rmse_norm == pytest.approx(math.sqrt(np.mean(expected_tilt**2)), abs=1e-7)


def test_timestamps_must_match_or_be_interpolated_explicitly():
    t_truth = np.arange(0, 101) * 1_000_000  # 1 kHz, 0..100 ms
    s = t_truth * 1e-9
    rate = np.array([0.5, -2.0, 3.0])
    truth = Motion(t_truth, omega_b_radps=np.column_stack([s, 2 * s, -s]) * 100,
                   quaternion_wb=quaternion_from_rotation_vector(np.outer(s, rate)))
    with pytest.raises(ValueError, match=r"the estimate has 3 rows, the truth 101\); they must be equal, or pass "
                                         r"align='interpolate'"):
        evaluate(Motion(t_truth[:3], omega_b_radps=np.zeros((3, 3))), truth)
    shifted = t_truth + 1
    with pytest.raises(ValueError, match=r"row 0 differs: estimate 1 ns, truth 0 ns"):
        evaluate(Motion(shifted, omega_b_radps=np.zeros((101, 3))), truth)
    t_est = np.arange(-2, 105) * 1_000_000 + 250_000  # 2 samples before and 5 after the truth's span
    se = t_est * 1e-9
    est = Motion(t_est, omega_b_radps=np.column_stack([se, 2 * se, -se]) * 100,
                 quaternion_wb=quaternion_from_rotation_vector(np.outer(se, rate)))
    valid = np.ones(101, bool)
    valid[50] = False
    with pytest.warns(EvaluationAlignmentWarning, match="interpolating the truth"):
        r = evaluate(est, truth, valid=valid, align="interpolate")
    assert r.alignment == "interpolated" and r.n_rows == 107 and r.n_outside == 7
    assert r.n_invalid == 2  # the estimate samples at 49.25 ms and 50.25 ms straddle the invalid truth sample
    assert r.n_compared == 98 and r["omega"].n == 98
    assert r["omega"].rmse_norm < 1e-12
    assert r["attitude"].rmse_norm < 1e-12  # constant-rate rotation: slerp is exact


def test_output_formats_carry_the_numbers():
    r = evaluate(*hand_motions())
    rows = list(csv.DictReader(io.StringIO(r.to_csv())))
    assert len(rows) == 1 and rows[0]["quantity"] == "omega_b_radps" and rows[0]["n_samples"] == "4"
    assert float(rows[0]["rmse_z"]) == 3.0 and float(rows[0]["rmse_x"]) == r["omega"].rmse[0]
    assert float(rows[0]["axis_sign_off_share"]) == 0.25 and float(rows[0]["share_off_5radps"]) == 0.25
    assert float(rows[0]["axis_sign_off_share_x"]) == 1.0 and rows[0]["axis_sign_off_share_y"] == "0.0"
    doc = json.loads(r.to_json())
    assert doc["n_compared"] == 4 and doc["quantities"][0]["median_norm"] == 1.25
    assert doc["quantities"][0]["relative_rms_z"] == pytest.approx(3.0 / math.sqrt(16.0025 / 4), rel=1e-15)
    assert "share_off_2radps" in evaluate(*hand_motions(), large_error_radps=2.0).rows[0]
    md = r.to_markdown(title="hand")
    assert md.startswith("### hand\n")
    assert "| omega | rad s^-1 | 4 | 1.001 | 0.25 | 3 | 3.173 | 1.25 | 50.1 % | 12.5 % | 150 % | 25 % | 25 % |" in md
    small = Motion(T, omega_b_radps=np.full((4, 3), 0.05))
    assert json.loads(evaluate(small, small).to_json())["quantities"][0]["axis_sign_off_share"] is None


def test_evaluate_log_uses_truth_else_reference_without_invalid_rows():
    array = cube_array()
    est, truth = hand_motions()
    log = Log(array, T, np.zeros((4, 12)), reference=truth, invalid_reference=np.array([False, False, False, True]))
    r = evaluate_log(est, log)
    assert r.n_invalid == 1 and r["omega"].rmse[2] == 0.0
    r = evaluate_log(est, log.replace(truth=truth))
    assert r.n_invalid == 0 and r["omega"].rmse[2] == 3.0


# --- command line -------------------------------------------------------------------

@pytest.fixture
def files(tmp_path):
    est, truth = hand_motions()
    log = Log(cube_array(), T, np.zeros((4, 12)), reference=truth, invalid_reference=np.array([False] * 3 + [True]))
    gio.write_log(log, tmp_path / "log")
    gio.write_motion_csv(est, tmp_path / "est.csv")
    gio.write_motion_csv(truth, tmp_path / "truth.csv")
    return tmp_path


def test_cli_markdown_against_a_truth_file(files, capsys):
    assert main(["evaluate", str(files / "est.csv"), str(files / "truth.csv")]) == 0
    out = capsys.readouterr().out
    assert "| omega | rad s^-1 | 4 | 1.001 | 0.25 | 3 | 3.173 | 1.25 |" in out
    assert "4 of 4 rows compared" in out


def test_cli_log_folder_uses_the_reference_valid_column(files, capsys):
    assert main(["evaluate", str(files / "est.csv"), str(files / "log"), "--format", "json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["n_invalid"] == 1 and doc["n_compared"] == 3
    assert doc["quantities"][0]["rmse_z"] == 0.0 and doc["quantities"][0]["share_off_5radps"] == 0.0


def test_cli_writes_csv_to_a_file(files, capsys):
    out = files / "eval.csv"
    assert main(["evaluate", str(files / "est.csv"), str(files / "truth.csv"), "--format", "csv", "--out", str(out)]) == 0
    assert str(out) in capsys.readouterr().out
    rows = list(csv.DictReader(out.open()))
    assert float(rows[0]["rmse_norm"]) == pytest.approx(math.sqrt(10.065), rel=1e-15)


def test_cli_errors_are_one_line_with_exit_status_2(files, capsys):
    gio.write_motion_csv(Motion(T + 5, omega_b_radps=W_EST), files / "late.csv")
    assert main(["evaluate", str(files / "late.csv"), str(files / "truth.csv")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"gfimu evaluate: error: {files / 'late.csv'} vs {files / 'truth.csv'}: estimate and truth "
                          "timestamps do not match (row 0 differs")
    assert "they must be equal, or give --interpolate to interpolate the truth" in err and err.count("\n") == 1
    assert "align=" not in err and "'interpolate'" not in err  # the option, not the Python keyword
    assert main(["evaluate", str(files / "late.csv"), str(files / "truth.csv"), "--interpolate"]) == 0
    assert "truth interpolated at the estimate's timestamps" in capsys.readouterr().out
    assert main(["evaluate", str(files / "est.csv"), str(files / "nothing")]) == 2
    err = capsys.readouterr().err
    assert "nothing: " in err and "not found" in err
    (files / "empty").mkdir()
    assert main(["evaluate", str(files / "est.csv"), str(files / "empty")]) == 2
    assert "log folder has no truth.csv or reference.csv" in capsys.readouterr().err



def test_cli_reference_first_moving_window_offset_and_errors(tmp_path, capsys):
    """Reference first (as evo), the older order still read the same; --moving-threshold-radps,
    --t-start-s/--t-end-s, --time-offset-s, --estimate-time-offset and --errors-out against a hand
    computation."""
    import csv as _csv_module

    t = np.arange(2000) * 2_000_000  # 500 Hz
    ts = t * 1e-9
    w_ref = np.column_stack([3.0 * np.sin(2 * np.pi * 0.7 * ts), 0.5 * np.cos(2 * np.pi * 0.3 * ts), 0.1 * ts])
    err = np.column_stack([0.1 * np.ones_like(ts), -0.2 * np.ones_like(ts), np.where(ts > 2.0, 0.3, 0.0)])
    gio.write_motion_csv(Motion(t, omega_b_radps=w_ref), tmp_path / "truth.csv")
    gio.write_motion_csv(Motion(t, omega_b_radps=w_ref + err), tmp_path / "est.csv")
    ref, est = str(tmp_path / "truth.csv"), str(tmp_path / "est.csv")

    def rmse_norm(args):
        assert main(["evaluate", *args, "--format", "json"]) == 0
        out = json.loads(capsys.readouterr().out)
        return next(r for r in out["quantities"] if r["quantity"] == "omega_b_radps")["rmse_norm"]

    moving = np.linalg.norm(w_ref, axis=1) > 1.0
    window = (ts >= 1.0) & (ts <= 3.0)
    expect = lambda m: float(np.sqrt(np.mean(np.sum(err[m] ** 2, axis=1))))  # noqa: E731
    assert rmse_norm([ref, est]) == pytest.approx(expect(np.ones(len(t), bool)), rel=1e-9)
    assert rmse_norm([est, ref]) == pytest.approx(expect(np.ones(len(t), bool)), rel=1e-9)  # older order
    assert rmse_norm([ref, est, "--moving-threshold-radps", "1"]) == pytest.approx(expect(moving), rel=1e-9)
    assert rmse_norm([ref, est, "--t-start-s", "1", "--t-end-s", "3"]) == pytest.approx(expect(window), rel=1e-9)
    # an estimate 20 ms late: shifted back by the given offset, or by the estimated one
    late = Motion(t + 20_000_000, omega_b_radps=w_ref)
    gio.write_motion_csv(late, tmp_path / "late.csv")
    assert rmse_norm([ref, str(tmp_path / "late.csv"), "--time-offset-s", "-0.02", "--t-start-s", "0.1",
                      "--t-end-s", "3.9"]) < 1e-9
    assert main(["evaluate", ref, str(tmp_path / "late.csv"), "--estimate-time-offset", "--t-start-s", "0.1",
                 "--t-end-s", "3.9", "--format", "json"]) == 0
    captured = capsys.readouterr()
    assert "shifted by -20.000 ms" in captured.err
    # per-sample errors
    errors = tmp_path / "errors.csv"
    assert main(["evaluate", ref, est, "--moving-threshold-radps", "1", "--errors-out", str(errors), "--out",
                 str(tmp_path / "table.md")]) == 0
    rows = list(_csv_module.reader(errors.open()))
    assert rows[0][0] == "#timestamp [ns]" and len(rows) == len(t) + 1
    table = np.array(rows[1:], dtype=float)
    np.testing.assert_allclose(table[:, 1:4], err, atol=1e-9)
    np.testing.assert_array_equal(table[:, 5] == 1, moving)
    # the two outputs on one file: refused before anything is written
    before = errors.read_bytes()
    assert main(["evaluate", ref, est, "--errors-out", str(errors), "--out", str(errors)]) == 2
    assert "--errors-out " + str(errors) + ": the same file as --out" in capsys.readouterr().err
    assert errors.read_bytes() == before


def test_cli_rows_left_out_by_the_selection_are_not_called_invalid_reference(tmp_path, capsys):
    """A log whose reference is invalid on 2 rows, evaluated with --moving-threshold-radps: the summary counts
    the invalid rows and the rows the threshold leaves out apart."""
    t = np.arange(10) * 10_000_000
    w = np.zeros((10, 3))
    w[:, 2] = [0, 0, 0, 3, 3, 3, 3, 3, 0, 0]
    ref = tmp_path / "reference.csv"
    lines = ["#timestamp [ns],w_x [rad s^-1],w_y [rad s^-1],w_z [rad s^-1],valid []"]
    lines += [f"{ti},0,0,{wz},{0 if k in (4, 5) else 1}" for k, (ti, wz) in enumerate(zip(t, w[:, 2]))]
    ref.write_text("\n".join(lines) + "\n")
    gio.write_motion_csv(Motion(t, omega_b_radps=w + 0.1), tmp_path / "est.csv")
    assert main(["evaluate", str(ref), str(tmp_path / "est.csv"), "--moving-threshold-radps", "1"]) == 0
    out = capsys.readouterr().out
    assert "3 of 10 rows compared; 2 left out as invalid reference; 5 left out by the selection." in out
    assert main(["evaluate", str(ref), str(tmp_path / "est.csv"), "--moving-threshold-radps", "1", "--format",
                 "json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert (doc["n_compared"], doc["n_invalid"], doc["n_deselected"]) == (3, 2, 5)
    assert main(["evaluate", str(ref), str(tmp_path / "est.csv")]) == 0
    assert "8 of 10 rows compared; 2 left out as invalid reference." in capsys.readouterr().out


def test_cli_calibration_removes_the_gyro_bias_from_the_reference(tmp_path, capsys):
    """An estimate made with --calibration has the gyro bias removed; evaluate --calibration removes it from the
    gyro reference too, so a bias-free estimate of the same motion scores 0 instead of the bias."""
    from gfimu.calibration import Calibration, SensorCalibration, write_calibration

    t = np.arange(5) * 10_000_000
    w = np.column_stack([np.linspace(0, 1, 5), np.ones(5), np.zeros(5)])
    bias = np.array([0.01, -0.02, 0.005])
    (tmp_path / "log").mkdir()
    gio.write_motion_csv(Motion(t, omega_b_radps=w + bias), tmp_path / "log" / "reference.csv")
    gio.write_motion_csv(Motion(t, omega_b_radps=w), tmp_path / "est.csv")
    sensor = SensorCalibration("a1", ("x", "y", "z"), np.eye(3), np.zeros(3))
    write_calibration(Calibration((sensor,), gyro_bias_b_radps=bias), tmp_path / "cal.toml")
    ref, est = str(tmp_path / "log" / "reference.csv"), str(tmp_path / "est.csv")
    assert main(["evaluate", ref, est, "--format", "json"]) == 0
    row = json.loads(capsys.readouterr().out)["quantities"][0]
    assert row["rmse_norm"] == pytest.approx(float(np.linalg.norm(bias)), rel=1e-9)
    assert main(["evaluate", ref, est, "--format", "json", "--calibration", str(tmp_path / "cal.toml")]) == 0
    row = json.loads(capsys.readouterr().out)["quantities"][0]
    assert row["rmse_norm"] < 1e-12
    assert main(["evaluate", ref, est, "--calibration", str(tmp_path / "cal.toml"), "--out",
                 str(tmp_path / "cal.toml")]) == 2
    assert "is an input of this command" in capsys.readouterr().err


def test_cli_warns_when_the_reference_is_the_logs_own_gyroscope(tmp_path, capsys):
    """A log whose gyroscope channels are its reference (convert --with-gyro / --gyro-as-reference): evaluate
    against it says once that it is no independent check; a log without gyro channels gets no warning."""
    from gfimu.simulate import simulate

    log = simulate("reversal", duration_s=0.2, seed=1)
    w = log.truth.omega_b_radps
    import dataclasses

    from gfimu.array import Gyroscope

    with_gyro = dataclasses.replace(log.array, gyroscope=Gyroscope())
    gio.write_log(log.replace(array=with_gyro, truth=None, gyro_b_radps=w,
                              reference=Motion(log.timestamps_ns, omega_b_radps=w)), tmp_path / "gyro")
    gio.write_motion_csv(Motion(log.timestamps_ns, omega_b_radps=w + 0.01), tmp_path / "est.csv")
    assert main(["evaluate", str(tmp_path / "gyro"), str(tmp_path / "est.csv"), "--format", "json"]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the reference is the log's own gyroscope" in err
    gio.write_log(log.replace(truth=None, reference=Motion(log.timestamps_ns, omega_b_radps=w)), tmp_path / "plain")
    assert main(["evaluate", str(tmp_path / "plain"), str(tmp_path / "est.csv"), "--format", "json"]) == 0
    assert capsys.readouterr().err == ""


def test_a_reference_that_is_the_logs_own_gyro_is_warned_about_with_advice_that_works(tmp_path, capsys):
    """evaluate warns when reference.csv is imu.csv's own gyroscope; the advice names options that exist and,
    followed (estimate -O use_gyro=False), gives an estimate that evaluates without the warning's cause."""
    import dataclasses

    from gfimu.array import Gyroscope
    from gfimu.simulate import simulate

    array = dataclasses.replace(cube_array(), gyroscope=Gyroscope(0.01))
    sim = simulate("random3d", array=array, seed=1, duration_s=2.0)
    log = sim.replace(truth=None, reference=Motion(sim.timestamps_ns, omega_b_radps=sim.gyro_b_radps.copy()))
    gio.write_log(log, tmp_path / "log")
    for extra in ([], ["-O", "use_gyro=False"]):
        assert main(["estimate", str(tmp_path / "log"), *extra, "--out", str(tmp_path / "est.csv"), "--quiet"]) == 0
        capsys.readouterr()
        assert main(["evaluate", str(tmp_path / "log"), str(tmp_path / "est.csv")]) == 0
        err = capsys.readouterr().err
        assert "the reference is the log's own gyroscope" in err
        assert "gfimu estimate -O use_gyro=False" in err and "convert mimu4444 or rosbag without --with-gyro" in err
        assert "convert without --with-gyro" not in err
    def help_text(*command: str) -> str:
        with contextlib.suppress(SystemExit):
            main(list(command))
        return capsys.readouterr().out

    assert "--with-gyro" in help_text("convert", "mimu4444", "--help")
    assert "--with-gyro" in help_text("convert", "rosbag", "--help")
    assert "--with-gyro" not in help_text("convert", "csv", "--help")
    assert "use_gyro" in help_text("estimate", "--method", "smoother", "--list-options")
    assert "use_gyro" in help_text("estimate", "--method", "ml", "--list-options")
