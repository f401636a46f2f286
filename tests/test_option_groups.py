"""The smoothers' options: declared once in their group dataclasses (gfimu.smoother.model.option_groups) with unit,
default and help; the flat classes assembled from the groups keep every flat name and give the groups back."""

from __future__ import annotations

from dataclasses import FrozenInstanceError, dataclass, fields, replace

import pytest

from gfimu.cli.options import method_options
from gfimu.errors import InputError
from gfimu.methods import make_estimator
from gfimu.option import Check
from gfimu.smoother.batch.engine import BatchSmootherEstimator
from gfimu.smoother.stream.fixed_lag import FixedLagEstimator
from gfimu.smoother.model.problem import SmootherOptions
from gfimu.smoother.model.option_groups import (GROUP_CLASSES, GROUPS, BatchOptions, ModelGroups, ModelOptions,
                                                StreamOptions, TuningOptions, assemble, groups_of)


def _names(*groups):
    return sorted(n for g in groups for n in GROUPS[g])


def test_every_declaration_carries_a_one_line_help_a_unit_and_its_check():
    seen = set()
    for group, cls in GROUP_CLASSES.items():
        for f in fields(cls):
            assert f.name not in seen, f.name  # each option in one group only
            seen.add(f.name)
            assert set(f.metadata) == {"unit", "help", "check"}, f.name
            assert isinstance(f.metadata["check"], Check), f.name  # and the default passes it
            assert f.metadata["check"].check(f.default, f.metadata["unit"]) == f.default, f.name
            assert f.metadata["help"] and "\n" not in f.metadata["help"], f.name
    f = {f.name: f for f in fields(ModelOptions)}["omega_dot_random_walk_radps2_per_sqrt_s"]
    assert (f.default, f.metadata["unit"]) == (30.0, "rad/s²/√s")
    f = {f.name: f for f in fields(BatchOptions)}["window_s"]
    assert (f.default, f.metadata["unit"]) == (30.0, "s")
    f = {f.name: f for f in fields(StreamOptions)}["relinearize_threshold"]
    assert (f.default, f.metadata["unit"]) == (0.1, "rad/s")


def test_each_group_is_small_and_the_model_s_groups_travel_together():
    # a group a reader holds in mind: the model, how a solve runs, the batch model, attitude, self-calibration...
    assert max(len(names) for names in GROUPS.values()) < 15, {g: len(n) for g, n in GROUPS.items()}
    opt = SmootherOptions(estimate_attitude=True, self_calibrate_bias=True, max_iterations=7, measurement="quadratic")
    groups = opt.model_groups
    assert groups._fields == ("model", "solve", "batch_model", "attitude", "self_calibration", "tuning")
    assert groups == ModelGroups.of(opt) and groups.solve.max_iterations == 7
    assert groups.attitude.estimate_attitude and groups.self_calibration.calibrates
    assert groups.batch_model.measurement == "quadratic"
    assert SmootherOptions.from_groups(*groups, opt.batch) == opt


def test_each_flat_class_has_exactly_its_groups_with_the_declared_metadata():
    batch = ("model", "solve", "batch_model", "attitude", "self_calibration", "batch", "tuning")
    assert sorted(f.name for f in fields(SmootherOptions)) == _names(*batch)
    assert sorted(f.name for f in fields(BatchSmootherEstimator)) == _names(*batch, "guard")
    assert sorted(f.name for f in fields(FixedLagEstimator)) == _names("model", "solve", "stream", "tuning", "guard")
    assert groups_of(FixedLagEstimator) == ("model", "solve", "stream", "tuning", "guard")
    for cls in (SmootherOptions, BatchSmootherEstimator, FixedLagEstimator):
        for f in fields(cls):
            declared = {d.name: d for d in fields(GROUP_CLASSES[f.metadata["group"]])}[f.name]
            assert dict(f.metadata) == {**declared.metadata, "group": f.metadata["group"]}, (cls, f.name)
            if f.name != "tune_process_noise":
                assert f.default == declared.default, (cls, f.name)
    # the one default the methods change: both estimators tune the process noise, the plain options do not
    assert SmootherOptions().tune_process_noise is False
    assert BatchSmootherEstimator().tune_process_noise is True and FixedLagEstimator().tune_process_noise is True


