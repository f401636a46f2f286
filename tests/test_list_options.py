"""``gfimu estimate --method M --list-options``: every -O option with its default, unit and help, read from the
option's declaration (the field's metadata)."""

import dataclasses
import inspect

import pytest

from gfimu.cli import main
from gfimu.methods import METHODS, estimator_class, resolve_options


@pytest.mark.parametrize("method", list(METHODS))
def test_every_option_is_listed_with_its_declared_default_unit_and_help(method, capsys):
    assert main(["estimate", "--method", method, "--list-options"]) == 0
    out = capsys.readouterr().out
    for f in dataclasses.fields(estimator_class(method)):
        if not f.init or f.name.startswith("_"):
            continue
        unit, help_ = f.metadata["unit"], f.metadata["help"]
        assert help_, (method, f.name)
        head = f"{f.name} = {f.default!r}" + (f" [{unit}]" if unit else "")
        assert f"\n{head}\n    {help_}\n" in out, (method, f.name)
    assert "(no description)" not in out


def test_hand_written_expectations():
    smoother, fixed_lag = resolve_options("smoother").describe(), resolve_options("fixed-lag").describe()
    for text in (smoother, fixed_lag):
        assert "\nomega_dot_random_walk_radps2_per_sqrt_s = 30.0 [rad/s²/√s]\n    white angular jerk density" in text
        assert "\ntune_process_noise = True\n" in text and "\nauto_model = True\n" in text
        assert "\nguard = 'replace'\n" in text
    assert "\nwindow_s = 30.0 [s]\n" in smoother and "\nreweight_iterations = 3\n" in smoother
    assert "\nworkers = 0 [processes]\n" in smoother
    assert "\naccel_noise_slope_mps2_per_radps = 0.0 [m/s² per rad/s]\n" in smoother and "\n[batch_model]\n" in smoother
    batch_only = ("estimate_attitude", "use_inclinometer", "self_calibrate_bias", "free_flight", "measurement",
                  "accel_robust_threshold", "omega_ddot_random_walk_radps3_per_sqrt_s")
    assert all(f"\n{n} = " in smoother for n in batch_only)
    assert not [n for n in batch_only if f"\n{n} = " in fixed_lag]
    assert not [n for n in ("window_s", "overlap_s", "reweight_iterations", "solver") if f"\n{n} = " in fixed_lag]
    assert "\nlag_s = 0.2 [s]\n" in fixed_lag and "\nrelinearize_threshold = 0.1 [rad/s]\n" in fixed_lag
    assert not [n for n in ("lag_s", "relinearize_threshold", "engine", "retune_every_s") if f"\n{n} = " in smoother]
    assert "\nnoise_std_mps2 = None [m/s²]\n" in resolve_options("ml").describe()
    assert "\nt1 = 0.1 [(rad/s)²]\n" in resolve_options("imm").describe()


def test_the_list_is_made_without_reading_any_source(monkeypatch):
    expected = {m: resolve_options(m).describe() for m in METHODS}

    def no_source(*args, **kwargs):
        raise OSError("source not available")

    monkeypatch.setattr(inspect, "getsource", no_source)
    monkeypatch.setattr(inspect, "getsourcelines", no_source)
    assert {m: resolve_options(m).describe() for m in METHODS} == expected


def test_estimate_without_a_log_asks_for_one(capsys):
    assert main(["estimate", "--method", "smoother"]) == 2
    assert "a LOG folder and --out" in capsys.readouterr().err
