"""gfimu: rigid-body motion from accelerometer arrays (gyroscope-free IMU).

The main verbs and values, importable from here (``from gfimu import estimate_log``):

- a log: :func:`read_log` (a log folder), :func:`simulate` (a simulated one), :class:`Log`,
  :class:`SensorArray` and :func:`cube_array`;
- an estimate: :func:`make_estimator` (a method by name, :data:`METHODS`), whose ``estimate(log)``
  gives an :class:`Estimate` (``motion``, a :class:`Motion`, and ``report``, a :class:`Report`);
  :func:`estimate_log` does what ``gfimu estimate`` does (read, screen, calibrate, estimate);
  :class:`FixedLagSmoother` takes one sample at a time;
- a score: :func:`evaluate` (an estimate against a truth or reference);
- the errors: :class:`GfimuError` and its kinds :class:`InputError`, :class:`DataError`,
  :class:`ResourceError` (:class:`MissingExtraError`: an optional package not installed).
"""

__version__ = "0.1.0"

# The names load on first use (PEP 562), so that ``import gfimu`` and ``gfimu --help`` import
# neither numpy nor scipy. Each name and the module (under gfimu) it comes from:
_LAZY = {
    "Accelerometer": "array", "ArrayModelError": "array", "Body": "array", "Gyroscope": "array",
    "Inclinometer": "array", "SensorArray": "array", "cube_array": "array",
    "Gap": "log", "Log": "log", "Motion": "motion", "Estimate": "estimate", "Report": "estimate",
    "GfimuError": "errors", "InputError": "errors", "DataError": "errors", "ResourceError": "errors",
    "MissingExtraError": "errors",
    "read_log": "io", "write_log": "io", "simulate": "simulate",
    "METHODS": "methods", "UnknownMethodError": "methods", "make_estimator": "methods",
    "FixedLagSmoother": "smoother.stream.fixed_lag", "evaluate": "evaluation",
    "estimate_log": "pipeline", "EstimateRun": "pipeline",
}


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'gfimu' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))

__all__ = [
    "Accelerometer",
    "ArrayModelError",
    "Body",
    "DataError",
    "Estimate",
    "EstimateRun",
    "FixedLagSmoother",
    "Gap",
    "GfimuError",
    "Gyroscope",
    "Inclinometer",
    "InputError",
    "Log",
    "METHODS",
    "MissingExtraError",
    "Motion",
    "Report",
    "ResourceError",
    "SensorArray",
    "UnknownMethodError",
    "__version__",
    "cube_array",
    "estimate_log",
    "evaluate",
    "make_estimator",
    "read_log",
    "simulate",
    "write_log",
]
