"""Kalibr extrinsics: the places of the accelerometers from a Kalibr IMU-chain YAML (``--extrinsics``).

Kalibr's multi-IMU calibration writes one entry per IMU, ``imu0``, ``imu1``,
..., each with ``T_i_b``, a 4×4 homogeneous matrix, and usually the
``rostopic`` the IMU was recorded on. ``T_i_b`` maps body-frame coordinates
to IMU i's frame::

    p_i = R_i_b p_b + t_i_b        T_i_b = [[R_i_b, t_i_b], [0 0 0 1]]

Kalibr's body frame is the frame of its reference IMU, ``imu0`` (its
``T_i_b`` is the identity). So IMU i's origin, where ``p_i = 0``, lies in the
body frame at ``p_b = -R_i_bᵀ t_i_b``, and a vector measured in IMU i's
axes is ``v_b = R_i_bᵀ v_i`` in the body frame: ``position_m = -R_i_bᵀ t_i_b``
and ``rotation_body_sensor = R_i_bᵀ`` in ``array.toml``.

The YAML entries are matched to the array's accelerometers by topic (every
entry's ``rostopic`` equal to one accelerometer's ``topic`` in array.toml, or
to its name with or without a leading ``/``), else by name (entry ``imu1``
for accelerometer ``imu1``), else by order; the report says which. pyyaml is
imported only here (the ``kalibr`` extra).
"""

from __future__ import annotations

import os
import re
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..array import SensorArray
from ..errors import MissingExtraError
from .array_toml import ROTATION_TOLERANCE
from .errors import LogFormatError, LogFormatWarning
from .safe_yaml import MAX_YAML_NODES, OpenCVMatrix, load_yaml  # noqa: F401 (MAX_YAML_NODES: documented bound)

BOTTOM_ROW_TOLERANCE = 1e-9
MAX_TRANSLATION_M = 100.0  # an IMU of one rigid body; beyond, the numbers overflow the model (and are not metres)
ORTHONORMAL_REPAIR_TOLERANCE = 1e-4  # max |RᵀR - I| taken as rounded digits (5 decimals give about 1e-5)


@dataclass(frozen=True)
class KalibrImu:
    """One entry of the IMU chain."""

    key: str
    topic: str | None
    rotation_i_b: np.ndarray  # R_i_b: body -> IMU
    translation_i_b_m: np.ndarray  # t_i_b
    time_offset_s: float | None

    @property
    def position_b_m(self) -> np.ndarray:
        """The IMU's origin in the body frame, ``-R_i_bᵀ t_i_b``."""
        return -self.rotation_i_b.T @ self.translation_i_b_m

    @property
    def rotation_body_sensor(self) -> np.ndarray:
        """``R_i_bᵀ``: ``v_b = R_i_bᵀ v_i``."""
        return self.rotation_i_b.T.copy()


def _line_of(text: str, key: str, after: int = 0) -> int | None:
    """1-based line of the first ``key:`` on or after line ``after`` (None if not found)."""
    for n, line in enumerate(text.splitlines()[max(after - 1, 0):], start=max(after, 1)):
        if re.match(rf"\s*['\"]?{re.escape(key)}['\"]?\s*:", line):
            return n
    return None


def _imu_number(key: str) -> int:
    m = re.fullmatch(r"imu(\d+)", key)
    return int(m.group(1)) if m else 1 << 30


