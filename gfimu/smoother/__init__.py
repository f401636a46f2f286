"""Factor-graph smoothers of ω, ω̇ and specific force from accelerometer arrays.

The package reads in layers, each importing only those above it in this list:

- :mod:`gfimu.smoother.model`: the state layout, the factor groups and their noise levels, the
  options (:class:`SmootherOptions`) and the smoothing problem (:class:`SmootherProblem`);
- :mod:`gfimu.smoother.solve`: the banded solver, sign-resolving initial states, restarts, σ scaling;
- :mod:`gfimu.smoother.tuning`: the model checked against the log and the noise tuned by evidence;
- :mod:`gfimu.smoother.guard` and :mod:`gfimu.smoother.result`: the fallback to the per-sample
  answer where the smoother fits worse, and the estimator face both engines share;
- :mod:`gfimu.smoother.batch`: the batch smoother (method "smoother") and its bound;
- :mod:`gfimu.smoother.stream`: the fixed-lag smoother (method "fixed-lag").
"""

from .model.problem import SmootherOptions, SmootherProblem

__all__ = ["SmootherOptions", "SmootherProblem"]
