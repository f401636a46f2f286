"""gfimu: rigid-body motion from accelerometer arrays (gyroscope-free IMU)."""

__version__ = "0.1.0"

# The classes load on first use (PEP 562), so that ``gfimu --help`` does not import numpy and scipy.
_LAZY = {
    "Accelerometer": "array", "ArrayModelError": "array", "Body": "array", "Gyroscope": "array",
    "Inclinometer": "array", "SensorArray": "array", "Gap": "log", "Log": "log", "Motion": "motion",
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
    "Gap",
    "Gyroscope",
    "Inclinometer",
    "Log",
    "Motion",
    "SensorArray",
    "__version__",
]