def _matrix(value, where: str, path: Path, line: int | None) -> np.ndarray:
    """A 4x4 float matrix from rows of numbers or an ``!!opencv-matrix``; LogFormatError naming ``where``."""
    if isinstance(value, OpenCVMatrix):
        line = value.line or line
        rows, cols, data = value.get("rows"), value.get("cols"), value.get("data")
        if not (isinstance(rows, int) and isinstance(cols, int) and isinstance(data, list)):
            raise LogFormatError(f"{where}: an !!opencv-matrix needs rows, cols and data (a list), got "
                                 f"{_shown(dict(value))}", path, line, where)
        if (rows, cols) != (4, 4) or len(data) != 16:
            raise LogFormatError(f"{where}: expected a 4x4 !!opencv-matrix with 16 data values, got rows {rows}, "
                                 f"cols {cols}, {len(data)} value(s)", path, line, where)
        value = [data[4 * k:4 * k + 4] for k in range(4)]
    ok = (isinstance(value, list) and len(value) == 4
          and all(isinstance(r, list) and len(r) == 4 and all(_is_number(v) for v in r) for r in value))
    m = np.array(value, dtype=float) if ok else np.zeros(0)
    if not ok or not np.all(np.isfinite(m)):
        raise LogFormatError(f"{where}: expected a 4x4 matrix of finite numbers (four rows of four), got "
                             f"{_shown(value)}", path, line, where)
    return m


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _shown(value, limit: int = 160) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def _rotation(m: np.ndarray, where: str, path: Path, line: int | None) -> np.ndarray:
    """The rotation part of ``m``: as written when orthonormal to ``ROTATION_TOLERANCE``; the nearest rotation,
    with a warning, when within ``ORTHONORMAL_REPAIR_TOLERANCE`` (digits rounded away); else LogFormatError."""
    r = m[:3, :3]
    if np.max(np.abs(r)) > 1.0 + ORTHONORMAL_REPAIR_TOLERANCE:
        raise LogFormatError(f"{where}: not a rigid transform: its rotation part holds {np.max(np.abs(r)):.6g}, "
                             "and no element of a rotation exceeds 1 in size", path, line, where)
    deviation = float(np.max(np.abs(r.T @ r - np.eye(3))))
    det = float(np.linalg.det(r))
    if det <= 0 or deviation > ORTHONORMAL_REPAIR_TOLERANCE:
        raise LogFormatError(f"{where}: not a rigid transform: its rotation part is not a rotation (RᵀR differs "
                             f"from the identity by {deviation:.3g}, determinant {det:.6g}; up to "
                             f"{ORTHONORMAL_REPAIR_TOLERANCE:g} is taken as rounding and repaired)", path, line, where)
    if deviation <= ROTATION_TOLERANCE:
        return r.copy()
    u, _, vt = np.linalg.svd(r)
    fixed = u @ vt
    where_text = f"{path}:{line}" if line else str(path)
    warnings.warn(f"{where_text}: {where}: rotation orthonormal only to {deviation:.2g} (RᵀR - I, rounded digits?); "
                  f"the nearest rotation is used, which moves no element by more than "
                  f"{float(np.max(np.abs(fixed - r))):.2g} (write more digits to silence this)", LogFormatWarning,
                  stacklevel=3)
    return fixed


def _hint(doc: dict) -> str:
    """What else the file looks like, for the message that it holds no IMU chain."""
    if isinstance(doc.get("relative_config_imu"), str):
        return (f"; this looks like an OpenVINS estimator config, whose IMU chain is the file its "
                f"relative_config_imu names ({doc['relative_config_imu']})")
    return ""


def parse_kalibr(doc, text: str, path: str | os.PathLike) -> list[KalibrImu]:
    """The IMU entries of a loaded Kalibr YAML, in chain order (imu0, imu1, ...)."""
    path = Path(path)
    if not isinstance(doc, dict):
        raise LogFormatError("expected a Kalibr IMU chain: entries imu0, imu1, ... each with T_i_b", path)
    for key, value in doc.items():
        if _imu_number(str(key)) < 1 << 30 and not isinstance(value, dict):
            raise LogFormatError(f"{key}: expected an IMU entry (T_i_b, rostopic, ...), got {_shown(value)}", path,
                                 _line_of(text, str(key)), str(key))
    entries = [(k, v) for k, v in doc.items() if isinstance(v, dict) and not isinstance(v, OpenCVMatrix)]
    if not entries:
        raise LogFormatError("no IMU entries (imu0, imu1, ... each with T_i_b, a 4x4 matrix)" + _hint(doc), path)
    entries.sort(key=lambda kv: (_imu_number(str(kv[0])), list(doc).index(kv[0])))
    out = []
    for key, entry in entries:
        key = str(key)
        line = _line_of(text, key)
        if "T_i_b" not in entry:
            found = ", ".join(str(k) for k in entry if str(k).startswith("T_")) or "none"
            camera = (" (a camera entry of a camera-IMU chain: --extrinsics needs the IMU chain)"
                      if any(str(k) in ("T_cam_imu", "T_imu_cam") for k in entry) else "")
            raise LogFormatError(f"{key}: has no T_i_b (the 4x4 body-to-IMU transform Kalibr's IMU chain holds; "
                                 f"transforms found: {found}){camera}", path, line, key)
        line = _line_of(text, "T_i_b", line or 0) or line
        where = f"{key}.T_i_b"
        m = _matrix(entry["T_i_b"], where, path, line)
        if np.max(np.abs(m[3] - [0.0, 0.0, 0.0, 1.0])) > BOTTOM_ROW_TOLERANCE:
            raise LogFormatError(f"{where}: not a rigid transform: its bottom row is {m[3].tolist()}, expected "
                                 "[0, 0, 0, 1]", path, line, where)
        r = _rotation(m, where, path, line)
        far = float(np.max(np.abs(m[:3, 3])))  # no overflow, unlike the norm of 1e200
        if far > MAX_TRANSLATION_M / np.sqrt(3.0) and far * np.linalg.norm(m[:3, 3] / far) > MAX_TRANSLATION_M:
            distance = far * np.linalg.norm(m[:3, 3] / far)
            raise LogFormatError(f"{where}: translation {m[:3, 3].tolist()} m puts the IMU {distance:.3g} m from the "
                                 f"body origin; an IMU of one rigid body lies within {MAX_TRANSLATION_M:g} m (T_i_b's "
                                 "translation is in metres)", path, line, where)
        topic = entry.get("rostopic")
        if topic is not None and not isinstance(topic, str):
            raise LogFormatError(f"{key}.rostopic: expected a topic name, got {_shown(topic)}", path,
                                 _line_of(text, "rostopic", line or 0), f"{key}.rostopic")
        offset = entry.get("time_offset")
        if offset is not None and not (_is_number(offset) and np.isfinite(offset)):
            raise LogFormatError(f"{key}.time_offset: expected a number of seconds, got {_shown(offset)}", path,
                                 _line_of(text, "time_offset", line or 0), f"{key}.time_offset")
        out.append(KalibrImu(key, topic, r, m[:3, 3].copy(), None if offset is None else float(offset)))
    return out


