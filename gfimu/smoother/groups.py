"""Factor groups: one physical equation over a log, written once for every consumer.

A group gives, for a :class:`gfimu.smoother.graph.SmootherProblem`,

- :meth:`FactorGroup.terms`: its whitened residuals and analytic Jacobians over all samples at
  once (vectorised; the batch solver and the tuner's normal equations),
- :meth:`FactorGroup.gtsam_factors`: the same residuals as GTSAM factors (the graph path),
- :meth:`FactorGroup.log_normaliser`: ``Σ log σ`` over its rows (the tuner's evidence),

so the batch solver, the noise tuner, the bound and the GTSAM graph read one definition. The
model's built-in groups that live here are the gyroscope (paper 001), free flight (paper 004,
eq. 1: Euler's torque-free equation and zero specific force), the inclinometer (paper 001) and the
calibration priors; the accelerometer measurement and the motion model are still written in
:class:`gfimu.smoother.graph.SmootherProblem`. Further groups are given with
``SmootherOptions.factor_groups`` and reach every consumer without changing any of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..factors import (
    attitude_key,
    diagonal_noise,
    euler,
    free_fall,
    gyroscope,
    inclinometer,
    omega_dot_key,
    omega_key,
    process,
    specific_force_key,
)
from .layout import OMEGA, OMEGA_DOT, SPECIFIC_FORCE


@dataclass
class Term:
    """Whitened residuals and Jacobians of one group of factors, vectorised.

    ``kind`` 'unary' (one state, rows per sample), 'binary' (samples k, k+1)
    or 'global' (calibration variables only). ``jac`` maps 'x' (unary) or
    'x0'/'x1' (binary) to (N, r, state size); ``jac_global`` is (N, r, G) or None.
    """

    kind: str
    residual: np.ndarray
    jac: dict
    jac_global: np.ndarray | None = None
    first: int = 0


class FactorGroup:
    """One equation over the samples of a problem (see the module docstring). Subclasses set
    :meth:`applies` and the three views; each is given the problem it belongs to."""

    name = "group"

    def applies(self, problem) -> bool:
        return True

    def terms(self, problem, states: np.ndarray, params: np.ndarray) -> list:
        raise NotImplementedError

    def gtsam_factors(self, problem) -> list:
        raise NotImplementedError

    def log_normaliser(self, problem) -> float:
        raise NotImplementedError


def unary_jacobian(problem, blocks: list[tuple[slice, np.ndarray]], rows: int, n: int) -> np.ndarray:
    """(n, rows, state size) Jacobian with the given (n, rows, 3) blocks at their state columns."""
    J = np.zeros((n, rows, problem.state_size))
    for sl, block in blocks:
        J[:, :, sl] = block
    return J


class GyroscopeGroup(FactorGroup):
    """``ω_k + b_g - ω_meas,k`` with the gyroscope's noise (paper 001), bias when self-calibrating."""

    name = "gyroscope"

    def applies(self, problem) -> bool:
        return bool(problem.use_gyro)

    def terms(self, problem, states, params):
        n, s = problem.n, problem.gyro_sigma
        gb = problem.global_part(params, "gyro_bias")
        r, j = gyroscope.gyroscope_residual(states[:, OMEGA], problem.log.gyro_b_radps, gb)
        jg = None
        if gb is not None:
            jg = np.zeros((n, 3, problem.n_global))
            jg[:, :, problem.global_blocks["gyro_bias"][0]] = j["g"] / s
        return [Term("unary", r / s, {"x": unary_jacobian(problem, [(OMEGA, j["w"])], 3, n) / s}, jg)]

    def gtsam_factors(self, problem):
        kg = problem.global_blocks["gyro_bias"][1] if "gyro_bias" in problem.global_blocks else None
        noise = diagonal_noise(np.full(3, problem.gyro_sigma))
        return [gyroscope.make_gyroscope_factor(omega_key(k), problem.log.gyro_b_radps[k], noise, kg) for k in range(problem.n)]

    def log_normaliser(self, problem):
        return 3 * problem.n * float(np.log(problem.gyro_sigma))


