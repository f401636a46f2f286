#!/usr/bin/env python3
"""Phone exports of linear acceleration: the first attitude against the phone's own gravity vector, and the median
|a| of the gravity-free acceleration, as gfimu read them before ``readings`` (the linear acceleration taken for
the specific force) and now (the export's Gravity.csv added back, or attitude refused).

    python3 tools/phone_exports.py [DIR]     # default $GFIMU_PHONE_EXPORTS_DIR

DIR holds export folders: ``sensorlogger-*`` (Sensor Logger's CSV export: Accelerometer.csv, Gravity.csv,
Gyroscope.csv, Metadata.csv) and ``phyphox-*`` (phyphox's per-sensor export: Linear Accelerometer.csv,
Gyroscope.csv, and Gravity.csv when its gravity sensor was recorded); a ``SOURCE`` file in a folder says where
it comes from. Each step is a ``gfimu`` command in its own process. Without DIR it says so and exits 0.
"""

from __future__ import annotations

import csv
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def gfimu(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gfimu", *args, "--quiet"], capture_output=True, text=True)


def table(path: Path) -> tuple[list[str], np.ndarray]:
    text = path.read_text(encoding="utf-8-sig")
    delimiter = ";" if text.splitlines()[0].count(";") > text.splitlines()[0].count(",") else ","
    rows = list(csv.reader(text.splitlines(), delimiter=delimiter))
    head = [h.strip() for h in rows[0]]
    return head, np.array([[float(v.replace(",", ".")) for v in r] for r in rows[1:] if r])


def xyz(head: list[str], values: np.ndarray) -> np.ndarray:
    """x, y, z columns of a Sensor Logger (x, y, z) or phyphox (X (m/s^2) ...) file."""
    names = [h.split(" ")[0].lower() for h in head]
    return values[:, [names.index(a) for a in "xyz"]]


def sign_of(folder: Path) -> float:
    """-1 for a Sensor Logger iOS export without Standardise (gravity reads -9.81 up), else +1."""
    meta = folder / "Metadata.csv"
    if not meta.is_file():
        return 1.0
    rows = list(csv.reader(meta.read_text(encoding="utf-8").splitlines()))
    doc = {k.strip().lower(): v.strip().lower() for k, v in zip(rows[0], rows[1])}
    return -1.0 if doc.get("platform") == "ios" and doc.get("standardisation", "false") != "true" else 1.0


def estimate(log: Path, out: Path, orientation: bool) -> tuple[str, np.ndarray | None, np.ndarray | None]:
    """(outcome, first up vector in B or None, a (N, 3) or None) of gfimu estimate on ``log``."""
    args = ["estimate", str(log), "--out", str(out)] + (["--orientation", "gyro"] if orientation else [])
    done = gfimu(*args)
    if done.returncode != 0:
        return f"exit {done.returncode}: refused", None, None
    head = out.read_text().splitlines()[0].split(",")
    e = np.loadtxt(out, delimiter=",", skiprows=1, ndmin=2)
    col = {h.split(" ")[0].lstrip("#"): j for j, h in enumerate(head)}
    a = e[:, [col["a_x"], col["a_y"], col["a_z"]]] if "a_x" in col else None
    up = None
    if "q_w" in col:
        w, x, y, z = (e[0, col[f"q_{c}"]] for c in "wxyz")
        up = np.array([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])  # R_WBᵀ e_z
    return "exit 0", up, a


def angle(u: np.ndarray | None, v: np.ndarray | None) -> str:
    if u is None or v is None:
        return "–"
    c = float(np.clip(u @ v / np.linalg.norm(u) / np.linalg.norm(v), -1, 1))
    return f"{np.degrees(np.arccos(c)):.1f}°"


def median_norm(a: np.ndarray | None) -> str:
    return "–" if a is None else f"{np.median(np.linalg.norm(a, axis=1)):.2f}"


def one(folder: Path, work: Path) -> list[str]:
    app = "sensorlogger" if folder.name.startswith("sensorlogger") else "phyphox"
    linear_file = "Accelerometer.csv" if app == "sensorlogger" else "Linear Accelerometer.csv"
    sign = sign_of(folder)
    own = xyz(*table(folder / linear_file)) * sign
    gravity = xyz(*table(folder / "Gravity.csv"))[0] * sign if (folder / "Gravity.csv").is_file() else None
    rows = []
    # before: the linear acceleration alone, recorded as the contract's specific force (as gfimu read it)
    bare = work / f"{folder.name}-bare"
    shutil.copytree(folder, bare)
    (bare / "Gravity.csv").unlink(missing_ok=True)
    done = gfimu("convert", "csv", str(bare), "--map", app, "--out", str(work / "before"))
    if done.returncode != 0:
        raise SystemExit(f"{folder}: convert failed: {done.stderr.strip()}")
    toml = work / "before" / "array.toml"
    toml.write_text(toml.read_text().replace('readings = "linear_acceleration"', 'readings = "specific_force"'))
    outcome, up, a = estimate(work / "before", work / "before.csv", True)
    rows.append((f"{folder.name}", "linear acceleration taken for the specific force (before)",
                 f"--orientation gyro: {outcome}", angle(up, gravity), median_norm(a)))
    # now: the export as it is
    done = gfimu("convert", "csv", str(folder), "--map", app, "--out", str(work / "now"))
    if done.returncode != 0:
        raise SystemExit(f"{folder}: convert failed: {done.stderr.strip()}")
    readings = next(line.split("=")[1].strip().strip('"') for line in (work / "now" / "array.toml").read_text()
                    .splitlines() if line.startswith("readings"))
    outcome, up, a = estimate(work / "now", work / "now.csv", True)
    rows.append((folder.name, f"readings = {readings} (now)", f"--orientation gyro: {outcome}", angle(up, gravity),
                 median_norm(a)))
    if a is None:
        outcome, _, a = estimate(work / "now", work / "now.csv", False)
        rows.append((folder.name, f"readings = {readings} (now)", f"no --orientation: {outcome}", "–",
                     median_norm(a)))
    source = (folder / "SOURCE").read_text().strip() if (folder / "SOURCE").is_file() else "(no SOURCE file)"
    print(f"{folder.name}: {len(own)} rows of {linear_file}; the phone's own linear acceleration: median |a| = "
          f"{np.median(np.linalg.norm(own, axis=1)):.2f} m/s²; gravity: "
          f"{'Gravity.csv' if gravity is not None else 'none in the export'}. Source: {source}")
    return [f"| {' | '.join(r)} |" for r in rows]


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    where = argv[0] if argv else os.environ.get("GFIMU_PHONE_EXPORTS_DIR")
    if not where or not Path(where).is_dir():
        print("Skipped: no folder of phone exports (give DIR or set GFIMU_PHONE_EXPORTS_DIR).")
        return 0
    folders = sorted(p for p in Path(where).iterdir() if p.is_dir() and p.name.startswith(("sensorlogger", "phyphox")))
    lines = ["| export | readings | estimate | first attitude vs the phone's gravity | median \\|a\\| [m/s²] |",
             "|---|---|---|---|---|"]
    for folder in folders:
        with tempfile.TemporaryDirectory() as tmp:
            lines += one(folder, Path(tmp))
    print()
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
