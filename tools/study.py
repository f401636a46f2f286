#!/usr/bin/env python3
"""The accuracy study: every method on the simulator's scenarios and several arrays, with the papers' figures.

    python3 tools/study.py --out study/            # the whole study (tens of minutes on 2 cores)
    python3 tools/study.py --out study/ --quick    # short logs, fewer cases (about a minute)

Writes into the folder:

- ``tables/<scenario>__<layout>.md`` and ``.csv``: the comparison table of
  :func:`gfimu.compare.compare` (RMSE per axis and of the norm, relative RMS
  error, wrong signs of ω, run time, Cramér–Rao and smoother bounds);
- ``summary.md``: RMSE of ‖ω‖, ‖ω̇‖ and ‖f‖ of every method on every case, and
  the figures below;
- ``figures/``: estimates against truth (Ho & Lin 2009; Lu, Tsai & Lin 2010; Lin et al. 2011, Figs. 4–5, 10–11);
  RMSE against T2 and best T2 against a + b + c (Lin et al. 2011, Figs. 7–8);
  polhodes of the free-flight scenarios (McGinnis, Perkins & King 2012, Fig. 5); error against
  step size with and without gyro (Li et al. 2021, Fig. 5); condition number
  against layout size (Ho & Lin 2009, §III).

Every simulation has a fixed seed, so the study is reproducible.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gfimu import plots  # noqa: E402
from gfimu.array import Gyroscope, Inclinometer, SensorArray, cube_array, mimu4444_array, paper001_array  # noqa: E402
from gfimu.compare import compare, condition_vs_scale, motion_level, t2_band, t2_sweep  # noqa: E402
from gfimu.methods import make_estimator  # noqa: E402
from gfimu.evaluation import evaluate  # noqa: E402
from gfimu.simulate import SCENARIOS, SensorErrors, simulate  # noqa: E402

LAYOUTS = {
    "cube-5cm": lambda: cube_array(0.025, noise_std_mps2=0.07),  # 5 cm edge
    "cube-5cm+gyro": lambda: _with_gyro(cube_array(0.025, noise_std_mps2=0.07)),
    "cube-10cm": lambda: cube_array(0.05, noise_std_mps2=0.07),
    "mimu4444": lambda: mimu4444_array(),
    "paper001": lambda: paper001_array(lever_arm_m=0.05),
}
FREE_FLIGHT = ("freeflight-major", "freeflight-intermediate", "freeflight-minor")
QUICK_SCENARIOS = ("random3d", "reversal", "turntable", "freeflight-major")
QUICK_LAYOUTS = ("cube-5cm", "cube-5cm+gyro")


def _with_gyro(array: SensorArray, gyro_noise_std_radps: float = 0.01) -> SensorArray:
    return SensorArray(array.accelerometers, array.name + " + gyro", gyroscope=Gyroscope(gyro_noise_std_radps),
                       inclinometer=Inclinometer(0.002))


def _say(msg: str) -> None:
    print(msg, flush=True)


# --- comparison tables ------------------------------------------------------------

def comparison_tables(out: Path, scenarios, layouts, duration_s: float | None, methods, seed: int) -> list[dict]:
    """One comparison per (scenario, layout); free-flight scenarios use their own single-triad array."""
    (out / "tables").mkdir(parents=True, exist_ok=True)
    cases = []
    for scenario in scenarios:
        layout_names = ["single-triad (McGinnis, Perkins & King 2012)"] if scenario in FREE_FLIGHT else layouts
        for layout in layout_names:
            array = None if scenario in FREE_FLIGHT else LAYOUTS[layout]()
            sc_duration = duration_s
            if sc_duration is not None and SCENARIOS[scenario].duration_s is not None:
                sc_duration = min(sc_duration, SCENARIOS[scenario].duration_s)
            t0 = time.perf_counter()
            stem = f"{scenario}__{layout.split(' ')[0]}"
            try:
                log = simulate(scenario, array, duration_s=sc_duration, seed=seed)
                result = compare(log, methods=methods, gyro_noise_std_radps=0.01)
            except Exception as exc:  # noqa: BLE001 - one case failing must not lose the rest of the study
                _say(f"  {stem}: FAILED {type(exc).__name__}: {exc}")
                (out / "tables" / f"{stem}.md").write_text(f"# {stem}\n\nfailed: {type(exc).__name__}: {exc}\n")
                continue
            (out / "tables" / f"{stem}.md").write_text(
                f"# {scenario} on {log.array.name}\n\n{SCENARIOS[scenario].summary}; "
                f"{len(log)} samples at {log.rate_hz:.0f} Hz, seed {seed}.\n\n" + result.to_markdown(), encoding="utf-8")
            (out / "tables" / f"{stem}.csv").write_text(result.to_csv(), encoding="utf-8")
            cases.append({"scenario": scenario, "layout": layout, "stem": stem, "log": log, "result": result})
            _say(f"  {stem}: {len(log)} samples, {time.perf_counter() - t0:.1f} s")
    return cases


def _cell(row: dict, column: str) -> str:
    v = row.get(column, math.nan)
    if row["status"] != "ok":
        return "n/a" if row["status"] == "not applicable" else row["status"]
    return "–" if not np.isfinite(v) else f"{v:.3g}"


def summary_tables(cases: list[dict]) -> str:
    methods = []
    for case in cases:
        for r in case["result"].rows:
            if r["method"] not in methods:
                methods.append(r["method"])
    lines = []
    for column, title in (("w_rmse_norm", "RMSE of ‖ω‖ [rad/s]"), ("dw_rmse_norm", "RMSE of ‖ω̇‖ [rad/s²]"),
                          ("f_rmse_norm", "RMSE of ‖f‖ [m/s²]")):
        lines += [f"### {title}", "", "| case | " + " | ".join(methods) + " |", "|---|" + "---|" * len(methods)]
        for case in cases:
            rows = {r["method"]: r for r in case["result"].rows}
            cells = [_cell(rows[m], column) if m in rows else "" for m in methods]
            lines.append(f"| [{case['stem']}](tables/{case['stem']}.md) | " + " | ".join(cells) + " |")
        lines.append("")
    lines.append("n/a: method not applicable to the array (see each table for the reason). Bound rows: "
                 "√(mean variance) of the bound along the truth.")
    return "\n".join(lines) + "\n"


def time_series_figure(out: Path, cases: list[dict], window_s: float = 3.0) -> list[str]:
    files = []
    for case in cases:
        if case["scenario"] not in ("random3d", "reversal") or not case["layout"].startswith("cube-5cm"):
            continue
        log, result = case["log"], case["result"]
        keep = [m for m in ("integration", "imm", "ml", "smoother") if m in result.estimates]
        if not keep:
            continue
        n = min(len(log), int(round(window_s * log.rate_hz)))
        sl = slice(0, n)
        fig = plots.plot_time_series(log.truth.select(sl), {m: result.estimates[m].select(sl) for m in keep},
                                     quantities=["specific_force_b_mps2", "omega_dot_b_radps2", "omega_b_radps"],
                                     title=f"{case['scenario']} on {log.array.name}: estimates against truth")
        name = f"figures/time_{case['stem']}.png"
        plots.save_figure(fig, out / name)
        files.append(name)
    return files


# --- Lin et al. 2011, Figs. 7-8 -----------------------------------------------------------

def t2_study(out: Path, quick: bool, seed: int) -> tuple[list[str], str]:
    """IMM RMSE against T2 on random3d logs of increasing amplitude; best T2 against a + b + c."""
    amplitudes = [0.75, 1.5, 3.0] if quick else [0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0]
    t2_values = np.linspace(0.5, 30.0, 12 if quick else 40)
    duration = 3.0 if quick else 10.0
    curves, levels, bests, bands = {}, [], [], []
    for i, amp in enumerate(amplitudes):
        log = simulate("random3d", cube_array(0.05, 0.07), duration_s=duration, seed=seed + i, omega_rms_radps=amp)
        rmse = t2_sweep(log, t2_values)
        curves[f"ω rms {amp:g} rad/s"] = rmse
        best, lo, hi = t2_band(t2_values, rmse, 0.2)
        levels.append(motion_level(log))
        bests.append(best)
        bands.append((lo, hi))
    plots.save_figure(plots.plot_t2_rmse(t2_values, curves), out / "figures/imm_rmse_vs_t2.png")
    plots.save_figure(plots.plot_t2_trend(np.array(levels), np.array(bests), np.array(bands)),
                      out / "figures/imm_best_t2_vs_motion.png")
    lines = ["| ω rms [rad/s] | a + b + c [rad²/s²] | T2 min | T2 range within +20 % |", "|---|---|---|---|"]
    for amp, level, best, (lo, hi) in zip(amplitudes, levels, bests, bands):
        lines.append(f"| {amp:g} | {level:.3g} | {best:.3g} | {lo:.3g} – {hi:.3g} |")
    if len(levels) >= 2:
        slope, intercept = np.polyfit(levels, bests, 1)
        lines += ["", f"Trend line: T2 = {slope:.3g} (a + b + c) + {intercept:.3g} "
                      f"(imm defaults: t2_slope, t2_intercept)."]
    return ["figures/imm_rmse_vs_t2.png", "figures/imm_best_t2_vs_motion.png"], "\n".join(lines) + "\n"


# --- McGinnis, Perkins & King 2012, Fig. 5 ---------------------------------------------------------------

def polhode_figures(out: Path, cases: list[dict]) -> list[str]:
    files = []
    for case in cases:
        if case["scenario"] not in FREE_FLIGHT:
            continue
        log, result = case["log"], case["result"]
        paths = {"truth": log.truth.omega_b_radps}
        for m in ("free-flight", "ml", "smoother"):
            if m in result.estimates:
                paths[m] = result.estimates[m].omega_b_radps
        fig = plots.plot_polhode(paths, log.array.body.principal_inertia_kgm2, constants_from="truth")
        name = f"figures/polhode_{case['scenario']}.png"
        plots.save_figure(fig, out / name)
        files.append(name)
    return files


# --- Li et al. 2021, Fig. 5 ---------------------------------------------------------------

def step_size_study(out: Path, quick: bool, seed: int) -> tuple[list[str], str]:
    """Attitude propagated with the gyro or with ω integrated from ω̇ ('pure-integration'), against the step (noise-free)."""
    from gfimu.estimators.gravity import add_orientation

    steps_ms = [1, 3, 5, 7, 9] if quick else [1, 2, 3, 4, 5, 6, 7, 8, 9]
    duration = 4.0 if quick else 10.0
    array = _with_gyro(cube_array(0.05, 0.07))
    tilt = {"gyro (Li et al. 2021 'Gyro')": [], "ω from integrated ω̇ (Li et al. 2021 'Non-gyro')": []}
    accel = {k: [] for k in tilt}
    for h in steps_ms:
        log = simulate("random3d", array, rate_hz=1000.0 / h, duration_s=duration, noise=SensorErrors.none(), seed=seed)
        # Li et al. 2021 starts from a known initial state (eq. 8): give the integration the true ω(0)
        w0 = tuple(float(v) for v in log.truth.omega_b_radps[0])
        motion = make_estimator("pure-integration", initial_omega=w0).estimate(log).motion
        for label, source in zip(tilt, ("gyro", "estimate")):
            ev = evaluate(add_orientation(log, motion, source=source), log.truth)
            tilt[label].append(ev["tilt_rad"].rmse_norm)
            accel[label].append(ev["accel_b_mps2"].rmse_norm)
    steps_s = np.array(steps_ms) * 1e-3
    plots.save_figure(plots.plot_step_size(steps_s, tilt, "RMS tilt error [rad]",
                                           "Attitude propagation (improved Euler) against step size"),
                      out / "figures/step_size_tilt.png")
    plots.save_figure(plots.plot_step_size(steps_s, accel, "RMSE of ‖a‖ [m/s²]",
                                           "Gravity-free acceleration against step size"),
                      out / "figures/step_size_accel.png")
    labels = list(tilt)
    lines = ["| step [ms] | " + " | ".join(f"tilt, {k} [rad]" for k in labels) + " | "
             + " | ".join(f"‖a‖, {k} [m/s²]" for k in labels) + " |", "|---|" + "---|" * (2 * len(labels))]
    for i, h in enumerate(steps_ms):
        lines.append(f"| {h} | " + " | ".join(f"{tilt[k][i]:.3g}" for k in labels) + " | "
                     + " | ".join(f"{accel[k][i]:.3g}" for k in labels) + " |")
    return ["figures/step_size_tilt.png", "figures/step_size_accel.png"], "\n".join(lines) + "\n"


# --- Ho & Lin 2009, §III -----------------------------------------------------------------

def condition_figure(out: Path) -> tuple[list[str], str]:
    sizes = np.logspace(-2, 2, 81)
    curves = {"cube, 4 triads (Ho & Lin 2009)": condition_vs_scale(cube_array(), sizes),
              "MIMU4444 board, 8 triads": condition_vs_scale(mimu4444_array(), sizes)}
    marks = [(1.0, math.sqrt(2), "√2 at 1"), (10.0, 10 * math.sqrt(2), "10√2 at 10"), (0.1, 10.0, "10 at 0.1")]
    plots.save_figure(plots.plot_condition_number(sizes, curves, marks=marks), out / "figures/condition_number.png")
    cube = condition_vs_scale(cube_array(), np.array([0.1, 1.0, 10.0]))
    text = (f"Cube condition number at half edge 0.1, 1, 10 (length unit of S): "
            f"{cube[0]:.4g}, {cube[1]:.4g}, {cube[2]:.4g} (Ho & Lin 2009: 10, √2 = 1.414, 10√2 = 14.14).\n")
    return ["figures/condition_number.png"], text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="folder to write the study to")
    ap.add_argument("--quick", action="store_true", help="short logs and fewer cases")
    ap.add_argument("--scenarios", default=None, help=f"comma-separated among {', '.join(SCENARIOS)}")
    ap.add_argument("--layouts", default=None, help=f"comma-separated among {', '.join(LAYOUTS)}")
    ap.add_argument("--methods", default=None, help="comma-separated methods (default: all)")
    ap.add_argument("--duration-s", type=float, default=None,
                    help="cap on each log's length (default: the scenario's; 2 s with --quick)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    scenarios = args.scenarios.split(",") if args.scenarios else list(QUICK_SCENARIOS if args.quick else SCENARIOS)
    layouts = args.layouts.split(",") if args.layouts else list(QUICK_LAYOUTS if args.quick else LAYOUTS)
    bad = [s for s in scenarios if s not in SCENARIOS] + [lay for lay in layouts if lay not in LAYOUTS]
    if bad:
        ap.error(f"unknown scenario(s) or layout(s): {bad}")
    duration = args.duration_s if args.duration_s is not None else (2.0 if args.quick else None)
    methods = args.methods.split(",") if args.methods else None
    out = Path(args.out)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()

    _say("comparisons:")
    cases = comparison_tables(out, scenarios, layouts, duration, methods, args.seed)
    _say("figures: time series, polhodes, condition number, T2 study, step size")
    figures = time_series_figure(out, cases) + polhode_figures(out, cases)
    cond_files, cond_text = condition_figure(out)
    t2_files, t2_text = t2_study(out, args.quick, args.seed)
    step_files, step_text = step_size_study(out, args.quick, args.seed)

    doc = ["# gfimu accuracy study", "",
           f"{'Quick run' if args.quick else 'Full run'}; seed {args.seed}; "
           f"{time.perf_counter() - t_start:.0f} s on this machine. Command: `python3 tools/study.py "
           + " ".join(argv if argv is not None else sys.argv[1:]) + "`.", "",
           "## All methods on every case", "", summary_tables(cases),
           "## Estimates against truth", ""] + [f"![]({f})" for f in figures if "time_" in f] + [
           "", "## Condition number against layout size (Ho & Lin 2009, §III)", "", cond_text] + [
           f"![]({f})" for f in cond_files] + [
           "", "## IMM threshold T2 (Lin et al. 2011, Figs. 7–8)", "", t2_text] + [f"![]({f})" for f in t2_files] + [
           "", "## Step size, with and without gyro (Li et al. 2021, Fig. 5)", "", step_text] + [
           f"![]({f})" for f in step_files] + [
           "", "## Free-flight polhodes (McGinnis, Perkins & King 2012, Fig. 5)", ""] + [f"![]({f})" for f in figures if "polhode" in f]
    (out / "summary.md").write_text("\n".join(doc) + "\n", encoding="utf-8")
    _say(f"study written to {out}/summary.md in {time.perf_counter() - t_start:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