class FreeFlightGroup(FactorGroup):
    """Free flight (paper 004, eq. 1): Euler's torque-free equation ``I ω̇ + ω × I ω = 0`` (torque
    noise ``torque_noise_std_nm``) and zero specific force (``free_fall_std_mps2``)."""

    name = "free flight"

    def applies(self, problem) -> bool:
        return bool(problem.options.free_flight)

    def terms(self, problem, states, params):
        n, opt = problem.n, problem.options
        r, j = euler.euler_residual(states[:, OMEGA], states[:, OMEGA_DOT], problem.log.array.body.principal_inertia_kgm2)
        s = opt.torque_noise_std_nm
        out = [Term("unary", r / s, {"x": unary_jacobian(problem, [(OMEGA, j["w"]), (OMEGA_DOT, j["d"])], 3, n) / s})]
        r, j = free_fall.free_fall_residual(states[:, SPECIFIC_FORCE])
        s = opt.free_fall_std_mps2
        out.append(Term("unary", r / s, {"x": unary_jacobian(problem, [(SPECIFIC_FORCE, j["f"])], 3, n) / s}))
        return out

    def gtsam_factors(self, problem):
        opt = problem.options
        inertia = problem.log.array.body.principal_inertia_kgm2
        torque = diagonal_noise(np.full(3, opt.torque_noise_std_nm))
        fall = diagonal_noise(np.full(3, opt.free_fall_std_mps2))
        out = []
        for k in range(problem.n):
            out.append(euler.make_euler_factor(omega_key(k), omega_dot_key(k), inertia, torque))
            out.append(free_fall.make_free_fall_factor(specific_force_key(k), fall))
        return out

    def log_normaliser(self, problem):
        opt = problem.options
        return 3 * problem.n * float(np.log(opt.torque_noise_std_nm) + np.log(opt.free_fall_std_mps2))


class InclinometerGroup(FactorGroup):
    """The inclinometer's two tilt angles against the attitude's direction cosines of gravity
    (paper 001, eqs. 12-13), when the attitude is estimated with ``use_inclinometer``."""

    name = "inclinometer"

    def applies(self, problem) -> bool:
        return bool(problem.attitude and problem.use_inclinometer)

    def terms(self, problem, states, params):
        s = problem.tilt_sigma
        r, j = inclinometer.inclinometer_residual(problem.rotations(states), problem.log.tilt_rad)
        J = unary_jacobian(problem, [(problem.layout.rotation, j["r"])], 2, problem.n) / s
        return [Term("unary", r / s, {"x": J})]

    def gtsam_factors(self, problem):
        noise = diagonal_noise(np.full(2, problem.tilt_sigma))
        return [inclinometer.make_inclinometer_factor(attitude_key(k), problem.log.tilt_rad[k], noise) for k in range(problem.n)]

    def log_normaliser(self, problem):
        return 2 * problem.n * float(np.log(problem.tilt_sigma))


class CalibrationPriorGroup(FactorGroup):
    """Zero-mean priors on the calibration variables (biases, scale-factor errors, gyroscope bias),
    so that nothing in the problem is unobserved."""

    name = "calibration priors"

    def applies(self, problem) -> bool:
        return problem.n_global > 0

    def terms(self, problem, states, params):
        s = problem.global_prior_sigma()
        return [Term("global", (params / s)[None], {}, np.diag(1.0 / s)[None])]

    def gtsam_factors(self, problem):
        s = problem.global_prior_sigma()
        return [process.make_prior_factor(key, np.zeros(sl.stop - sl.start), diagonal_noise(s[sl]))
                for sl, key in problem.global_blocks.values()]

    def log_normaliser(self, problem):
        return float(np.sum(np.log(problem.global_prior_sigma())))


BUILT_IN = (GyroscopeGroup(), FreeFlightGroup(), InclinometerGroup(), CalibrationPriorGroup())
"""The built-in groups defined here, in the order the problem adds them."""
