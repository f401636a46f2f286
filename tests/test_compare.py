"""Comparison table: numbers against gfimu.evaluation, bounds, failures, formats, CLI."""

from __future__ import annotations

import json
import math
import sys
import types

import numpy as np
import pytest

from gfimu.array import cube_array, single_triad
from gfimu.compare import (
    COLUMNS,
    ComparisonResult,
    compare,
    condition_vs_scale,
    metrics_from_evaluation,
    t2_band,
)
from gfimu.estimate import Estimate, Report
from gfimu.evaluation import evaluate
from gfimu.simulate import SensorErrors, simulate


@pytest.fixture(scope="module")
def noisy_log():
    return simulate("random3d", array=cube_array(0.05, noise_std_mps2=0.07), duration_s=1.0, seed=3)


@pytest.fixture(scope="module")
def noisy_result(noisy_log):
    return compare(noisy_log, methods=["inversion", "imm", "gyro-aided", "free-flight"], bounds=["crb", "crb_gyro"],
                   gyro_noise_std_radps=0.01)


def _same(a, b) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, rel=1e-12, abs=0)
    return a == b


def test_rows_match_evaluate_run_directly(noisy_log, noisy_result):
    r = noisy_result.row("inversion")
    assert r["status"] == "ok" and r["reason"] == ""
    ev = evaluate(noisy_result.estimates["inversion"], noisy_log.truth)
    w, dw, f = ev["omega_b_radps"], ev["omega_dot_b_radps2"], ev["specific_force_b_mps2"]
    assert [r["w_rmse_x"], r["w_rmse_y"], r["w_rmse_z"]] == list(w.rmse)
    assert r["w_rmse_norm"] == w.rmse_norm
    assert [r["dw_rel_rms_x"], r["dw_rel_rms_y"], r["dw_rel_rms_z"]] == list(dw.relative_rms)
    assert r["f_rmse_norm"] == f.rmse_norm
    assert r["w_axis_sign_off_share"] == w.signs.axis_sign_off_share
    assert r["w_off_5radps_share"] == w.signs.large_error_share
    assert r["n_evaluated"] == len(noisy_log)
    # the linear inversion with σ = 0.07 m/s² on every axis: f error ≈ σ/2 per axis (4 triads)
    assert r["f_rmse_x"] == pytest.approx(0.035, rel=0.15)
    assert r["time_s"] > 0 and r["samples_per_s"] == pytest.approx(len(noisy_log) / r["time_s"])


def test_non_applicable_methods_get_their_reason(noisy_result):
    gyro = noisy_result.row("gyro-aided")
    assert gyro["status"] == "not applicable" and "gyroscope" in gyro["reason"]
    assert math.isnan(gyro["w_rmse_norm"])
    ff = noisy_result.row("free-flight")
    assert ff["status"] == "not applicable" and "body" in ff["reason"]
    md = noisy_result.to_markdown()
    assert "**gyro-aided** (not applicable)" in md and gyro["reason"] in md


def test_crb_rows_and_ratios(noisy_log, noisy_result):
    crb = noisy_result.row("CRB (accelerometers)")
    assert crb["kind"] == "bound" and crb["status"] == "ok"
    # symmetric cube (Σ r = 0): f decouples from ω̇ and ω, its bound is σ/2 per axis exactly
    for a in "xyz":
        assert crb[f"f_rmse_{a}"] == pytest.approx(0.07 / 2, rel=1e-9)
    assert crb["f_rmse_norm"] == pytest.approx(0.07 / 2 * math.sqrt(3), rel=1e-9)
    gyro = noisy_result.row("CRB (with gyro)")
    # a gyro of 0.01 rad/s can only lower the bound on ω, and not below its own noise
    assert gyro["w_rmse_norm"] < crb["w_rmse_norm"]
    assert gyro["w_rmse_norm"] <= 0.01 * math.sqrt(3) + 1e-12
    inv = noisy_result.row("inversion")
    assert inv["w_rmse_norm_over_crb"] == pytest.approx(inv["w_rmse_norm"] / crb["w_rmse_norm"])
    assert inv["f_rmse_norm_over_crb_gyro"] == pytest.approx(inv["f_rmse_norm"] / gyro["f_rmse_norm"])
    # the unbiased per-sample inversion of f is efficient: ratio near 1
    assert inv["f_rmse_norm_over_crb"] == pytest.approx(1.0, abs=0.15)


