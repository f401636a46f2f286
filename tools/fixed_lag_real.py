#!/usr/bin/env python3
"""The fixed-lag smoother on the real MIMU4444 recordings: ω accuracy against its lag.

For each recording (``data.bin``) given, the plain user's flow: ``gfimu convert mimu4444 data.bin
--out LOG`` in its own process (no calibration), then in this process
(:func:`gfimu.pipeline.estimate_log`) the per-sample method ``ml``, the batch smoother
(``smoother``) and the fixed-lag smoother (``fixed-lag``) at each lag of ``--lags`` (``-O
lag_s=...``), one after the other. Each estimate is scored against the board's gyro reference
(``reference.csv``, the mean of its gyros) as ``gfimu evaluate LOG EST --moving-threshold-radps 2``
scores it (:func:`gfimu.evaluation.evaluate`): the rows whose reference is valid and turns faster
than 2 rad/s; ω RMSE of the error norm, wrong sign (ω_est · ω_ref < 0) and the wall time of the
estimate (reading the log included) and its CPU time (its worker processes included).

Prints one table per recording and whether each meets the two targets:

- at the default lag (``FixedLagEstimator.lag_s``), an ω RMSE below ``ml``'s and under 2 % of the
  samples with the wrong sign;
- at a lag of 1 s, an ω RMSE at most 1.25 times the batch smoother's.

    python3 tools/fixed_lag_real.py                        # the three recordings, every lag (about 20 minutes on 2 cores)
    python3 tools/fixed_lag_real.py --quick                # the first 120 s of each, lags 0.2 and 1 s
    python3 tools/fixed_lag_real.py --recordings DATA.bin --lags 0.2,1 --json lags.json

The default recordings are ``exp_1/data.bin`` ... in ``$GFIMU_MIMU4444_DIR`` or
``../shared/data/mimu4444`` beside the repository; those absent are skipped (said on standard
error). A recording given by name that is not there is an error. A method that fails on a
recording is shown as failed in its table and the exit status is 1.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tools"))

DEFAULT_DIR = Path(os.environ.get("GFIMU_MIMU4444_DIR", REPO.parent / "shared" / "data" / "mimu4444"))
DEFAULT_RECORDINGS = tuple(DEFAULT_DIR / n / "data.bin" for n in ("exp_1", "exp_2", "exp_3"))
LAGS_S = (0.1, 0.2, 0.5, 1.0, 2.0, 3.0)
QUICK_LAGS_S = (0.2, 1.0)
QUICK_SECONDS = 120.0
MOVING_RADPS = 2.0
SIGN_THRESHOLD_RADPS = 0.1  # gfimu evaluate's default --sign-threshold
WRONG_SIGN_LIMIT = 0.02  # target at the default lag
BATCH_LAG_S = 1.0
BATCH_FACTOR = 1.25  # target at BATCH_LAG_S


def default_lag_s() -> float:
    """The fixed-lag smoother's default lag (what ``gfimu live`` and ``--method fixed-lag`` run)."""
    from gfimu.smoother.stream.fixed_lag import FixedLagEstimator

    return float({f.name: f.default for f in dataclasses.fields(FixedLagEstimator)}["lag_s"])


def parse_lags(text: str) -> tuple[float, ...]:
    """``0.2,1`` -> (0.2, 1.0): positive, finite, no repeats, in the order given."""
    lags = []
    for item in text.split(","):
        try:
            lag = float(item)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number of seconds: {item.strip()!r}") from None
        if not (math.isfinite(lag) and lag > 0):
            raise argparse.ArgumentTypeError(f"a lag must be a positive number of seconds, got {item.strip()!r}")
        if lag in lags:
            raise argparse.ArgumentTypeError(f"lag {item.strip()} s is given twice")
        lags.append(lag)
    return tuple(lags)


# --- scoring ---------------------------------------------------------------------------------------