def test_flat_options_round_trip_through_their_groups():
    opt = SmootherOptions(motion_model="snap", window_s=10.0, tune_accel_noise=True, workers=2)
    assert opt.model.motion_model == "snap" and opt.batch.window_s == 10.0 and opt.tuning.tune_accel_noise is True
    assert isinstance(opt.batch, BatchOptions) and opt.batch.workers == 2
    assert SmootherOptions.from_groups(opt.model, opt.batch, opt.tuning) == opt
    assert SmootherOptions.from_groups(opt.model, opt.batch, opt.tuning, window_s=20.0) == replace(opt, window_s=20.0)
    attitude = SmootherOptions(estimate_attitude=True, initial_yaw_std_rad=0.5)
    assert attitude.attitude.estimate_attitude is True and attitude.attitude.initial_yaw_std_rad == 0.5
    assert SmootherOptions.from_groups(attitude.model, attitude.attitude) == attitude
    assert SmootherOptions.from_groups(*attitude.model_groups, attitude.batch) == attitude
    # a group left out keeps its defaults
    assert SmootherOptions.from_groups(opt.model) == SmootherOptions(motion_model="snap")
    assert SmootherOptions().model == ModelOptions() and SmootherOptions().tuning == TuningOptions()
    with pytest.raises(FrozenInstanceError):
        opt.model.motion_model = "jerk"
    with pytest.raises(TypeError, match="no option group 'stream'"):
        SmootherOptions.from_groups(StreamOptions())
    with pytest.raises(TypeError, match="no option lag_s"):
        SmootherOptions.from_groups(opt.model, lag_s=0.1)
    with pytest.raises(InputError, match="motion_model must be 'jerk' or 'snap'"):  # values checked when flat
        SmootherOptions.from_groups(replace(opt.model, motion_model="quintic"))


def test_the_estimators_give_their_groups_back():
    est = make_estimator("fixed-lag", lag_s=0.1, engine="gtsam", guard="warn", initialisation="ml")
    assert est.stream.lag_s == 0.1 and est.stream.engine == "gtsam" and est.solve.initialisation == "ml"
    assert not hasattr(est, "batch") and not hasattr(est, "attitude")
    assert FixedLagEstimator.from_groups(est.model, est.solve, est.stream, est.tuning, guard="warn") == est
    # the model given to the stream: the estimator's model, solve and tuning, the batch model's groups at their
    # defaults
    inner = est.model_groups
    assert inner.model == est.model and inner.solve == est.solve and inner.tuning == est.tuning
    assert inner.batch_model == SmootherOptions().batch_model and inner.attitude == SmootherOptions().attitude
    batch = make_estimator("smoother", window_s=12.0, solver="gtsam", tune_span_s=None)
    assert batch.batch.window_s == 12.0 and batch.batch.solver == "gtsam" and batch.batch.tune_span_s is None
    assert not hasattr(batch, "stream") and batch.model_groups == (batch.model, batch.solve, batch.batch_model,
                                                                    batch.attitude, batch.self_calibration, batch.tuning)


def test_the_fixed_lag_estimator_checks_its_model_options_when_made():
    with pytest.raises(InputError, match=r"^fixed-lag option omega_dot_random_walk_radps2_per_sqrt_s must be a number > 0 "
                                         r"\[rad/s²/√s\], got -1.0$"):
        FixedLagEstimator(omega_dot_random_walk_radps2_per_sqrt_s=-1.0)
    with pytest.raises(InputError, match="^fixed-lag option guard must be one of 'replace', 'warn', 'off', got 'sometimes'$"):
        FixedLagEstimator(guard="sometimes")
    # the batch group's options joined SmootherOptions from the batch estimator, and are checked there too
    with pytest.raises(InputError, match=r"^smoother option tune_span_s must be a number > 0 \[s\] or None, got -1.0$"):
        SmootherOptions(tune_span_s=-1.0)
    with pytest.raises(InputError, match=r"workers must be an integer >= 0 \[processes\], got -1"):
        SmootherOptions(workers=-1)


