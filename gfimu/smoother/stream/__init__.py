"""The stream engine: the fixed-lag smoother (a window filter with cross-covariances, its compiled
kernels and an optional GTSAM window), its model re-chosen from the stream's recent past."""
