"""Each option declaration carries its check (gfimu.option): the classes that hold options check every value with
it, ``-O NAME=VALUE`` is read by it (``-O use_gyro=true``), ``--list-options`` shows what it accepts, and a bad
value ends in one line naming the option and what it accepts (exit status 2)."""

from __future__ import annotations

import dataclasses
from enum import StrEnum

import pytest

from gfimu.cli import main
from gfimu.cli.options import OptionError, method_options
from gfimu.errors import InputError
from gfimu.methods import METHODS, estimator_class, make_estimator
from gfimu.option import Check, Choice, Number, Rejected, Switch
from gfimu.smoother.model import option_groups as og
from gfimu.smoother.model.problem import SmootherOptions

CHOICES = {"motion_model": (og.MotionModel, ("jerk", "snap")),
           "measurement": (og.Measurement, ("accelerometer", "quadratic")),
           "initialisation": (og.Initialisation, ("sign-resolving", "ml")),
           "robust_loss": (og.RobustLoss, ("huber", "cauchy")),
           "solver": (og.Solver, ("numpy", "gtsam")),
           "engine": (og.Engine, ("numpy", "gtsam")),
           "guard": (og.Guard, ("replace", "warn", "off"))}


@pytest.mark.parametrize("method", list(METHODS))
def test_every_option_declares_its_unit_default_and_check(method):
    cls = estimator_class(method)
    if not dataclasses.is_dataclass(cls):
        return
    for f in dataclasses.fields(cls):
        if not f.init or f.name.startswith("_"):
            continue
        assert {"unit", "help", "check"} <= set(f.metadata), (method, f.name)
        assert f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING, (method, f.name)
        check = f.metadata["check"]
        if method in ("smoother", "fixed-lag") or isinstance(f.default, bool):
            assert isinstance(check, Check), (method, f.name)  # every smoother option, every switch
        if check is not None:
            assert check.check(f.default, f.metadata["unit"]) == f.default, (method, f.name)
            assert check.describe(f.metadata["unit"]), (method, f.name)


def test_the_seven_choices_are_enums():
    fields = {f.name: f for cls in og.GROUP_CLASSES.values() for f in dataclasses.fields(cls)}
    for name, (enum, values) in CHOICES.items():
        check = fields[name].metadata["check"]
        assert isinstance(check, Choice) and check.choices is enum and issubclass(enum, StrEnum), name
        assert check.values == values, name
    strings = [n for n, f in fields.items() if isinstance(f.default, str)]
    assert sorted(strings) == sorted(CHOICES)  # no other option is free text


def test_a_declaration_refuses_a_default_its_check_refuses():
    with pytest.raises(TypeError, match="the default -1 is not a number > 0"):
        og.option(-1, "s", "a length", check=Number(0, low_open=True))


def test_the_checks_read_values_as_documented():
    assert [Switch().parse(v) for v in ("true", "False", "yes", "off", 1, 0, True)] == [True, False, True, False,
                                                                                       True, False, True]
    with pytest.raises(Rejected, match="^true or false$"):
        Switch().parse("maybe")
    with pytest.raises(Rejected):
        Switch().check(1)  # from Python a switch is True or False
    n = Number(0, 1e4, none=True)
    assert n.parse("None") is None and n.check(3) == 3 and n.describe("Hz") == "a number >= 0 and <= 10000 [Hz] or None"
    with pytest.raises(Rejected, match="^a finite number >= 0"):
        n.check(float("nan"))
    assert Number(1, integer=True).describe() == "an integer >= 1"
    assert og.DENSITY.parse(1e-9) == 1e-9 and og.DENSITY.check(1e-12) == 1e-12  # the floor is the command line's
    with pytest.raises(Rejected, match=r"^a number >= 1e-09 \[m\] \(a smaller noise density"):
        og.DENSITY.parse(1e-12, "m")


def test_minus_O_values_parse_as_documented():
    opts = method_options("smoother", ["use_gyro=true", "ml_sign_chain=no", "motion_model=snap", "window_s=None",
                                       "process_axis_factors=1,2,3", "workers=2", "robust_loss=cauchy"]).options
    assert opts == {"use_gyro": True, "ml_sign_chain": False, "motion_model": "snap", "window_s": None,
                    "process_axis_factors": (1.0, 2.0, 3.0), "workers": 2, "robust_loss": "cauchy"}
    assert type(opts["motion_model"]) is str  # the option holds the value's text
    est = make_estimator("smoother", **opts)
    assert est.use_gyro is True and est.motion_model == og.MotionModel.SNAP and est.process_axis_factors == (1.0, 2.0, 3.0)
    assert method_options("fixed-lag", ["engine=gtsam", "screen_readings=false", "marginalise_every_s=null"]).options == {
        "engine": "gtsam", "screen_readings": False, "marginalise_every_s": None}


