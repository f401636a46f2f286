"""The package's own names: ``from gfimu import estimate_log, read_log, ...``, loaded on first use."""

import importlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import gfimu

ROOT = Path(__file__).resolve().parents[1]


def run(code: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT)


@pytest.mark.parametrize("name", sorted(set(gfimu.__all__) - {"__version__"}))
def test_each_exported_name_is_its_modules_own(name):
    value = getattr(gfimu, name)
    module = importlib.import_module(f"gfimu.{gfimu._LAZY[name]}")
    if name == "simulate" and value is module:  # the package gfimu.simulate, imported first, calls its function
        args = dict(array=gfimu.cube_array(0.025), rate_hz=100.0, duration_s=0.2, seed=3)
        np.testing.assert_array_equal(value("reversal", **args).accel_mps2, module.simulate("reversal", **args).accel_mps2)
    else:
        assert value is getattr(module, name)
    assert name in dir(gfimu)


def test_the_main_verbs_are_exported():
    assert {"estimate_log", "read_log", "make_estimator", "Estimate", "Report", "GfimuError", "InputError",
            "DataError", "ResourceError", "MissingExtraError", "Motion", "Log", "SensorArray", "simulate",
            "evaluate"} <= set(gfimu.__all__)
    assert set(gfimu.__all__) - {"__version__"} == set(gfimu._LAZY)
    with pytest.raises(AttributeError, match="no attribute 'nothing_here'"):
        gfimu.nothing_here  # noqa: B018


def test_import_gfimu_loads_neither_numpy_nor_scipy():
    done = run("import sys, gfimu\n"
               "print(sorted(m for m in sys.modules if m.split('.')[0] in ('numpy', 'scipy')))\n"
               "print(sorted(m for m in sys.modules if m.startswith('gfimu')))")
    assert done.returncode == 0, done.stderr[-2000:]
    heavy, ours = done.stdout.splitlines()
    assert heavy == "[]" and ours == "['gfimu']"


def test_simulate_is_the_function_whichever_import_came_first():
    """Importing the package ``gfimu.simulate`` binds it as ``gfimu.simulate``; it calls the function."""
    code = ("import gfimu.simulate.scenarios\n"
            "from gfimu import simulate, cube_array\n"
            "from gfimu.simulate import simulate as f\n"
            "a = simulate('reversal', array=cube_array(0.025), rate_hz=100.0, duration_s=0.5, seed=3)\n"
            "b = f('reversal', array=cube_array(0.025), rate_hz=100.0, duration_s=0.5, seed=3)\n"
            "print(a.accel_mps2.shape, (a.accel_mps2 == b.accel_mps2).all())")
    done = run(code)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["(50,", "12)", "True"]


def test_the_readme_example_runs_from_the_short_imports():
    from gfimu import cube_array, evaluate, make_estimator, simulate

    log = simulate("reversal", array=cube_array(0.025, noise_std_mps2=0.0), rate_hz=200.0, duration_s=1.0, seed=1)
    est = make_estimator("inversion").estimate(log)
    assert isinstance(est, gfimu.Estimate) and isinstance(est.motion, gfimu.Motion)
    # noise-free readings: the inversion gives ω̇ exactly (to the solve's rounding)
    np.testing.assert_allclose(est.motion.omega_dot_b_radps2, log.truth.omega_dot_b_radps2, atol=1e-8)
    metrics = {m.label: m for m in evaluate(est.motion, log.truth).metrics}
    assert metrics["omega_dot"].n == 200 and metrics["omega_dot"].rmse_norm < 1e-8
    assert metrics["omega"].signs.flipped_share == 0.0
