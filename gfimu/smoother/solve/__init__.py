"""Solving a window of the model: the banded Gauss-Newton solver, initial states and their sign,
restarts, and the σ scaling by the log's own residuals. Shared by the batch and the stream engine."""
