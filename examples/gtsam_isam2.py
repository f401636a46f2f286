"""gfimu's accelerometer-array factors in your own GTSAM graph, solved incrementally with ISAM2.

The graph holds, for every sample k of a log with a gyroscope:

- gfimu's factors (``gfimu.factors``), on the variables ω_k, ω̇_k, f_k (vectors in the body frame B, keys
  ``omega_key(k)`` ...) and the attitude R_k (``Rot3``, key ``attitude_key(k)``):
  one accelerometer factor per sensor (its reading = sᵀ(f + ω̇×r + ω×(ω×r)) plus white noise), the
  trapezoid step ω_{k+1} = ω_k + h (ω̇_k + ω̇_{k+1}) / 2, random walks of ω̇ and f, and the attitude step
  R_{k+1} = R_k Exp(h (ω_k + ω_{k+1}) / 2);
- GTSAM's own factors, as a GTSAM user already has them: a ``PriorFactorRot3`` on the first attitude, an
  ``AHRSFactor`` from ``PreintegratedAhrsMeasurements`` of the gyro between keyframes (every
  ``--keyframe`` samples) with a gyro bias per keyframe, a ``BetweenFactorVector`` (the bias random walk)
  between consecutive biases and a ``PriorFactorVector`` on the first bias.

The gyro reaches ω only through the keyframe rotations, the accelerometers give ω sample by sample: the
two together give ω, and the gyro bias, at the log's rate. ``gtsam.ISAM2`` is updated once per keyframe
with that keyframe's factors and initial values.

Run it on a log folder with a gyroscope (``gfimu convert ... --with-gyro``, or a simulated one with a gyro
in its array), or let it write the simulated log of docs/gtsam.md first (``--simulate``, into a new folder)::

    python examples/gtsam_isam2.py LOG [--simulate] [--keyframe 10] [--seconds 2] [--out estimate.csv]

It prints the ω RMSE against the log's truth when it has one, and writes ω, ω̇ and f as an estimate CSV
with ``--out``. ``tests/test_gtsam_example.py`` runs it on a simulated log. Needs ``gtsam`` (the
``smoother`` extra).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np


@dataclass
class Noise:
    """Standard deviations; the densities are gfimu's smoother defaults (``SmootherOptions``)."""

    accel_mps2: float  # per reading
    gyro_radps: float  # per reading
    omega_dot_density: float = 30.0  # white angular jerk [rad/s^2/sqrt(s)]
    specific_force_density: float = 30.0  # [m/s^2/sqrt(s)]
    attitude_density: float = 1e-3  # [rad/sqrt(s)]
    gyro_bias_density: float = 1e-3  # bias random walk [rad/s/sqrt(s)]
    gyro_bias_prior_radps: float = 0.05
    first_attitude_rad: float = 1e-3


@dataclass
class Result:
    omega_b_radps: np.ndarray  # (N, 3)
    omega_dot_b_radps2: np.ndarray  # (N, 3)
    specific_force_b_mps2: np.ndarray  # (N, 3)
    gyro_bias_radps: np.ndarray  # (keyframes, 3)
    updates: int


def bias_key(i: int) -> int:
    import gtsam

    return gtsam.symbol("g", i)


