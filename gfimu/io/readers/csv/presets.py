"""The built-in column maps (:data:`PRESETS`: ``euroc``, ``phyphox``, ``sensorlogger``) and the choice of
the files a preset reads from what a folder or export holds; :func:`load_map` takes a map file or a
preset name.
"""

from __future__ import annotations

import csv as _csv
from pathlib import Path

from ...errors import LogFormatError, read_utf8_text
from .column_map import ColumnMap, MAP_FORMAT, parse_map
from .files import Source


PRESETS: dict[str, str] = {
    "euroc": f'''format = "{MAP_FORMAT}"
name = "euroc-imu0"
# mav0/imu0/data.csv of the EuRoC MAV datasets (and TUM-VI): units in the header
[time]
column = "timestamp"
[[accelerometers]]
name = "imu0"
x = "a_RS_S_x"
y = "a_RS_S_y"
z = "a_RS_S_z"
[gyroscope]
x = "w_RS_S_x"
y = "w_RS_S_y"
z = "w_RS_S_z"
''',
    "phyphox": f'''format = "{MAP_FORMAT}"
name = "phyphox"
# phyphox "Acceleration with g" (or "Linear Acceleration") export, one CSV file; a gyroscope
# in the same file is read when present; any of phyphox's CSV exports (comma, tab or semicolon,
# decimal point or comma)
[csv]
decimal = "auto"
[time]
column = "Time"
[[accelerometers]]
name = "phone"
x = ["Acceleration x", "Linear Acceleration x"]
y = ["Acceleration y", "Linear Acceleration y"]
z = ["Acceleration z", "Linear Acceleration z"]
[gyroscope]
optional = true
x = "Gyroscope x"
y = "Gyroscope y"
z = "Gyroscope z"
''',
    "sensorlogger": f'''format = "{MAP_FORMAT}"
name = "sensorlogger"
# Sensor Logger's CSV export, the folder of its files: time in epoch nanoseconds
[time]
column = "time"
unit = "ns"
[[accelerometers]]
name = "phone"
file = "TotalAcceleration.csv"
unit = "m/s^2"
x = "x"
y = "y"
z = "z"
[gyroscope]
optional = true
file = "Gyroscope.csv"
unit = "rad/s"
x = "x"
y = "y"
z = "z"
''',
}
"""Built-in column maps, used with ``--map NAME``."""


_PHYPHOX_SENSORS = f'''format = "{MAP_FORMAT}"
name = "phyphox"
# phyphox's export of a sensor experiment as one CSV file per sensor (a folder, or the zip phyphox writes)
[csv]
decimal = "auto"
[time]
column = "Time"
[[accelerometers]]
name = "phone"
file = {{file}}
x = "X"
y = "Y"
z = "Z"
[gyroscope]
optional = true
file = "Gyroscope.csv"
x = "X"
y = "Y"
z = "Z"
'''


_SENSORLOGGER_ACCELEROMETER = f'''format = "{MAP_FORMAT}"
name = "sensorlogger"
# Sensor Logger's export without TotalAcceleration.csv: Accelerometer.csv, the acceleration without gravity
[time]
column = "time"
unit = "ns"
[[accelerometers]]
name = "phone"
file = "Accelerometer.csv"
unit = "m/s^2"
x = {{ column = "x", sign = {{sign}} }}
y = {{ column = "y", sign = {{sign}} }}
z = {{ column = "z", sign = {{sign}} }}
[gyroscope]
optional = true
file = "Gyroscope.csv"
unit = "rad/s"
x = "x"
y = "y"
z = "z"
'''


def gravity_map(name: str, source: "Source", accel_map: str) -> tuple[str, str] | None:
    """(a one-accelerometer map reading the export's own gravity vector, in the same axes, signs and units as
    ``accel_map`` reads the linear acceleration; the file's name), or None when the export holds none:
    Sensor Logger's Gravity.csv, a phyphox gravity sensor's Gravity.csv."""
    if not source.is_folder or name not in ("sensorlogger", "phyphox"):
        return None
    file = "Gravity.csv"
    if not source.exists(source.folder / file):
        return None
    for linear in ('"Accelerometer.csv"', '"Linear Accelerometer.csv"'):
        if f"file = {linear}" in accel_map:
            return accel_map.replace(f"file = {linear}", f'file = "{file}"', 1), file
    return None


