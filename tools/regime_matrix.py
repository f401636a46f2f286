#!/usr/bin/env python3
"""Where the smoothers keep their promise: a matrix of simulated regimes.

The smoothers (batch ``smoother``, streaming ``fixed-lag``) start from the per-sample answer
(``inversion``, ``ml``) and should never be worse than it. Each cell below builds a log (written to
a temporary folder, read back as a user's log is: ``gfimu.io.read_log`` and the screening), runs
every method on it in a child process with a time limit, and scores ω against the truth.

Rule (per smoother, a cell PASSes when both smoothers do):

- ω RMSE ≤ max(1.1 × the best per-sample method's ω RMSE, :data:`RMSE_FLOOR_RADPS`);
- wrong-sign share ≤ that best per-sample method's + :data:`SIGN_MARGIN` (share of the samples
  with |ω_true| > 0.1 rad/s whose estimate points against the truth, ω̂ · ω < 0);
- a consistent log (rigid body, white noise, stated or not, noise-free included) keeps the batch
  smoother's Gaussian model (:mod:`gfimu.smoother.tuning.model_choice`);
- time linear in the samples: CPU time (the estimator's process and the workers it forks; wall time
  on a shared machine measures the neighbours) at most :data:`TIME_BASE_S` + :data:`TIME_PER_SAMPLE_S`
  × samples (6,000 samples: 14 s); a method still running (wall time) at the cell's limit
  (``--timeout-base`` + ``--timeout-per-sample`` × samples) is stopped and reported as a timeout;
- no error.

Slow cells (``slow=True``: slow random 3-D rotation, |ω| at most 1 rad/s, where the readings see ω
through q(ω) ~ |ω|², small against the noise) are held to more: each smoother's ω RMSE lies below that
of every per-sample method (:data:`SLOW_PER_SAMPLE`, ``imm`` and ``integration`` included), and the
fixed-lag smoother's is at most :data:`SLOW_BATCH_FACTOR` times the batch smoother's.

Axes covered (not a full product): rates 50 Hz - 20 kHz; durations 0.5 s - 30 min; noise 0 stated
as 0, 0 not stated, 0.01, 0.1, 1 m/s², stated and not; 16-bit readings over ±16 g; lever arms
(cube half edges) 5 mm, 5 cm, 0.3 m; |ω| up to 50 rad/s; motions: torque-free free flight
(gfimu's closed form, and tools/foreign_sim.py's ellipsoid with an impact, converted from its own
CSV layout by ``gfimu convert csv --map``), hand-held (random 3-D), turntable (constant ω about
one axis, after a spin-up from rest), vehicle (slow yaw, long accelerations), impacts of 20-100 g lasting 1-5 ms, a long
still stretch then motion, and a body at rest in free fall (all readings zero).

    python3 tools/regime_matrix.py [--quick] [--cells PATTERN] [--draw N] [--json OUT] [--keep DIR]
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import traceback
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import foreign_sim  # noqa: E402
from gfimu import io as gio  # noqa: E402
from gfimu.array import SensorArray, cube_array  # noqa: E402
from gfimu.log import Log  # noqa: E402
from gfimu.simulate import SCENARIOS, SensorErrors, motion_from_truth, sample_timestamps_ns  # noqa: E402
from gfimu.simulate.trajectory import BodyKinematics, integrate_attitude, sum_of_sines  # noqa: E402

PER_SAMPLE = ("inversion", "ml")
SLOW_PER_SAMPLE = ("inversion", "integration", "imm", "ml")
"""The per-sample methods a slow cell's smoothers are compared with (every one of them)."""
SLOW_BATCH_FACTOR = 2.0
"""A slow cell's fixed-lag ω RMSE is at most this many times the batch smoother's."""
SMOOTHERS = ("smoother", "fixed-lag")
METHODS = PER_SAMPLE + SMOOTHERS
RMSE_FACTOR = 1.1
RMSE_FLOOR_RADPS = 1e-3
"""Absolute floor of the RMSE rule [rad/s]: a smoother within 1e-3 rad/s of the truth passes even
where a per-sample method is exact (noise-free logs)."""
SIGN_MARGIN = 0.005
TIME_BASE_S = 2.0
TIME_PER_SAMPLE_S = 2e-3
SIGN_MIN_RADPS = 0.1
G = 9.80665
LSB_16G_16BIT_MPS2 = 2 * 16 * G / 65536
"""One count of a 16-bit reading over ±16 g [m/s²] (4.8e-3 m/s²; its rounding error has std LSB/√12)."""


# ---------------------------------------------------------------- motions

def _smoothstep(t, t0, width):
    """(s, s', s'') of a quintic step from 0 at t0 to 1 at t0 + width."""
    x = np.clip((t - t0) / width, 0.0, 1.0)
    s = x**3 * (10 - 15 * x + 6 * x * x)
    ds = 30 * x**2 * (1 - x) ** 2 / width
    dds = 60 * x * (1 - x) * (1 - 2 * x) / width**2
    return s, ds, dds


def _sines(rng, k, fmin, fmax, rms):
    freq = rng.uniform(fmin, fmax, size=(k, 3))
    amp = rng.uniform(0.5, 1.0, size=(k, 3))
    amp *= rms / np.sqrt(0.5 * np.sum(amp**2, axis=0, keepdims=True))
    return amp, freq, rng.uniform(0, 2 * np.pi, size=(k, 3))