def test_noise_free_inversion_is_exact_and_crb_without_gyro_is_not_applicable():
    log = simulate("random3d", array=cube_array(0.05), duration_s=0.5, noise=SensorErrors.none(), seed=1)
    res = compare(log, methods=["inversion"], bounds=["crb_gyro"])
    r = res.row("inversion")
    assert r["f_rmse_norm"] < 1e-9 and r["dw_rmse_norm"] < 1e-7
    b = res.row("CRB (with gyro)")
    assert b["status"] == "not applicable" and "gyroscope" in b["reason"]
    assert math.isnan(r["w_rmse_norm_over_crb_gyro"])


def test_failing_and_unknown_methods_do_not_stop_the_table(monkeypatch, noisy_log):
    from gfimu.methods import METHODS

    module = types.ModuleType("gfimu_broken_method")

    class Broken:
        def applicable(self, array):
            return None

        def estimate(self, log, progress=False):
            raise RuntimeError("diverged at sample 7")

    class Short:
        def applicable(self, array):
            return None

        def estimate(self, log, progress=False):
            return Estimate(noisy_log.truth.select(slice(0, 10)), Report("short"))

    module.Broken, module.Short = Broken, Short
    monkeypatch.setitem(sys.modules, "gfimu_broken_method", module)
    monkeypatch.setitem(METHODS, "broken", "gfimu_broken_method:Broken")
    monkeypatch.setitem(METHODS, "short", "gfimu_broken_method:Short")
    monkeypatch.setitem(METHODS, "missing", "gfimu_no_such_module:Nothing")
    res = compare(noisy_log, methods=["broken", "short", "missing", "nonexistent", "inversion"], bounds=False)
    assert res.row("broken")["status"] == "failed" and "diverged at sample 7" in res.row("broken")["reason"]
    assert res.row("short")["status"] == "failed" and "10 rows" in res.row("short")["reason"]
    assert res.row("missing")["status"] == "unavailable"
    assert res.row("nonexistent")["status"] == "unknown"
    assert res.row("inversion")["status"] == "ok"
    assert [r["method"] for r in res.rows] == ["broken", "short", "missing", "nonexistent", "inversion"]


def test_reference_with_invalid_rows(noisy_log):
    truth = noisy_log.truth
    rng = np.random.default_rng(0)
    w_ref = truth.omega_b_radps + 0.01 * rng.standard_normal(truth.omega_b_radps.shape)
    invalid = np.zeros(len(truth), bool)
    invalid[100:150] = True
    w_ref[invalid] = 40.0  # saturated gyro: must not count
    reference = truth.replace(omega_b_radps=w_ref, accel_b_mps2=None, quaternion_wb=None)
    log = noisy_log.replace(truth=None, reference=reference, invalid_reference=invalid)
    res = compare(log, methods=["inversion"])
    assert res.against == "reference"
    r = res.row("inversion")
    ev = evaluate(res.estimates["inversion"], reference, valid=~invalid)
    assert r["w_rmse_norm"] == ev["omega_b_radps"].rmse_norm
    assert r["n_evaluated"] == len(log) - 50
    assert r["w_rmse_norm"] < 20
    assert {row["status"] for row in res.rows if row["kind"] == "bound"} == {"not applicable"}


def test_log_without_truth_or_reference_is_an_error(noisy_log):
    with pytest.raises(ValueError, match="neither truth.csv nor reference.csv"):
        compare(noisy_log.replace(truth=None), methods=["inversion"])
    with pytest.raises(ValueError, match="options given for methods not compared"):
        compare(noisy_log, methods=["inversion"], options={"imm": {"t2": 3.0}})


def test_formats_round_trip(noisy_result):
    for parsed in (ComparisonResult.from_csv(noisy_result.to_csv()), ComparisonResult.from_json(noisy_result.to_json())):
        assert len(parsed.rows) == len(noisy_result.rows)
        for a, b in zip(parsed.rows, noisy_result.rows):
            assert set(a) == set(COLUMNS)
            bad = [c for c in COLUMNS if not _same(a[c], b[c])]
            assert not bad, bad
    doc = json.loads(noisy_result.to_json())
    assert doc["n_samples"] == noisy_result.n_samples and doc["columns"] == COLUMNS
    md = noisy_result.to_markdown()
    inv = noisy_result.row("inversion")
    assert f"| inversion | " in md and f"{inv['f_rmse_x']:.4g}" in md


def test_metrics_from_evaluation_handles_missing_quantities(noisy_log):
    est = noisy_log.truth.replace(omega_dot_b_radps2=None, specific_force_b_mps2=None, accel_b_mps2=None,
                                  quaternion_wb=None)
    m = metrics_from_evaluation(evaluate(est, noisy_log.truth))
    assert m["w_rmse_norm"] == 0.0 and m["w_axis_sign_off_share"] == 0.0
    assert "dw_rmse_norm" not in m and "f_rmse_x" not in m


