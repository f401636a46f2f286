"""``gfimu demo``: the main job on built-in data, with an accuracy table.

Two logs are made in memory: a simulated ``random3d`` motion and the real
EuRoC V1_01_easy motion shipped with GTSAM (real motion, synthetic array
readings), both on the four-triad cube array. Every applicable method runs on
each and the comparison table is printed. The array, noise, rate, duration and
seed default to those of ``gfimu simulate`` (:mod:`gfimu.simulate.defaults`), so
its first log is ``gfimu simulate random3d``'s.
"""

from __future__ import annotations

import argparse

from . import add_no_progress, show_progress
from .options import integer, non_negative, number, positive

DEFAULT_METHODS = ("inversion", "integration", "imm", "ml", "smoother", "fixed-lag")

CASES = (
    ("random3d: simulated motion", "random3d"),
    ("euroc: real EuRoC V1_01_easy motion, synthetic array readings", "euroc"),
)


def register(sub: argparse._SubParsersAction) -> None:
    from ..simulate import defaults

    p = sub.add_parser(
        "demo",
        help="run every method on built-in data and print an accuracy table",
        description="Simulate a random 3-D motion and replay the real EuRoC V1_01_easy motion (shipped with "
        "GTSAM) through a four-triad cube array, run the estimation methods and print their accuracy. The "
        "defaults are gfimu simulate's: with nothing set, the first log is `gfimu simulate random3d`.",
    )
    p.add_argument("--methods", default=",".join(DEFAULT_METHODS),
                   help=f"comma-separated methods (default: {','.join(DEFAULT_METHODS)})")
    p.add_argument("--duration-s", type=positive("s"), default=defaults.DURATION_S,
                   help=f"length of each log [s] (default {defaults.DURATION_S:g})")
    p.add_argument("--rate-hz", type=number(0.0, 100e3, "Hz", low_open=True), default=defaults.RATE_HZ,
                   help=f"sample rate [Hz], at most 100 kHz (default {defaults.RATE_HZ:g})")
    p.add_argument("--half-edge-m", type=positive("m"), default=defaults.CUBE_HALF_EDGE_M,
                   help=f"half edge of the cube array [m] (default {defaults.CUBE_HALF_EDGE_M:g})")
    p.add_argument("--noise-std-mps2", type=non_negative("m/s^2"), default=defaults.ACCEL_NOISE_STD_MPS2,
                   help=f"white accelerometer noise per axis [m/s^2] (default {defaults.ACCEL_NOISE_STD_MPS2:g})")
    p.add_argument("--seed", type=integer(0), default=defaults.SEED,
                   help=f"seed of the motion and noise (default {defaults.SEED})")
    p.add_argument("--format", choices=["markdown", "csv", "json"], default="markdown",
                   help="table format (default: markdown)")
    add_no_progress(p)
    p.set_defaults(func=run)


def demo_logs(args):
    """(title, log) of each case of the demo, simulated in memory with the command's settings, one at a time."""
    from ..array import cube_array
    from ..simulate import simulate

    array = cube_array(args.half_edge_m, noise_std_mps2=args.noise_std_mps2)
    for title, scenario in CASES:
        yield title, simulate(scenario, array=array, rate_hz=args.rate_hz, duration_s=args.duration_s,
                              seed=args.seed, progress=show_progress(args))


def run(args) -> int:
    from ..compare import compare

    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    for title, log in demo_logs(args):
        result = compare(log, methods=methods, progress=show_progress(args))
        text = {"markdown": result.to_markdown, "csv": result.to_csv, "json": result.to_json}[args.format]()
        print(f"## {title} ({log.array.name}, {args.rate_hz:g} Hz, {args.duration_s:g} s, "
              f"{args.noise_std_mps2:g} m/s² noise)\n")
        print(text)
    return 0
