"""Every smoother option has a group, a unit where its name carries one, a default and a meaning;
``gfimu estimate --list-options`` prints them; the flat ``-O name=value`` keeps working."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from gfimu.methods import describe_options, make_estimator
from gfimu.optiondoc import unit_of
from gfimu.smoother.option_groups import GROUPS

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("method", ["smoother", "fixed-lag"])
def test_smoother_options_are_grouped_and_documented(method):
    infos = describe_options(method)
    assert {i.group for i in infos} <= set(GROUPS)
    for info in infos:
        assert info.help, f"{method} option {info.name} has no documentation"
    units = {i.name: i.unit for i in infos}
    assert units["window_s"] == "s" and units["omega_dot_random_walk_radps2_per_sqrt_s"] == "rad/s²/√s"
    assert units["accel_noise_slope_mps2_per_radps"] == "(m/s²)/(rad/s)"
    defaults = {i.name: i.default for i in infos}
    assert defaults["window_s"] == make_estimator(method).window_s


def test_unit_of_names():
    assert unit_of("torque_noise_std_nm") == "N·m" and unit_of("process_axis_frequencies_hz") == "Hz"
    assert unit_of("motion_model") == ""


def test_cli_lists_the_options():
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, "-m", "gfimu", "estimate", "--list-options", "--method", "smoother"],
                       env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    for head in ("model:", "batch:", "tuning:"):
        assert head in r.stdout
    assert "window_s [s] = 30.0" in r.stdout and "solver = 'numpy'" in r.stdout
