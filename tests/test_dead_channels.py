"""Channels that measure nothing: every reading exactly 0 (dead), one value throughout (constant), or fill values
(-999, the integer limits) are named by ``gfimu diagnose`` (FIX FIRST, never CLEAN) and by a warning line of
``gfimu estimate``, whose exit status stays 0."""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.cli import main
from gfimu.diagnose import diagnose
from gfimu.readings import PLACEHOLDER_VALUES_MPS2, dead_channels
from gfimu.simulate import simulate


@pytest.fixture(scope="module")
def base():
    return simulate("random3d", seed=3, duration_s=2.0)


def run(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(list(argv))
    return rc, out.getvalue(), err.getvalue()


def planted(base, kind: str):
    y = base.accel_mps2.copy()
    if kind == "dead":
        y[:] = 0.0
    elif kind == "constant":
        y[:, 4] = 3.25
    else:
        y[100:160, 7] = -999.0
    return base.replace(accel_mps2=y)


def test_dead_channels_names_each_kind(base):
    columns = base.array.accel_columns
    assert dead_channels(base.accel_mps2, columns) == []  # a noisy log: every channel moves
    found = dead_channels(planted(base, "dead").accel_mps2, columns)
    assert [d.kind for d in found] == ["dead"] * 12 and all(d.samples == len(base) for d in found)
    (one,) = dead_channels(planted(base, "constant").accel_mps2, columns)
    assert (one.column, one.kind, one.value_mps2, one.first_row) == (columns[4], "constant", 3.25, 0)
    (fill,) = dead_channels(planted(base, "placeholder").accel_mps2, columns)
    assert (fill.column, fill.kind, fill.value_mps2, fill.samples, fill.first_row) == (columns[7], "placeholder",
                                                                                         -999.0, 60, 100)
    y = base.accel_mps2.copy()
    y[5, 2] = PLACEHOLDER_VALUES_MPS2[-1]
    assert [d.kind for d in dead_channels(y, columns)] == ["placeholder"]


@pytest.mark.parametrize("kind, text", [
    ("dead", "all 12 of 12 accelerometer channel(s) read exactly 0 in every row"),
    ("constant", "1 of 12 accelerometer channel(s) read one value in every row (a stuck sensor, or a value filled "
                 "in): a2_y = 3.25"),
    ("placeholder", "1 of 12 accelerometer channel(s) hold a fill value (a missing reading written as a number): "
                    "a3_y = -999 (60 rows from row 100)"),
])
def test_diagnose_and_estimate_name_them(tmp_path, base, kind, text):
    log = planted(base, kind)
    d = diagnose(log)
    assert d.verdict.startswith("FIX FIRST: " + text), d.verdict
    assert not d.verdict.startswith("CLEAN")
    assert kind in {f.kind for f in d.faults}
    gio.write_log(log, tmp_path / "log")
    rc, out, err = run("diagnose", str(tmp_path / "log"), "--quiet")
    assert rc == 0 and "verdict: FIX FIRST: " + text in out
    assert "no stuck, clipped, dead or constant channel" not in out
    rc, out, err = run("estimate", str(tmp_path / "log"), "--method", "ml", "--out", str(tmp_path / "e.csv"))
    assert rc == 0, err
    lines = [line for line in err.splitlines() if text in line]
    assert len(lines) == 1 and lines[0].startswith("gfimu estimate: warning: ")
    assert lines[0].endswith("; the estimate from them is not a measurement")


def test_a_linear_acceleration_log_is_not_taken_for_readings_in_g(base):
    """|f| far from 9.81 is a unit mistake only for specific force: a log of linear acceleration (gravity removed)
    reads about 1 m/s² and is no 'readings in g'."""
    from dataclasses import replace

    t = base.truth
    gravity_b = t.specific_force_b_mps2 - t.accel_b_mps2  # -g in B at each sample
    zeros = np.zeros_like(gravity_b)
    f_free = base.accel_mps2 - base.array.predict_readings(gravity_b, zeros, zeros)
    # a hand-held phone's size (median |a| 1.2 m/s²): all readings scaled alike stay a rigid body's (ω by √c)
    f_free *= 1.2 / float(np.median(np.linalg.norm(t.accel_b_mps2, axis=1)))
    specific = diagnose(base.replace(accel_mps2=f_free))
    assert specific.accel_unit_suspect is not None  # taken for specific force, the scale looks wrong
    linear = diagnose(base.replace(accel_mps2=f_free, array=replace(base.array, readings="linear_acceleration")))
    assert linear.accel_unit_suspect is None and not any("readings likely in" in w for w in linear.warnings)
