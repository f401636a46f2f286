"""Named smoother settings (gfimu.smoother.model.presets): values, precedence, errors, CLI and the real recording."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.array import mimu4444_array
from gfimu.cli import main
from gfimu.methods import make_estimator
from gfimu.simulate import simulate
from gfimu.smoother.batch.engine import BatchSmootherEstimator
from gfimu.smoother.model.presets import PRESETS, apply_preset, expand_preset

HAND_HELD = {"initialisation": "ml", "ml_sign_chain": True, "tune_process_noise": False,
             "omega_dot_random_walk_radps2_per_sqrt_s": 3000.0, "specific_force_random_walk_mps2_per_sqrt_s": 300.0,
             "accel_noise_slope_mps2_per_radps": 0.03, "robust_loss": "cauchy", "accel_robust_threshold": 2.0,
             "process_robust_threshold": 2.0, "reweight_iterations": 5}
"""The settings of tools/mimu4444_study.py chosen on the first MIMU4444 recording, written out."""

EXPLICIT_CLI = ["-O", "initialisation=ml", "-O", "ml_sign_chain=True", "-O", "tune_process_noise=False",
                "-O", "omega_dot_random_walk_radps2_per_sqrt_s=3000", "-O", "specific_force_random_walk_mps2_per_sqrt_s=300",
                "-O", "accel_noise_slope_mps2_per_radps=0.03", "-O", "robust_loss=cauchy", "-O", "accel_robust_threshold=2",
                "-O", "process_robust_threshold=2", "-O", "reweight_iterations=5"]


def test_hand_held_preset_holds_exactly_the_study_settings():
    description, overrides = PRESETS["hand-held-low-rate"]
    assert "hand-held" in description and "Hz" in description
    assert overrides == HAND_HELD
    est = make_estimator("smoother", preset="hand-held-low-rate")
    assert isinstance(est, BatchSmootherEstimator)
    defaults = BatchSmootherEstimator()
    for f in dataclasses.fields(BatchSmootherEstimator):
        expected = HAND_HELD.get(f.name, getattr(defaults, f.name))
        assert getattr(est, f.name) == expected, f.name
    # the preset changes every one of its options away from the method's defaults
    assert all(getattr(defaults, k) != v for k, v in HAND_HELD.items())


def test_explicit_options_win_over_the_preset():
    opts = apply_preset("hand-held-low-rate", {"reweight_iterations": 3, "compute_sigma": True})
    assert opts == {**HAND_HELD, "reweight_iterations": 3, "compute_sigma": True}
    est = make_estimator("smoother", preset="hand-held-low-rate", accel_robust_threshold=0.0, window_s=20.0)
    assert est.accel_robust_threshold == 0.0 and est.window_s == 20.0
    assert est.process_robust_threshold == 2.0 and est.omega_dot_random_walk_radps2_per_sqrt_s == 3000.0
    # the preset's dict is not changed by an application
    assert PRESETS["hand-held-low-rate"][1] == HAND_HELD
    assert expand_preset("smoother", {"window_s": 10.0}) == {"window_s": 10.0}


def test_unknown_preset_or_method_is_refused_by_name():
    with pytest.raises(ValueError, match=r"unknown smoother preset 'fast'.*hand-held-low-rate"):
        apply_preset("fast", {})
    with pytest.raises(ValueError, match=r"unknown smoother preset 'fast'.*hand-held-low-rate"):
        make_estimator("smoother", preset="fast")
    with pytest.raises(ValueError, match=r"presets apply to .*smoother.*not 'ml'"):
        make_estimator("ml", preset="hand-held-low-rate")
    with pytest.raises(ValueError, match="no option"):  # options are still checked by name
        make_estimator("smoother", preset="hand-held-low-rate", jerk=1.0)


@pytest.fixture(scope="module")
def hand_log_dir(tmp_path_factory):
    """4 s of a fast reversal seen by the MIMU4444 layout at 62.5 Hz, written as a log."""
    log = simulate("reversal", array=mimu4444_array(), rate_hz=62.5, duration_s=4.0, seed=2)
    out = tmp_path_factory.mktemp("hand") / "log"
    gio.write_log(log, out)
    return out


def test_cli_estimate_preset_equals_explicit_options(hand_log_dir, tmp_path, capsys):
    a, b, c = tmp_path / "preset.csv", tmp_path / "explicit.csv", tmp_path / "default.csv"
    base = ["estimate", str(hand_log_dir), "--method", "smoother", "--no-progress"]
    assert main(base + ["--preset", "hand-held-low-rate", "--out", str(a)]) == 0
    assert main(base + EXPLICIT_CLI + ["--out", str(b)]) == 0
    assert main(base + ["--out", str(c)]) == 0
    pa, pb, pc = (gio.read_motion_csv(p) for p in (a, b, c))
    np.testing.assert_array_equal(pa.omega_b_radps, pb.omega_b_radps)
    np.testing.assert_array_equal(pa.specific_force_b_mps2, pb.specific_force_b_mps2)
    assert np.max(np.abs(pa.omega_b_radps - pc.omega_b_radps)) > 1e-3  # the preset is not the default
    # -O wins over --preset
    d = tmp_path / "override.csv"
    assert main(base + ["--preset", "hand-held-low-rate", "-O", "reweight_iterations=1", "--out", str(d)]) == 0
    e = tmp_path / "override_explicit.csv"
    assert main(base + EXPLICIT_CLI + ["-O", "reweight_iterations=1", "--out", str(e)]) == 0
    np.testing.assert_array_equal(gio.read_motion_csv(d).omega_b_radps, gio.read_motion_csv(e).omega_b_radps)
    assert np.max(np.abs(gio.read_motion_csv(d).omega_b_radps - pa.omega_b_radps)) > 0


def test_cli_compare_applies_the_preset_to_the_smoother(hand_log_dir, tmp_path):
    out = tmp_path / "table.json"
    assert main(["compare", str(hand_log_dir), "--methods", "smoother,ml", "--preset", "hand-held-low-rate",
                 "--no-bounds", "--format", "json", "--out", str(out), "--estimates-dir", str(tmp_path / "est")]) == 0
    est = gio.read_motion_csv(tmp_path / "est" / "smoother.csv")
    from gfimu.readings import screen_log

    log, _ = screen_log(gio.read_log(hand_log_dir))  # the command replaces gross reading errors first
    direct = make_estimator("smoother", **HAND_HELD).estimate(log).motion
    np.testing.assert_allclose(est.omega_b_radps, direct.omega_b_radps, rtol=0, atol=1e-9)


@pytest.mark.parametrize("argv", [
    ["estimate", "{log}", "--method", "smoother", "--preset", "fast", "--out", "{tmp}/x.csv"],
    ["compare", "{log}", "--methods", "smoother", "--preset", "fast"],
])
def test_cli_unknown_preset_exits_2_naming_the_presets(argv, hand_log_dir, tmp_path, capsys):
    argv = [a.format(log=hand_log_dir, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "unknown smoother preset 'fast'" in err and "hand-held-low-rate" in err
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize("argv, message", [
    (["estimate", "{log}", "--method", "ml", "--preset", "hand-held-low-rate", "--out", "{tmp}/x.csv"],
     "--preset applies to --method smoother only"),
    (["compare", "{log}", "--methods", "ml,inversion", "--preset", "hand-held-low-rate"],
     "smoother is not among --methods"),
])
def test_cli_preset_for_another_method_exits_2(argv, message, hand_log_dir, tmp_path, capsys):
    argv = [a.format(log=hand_log_dir, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


@pytest.mark.slow
def test_preset_reproduces_the_explicit_settings_on_the_real_recording(mimu4444_dir):
    """Busiest 40 s of exp_1 (own calibration, reference shifted by -1.5 ms): the preset gives the
    estimate of the explicit settings bit for bit, at the measured accuracy of those settings."""
    from test_smoother_real import busiest_part, scores

    part, mask = busiest_part(mimu4444_dir, 1)
    preset = make_estimator("smoother", preset="hand-held-low-rate").estimate(part).motion
    explicit = BatchSmootherEstimator(**HAND_HELD).estimate(part).motion
    np.testing.assert_array_equal(preset.omega_b_radps, explicit.omega_b_radps)
    np.testing.assert_array_equal(preset.omega_dot_b_radps2, explicit.omega_dot_b_radps2)
    rmse, opposite = scores(preset, part, mask)
    print(f"exp_1 busiest 40 s: {mask.sum()} moving samples, ω RMSE {rmse:.3f} rad/s, {opposite:.2%} opposite")
    assert mask.sum() > 1500
    assert rmse < 3.3 and opposite < 0.01  # measured 3.09 rad/s, 0.15 %


def _study():
    import importlib
    import sys
    from pathlib import Path

    tools = str(Path(__file__).resolve().parents[1] / "tools")
    if tools not in sys.path:
        sys.path.insert(0, tools)
    return importlib.import_module("mimu4444_study")


def test_study_bound_at_the_reference_is_the_smoother_bound_plus_the_noise_slope():
    """tools/mimu4444_study.py --bound: with no slope it is gfimu.smoother.batch.bound at the same trajectory;
    the preset's noise slope raises it."""
    from gfimu.smoother.batch.bound import smoother_bound
    from gfimu.smoother.model.problem import SmootherOptions

    study = _study()
    log = simulate("reversal", array=mimu4444_array(), rate_hz=62.5, duration_s=4.0, seed=2)
    log = log.replace(reference=log.truth, invalid_reference=np.zeros(len(log), bool))
    mask = np.ones(len(log), bool)
    flat = {**HAND_HELD, "accel_noise_slope_mps2_per_radps": 0.0}
    got = study.reference_bound(log, flat, mask)
    keys = {f.name for f in dataclasses.fields(SmootherOptions)}
    bound_options = SmootherOptions(**{k: v for k, v in flat.items() if k in keys})
    sd = smoother_bound(log, bound_options.model_groups, bound_options.batch).sigma["omega_b_radps"]
    assert got["rms_bound_norm"] == pytest.approx(float(np.sqrt(np.mean(np.sum(sd**2, axis=1)))), rel=1e-9)
    sloped = study.reference_bound(log, HAND_HELD, mask)
    assert sloped["rms_bound_norm"] > 1.05 * got["rms_bound_norm"]