def _kinematics(times_s, omega, omega_dot, accel_b, q0=(1.0, 0.0, 0.0, 0.0)) -> BodyKinematics:
    """BodyKinematics of sampled ω, ω̇ and acceleration (B), attitude by integrating ``omega(t)``."""
    q = integrate_attitude(omega, times_s, np.asarray(q0, dtype=float), omega_samples=omega(times_s))
    return BodyKinematics(times_s, omega(times_s), omega_dot(times_s), accel_b(times_s), q)


def vehicle(times_s, rng, array, *, yaw_rms_radps=0.2, accel_rms_mps2=1.5):
    """A car: slow yaw (0.01-0.05 Hz), small roll and pitch from the suspension (0.5-2 Hz, 0.02 rad/s),
    long accelerations along x (0.005-0.03 Hz) and the lateral acceleration of the turns."""
    yaw = _sines(rng, 4, 0.01, 0.05, yaw_rms_radps)
    rp = _sines(rng, 4, 0.5, 2.0, 0.02)
    lon = _sines(rng, 4, 0.005, 0.03, accel_rms_mps2)

    def omega(t, order=0):
        w = sum_of_sines(t, *rp, order=order)
        w[:, 2] = sum_of_sines(t, *yaw, order=order)[:, 2]
        return w

    def accel(t):
        a = np.zeros((np.size(t), 3))
        a[:, 0] = sum_of_sines(t, *lon)[:, 0]
        a[:, 1] = 10.0 * omega(t)[:, 2]  # 10 m/s through the turn
        return a

    return _kinematics(times_s, omega, lambda t: omega(t, 1), accel), array