def test_the_batch_smoother_s_guard_and_solver_are_checked_by_their_declarations_alone():
    # the declarations (Choice) are the only check of these values: made directly, by name, or from -O
    with pytest.raises(InputError, match="^smoother option guard must be one of 'replace', 'warn', 'off', got 'sometimes'$"):
        BatchSmootherEstimator(guard="sometimes")
    with pytest.raises(InputError, match="^smoother option solver must be 'numpy' or 'gtsam', got 'scipy'$"):
        make_estimator("smoother", solver="scipy")
    with pytest.raises(InputError, match=r"^-O guard='sometimes': expected one of 'replace', 'warn', 'off' \(option of "
                                         r"method 'smoother', default 'replace'\)$"):
        method_options("smoother", ["guard=sometimes"])
    assert BatchSmootherEstimator(guard="warn", solver="gtsam").guard == "warn"


def test_an_option_is_declared_in_its_group_only():
    with pytest.raises(TypeError, match="declares window_s: declare an option in its group only"):
        @dataclass(frozen=True)
        @assemble("model")
        class Twice:
            window_s: float = 1.0


def test_the_fixed_lag_smoother_takes_the_stream_group_as_it_is_given():
    """``FixedLagSmoother.of_groups``: every setting of the stream group reaches the smoother (its lag, gaps,
    warm-up, hold, engine and model updates), and a setting given beside it wins; the fixed-lag method hands
    its own group over, its lag shortened by the screening's wait where that fits in it."""
    from gfimu.array import cube_array
    from gfimu.smoother.stream.fixed_lag import FixedLagSmoother

    array = cube_array(0.05)
    stream = StreamOptions(lag_s=0.5, gap_factor=2.5, warmup_s=0.1, hold_max_s=1.0, tune_window_s=2.0)
    sm = FixedLagSmoother.of_groups(array, SmootherOptions().model_groups, stream, 500.0)
    assert (sm.lag_s, sm.gap_factor, sm.rate_hz) == (0.5, 2.5, 500.0)
    assert sm.config.warmup_n == 50  # 0.1 s at 500 Hz
    assert sm.engine == "numpy"
    assert FixedLagSmoother.of_groups(array, SmootherOptions().model_groups, stream, 500.0, lag_s=0.3).lag_s == 0.3
    est = FixedLagEstimator(lag_s=0.4)
    made = est.smoother(array, 500.0)
    assert made.lag_s == pytest.approx(est.window_lag_s(500.0), abs=0.0)
    assert made.gap_factor == est.gap_factor