def test_study_start_at_reference_changes_only_the_initial_omega():
    """--start-at-reference: the smoother's initial ω is the reference's (at valid samples), ω̇ and f
    those of its own initialisation, given to the smoother as its ``initial`` (nothing patched)."""
    from gfimu.smoother.solve.initialise import initial_estimate

    study = _study()
    log = simulate("reversal", array=mimu4444_array(), rate_hz=62.5, duration_s=2.0, seed=4)
    invalid = np.zeros(len(log), bool)
    invalid[40:45] = True
    log = log.replace(reference=log.truth, invalid_reference=invalid)
    opt = make_estimator("smoother", preset="hand-held-low-rate")
    own = initial_estimate(log, opt.model_groups)
    x = study.started_at_reference(log, opt.model_groups)
    np.testing.assert_array_equal(x[~invalid, 0:3], log.truth.omega_b_radps[~invalid])
    np.testing.assert_array_equal(np.abs(x[invalid, 0:3]), np.abs(own[invalid, 0:3]))
    assert np.all(np.sum(x[invalid, 0:3] * log.truth.omega_b_radps[invalid], axis=1) >= 0)
    np.testing.assert_array_equal(x[:, 3:], own[:, 3:])
    np.testing.assert_array_equal(initial_estimate(log, opt.model_groups), own)


