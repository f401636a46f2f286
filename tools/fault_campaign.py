"""A fault campaign: every gfimu command on bad inputs and bad options, each in its own process.

Builds the inputs in a work folder (a simulated log, its files broken one way each: empty, truncated,
binary, huge, NaN, inf, negative, repeated or unsorted times; array.toml, truth.csv, reference.csv,
calibration.toml, column maps, Kalibr YAML, MIMU4444 data.bin, bags with the wrong types; outputs onto
inputs, symbolic links, missing folders and folders) and checks of each run:

- the exit status is 0, 1, 2, 130 or 143, and standard error holds no traceback and no ``internal error``;
- exit 2: exactly one line ``gfimu CMD: error: ...`` on standard error (besides ``gfimu CMD: warning: ...``
  lines said before it), naming a path, option or key;
- the inputs are byte for byte as they were (SHA-256 before and after);
- nothing is written outside the case's output folder;
- no hang (60 s) and bounded memory (the child's address space is limited to 4 GB).

    python tools/fault_campaign.py                 # every case; a table and a summary
    python tools/fault_campaign.py --only csv-     # the cases whose name starts so
    python tools/fault_campaign.py --json out.json

The exit status is 0 when every case passes, 1 otherwise.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TIMEOUT_S = 60.0
MEMORY_BYTES = 4 << 30
EXIT_OK = {0, 1, 2, 130, 143}


@dataclass
class Case:
    name: str
    args: list[str]  # after "gfimu"; "{w}" is the case's folder
    inputs: list[str] = field(default_factory=list)  # paths (relative to the case's folder) that must not change
    stdin: bytes | None = None
    expect: set[int] | None = None  # exit statuses this case must end with (None: any of EXIT_OK)
    setup: object = None  # a function of the case's folder that makes its inputs
    message: str | None = None  # words standard error must hold (the error line, or a warning)
    produces: list[str] = field(default_factory=list)  # files (relative to the case's folder) the run must write
    file_limit: int | None = None  # RLIMIT_FSIZE of the child [bytes]: a disk that fills up at that size

    @property
    def command(self) -> str:
        return self.args[0]


# --- inputs ------------------------------------------------------------------------------------------

def _gfimu_in_process(args: list[str]) -> None:
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
    subprocess.run([sys.executable, "-m", "gfimu", *args], check=True, env=env, capture_output=True)


def build_base(base: Path) -> None:
    """The good inputs every case starts from: a log with truth, one with a reference, a calibration, an
    estimate, a column map and its CSV, a Kalibr YAML, a MIMU4444 data.bin."""
    _gfimu_in_process(["simulate", "random3d", "--out", str(base / "log"), "--rate-hz", "100", "--duration-s", "2",
                       "--quiet", "--no-progress"])
    ref = base / "reflog"
    shutil.copytree(base / "log", ref)
    (ref / "truth.csv").rename(ref / "reference.csv")
    _gfimu_in_process(["estimate", str(base / "log"), "--method", "inversion", "--out", str(base / "est.csv"),
                       "--quiet"])
    sys.path.insert(0, str(REPO))
    import numpy as np

    from gfimu import io as gio
    from gfimu.calibration import Calibration, SensorCalibration, write_calibration

    array = gio.read_array_toml(base / "log" / "array.toml")
    write_calibration(Calibration(tuple(SensorCalibration(a.name, tuple(a.axes), np.eye(3)[[("xyz".index(x)) for x in a.axes]]
                                                          @ np.asarray(a.rotation_body_sensor).T,
                                                          np.zeros(len(a.axes)))
                                        for a in array.accelerometers)), base / "calibration.toml")
    (base / "data.csv").write_text(
        "t [ms],ax,ay,az,bx,by,bz,cx,cy,cz,dx,dy,dz\n"
        + "".join(f"{10 * k},0.1,0.2,9.8,0.1,0.2,9.8,0.1,0.2,9.8,0.1,0.2,9.8\n" for k in range(50)))
    (base / "map.toml").write_text(
        'format = "gfimu-csv-map/1"\nname = "board"\n[csv]\nfile = "data.csv"\n[time]\ncolumn = "t"\n'
        + "".join(f'[[accelerometers]]\nname = "{s}"\nposition_m = {p}\nunit = "m/s^2"\nx = "{s}x"\ny = "{s}y"\n'
                  f'z = "{s}z"\n' for s, p in (("a", "[0.05, 0.05, 0.05]"), ("b", "[0.05, -0.05, -0.05]"),
                                                ("c", "[-0.05, 0.05, -0.05]"), ("d", "[-0.05, -0.05, 0.05]"))))
    shutil.copy(REPO / "tests" / "data" / "kalibr" / "imu-camera_imu.yaml", base / "kalibr.yaml")
    # a MIMU4444 data.bin: the first 64 kB of a real recording when there is one, else none
    real = Path("/work/shared/data/mimu4444/exp_1/data.bin")
    if real.is_file():
        with open(real, "rb") as fh:
            (base / "data.bin").write_bytes(fh.read(1 << 16))


def _edit(path: Path, fn) -> None:
    path.write_text(fn(path.read_text()))


def _rows(path: Path, fn) -> None:
    """Rewrite a CSV file's data rows with ``fn(rows) -> rows``."""
    lines = path.read_text().splitlines()
    path.write_text("\n".join([lines[0]] + fn(lines[1:])) + "\n")


def _imu_rows(w: Path, fn) -> None:
    """Rewrite imu.csv's data rows with ``fn(rows) -> rows``."""
    _rows(w / "log" / "imu.csv", fn)


def _field(rows: list[str], row: int, col: int, value: str) -> list[str]:
    f = rows[row].split(",")
    f[col] = value
    rows[row] = ",".join(f)
    return rows


def _write(rel: str, data: bytes | str):
    def setup(w: Path) -> None:
        p = w / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data if isinstance(data, bytes) else data.encode())
    return setup


def _huge_line(rel: str, keep_header: bool = True):
    def setup(w: Path) -> None:
        p = w / rel
        head = p.read_bytes().split(b"\n", 1)[0] + b"\n" if keep_header else b""
        with open(p, "wb") as fh:
            fh.write(head)
            fh.write(b"\0" * (50 << 20))
    return setup


EST = ["--out", "{w}/out/e.csv"]
LOG_FILES = ["log/array.toml", "log/imu.csv", "log/truth.csv"]