def score(motion, reference, valid: np.ndarray | None, moving_radps: float = MOVING_RADPS) -> dict:
    """ω errors of ``motion`` against ``reference`` as ``gfimu evaluate REF EST --moving-threshold-radps
    MOVING`` computes them: the rows whose reference is valid and |ω_ref| > ``moving_radps``, timestamps
    equal. {"moving": rows compared, "rmse_radps": RMSE of the error norm, "wrong_sign_share":
    share with ω_est · ω_ref < 0}."""
    from gfimu.evaluation import evaluate

    use = np.ones(len(reference), bool) if valid is None else np.array(valid, bool)
    use &= np.linalg.norm(reference.omega_b_radps, axis=1) > moving_radps
    if not np.any(use):
        return {"moving": 0, "rmse_radps": math.nan, "wrong_sign_share": math.nan}
    omega = evaluate(motion, reference, valid=use, sign_threshold_radps=SIGN_THRESHOLD_RADPS)["omega"]
    return {"moving": omega.n, "rmse_radps": omega.rmse_norm, "wrong_sign_share": omega.signs.flipped_share}


# --- the tables ------------------------------------------------------------------------------------

def label(row: dict, default_lag: float) -> str:
    if row["method"] != "fixed-lag":
        return {"smoother": "smoother (batch)"}.get(row["method"], row["method"])
    return f"fixed-lag, lag {row['lag_s']:g} s" + (" (default)" if row["lag_s"] == default_lag else "")


