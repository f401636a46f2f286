"""``gfimu simulate SCENARIO --out DIR``: write a simulated log (array.toml, imu.csv, truth.csv)."""

from __future__ import annotations

import argparse
import sys
import textwrap

from . import CLIError, add_no_progress, info, show_progress
from .options import integer, non_negative, number, parse_options, positive

ARRAY_CHOICES = ("cube", "paper001", "single-triad", "mimu4444")

MAX_SAMPLES = 2e7
"""The most samples ``gfimu simulate`` writes (5.6 hours at 1 kHz; more would not fit in memory)."""


def _scenario_help() -> str:
    from ..simulate import SCENARIOS

    lines = []
    for s in SCENARIOS.values():
        dur = "whole recording" if s.duration_s is None else f"{s.duration_s:g} s"
        lines.append(f"  {s.name:24s}{s.summary} [{s.rate_hz:g} Hz, {dur}]")
    return "\n".join(lines)


def register(sub: argparse._SubParsersAction) -> None:
    from ..simulate import SCENARIOS, defaults

    p = sub.add_parser(
        "simulate",
        help="write a simulated log (exact rigid-body motion, synthetic readings, truth)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=textwrap.dedent(
            """\
            Simulate a motion seen by an accelerometer array and write a log folder
            (array.toml, imu.csv, truth.csv). Readings are the exact rigid-body
            specific force at each sensor plus the chosen noise; truth holds ω, ω̇,
            the gravity-free acceleration a, the specific force f and the attitude.

            euroc and kitti replay REAL recorded motions (EuRoC V1_01_easy and a
            KITTI drive, shipped with the gtsam package): the recorded gyro and
            specific force, smoothed, become the true motion, and the array's
            readings are SYNTHETIC.

            scenarios (default rate, duration):
            """
        ) + _scenario_help(),
    )
    p.add_argument("scenario", choices=list(SCENARIOS), metavar="SCENARIO", help="motion to simulate (see above)")
    p.add_argument("--out", required=True,
                   help="log folder to write (created when missing; an existing non-empty folder needs --force)")
    p.add_argument("--force", action="store_true",
                   help="write into a non-empty --out folder: its array.toml, imu.csv, truth.csv and reference.csv "
                        "are replaced or removed, other files are kept")
    p.add_argument("--array", default=None,
                   help="cube | paper001 | single-triad | mimu4444 | PATH/array.toml (default: cube, "
                        "or the block's single triad for the freeflight scenarios)")
    p.add_argument("--half-edge-m", type=positive("m"), default=None,
                   help=f"half edge of the cube array [m] (default {defaults.CUBE_HALF_EDGE_M:g})")
    p.add_argument("--rate-hz", type=number(0.0, 100e3, "Hz", low_open=True), default=None,
                   help="sample rate [Hz], at most 100 kHz (default: the scenario's)")
    p.add_argument("--duration-s", type=positive("s"), default=None,
                   help="length [s] (default: the scenario's; at most 2e7 samples with the rate)")
    p.add_argument("--noise-std-mps2", type=non_negative("m/s^2"), default=None,
                   help="white accelerometer noise per axis [m/s^2] (default: the array's noise_std_mps2, "
                        f"{defaults.ACCEL_NOISE_STD_MPS2:g} for the cube; the ADXL330 figures of Ho & Lin 2009 for an "
                        "array.toml without one)")
    p.add_argument("--no-noise", action="store_true", help="exact readings (no sensor errors at all)")
    p.add_argument("--seed", type=integer(0), default=defaults.SEED,
                   help=f"seed of the random motion and noise (default {defaults.SEED})")
    p.add_argument("--option", "-O", action="append", default=[], metavar="KEY=VALUE",
                   help="scenario option, repeatable (e.g. -O spin_radps=20, -O start_s=5)")
    add_no_progress(p)
    p.set_defaults(func=run)


def _array(args):
    from ..array import LAYOUTS
    from ..simulate.defaults import default_cube

    if args.half_edge_m is not None and args.array not in (None, "cube"):
        raise CLIError("--half-edge-m applies to --array cube only")
    if args.half_edge_m is not None and not args.half_edge_m > 0:
        raise CLIError(f"--half-edge-m must be positive, got {args.half_edge_m}")
    if args.array is None:
        return default_cube(args.half_edge_m) if args.half_edge_m is not None else None
    if args.array == "cube":
        return default_cube(args.half_edge_m)
    if args.array in LAYOUTS:
        return LAYOUTS[args.array]()
    from pathlib import Path

    from .. import io as gio

    path = Path(args.array)
    if path.is_dir():
        path = path / "array.toml"
    if not path.is_file():
        raise CLIError(f"--array {args.array!r}: not one of {', '.join(ARRAY_CHOICES)} and no such file")
    return gio.read_array_toml(path)


def run(args) -> int:
    from .. import io as gio
    from ..io.outputs import prepare_log_folder
    from ..simulate import SensorErrors, simulate

    array_input = None
    if args.array is not None and args.array not in ARRAY_CHOICES:
        array_input = args.array
    options = parse_options(args.option)
    if args.no_noise and args.noise_std_mps2 is not None:
        raise CLIError("--no-noise and --noise-std-mps2 exclude each other")
    prepare_log_folder(args.out, [array_input], force=args.force)
    from ..simulate import SCENARIOS

    scenario = SCENARIOS[args.scenario]
    rate = args.rate_hz if args.rate_hz is not None else scenario.rate_hz
    if args.duration_s is not None and args.duration_s * rate > MAX_SAMPLES:
        raise CLIError(f"--duration-s {args.duration_s:g} at {rate:g} Hz is {args.duration_s * rate:.3g} samples; a "
                       f"simulated log holds at most {MAX_SAMPLES:.0e} (give a shorter --duration-s or a lower "
                       "--rate-hz)")
    if args.no_noise:
        noise = SensorErrors.none()
    elif args.noise_std_mps2 is not None:
        noise = SensorErrors.white(args.noise_std_mps2)
    else:
        noise = None
    log = simulate(args.scenario, array=_array(args), rate_hz=args.rate_hz, duration_s=args.duration_s,
                   noise=noise, seed=args.seed, progress=show_progress(args), **options)
    gio.write_log(log, args.out, what="--out")
    info(args, f"{args.scenario}: {len(log)} samples at {log.rate_hz:g} Hz ({log.array.name}, "
          f"{log.array.n_axes} accelerometer axes) -> {args.out}", file=sys.stdout)
    return 0
