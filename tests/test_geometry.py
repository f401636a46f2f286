"""Observability of the array checked before solving (docs/geometry.md): co-located and collinear arrays refused by
every ω method (the smoothers included), exactly coplanar triads refused by ml and the smoothers, the near-planar
MIMU4444 board accepted and solved."""

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.array import (MAX_LINEAR_CONDITION, MAX_OMEGA_CONDITION, Accelerometer, Gyroscope, SensorArray, cube_array,
                         mimu4444_array)
from gfimu.methods import make_estimator
from gfimu.simulate import simulate

METHODS = ["inversion", "integration", "pure-integration", "imm", "ml", "gyro-aided", "smoother", "fixed-lag"]


def squeezed(array, factors, gyro=True):
    accs = tuple(Accelerometer(a.name, a.position_m * np.asarray(factors, float), noise_std_mps2=a.noise_std_mps2)
                 for a in array.accelerometers)
    return SensorArray(accs, "test", Gyroscope(0.01) if gyro else None)


def test_condition_number_is_unit_free_and_grows_as_one_over_the_width():
    cube = cube_array()
    assert cube.linear_condition_number() == pytest.approx(np.sqrt(1.5))
    assert cube_array(0.001).linear_condition_number() == pytest.approx(np.sqrt(1.5))  # size does not matter
    shifted = SensorArray(tuple(Accelerometer(a.name, a.position_m + [1.0, -2.0, 0.5]) for a in cube.accelerometers))
    assert shifted.linear_condition_number() == pytest.approx(np.sqrt(1.5))  # nor the body origin
    for eta in (0.1, 0.01, 0.001):  # triads closing in on the x axis: cond ≈ 1 / (√2 eta)
        assert squeezed(cube, (1, eta, eta)).linear_condition_number() == pytest.approx(1 / (np.sqrt(2) * eta), rel=0.02)
    assert squeezed(cube, (1, 0, 0)).linear_condition_number() == np.inf
    assert squeezed(cube, (1, 1, 0)).linear_condition_number() == pytest.approx(np.sqrt(2))  # a plane is fine for [f, ω̇]
    assert cube.omega_equations() == 6 and squeezed(cube, (1, 1, 0)).omega_equations() == 3
    assert mimu4444_array().omega_equations() == 6 and squeezed(mimu4444_array(), (1, 1, 0)).omega_equations() == 3
    # the equations left for ω: √2 for the cube, √2 / eps for triads flattened by eps, infinite when coplanar
    assert cube.omega_condition_number() == pytest.approx(np.sqrt(2))
    for eps in (0.1, 0.01, 0.001):
        assert squeezed(cube, (1, 1, eps)).omega_condition_number() == pytest.approx(np.sqrt(2) / eps, rel=0.01)
    assert squeezed(cube, (1, 1, 0)).omega_condition_number() == np.inf
    assert mimu4444_array().omega_condition_number() == pytest.approx(13.4, abs=0.1)  # 19 mm square, ±1 mm


def test_nearly_coplanar_triads_are_refused_by_the_smoothers_only_beyond_the_studied_limit():
    thin = squeezed(cube_array(), (1, 1, 0.001), gyro=False)  # ω condition 1414: the smoother lost ω in the study
    assert thin.omega_condition_number() > MAX_OMEGA_CONDITION
    for method in ("smoother", "fixed-lag"):
        assert "nearly coplanar triads" in make_estimator(method).applicable(thin)
    assert make_estimator("ml").applicable(thin) is None  # per sample: no worse than at 0.1 in the study
    for method in ("smoother", "fixed-lag", "ml"):
        assert make_estimator(method).applicable(squeezed(cube_array(), (1, 1, 0.01), gyro=False)) is None


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("layout, words", [((0, 0, 0), "sit at one point"), ((1, 0, 0), "lie on one line"),
                                           ((1, 0.3 / MAX_LINEAR_CONDITION, 0.3 / MAX_LINEAR_CONDITION),
                                            "nearly degenerate")])
def test_co_located_collinear_and_nearly_collinear_arrays_are_refused_by_every_method(method, layout, words):
    array = squeezed(cube_array(), layout, gyro=method == "gyro-aided")  # the smoothers use a gyroscope when there is one
    reason = make_estimator(method).applicable(array)
    assert reason is not None and words in reason, reason


@pytest.mark.parametrize("method", ["ml", "smoother", "fixed-lag", "inversion"])
def test_exactly_coplanar_triads_are_refused_and_the_near_planar_board_accepted(method):
    for flat in (squeezed(cube_array(), (1, 1, 0), gyro=False), squeezed(mimu4444_array(), (1, 1, 0), gyro=False)):
        assert make_estimator(method).applicable(flat) is not None
    assert make_estimator(method).applicable(mimu4444_array()) is None


def test_the_smoother_with_a_gyroscope_is_not_held_by_the_accelerometer_geometry():
    array = squeezed(cube_array(), (1, 1, 0))  # coplanar, with a gyroscope
    assert make_estimator("smoother", use_gyro=True).applicable(array) is None


@pytest.mark.parametrize("layout, words", [((1, 0, 0), "lie on one line"), ((0, 0, 0), "sit at one point")])
def test_the_cli_refuses_a_collinear_or_co_located_array_with_one_line(tmp_path, capsys, layout, words):
    from gfimu.cli import main

    log = simulate("random3d", duration_s=1.0, seed=1)
    flat = squeezed(log.array, layout, gyro=False)
    gio.write_log(log.replace(array=flat), tmp_path / "log")
    for method in ("smoother", "fixed-lag", "ml", "inversion", "imm"):
        code = main(["estimate", str(tmp_path / "log"), "--method", method, "--out", str(tmp_path / "e.csv"),
                     "--no-progress"])
        err = capsys.readouterr().err
        assert code == 2 and words in err and f"method {method!r} cannot run on" in err, (method, err)
        assert "Traceback" not in err and not (tmp_path / "e.csv").exists()


def test_the_near_planar_board_keeps_its_accuracy_with_the_smoother():
    """The study's MIMU4444 row (docs/geometry.md): ω RMSE 0.07 rad/s for the smoother on 5 s of random3d."""
    log = simulate("random3d", array=mimu4444_array(), duration_s=5.0, seed=1)
    w = make_estimator("smoother").estimate(log).motion.omega_b_radps
    rmse = float(np.sqrt(np.mean(np.sum((w - log.truth.omega_b_radps) ** 2, axis=1))))
    assert rmse < 0.2, rmse
