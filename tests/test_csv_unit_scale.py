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


def _spun(array, omega_z_radps: float, n: int = 400, rate_hz: float = 200.0):
    """Readings of ``array`` turning at a constant rate about the body z axis through its origin, upright
    (specific force at the origin: gravity's reaction along +z), noise-free."""
    from gfimu.log import Log
    from gfimu.rigid_body import quadratic_terms

    x = np.concatenate([[0.0, 0.0, G], [0.0, 0.0, 0.0], quadratic_terms(np.array([0.0, 0.0, omega_z_radps]))])
    y = np.tile(array.structure_matrix() @ x, (n, 1))
    return Log(array, (np.arange(n) * (1e9 / rate_hz)).astype(np.int64), y, source="spun")


def test_a_fast_spin_of_sensors_off_the_axis_is_no_unit_error():
    """Four triads 0.2 m off a spin axis through the body origin at 20 rad/s: each reads about 8 g of
    centripetal force (their mean too), which a unit check on the raw readings takes for m/s² under [g].
    With the rotation taken out by the per-sample inversion, the origin's |f| is gravity: no warning."""
    from dataclasses import replace

    from gfimu.array import SensorArray
    from gfimu.io.plausibility import check_gravity

    cube = cube_array(0.05)
    off = SensorArray(tuple(replace(a, position_m=np.asarray(a.position_m) + [0.2, 0.0, 0.0])
                            for a in cube.accelerometers), "off-axis cube")
    log = _spun(off, 20.0)
    common = np.linalg.norm(log.accel_mps2.reshape(len(log), 4, 3).mean(axis=1), axis=1)
    assert 8.0 <= np.median(common) / G <= 12.0  # the mean of the raw readings falls in the unit band
    assert median_specific_force(log) == pytest.approx(G, rel=1e-9)
    assert check_gravity(log, "spun") == []


def test_a_single_triad_spun_fast_is_warned_with_both_causes():
    """One triad cannot take its rotation out: 8 g of centripetal force is warned of as a likely unit
    error, and the spin is named as the other cause."""
    from gfimu.array import single_triad
    from gfimu.io.plausibility import check_gravity

    said = check_gravity(_spun(single_triad((0.2, 0.0, 0.0)), 20.0), "spun")
    assert len(said) == 1 and "likely m/s² taken for g" in said[0]
    assert "or the sensors spin fast off the rotation axis" in said[0]