def test_preset_sign_chain_is_not_thrown_by_one_glitched_sample():
    """The preset's sign chain (gfimu.smoother.solve.initialise.sign_chain, Cauchy steps): humps of |ω| between
    5 and 40 rad/s at 62.5 Hz, per-sample signs 30 % flipped, noise 1 rad/s on ω and 50 rad/s² on ω̇, and
    at three peaks one sample with the reading spike seen on MIMU4444 exp_3 (ω̇ off by ~4700 rad/s² there
    and ~1600 at the next sample, ω in a wrong direction). The plain squares flip the run after each
    spike onto the wrong branch; the robust chain keeps every other sample on the right one."""
    from gfimu.smoother.solve.initialise import sign_chain

    h = 0.016
    t = np.arange(200) * h
    axis = np.array([-3.74, 33.3, -25.2]) / np.linalg.norm([-3.74, 33.3, -25.2])
    omega = (22.5 + 17.5 * np.cos(2 * np.pi * 2.5 * t))[:, None] * axis
    omega_dot = np.gradient(omega, t, axis=0)
    rng = np.random.default_rng(0)
    flips = np.where(rng.random(len(t)) < 0.3, -1.0, 1.0)
    given = omega * flips[:, None] + rng.normal(size=omega.shape)
    dw = omega_dot + 50.0 * rng.normal(size=omega.shape)
    spikes = np.array([50, 100, 150])  # peaks of |ω|
    dw[spikes] += [1436.0, 852.0, 4472.0]
    dw[spikes + 1] += [-1142.0, -1082.0, 256.0]
    given[spikes] = np.array([14.84, -27.61, -26.67]) * flips[spikes, None]
    keep = np.ones(len(t), bool)
    keep[spikes] = False

    def wrong(*scale):
        s = sign_chain(given, dw, np.full(len(t) - 1, h), *scale)
        return int(np.sum(np.sum(given[keep] * s[keep, None] * omega[keep], axis=1) < 0))

    assert wrong(None) > 30  # measured 41: a run of ~13 samples after each spike
    assert wrong() == 0  # the default, as the smoother calls it
    with pytest.raises(ValueError, match="robust_scale_radps"):
        sign_chain(given, dw, np.full(len(t) - 1, h), 0.0)
