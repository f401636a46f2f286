"""Factor-graph smoothers of ω, ω̇ and specific force from accelerometer arrays.

- :mod:`gfimu.smoother.graph`: options (:class:`SmootherOptions`) and the
  smoothing problem (vectorised factors; the same problem as a GTSAM graph);
- :mod:`gfimu.smoother.initialise`: sign-resolving initial states;
- :mod:`gfimu.smoother.batch`: the batch smoother (method "smoother");
- :mod:`gfimu.smoother.bound`: the smoother's own efficiency bound;
- :mod:`gfimu.smoother.fixed_lag`: the fixed-lag smoother (method "fixed-lag").
"""

from .graph import SmootherOptions, SmootherProblem

__all__ = ["SmootherOptions", "SmootherProblem"]