def _metadata(source: "Source", path: Path) -> dict[str, str]:
    """The first row of Sensor Logger's Metadata.csv as {column: value} (empty when unreadable)."""
    try:
        text = source.text(path)
        if text is None:
            text = read_utf8_text(path)
        rows = list(_csv.reader(text.splitlines()))
    except (LogFormatError, OSError):
        return {}
    if len(rows) < 2:
        return {}
    return {k.strip().lower(): v.strip() for k, v in zip(rows[0], rows[1])}


def preset_for(name: str, source: "Source") -> tuple[str, Path, list[str], bool]:
    """(the preset's map text for what ``source`` holds, the input to read, report lines, whether the
    accelerometer file read holds the acceleration without gravity)."""
    folder = source.folder
    if not source.is_folder:
        return PRESETS[name], source.input, [], False
    if name == "euroc":
        for sub in ("mav0/imu0/data.csv", "imu0/data.csv", "data.csv"):
            if source.exists(folder / sub):
                return PRESETS[name], folder / sub, [f"EuRoC: {folder / sub}"], False
        raise LogFormatError("holds no mav0/imu0/data.csv, imu0/data.csv or data.csv (give a EuRoC dataset folder, "
                             "its mav0 or mav0/imu0 folder, or the data.csv)", source.input)
    if name == "phyphox":
        if source.exists(folder / "Raw Data.csv"):
            return PRESETS[name].replace("[csv]\n", '[csv]\nfile = "Raw Data.csv"\n', 1), source.input, [], False
        present = [f for f in ("Accelerometer.csv", "Linear Accelerometer.csv") if source.exists(folder / f)]
        if not present:
            raise LogFormatError("holds neither Accelerometer.csv, Linear Accelerometer.csv nor Raw Data.csv (a "
                                 "phyphox export)", source.input)
        meaning = ("the specific force (gravity included)" if present[0] == "Accelerometer.csv" else
                   "the linear acceleration (gravity removed by the phone), not the specific force: the same at "
                   "every sensor of a rigid body, so ω is unaffected")
        return (_PHYPHOX_SENSORS.replace("{file}", f'"{present[0]}"'), source.input,
                [f"phyphox: {present[0]}, {meaning}"], present[0] != "Accelerometer.csv")
    if name == "sensorlogger":
        if source.exists(folder / "TotalAcceleration.csv") or not source.exists(folder / "Accelerometer.csv"):
            return PRESETS[name], source.input, ["Sensor Logger: TotalAcceleration.csv, the specific force "
                                                 "(gravity included)"], False
        meta_path = next((folder / m for m in ("Metadata.csv", "metadata.csv") if source.exists(folder / m)), None)
        meta = _metadata(source, meta_path) if meta_path is not None else {}
        platform = meta.get("platform", "").lower()
        if platform not in ("ios", "android"):
            raise LogFormatError("holds Accelerometer.csv but no TotalAcceleration.csv, and no Metadata.csv naming "
                                 "the platform (iOS and Android give Accelerometer.csv opposite signs): cannot be "
                                 "read unambiguously", source.input)
        standardised = meta.get("standardisation", "").lower() == "true"
        flip = platform == "ios" and not standardised
        how = ("its signs turned (iOS reports the opposite of Android's convention, +9.81 m/s² up at rest)" if flip
               else "in Android's sign convention" + (" (Standardise Units & Frames on)" if platform == "ios" else ""))
        return (_SENSORLOGGER_ACCELEROMETER.replace("{sign}", "-1" if flip else "1"), source.input,
                [f"Sensor Logger ({meta_path.name}: platform {meta.get('platform')}, app "
                 f"{meta.get('appversion', '?')}): Accelerometer.csv, the acceleration without gravity in m/s², "
                 f"{how}; not the specific force (no TotalAcceleration.csv): the same at every sensor of a rigid "
                 "body, so ω is unaffected"], True)
    return PRESETS[name], source.input, [], False


def load_map(spec: str) -> ColumnMap:
    """The column map of a file or of a preset name."""
    p = Path(spec)
    if not p.exists() and spec in PRESETS:
        return parse_map(PRESETS[spec], f"preset {spec}")
    text = read_utf8_text(spec, missing=f"column map not found (a TOML file, or a preset: {', '.join(sorted(PRESETS))})",
                          folder="is a folder; --map takes a TOML file or a preset name")
    return parse_map(text, spec)


class PresetContext:
    """Errors of a built-in preset name the recording, never a line of the preset's text."""

    def __init__(self, name: str, input_path: Path):
        self.name = name
        self.input = input_path

    def error(self, message: str, table: str = "", index: int = 0, key: str | None = None) -> LogFormatError:
        return LogFormatError(f"{message} (read with the preset {self.name})", self.input)