def read_kalibr(path: str | os.PathLike) -> list[KalibrImu]:
    """The IMU entries of a Kalibr IMU-chain YAML file."""
    doc, text = load_yaml(Path(path))
    return parse_kalibr(doc, text, path)


def _match(array: SensorArray, imus: list[KalibrImu]) -> tuple[list[int], str]:
    """For each accelerometer, the index of its entry; and how they were matched."""
    names = [a.name for a in array.accelerometers]
    topics = [getattr(a, "topic", None) for a in array.accelerometers]
    if all(imu.topic for imu in imus):
        keys = []
        for imu in imus:
            t = imu.topic
            hits = [i for i, (n, tp) in enumerate(zip(names, topics)) if tp == t or n in (t, t.lstrip("/"))]
            keys.append(hits[0] if len(hits) == 1 else None)
        if None not in keys and len(set(keys)) == len(keys):
            return [keys.index(i) for i in range(len(names))], "by rostopic"
    by_key = {imu.key: j for j, imu in enumerate(imus)}
    if set(by_key) == set(names):
        return [by_key[n] for n in names], "by name"
    return list(range(len(names))), "by order"


def apply_kalibr(array: SensorArray, imus: list[KalibrImu], path: str | os.PathLike = "kalibr.yaml"
                 ) -> tuple[SensorArray, list[str]]:
    """The array with every accelerometer's position and rotation from its Kalibr entry; and report lines."""
    if len(imus) != len(array.accelerometers):
        raise LogFormatError(f"has {len(imus)} IMU entr{'y' if len(imus) == 1 else 'ies'} "
                             f"({', '.join(i.key for i in imus)}) but the array has {len(array.accelerometers)} "
                             f"accelerometer(s) ({', '.join(a.name for a in array.accelerometers)}); one entry per "
                             "accelerometer is needed", path)
    order, how = _match(array, imus)
    accs = []
    first = imus[0]
    if np.allclose(first.rotation_i_b, np.eye(3), atol=1e-9) and np.allclose(first.translation_i_b_m, 0.0, atol=1e-12):
        body = f"the frame of {first.key} (Kalibr's reference IMU)"
    else:
        body = f"the frame T_i_b maps from ({first.key}'s T_i_b is not the identity: {first.key} is not at its origin)"
    lines = [f"extrinsics: {path}, Kalibr entries matched {how}; body frame = {body}"]
    for acc, j in zip(array.accelerometers, order):
        imu = imus[j]
        accs.append(replace(acc, position_m=imu.position_b_m, rotation_body_sensor=imu.rotation_body_sensor))
        lines.append(f"  {acc.name} <- {imu.key}" + (f" ({imu.topic})" if imu.topic else "")
                     + f": position {np.round(imu.position_b_m, 6).tolist()} m")
        if imu.time_offset_s:
            lines.append(f"  {imu.key}: time_offset {imu.time_offset_s:g} s is not applied")
    return replace(array, accelerometers=tuple(accs)), lines


def kalibr_yaml(array: SensorArray, topics: list[str] | None = None) -> str:
    """Kalibr IMU-chain YAML text of an array's accelerometer places (T_i_b from position and rotation)."""
    try:
        import yaml
    except ImportError:
        raise MissingExtraError("writing Kalibr YAML", "pyyaml", "kalibr") from None

    doc = {}
    for k, acc in enumerate(array.accelerometers):
        r_i_b = np.asarray(acc.rotation_body_sensor, dtype=float).T
        t = np.eye(4)
        t[:3, :3] = r_i_b
        t[:3, 3] = -r_i_b @ np.asarray(acc.position_m, dtype=float)
        entry = {"T_i_b": t.tolist()}
        if topics is not None:
            entry["rostopic"] = topics[k]
        entry["time_offset"] = 0.0
        doc[f"imu{k}"] = entry
    return yaml.safe_dump(doc, sort_keys=False)