def impacts(times_s, rng, array, *, n_impacts=4, peak_g=(20.0, 100.0), width_s=(1e-3, 5e-3), omega_rms_radps=1.0):
    """Hand-held motion (random 3-D sines below 2 Hz) struck ``n_impacts`` times: each impact a
    half-sine of specific force of peak 20-100 g over 1-5 ms in a random direction, with a half-sine
    of angular acceleration (peak 500-3000 rad/s²) over the same time, which leaves ω changed."""
    base = _sines(rng, 6, 0.1, 2.0, omega_rms_radps)
    lin = _sines(rng, 6, 0.1, 2.0, 2.0)
    t_end = float(times_s[-1])
    starts = np.sort(rng.uniform(0.1 * t_end, 0.9 * t_end, n_impacts))
    widths = rng.uniform(*width_s, n_impacts)
    peaks = rng.uniform(*peak_g, n_impacts) * G
    dirs = rng.normal(size=(n_impacts, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    alpha = rng.uniform(500.0, 3000.0, n_impacts)[:, None] * rng.choice([-1.0, 1.0], size=(n_impacts, 3))

    def pulses(t, order):
        t = np.asarray(t, dtype=float)
        out = np.zeros((t.size, 3))
        for t0, w, a in zip(starts, widths, alpha):
            x = np.clip((t - t0) / w, 0.0, 1.0)
            inside = (t > t0) & (t < t0 + w)
            if order == 1:  # angular acceleration
                out += np.where(inside, np.sin(np.pi * x), 0.0)[:, None] * a
            else:  # its integral, the change of ω
                out += (w / np.pi * (1 - np.cos(np.pi * x)))[:, None] * a
        return out

    def omega(t):
        return sum_of_sines(t, *base) + pulses(t, 0)

    def omega_dot(t):
        return sum_of_sines(t, *base, order=1) + pulses(t, 1)

    def accel(t):
        a = sum_of_sines(t, *lin)
        t = np.asarray(t, dtype=float)
        for t0, w, p, d in zip(starts, widths, peaks, dirs):
            inside = (t > t0) & (t < t0 + w)
            a += np.where(inside, p * np.sin(np.pi * (t - t0) / w), 0.0)[:, None] * d
        return a

    return _kinematics(times_s, omega, omega_dot, accel), array


def still_then_motion(times_s, rng, array, *, still_s=60.0, omega_rms_radps=1.5):
    """At rest, tilted, for ``still_s``, then hand-held motion (random 3-D sines below 2 Hz) that
    fades in over 1 s (a quintic step, so ω̇ stays continuous)."""
    rot = _sines(rng, 6, 0.1, 2.0, omega_rms_radps)
    lin = _sines(rng, 6, 0.1, 2.0, 2.0)

    def omega(t):
        s = _smoothstep(np.asarray(t, dtype=float), still_s, 1.0)[0]
        return s[:, None] * sum_of_sines(t, *rot)

    def omega_dot(t):
        s, ds, _ = _smoothstep(np.asarray(t, dtype=float), still_s, 1.0)
        return ds[:, None] * sum_of_sines(t, *rot) + s[:, None] * sum_of_sines(t, *rot, order=1)

    def accel(t):
        s = _smoothstep(np.asarray(t, dtype=float), still_s, 1.0)[0]
        return s[:, None] * sum_of_sines(t, *lin)

    q0 = (np.cos(0.2), np.sin(0.2) * 0.6, np.sin(0.2) * 0.8, 0.0)
    return _kinematics(times_s, omega, omega_dot, accel, q0), array


def turntable(times_s, rng, array, *, rate_deg_s=180.0, spin_up_s=0.5, tilt_deg=12.0, axis_offset_m=0.03):
    """gfimu's turntable (Lu, Tsai & Lin 2010's bench: axis tilted ``tilt_deg``, origin ``axis_offset_m`` off
    it) started from rest: the rate rises to ``rate_deg_s`` over ``spin_up_s`` (a quintic step), then
    stays constant. Without the spin-up the sign of a constant ω about one axis is not observable
    from accelerometers (q(ω) = q(-ω), ω̇ = 0), and no estimator could be judged on it."""
    from gfimu.simulate.scenarios import _turntable

    t = np.asarray(times_s, dtype=float)
    w = np.deg2rad(rate_deg_s)
    s, ds, _ = _smoothstep(t, 0.0, spin_up_s)
    x = np.clip(t / spin_up_s, 0.0, 1.0)
    theta = w * np.where(t < spin_up_s, spin_up_s * (2.5 * x**4 - 3 * x**5 + x**6), 0.5 * spin_up_s + t - spin_up_s)
    return _turntable(t, theta, w * s, w * ds, array, tilt_deg, axis_offset_m)


def free_fall_rest(times_s, rng, array):
    """A body at rest in free fall: no rotation, zero specific force (every reading exactly 0)."""
    n = np.size(times_s)
    zeros = np.zeros((n, 3))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return BodyKinematics(np.asarray(times_s), zeros, zeros.copy(), zeros.copy() + np.array([0, 0, -G]), q), array


def _scenario(name):
    def build(times_s, rng, array, **options):
        return SCENARIOS[name].build(times_s, rng, array, **options)
    return build


MOTIONS: dict[str, Callable] = {
    "handheld": _scenario("random3d"),
    "turntable": turntable,
    "freeflight": _scenario("freeflight-intermediate"),
    "vehicle": vehicle,
    "impacts": impacts,
    "still-then-motion": still_then_motion,
    "free-fall-rest": free_fall_rest,
    "slow": _scenario("slow3d"),
}


# ---------------------------------------------------------------- cells

NOT_STATED = None


@dataclass(frozen=True)
class Cell:
    """One regime. ``noise_mps2``: white-noise std applied; ``stated_mps2``: what array.toml says
    (``NOT_STATED``: no ``noise_std_mps2`` key; 0.0: stated as exactly 0)."""

    name: str
    motion: str
    rate_hz: float
    duration_s: float
    half_edge_m: float = 0.025
    noise_mps2: float = 0.01
    stated_mps2: float | None = 0.01
    quantised: bool = False
    motion_options: dict = field(default_factory=dict)
    quick: bool = False
    consistent: bool = True
    """Whether the readings follow the rigid-body equation up to white noise (the batch smoother must
    then keep its Gaussian model)."""
    foreign: bool = False
    """The log comes from tools/foreign_sim.py through ``gfimu convert csv --map``."""
    seed: int = 1
    note: str = ""
    slow: bool = False
    """Slow motion: the smoothers are compared with every per-sample method of :data:`SLOW_PER_SAMPLE`, and
    the fixed-lag smoother with the batch smoother (module docstring)."""

    @property
    def per_sample(self) -> tuple[str, ...]:
        """The per-sample methods this cell runs and compares the smoothers with."""
        return SLOW_PER_SAMPLE if self.slow else PER_SAMPLE

    def describe(self) -> str:
        stated = "not stated" if self.stated_mps2 is None else f"stated {self.stated_mps2:g}"
        q = ", 16-bit ±16 g" if self.quantised else ""
        arm = "foreign array 0.08-0.15 m" if self.foreign else f"cube half edge {self.half_edge_m * 1e3:g} mm"
        return (f"{self.motion}, {self.rate_hz:g} Hz, {self.duration_s:g} s, {arm}, noise {self.noise_mps2:g} m/s² "
                f"({stated}){q}")


QUANT_STD = LSB_16G_16BIT_MPS2 / np.sqrt(12.0)

CELLS: tuple[Cell, ...] = (
    # --quick: the fast subset (tests/test_regimes.py asserts on the same kinds of cells)
    Cell("noisefree-stated0", "handheld", 200.0, 10.0, 0.025, 0.0, 0.0, quick=True),
    Cell("noisefree-unstated", "handheld", 200.0, 10.0, 0.025, 0.0, NOT_STATED, quick=True),
    Cell("noise0.01-unstated", "handheld", 200.0, 10.0, 0.025, 0.01, NOT_STATED, quick=True),
    Cell("noise0.1-stated-1kHz", "handheld", 1000.0, 5.0, 0.025, 0.1, 0.1, quick=True),
    Cell("50Hz-0.3m-noise0.1", "handheld", 50.0, 60.0, 0.3, 0.1, 0.1, quick=True),
    Cell("5mm-noise0.01", "handheld", 1000.0, 5.0, 0.005, 0.01, 0.01, quick=True),
    Cell("quant16-1kHz", "handheld", 1000.0, 5.0, 0.025, 0.0, QUANT_STD, quantised=True, quick=True,
         note="noise = the rounding to 16 bits over ±16 g alone; stated = its std LSB/√12"),
    Cell("still60-then-motion", "still-then-motion", 200.0, 70.0, 0.025, 0.01, 0.01, quick=True),
    Cell("turntable-50radps", "turntable", 1000.0, 3.0, 0.025, 0.01, 0.01,
         motion_options={"rate_deg_s": float(np.rad2deg(50.0))}, quick=True),
    Cell("impacts-4kHz", "impacts", 4000.0, 1.5, 0.025, 0.01, 0.01, quick=True),
    Cell("free-fall-rest-noisefree", "free-fall-rest", 200.0, 5.0, 0.025, 0.0, 0.0, quick=True),
    Cell("foreign-ff-impact-4kHz", "foreign", 4000.0, 1.5, noise_mps2=0.0, stated_mps2=NOT_STATED, foreign=True,
         quick=True, note="tools/foreign_sim.py, converted with gfimu convert csv --map; readings in g of 9.8 m/s² "
                          "read as g of 9.80665 (what a user's map says): a common gain of 1.0007"),
    # the full run adds
    Cell("foreign-ff-impact-4kHz-noise", "foreign", 4000.0, 1.5, noise_mps2=0.01, stated_mps2=0.01, foreign=True),
    Cell("foreign-ff-impact-4kHz-stated0", "foreign", 4000.0, 1.5, noise_mps2=0.0, stated_mps2=0.0, foreign=True),
    Cell("foreign-noisefree-stated0.01", "foreign", 4000.0, 1.5, noise_mps2=0.0, stated_mps2=0.01, foreign=True,
         note="noise-free readings with a noise level stated: the model check sees the round-off residual's tails"),
    Cell("freeflight-1kHz", "freeflight", 1000.0, 2.0, 0.025, 0.01, 0.01),
    Cell("20kHz-0.5s", "handheld", 20000.0, 0.5, 0.025, 0.01, 0.01),
    Cell("4kHz-0.3m-noise0.1", "handheld", 4000.0, 2.0, 0.3, 0.1, 0.1),
    Cell("noise1-0.3m-200Hz", "handheld", 200.0, 30.0, 0.3, 1.0, 1.0),
    Cell("noise1-unstated", "handheld", 200.0, 30.0, 0.3, 1.0, NOT_STATED),
    Cell("noise0.1-unstated", "handheld", 1000.0, 5.0, 0.025, 0.1, NOT_STATED),
    Cell("handheld-50radps", "handheld", 1000.0, 5.0, 0.025, 0.01, 0.01,
         motion_options={"omega_rms_radps": 25.0, "max_frequency_hz": 2.0}),
    Cell("quant16-noise0.01-5mm", "handheld", 1000.0, 5.0, 0.005, 0.01, 0.01, quantised=True),
    Cell("turntable-0.3m-unstated", "turntable", 200.0, 10.0, 0.3, 0.1, NOT_STATED),
    Cell("vehicle-50Hz-60s", "vehicle", 50.0, 60.0, 0.3, 0.01, 0.01),
    Cell("vehicle-50Hz-30min", "vehicle", 50.0, 1800.0, 0.3, 0.01, 0.01),
    Cell("impacts-20kHz", "impacts", 20000.0, 0.5, 0.025, 0.1, 0.1, motion_options={"n_impacts": 2}),
    Cell("still60-noisefree-stated0", "still-then-motion", 200.0, 70.0, 0.025, 0.0, 0.0),
    Cell("slow-5cm-500Hz", "slow", 500.0, 20.0, 0.05, 0.07, 0.07, slow=True,
         note="a hovering drone or a slow hand: |ω| at most 1 rad/s"),
    Cell("slow-2.5cm-500Hz", "slow", 500.0, 20.0, 0.025, 0.07, 0.07, slow=True),
    Cell("slow-10cm-100Hz", "slow", 100.0, 20.0, 0.1, 0.07, 0.07, slow=True),
    Cell("slow-2.5cm-100Hz", "slow", 100.0, 20.0, 0.025, 0.07, 0.07, slow=True),
)


def named_cell(name: str, duration_s: float | None = None) -> Cell | None:
    """The cell called ``name`` (None: there is none), ``duration_s`` long where given (the tools that measure
    one cell's log: bench_floor.py, replay_udp.py, stream_cost.py)."""
    cell = next((c for c in CELLS if c.name == name), None)
    return cell if cell is None or duration_s is None else replace(cell, duration_s=duration_s)


def cells_selected(quick: bool, pattern: str | None) -> list[Cell]:
    """The cells of the run: the quick subset or all, filtered by ``pattern`` (comma-separated names or
    glob patterns; a plain word matches every cell whose name contains it)."""
    out = [c for c in CELLS if c.quick or not quick]
    if pattern:
        pats = [p.strip() for p in pattern.split(",") if p.strip()]
        out = [c for c in out if any(fnmatch.fnmatch(c.name, p if any(ch in p for ch in "*?[") else f"*{p}*")
                                     for p in pats)]
    return out


# ---------------------------------------------------------------- building logs

def _with_stated_noise(array: SensorArray, stated: float | None) -> SensorArray:
    return array.with_accelerometers(replace(a, noise_std_mps2=stated) for a in array.accelerometers)


def build_log(cell: Cell, folder: Path) -> tuple[Path, np.ndarray]:
    """Write ``cell``'s log into ``folder`` (a log folder for gfimu); returns (its path, true ω (N, 3))."""
    if cell.foreign:
        return build_foreign_log(cell, folder)
    array = _with_stated_noise(cube_array(cell.half_edge_m, None), cell.stated_mps2)
    if cell.quantised:
        array = array.with_accelerometers(replace(a, range_mps2=16 * G) for a in array.accelerometers)
    ts = sample_timestamps_ns(cell.rate_hz, cell.duration_s)
    motion_seq, noise_seq = np.random.SeedSequence(cell.seed).spawn(2)
    kin, array_built = MOTIONS[cell.motion](ts * 1e-9, np.random.default_rng(motion_seq), array,
                                            **cell.motion_options)
    array = _with_stated_noise(array_built, cell.stated_mps2)  # a scenario may return its own (free flight: the body)
    truth = motion_from_truth(ts, kin)
    errors = SensorErrors(accel_noise_std_mps2=cell.noise_mps2,
                          accel_quantisation_mps2=LSB_16G_16BIT_MPS2 if cell.quantised else 0.0,
                          accel_range_mps2=16 * G if cell.quantised else np.inf)
    readings = errors.accel_readings(array, truth.specific_force_b_mps2, truth.omega_dot_b_radps2,
                                     truth.omega_b_radps, np.random.default_rng(noise_seq))
    log = Log(array, ts, readings, truth=truth, source=cell.name)
    path = folder / cell.name
    gio.write_log(log, path)
    return path, truth.omega_b_radps


def foreign_map_text(sensors_json: Path, stated_mps2: float | None) -> str:
    """A ``gfimu-csv-map/1`` column map for tools/foreign_sim.py's ``readings.csv``, written as its user
    would: positions from millimetres to metres, the z-y-x Euler angles to rotation matrices, the
    readings' unit ``g`` (gfimu's 9.80665 m/s²: the recording's own 9.8 is not expressible in a map)."""
    from scipy.spatial.transform import Rotation

    spec = json.loads(Path(sensors_json).read_text())
    lines = ['format = "gfimu-csv-map/1"', 'name = "foreign-ellipsoid"', "", "[time]", 'column = "t_ms"',
             'unit = "ms"', ""]
    for s in spec["sensors"]:
        sid = s["id"]
        pos = [v / 1000.0 for v in s["position_mm"]]
        rot = Rotation.from_euler("ZYX", s["euler_zyx_deg"], degrees=True).as_matrix()
        lines += ["[[accelerometers]]", f'name = "{sid}"', f"position_m = [{', '.join(repr(v) for v in pos)}]",
                  "rotation_body_sensor = [" + ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]"
                                                         for row in rot) + "]",
                  'unit = "g"', f'x = "{sid}_ax"', f'y = "{sid}_ay"', f'z = "{sid}_az"']
        if stated_mps2 is not None:
            lines.append(f"noise_std_mps2 = {stated_mps2!r}")
        lines.append("")
    return "\n".join(lines)