def test_python_values_are_checked_by_the_same_declarations():
    assert SmootherOptions(process_axis_factors=[1, 2, 3]).process_axis_factors == (1.0, 2.0, 3.0)
    with pytest.raises(InputError, match=r"^smoother option robust_loss must be 'huber' or 'cauchy', got 'l1'$"):
        SmootherOptions(robust_loss="l1")
    with pytest.raises(InputError, match=r"^smoother option use_gyro must be true or false, got 'yes'$"):
        SmootherOptions(use_gyro="yes")
    with pytest.raises(InputError, match=r"^smoother option process_axis_frequencies_hz must be three numbers >= 0 "
                                         r"and <= 10000 \[Hz\] as 1,2,3, got \(0.0, 20000.0, 0.0\)$"):
        SmootherOptions(process_axis_frequencies_hz=(0.0, 2e4, 0.0))
    with pytest.raises(InputError, match=r"^fixed-lag option lag_s must be a number > 0 \[s\], got 0$"):
        make_estimator("fixed-lag", lag_s=0)
    with pytest.raises(InputError, match=r"^fixed-lag smoother option hold_max_s must be a number >= 0 \[s\], got -1$"):
        _fixed_lag_smoother(hold_max_s=-1)


def _fixed_lag_smoother(**kwargs):
    from gfimu.array import cube_array
    from gfimu.smoother.stream.fixed_lag import FixedLagSmoother

    return FixedLagSmoother(cube_array(), SmootherOptions().model_groups, **kwargs)


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    d = tmp_path_factory.mktemp("checks") / "log"
    assert main(["simulate", "random3d", "--out", str(d), "--rate-hz", "100", "--duration-s", "1", "--no-progress",
                 "--quiet"]) == 0
    return d


def test_a_switch_given_as_true_runs(log, tmp_path):
    out = tmp_path / "e.csv"
    assert main(["estimate", str(log), "-O", "use_gyro=true", "-O", "tune_process_noise=false", "-O", "guard=off",
                 "--out", str(out), "--no-progress", "--quiet"]) == 0
    assert out.stat().st_size > 0


@pytest.mark.parametrize("method, option, expected", [
    ("smoother", "use_gyro=maybe", "-O use_gyro='maybe': expected true or false (option of method 'smoother', "
                                   "default True)"),
    ("smoother", "motion_model=quintic", "-O motion_model='quintic': expected 'jerk' or 'snap' (option of method "
                                         "'smoother', default 'jerk')"),
    ("smoother", "initialisation=random", "-O initialisation='random': expected 'sign-resolving' or 'ml'"),
    ("smoother", "process_axis_factors=1,2,-3", "-O process_axis_factors=(1.0, 2.0, -3.0): expected three numbers "
                                                "> 0 as 1,2,3 (option of method 'smoother', default (1.0, 1.0, 1.0))"),
    ("smoother", "workers=1.5", "-O workers=1.5: expected an integer >= 0 [processes] (option of method 'smoother', "
                                "default 0)"),
    ("smoother", "window_s=-2", "-O window_s=-2: expected a number > 0 [s] or None (option of method 'smoother', "
                                "default 30.0)"),
    ("smoother", "solver=scipy", "-O solver='scipy': expected 'numpy' or 'gtsam'"),
    ("fixed-lag", "gap_factor=1", "-O gap_factor=1: expected a number > 1 (option of method 'fixed-lag', "
                                  "default 1.5)"),
    ("fixed-lag", "engine=cuda", "-O engine='cuda': expected 'numpy' or 'gtsam'"),
    ("fixed-lag", "guard=maybe", "-O guard='maybe': expected one of 'replace', 'warn', 'off'"),
])
def test_a_bad_value_is_one_line_naming_the_option_and_what_it_accepts(log, tmp_path, capsys, method, option,
                                                                        expected):
    out = tmp_path / "e.csv"
    assert main(["estimate", str(log), "--method", method, "-O", option, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"gfimu estimate: error: {expected}") and err.count("\n") == 1, err
    assert not out.exists()
    with pytest.raises(OptionError):
        method_options(method, [option])


def test_list_options_shows_unit_default_and_what_each_accepts(capsys):
    assert main(["estimate", "--method", "smoother", "--list-options"]) == 0
    text = capsys.readouterr().out
    assert "\nmotion_model = 'jerk'\n" in text and "\n    accepts: 'jerk' or 'snap'\n" in text
    assert "\nomega_dot_random_walk_radps2_per_sqrt_s = 30.0 [rad/s²/√s]\n" in text
    assert "\n    accepts: a number >= 1e-09 [rad/s²/√s]\n" in text
    assert "\nwindow_s = 30.0 [s]\n" in text and "\n    accepts: a number > 0 [s] or None\n" in text
    assert "\nuse_gyro = True\n" in text and "\n    accepts: true or false\n" in text
    assert "values are JSON" not in text and "a switch as true or false" in text
    assert main(["estimate", "--method", "fixed-lag", "--list-options"]) == 0
    text = capsys.readouterr().out
    assert "\nengine = 'numpy'\n" in text and "\n    accepts: 'numpy' or 'gtsam'\n" in text
    assert "\nlag_s = 0.2 [s]\n" in text and "\n    accepts: a number > 0 [s]\n" in text
