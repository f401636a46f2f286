"""Motion scenarios: exact, self-consistent body kinematics at given times.

Every scenario returns :class:`~gfimu.simulate.trajectory.BodyKinematics`
whose ω̇ is the exact derivative of ω, whose attitude is the integral of ω
(analytic for the turntables, :func:`integrate_attitude` otherwise) and whose
acceleration is the exact second derivative of the origin's position,
expressed in B.

Scenarios
---------
turntable               Lu, Tsai & Lin 2010 bench: axis tilted 12°, ±23.5° at 1 Hz, origin 30 mm off the axis
turntable-constant      same bench turning at a constant 180 °/s
random3d                band-limited random 3-D rotation and translation (Lin et al. 2011's hand-held test)
slow3d                  the same, slow: |ω| below 1 rad/s (a hovering drone, a slow hand)
reversal                ω_i = A_i sin(2π f_i t + φ_i): every axis crosses zero about every second
freeflight-major        McGinnis, Perkins & King 2012's Delrin block spun near its major axis (closed-form Euler solution)
freeflight-intermediate ... near its intermediate axis (unstable: the block flips)
freeflight-minor        ... near its minor axis
euroc                   real motion of EuRoC V1_01_easy (shipped with GTSAM), synthetic array readings
kitti                   real motion of a KITTI car drive (shipped with GTSAM), synthetic array readings
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np
from scipy import interpolate

from ..array import Body, SensorArray, single_triad
from ..errors import InputError
from .free_flight import TorqueFreeMotion, box_principal_inertia
from .trajectory import (
    GRAVITY_W_MPS2,
    BodyKinematics,
    gravity_in_body,
    integrate_attitude,
    level_quaternion_from_specific_force,
    quaternion_axis_angle,
    sum_of_sines,
)
from .. import rotations
from ..datasets.gtsam_recordings import RECORDINGS
from .defaults import DURATION_S, RATE_HZ, default_cube

# McGinnis, Perkins & King 2012: the accelerometer sits at a corner of the block's +z face,
# about 15 mm in from both edges and 7 mm above the face (IMU in its casing).
FREE_FLIGHT_SENSOR_POSITION_M = (0.201 / 2 - 0.015, 0.147 / 2 - 0.015, 0.102 / 2 + 0.007)
FREE_FLIGHT_SPIN_RADPS = np.deg2rad(1570.0)  # McGinnis, Perkins & King 2012, Fig. 3 (≈ 27.4 rad/s)


@dataclass(frozen=True)
class Scenario:
    """A named motion with its default rate, duration and array."""

    name: str
    summary: str
    rate_hz: float
    duration_s: float | None  # None: the whole recording
    build: Callable[..., tuple[BodyKinematics, SensorArray]]
    default_array: Callable[[], SensorArray]

    def options(self) -> dict[str, object]:
        """Scenario options and their defaults."""
        sig = inspect.signature(self.build)
        return {k: p.default for k, p in sig.parameters.items() if p.kind is inspect.Parameter.KEYWORD_ONLY}


# --- turntable (Lu, Tsai & Lin 2010, §III) ------------------------------------------------

def _turntable(times_s, theta, theta_dot, theta_ddot, array, tilt_deg, axis_offset_m):
    """Body turning about its z axis, which is tilted by ``tilt_deg`` about world x.

    ``R_wb(t) = R_x(tilt) R_z(θ(t))`` so ``ω_b = (0, 0, θ̇)``. The origin is
    ``axis_offset_m`` from the axis along body −y (Lu, Tsai & Lin 2010: the centre of
    mass 30 mm from the axis along minus y), so its acceleration in B is
    ``ω̇ × d + ω × (ω × d)`` with ``d = (0, −offset, 0)``.
    """
    n = times_s.size
    ez = np.array([0.0, 0.0, 1.0])
    omega = np.zeros((n, 3))
    omega[:, 2] = theta_dot
    omega_dot = np.zeros((n, 3))
    omega_dot[:, 2] = theta_ddot
    d = np.array([0.0, -axis_offset_m, 0.0])
    accel = np.cross(omega_dot, d) + np.cross(omega, np.cross(omega, d))
    q_tilt = quaternion_axis_angle(np.array([1.0, 0.0, 0.0]), np.array(np.deg2rad(tilt_deg)))
    q = rotations.quaternion_multiply(q_tilt, quaternion_axis_angle(ez, theta))
    position = np.einsum("nij,j->ni", rotations.matrix_from_quaternion(q), d)  # axis through the W origin
    return BodyKinematics(times_s, omega, omega_dot, accel, q, position), array


def turntable(times_s, rng, array, *, tilt_deg: float = 12.0, amplitude_deg: float = 23.5,
              frequency_hz: float = 1.0, axis_offset_m: float = 0.030):
    """Sinusoidal turntable of Lu, Tsai & Lin 2010: ``θ = A sin(2π f t)``, A = 23.5°, f = 1 Hz."""
    a = np.deg2rad(amplitude_deg)
    w = 2.0 * np.pi * frequency_hz
    return _turntable(times_s, a * np.sin(w * times_s), a * w * np.cos(w * times_s),
                      -a * w * w * np.sin(w * times_s), array, tilt_deg, axis_offset_m)


def turntable_constant(times_s, rng, array, *, tilt_deg: float = 12.0, rate_deg_s: float = 180.0,
                       axis_offset_m: float = 0.030):
    """Turntable of Lu, Tsai & Lin 2010 turning at a constant rate (180 °/s)."""
    w = np.deg2rad(rate_deg_s)
    return _turntable(times_s, w * times_s, np.full(times_s.size, w), np.zeros(times_s.size),
                      array, tilt_deg, axis_offset_m)


# --- sums of sines: random3d and reversal -------------------------------------------

def _sines_motion(times_s, omega_sines, position_sines, array):
    """ω from sums of sines in B, position of the origin from sums of sines in W."""
    omega = sum_of_sines(times_s, *omega_sines)
    omega_dot = sum_of_sines(times_s, *omega_sines, order=1)
    q = integrate_attitude(lambda t: sum_of_sines(t, *omega_sines), times_s, np.array([1.0, 0, 0, 0]),
                           omega_samples=omega)
    accel_w = sum_of_sines(times_s, *position_sines, order=2)
    r = rotations.matrix_from_quaternion(q)
    accel_b = np.einsum("nji,nj->ni", r, accel_w)
    position = sum_of_sines(times_s, *position_sines)
    return BodyKinematics(times_s, omega, omega_dot, accel_b, q, position), array


def _random_sines(rng, n_components, max_frequency_hz, rms, min_frequency_hz=0.1):
    """(amplitude, frequency, phase) arrays (K, 3) with per-column RMS ``rms``."""
    k = int(n_components)
    if k < 1:
        raise InputError(f"n_components must be >= 1, got {n_components}")
    if not (max_frequency_hz > min_frequency_hz):
        raise InputError(f"max_frequency_hz must exceed {min_frequency_hz} Hz, got {max_frequency_hz}")
    freq = rng.uniform(min_frequency_hz, max_frequency_hz, size=(k, 3))
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(k, 3))
    amp = rng.uniform(0.5, 1.0, size=(k, 3))
    amp *= np.asarray(rms, dtype=float) / np.sqrt(0.5 * np.sum(amp * amp, axis=0))
    return amp, freq, phase


def random3d(times_s, rng, array, *, omega_rms_radps: float = 1.5, max_frequency_hz: float = 2.0,
             position_rms_m: float = 0.1, max_position_frequency_hz: float = 1.5, n_components: int = 6):
    """Smooth arbitrary 3-D rotation and translation (Lin et al. 2011's random motion test).

    Each ω component (in B) is a sum of ``n_components`` sines with random
    frequencies in [0.1, max_frequency_hz] and phases, scaled to
    ``omega_rms_radps``; likewise each coordinate of the origin in W, scaled
    to ``position_rms_m``. With the defaults |ω| reaches about 4-5 rad/s and
    |ω̇| a few tens of rad/s², like a hand-held device.
    """
    omega_sines = _random_sines(rng, n_components, max_frequency_hz, omega_rms_radps)
    position_sines = _random_sines(rng, n_components, max_position_frequency_hz, position_rms_m)
    return _sines_motion(times_s, omega_sines, position_sines, array)


def slow3d(times_s, rng, array, *, omega_rms_radps: float = 0.3, max_omega_radps: float = 1.0,
           max_frequency_hz: float = 1.0, position_rms_m: float = 0.05, max_position_frequency_hz: float = 1.0,
           n_components: int = 6):
    """Slow random 3-D rotation and translation: :func:`random3d`'s sums of sines with ``omega_rms_radps``
    per ω component and frequencies up to ``max_frequency_hz``, scaled down where needed so that |ω|
    does not exceed ``max_omega_radps`` over the log (a hovering drone, a slow hand). The readings then see ω
    through q(ω) ~ |ω|², small against the noise."""
    if not max_omega_radps > 0:
        raise InputError(f"max_omega_radps must be positive, got {max_omega_radps}")
    amp, freq, phase = _random_sines(rng, n_components, max_frequency_hz, omega_rms_radps)
    peak = float(np.max(np.linalg.norm(sum_of_sines(times_s, amp, freq, phase), axis=1))) if times_s.size else 0.0
    if peak > max_omega_radps:
        amp = amp * (max_omega_radps / peak)
    position_sines = _random_sines(rng, n_components, max_position_frequency_hz, position_rms_m)
    return _sines_motion(times_s, (amp, freq, phase), position_sines, array)


def reversal(times_s, rng, array, *, amplitude_radps=(2.0, 2.5, 3.0), frequency_hz=(0.55, 0.75, 0.95),
             phase_rad=(0.0, 1.0, 2.0), position_rms_m: float = 0.05):
    """ω_i(t) = A_i sin(2π f_i t + φ_i) in B: each axis reverses every 1/(2 f_i) s.

    The worst case of the sign ambiguity of ω from q(ω): zero crossings on
    every axis, often near each other. The origin also moves (random sines,
    ``position_rms_m`` per coordinate in W).
    """
    omega_sines = tuple(np.asarray(v, dtype=float).reshape(1, 3) for v in (amplitude_radps, frequency_hz, phase_rad))
    position_sines = _random_sines(rng, 4, 1.5, position_rms_m)
    return _sines_motion(times_s, omega_sines, position_sines, array)


# --- free flight (McGinnis, Perkins & King 2012) -------------------------------------------------------

def free_flight_array(noise_std_mps2: float | None = 0.02) -> SensorArray:
    """McGinnis, Perkins & King 2012's set-up: one triaxial accelerometer near a corner of the Delrin block.

    The paper locates the sensor at a corner of the block's surface without
    printing the vector; :data:`FREE_FLIGHT_SENSOR_POSITION_M` is that corner
    inset by 15 mm, 7 mm above the face. Noise: 0.1 mg/√Hz over 400 Hz
    ≈ 0.02 m/s². B is along the block's edges (x minor, y intermediate,
    z major axis).
    """
    arr = single_triad(FREE_FLIGHT_SENSOR_POSITION_M, noise_std_mps2=noise_std_mps2,
                       body=Body(tuple(box_principal_inertia())))
    return replace(arr, name="paper004-block-triad")


def _free_flight(times_s, array, which, spin_radps, off_axis_fraction):
    body = array.body if array.body is not None else Body(tuple(box_principal_inertia()))
    inertia = np.asarray(body.principal_inertia_kgm2)
    axis = {"major": int(np.argmax(inertia)), "minor": int(np.argmin(inertia))}.get(which)
    if axis is None:
        axis = int(np.argsort(inertia)[1])
    others = [j for j in range(3) if j != axis]
    omega0 = np.zeros(3)
    omega0[axis] = spin_radps
    omega0[others] = off_axis_fraction * spin_radps / np.sqrt(2.0)
    motion = TorqueFreeMotion.from_initial(inertia, omega0)
    omega = motion.omega(times_s)
    q = integrate_attitude(motion.omega, times_s, np.array([1.0, 0, 0, 0]), omega_samples=omega)
    # free fall: the centre of mass accelerates at g, the specific force there is zero
    position = 0.5 * np.outer(times_s**2, GRAVITY_W_MPS2)  # released at rest at the W origin
    kin = BodyKinematics(times_s, omega, motion.omega_dot(times_s), gravity_in_body(q), q, position)
    return kin, (array if array.body is not None else replace(array, body=body))


def freeflight_major(times_s, rng, array, *, spin_radps: float = FREE_FLIGHT_SPIN_RADPS,
                     off_axis_fraction: float = 0.1):
    """Torque-free block spun near its major axis (stable precession)."""
    return _free_flight(times_s, array, "major", spin_radps, off_axis_fraction)


def freeflight_intermediate(times_s, rng, array, *, spin_radps: float = FREE_FLIGHT_SPIN_RADPS,
                            off_axis_fraction: float = 0.02):
    """Torque-free block spun near its intermediate axis (unstable: it flips over)."""
    return _free_flight(times_s, array, "intermediate", spin_radps, off_axis_fraction)


def freeflight_minor(times_s, rng, array, *, spin_radps: float = FREE_FLIGHT_SPIN_RADPS,
                     off_axis_fraction: float = 0.1):
    """Torque-free block spun near its minor axis (stable precession)."""
    return _free_flight(times_s, array, "minor", spin_radps, off_axis_fraction)


# --- real motions (gtsam recordings) -----------------------------------------------

def smooth_recording(times_s, values, bandwidth_hz: float, degree: int = 5) -> interpolate.BSpline:
    """Least-squares B-spline through recorded samples, knots every ``1 / (2 bandwidth)`` s.

    The knots are multiples of that spacing in the recording's time.

    A degree-5 spline keeps ω̇ (its derivative) smooth; the knot spacing
    sets the low-pass cut-off.
    """
    t = np.asarray(times_s, dtype=float)
    if not (bandwidth_hz > 0):
        raise InputError(f"bandwidth_hz must be positive, got {bandwidth_hz}")
    spacing = 0.5 / bandwidth_hz
    # knots on a grid fixed in recording time, so any window of a recording gets the same fit
    grid = np.arange(np.ceil(t[0] / spacing), np.floor(t[-1] / spacing) + 1) * spacing
    interior = grid[(grid > t[0] + 0.5 * spacing) & (grid < t[-1] - 0.5 * spacing)]
    knots = np.concatenate([np.full(degree + 1, t[0]), interior, np.full(degree + 1, t[-1])])
    return interpolate.make_lsq_spline(t, np.asarray(values, dtype=float), knots, k=degree)


def _recorded(times_s, recording, start_s, bandwidth_hz, still_s, array):

    rec = RECORDINGS[recording]().longest_segment()
    if still_s > 0:
        # The recording's gyro bias would tilt the integrated attitude and leak
        # gravity into a; its mean over the initial still period is removed.
        still = rec.times_s <= still_s
        if np.count_nonzero(still) < 2:
            raise InputError(f"{recording}: still_s={still_s:g} s covers fewer than two samples")
        rec = replace(rec, omega_radps=rec.omega_radps - rec.omega_radps[still].mean(axis=0))
    t_end = start_s + float(times_s[-1])
    if start_s < 0 or t_end > rec.duration_s + 1e-9:
        raise InputError(
            f"{recording}: {start_s:g} s + {times_s[-1]:g} s goes beyond the recording "
            f"({rec.duration_s:.2f} s); shorten duration_s or move start_s"
        )
    pad = 5.0 / bandwidth_hz  # fit a little beyond the window to keep spline ends away
    sel = (rec.times_s >= start_s - pad) & (rec.times_s <= t_end + pad)
    t_rec = rec.times_s[sel]
    omega_spline = smooth_recording(t_rec, rec.omega_radps[sel], bandwidth_hz)
    force_spline = smooth_recording(t_rec, rec.specific_force_mps2[sel], bandwidth_hz)
    omega_dot_spline = omega_spline.derivative()
    tt = start_s + times_s
    omega = omega_spline(tt)
    f = force_spline(tt)
    q0 = level_quaternion_from_specific_force(f[0])
    q = integrate_attitude(lambda t: omega_spline(start_s + t), times_s, q0, omega_samples=omega)
    accel = f + gravity_in_body(q)  # a = f + g, in B
    return BodyKinematics(times_s, omega, omega_dot_spline(tt), accel, q), array


def euroc(times_s, rng, array, *, start_s: float = 0.0, bandwidth_hz: float = 20.0, still_s: float = 1.0):
    """Real motion of EuRoC V1_01_easy (MAV in a Vicon room, 200 Hz), synthetic array readings.

    The recorded gyro becomes the true ω through a degree-5 least-squares
    spline (cut-off about ``bandwidth_hz``), whose derivative is ω̇; the
    recorded specific force, smoothed the same way, is the true f at the body
    origin. The attitude integrates ω from the level attitude of the first
    sample, and a = f + Rᵀ g. The mean gyro reading of the first ``still_s``
    seconds (the vehicle at rest) is taken as gyro bias and removed first
    (0 keeps the raw gyro); the rest of the recording's noise and bias drift
    is part of this "true" motion.
    """
    return _recorded(times_s, "euroc", start_s, bandwidth_hz, still_s, array)


def kitti(times_s, rng, array, *, start_s: float = 0.0, bandwidth_hz: float = 10.0, still_s: float = 0.0):
    """Real motion of a KITTI car drive (100 Hz), synthetic array readings (as :func:`euroc`).

    The car is not at rest at the start, so by default (``still_s = 0``) no
    gyro bias is removed.
    """
    return _recorded(times_s, "kitti", start_s, bandwidth_hz, still_s, array)


def _cube():
    return default_cube()


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario("turntable", "Lu, Tsai & Lin 2010 bench: axis tilted 12°, ±23.5° at 1 Hz, origin 30 mm off the axis",
                 1000.0, 10.0, turntable, _cube),
        Scenario("turntable-constant", "Lu, Tsai & Lin 2010 bench turning at a constant 180 °/s", 1000.0, 10.0,
                 turntable_constant, _cube),
        Scenario("random3d", "band-limited random 3-D rotation and translation (Lin et al. 2011)", RATE_HZ, DURATION_S,
                 random3d, _cube),
        Scenario("slow3d", "slow random 3-D rotation and translation, |ω| below 1 rad/s", RATE_HZ, 20.0,
                 slow3d, _cube),
        Scenario("reversal", "ω_i = A_i sin(2π f_i t + φ_i): zero crossings on every axis", RATE_HZ, DURATION_S,
                 reversal, _cube),
        Scenario("freeflight-major", "McGinnis, Perkins & King 2012 block in free flight, spun near its major axis", 1000.0, 2.0,
                 freeflight_major, free_flight_array),
        Scenario("freeflight-intermediate", "McGinnis, Perkins & King 2012 block in free flight, spun near its intermediate axis",
                 1000.0, 2.0, freeflight_intermediate, free_flight_array),
        Scenario("freeflight-minor", "McGinnis, Perkins & King 2012 block in free flight, spun near its minor axis", 1000.0, 2.0,
                 freeflight_minor, free_flight_array),
        Scenario("euroc", "real EuRoC V1_01_easy motion (GTSAM data), synthetic array readings", 200.0, None,
                 euroc, _cube),
        Scenario("kitti", "real KITTI car motion (GTSAM data), synthetic array readings", 100.0, 60.0,
                 kitti, _cube),
    )
}
