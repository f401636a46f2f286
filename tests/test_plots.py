"""Figures: structure of the Figure objects, written PNG files, the plot command."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from gfimu import plots  # noqa: E402
from gfimu.array import cube_array  # noqa: E402
from gfimu.compare import condition_vs_scale  # noqa: E402
from gfimu.motion import Motion  # noqa: E402

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _motions(n: int = 300):
    t = np.arange(n) * 2_000_000
    ts = t * 1e-9
    w = np.column_stack([np.sin(2 * np.pi * ts), np.cos(3 * ts), 0.5 + 0 * ts])
    dw = np.column_stack([2 * np.pi * np.cos(2 * np.pi * ts), -3 * np.sin(3 * ts), 0 * ts])
    f = np.column_stack([np.sin(ts), 0 * ts, 9.8 + 0 * ts])
    truth = Motion(t, omega_b_radps=w, omega_dot_b_radps2=dw, specific_force_b_mps2=f)
    est = Motion(t, omega_b_radps=w + 0.1, omega_dot_b_radps2=dw - 0.2, specific_force_b_mps2=f)
    only_w = Motion(t, omega_b_radps=w * 1.1)
    return truth, est, only_w


def _check_png(path):
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE and len(data) > 10_000


def test_time_series_layout_lines_and_errors(tmp_path):
    truth, est, only_w = _motions()
    fig = plots.plot_time_series(truth, {"a": est, "b": only_w})
    # f, ω̇, ω: a row of values and a row of errors each, three axes per row
    assert len(fig.axes) == 3 * 2 * 3
    value_ax_w, error_ax_w = fig.axes[4 * 3], fig.axes[5 * 3]  # ω_x values and errors
    assert len(value_ax_w.lines) == 3  # truth + two estimates
    err_a = error_ax_w.lines[0].get_ydata()
    np.testing.assert_allclose(err_a, 0.1, atol=1e-12)  # estimate − truth
    assert value_ax_w.get_ylabel() == "w_x [rad/s]" and fig.axes[-1].get_xlabel() == "time [s]"
    assert len(fig.axes[2 * 3].lines) == 2  # ω̇_x: truth and "a" only
    _check_png(plots.save_figure(fig, tmp_path / "ts.png"))
    fig = plots.plot_time_series(truth, {"b": only_w}, errors=False)
    assert len(fig.axes) == 3  # only ω is shared
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["truth", "b"]


def _bands(ax):
    from matplotlib.collections import PolyCollection

    return [c for c in ax.collections if isinstance(c, PolyCollection)]


def test_sigma_bands_and_several_estimates_stay_apart(tmp_path):
    truth, est, only_w = _motions()
    sigma_w = np.full((len(truth), 3), 0.05)
    sigma_w[:, 1] = np.linspace(0.01, 0.2, len(truth))
    with_sigma = est.replace(sigma={"omega_b_radps": sigma_w})
    third = est.replace(omega_b_radps=truth.omega_b_radps - 0.3)
    estimates = {"smoother": with_sigma, "ml": only_w, "fixed-lag": third}
    fig = plots.plot_time_series(truth, estimates, quantities=["omega_b_radps"])
    values_y, errors_y = fig.axes[1], fig.axes[4]  # ω_y: values and errors
    # one line per estimate plus the reference in the values, one per estimate (and zero) in the errors
    labels = [line.get_label() for line in values_y.lines]
    assert labels == ["truth", "smoother", "ml", "fixed-lag"]
    assert [line.get_label() for line in errors_y.lines][:3] == ["smoother", "ml", "fixed-lag"]
    # one ±1σ band, only for the estimate with sigma, in each panel; values ± σ and ± σ around zero
    for ax, centre in ((values_y, with_sigma.omega_b_radps[:, 1]), (errors_y, 0.0)):
        (band,) = _bands(ax)
        assert band.get_label() == "smoother ±1σ"
        x, y = band.get_paths()[0].vertices.T
        at = [y[np.isclose(x, ti, rtol=0, atol=1e-12)] for ti in truth.times_s]
        np.testing.assert_allclose([v.max() for v in at], centre + sigma_w[:, 1], atol=1e-12)
        np.testing.assert_allclose([v.min() for v in at], centre - sigma_w[:, 1], atol=1e-12)
        assert 0 < band.get_facecolor()[0][3] < 0.5  # translucent
    # distinct colours and line styles; the reference drawn apart (black, wide, pale, underneath)
    lines = values_y.lines[1:]
    assert len({line.get_color() for line in lines}) == 3 and len({line.get_linestyle() for line in lines}) == 3
    ref = values_y.lines[0]
    assert ref.get_color() == "k" and ref.get_linewidth() > 2 * max(line.get_linewidth() for line in lines)
    assert ref.get_alpha() < 1 and ref.get_zorder() < min(line.get_zorder() for line in lines)
    # the most accurate estimate on top (ml's error is 10 % of ω, the others' 0.1 and 0.3 rad/s)
    z = {line.get_label(): line.get_zorder() for line in lines}
    assert z["smoother"] > z["fixed-lag"]
    # one legend for the figure naming the reference, the estimates and the band
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["truth", "smoother", "smoother ±1σ", "ml",
                                                                  "fixed-lag"]
    fig = plots.plot_time_series(truth, estimates, quantities=["omega_b_radps"], bands=False)
    assert not any(_bands(ax) for ax in fig.axes)
    with pytest.raises(ValueError, match="no estimate has linear acceleration"):
        plots.plot_time_series(truth.replace(accel_b_mps2=truth.specific_force_b_mps2), {"ml": only_w},
                               quantities=["accel_b_mps2"])


def test_time_series_masks_invalid_samples_and_checks_input():
    truth, est, _ = _motions()
    valid = np.ones(len(truth), bool)
    valid[10:20] = False
    fig = plots.plot_time_series(truth, {"a": est}, quantities=["omega_b_radps"], valid=valid)
    err = fig.axes[3].lines[0].get_ydata()
    assert np.all(np.isnan(err[10:20])) and np.all(np.isfinite(err[20:]))
    with pytest.raises(ValueError, match="at least one estimate"):
        plots.plot_time_series(truth, {})
    with pytest.raises(ValueError, match="no linear acceleration"):
        plots.plot_time_series(truth, {"a": est}, quantities=["accel_b_mps2"])


def test_condition_number_figure(tmp_path):
    sizes = np.logspace(-2, 2, 21)
    cond = condition_vs_scale(cube_array(), sizes)
    fig = plots.plot_condition_number(sizes, {"cube": cond}, marks=[(1.0, math.sqrt(2), "√2")])
    (ax,) = fig.axes
    np.testing.assert_allclose(ax.lines[0].get_ydata(), cond)
    assert ax.get_xscale() == "log" and "half edge" in ax.get_xlabel()
    _check_png(plots.save_figure(fig, tmp_path / "cond.png"))


def test_polhode_constants_and_figure(tmp_path):
    inertia = np.array([1.0, 2.0, 3.0])
    w = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]])
    two_t, h2 = plots.polhode_constants(w, inertia)
    assert two_t == 1 + 8 + 27 and h2 == 1 + 16 + 81
    fig = plots.plot_polhode({"truth": w, "estimate": w * 1.01}, inertia)
    assert len(fig.axes) == 4  # 3-D view and three plane projections
    assert fig.axes[0].name == "3d" and len(fig.axes[1].lines) == 2
    _check_png(plots.save_figure(fig, tmp_path / "polhode.png"))


def test_t2_and_step_size_figures(tmp_path):
    t2 = np.linspace(0.5, 12, 12)
    fig = plots.plot_t2_rmse(t2, {"trial 1": (t2 - 5) ** 2 + 1, "trial 2": (t2 - 7) ** 2 + 2})
    (ax,) = fig.axes
    # each trial: its curve and its best point
    stars = [line for line in ax.lines if line.get_marker() == "*"]
    assert [float(s.get_xdata()[0]) for s in stars] == [t2[np.argmin((t2 - 5) ** 2)], t2[np.argmin((t2 - 7) ** 2)]]
    _check_png(plots.save_figure(fig, tmp_path / "t2.png"))
    fig = plots.plot_t2_trend(np.array([1.0, 2.0, 3.0]), np.array([3.0, 4.0, 5.0]), np.array([[2, 4], [3, 6], [4, 7]]))
    assert "trend: T2 = 1(a+b+c) + 2" in [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    fig = plots.plot_step_size(np.array([0.001, 0.002]), {"gyro": [1e-3, 2e-3], "no gyro": [1e-2, 5e-2]}, "error [rad]")
    assert len(fig.axes[0].lines) == 2 and fig.axes[0].get_xlabel() == "step size [ms]"
    _check_png(plots.save_figure(fig, tmp_path / "step.png"))


def _log_and_offset_estimate(tmp_path, duration_s: float):
    """A simulated log folder ``log`` and ``est.csv``: its truth with ω off by 0.05 rad/s; returns the truth."""
    from gfimu.io import write_log, write_motion_csv
    from gfimu.simulate import simulate

    log = simulate("random3d", duration_s=duration_s, seed=2)
    write_log(log, tmp_path / "log")
    truth = log.truth
    write_motion_csv(truth.replace(omega_b_radps=truth.omega_b_radps + 0.05, accel_b_mps2=None, quaternion_wb=None),
                     tmp_path / "est.csv")
    return truth


def test_cli_plot(tmp_path):
    from gfimu.cli import main

    _log_and_offset_estimate(tmp_path, 0.6)
    out = tmp_path / "fig.png"
    assert main(["plot", str(tmp_path / "log"), str(tmp_path / "est.csv"), "--out", str(out), "--start-s", "0.1"]) == 0
    _check_png(out)
    assert main(["plot", str(tmp_path / "log"), "--kind", "condition", "--out", str(tmp_path / "c.png")]) == 0
    _check_png(tmp_path / "c.png")
    # no [body] in a cube's array.toml: the polhode is refused with the reason
    assert main(["plot", str(tmp_path / "log"), str(tmp_path / "est.csv"), "--kind", "polhode",
                 "--out", str(tmp_path / "p.png")]) == 2
    assert main(["plot", str(tmp_path / "log"), "--out", str(tmp_path / "x.png")]) == 2


def test_estimate_labels_tell_files_apart():
    from gfimu.cli.plot import estimate_labels

    assert estimate_labels(["x/a/est.csv", "x/b/est.csv", "est.csv"]) == ["a/est", "b/est", "est"]
    assert estimate_labels(["smoother.csv", "ml.csv", "ml.csv"]) == ["smoother", "ml", "ml (2)"]


def test_cli_plot_sigma_columns_and_files_of_the_same_name(tmp_path):
    from gfimu.cli import main
    from gfimu.io import write_motion_csv

    truth = _log_and_offset_estimate(tmp_path, 0.3)
    sigma = {"omega_b_radps": np.full((len(truth), 3), 0.02)}
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        write_motion_csv(truth.replace(accel_b_mps2=None, quaternion_wb=None, sigma=sigma if folder == "a" else {}),
                         tmp_path / folder / "est.csv")
    assert main(["plot", str(tmp_path / "log"), str(tmp_path / "a" / "est.csv"), str(tmp_path / "b" / "est.csv"),
                 str(tmp_path / "est.csv"), "--out", str(tmp_path / "three.png"), "--quantities", "w", "-q"]) == 0
    _check_png(tmp_path / "three.png")