def convert_foreign(recording: Path, map_path: Path, out: Path) -> None:
    """``gfimu convert csv READINGS --map MAP --out OUT`` in a subprocess (what a user runs)."""
    cmd = [sys.executable, "-m", "gfimu", "convert", "csv", str(recording / "readings.csv"), "--map", str(map_path),
           "--out", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr.strip() or proc.stdout.strip()}")


def build_foreign_log(cell: Cell, folder: Path) -> tuple[Path, np.ndarray]:
    cfg = foreign_sim.Config(rate_hz=cell.rate_hz, duration_s=cell.duration_s, noise_g=cell.noise_mps2 / foreign_sim.FILE_G,
                             seed=3 + cell.seed - 1)
    rec = folder / f"{cell.name}-recording"
    foreign_sim.write_recording(foreign_sim.simulate(cfg), rec, cfg)
    map_path = folder / f"{cell.name}-map.toml"
    map_path.write_text(foreign_map_text(rec / "sensors.json", cell.stated_mps2))
    out = folder / cell.name
    convert_foreign(rec, map_path, out)
    _, omega = foreign_sim.read_truth(rec / "truth.csv")
    return out, omega


# ---------------------------------------------------------------- running

def _cpu_seconds() -> float:
    """CPU time of this process and of its ended children (the batch smoother's forked workers) [s]."""
    import resource

    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _model_of(log, est) -> tuple[str, str]:
    """(model, the check's description) the batch smoother takes on ``log`` (its model check alone)."""
    from gfimu.smoother.batch.engine import chosen_model
    from gfimu.smoother.model.option_groups import ModelGroups

    if not est.auto_model:
        return "n/a", ""
    try:
        _, auto = chosen_model(log, ModelGroups.of(est), attitude=False)
        check = None if auto is None else auto[0]
    except Exception:  # the options that follow the check failed (the run will say so): the check alone
        from gfimu.estimators.ml import MLEstimator
        from gfimu.smoother.tuning.model_choice import check_model

        check = check_model(log, MLEstimator().estimate_motion(log))
    if check is None:
        return "n/a", ""
    return ("gaussian" if check.consistent else "robust"), check.describe()


