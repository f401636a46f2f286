"""``gfimu demo``: the main job on built-in data, with an accuracy table.

Two logs are made in memory: a simulated ``random3d`` motion and the real
EuRoC V1_01_easy motion shipped with GTSAM (real motion, synthetic array
readings), both on the four-triad cube array. Every applicable method runs on
each and the comparison table is printed.
"""

from __future__ import annotations

import argparse
import sys

from .options import integer, number, positive

DEFAULT_METHODS = ("inversion", "integration", "imm", "ml", "smoother", "fixed-lag")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="run every method on built-in data and print an accuracy table",
        description="Simulate a random 3-D motion and replay the real EuRoC V1_01_easy motion (shipped with "
        "GTSAM) through a four-triad cube array, run the estimation methods and print their accuracy.",
    )
    p.add_argument("--methods", default=",".join(DEFAULT_METHODS), help="comma-separated methods")
    p.add_argument("--duration-s", type=positive("s"), default=10.0, help="length of each log [s] (default 10)")
    p.add_argument("--rate-hz", type=number(0.0, 100e3, "Hz", low_open=True), default=500.0,
                   help="sample rate [Hz], at most 100 kHz (default 500)")
    p.add_argument("--half-edge-m", type=positive("m"), default=0.025,
                   help="half edge of the cube array [m] (default 0.025: a 5 cm cube)")
    p.add_argument("--seed", type=integer(0), default=0, help="seed of the motion and noise (default 0)")
    p.add_argument("--format", choices=["markdown", "csv", "json"], default="markdown")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..array import cube_array
    from ..compare import compare
    from ..simulate import simulate

    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    array = cube_array(args.half_edge_m, noise_std_mps2=0.07)
    cases = [
        ("random3d: simulated motion", "random3d"),
        ("euroc: real EuRoC V1_01_easy motion, synthetic array readings", "euroc"),
    ]
    for title, scenario in cases:
        log = simulate(scenario, array=array, rate_hz=args.rate_hz, duration_s=args.duration_s, seed=args.seed)
        result = compare(log, methods=methods, progress=sys.stderr.isatty())
        text = {"markdown": result.to_markdown, "csv": result.to_csv, "json": result.to_json}[args.format]()
        print(f"## {title} ({array.name}, {args.rate_hz:g} Hz, {args.duration_s:g} s, 0.07 m/s² noise)\n")
        print(text)
    return 0
