"""``gfimu simulate`` and ``gfimu demo`` take their array, noise, rate, duration and seed from one place."""

from __future__ import annotations

import numpy as np

from gfimu import io as gio
from gfimu.cli import build_parser, main
from gfimu.cli.demo import demo_logs
from gfimu.simulate import SCENARIOS, defaults, simulate


def test_demo_and_simulate_defaults_agree():
    parser = build_parser("demo")
    args = parser.parse_args(["demo"])
    assert args.rate_hz == defaults.RATE_HZ == SCENARIOS["random3d"].rate_hz == 500.0
    assert args.duration_s == defaults.DURATION_S == SCENARIOS["random3d"].duration_s == 10.0
    assert args.half_edge_m == defaults.CUBE_HALF_EDGE_M == 0.05
    assert args.noise_std_mps2 == defaults.ACCEL_NOISE_STD_MPS2 == 0.07
    sim = build_parser("simulate").parse_args(["simulate", "random3d", "--out", "x"])
    assert args.seed == sim.seed == defaults.SEED == 0
    cube = SCENARIOS["random3d"].default_array()
    assert {a.noise_std_mps2 for a in cube.accelerometers} == {defaults.ACCEL_NOISE_STD_MPS2}
    np.testing.assert_array_equal(np.abs([a.position_m for a in cube.accelerometers]), defaults.CUBE_HALF_EDGE_M)


def test_demo_first_log_is_simulate_random3d(tmp_path):
    """Same readings, bit for bit: what `gfimu simulate random3d` writes is what the demo scores first."""
    assert main(["simulate", "random3d", "--out", str(tmp_path / "log"), "--duration-s", "1", "--quiet"]) == 0
    written = gio.read_log(tmp_path / "log")
    args = build_parser("demo").parse_args(["demo", "--duration-s", "1", "--quiet"])
    title, log = next(iter(demo_logs(args)))
    assert title.startswith("random3d")
    np.testing.assert_array_equal(log.timestamps_ns, written.timestamps_ns)
    np.testing.assert_array_equal(log.accel_mps2, written.accel_mps2)
    assert gio.format_array_toml(log.array) == gio.format_array_toml(written.array)
    python = simulate("random3d", duration_s=1.0)
    np.testing.assert_array_equal(python.accel_mps2, written.accel_mps2)