def _run_child(conn, log_dir: str, method: str, options: dict, cpu_limit_s: float | None) -> None:
    os.setsid()  # its own process group: a timeout stops it and any workers it forked
    if cpu_limit_s:  # SIGXCPU ends it (and each worker it forks) at this much CPU time
        import resource

        limit = int(np.ceil(cpu_limit_s))
        resource.setrlimit(resource.RLIMIT_CPU, (limit, limit + 5))
    try:
        from gfimu.methods import make_estimator
        from gfimu.readings import screen_log

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            log = gio.read_log(log_dir, truth=False)
            log, _ = screen_log(log)
            est = make_estimator(method, **options)
            reason = est.applicable(log.array)
            if reason:
                conn.send({"error": f"not applicable: {reason}"})
                return
            if method == "smoother":  # the model it will take, known before a run that may not end
                conn.send({"early_model": _model_of(log, est)})
            t0, cpu0 = time.perf_counter(), _cpu_seconds()
            estimate = est.estimate(log)
            motion, check = estimate.motion, estimate.report.model_check
            result_warnings = list(estimate.report.warnings)
            seconds, cpu = time.perf_counter() - t0, _cpu_seconds() - cpu0
        model = None
        if method in SMOOTHERS:
            model = "n/a" if check is None else ("gaussian" if check.consistent else "robust")
        conn.send({"omega": motion.omega_b_radps, "seconds": seconds, "cpu_seconds": cpu, "model": model,
                   "model_check": None if check is None else check.describe(),
                   "warnings": [str(w) for w in result_warnings] + [str(w.message) for w in caught][:5]})
    except BaseException as exc:  # reported in the table, not fatal to the study
        conn.send({"error": f"{type(exc).__name__}: {exc}".strip(), "traceback": traceback.format_exc(limit=4)})
    finally:
        conn.close()


