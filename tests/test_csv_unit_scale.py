"""A unit misread on a moving log without a still stretch: ``[g]`` over values in m/s² (and values in g under
``[m/s^2]``) is warned about by ``gfimu convert csv``, naming the file, the columns and the unit read, and by
reading the log written; the correct unit, and acceleration without gravity, give no warning."""

from __future__ import annotations

import contextlib
import io
import warnings
from pathlib import Path

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.array import cube_array
from gfimu.cli import main
from gfimu.io.errors import LogPlausibilityWarning
from gfimu.io.plausibility import median_specific_force, still_specific_force
from gfimu.simulate import simulate

G = 9.80665


@pytest.fixture(scope="module")
def moving():
    log = simulate("random3d", array=cube_array(0.05), rate_hz=200.0, duration_s=6.0, seed=3)
    assert still_specific_force(log) is None  # no still stretch: the still check cannot help
    return log


def write_recording(folder: Path, log, header_unit: str, scale: float) -> tuple[Path, Path]:
    """The log's readings times ``scale`` under ``header_unit``, and a map placing the array."""
    folder.mkdir()
    names = log.array.accel_columns
    lines = ["t [ns]," + ",".join(f"{n} [{header_unit}]" for n in names)]
    for t, row in zip(log.timestamps_ns.tolist(), (log.accel_mps2 * scale).tolist()):
        lines.append(f"{t}," + ",".join(repr(v) for v in row))
    (folder / "board.csv").write_text("\n".join(lines) + "\n")
    m = ['format = "gfimu-csv-map/1"', "[time]", 'column = "t"']
    for a in log.array.accelerometers:
        m += ["[[accelerometers]]", f'name = "{a.name}"', f"position_m = {list(map(float, a.position_m))}"]
        m += [f'{ax} = "{a.name}_{ax}"' for ax in "xyz"]
    (folder / "map.toml").write_text("\n".join(m) + "\n")
    return folder / "board.csv", folder / "map.toml"


def run(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(["convert", "csv", *argv])
    return rc, out.getvalue(), err.getvalue()


def test_m_per_s2_values_under_a_g_header(moving, tmp_path):
    csv, cmap = write_recording(tmp_path / "rec", moving, "g", 1.0)
    before = csv.read_bytes()
    rc, out, err = run(str(csv), "--map", str(cmap), "--out", str(tmp_path / "log"))
    assert rc == 0 and csv.read_bytes() == before
    warning = [ln for ln in err.splitlines() if "median |f|" in ln]
    assert len(warning) == 1, err
    m = median_specific_force(moving) * G
    assert f"{csv} (columns 'a1_x [g]', 'a1_y [g]', 'a1_z [g]', ... read as [g])" in warning[0]
    assert f"median |f| = {m:.4g} m/s²" in warning[0]
    assert "likely the values are in m/s² under a [g] unit; give the unit [m/s^2] (in the header or the map)" in warning[0]
    # reading the log written warns too, without a still stretch
    with pytest.warns(LogPlausibilityWarning, match=r"no still stretch, but .* likely m/s² taken for g"):
        gio.read_log(tmp_path / "log")


def test_g_values_under_a_m_per_s2_header(moving, tmp_path):
    csv, cmap = write_recording(tmp_path / "rec", moving, "m/s^2", 1.0 / G)
    rc, out, err = run(str(csv), "--map", str(cmap), "--out", str(tmp_path / "log"))
    assert rc == 0
    warning = [ln for ln in err.splitlines() if "median |f|" in ln]
    assert len(warning) == 1, err
    assert f"median |f| = {median_specific_force(moving) / G:.4g} m/s²" in warning[0]
    assert f"{csv} (columns 'a1_x [m/s^2]', 'a1_y [m/s^2]', 'a1_z [m/s^2]', ... read as [m/s^2])" in warning[0]
    assert "likely the values are in g under an [m/s²] unit; give the unit [g]" in warning[0]


@pytest.mark.parametrize("unit, scale", [("m/s^2", 1.0), ("g", 1.0 / G), ("mg", 1000.0 / G)])
def test_the_right_unit_gives_no_warning(moving, tmp_path, unit, scale):
    csv, cmap = write_recording(tmp_path / "rec", moving, unit, scale)
    rc, out, err = run(str(csv), "--map", str(cmap), "--out", str(tmp_path / "log"))
    assert rc == 0 and err == ""
    with warnings.catch_warnings():
        warnings.simplefilter("error", LogPlausibilityWarning)
        log = gio.read_log(tmp_path / "log")
    np.testing.assert_allclose(log.accel_mps2, moving.accel_mps2, rtol=1e-12, atol=1e-12)


def test_acceleration_without_gravity_is_not_taken_for_a_unit_misread(tmp_path):
    from csv_exports import phyphox_export

    src = phyphox_export(tmp_path / "export", linear=True)
    rc, out, err = run(str(src), "--map", "phyphox", "--out", str(tmp_path / "log"))
    assert rc == 0 and err == ""