def solve(log, keyframe: int = 10, noise: Noise | None = None, first_attitude_wb=None) -> Result:
    """ω, ω̇, f of every sample of ``log`` (a :class:`gfimu.log.Log` with a gyroscope) from gfimu's accelerometer
    factors and GTSAM's AHRS factors, updated into ``gtsam.ISAM2`` one keyframe at a time."""
    import gtsam

    from gfimu.factors import attitude_key, omega_dot_key, omega_key, specific_force_key
    from gfimu.factors import diagonal_noise, isotropic_noise
    from gfimu.factors.accelerometer import array_geometry, make_accelerometer_factor
    from gfimu.factors.kinematics import make_angular_velocity_factor, make_attitude_factor, trapezoid_sigma
    from gfimu.factors.process import make_random_walk_factor, random_walk_sigma
    from gfimu.rotations import matrix_from_rotation_vector as exp_so3

    if log.gyro_b_radps is None:
        raise ValueError(f"{log.source}: the log has no gyroscope channels (w_x, w_y, w_z)")
    if noise is None:
        accel = [a.noise_std_mps2 for a in log.array.accelerometers if a.noise_std_mps2]
        gyro = log.array.gyroscope.noise_std_radps if log.array.gyroscope else None
        noise = Noise(float(np.mean(accel)) if accel else 0.05, gyro or 0.01)
    t = (log.timestamps_ns - log.timestamps_ns[0]) * 1e-9
    n = len(log)
    geometry = array_geometry(log.array)
    accel_noise = [isotropic_noise(d.shape[0], noise.accel_mps2) for d, _, _ in geometry]
    first = gtsam.Rot3() if first_attitude_wb is None else gtsam.Rot3(np.asarray(first_attitude_wb, float))

    params = gtsam.PreintegratedRotationParams()
    # GTSAM takes the gyro's continuous-time covariance: a reading's variance times its period
    params.setGyroscopeCovariance(noise.gyro_radps ** 2 * float(np.median(np.diff(t))) * np.eye(3))

    isam = gtsam.ISAM2(gtsam.ISAM2Params())  # GTSAM's defaults (relinearisation checked every 10th update)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    # GTSAM's own priors: the first attitude and the first gyro bias; weak ones on gfimu's first state
    graph.add(gtsam.PriorFactorRot3(attitude_key(0), first, isotropic_noise(3, noise.first_attitude_rad)))
    graph.add(gtsam.PriorFactorVector(bias_key(0), np.zeros(3), isotropic_noise(3, noise.gyro_bias_prior_radps)))
    for key, sigma in ((omega_key(0), 100.0), (omega_dot_key(0), 1000.0), (specific_force_key(0), 1000.0)):
        graph.add(gtsam.PriorFactorVector(key, np.zeros(3), isotropic_noise(3, sigma)))
    values.insert(bias_key(0), np.zeros(3))

    estimate = gtsam.Values()
    attitude = first
    bias = np.zeros(3)
    pim = gtsam.PreintegratedAhrsMeasurements(params, bias)
    keyframe_start = 0
    i = 0  # the current keyframe's bias
    updates = 0
    for k in range(n):
        gyro = log.gyro_b_radps[k] - bias
        # initial values: the gyro for ω, the mean of the readings turned into B for f, the attitude carried on
        values.insert(omega_key(k), gyro.copy())
        values.insert(omega_dot_key(k), np.zeros(3))
        readings_b = [acc.rotation_body_sensor @ _full_triad(log.accel_mps2[k, sl], acc.axes)
                      for acc, (_, _, sl) in zip(log.array.accelerometers, geometry)]
        values.insert(specific_force_key(k), np.mean(readings_b, axis=0))
        if k:
            h = float(t[k] - t[k - 1])
            attitude = attitude.compose(gtsam.Rot3(exp_so3(0.5 * h * (log.gyro_b_radps[k - 1] + log.gyro_b_radps[k]
                                                                      - 2 * bias))))
        values.insert(attitude_key(k), attitude)
        # gfimu: one factor per accelerometer on (ω_k, ω̇_k, f_k)
        for (directions, positions, sl), model in zip(geometry, accel_noise):
            graph.add(make_accelerometer_factor(omega_key(k), omega_dot_key(k), specific_force_key(k),
                                                log.accel_mps2[k, sl], directions, positions, model))
        if k:
            # gfimu: the motion model and the attitude step between samples k-1 and k
            graph.add(make_angular_velocity_factor(omega_key(k - 1), omega_key(k), omega_dot_key(k - 1),
                                                   omega_dot_key(k), h,
                                                   diagonal_noise(np.full(3, trapezoid_sigma(noise.omega_dot_density, h)))))
            graph.add(make_random_walk_factor(omega_dot_key(k - 1), omega_dot_key(k),
                                              isotropic_noise(3, random_walk_sigma(noise.omega_dot_density, h))))
            graph.add(make_random_walk_factor(specific_force_key(k - 1), specific_force_key(k),
                                              isotropic_noise(3, random_walk_sigma(noise.specific_force_density, h))))
            graph.add(make_attitude_factor(attitude_key(k - 1), attitude_key(k), omega_key(k - 1), omega_key(k), h,
                                           isotropic_noise(3, random_walk_sigma(noise.attitude_density, h))))
            # GTSAM: the gyro preintegrated between keyframes, the mean of the step's two readings (the trapezoid
            # of gfimu's attitude step: with the reading at the step's start alone, the two would differ by
            # h (ω_j - ω_i) / 2 per keyframe, which the bias would take up)
            pim.integrateMeasurement(0.5 * (log.gyro_b_radps[k - 1] + log.gyro_b_radps[k]), h)
        if (k - keyframe_start == keyframe) or (k == n - 1 and k > keyframe_start):
            j = i + 1
            graph.add(gtsam.AHRSFactor(attitude_key(keyframe_start), attitude_key(k), bias_key(i), pim))
            graph.add(gtsam.BetweenFactorVector(bias_key(i), bias_key(j), np.zeros(3), isotropic_noise(
                3, noise.gyro_bias_density * np.sqrt(float(t[k] - t[keyframe_start])))))
            values.insert(bias_key(j), bias)
            isam.update(graph, values)
            updates += 1
            graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
            estimate = isam.calculateEstimate()
            bias = np.asarray(estimate.atVector(bias_key(j)), float)
            attitude = estimate.atRot3(attitude_key(k))
            pim = gtsam.PreintegratedAhrsMeasurements(params, bias)
            keyframe_start, i = k, j
    if not values.empty() or graph.size():  # a log of one sample
        isam.update(graph, values)
        updates += 1
        estimate = isam.calculateEstimate()
    return Result(
        np.array([estimate.atVector(omega_key(k)) for k in range(n)]),
        np.array([estimate.atVector(omega_dot_key(k)) for k in range(n)]),
        np.array([estimate.atVector(specific_force_key(k)) for k in range(n)]),
        np.array([estimate.atVector(bias_key(b)) for b in range(i + 1)]),
        updates,
    )