def _compile_kernels() -> None:
    """In a forked child: the compiled kernels built into numba's cache (the batch smoother's, and the stream's
    by a fixed-lag run on a 6 s simulated log), so that a first run in a fresh checkout times the cells' work,
    not the compiling (about 16 s once: ``tools/bench_first_run.py``)."""
    from gfimu.methods import make_estimator
    from gfimu.simulate import simulate
    from gfimu.smoother import preload
    from gfimu.smoother.model import kernels

    kernels.warm()
    est = make_estimator("fixed-lag", compute_sigma=True)  # (σ too: its running scale's kernels)
    est.preload()  # (numba loaded, as the command line does: the stream's steps then run compiled)
    preload.wait()
    est.estimate(simulate("random3d", rate_hz=500.0, duration_s=6.0, seed=0))  # (past the first 3 s: the stream)


def compile_kernels() -> float:
    """:func:`_compile_kernels` in a child process; its wall time [s]."""
    t0 = time.perf_counter()
    proc = multiprocessing.get_context("fork").Process(target=_compile_kernels)
    proc.start()
    proc.join()
    return time.perf_counter() - t0


def run_method(log_dir: Path, method: str, timeout_s: float, options: dict | None = None) -> dict:
    """``method`` on the log in a forked child, stopped at ``timeout_s`` of CPU time (its own, and each
    worker's), or at three times that (plus 10 s) of wall time on a busy machine. Returns a dict with
    ``omega`` (N, 3), ``seconds`` (wall), ``cpu_seconds``, ``model``, ``warnings``; or ``error``, or
    ``timeout`` with the seconds it ran."""
    ctx = multiprocessing.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_run_child, args=(child, str(log_dir), method, dict(options or {}), timeout_s))
    t0 = time.perf_counter()
    proc.start()
    child.close()
    out, early = None, {}
    deadline = t0 + 3.0 * timeout_s + 10.0
    while out is None and parent.poll(max(deadline - time.perf_counter(), 0.0)):
        try:
            msg = parent.recv()
            if "early_model" in msg:
                early = {"model": msg["early_model"][0], "model_check": msg["early_model"][1]}
            else:
                out = msg
        except EOFError:
            proc.join(timeout=5.0)
            if proc.exitcode in (-signal.SIGXCPU, -signal.SIGKILL):
                out = {"timeout": True, "seconds": time.perf_counter() - t0, "limit": f"{timeout_s:.0f} s CPU"}
            else:
                out = {"error": f"the child process ended without a result (exit code {proc.exitcode})"}
    proc.join(timeout=1.0)
    if out is None:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.join()
        out = {"timeout": True, "seconds": time.perf_counter() - t0, "limit": f"{3 * timeout_s + 10:.0f} s wall"}
    parent.close()
    for key, value in early.items():  # an error or a timeout still tells the model the check chose
        if out.get(key) is None:
            out[key] = value
    return out


def score(omega_est: np.ndarray, omega_true: np.ndarray, rows: slice | np.ndarray | None = None) -> tuple[float, float]:
    """(ω RMSE of the error norm [rad/s], wrong-sign share among samples with |ω_true| > 0.1 rad/s)."""
    e, w = omega_est, omega_true
    if rows is not None:
        e, w = e[rows], w[rows]
    err = e - w
    ok = np.all(np.isfinite(err), axis=1)
    rmse = float(np.sqrt(np.mean(np.sum(err[ok] ** 2, axis=1)))) if np.any(ok) else float("nan")
    if np.count_nonzero(~ok):
        rmse = float("nan")  # an estimate with missing rows is not scored as good
    big = np.linalg.norm(w, axis=1) > SIGN_MIN_RADPS
    wrong = float(np.mean(np.sum(e[big] * w[big], axis=1) < 0)) if np.any(big) else 0.0
    return rmse, wrong


def time_budget_s(samples: int) -> float:
    return TIME_BASE_S + TIME_PER_SAMPLE_S * samples


