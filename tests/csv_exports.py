"""Generators of the exact file layouts phone apps and datasets write, for the tests of ``gfimu convert csv``.

Each writes a recording of a known motion so that a test can compare what gfimu reads with what was
recorded. The layouts (file names, header text and quoting, number format, folders and zip archives) are
those of:

- phyphox 1.1.16, an experiment's "CSV (Comma, decimal point)", "CSV (Tabulator, decimal point)" and
  "CSV (Semicolon, decimal comma)" exports: one file per sensor (``Accelerometer.csv``,
  ``Linear Accelerometer.csv``, ``Gyroscope.csv``) with the header
  ``"Time (s)","X (m/s^2)","Y (m/s^2)","Z (m/s^2)"`` (``"X (rad/s)"`` ... for the gyroscope), numbers as
  ``1.234567890E-1``, and a ``meta/`` folder (``device.csv``, ``time.csv``), as a folder or as the zip;
- Sensor Logger (Android and iOS) CSV export: ``time`` (epoch ns), ``seconds_elapsed``, ``z``, ``y``,
  ``x`` in every sensor file; Android writes ``TotalAcceleration.csv`` (with gravity) and
  ``Accelerometer.csv`` (without), iOS only ``Accelerometer.csv`` (without gravity, every axis of the
  opposite sign to Android's) and ``Gravity.csv``; ``Metadata.csv`` names the platform
  (github.com/tszheichoi/awesome-sensor-logger, UNITS.md and COORDINATES.md);
- EuRoC MAV ``mav0/imu0/data.csv``: ``#timestamp [ns],w_RS_S_x [rad s^-1],...,a_RS_S_z [m s^-2]``.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

G = 9.80665
T0_NS = 1_700_000_000_000_000_000


def motion(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(specific force with gravity [m/s²], the same without gravity, angular velocity [rad/s]) of a phone
    held roughly flat and shaken: in Android's convention, +9.81 on z at rest."""
    t = np.asarray(t_s, dtype=float)
    linear = np.column_stack([1.5 * np.sin(2.0 * t), 0.8 * np.cos(3.0 * t), 0.5 * np.sin(1.3 * t)])
    gravity = np.column_stack([0.3 * np.sin(0.5 * t), 0.2 * np.cos(0.4 * t), np.full(t.size, G)])
    gravity *= G / np.linalg.norm(gravity, axis=1, keepdims=True)
    omega = np.column_stack([0.4 * np.cos(0.5 * t), -0.3 * np.sin(0.4 * t), 0.2 + 0.1 * np.sin(t)])
    return linear + gravity, linear, omega


def _phyphox_number(x: float, decimal: str) -> str:
    text = f"{x:.9E}"
    mantissa, exponent = text.split("E")
    out = f"{mantissa}E{int(exponent)}"
    return out.replace(".", ",") if decimal == "," else out


def phyphox_export(path: Path, seconds: float = 4.0, rate_hz: float = 200.0, linear: bool = False,
                   style: str = "comma", as_zip: bool = False, gyro: bool = True, gravity: bool = False) -> Path:
    """phyphox's per-sensor export: a folder, or the zip phyphox writes (``as_zip``); ``style`` is
    "comma", "tab" or "semicolon" (decimal comma). The gyroscope runs on its own clock (3 ms later).
    ``gravity``: also the gravity sensor's ``Gravity.csv`` (same clock as the accelerometer)."""
    delimiter, decimal = {"comma": (",", "."), "tab": ("\t", "."), "semicolon": (";", ",")}[style]
    files: dict[str, str] = {}
    t_acc = np.arange(int(seconds * rate_hz)) / rate_hz + 0.0123
    f, a, _ = motion(t_acc)
    values = a if linear else f
    name = "Linear Accelerometer.csv" if linear else "Accelerometer.csv"
    unit = "m/s^2"
    lines = [delimiter.join(f'"{h}"' for h in ("Time (s)", f"X ({unit})", f"Y ({unit})", f"Z ({unit})"))]
    lines += [delimiter.join(_phyphox_number(v, decimal) for v in (t, *row)) for t, row in zip(t_acc, values)]
    files[name] = "\n".join(lines) + "\n"
    if gravity:
        lines = [lines[0]] + [delimiter.join(_phyphox_number(v, decimal) for v in (t, *row))
                              for t, row in zip(t_acc, f - a)]
        files["Gravity.csv"] = "\n".join(lines) + "\n"
    if gyro:
        t_gyr = np.arange(int(seconds * rate_hz)) / rate_hz + 0.0153
        w = motion(t_gyr)[2]
        lines = [delimiter.join(f'"{h}"' for h in ("Time (s)", "X (rad/s)", "Y (rad/s)", "Z (rad/s)"))]
        lines += [delimiter.join(_phyphox_number(v, decimal) for v in (t, *row)) for t, row in zip(t_gyr, w)]
        files["Gyroscope.csv"] = "\n".join(lines) + "\n"
    files["meta/device.csv"] = '"property","value"\n"version","1.1.16"\n"build","1011602"\n"deviceModel","test"\n'
    files["meta/time.csv"] = ('"event","experiment time","system time","system time text"\n'
                              '"START",0.000000000E0,1.700000000E9,"2023-11-14 22:13:20.000 UTC+00:00"\n')
    if as_zip:
        path.parent.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(path, "w") as z:
            for n, text in files.items():
                z.writestr(n, text)
        return path
    for n, text in files.items():
        (path / n).parent.mkdir(parents=True, exist_ok=True)
        (path / n).write_text(text, encoding="utf-8")
    return path