def _full_triad(values: np.ndarray, axes: str) -> np.ndarray:
    """A reading of the listed axes as a 3-vector of the sensor frame (0 on the axes not listed)."""
    out = np.zeros(3)
    out[["xyz".index(a) for a in axes]] = values
    return out


def simulated_log():
    """The log of docs/gtsam.md and tests/test_gtsam_example.py: 2 s of ``random3d`` motion at 200 Hz seen by the
    5 cm cube (0.07 m/s² noise) and a gyro with 0.01 rad/s noise and a constant bias drawn with 0.02 rad/s per
    axis, seed 3."""
    from dataclasses import replace

    from gfimu.array import Gyroscope, cube_array
    from gfimu.simulate import SensorErrors, simulate

    array = replace(cube_array(0.025, noise_std_mps2=0.07), gyroscope=Gyroscope(0.01))
    return simulate("random3d", array=array, rate_hz=200.0, duration_s=2.0, seed=3,
                    noise=SensorErrors(gyro_bias_std_radps=0.02))


def main(argv: list[str] | None = None) -> int:
    from pathlib import Path

    from gfimu import io as gio
    from gfimu.motion import Motion

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", help="log folder (array.toml, imu.csv with w_x, w_y, w_z)")
    parser.add_argument("--keyframe", type=int, default=10, help="samples per AHRS factor and ISAM2 update (default 10)")
    parser.add_argument("--seconds", type=float, default=None, help="use only the first seconds of the log")
    parser.add_argument("--out", default=None, help="write ω, ω̇ and f as an estimate CSV here")
    parser.add_argument("--simulate", action="store_true",
                        help="first write LOG, a new folder: the simulated log of docs/gtsam.md (simulated_log())")
    args = parser.parse_args(argv)
    if args.simulate:
        if Path(args.log).exists():
            parser.error(f"--simulate writes {args.log}, which exists; name a new folder")
        gio.write_log(simulated_log(), args.log)
        print(f"log written: {args.log}")
    log = gio.read_log(args.log)
    if args.seconds is not None:
        log = log.select(np.nonzero((log.timestamps_ns - log.timestamps_ns[0]) * 1e-9 <= args.seconds)[0])
    first = None
    if log.truth is not None and log.truth.quaternion_wb is not None:
        from gfimu.rotations import matrix_from_quaternion

        first = matrix_from_quaternion(log.truth.quaternion_wb[0])
    result = solve(log, keyframe=args.keyframe, first_attitude_wb=first)
    print(f"{len(log)} samples, {result.updates} ISAM2 updates; gyro bias at the end "
          f"{np.round(result.gyro_bias_radps[-1], 5).tolist()} rad/s")
    if log.truth is not None and log.truth.omega_b_radps is not None:
        err = result.omega_b_radps - log.truth.omega_b_radps
        print(f"omega RMSE against the truth: {float(np.sqrt(np.mean(np.sum(err ** 2, axis=1)))):.5f} rad/s")
    if args.out:
        motion = Motion(log.timestamps_ns, omega_b_radps=result.omega_b_radps,
                        omega_dot_b_radps2=result.omega_dot_b_radps2,
                        specific_force_b_mps2=result.specific_force_b_mps2)
        gio.write_motion_csv(motion, args.out)
        print(f"estimate written: {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