def test_the_guard_is_given_the_guard_group_and_the_groups_of_the_model_its_smoother_solved(monkeypatch):
    """The guard (gfimu.smoother.result.guarded) takes the estimator's guard group and what the smoother used beyond
    the accelerometers: its model group, and its attitude and self-calibration groups where it has them (the
    fixed-lag smoother has none)."""
    import numpy as np

    from gfimu.estimate import Estimate, Report
    from gfimu.motion import Motion
    from gfimu.smoother import result
    from gfimu.smoother.guard import GuardResult
    from gfimu.smoother.model.option_groups import GuardOptions, SelfCalibrationOptions

    seen = []

    def guarded(log, run, guard, model, attitude=None, self_calibration=None):
        seen.append((guard, model, attitude, self_calibration))
        return run.motion, GuardResult(guard.guard)

    still = Motion(np.arange(3, dtype=np.int64), omega_b_radps=np.zeros((3, 3)), omega_dot_b_radps2=np.zeros((3, 3)),
                   specific_force_b_mps2=np.zeros((3, 3)))
    monkeypatch.setattr(result, "guarded", guarded)
    for cls in (BatchSmootherEstimator, FixedLagEstimator):
        monkeypatch.setattr(cls, "result", lambda self, log, progress=False: Estimate(still, Report(self.method)))
    monkeypatch.setattr(FixedLagEstimator, "_per_sample_ahead", lambda self, log: None)  # (no log to estimate)
    batch = BatchSmootherEstimator(guard="warn", use_gyro=False, self_calibrate_bias=True)
    assert batch.estimate(None).report.guard.mode == "warn"
    assert seen[-1] == (GuardOptions("warn"), batch.model, batch.attitude, batch.self_calibration)
    assert seen[-1][3] == SelfCalibrationOptions(self_calibrate_bias=True)
    stream = FixedLagEstimator(factor_groups=())
    stream.estimate(None)
    assert seen[-1] == (GuardOptions("replace"), stream.model, None, None)
    BatchSmootherEstimator(guard="off").estimate(None)
    assert len(seen) == 2  # 'off': no guard


def test_the_guard_reads_what_the_smoother_used_from_the_model_groups():
    """``unguarded``: the model group says whether the gyroscope and factor groups were used, the attitude and
    self-calibration groups whether the inclinometer or calibration were; a smoother without them used neither."""
    import numpy as np

    from gfimu.array import cube_array
    from gfimu.log import Log
    from gfimu.smoother.model.groups import AccelerometerGroup
    from gfimu.smoother.model.option_groups import AttitudeOptions, SelfCalibrationOptions
    from gfimu.smoother.result import unguarded

    array = cube_array(0.05)
    log = Log(array, np.arange(10, dtype=np.int64) * 10_000_000, np.zeros((10, array.structure_matrix().shape[0])))
    assert unguarded(log, ModelOptions()) is None
    assert unguarded(log, ModelOptions(), AttitudeOptions(), SelfCalibrationOptions()) is None
    assert "calibrates" in unguarded(log, ModelOptions(), None, SelfCalibrationOptions(self_calibrate_scale=True))
    assert "factor groups" in unguarded(log, ModelOptions(factor_groups=(AccelerometerGroup(),)))


def test_the_tuner_takes_the_model_batch_model_and_tuning_groups(monkeypatch):
    """``tune`` reads the model and batch model it tunes and the tuning group's choices (which motion models,
    the accelerometer noise scale, the oscillators), and gives the groups back with the tuned model and batch
    model: the jerk density in the model group, the snap density in the batch model group."""
    from gfimu.array import cube_array
    from gfimu.simulate import simulate
    from gfimu.smoother.solve.initialise import initial_states
    from gfimu.smoother.tuning import evidence

    runs = []
    run = evidence._NoiseSearch.run

    def recorded(search, accel_noise):
        runs.append((search.motion_model, accel_noise, search.frequencies))
        return run(search, accel_noise)

    monkeypatch.setattr(evidence._NoiseSearch, "run", recorded)
    log = simulate("random3d", cube_array(0.025, noise_std_mps2=0.07), rate_hz=100.0, duration_s=2.0, seed=1)
    groups = SmootherOptions(specific_force_random_walk_mps2_per_sqrt_s=20.0).model_groups
    model, batch_model = groups.model, groups.batch_model
    x = initial_states(log, groups)
    tuning, tuned = evidence.tune(log, groups, x)
    tuned_batch = tuned.batch_model
    assert runs == [("jerk", False, True)]
    assert tuned == groups._replace(model=replace(model, omega_dot_random_walk_radps2_per_sqrt_s=tuning.density,
                            process_axis_factors=tuning.axis_factors,
                            process_axis_frequencies_hz=tuning.axis_frequencies_hz,
                            specific_force_random_walk_mps2_per_sqrt_s=tuning.specific_force_density))
    assert tuned_batch == batch_model
    runs.clear()
    both = TuningOptions(tune_motion_model=True, tune_accel_noise=True, tune_axis_frequencies=False)
    tuning, tuned = evidence.tune(log, groups._replace(tuning=both), x)
    tuned, tuned_batch = tuned.model, tuned.batch_model
    assert runs == [("jerk", True, False), ("snap", True, False)]
    assert tuned.motion_model == tuning.motion_model
    if tuning.motion_model == "snap":
        assert tuned_batch.omega_ddot_random_walk_radps3_per_sqrt_s == tuning.density
        assert tuned.omega_dot_random_walk_radps2_per_sqrt_s == model.omega_dot_random_walk_radps2_per_sqrt_s
    else:
        assert tuned.omega_dot_random_walk_radps2_per_sqrt_s == tuning.density and tuned_batch == batch_model