def judge(cell: Cell, results: dict, samples: int) -> dict:
    """Verdict of each smoother and of the cell by the rule of the module docstring."""
    ps = {m: results[m] for m in cell.per_sample if "rmse" in results.get(m, {}) and np.isfinite(results[m]["rmse"])}
    verdict = {}
    if not ps:
        return {"cell": "FAIL", "reasons": ["no per-sample method gave an estimate"]}
    best = min(ps, key=lambda m: ps[m]["rmse"])
    limit_rmse = max(RMSE_FACTOR * ps[best]["rmse"], RMSE_FLOOR_RADPS)
    if cell.slow:  # below every per-sample method
        limit_rmse = ps[best]["rmse"]
    limit_sign = ps[best]["wrong_sign"] + SIGN_MARGIN
    reasons_all = []
    for m in SMOOTHERS:
        r = results.get(m, {})
        why = []
        if r.get("timeout"):
            why.append(f"stopped at the limit of {r['limit']} ({r['seconds']:.0f} s wall)")
        elif "error" in r:
            why.append("error: " + r["error"].splitlines()[0][:120])
        else:
            if not r["rmse"] <= limit_rmse:
                why.append(f"RMSE {r['rmse']:.3g} > {limit_rmse:.3g}")
            if not r["wrong_sign"] <= limit_sign:
                why.append(f"wrong sign {100 * r['wrong_sign']:.2f} % > {100 * limit_sign:.2f} %")
            if r["cpu_seconds"] > time_budget_s(samples):
                why.append(f"CPU time {r['cpu_seconds']:.1f} s > {time_budget_s(samples):.1f} s")
            batch_rmse = results.get("smoother", {}).get("rmse", np.nan)
            if cell.slow and m == "fixed-lag" and not r["rmse"] <= SLOW_BATCH_FACTOR * batch_rmse:
                why.append(f"RMSE {r['rmse']:.3g} > {SLOW_BATCH_FACTOR:g} x batch {batch_rmse:.3g}")
        if m == "smoother" and cell.consistent and r.get("model") != "gaussian":
            why.append(f"model {r.get('model') or 'unknown'} on a consistent log")
        verdict[m] = "PASS" if not why else "FAIL"
        reasons_all += [f"{'batch' if m == 'smoother' else m}: {w}" for w in why]
    verdict.update(best_per_sample=best, best_per_sample_rmse=ps[best]["rmse"], rmse_limit=limit_rmse, sign_limit=limit_sign,
                   cell="PASS" if all(verdict[m] == "PASS" for m in SMOOTHERS) else "FAIL", reasons=reasons_all)
    return verdict


def run_cell(cell: Cell, folder: Path, timeout_base: float = 20.0, timeout_per_sample: float = 3e-3,
             methods=METHODS, keep_omega: bool = False, options: dict | None = None) -> dict:
    """Build ``cell``'s log in ``folder``, run ``methods`` (``options``: method -> its options), score
    and judge. ``keep_omega``: the estimates (and the truth) stay in the returned dict (under
    ``omega``, ``truth``)."""
    t0 = time.perf_counter()
    log_dir, truth = build_log(cell, folder)
    build_s = time.perf_counter() - t0
    samples = len(truth)
    timeout = timeout_base + timeout_per_sample * samples
    if cell.slow and methods == METHODS:
        methods = cell.per_sample + SMOOTHERS
    results = {}
    for m in methods:
        r = run_method(log_dir, m, timeout, (options or {}).get(m))
        if "omega" in r:
            if r["omega"].shape != truth.shape:
                r = {"error": f"estimate has {r['omega'].shape[0]} rows, the log {samples}", "seconds": r["seconds"]}
            else:
                r["rmse"], r["wrong_sign"] = score(r["omega"], truth)
        if not keep_omega:
            r.pop("omega", None)
        r.pop("traceback", None) if "error" not in r else None
        results[m] = r
    row = {"cell": cell.name, "description": cell.describe(), "note": cell.note, "samples": samples,
           "log_dir": str(log_dir), "build_s": build_s, "timeout_s": timeout, "results": results,
           "verdict": judge(cell, results, samples) if set(SMOOTHERS) <= set(methods) else None}
    row["per_sample"] = {m: results[m].get("rmse") for m in cell.per_sample if m in results}
    if keep_omega:
        row["truth"] = truth
    return row


def _fmt_time(r: dict) -> str:
    if r.get("timeout"):
        return f"> {r['limit']}"
    if "error" in r:
        return "error"
    return f"{r['cpu_seconds']:.2f}"


def _fmt_rmse(r: dict) -> str:
    return "-" if "rmse" not in r else f"{r['rmse']:.3g}"


def _fmt_sign(r: dict) -> str:
    return "-" if "wrong_sign" not in r else f"{100 * r['wrong_sign']:.1f}"


def table_header() -> str:
    names = ["inv", "ml", "batch", "fixed"]
    head = (["cell", "samples"] + [f"cpu {n} s" for n in names] + [f"RMSE {n}" for n in names]
            + [f"sign {n} %" for n in names] + ["model (batch)", "verdict"])
    return "| " + " | ".join(head) + " |\n|" + "---|" * len(head)


def table_row(row: dict) -> str:
    res = [row["results"].get(m, {}) for m in METHODS]
    v = row["verdict"] or {}
    batch = row["results"].get("smoother", {})
    verdict = v.get("cell", "-")
    if v and v.get("best_per_sample") not in (None, "inversion", "ml"):
        verdict += f" (best per-sample: {v['best_per_sample']} {v['best_per_sample_rmse']:.3g})"
    if v.get("reasons"):
        verdict += ": " + "; ".join(v["reasons"])
    cells = ([row["cell"], str(row["samples"])] + [_fmt_time(r) for r in res] + [_fmt_rmse(r) for r in res]
             + [_fmt_sign(r) for r in res] + [batch.get("model") or "-", verdict])
    return "| " + " | ".join(cells) + " |"


