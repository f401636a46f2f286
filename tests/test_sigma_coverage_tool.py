"""tools/sigma_coverage.py: σ's coverage on simulated cells with a misfit built from physics, known truth."""

import warnings

import numpy as np
import pytest
from tool_modules import load_tool

sc = load_tool("sigma_coverage")


def test_spread_is_the_binomial_std_for_independent_samples_and_grows_with_correlation():
    rng = np.random.default_rng(0)
    n = 20000
    err = rng.standard_normal((n, 1))
    sigma = np.ones((n, 1))
    c = np.mean(np.abs(err) < 1)
    # independent samples: τ = 1 up to the first negative lag (a few 1/√n at most)
    assert sc.spread(err, sigma) == pytest.approx(np.sqrt(c * (1 - c) / n), rel=0.1)
    # each error repeated 10 times: 10 times fewer independent samples, √10 times the spread
    slow = np.repeat(err[: n // 10], 10, axis=0)
    c10 = np.mean(np.abs(slow) < 1)
    # the indicator correlated 1 - k/10 at lag k < 10: τ = 1 + 2 Σ_{k<10} (1 - k/10) = 10
    assert sc.spread(slow, sigma) == pytest.approx(np.sqrt(c10 * (1 - c10) * 10 / n), rel=0.15)


def test_spread_of_independent_draws_pooled_counts_the_samples_of_all_draws():
    rng = np.random.default_rng(1)
    n, draws = 5000, 4
    parts = [(rng.standard_normal((n, 2)), np.ones((n, 2))) for _ in range(draws)]
    (e0, s0), rest = parts[0], parts[1:]
    c = np.mean(np.abs(np.vstack([e for e, _ in parts])) < 1, axis=0)
    # four independent draws of n independent samples: the binomial std of 4 n samples, the larger axis's
    expected = np.max(np.sqrt(c * (1 - c) / (draws * n)))
    assert sc.spread(e0, s0, rest) == pytest.approx(expected, rel=0.1)
    # half the spread of one draw (√4), within the scatter of τ's estimate
    assert sc.spread(e0, s0, rest) == pytest.approx(sc.spread(e0, s0) / 2, rel=0.15)
    # an error constant over each draw: one independent sample per draw, however long the draw
    const = [(np.full((n, 1), v), np.ones((n, 1))) for v in (0.5, 2.0, 0.3, 1.5)]
    assert sc.spread(const[0][0], const[0][1], const[1:]) == pytest.approx(np.sqrt(0.5 * 0.5 / draws))


def test_draws_are_the_cell_with_consecutive_seeds():
    mc = _cell("20kHz-0.5s")
    got = sc.draws(mc, 3)
    assert got[0] == mc
    assert [d.cell.seed for d in got] == [mc.cell.seed, mc.cell.seed + 1, mc.cell.seed + 2]
    assert all(d.cell.rate_hz == mc.cell.rate_hz and d.name == mc.name for d in got)


def test_in_target_bounds():
    from gfimu.evaluation import SigmaCoverage

    m = SigmaCoverage(100, (0.6, 0.7, 0.76), (0.9, 0.95, 0.98), 3.0)
    assert sc.in_target(m)
    m = SigmaCoverage(100, (0.59, 0.7, 0.7), (0.9, 0.95, 0.98), 3.0)
    assert not sc.in_target(m) and sc.in_target(m, 0.02)


def _cell(name):
    return next(c for c in sc.CELLS if c.name == name)


@pytest.mark.slow
@pytest.mark.parametrize("name, white_wide", [("scale-1pc-200Hz", False), ("vibration-37Hz-200Hz", True)])
@pytest.mark.parametrize("method", ["smoother", "fixed-lag"])
def test_scaled_sigma_covers_a_physical_misfit_within_the_binomial_spread(tmp_path, name, white_wide, method):
    from gfimu import io as gio
    from gfimu.readings import screen_log

    path, omega = sc.build(_cell(name), tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log, _ = screen_log(gio.read_log(path, truth=False))
    motion, white = sc.run_both(log, method)
    err = motion.omega_b_radps - omega
    scaled = motion.sigma["omega_b_radps"]
    m_white = sc.sigma_metrics(err, white)
    m = sc.sigma_metrics(err, scaled)
    if white_wide:  # vibration: the robust model's white σ far too wide (nearly every error within it)
        assert min(m_white.coverage_1sigma) > 0.9
    else:  # 1 % gain errors: the white σ several times too small
        assert max(m_white.coverage_1sigma) < 0.35
    # the target band widened by 3 binomial stds of the count of independent samples (errors correlated
    # over a fraction of a second: a few dozen independent samples in 10 s)
    sp = sc.spread(err, scaled)
    assert 0.0 < sp < 0.15
    assert sc.in_target(m, 3 * sp), (m, sp)
    assert 1.5 < m.mean_nees < 6.0


@pytest.mark.parametrize("constant, drawn", [(False, 1), (True, sc.MAX_DRAWS)])
def test_auto_draws_stop_once_the_scaled_sigma_holds_enough_independent_samples(monkeypatch, tmp_path, capsys,
                                                                                constant, drawn):
    # a draw of 2000 independent errors holds 2000 independent samples per axis: one draw is enough; an error
    # constant over each draw holds one per draw, so the drawing goes on to MAX_DRAWS
    from gfimu.motion import Motion

    n = 2000
    seen = []

    def read_cell(cell, folder):
        seen.append(cell.cell.seed)
        return cell.cell.seed, np.zeros((n, 3))

    def run_both(seed, method):
        rng = np.random.default_rng(seed)
        err = np.full((n, 3), rng.standard_normal()) if constant else rng.standard_normal((n, 3))
        sigma = np.ones((n, 3))
        return Motion(np.arange(n, dtype=np.int64), err, sigma={"omega_b_radps": sigma}), sigma

    monkeypatch.setattr(sc, "read_cell", read_cell)
    monkeypatch.setattr(sc, "run_both", run_both)
    mc = _cell("turntable-0.3m-unstated")
    sc.pooled_rows_for(mc, None, ["smoother"], tmp_path)
    assert len(seen) == drawn and seen[0] == mc.cell.seed
    out = capsys.readouterr().out
    assert (f"({drawn} draws)" in out) == (drawn > 1) and out.count("| smoother |") == 2
    # a number of draws given: exactly that many
    seen.clear()
    sc.pooled_rows_for(mc, 2, ["smoother"], tmp_path)
    assert len(seen) == 2


def test_a_cell_with_a_calibration_error_is_drawn_the_most_times(monkeypatch, tmp_path, capsys):
    # positions or gains off: one error per draw, so the draws go on to MAX_DRAWS however many independent
    # samples the first holds
    from gfimu.motion import Motion

    n = 2000
    seen = []
    monkeypatch.setattr(sc, "read_cell", lambda cell, folder: (seen.append(cell.cell.seed), cell.cell.seed)[1:] +
                        (np.zeros((n, 3)),))

    def run_both(seed, method):
        err = np.random.default_rng(seed).standard_normal((n, 3))
        return Motion(np.arange(n, dtype=np.int64), err, sigma={"omega_b_radps": np.ones((n, 3))}), np.ones((n, 3))

    monkeypatch.setattr(sc, "run_both", run_both)
    sc.pooled_rows_for(_cell("mimu-like-62Hz"), None, ["smoother"], tmp_path)
    assert len(seen) == sc.MAX_DRAWS and f"({sc.MAX_DRAWS} draws)" in capsys.readouterr().out
