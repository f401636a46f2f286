"""Every export layout ``gfimu convert csv`` reads (docs/formats.md), converted from outside through the command:
exit 0, no warning, inputs byte-identical, the readings of the known motion back, the file the report says was
read, and the measured rate in array.toml. The layouts come from tests/csv_exports.py; the real EuRoC rows are
those GTSAM ships (V1_01_easy), laid out as a EuRoC dataset folder."""

from __future__ import annotations

import contextlib
import hashlib
import io
import tomllib
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

from csv_exports import T0_NS, euroc_dataset, motion, phyphox_export, sensor_logger_export
from gfimu import io as gio
from gfimu.cli import main


def _phyphox(style, as_zip, linear):
    def build(tmp: Path):
        src = phyphox_export(tmp / ("export.zip" if as_zip else "export"), style=style, as_zip=as_zip, linear=linear)
        return src, "phyphox", "Linear Accelerometer.csv" if linear else "Accelerometer.csv", 0, 1 if linear else 0
    return build


def _sensorlogger(platform, as_zip, standardised=False):
    def build(tmp: Path):
        src = sensor_logger_export(tmp / ("rec.zip" if as_zip else "rec"), platform, as_zip=as_zip,
                                   standardised=standardised)
        # iOS: Accelerometer.csv plus the Gravity.csv beside it, the specific force as Android's TotalAcceleration
        return (src, "sensorlogger", "TotalAcceleration.csv" if platform == "android" else "Accelerometer.csv",
                T0_NS, 0)
    return build


def _euroc(level):
    def build(tmp: Path):
        root = euroc_dataset(tmp / "MH_01_easy")
        return (root / level if level else root), "euroc", "mav0/imu0/data.csv", None, 0
    return build


CASES = {
    **{f"phyphox-{style}-{'zip' if z else 'folder'}{'-linear' if lin else ''}": _phyphox(style, z, lin)
       for style in ("comma", "tab", "semicolon") for z in (False, True) for lin in (False, True)},
    "sensorlogger-android-folder": _sensorlogger("android", False),
    "sensorlogger-android-zip": _sensorlogger("android", True),
    "sensorlogger-ios-folder": _sensorlogger("ios", False),
    "sensorlogger-ios-zip": _sensorlogger("ios", True),
    "sensorlogger-ios-standardised": _sensorlogger("ios", False, standardised=True),
    "euroc-dataset": _euroc(""),
    "euroc-mav0": _euroc("mav0"),
    "euroc-imu0": _euroc("mav0/imu0"),
}


def snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*"))
            if p.is_file()}


def convert(src: Path, preset: str, out: Path) -> tuple[str, str]:
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        rc = main(["convert", "csv", str(src), "--map", preset, "--out", str(out), "--no-progress"])
    assert rc == 0, stderr.getvalue()
    return stdout.getvalue(), stderr.getvalue()


@pytest.mark.parametrize("case", sorted(CASES))
def test_corpus(tmp_path, case):
    src, preset, read_file, t0_ns, which = CASES[case](tmp_path / "in")
    before = snapshot(tmp_path / "in")
    out, err = convert(src, preset, tmp_path / "log")
    assert err == ""  # no warning: units, rate and scale all plausible
    assert snapshot(tmp_path / "in") == before
    assert f"/{read_file}: " in out
    log = gio.read_log(tmp_path / "log")
    t0 = log.timestamps_ns[0] if t0_ns is None else t0_ns
    expected = motion((log.timestamps_ns - t0) * 1e-9)
    np.testing.assert_allclose(log.accel_mps2, expected[which], rtol=0, atol=1e-8)
    assert log.gyro_b_radps is not None
    np.testing.assert_allclose(log.gyro_b_radps, expected[2], rtol=0, atol=2e-5)
    doc = tomllib.loads((tmp_path / "log" / "array.toml").read_text())
    assert doc["rate_hz"] == 1e9 / float(np.median(np.diff(log.timestamps_ns)))
    assert doc["readings"] == ("linear_acceleration" if which == 1 else "specific_force")


def test_corpus_real_euroc_rows_as_a_dataset_folder(tmp_path):
    """The real V1_01_easy imu0 rows (GTSAM's eqvio_processed_30s.csv), as mav0/imu0/data.csv of a dataset
    folder given whole."""
    from gfimu.datasets.gtsam_recordings import EUROC_FILE, data_dir

    src = data_dir() / EUROC_FILE
    if not src.is_file():
        pytest.skip(f"{src} not found")
    text = src.read_text().splitlines()
    header = text[0].split(",")
    col = {name: header.index(name) for name in ("t_abs", "gx", "gy", "gz", "ax", "ay", "az")}
    rows = [ln.split(",") for ln in text[1:] if ln.startswith("imu,")]
    t_ns = [int((Decimal(r[col["t_abs"]]) * 10**9).to_integral_value()) for r in rows]
    imu = tmp_path / "V1_01_easy" / "mav0" / "imu0"
    imu.mkdir(parents=True)
    (imu / "data.csv").write_text(
        "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],"
        "a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n"
        + "".join(f"{t},{r[col['gx']]},{r[col['gy']]},{r[col['gz']]},{r[col['ax']]},{r[col['ay']]},{r[col['az']]}\n"
                  for t, r in zip(t_ns, rows)))
    before = snapshot(tmp_path / "V1_01_easy")
    out, err = convert(tmp_path / "V1_01_easy", "euroc", tmp_path / "log")
    assert err == "" and snapshot(tmp_path / "V1_01_easy") == before
    assert f"EuRoC: {imu / 'data.csv'}" in out
    log = gio.read_log(tmp_path / "log")
    assert log.timestamps_ns.tolist() == t_ns and len(log) == 6001
    assert log.accel_mps2.tolist() == [[float(r[col[c]]) for c in ("ax", "ay", "az")] for r in rows]
    rate = tomllib.loads((tmp_path / "log" / "array.toml").read_text())["rate_hz"]
    assert rate == pytest.approx(200.0, rel=1e-3)