def parse_options(items) -> dict:
    """``["smoother.tune_span_s=None", ...]`` -> ``{"smoother": {"tune_span_s": None}}``."""
    import ast

    out: dict = {}
    for item in items:
        key, sep, value = item.partition("=")
        method, dot, name = key.partition(".")
        if not sep or not dot or method not in METHODS or not name:
            raise ValueError(f"{item!r} is not METHOD.NAME=VALUE with METHOD one of {', '.join(METHODS)}")
        try:
            parsed = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            parsed = value  # a bare word: a string option
        out.setdefault(method, {})[name] = parsed
    return out


def _jsonable(row: dict) -> dict:
    out = {k: v for k, v in row.items() if k not in ("truth",)}
    out["results"] = {m: {k: v for k, v in r.items() if k != "omega"} for m, r in row["results"].items()}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 epilog="PASS rule and axes: see the module docstring (python3 -m pydoc tools/regime_matrix.py)")
    ap.add_argument("--quick", action="store_true", help="the fast subset (no 30-min cell)")
    ap.add_argument("--cells", metavar="PATTERN",
                    help="comma-separated cell names or glob patterns (a plain word matches any cell containing it)")
    ap.add_argument("--json", metavar="OUT", help="write every number of the table (and the warnings) to OUT")
    ap.add_argument("--keep", metavar="DIR", help="build the logs in DIR (kept) instead of a temporary folder")
    ap.add_argument("--timeout-base", type=float, default=20.0,
                    help="per-method limit of CPU time (wall: three times it, plus 10 s): this [s] ...")
    ap.add_argument("--timeout-per-sample", type=float, default=3e-3, help="... plus this [s] per sample")
    ap.add_argument("-O", dest="options", action="append", default=[], metavar="METHOD.NAME=VALUE",
                    help="an option of one method (a Python literal: 1e-3, None, 'ml'), e.g. -O smoother.tune_span_s=None")
    ap.add_argument("--draw", type=int, default=0, metavar="N",
                    help="another draw of each cell: its seed plus N (its motion, noise and misfit drawn again; "
                         "default 0, the cell as listed)")
    ap.add_argument("--list", action="store_true", help="list the cells and exit")
    args = ap.parse_args(argv)
    if args.draw < 0:
        ap.error("--draw: 0 or more")
    try:
        options = parse_options(args.options)
    except ValueError as exc:
        print(f"-O: {exc}", file=sys.stderr)
        return 2
    cells = [replace(c, seed=c.seed + args.draw) for c in cells_selected(args.quick, args.cells)]
    if args.draw:
        print(f"draw {args.draw}: each cell's seed plus {args.draw}")
    if args.list:
        for c in cells:
            print(f"{c.name:34s} {'quick' if c.quick else 'full '}  {c.describe()}")
        return 0
    if not cells:
        print(f"no cell matches {args.cells!r}; --list shows them", file=sys.stderr)
        return 2
    if args.json and Path(args.json).exists() and Path(args.json).is_dir():
        print(f"--json {args.json}: is a folder", file=sys.stderr)
        return 2
    folder = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="gfimu-regimes-"))
    folder.mkdir(parents=True, exist_ok=True)
    if options:
        print(f"options: {options}")
    print(f"rule: smoother RMSE <= max({RMSE_FACTOR} x best per-sample, {RMSE_FLOOR_RADPS:g} rad/s); wrong sign <= "
          f"best per-sample's + {100 * SIGN_MARGIN:g} %; consistent logs keep the Gaussian model; CPU time <= "
          f"{TIME_BASE_S:g} s + {TIME_PER_SAMPLE_S * 1e3:g} ms/sample; limit {args.timeout_base:g} s + "
          f"{args.timeout_per_sample * 1e3:g} ms/sample of CPU time per method. Sign: share of samples with |w| > "
          f"{SIGN_MIN_RADPS} rad/s and w_est.w < 0. Times: CPU seconds of the estimate (wall time in --json).")
    print(f"kernels compiled or loaded from numba's cache in {compile_kernels():.1f} s (not in the cells' times)",
          file=sys.stderr, flush=True)
    print(table_header(), flush=True)
    rows = []
    t_all = time.perf_counter()
    try:
        for cell in cells:
            try:
                row = run_cell(cell, folder, args.timeout_base, args.timeout_per_sample, options=options)
            except Exception as exc:  # a cell that cannot be built is reported, the rest still run
                row = {"cell": cell.name, "description": cell.describe(), "samples": 0, "results": {},
                       "verdict": {"cell": "FAIL", "reasons": [f"building the log: {type(exc).__name__}: {exc}"]}}
            rows.append(row)
            print(table_row(row), flush=True)
    finally:
        if not args.keep:
            shutil.rmtree(folder, ignore_errors=True)
    failed = sum(1 for r in rows if (r.get("verdict") or {}).get("cell") != "PASS")
    print(f"\n{len(rows) - failed} of {len(rows)} cells pass; {time.perf_counter() - t_all:.0f} s in all")
    for r in rows:
        print(f"  {r['cell']}: {r['description']}" + (f" ({r['note']})" if r.get("note") else ""))
    if args.json:
        gio.atomic_write_text(args.json, json.dumps([_jsonable(r) for r in rows], indent=2, default=float))
        print(f"written {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