def sensor_logger_export(path: Path, platform: str = "android", seconds: float = 4.0, rate_hz: float = 100.0,
                         standardised: bool = False, as_zip: bool = False, metadata: bool = True) -> Path:
    """Sensor Logger's CSV export (a folder, or the zip): Android with TotalAcceleration.csv and
    Accelerometer.csv, iOS with Accelerometer.csv and Gravity.csv (iOS signs unless ``standardised``)."""
    n = int(seconds * rate_hz)
    t_ns = T0_NS + (np.arange(n) * (1e9 / rate_hz)).astype(np.int64)
    f, a, w = motion((t_ns - T0_NS) * 1e-9)
    sign = -1.0 if platform == "ios" and not standardised else 1.0
    files: dict[str, str] = {}

    def table(values: np.ndarray) -> str:
        rows = [f"{t},{(t - T0_NS) * 1e-9!r},{v[2]!r},{v[1]!r},{v[0]!r}" for t, v in zip(t_ns.tolist(),
                                                                                     values.tolist())]
        return "time,seconds_elapsed,z,y,x\n" + "\n".join(rows) + "\n"

    files["Accelerometer.csv"] = table(sign * a)
    if platform == "android":
        files["TotalAcceleration.csv"] = table(f)
    files["Gravity.csv"] = table(sign * (f - a))
    files["Gyroscope.csv"] = table(w)
    if metadata:
        files["Metadata.csv"] = ("version,device name,recording epoch time,recording time,recording timezone,"
                                 "platform,appVersion,device id,sensors,sampleRateMs,standardisation,"
                                 "platform version\n"
                                 f"3,test,{T0_NS // 1_000_000},2023-11-14_22-13-20,UTC,{platform},1.41.1,x,"
                                 f"Accelerometer|Gravity|Gyroscope,10|10|10,{str(standardised).lower()},17\n")
    if as_zip:
        path.parent.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(path, "w") as z:
            for name, text in files.items():
                z.writestr(name, text)
        return path
    path.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (path / name).write_text(text, encoding="utf-8")
    return path


def euroc_dataset(path: Path, seconds: float = 2.0, rate_hz: float = 200.0) -> Path:
    """A EuRoC MAV dataset folder ``path/mav0/imu0/data.csv`` (with its sensor.yaml)."""
    n = int(seconds * rate_hz)
    t_ns = 1_403_636_579_758_555_392 + np.arange(n, dtype=np.int64) * 5_000_000
    f, _, w = motion((t_ns - t_ns[0]) * 1e-9)
    imu = path / "mav0" / "imu0"
    imu.mkdir(parents=True)
    rows = ["#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
            "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"]
    rows += [",".join([str(t)] + [repr(v) for v in (*wr, *fr)]) for t, wr, fr in zip(t_ns.tolist(), w.tolist(),
                                                                                   f.tolist())]
    (imu / "data.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    (imu / "sensor.yaml").write_text("sensor_type: imu\nrate_hz: 200\n", encoding="utf-8")
    return path
