"""``gfimu estimate --method M --list-options``: every -O option with unit, default and meaning."""

import dataclasses

import pytest

from gfimu.cli import main
from gfimu.cli.options import attribute_docs, describe_options, unit_of
from gfimu.methods import METHODS, estimator_class


@pytest.mark.parametrize("method", list(METHODS))
def test_every_option_is_listed_with_a_meaning(method, capsys):
    assert main(["estimate", "--method", method, "--list-options"]) == 0
    out = capsys.readouterr().out
    cls = estimator_class(method)
    for f in dataclasses.fields(cls):
        if f.init and not f.name.startswith("_"):
            assert f"\n{f.name} = " in out, f.name
    assert "(no description)" not in out


def test_units_defaults_and_docs_of_the_smoother():
    text = describe_options("smoother")
    assert "omega_dot_random_walk_radps2_per_sqrt_s = 30.0 [rad/s²/√s]" in text
    assert "window_s = 30.0 [s]" in text and "auto_model = True\n" in text
    docs = attribute_docs(estimator_class("smoother"))
    assert docs["auto_model"].startswith("Choose the model from the log")
    assert unit_of("accel_noise_slope_mps2_per_radps") == "m/s² per rad/s" and unit_of("reweight_iterations") == ""


def test_estimate_without_a_log_asks_for_one(capsys):
    assert main(["estimate", "--method", "smoother"]) == 2
    assert "a LOG folder and --out" in capsys.readouterr().err