def test_condition_number_against_size_matches_paper_000():
    sizes = np.array([0.1, 1.0, 10.0])
    cond = condition_vs_scale(cube_array(0.05), sizes)
    np.testing.assert_allclose(cond, [10.0, math.sqrt(2), 10 * math.sqrt(2)], rtol=1e-12)
    with pytest.raises(ValueError, match="at the origin"):
        condition_vs_scale(single_triad(), sizes)


def test_t2_band():
    t2 = np.arange(1.0, 11.0)
    rmse = np.array([5.0, 3.0, 1.15, 1.05, 1.0, 1.1, 1.19, 1.3, 1.1, 2.0])
    best, lo, hi = t2_band(t2, rmse, tolerance=0.2)
    assert (best, lo, hi) == (5.0, 3.0, 7.0)


def test_cli_compare_json(tmp_path, noisy_log):
    from gfimu.cli import main
    from gfimu.io import write_log

    write_log(noisy_log, tmp_path / "log")
    out = tmp_path / "table.json"
    code = main(["compare", str(tmp_path / "log"), "--methods", "inversion,imm", "-O", "imm.t2=4.0",
                 "--format", "json", "--out", str(out), "--no-bounds", "--estimates-dir", str(tmp_path / "est")])
    assert code == 0
    doc = json.loads(out.read_text())
    assert [r["method"] for r in doc["rows"]] == ["inversion", "imm"]
    assert (tmp_path / "est" / "imm.csv").is_file()
    direct = compare(noisy_log, methods=["imm"], options={"imm": {"t2": 4.0}}, bounds=False).row("imm")
    assert doc["rows"][1]["w_rmse_norm"] == pytest.approx(direct["w_rmse_norm"], rel=1e-9)
    assert main(["compare", str(tmp_path / "log"), "--methods", "nope"]) == 2
    assert main(["compare", str(tmp_path / "log"), "--methods", "inversion", "-O", "imm.t2=4"]) == 2


def test_motion_level_and_t2_sweep():
    from gfimu.compare import motion_level, omega_rmse_sum, t2_sweep
    from gfimu.methods import make_estimator

    log = simulate("random3d", array=cube_array(0.05), duration_s=1.0, noise=SensorErrors.none(), seed=4)
    # a + b + c = (ωx²+ωy²) + (ωx²+ωz²) + (ωy²+ωz²) = 2|ω|², recovered exactly without noise
    assert motion_level(log) == pytest.approx(np.mean(2 * np.sum(log.truth.omega_b_radps**2, axis=1)), rel=1e-9)
    noisy = simulate("random3d", array=cube_array(0.05, 0.07), duration_s=1.0, seed=4)
    t2 = [1.0, 6.0]
    curve = t2_sweep(noisy, t2)
    for value, t in zip(curve, t2):
        direct = make_estimator("imm", t2=t).estimate(noisy).motion
        err = direct.omega_b_radps - noisy.truth.omega_b_radps
        assert value == pytest.approx(np.sum(np.sqrt(np.mean(err**2, axis=0))), rel=1e-12)
        assert value == pytest.approx(omega_rmse_sum(direct, noisy.truth), rel=1e-12)


def test_smoother_bound_uses_the_process_noise_the_smoother_chose():
    from gfimu.smoother.batch.engine import BatchSmootherEstimator
    from gfimu.smoother.batch.bound import smoother_bound
    from gfimu.smoother.model.problem import SmootherOptions

    log = simulate("turntable", array=cube_array(0.025, noise_std_mps2=0.07), rate_hz=500.0, duration_s=3.0, seed=2)
    result = compare(log, methods=["smoother"], bounds=["smoother_bound"])
    row, bound = result.row("smoother"), result.row("smoother bound")
    est = BatchSmootherEstimator()
    report = est.estimate(log).report
    tuned = smoother_bound(log, est.model_groups, est.batch, log.truth,
                           window_models=[t.apply(est.model_groups) for t in report.tunings]).sigma["omega_b_radps"]
    assert bound["w_rmse_norm"] == pytest.approx(np.sqrt(np.mean(np.sum(tuned**2, axis=1))), rel=1e-9)
    # on the smooth turntable the chosen noise is far below the default, and so is the bound
    default = smoother_bound(log, truth=log.truth).sigma["omega_b_radps"]
    assert np.sqrt(np.mean(np.sum(default**2, axis=1))) > 1.3 * bound["w_rmse_norm"]
    assert row["w_rmse_norm_over_smoother_bound"] == pytest.approx(row["w_rmse_norm"] / bound["w_rmse_norm"])
