"""Sensor error models applied to exact readings (seeded, reproducible).

Each accelerometer axis j reads, in its own frame,

    y_j = sat(quant((1 + k_j) s̃_jᵀ f_p(r_j) + b_j + n_j))

with ``f_p = f + ω̇ × r + ω × (ω × r)`` the exact specific force at the sensor,
``s̃_j`` the sensing direction tilted by the misalignment, ``k_j`` the scale
factor error, ``b_j`` a constant bias, ``n_j`` white noise, then quantisation
to the LSB and saturation at the range. The gyroscope reads ``ω + b + n``
(saturated), the inclinometer ``tilt + n``.

Defaults (``SensorErrors()``): white noise only, everything else zero. The
accelerometer noise std is the array's ``noise_std_mps2`` where array.toml
gives one, otherwise the ADXL330 chip figures measured in Ho & Lin 2009 (§V):
0.0742 m/s² on the sensor's x and y axes, 0.1039 m/s² on z. Gyro and
inclinometer noise come from the array's ``[gyroscope]`` and
``[inclinometer]`` tables, else 0.01 rad/s and 0.002 rad.
:meth:`SensorErrors.none` is exactly noise-free; :meth:`SensorErrors.adxl330`
adds the bias, scale, misalignment, 16-bit quantisation and ±3 g range of the
benches of Ho & Lin 2009; Lu, Tsai & Lin 2010; Lin et al. 2011.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..array import SensorArray
from ..errors import InputError

ADXL330_NOISE_XY_MPS2 = 0.0742
ADXL330_NOISE_Z_MPS2 = 0.1039
DEFAULT_GYRO_NOISE_RADPS = 0.01
DEFAULT_INCLINOMETER_NOISE_RAD = 0.002
STANDARD_GRAVITY_MPS2 = 9.80665


@dataclass(frozen=True)
class SensorErrors:
    """Error model of the simulated sensors (all per axis, one sigma).

    ``None`` for a noise std means "from the array, else the default above".
    Biases, scale factors and misalignments are drawn once per simulation
    from zero-mean normal distributions with the given std.
    """

    accel_noise_std_mps2: float | None = None
    accel_bias_std_mps2: float = 0.0
    accel_scale_std: float = 0.0
    accel_misalignment_std_rad: float = 0.0
    accel_quantisation_mps2: float = 0.0
    accel_range_mps2: float = np.inf
    gyro_noise_std_radps: float | None = None
    gyro_bias_std_radps: float = 0.0
    gyro_range_radps: float = np.inf
    inclinometer_noise_std_rad: float | None = None

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None:
                continue
            if not isinstance(v, (int, float, np.floating, np.integer)) or np.isnan(v) or v < 0:
                raise InputError(f"SensorErrors.{f.name} must be a non-negative number, got {v!r}")
            if f.name.endswith("range_mps2") or f.name.endswith("range_radps"):
                if v == 0:
                    raise InputError(f"SensorErrors.{f.name} must be positive (use inf for no saturation)")
            elif not np.isfinite(v):
                raise InputError(f"SensorErrors.{f.name} must be finite, got {v!r}")

    @classmethod
    def none(cls) -> "SensorErrors":
        """Exact readings: no noise, bias, scale, misalignment, quantisation or saturation."""
        return cls(accel_noise_std_mps2=0.0, gyro_noise_std_radps=0.0, inclinometer_noise_std_rad=0.0)

    @classmethod
    def white(cls, accel_noise_std_mps2: float) -> "SensorErrors":
        """White accelerometer noise of the given std on every axis, nothing else."""
        return cls(accel_noise_std_mps2=accel_noise_std_mps2)

    @classmethod
    def adxl330(cls) -> "SensorErrors":
        """ADXL330 benches (Ho & Lin 2009; Lu, Tsai & Lin 2010; Lin et al. 2011): chip noise, ±3 g, 16-bit ADC over ±10 V at 300 mV/g.

        Bias 0.05 m/s², scale 1 %, misalignment 5 mrad (one sigma) stand for
        an uncalibrated module; ADXRS610 gyro ±300 °/s.
        """
        lsb = 20.0 / 2**16 / 0.300 * STANDARD_GRAVITY_MPS2
        return cls(
            accel_bias_std_mps2=0.05,
            accel_scale_std=0.01,
            accel_misalignment_std_rad=0.005,
            accel_quantisation_mps2=lsb,
            accel_range_mps2=3.0 * STANDARD_GRAVITY_MPS2,
            gyro_bias_std_radps=0.01,
            gyro_range_radps=np.deg2rad(300.0),
        )

    # --- resolved noise levels ---------------------------------------------
    def accel_noise_per_axis_mps2(self, array: SensorArray) -> np.ndarray:
        """(n_axes,) white-noise std of each accelerometer axis for this array."""
        if self.accel_noise_std_mps2 is not None:
            return np.full(array.n_axes, float(self.accel_noise_std_mps2))
        std = array.noise_std_per_axis_mps2.copy()
        chip = np.array([ADXL330_NOISE_Z_MPS2 if ax == "z" else ADXL330_NOISE_XY_MPS2
                         for acc in array.accelerometers for ax in acc.axes])
        missing = np.isnan(std)
        std[missing] = chip[missing]
        return std

    def gyro_noise_radps(self, array: SensorArray) -> float:
        if self.gyro_noise_std_radps is not None:
            return float(self.gyro_noise_std_radps)
        g = array.gyroscope
        return DEFAULT_GYRO_NOISE_RADPS if g is None or g.noise_std_radps is None else float(g.noise_std_radps)

    def inclinometer_noise_rad(self, array: SensorArray) -> float:
        if self.inclinometer_noise_std_rad is not None:
            return float(self.inclinometer_noise_std_rad)
        i = array.inclinometer
        return DEFAULT_INCLINOMETER_NOISE_RAD if i is None or i.noise_std_rad is None else float(i.noise_std_rad)

    # --- application -------------------------------------------------------
    def misaligned_directions_b(self, array: SensorArray, rng: np.random.Generator) -> np.ndarray:
        """(n_axes, 3) actual sensing directions: nominal ones tilted by random small angles."""
        s = array.axis_directions_b
        if self.accel_misalignment_std_rad == 0:
            return s
        delta = rng.normal(0.0, self.accel_misalignment_std_rad, size=s.shape)
        delta -= np.sum(delta * s, axis=1, keepdims=True) * s  # perpendicular part only
        tilted = s + delta
        return tilted / np.linalg.norm(tilted, axis=1, keepdims=True)

    def accel_readings(self, array: SensorArray, specific_force_b, omega_dot_b, omega_b,
                       rng: np.random.Generator, chunk: int = 20_000, progress=None) -> np.ndarray:
        """Accelerometer readings (N, n_axes) in each sensor's own frame and axes.

        Misalignment, scale factors and biases are drawn once, then the
        samples are processed in chunks of ``chunk`` rows (``progress(iterable,
        total)`` may wrap the chunk loop, e.g. with a progress bar).
        """
        f = np.asarray(specific_force_b, dtype=float)
        dw = np.asarray(omega_dot_b, dtype=float)
        w = np.asarray(omega_b, dtype=float)
        n_axes = array.n_axes
        directions = self.misaligned_directions_b(array, rng)
        scale = 1.0 + rng.normal(0.0, self.accel_scale_std, size=n_axes) if self.accel_scale_std > 0 else None
        bias = rng.normal(0.0, self.accel_bias_std_mps2, size=n_axes) if self.accel_bias_std_mps2 > 0 else None
        std = self.accel_noise_per_axis_mps2(array)
        positions = np.array([a.position_m for a in array.accelerometers])
        owner = array.axis_owner
        out = np.empty((f.shape[0], n_axes))
        starts = range(0, f.shape[0], max(int(chunk), 1))
        if progress is not None:
            starts = progress(starts, len(starts))
        for s in starts:
            sl = slice(s, s + chunk)
            fw, dww, ww = f[sl, None, :], dw[sl, None, :], w[sl, None, :]
            # exact specific force at each accelerometer, (n, n_acc, 3)
            at_sensor = fw + np.cross(dww, positions[None]) + np.cross(ww, np.cross(ww, positions[None]))
            y = np.einsum("nji,ji->nj", at_sensor[:, owner, :], directions)
            if scale is not None:
                y = y * scale
            if bias is not None:
                y = y + bias
            if np.any(std > 0):
                y = y + rng.standard_normal(y.shape) * std
            if self.accel_quantisation_mps2 > 0:
                y = np.round(y / self.accel_quantisation_mps2) * self.accel_quantisation_mps2
            if np.isfinite(self.accel_range_mps2):
                y = np.clip(y, -self.accel_range_mps2, self.accel_range_mps2)
            out[sl] = y
        return out

    def gyro_readings(self, array: SensorArray, omega_b, rng: np.random.Generator) -> np.ndarray:
        """Gyroscope readings (N, 3) in B."""
        w = np.array(omega_b, dtype=float)
        if self.gyro_bias_std_radps > 0:
            w += rng.normal(0.0, self.gyro_bias_std_radps, size=3)
        std = self.gyro_noise_radps(array)
        if std > 0:
            w += rng.standard_normal(w.shape) * std
        if np.isfinite(self.gyro_range_radps):
            w = np.clip(w, -self.gyro_range_radps, self.gyro_range_radps)
        return w

    def tilt_readings(self, array: SensorArray, tilt_rad, rng: np.random.Generator) -> np.ndarray:
        """Inclinometer readings (N, 2)."""
        t = np.array(tilt_rad, dtype=float)
        std = self.inclinometer_noise_rad(array)
        if std > 0:
            t += rng.standard_normal(t.shape) * std
        return t
