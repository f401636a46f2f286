"""What a factor group is: the interface every group of :mod:`gfimu.smoother.model.groups` (the built-in model) and
every group given in ``factor_groups`` implements, and the vectorised :class:`Term` its rows come in.

The problem a group is given is a :class:`gfimu.smoother.model.noise_levels.ModelView`: the batch smoother's
:class:`gfimu.smoother.model.problem.SmootherProblem` or the fixed-lag smoother's view of one or two samples
(:class:`gfimu.smoother.stream.array_model.StreamView`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
    """One equation over the samples of a problem (see :mod:`gfimu.smoother.model.groups`). Subclasses set
    :meth:`applies`, :meth:`noise` (their noise levels) and the three views; each is given the problem it
    belongs to."""

    name = "group"
    first = False
    """Whether its terms come right after the measurement's, before the other groups' (only the order of
    summation)."""
    measurement = False
    """Whether it is the array's measurement (evaluated apart by the tuner's evidence and the cost)."""
    per_sample = True
    """Whether each of its rows depends on one sample's state only (unary terms, no calibration
    variables): the fixed-lag smoother can then stream it, evaluating it on each sample alone."""
    steps = False
    """Whether each of its rows ties two consecutive samples at most (binary terms of samples k, k+1, no
    calibration variables): the fixed-lag smoother then takes it into every step, evaluating it on
    the two samples (:meth:`gfimu.smoother.stream.array_model.ArrayModel.step`)."""
    linear = False
    """Whether its rows are affine in the states with Jacobians that depend on the step length and its
    noise only (the fixed-lag smoother then keeps its step per step length)."""
    motion = False
    """Whether its rows are the motion model's, whose stds the local motion density scales
    (:meth:`gfimu.smoother.model.noise_levels.MotionNoise.scaled_steps`; the fixed-lag smoother's steps)."""

    def applies(self, problem) -> bool:
        return True

    def noise(self, problem):
        """Its noise levels, computed from the options and the log (once, when the problem is built;
        :meth:`gfimu.smoother.model.noise_levels.NoiseLevels.gather`): a built-in group's typed value
        (:class:`~gfimu.smoother.model.noise_levels.AccelNoise`, ...), read back under its field
        (``problem.noise.accel``); any other value (a group given in the options), read back with
        ``problem.noise.of(self)``. None by default."""
        return None

    def log_normaliser_parts(self, problem) -> list[float]:
        """:meth:`log_normaliser` as the parts it sums (kept apart so that the sum's rounding does not
        depend on how the groups are cut)."""
        return [self.log_normaliser(problem)]

    def accumulate(self, problem, states: np.ndarray, params: np.ndarray, diag: np.ndarray, lower: np.ndarray,
                   grad: np.ndarray) -> tuple[float, int] | None:
        """Add its ``JᵀJ`` blocks (``diag`` (N, m, m), ``lower`` (N-1, m, m)) and ``Jᵀr`` (``grad`` (N, m))
        straight into the normal equations where it has them in closed form, returning (half its
        squared residuals, its rows); None (the default): the caller accumulates its :meth:`terms`."""
        return None

    def squared_norm(self, problem, states: np.ndarray, params: np.ndarray) -> float:
        """Sum of its squared whitened residuals at ``states`` (twice its share of the cost)."""
        return float(sum(float(np.sum(t.residual**2)) for t in self.terms(problem, states, params)))

    def terms(self, problem, states: np.ndarray, params: np.ndarray) -> list:
        raise NotImplementedError

    def gtsam_factors(self, problem) -> list:
        raise NotImplementedError

    def log_normaliser(self, problem) -> float:
        raise NotImplementedError