def _cell(text: str) -> str:
    """Text as one markdown table cell: on one line, its bars escaped."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _num(v, fmt: str) -> str:
    return "–" if v is None or not math.isfinite(v) else format(v, fmt)


def with_ratios(rows: list[dict]) -> list[dict]:
    """The rows of one recording, each with ``rmse_over_batch`` (its ω RMSE over the batch smoother's;
    None without a batch figure)."""
    batch = next((r.get("rmse_radps") for r in rows if r["method"] == "smoother" and not r.get("error")), None)
    out = []
    for r in rows:
        ratio = None
        if batch and r.get("rmse_radps") is not None and not r.get("error"):
            ratio = r["rmse_radps"] / batch
        out.append({**r, "rmse_over_batch": ratio})
    return out


def recording_table(rows: list[dict], default_lag: float) -> str:
    """The markdown table of one recording's runs (rows with ``rmse_over_batch``, see :func:`with_ratios`)."""
    lines = ["| method | ω RMSE [rad/s] | wrong sign | time [s] | CPU [s] | RMSE / batch |",
             "|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        if r.get("error"):
            lines.append(f"| {label(r, default_lag)} | failed: {_cell(r['error'])} | | {_num(r.get('time_s'), '.1f')} | "
                         f"{_num(r.get('cpu_s'), '.1f')} | |")
            continue
        share = r["wrong_sign_share"]
        lines.append(f"| {label(r, default_lag)} | {_num(r['rmse_radps'], '.3f')} | "
                     f"{'–' if share is None or not math.isfinite(share) else format(100 * share, '.2f') + ' %'} | "
                     f"{_num(r['time_s'], '.1f')} | {_num(r['cpu_s'], '.1f')} | {_num(r['rmse_over_batch'], '.2f')} |")
    return "\n".join(lines)


def _find(rows: list[dict], method: str, lag: float | None = None) -> dict | None:
    for r in rows:
        if r["method"] == method and (lag is None or r.get("lag_s") == lag):
            return r
    return None


def _usable(r: dict | None) -> bool:
    return r is not None and not r.get("error") and r.get("rmse_radps") is not None and math.isfinite(r["rmse_radps"])


def targets(rows: list[dict], default_lag: float) -> dict:
    """The two targets on one recording's rows: {"default_lag": (verdict, detail), "lag_1s": (verdict,
    detail)}, verdict "PASS", "FAIL" or "not run" (the runs it needs are missing or failed)."""
    out = {}
    fl, ml = _find(rows, "fixed-lag", default_lag), _find(rows, "ml")
    if not (_usable(fl) and _usable(ml)) or fl["wrong_sign_share"] is None or not math.isfinite(fl["wrong_sign_share"]):
        out["default_lag"] = ("not run", f"needs ml and fixed-lag at {default_lag:g} s")
    else:
        ok = fl["rmse_radps"] < ml["rmse_radps"] and fl["wrong_sign_share"] < WRONG_SIGN_LIMIT
        out["default_lag"] = ("PASS" if ok else "FAIL",
                              f"RMSE {fl['rmse_radps']:.3f} vs ml {ml['rmse_radps']:.3f} rad/s, "
                              f"wrong sign {100 * fl['wrong_sign_share']:.2f} %")
    fl1, batch = _find(rows, "fixed-lag", BATCH_LAG_S), _find(rows, "smoother")
    if not (_usable(fl1) and _usable(batch)) or batch["rmse_radps"] <= 0:
        out["lag_1s"] = ("not run", f"needs smoother and fixed-lag at {BATCH_LAG_S:g} s")
    else:
        ratio = fl1["rmse_radps"] / batch["rmse_radps"]
        out["lag_1s"] = ("PASS" if ratio <= BATCH_FACTOR else "FAIL",
                         f"RMSE {fl1['rmse_radps']:.3f} vs batch {batch['rmse_radps']:.3f} rad/s: {ratio:.2f}×")
    return out


def summary_table(verdicts: dict[str, dict], default_lag: float) -> str:
    """The markdown table of the targets, one row per recording (``verdicts``: name -> :func:`targets`)."""
    lines = [f"| recording | lag {default_lag:g} s (default): RMSE below ml's, wrong sign < "
             f"{100 * WRONG_SIGN_LIMIT:g} % | lag {BATCH_LAG_S:g} s: RMSE ≤ {BATCH_FACTOR:g} × batch |",
             "|---|---|---|"]
    for name, v in verdicts.items():
        cells = [f"**{v[k][0]}** ({v[k][1]})" if v[k][0] != "not run" else f"not run ({v[k][1]})"
                 for k in ("default_lag", "lag_1s")]
        lines.append(f"| {name} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines)


# --- running ---------------------------------------------------------------------------------------

def convert(recording: Path, out: Path, env: dict) -> None:
    """``gfimu convert mimu4444 RECORDING --out OUT`` in its own process; exits naming the recording on failure."""
    done = subprocess.run([sys.executable, "-m", "gfimu", "convert", "mimu4444", str(recording), "--out", str(out),
                           "--quiet"], env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"fixed_lag_real: gfimu convert mimu4444 {recording} failed (exit status "
                         f"{done.returncode}): {done.stderr.strip()}")


def first_seconds(log_dir: Path, seconds: float, out: Path) -> int:
    """Write the first ``seconds`` of the log at ``log_dir`` as a log folder ``out`` (the library's
    reader and writer); its sample count."""
    from gfimu import io as gio

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = gio.read_log(log_dir, check=False)
    n = int(np.searchsorted(log.timestamps_ns - log.timestamps_ns[0], int(round(seconds * 1e9)), side="left"))
    gio.write_log(log.select(slice(0, n)), out, rate_hz=log.rate_hz)
    return n


def run_method(log_dir: Path, method: str, options: dict) -> tuple[object | None, float, float, str | None]:
    """(motion or None, wall time [s], CPU time [s], error message or None) of one estimate."""
    from gfimu.errors import InputError
    from gfimu.pipeline import estimate_log

    t0, c0 = time.perf_counter(), cpu_seconds()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run = estimate_log(log_dir, method, options)
    except (InputError, RuntimeError, ValueError, np.linalg.LinAlgError) as exc:
        return None, time.perf_counter() - t0, cpu_seconds() - c0, f"{type(exc).__name__}: {exc}"
    return run.motion, time.perf_counter() - t0, cpu_seconds() - c0, None


def cpu_seconds() -> float:
    """CPU time (user + system) of this process and of its children that have ended (the worker
    processes of the batch smoother and of ``ml``) [s]."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def study(log_dir: Path, name: str, lags: tuple[float, ...], default_lag: float) -> list[dict]:
    """Every method on one converted log, scored; one row each (printed to standard error as it goes)."""
    from gfimu import io as gio

    reference, valid = gio.read_motion_table(log_dir / "reference.csv")
    runs = [("ml", None, {}), ("smoother", None, {})] + [("fixed-lag", lag, {"lag_s": lag}) for lag in lags]
    rows = []
    for method, lag, options in runs:
        motion, wall, cpu, error = run_method(log_dir, method, options)
        row = {"recording": name, "method": method, "lag_s": lag, "time_s": wall, "cpu_s": cpu, "error": error}
        if motion is not None:
            row.update(score(motion, reference, valid))
        rows.append(row)
        shown = error or f"ω RMSE {row['rmse_radps']:.3f} rad/s, wrong sign {100 * row['wrong_sign_share']:.2f} %"
        print(f"fixed_lag_real: {name}: {label(row, default_lag)}: {shown}, {wall:.1f} s", file=sys.stderr, flush=True)
    return rows


def recording_name(path: Path) -> str:
    return path.parent.name if path.name == "data.bin" and path.parent.name else path.name


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--recordings", nargs="+", type=Path, default=None, metavar="DATA.bin",
                    help="MIMU4444 recordings (default: exp_1/data.bin, exp_2/data.bin, exp_3/data.bin in "
                         f"{DEFAULT_DIR}, those present)")
    ap.add_argument("--lags", type=parse_lags, default=None, metavar="S,S,...",
                    help=f"lags of the fixed-lag smoother [s] (default {','.join(f'{x:g}' for x in LAGS_S)}; "
                         f"with --quick {','.join(f'{x:g}' for x in QUICK_LAGS_S)})")
    ap.add_argument("--quick", action="store_true",
                    help=f"the first {QUICK_SECONDS:g} s of each recording, lags {' and '.join(f'{x:g}' for x in QUICK_LAGS_S)} s")
    ap.add_argument("--json", type=Path, default=None, metavar="OUT", help="also write every run's figures as JSON here")
    args = ap.parse_args(argv)
    lags = args.lags or (QUICK_LAGS_S if args.quick else LAGS_S)
    if args.recordings is None:
        recordings = [p for p in DEFAULT_RECORDINGS if p.is_file()]
        for p in DEFAULT_RECORDINGS:
            if not p.is_file():
                print(f"fixed_lag_real: skipped {p}: not found", file=sys.stderr)
        if not recordings:
            print(f"No MIMU4444 recording (exp_1/data.bin ...) in {DEFAULT_DIR}: nothing to do.")
            return 0
    else:
        recordings = list(args.recordings)
        for p in recordings:
            if not p.is_file():
                ap.error(f"--recordings: {p}: no such file")
    if args.json is not None:
        if any(args.json.resolve() == p.resolve() for p in recordings):
            ap.error(f"--json {args.json}: that is an input recording")
        if args.json.exists() and not args.json.is_file():
            ap.error(f"--json {args.json}: not a regular file")

    from bench_env import command_env

    env = command_env(REPO, threads=None)
    default_lag = default_lag_s()
    print("Every estimate in this process, one after the other"
          + (f"; the first {QUICK_SECONDS:g} s of each recording (--quick)" if args.quick else "") + ".")
    everything, verdicts, failed = [], {}, False
    for rec in recordings:
        name = recording_name(rec)
        with tempfile.TemporaryDirectory(prefix="gfimu-fixed-lag-real-") as tmp:
            log_dir = Path(tmp) / "log"
            convert(rec, log_dir, env)
            if args.quick:
                first_seconds(log_dir, QUICK_SECONDS, Path(tmp) / "first")
                log_dir = Path(tmp) / "first"
            rows = with_ratios(study(log_dir, name, lags, default_lag))
        moving = max((r.get("moving", 0) for r in rows), default=0)
        failed |= any(r["error"] for r in rows)
        verdicts[name] = targets(rows, default_lag)
        print(f"\n### {name}\n\n{moving} moving samples (reference valid, |ω_ref| > {MOVING_RADPS:g} rad/s).\n")
        print(recording_table(rows, default_lag), flush=True)
        everything += rows
    print("\n### Targets\n")
    print(summary_table(verdicts, default_lag))
    if args.json is not None:
        clean = [{k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in r.items()}
                 for r in everything]
        args.json.write_text(json.dumps({"default_lag_s": default_lag, "lags_s": list(lags), "quick": args.quick,
                                         "rows": clean,
                                         "targets": {n: {k: list(v) for k, v in t.items()} for n, t in verdicts.items()}},
                                        indent=2) + "\n")
        print(f"written {args.json}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