def cases() -> list[Case]:
    """Every case of the campaign."""
    out: list[Case] = []

    def add(name, args, setup=None, inputs=None, stdin=None, expect=None):
        out.append(Case(name, args, list(LOG_FILES if inputs is None else inputs), stdin, expect, setup))

    est = ["estimate", "{w}/log", "--method", "inversion", *EST]
    # imu.csv
    for name, setup in [
        ("imu-empty", _write("log/imu.csv", b"")),
        ("imu-header-only", lambda w: _imu_rows(w, lambda r: [])),
        ("imu-truncated-row", lambda w: _imu_rows(w, lambda r: r[:50] + [r[50][: len(r[50]) // 2]])),
        ("imu-binary", _write("log/imu.csv", bytes(range(256)) * 400)),
        ("imu-nul-50MB", _huge_line("log/imu.csv")),
        ("imu-nan", lambda w: _imu_rows(w, lambda r: _field(r, 10, 2, "nan"))),
        ("imu-all-nan", lambda w: _imu_rows(w, lambda r: [x.split(",")[0] + ",nan" * (len(x.split(",")) - 1)
                                                         for x in r])),
        ("imu-inf", lambda w: _imu_rows(w, lambda r: _field(r, 10, 3, "inf"))),
        ("imu-huge-value", lambda w: _imu_rows(w, lambda r: _field(r, 10, 3, "1e308"))),
        ("imu-huge-values", lambda w: _imu_rows(w, lambda r: [_field(r, k, 1 + k % 12, "-1e300")[k]
                                                              for k in range(len(r))])),
        ("imu-negative-time", lambda w: _imu_rows(w, lambda r: _field(r, 0, 0, "-5"))),
        ("imu-duplicate-time", lambda w: _imu_rows(w, lambda r: _field(r, 5, 0, r[4].split(",")[0]))),
        ("imu-unsorted", lambda w: _imu_rows(w, lambda r: r[:5] + [r[6], r[5]] + r[7:])),
        ("imu-time-text", lambda w: _imu_rows(w, lambda r: _field(r, 3, 0, "abc"))),
        ("imu-time-2e19", lambda w: _imu_rows(w, lambda r: _field(r, 199, 0, "20000000000000000000"))),
        ("imu-extra-field", lambda w: _imu_rows(w, lambda r: [r[0] + ",1"] + r[1:])),
        ("imu-bad-header", lambda w: _imu_rows(w, lambda r: r) or _edit(w / "log" / "imu.csv",
                                                                         lambda t: "x,y\n" + t.split("\n", 1)[1])),
        ("imu-one-row", lambda w: _imu_rows(w, lambda r: r[:1])),
        ("imu-folder", lambda w: ((w / "log" / "imu.csv").unlink(), (w / "log" / "imu.csv").mkdir())),
        ("imu-missing", lambda w: (w / "log" / "imu.csv").unlink()),
        ("imu-constant", lambda w: _imu_rows(w, lambda r: [x.split(",")[0] + ",1.0" * (len(x.split(",")) - 1)
                                                          for x in r])),
    ]:
        add(name, est, setup)
    # array.toml
    for name, text_fn in [
        ("array-empty", lambda t: ""),
        ("array-truncated", lambda t: t[: len(t) // 3]),
        ("array-binary", None),
        ("array-nan-position", lambda t: t.replace("position_m = [", "position_m = [nan, ", 1).replace(
            "[nan, 0.05, ", "[nan, ", 1)),
        ("array-huge-position", lambda t: t.replace("position_m = [", "position_m = [1e300, 1e300, 1e300]\nx_=[", 1)),
        ("array-not-rotation", lambda t: t.replace('axes = ["x", "y", "z"]',
                                                   'rotation_body_sensor = [[1,2,3],[4,5,6],[7,8,9]]', 1)),
        ("array-int-axes", lambda t: t.replace('axes = ["x", "y", "z"]', "axes = 5", 1)),
        ("array-int-accelerometers", lambda t: 'format = "gfimu-array/1"\naccelerometers = 5\n'),
        ("array-deep", lambda t: "x = " + "[" * 5000 + "]" * 5000 + "\n" + t),
        ("array-colocated", lambda t: "".join(
            ln if not ln.startswith("position_m") else "position_m = [0.0, 0.0, 0.0]\n"
            for ln in t.splitlines(keepends=True))),
        ("array-rate-negative", lambda t: t.replace('format = "gfimu-array/1"', 'format = "gfimu-array/1"\nrate_hz = -5', 1)),
    ]:
        if text_fn is None:
            add(name, est, _write("log/array.toml", b"\x00\xff\xfe" * 1000))
        else:
            add(name, est, (lambda f: lambda w: _edit(w / "log" / "array.toml", f))(text_fn))
    # truth.csv / reference.csv with evaluate and compare
    ev = ["evaluate", "{w}/log", "{w}/est.csv"]
    for name, setup in [
        ("truth-empty", _write("log/truth.csv", b"")),
        ("truth-nan", lambda w: _rows(w / "log" / "truth.csv", lambda r: _field(r, 10, 1, "nan"))),
        ("truth-all-nan", lambda w: _rows(w / "log" / "truth.csv", lambda r: [x.split(",")[0] + ",nan" * (
            len(x.split(",")) - 1) for x in r])),
        ("truth-inf", lambda w: _rows(w / "log" / "truth.csv", lambda r: _field(r, 10, 2, "-inf"))),
        ("truth-other-times", lambda w: _edit(w / "log" / "truth.csv",
                                              lambda t: "\n".join(t.splitlines()[:-5]) + "\n")),
        ("truth-binary", _write("log/truth.csv", b"\x89PNG\r\n\x1a\n" + bytes(5000))),
        ("truth-nul-50MB", _huge_line("log/truth.csv")),
    ]:
        add(name, ev, setup, inputs=LOG_FILES + ["est.csv"])
    ref_files = ["reflog/array.toml", "reflog/imu.csv", "reflog/reference.csv", "est.csv"]
    add("reference-bad-valid", ["evaluate", "{w}/reflog", "{w}/est.csv"],
        lambda w: _edit(w / "reflog" / "reference.csv", lambda t: t.replace(",", ",", 0)), inputs=ref_files)
    add("reference-unsorted", ["evaluate", "{w}/reflog", "{w}/est.csv"],
        lambda w: _edit(w / "reflog" / "reference.csv", lambda t: "\n".join(
            t.splitlines()[:3] + [t.splitlines()[4], t.splitlines()[3]] + t.splitlines()[5:]) + "\n"),
        inputs=ref_files)
    add("estimate-file-empty", ev, _write("est.csv", b""), inputs=LOG_FILES + ["est.csv"])
    add("estimate-file-wrong-rows", ev, lambda w: _edit(w / "est.csv", lambda t: "\n".join(t.splitlines()[:20]) + "\n"),
        inputs=LOG_FILES + ["est.csv"])
    add("compare-truth-nan", ["compare", "{w}/log", "--methods", "inversion,ml", "--no-bounds"],
        lambda w: _rows(w / "log" / "truth.csv", lambda r: _field(r, 10, 1, "nan")))
    add("compare-estimates-into-log", ["compare", "{w}/log", "--methods", "inversion", "--estimates-dir", "{w}/log"],
        expect={2})
    add("compare-unknown-method", ["compare", "{w}/log", "--methods", "inversion,nope"], expect={2})
    # calibration.toml
    cal_in = LOG_FILES + ["calibration.toml"]
    cal_est = ["estimate", "{w}/log", "--calibration", "{w}/calibration.toml", "--method", "inversion", *EST]
    for name, fn in [
        ("calibration-empty", lambda t: ""),
        ("calibration-truncated", lambda t: t[: len(t) // 2]),
        ("calibration-nan-gain", lambda t: t.replace("gain = [[1.0", "gain = [[nan", 1)),
        ("calibration-wrong-names", lambda t: t.replace('name = "a1"', 'name = "zz"', 1)),
        ("calibration-deep", lambda t: "x = " + "[" * 5000 + "]" * 5000 + "\n"),
        ("calibration-gravity-negative", lambda t: t + "\n" if "gravity_mps2" not in t else
         t.replace("gravity_mps2 = ", "gravity_mps2 = -", 1)),
        ("calibration-int-sensors", lambda t: 'format = "gfimu-calibration/1"\naccelerometers = 5\n'),
        ("calibration-list-of-ints", lambda t: 'format = "gfimu-calibration/1"\naccelerometers = [5, 6]\n'),
        ("calibration-int-axes", lambda t: t.replace('axes = ["x", "y", "z"]', "axes = 5", 1)),
        ("calibration-nested-axes", lambda t: t.replace('axes = ["x", "y", "z"]', 'axes = [["x"]]', 1)),
        ("calibration-int-gyroscope", lambda t: t.replace("gravity_mps2", "gyroscope = 5\ngravity_mps2", 1)),
    ]:
        add(name, cal_est, (lambda f: lambda w: _edit(w / "calibration.toml", f))(fn), inputs=cal_in)
    # column maps and convert csv
    conv = ["convert", "csv", "{w}/data.csv", "--map", "{w}/map.toml", "--out", "{w}/out/log"]
    conv_in = ["data.csv", "map.toml"]
    for name, setup in [
        ("map-empty", _write("map.toml", "")),
        ("map-int-delimiter", lambda w: _edit(w / "map.toml", lambda t: t.replace("[csv]\n", "[csv]\ndelimiter = [1]\n"))),
        ("map-int-time", lambda w: _edit(w / "map.toml", lambda t: t.replace('column = "t"', "column = [5]"))),
        ("map-int-accelerometers", _write("map.toml", 'format = "gfimu-csv-map/1"\naccelerometers = 5\n')),
        ("map-int-x", lambda w: _edit(w / "map.toml", lambda t: t.replace('x = "ax"', "x = { column = [1] }"))),
        ("map-deep", _write("map.toml", 'format = "gfimu-csv-map/1"\nx = ' + "{a=" * 3000 + "1" + "}" * 3000 + "\n")),
        ("csv-nul-50MB", _huge_line("data.csv")),
        ("csv-binary", _write("data.csv", bytes(range(256)) * 100)),
        ("csv-nan-time", lambda w: _edit(w / "data.csv", lambda t: t.replace("\n20,", "\nnan,"))),
        ("csv-unsorted", lambda w: _edit(w / "data.csv", lambda t: t.replace("\n20,", "\n5,"))),
        ("csv-duplicate-time", lambda w: _edit(w / "data.csv", lambda t: t.replace("\n20,", "\n10,"))),
        ("csv-empty", _write("data.csv", "")),
    ]:
        add(name, conv, setup, inputs=conv_in)
    add("convert-max-gap-nan", conv + ["--max-gap-periods", "nan"], inputs=conv_in, expect={2})
    add("convert-resample-negative", conv + ["--resample-hz", "-1"], inputs=conv_in, expect={2})
    # Kalibr YAML
    kal = conv + ["--extrinsics", "{w}/kalibr.yaml"]
    for name, setup in [
        ("kalibr-empty", _write("kalibr.yaml", "")),
        ("kalibr-binary", _write("kalibr.yaml", b"\xff\xfe\x00" * 100)),
        ("kalibr-deep", _write("kalibr.yaml", "imu0:\n  T_i_b: " + "[" * 5000 + "]" * 5000 + "\n")),
        ("kalibr-not-matrix", _write("kalibr.yaml", "imu0:\n  T_i_b: 5\n  rostopic: /imu0\n")),
        ("kalibr-anchor-bomb", _write("kalibr.yaml", "a: &a [x,x,x,x,x,x,x,x,x]\nb: &b [*a,*a,*a,*a,*a,*a,*a,*a]\n"
                                      "c: &c [*b,*b,*b,*b,*b,*b,*b,*b]\nd: &d [*c,*c,*c,*c,*c,*c,*c,*c]\n"
                                      "e: [*d,*d,*d,*d,*d,*d,*d,*d]\n")),
    ]:
        add(name, kal, setup, inputs=conv_in + ["kalibr.yaml"])
    # MIMU4444
    mimu = ["convert", "mimu4444", "{w}/data.bin", "--out", "{w}/out/log"]
    add("mimu-empty", mimu, _write("data.bin", b""), inputs=["data.bin"])
    add("mimu-garbage", mimu, _write("data.bin", os.urandom(1 << 16)), inputs=["data.bin"])
    add("mimu-truncated", mimu, lambda w: (w / "data.bin").write_bytes((w / "data.bin").read_bytes()[:1001])
        if (w / "data.bin").exists() else _write("data.bin", b"\xaa" * 1001)(w), inputs=["data.bin"])
    add("mimu-text", mimu, _write("data.bin", "timestamp,a,b\n1,2,3\n"), inputs=["data.bin"])
    add("mimu-folder", ["convert", "mimu4444", "{w}/log", "--out", "{w}/out/log"])
    # bags with the wrong types
    bag_array = ["--array", "{w}/log/array.toml"]
    add("bag-text", ["convert", "rosbag", "{w}/x.bag", *bag_array, "--out", "{w}/out/log"],
        _write("x.bag", "#ROSBAG V2.0\nnot a bag\n"), inputs=LOG_FILES + ["x.bag"])
    add("bag-sqlite-garbage", ["convert", "rosbag", "{w}/bag2", *bag_array, "--out", "{w}/out/log"],
        _write("bag2/bag2_0.db3", b"SQLite format 3\x00" + bytes(2000)), inputs=LOG_FILES + ["bag2/bag2_0.db3"])
    add("bag-mcap-garbage", ["convert", "rosbag", "{w}/x.mcap", *bag_array, "--out", "{w}/out/log"],
        _write("x.mcap", b"\x89MCAP0\r\n" + bytes(3000)), inputs=LOG_FILES + ["x.mcap"])
    add("bag-wrong-types", ["convert", "rosbag", "{w}/bag3", *bag_array, "--out", "{w}/out/log"],
        _make_wrong_type_bag, inputs=LOG_FILES)
    for fault in ("nan", "huge", "back", "zero"):
        add(f"bag-imu-{fault}", ["convert", "rosbag", "{w}/bag", "--array", "{w}/bagarray.toml", "--out",
                                 "{w}/out/log"], _imu_bag(fault), inputs=LOG_FILES, expect={0})
    # bad options
    for name, args, expect in [
        ("opt-unknown-method", ["estimate", "{w}/log", "--method", "nope", *EST], {2}),
        ("opt-unknown-key", ["estimate", "{w}/log", "--method", "ml", "-O", "nope=1", *EST], {2}),
        ("opt-no-equals", ["estimate", "{w}/log", "--method", "ml", "-O", "nope", *EST], {2}),
        ("opt-nan", ["estimate", "{w}/log", "--method", "smoother", "-O", "window_s=nan", *EST], {2}),
        ("opt-huge-value", ["estimate", "{w}/log", "--method", "smoother", "-O", "window_s=" + "a" * 129_000, *EST], {2}),
        ("opt-initial-omega", ["estimate", "{w}/log", "--method", "integration", "-O", "initial_omega=1,2,3", *EST],
         {0}),
        ("opt-initial-omega-short", ["estimate", "{w}/log", "--method", "integration", "-O", "initial_omega=[1,2]",
                                     *EST], {2}),
        ("opt-axis-factors-text", ["estimate", "{w}/log", "--method", "smoother", "-O",
                                   "process_axis_factors=abc", *EST], {2}),
        ("opt-factor-groups", ["estimate", "{w}/log", "--method", "smoother", "-O", "factor_groups=3", *EST], {2}),
        ("opt-ml-grid-zero", ["estimate", "{w}/log", "--method", "ml", "-O", "grid_directions=0", *EST], {2}),
        ("opt-ml-max-omega-zero", ["estimate", "{w}/log", "--method", "ml", "-O", "max_omega_radps=0", *EST], {2}),
        ("opt-fixed-lag-tune-zero", ["estimate", "{w}/log", "--method", "fixed-lag", "-O", "tune_window_s=0", *EST],
         {2}),
        ("opt-smoother-window-1e308", ["estimate", "{w}/log", "--method", "smoother", "-O", "window_s=1e308", *EST],
         {2}),
        ("opt-smoother-noise-1e-320", ["estimate", "{w}/log", "--method", "smoother", "-O",
                                       "initial_omega_std_radps=1e-320", *EST], {2}),
        ("opt-smoother-random-walk-1e-90", ["estimate", "{w}/log", "--method", "smoother", "-O",
                                           "omega_dot_random_walk_radps2_per_sqrt_s=1e-90", *EST], {2}),
        ("opt-fixed-lag-lag-1e20", ["estimate", "{w}/log", "--method", "fixed-lag", "-O", "lag_s=1e20", *EST], {2}),
        ("opt-window-negative", ["estimate", "{w}/log", "--method", "smoother", "-O", "window_s=-1", *EST], {2}),
        ("opt-simulate-rate-zero", ["simulate", "random3d", "--rate-hz", "0", "--out", "{w}/out/s"], {2}),
        ("opt-simulate-huge-duration", ["simulate", "random3d", "--duration-s", "1e12", "--out", "{w}/out/s"], {2}),
        ("opt-simulate-unknown", ["simulate", "nope", "--out", "{w}/out/s"], {2}),
        ("opt-plot-window", ["plot", "{w}/log", "--start-s", "5", "--end-s", "1", "--out", "{w}/out/p.png"], {2}),
        ("opt-calibrate-window", ["calibrate", "{w}/log", "--window-s", "-1", "--out", "{w}/out/c.toml"], {2}),
        ("opt-batch-workers", ["batch", "{w}/log", "--workers", "0", "--out", "{w}/out/b"], {2}),
        ("opt-live-lag", ["live", "--array", "{w}/log/array.toml", "--source", "-", "--lag-s", "-1", "--out",
                          "{w}/out/l.csv"], {2}),
        ("opt-diagnose-huge", ["diagnose", "{w}/log", "--calibration", "x" * 5000], {2}),
    ]:
        add(name, args, expect=expect)
    # outputs onto inputs, symbolic links, missing folders, folders
    for name, args, setup, expect in [
        ("out-onto-imu", ["estimate", "{w}/log", "--method", "inversion", "--out", "{w}/log/imu.csv"], None, {2}),
        ("out-onto-array", ["diagnose", "{w}/log", "--out", "{w}/log/array.toml"], None, {2}),
        ("out-symlink-to-input", ["estimate", "{w}/log", "--method", "inversion", "--out", "{w}/out/link.csv"],
         lambda w: os.symlink(w / "log" / "imu.csv", w / "out" / "link.csv"), {2}),
        ("out-missing-folder", ["estimate", "{w}/log", "--method", "inversion", "--out", "{w}/out/no/e.csv"], None, {2}),
        ("out-is-folder", ["estimate", "{w}/log", "--method", "inversion", "--out", "{w}/out"], None, {2}),
        ("out-evaluate-onto-estimate", ["evaluate", "{w}/log", "{w}/est.csv", "--out", "{w}/est.csv"], None, {2}),
        ("out-simulate-onto-log", ["simulate", "random3d", "--out", "{w}/log"], None, {2}),
        ("out-convert-onto-array", ["convert", "csv", "{w}/data.csv", "--map", "{w}/map.toml", "--array",
                                    "{w}/log/array.toml", "--out", "{w}/log", "--force"], None, {2}),
        ("out-convert-onto-csv", ["convert", "csv", "{w}/log/imu.csv", "--map", "{w}/map.toml", "--out", "{w}/log",
                                  "--force"], None, {2}),
        ("out-estimate-dir-symlink-loop", ["estimate", "{w}/log", "--method", "inversion", "--out",
                                           "{w}/out/loop/e.csv"],
         lambda w: os.symlink(w / "out" / "loop", w / "out" / "loop"), {2}),
        ("out-compare-onto-log-file", ["compare", "{w}/log", "--methods", "inversion", "--out", "{w}/log/truth.csv"],
         None, {2}),
        ("out-calibrate-onto-log", ["calibrate", "{w}/log", "--out", "{w}/log/imu.csv"], None, {2}),
        ("out-plot-onto-estimate", ["plot", "{w}/log", "{w}/est.csv", "--out", "{w}/est.csv"], None, {2}),
        ("out-batch-onto-log", ["batch", "{w}/log", "--method", "inversion", "--out", "{w}/log"], None, {2}),
        ("out-batch-inside-log", ["batch", "{w}/log", "--method", "inversion", "--out", "{w}/log/b"], None, {2}),
        ("out-live-onto-array", ["live", "--array", "{w}/log/array.toml", "--source", "-", "--out",
                                 "{w}/log/array.toml"], None, {2}),
        ("out-tum-onto-truth", ["estimate", "{w}/log", "--method", "inversion", "--orientation", "gyro", "--tum",
                                "{w}/log/truth.csv", *EST], None, {2}),
    ]:
        add(name, args, setup, inputs=LOG_FILES + ["est.csv", "data.csv", "map.toml"], expect=expect)
    # the other commands on broken readings
    huge = lambda w: _imu_rows(w, lambda r: _field(r, 10, 3, "1e308"))  # noqa: E731
    nan_column = lambda w: _imu_rows(w, lambda r: [_field(r, k, 2, "nan")[k] for k in range(len(r))])  # noqa: E731
    for name, args, setup in [
        ("smoother-huge-value", ["estimate", "{w}/log", "--method", "smoother", *EST], huge),
        ("fixed-lag-huge-value", ["estimate", "{w}/log", "--method", "fixed-lag", *EST], huge),
        ("ml-nan-column", ["estimate", "{w}/log", "--method", "ml", *EST], nan_column),
        ("diagnose-huge-value", ["diagnose", "{w}/log"], huge),
        ("diagnose-nan-column", ["diagnose", "{w}/log"], nan_column),
        ("diagnose-array-deep", ["diagnose", "{w}/log"],
         lambda w: _edit(w / "log" / "array.toml", lambda t: "x = " + "[" * 3000 + "]" * 3000 + "\n" + t)),
        ("calibrate-nan-column", ["calibrate", "{w}/log", "--out", "{w}/out/c.toml"], nan_column),
        ("calibrate-no-still", ["calibrate", "{w}/log", "--out", "{w}/out/c.toml"], None),
        ("plot-nan-column", ["plot", "{w}/log", "--out", "{w}/out/p.png"], nan_column),
        ("plot-estimate-binary", ["plot", "{w}/log", "{w}/est.csv", "--out", "{w}/out/p.png"],
         _write("est.csv", bytes(range(256)) * 10)),
        ("compare-huge-value", ["compare", "{w}/log", "--methods", "inversion,ml,smoother", "--no-bounds"], huge),
        ("simulate-array-broken", ["simulate", "random3d", "--array", "{w}/log/array.toml", "--out", "{w}/out/s"],
         lambda w: _edit(w / "log" / "array.toml", lambda t: t.replace("position_m", "position_m = 5\nx", 1))),
        ("batch-one-broken-log", ["batch", "{w}/log", "{w}/reflog", "--method", "inversion", "--out", "{w}/out/b",
                                  "--workers", "1"], _write("log/imu.csv", b"")),
        ("evaluate-errors-out-onto-truth", ["evaluate", "{w}/log", "{w}/est.csv", "--errors-out",
                                            "{w}/log/truth.csv"], None),
    ]:
        add(name, args, setup, inputs=LOG_FILES + ["est.csv", "reflog/imu.csv", "reflog/array.toml"])
    # every command once on a good log (the baseline of the campaign)
    for name, args in [
        ("ok-estimate", est),
        ("ok-diagnose", ["diagnose", "{w}/log", "--out", "{w}/out/d.txt"]),
        ("ok-evaluate", ev),
        ("ok-convert", conv),
        ("ok-batch", ["batch", "{w}/log", "--method", "inversion", "--out", "{w}/out/b", "--workers", "1"]),
    ]:
        add(name, args, inputs=LOG_FILES + ["est.csv", "data.csv", "map.toml"], expect={0})
    # live over standard input
    out.extend(containment_cases())
    live = ["live", "--array", "{w}/log/array.toml", "--source", "-", "--out", "{w}/out/l.csv"]
    add("live-binary", live, stdin=os.urandom(20000))
    add("live-empty", live, stdin=b"")
    add("live-nul", live, stdin=b"\0" * (5 << 20))
    add("live-bad-header", live, stdin=b"a,b,c\n1,2,3\n")
    add("live-huge-values", live, None)
    out[-1].setup = _live_huge_stdin
    add("live-nan-rows", live, None, stdin=None)
    out[-1].setup = _live_nan_stdin
    add("live-unsorted", live, None)
    out[-1].setup = _live_unsorted_stdin
    return out


def containment_cases() -> list[Case]:
    """live and batch against a careless user, units by any factor, bounded resources, and one line per message
    case (each with the words its line must hold)."""
    out: list[Case] = []
    logs = LOG_FILES + ["est.csv", "data.csv", "map.toml"]

    def add(name, args, setup=None, expect=None, message=None, inputs=None, stdin=None, produces=(), file_limit=None):
        out.append(Case(name, args, list(logs if inputs is None else inputs), stdin, expect, setup, message,
                        list(produces), file_limit))

    batch = ["batch", "--method", "inversion", "--workers", "1"]
    add("batch-link-in-out", batch + ["{w}/log", "--out", "{w}/out/b"], _link_in_out, {2}, "is a symbolic link")
    add("batch-same-folder-names", batch + ["{w}/a/log", "{w}/b/log", "{w}/c/log-2", "--out", "{w}/out/b"],
        _three_logs, {0}, produces=["out/b/a__log/estimate.csv", "out/b/b__log/estimate.csv",
                                    "out/b/log-2/estimate.csv", "out/b/summary.csv"])
    add("batch-log-twice", batch + ["{w}/log", "{w}/log/", "--out", "{w}/out/b"], None, {2}, "given twice")
    add("batch-log-named-summary", batch + ["{w}/summary.csv", "--out", "{w}/out/b"],
        lambda w: shutil.copytree(w / "log", w / "summary.csv"), {0},
        produces=["out/b/summary.csv"])
    add("batch-scheduler-ssh", batch + ["{w}/log", "--out", "{w}/out/b", "--scheduler", "tcp://127.0.0.1:{port}"],
        _ssh_peer, {2}, "not a Dask scheduler")
    live = ["live", "--array", "{w}/log/array.toml", "--out", "{w}/out/l.csv"]
    add("live-g-header", live + ["--source", "-"], _live_g_header, {0}, "× gravity")
    add("live-guard-replace", live + ["--source", "-", "-O", "guard=replace"], None, {2}, "-O guard=replace")
    add("live-udp-no-port", live + ["--source", "udp://127.0.0.1"], None, {2}, "give the port")
    add("live-serial-baud-negative", live + ["--source", "serial:///dev/null?baud=-5"], None, {2}, "baud=-5")
    add("live-1ns-steps", live + ["--source", "-"], _live_1ns, {2}, "beyond any IMU")
    add("live-rate-1e9", live + ["--source", "-", "--rate-hz", "1e9"], None, {2}, "--rate-hz")
    est = ["estimate", "{w}/log", "--method", "inversion", *EST]
    add("array-400-digit-position", est, lambda w: _edit(w / "log" / "array.toml", lambda t: t.replace(
        "position_m = [", "position_m = [" + "9" * 400 + ", ", 1).replace("9" * 400 + ", 0.05, ", "9" * 400 + ", ", 1)),
        {2}, "position_m")
    add("array-range-tiny", est, lambda w: _edit(w / "log" / "array.toml", lambda t: t.replace(
        "noise_std_mps2 = 0.07", "noise_std_mps2 = 0.07\nrange_mps2 = 1e-300", 1)), {2}, "range_mps2")
    add("array-noise-1e300", est, lambda w: _edit(w / "log" / "array.toml", lambda t: t.replace(
        "noise_std_mps2 = 0.07", "noise_std_mps2 = 1e300", 1)), {2}, "noise_std_mps2")
    add("imu-underscore-number", est, lambda w: _imu_rows(w, lambda r: _field(r, 4, 2, "1_0.5")), {2}, "'1_0.5'")
    add("imu-cr-line-ends", est, lambda w: (w / "log" / "imu.csv").write_bytes(
        (w / "log" / "imu.csv").read_bytes().replace(b"\n", b"\r")), {0})
    add("imu-1ns-steps-fixed-lag", ["estimate", "{w}/log", "--method", "fixed-lag", *EST],
        lambda w: _imu_rows(w, lambda r: [f"{k}," + x.split(",", 1)[1] for k, x in enumerate(r)]), {2},
        "beyond any IMU")
    add("opt-axis-frequency-1e308", ["estimate", "{w}/log", "--method", "smoother", "-O",
                                     "process_axis_frequencies_hz=1e308,0,0", *EST], None, {2},
        "process_axis_frequencies_hz")
    conv = ["convert", "csv", "{w}/data.csv", "--map", "{w}/map.toml", "--out", "{w}/out/log"]
    add("map-column-twice", conv, lambda w: _edit(w / "map.toml", lambda t: t.replace('y = "ay"', 'y = "ax"', 1)),
        {2}, "mapped to a.x already", inputs=["data.csv", "map.toml"])
    add("map-mg-over-mps2", conv, _moving_csv_mg, {0}, "likely the values are in m/s², not [mg]",
        inputs=["data.csv", "map.toml"])
    add("mimu-one-packet", ["convert", "mimu4444", "{w}/data.bin", "--out", "{w}/out/log"],
        lambda w: (w / "data.bin").write_bytes((w / "data.bin").read_bytes()[:120]) if (w / "data.bin").exists()
        else _write("data.bin", b"")(w), {2}, "data.bin", inputs=["data.bin"])
    add("kalibr-large-no-alias", conv + ["--extrinsics", "{w}/kalibr.yaml"], _write(
        "kalibr.yaml", "imu0:\n  T_i_b: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n  rostopic: /imu0\n  junk: ["
        + ",".join(["1.5"] * 300_000) + "]\n"), {2}, "values", inputs=["data.csv", "map.toml", "kalibr.yaml"])
    add("mimu-random-counters", ["convert", "mimu4444", "{w}/data.bin", "--out", "{w}/out/log"], _random_counters,
        {0}, "the packet counter does not count", inputs=["data.bin"])
    add("live-tcp-garbage", ["live", "--array", "{w}/log/array.toml", "--source", "tcp://127.0.0.1:{port}", "--out",
                             "{w}/out/l.csv"], _garbage_peer, {0}, "1 bad rows")
    phyphox = ["convert", "csv", "{w}/export.zip", "--map", "phyphox", "--out", "{w}/out/log"]
    add("zip-bomb", phyphox, _zip_bomb, {2}, "zip bomb", inputs=["export.zip"])
    add("zip-member-twice", phyphox, _zip_twice, {2}, "2 times", inputs=["export.zip"])
    add("simulate-full-disk", ["simulate", "reversal", "--duration-s", "5", "--out", "{w}/out/s"], None, {1},
        "imu.csv", inputs=[], file_limit=1 << 16)
    return out


def _link_in_out(w: Path) -> None:
    (w / "elsewhere").mkdir()
    (w / "out" / "b").mkdir()
    os.symlink("../../elsewhere", w / "out" / "b" / "log")


def _three_logs(w: Path) -> None:
    for rel in ("a/log", "b/log", "c/log-2"):
        shutil.copytree(w / "log", w / rel)


_PEERS: list = []


def _ssh_peer(w: Path) -> None:
    """A TCP server in this process that greets like an SSH server and never says more; its port in the case's
    arguments (``{port}``)."""
    import socket
    import threading

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    _PEERS.append(srv)

    def serve():
        while True:
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            _PEERS.append(conn)
            conn.sendall(b"SSH-2.0-OpenSSH_9.6\r\n")

    threading.Thread(target=serve, daemon=True).start()
    (w / "port").write_text(str(srv.getsockname()[1]))


def _garbage_peer(w: Path) -> None:
    """A TCP server in this process that sends 64 KiB of random bytes to the first connection and closes it."""
    import socket
    import threading

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    _PEERS.append(srv)
    data = os.urandom(1 << 16)

    def serve():
        try:
            conn, _ = srv.accept()
        except OSError:
            return
        with conn:
            conn.sendall(data)
        srv.close()

    threading.Thread(target=serve, daemon=True).start()
    (w / "port").write_text(str(srv.getsockname()[1]))


def _random_counters(w: Path) -> None:
    """data.bin (the real recording's first packets, or none) with each packet's counter drawn at random and its
    checksum made right again."""
    import numpy as np

    path = w / "data.bin"
    if not path.exists():
        path.write_bytes(b"")
        return
    sys.path.insert(0, str(REPO))
    from gfimu.io.readers.mimu4444 import find_packets

    d = bytearray(path.read_bytes())
    starts, _, _ = find_packets(np.frombuffer(bytes(d), dtype=np.uint8))
    rng = np.random.default_rng(1)
    for s in starts:
        c = int(rng.integers(0, 65536))
        d[s + 1], d[s + 2] = c >> 8, c & 255
        check = sum(d[s:s + 104]) % 65536
        d[s + 104], d[s + 105] = check >> 8, check & 255
    path.write_bytes(bytes(d))


def _live_g_header(w: Path) -> None:
    lines = (w / "log" / "imu.csv").read_text().splitlines()
    (w / "stdin").write_text("\n".join([lines[0].replace("[m s^-2]", "[g]")] + lines[1:]) + "\n")


def _live_1ns(w: Path) -> None:
    lines = (w / "log" / "imu.csv").read_text().splitlines()
    (w / "stdin").write_text("\n".join([lines[0]] + [f"{k}," + x.split(",", 1)[1] for k, x in enumerate(lines[1:])])
                             + "\n")


def _moving_csv_mg(w: Path) -> None:
    """data.csv: the log's readings (m/s², moving) under a map whose unit says mg."""
    lines = (w / "log" / "imu.csv").read_text().splitlines()[1:]
    rows = [f"{int(ln.split(',')[0]) // 1_000_000}," + ",".join(ln.split(",")[1:13]) for ln in lines]
    (w / "data.csv").write_text("t [ms],ax,ay,az,bx,by,bz,cx,cy,cz,dx,dy,dz\n" + "\n".join(rows) + "\n")
    _edit(w / "map.toml", lambda t: t.replace('unit = "m/s^2"', 'unit = "mg"'))


def _zip_bomb(w: Path) -> None:
    import zipfile

    row = b"0.0100000000E0,0.0000000000E0,0.0000000000E0,9.8100000000E0\n"
    with zipfile.ZipFile(w / "export.zip", "w", zipfile.ZIP_DEFLATED, compresslevel=9) as z:
        with z.open("Accelerometer.csv", "w", force_zip64=True) as fh:
            fh.write(b'"Time (s)","X (m/s^2)","Y (m/s^2)","Z (m/s^2)"\n')
            block = row * ((1 << 20) // len(row))
            for _ in range(200):
                fh.write(block)


def _zip_twice(w: Path) -> None:
    import warnings
    import zipfile

    text = "\n".join(['"Time (s)","X (m/s^2)","Y (m/s^2)","Z (m/s^2)"']
                     + [f"{k / 100:.4f},0.1,0.2,9.8" for k in range(200)]) + "\n"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with zipfile.ZipFile(w / "export.zip", "w") as z:
            z.writestr("Accelerometer.csv", text)
            z.writestr("Accelerometer.csv", text.replace("9.8", "0.98"))


def _live_nan_stdin(w: Path) -> None:
    lines = (w / "log" / "imu.csv").read_text().splitlines()
    rows = [lines[0]] + [ln.split(",")[0] + ",nan" * (len(ln.split(",")) - 1) for ln in lines[1:50]] + lines[50:]
    (w / "stdin").write_text("\n".join(rows) + "\n")


def _imu_bag(fault: str):
    """A ROS 2 bag of four sensor_msgs/msg/Imu topics /imu0../imu3 (the log's accelerometers a1..a4 take them
    through a copy of its array.toml with topics), with one fault: 'nan' or 'huge' a reading of /imu1, 'back'
    a stamp of /imu2 going back 50 ms, 'zero' every header stamp 0."""

    def setup(w: Path) -> None:
        import math

        import numpy as np
        try:
            from rosbags.rosbag2 import Writer
            from rosbags.typesys import Stores, get_typestore
        except ImportError:
            (w / "bag").mkdir()
            return
        text = (w / "log" / "array.toml").read_text()
        for i in range(4):
            text = text.replace(f'name = "a{i + 1}"', f'name = "a{i + 1}"\ntopic = "/imu{i}"')
        (w / "bagarray.toml").write_text(text)
        store = get_typestore(Stores.ROS2_HUMBLE)
        t_ = store.types
        with Writer(w / "bag", version=8) as writer:
            conns = [writer.add_connection(f"/imu{i}", "sensor_msgs/msg/Imu", typestore=store) for i in range(4)]
            for k in range(200):
                t = 1_000_000_000 + k * 10_000_000
                for i, conn in enumerate(conns):
                    ax, stamp = 0.1 * math.sin(k / 10 + i), t
                    if k == 50 and i == 1 and fault in ("nan", "huge"):
                        ax = float("nan") if fault == "nan" else 1e308
                    if fault == "back" and k == 51 and i == 2:
                        stamp = t - 50_000_000
                    if fault == "zero":
                        stamp = 0
                    header = t_["std_msgs/msg/Header"](stamp=t_["builtin_interfaces/msg/Time"](
                        sec=int(stamp // 10**9), nanosec=int(stamp % 10**9)), frame_id="x")
                    vec = t_["geometry_msgs/msg/Vector3"]
                    msg = t_["sensor_msgs/msg/Imu"](
                        header=header, orientation=t_["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                        orientation_covariance=np.zeros(9), angular_velocity=vec(x=0.0, y=0.0, z=0.0),
                        angular_velocity_covariance=np.zeros(9), linear_acceleration=vec(x=ax, y=0.0, z=9.81),
                        linear_acceleration_covariance=np.zeros(9))
                    writer.write(conn, t, store.serialize_cdr(msg, "sensor_msgs/msg/Imu"))
    return setup


def _live_huge_stdin(w: Path) -> None:
    lines = (w / "log" / "imu.csv").read_text().splitlines()
    rows = [lines[0]] + [",".join([ln.split(",")[0]] + ["1e308"] + ln.split(",")[2:]) if 40 <= k < 45 else ln
                         for k, ln in enumerate(lines[1:])]
    (w / "stdin").write_text("\n".join(rows) + "\n")


def _live_unsorted_stdin(w: Path) -> None:
    lines = (w / "log" / "imu.csv").read_text().splitlines()
    (w / "stdin").write_text("\n".join([lines[0]] + lines[1:][::-1]) + "\n")


def _make_wrong_type_bag(w: Path) -> None:
    """A ROS 2 bag (sqlite3) whose topics are no sensor_msgs/msg/Imu (a std_msgs/msg/String)."""
    try:
        from rosbags.rosbag2 import Writer
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        (w / "bag3").mkdir()
        return
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Writer(w / "bag3", version=8) as writer:
        conn = writer.add_connection("/imu0", "std_msgs/msg/String", typestore=store)
        msg = store.types["std_msgs/msg/String"](data="hello")
        for k in range(5):
            writer.write(conn, k * 10_000_000, store.serialize_cdr(msg, "std_msgs/msg/String"))


# --- running -----------------------------------------------------------------------------------------

def _digests(root: Path) -> dict[str, str]:
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_file() and not p.is_symlink():
            out[str(p.relative_to(root))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_BYTES, MEMORY_BYTES))


def _limits(file_limit: int | None):
    """The child's limits: memory, and with ``file_limit`` files no larger than that (a full disk: EFBIG)."""
    def apply() -> None:
        _limit_memory()
        if file_limit is not None:
            import signal

            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (file_limit, file_limit))
    return apply


def _names_something(line: str, args: list[str], w: Path) -> bool:
    """The error line names a path, an option or a key: a path of the case, an argument given (its first
    40 characters: a long one is quoted in part), an option's or key's name, or a quoted name."""
    import re

    text = line.split(": error: ", 1)[-1]
    if str(w) in text or re.search(r"\S+\.(csv|toml|yaml|bin|bag|mcap|db3|png)\b", text):
        return True
    for a in args:
        if len(a) >= 2 and a[:40] in text:
            return True
        key = a.split("=", 1)[0].split(".")[-1]
        if "=" in a and len(key) > 1 and key in text:
            return True
    return bool(re.search(r"'[^']+'|argument --|--[a-z]", text))


def run_case(case: Case, base: Path, work: Path) -> dict:
    w = work / case.name
    shutil.copytree(base, w, symlinks=True)
    (w / "out").mkdir()  # the output folder of every case (its absence is a case of its own)
    if case.setup is not None:
        case.setup(w)
    args = [a.replace("{w}", str(w)) for a in case.args]
    if (w / "port").exists():
        args = [a.replace("{port}", (w / "port").read_text()) for a in args]
    stdin = case.stdin
    if stdin is None and (w / "stdin").exists():
        stdin = (w / "stdin").read_bytes()
    before_inputs = {rel: hashlib.sha256((w / rel).read_bytes()).hexdigest()
                     for rel in case.inputs if (w / rel).is_file()}
    outside_before = _digests(w)
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
    t0 = time.monotonic()
    try:
        proc = subprocess.run([sys.executable, "-m", "gfimu", *args], input=stdin if stdin is not None else b"",
                              capture_output=True, timeout=TIMEOUT_S, env=env, cwd=w,
                              preexec_fn=_limits(case.file_limit))
        code, stderr = proc.returncode, proc.stderr.decode("utf-8", "replace")
    except subprocess.TimeoutExpired as exc:
        code, stderr = None, (exc.stderr or b"").decode("utf-8", "replace")
    seconds = time.monotonic() - t0
    problems = []
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    if code is None:
        problems.append(f"no end within {TIMEOUT_S:g} s")
    elif code not in EXIT_OK:
        problems.append(f"exit {code}")
    if case.expect is not None and code is not None and code not in case.expect:
        problems.append(f"exit {code}, expected {sorted(case.expect)}")
    if "Traceback" in stderr:
        problems.append("traceback")
    if "internal error" in stderr:
        problems.append("internal error")
    if code == 2:
        errors = [ln for ln in lines if ": error: " in ln]
        others = [ln for ln in lines if ": error: " not in ln and not ln.startswith(f"gfimu {case.command}: warning: ")]
        if len(errors) != 1 or not errors[0].startswith(f"gfimu {case.command}: error: ") \
                and not errors[0].startswith("gfimu: error: "):
            problems.append("not one 'gfimu CMD: error:' line")
        elif not _names_something(errors[0], args, w):
            problems.append("the error names no path, option or key")
        elif others and case.command != "live":  # live prints its session's counts too
            problems.append(f"{len(others)} line(s) on standard error besides the error and warnings")
    if case.message is not None and case.message not in stderr:
        problems.append(f"standard error does not say {case.message!r}")
    for rel in case.produces:
        if not (w / rel).is_file() or (w / rel).is_symlink():
            problems.append(f"{rel} not written")
    for rel, digest in before_inputs.items():
        p = w / rel
        if not p.is_file() or hashlib.sha256(p.read_bytes()).hexdigest() != digest:
            problems.append(f"input {rel} changed")
    after = _digests(w)
    for rel, digest in after.items():
        if rel.startswith("out/") or rel in ("stdin", "port"):
            continue
        if outside_before.get(rel) != digest:
            problems.append(f"{rel} written outside the output folder")
    for rel in outside_before:
        if rel not in after and not rel.startswith("out/"):
            problems.append(f"{rel} removed")
    shutil.rmtree(w, ignore_errors=True)
    last = lines[-1] if lines else ""
    return {"case": case.name, "command": case.command, "exit": code, "seconds": round(seconds, 2),
            "verdict": "ok" if not problems else "FAIL", "problems": sorted(set(problems)),
            "stderr": last[:300]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", action="append", default=None, help="run the cases whose name starts so")
    parser.add_argument("--json", default=None, help="write the results to this file")
    parser.add_argument("--list", action="store_true", help="list the cases and stop")
    args = parser.parse_args(argv)
    selected = [c for c in cases() if not args.only or any(c.name.startswith(p) for p in args.only)]
    if args.list:
        for c in selected:
            print(c.name, " ".join(c.args))
        return 0
    results = []
    with tempfile.TemporaryDirectory(prefix="gfimu-faults-") as tmp:
        base, work = Path(tmp) / "base", Path(tmp) / "work"
        base.mkdir()
        work.mkdir()
        build_base(base)
        print(f"{'case':34} {'command':10} {'exit':>4}  verdict")
        for case in selected:
            r = run_case(case, base, work)
            results.append(r)
            print(f"{r['case']:34} {r['command']:10} {str(r['exit']):>4}  {r['verdict']}"
                  + (f"  {'; '.join(r['problems'])}: {r['stderr']}" if r["problems"] else ""), flush=True)
    failed = [r for r in results if r["verdict"] != "ok"]
    print(f"\n{len(results)} cases, {len(results) - len(failed)} ok, {len(failed)} failed")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1, ensure_ascii=False) + "\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
