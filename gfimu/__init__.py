"""gfimu: rigid-body motion from accelerometer arrays (gyroscope-free IMU)."""

from .array import Accelerometer, ArrayModelError, Body, Gyroscope, Inclinometer, SensorArray
from .log import Gap, Log
from .motion import Motion

__version__ = "0.1.0"

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