def test_the_batch_engine_takes_the_model_batch_model_batch_and_tuning_groups(monkeypatch):
    """``smooth``, the batch smoother's engine, is given the estimator's groups of the model and its batch group,
    and cuts its solve windows, picks its solver and workers and chooses the model as they say; the estimator
    hands its own groups over."""
    import numpy as np

    from gfimu.array import cube_array
    from gfimu.simulate import simulate
    from gfimu.smoother.batch import engine

    log = simulate("random3d", cube_array(0.025, noise_std_mps2=0.07), rate_hz=100.0, duration_s=3.0, seed=1)
    model = ModelOptions(omega_dot_random_walk_radps2_per_sqrt_s=20.0)
    batch = BatchOptions(window_s=1.2, overlap_s=0.4, workers=1, branch_restarts=False)
    tuning = TuningOptions(auto_model=False, tune_process_noise=False)
    groups = SmootherOptions.from_groups(model, tuning).model_groups
    run = engine.smooth(log, groups, batch)
    assert run.report.windows == len(engine.window_slices(len(log), log.rate_hz, 1.2, 0.4)) == 3
    assert run.report.model_check is None and run.report.tunings == ()  # no model choice, no tuning
    assert run.report.options["omega_dot_random_walk_radps2_per_sqrt_s"] == 20.0
    assert run.report.options["window_s"] == 1.2
    whole = engine.smooth(log, groups, replace(batch, window_s=None))
    assert whole.report.windows == 1
    tuned = engine.smooth(log, groups._replace(tuning=replace(tuning, tune_process_noise=True)), batch)
    assert len(tuned.report.tunings) == 3  # one per window

    given = []
    smooth = engine.smooth
    monkeypatch.setattr(engine, "smooth", lambda log, *groups, **kw: given.append(groups) or smooth(log, *groups, **kw))
    est = BatchSmootherEstimator.from_groups(model, batch, tuning, guard="off")
    out = est.estimate(log)
    assert given == [(est.model_groups, batch)]
    np.testing.assert_array_equal(out.motion.omega_b_radps, run.motion.omega_b_radps)


def test_the_problem_s_check_reads_the_groups_of_the_model():
    """``options_reason``: what the batch problem cannot solve on an array, from the groups of its model (the
    batch estimator's ``applicable`` hands its own over)."""
    from gfimu.array import cube_array
    from gfimu.smoother.model.problem import options_reason

    array = cube_array(0.05)
    assert options_reason(array, SmootherOptions().model_groups) is None
    inclinometer = SmootherOptions(use_inclinometer=True).model_groups
    assert inclinometer.attitude.use_inclinometer and inclinometer.batch_model == SmootherOptions().batch_model
    assert "need the attitude state" in options_reason(array, inclinometer)
    assert "has no inclinometer" in options_reason(array, inclinometer, attitude_supported=True)
    assert BatchSmootherEstimator(use_inclinometer=True).applicable(array) == options_reason(
        array, inclinometer, attitude_supported=True)
    assert "[body]" in BatchSmootherEstimator(free_flight=True).applicable(array)
