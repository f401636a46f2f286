"""``gfimu --help`` and ``--version`` import nothing heavy; heavy libraries load where they are used."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = {"numpy", "scipy", "gtsam", "matplotlib", "numba", "pandas"}


def imported_modules(*args: str, code: str | None = None) -> set[str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cmd = [sys.executable, "-X", "importtime"] + (["-c", code] if code else ["-m", "gfimu", *args])
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    return {line.split("|")[-1].strip() for line in done.stderr.splitlines() if line.startswith("import time:")}


@pytest.mark.parametrize("args", [["--help"], ["--version"], []])
def test_help_and_version_import_no_heavy_library(args):
    if not args:  # bare ``gfimu`` prints the help and exits 2
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        done = subprocess.run([sys.executable, "-m", "gfimu"], capture_output=True, text=True, env=env)
        assert done.returncode == 2 and "COMMAND" in done.stdout
        return
    assert imported_modules(*args) & HEAVY == set()


def test_top_level_help_lists_each_commands_own_summary():
    from gfimu.cli import COMMANDS, SUMMARIES, build_parser

    def summaries(parser):
        sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
        return {a.dest: a.help for a in sub._choices_actions}

    full = summaries(build_parser(""))
    light = summaries(build_parser(None))
    assert set(full) == set(COMMANDS) == set(light)
    assert full == light == SUMMARIES


def test_stub_commands_still_parse_fully_when_named(capsys):
    from gfimu.cli import main

    assert main(["estimate", "--help"]) == 0
    assert "--method" in capsys.readouterr().out
    assert main(["nosuchcommand"]) == 2
    assert "invalid choice: 'nosuchcommand'" in capsys.readouterr().err


def test_the_fixed_lag_smoother_with_the_numpy_engine_does_not_load_gtsam():
    mods = imported_modules(code=(
        "import numpy as np\n"
        "from gfimu.array import cube_array\n"
        "from gfimu.simulate import simulate\n"
        "from gfimu.smoother.stream.fixed_lag import FixedLagEstimator\n"
        "log = simulate('random3d', cube_array(0.05, 0.07), rate_hz=200.0, duration_s=0.5, seed=0)\n"
        "FixedLagEstimator(tune_process_noise=False).estimate(log).motion\n"))
    assert "gtsam" not in mods and "matplotlib" not in mods and "pandas" not in mods


def test_package_attributes_load_on_first_use():
    import gfimu

    from gfimu import Log, Motion, SensorArray  # noqa: F401
    assert {"Log", "Motion", "SensorArray", "__version__"} <= set(dir(gfimu))
    with pytest.raises(AttributeError, match="no attribute 'Nothing'"):
        gfimu.Nothing  # noqa: B018
