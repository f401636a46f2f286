"""Factors of the gfimu smoother: one module per physical equation.

Every module offers

- a pure, vectorised numpy function ``<equation>_residual(...)`` returning the
  residuals of N instances at once and their analytic Jacobians (used by the
  banded batch engine of :mod:`gfimu.smoother.batch.engine`), and
- a constructor ``make_<equation>_factor(keys..., measurement..., noise_model)``
  returning a ``gtsam.CustomFactor`` whose error function calls the same
  numpy function for one instance (used by the GTSAM graph path and the
  fixed-lag smoother).

Residuals are *predicted minus measured* (or the constraint violation) and
are not whitened; whitening is done by the noise model (GTSAM) or by the
batch engine with the same standard deviations.

Key conventions (``gtsam.symbol(char, index)``), all vectors stored as plain
numpy vectors in ``gtsam.Values`` (read with ``Values.atVector``):

========  =================================================  ===========
char      variable                                           type
========  =================================================  ===========
``'w'``   ω_k, angular velocity of sample k in B [rad/s]       vector 3
``'d'``   ω̇_k, angular acceleration of sample k in B [rad/s²]  vector 3
``'f'``   f_k, specific force at the body origin in B [m/s²]  vector 3
``'j'``   ω̈_k, angular jerk of sample k in B [rad/s³]        vector 3
``'a'``   a_k, gravity-free acceleration of the origin in B    vector 3
``'r'``   R_k, attitude W←B of sample k                       ``Rot3``
``'b'``   bias of accelerometer i (one per listed axis) [m/s²]  vector n_i
``'s'``   scale-factor error of accelerometer i (dimensionless) vector n_i
``'g'``   gyroscope bias [rad/s]                              vector 3
========  =================================================  ===========

Rot3 Jacobians are with respect to the right perturbation R ← R Exp(δ),
GTSAM's tangent-space convention.
"""

from __future__ import annotations

import numpy as np

GRAVITY_W_MPS2 = np.array([0.0, 0.0, -9.80665])


def _symbol(char: str, index: int) -> int:
    """``gtsam.symbol(char, index)`` without importing gtsam: the character in the top byte, the index below."""
    return (ord(char) << 56) | int(index)


def omega_key(k: int) -> int:
    return _symbol("w", int(k))


def omega_dot_key(k: int) -> int:
    return _symbol("d", int(k))


def specific_force_key(k: int) -> int:
    return _symbol("f", int(k))


def omega_ddot_key(k: int) -> int:
    return _symbol("j", int(k))


def accel_key(k: int) -> int:
    return _symbol("a", int(k))


def attitude_key(k: int) -> int:
    return _symbol("r", int(k))


def bias_key(i: int) -> int:
    return _symbol("b", int(i))


def scale_key(i: int) -> int:
    return _symbol("s", int(i))


def gyro_bias_key() -> int:
    return _symbol("g", 0)


def vector_at(values: gtsam.Values, key: int) -> np.ndarray:
    return np.asarray(values.atVector(key), dtype=float)


def rotation_at(values: gtsam.Values, key: int) -> np.ndarray:
    return np.asarray(values.atRot3(key).matrix(), dtype=float)


def custom_factor(noise_model, keys, error) -> gtsam.CustomFactor:
    """Wrap ``error(values) -> (residual, [jacobian per key])`` as a CustomFactor."""

    def error_function(this: gtsam.CustomFactor, values: gtsam.Values, jacobians) -> np.ndarray:
        residual, jac = error(values)
        if jacobians is not None:
            for i, j in enumerate(jac):
                jacobians[i] = np.ascontiguousarray(np.atleast_2d(j), dtype=float)
        return np.asarray(residual, dtype=float).reshape(-1)

    import gtsam

    return gtsam.CustomFactor(noise_model, [int(k) for k in keys], error_function)


def isotropic_noise(dim: int, sigma: float):
    import gtsam

    return gtsam.noiseModel.Isotropic.Sigma(int(dim), float(sigma))


def diagonal_noise(sigmas) -> gtsam.noiseModel.Diagonal:
    import gtsam

    return gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, dtype=float))


def gaussian_noise(covariance) -> gtsam.noiseModel.Gaussian:
    import gtsam

    return gtsam.noiseModel.Gaussian.Covariance(np.asarray(covariance, dtype=float))
