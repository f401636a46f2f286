"""Where each quantity sits in the smoother's state: one place for every consumer.

A state row of sample k holds ``[ω_k, ω̇_k, f_k]`` (body frame B), then ω̈_k for the
'snap' motion model, then the attitude's rotation vector ``log(R_k)`` (W←B) when the
attitude is estimated; the calibration variables (biases, scale-factor errors, gyroscope
bias) are one vector beside the states, named by :attr:`SmootherProblem.global_blocks
<gfimu.smoother.model.problem.SmootherProblem>`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

OMEGA = slice(0, 3)
"""ω, angular velocity [rad/s]."""
OMEGA_DOT = slice(3, 6)
"""ω̇, angular acceleration [rad/s²]."""
SPECIFIC_FORCE = slice(6, 9)
"""f, specific force at the body origin [m/s²]."""
OMEGA_DDOT = slice(9, 12)
"""ω̈, angular jerk [rad/s³] ('snap' motion model only)."""
KINEMATIC_SIZE = 9
"""Size of ``[ω, ω̇, f]``, the state of the default white-jerk model."""

QUANTITIES = {"omega_b_radps": OMEGA, "omega_dot_b_radps2": OMEGA_DOT, "specific_force_b_mps2": SPECIFIC_FORCE}
"""Motion column name -> its slice of the state."""


@dataclass(frozen=True)
class StateLayout:
    """The columns of a state row for one model (see the module docstring)."""

    snap: bool = False
    attitude: bool = False

    @classmethod
    def of(cls, model, attitude) -> StateLayout:
        """The layout of the model options ``model`` (the motion model) and the attitude options ``attitude``
        (:mod:`gfimu.smoother.model.option_groups`)."""
        return cls(model.motion_model == "snap", bool(attitude.estimate_attitude or attitude.use_inclinometer))

    @classmethod
    def from_options(cls, options) -> StateLayout:
        """The layout of flat options (:class:`gfimu.smoother.model.problem.SmootherOptions`) ``options``."""
        return cls.of(options.model, options.attitude)

    omega = OMEGA
    omega_dot = OMEGA_DOT
    specific_force = SPECIFIC_FORCE

    @property
    def omega_ddot(self) -> slice | None:
        return OMEGA_DDOT if self.snap else None

    @property
    def motion_size(self) -> int:
        """Columns of the motion part ``[ω, ω̇, f(, ω̈)]``."""
        return KINEMATIC_SIZE + (3 if self.snap else 0)

    @property
    def rotation(self) -> slice | None:
        """Rotation vector of the attitude R (W←B) [rad], or None without attitude."""
        return slice(self.motion_size, self.motion_size + 3) if self.attitude else None

    @property
    def size(self) -> int:
        return self.motion_size + (3 if self.attitude else 0)

    def quantities(self, states: np.ndarray) -> dict[str, np.ndarray]:
        """Motion column name -> (N, 3) view of ``states``."""
        return {name: states[:, sl] for name, sl in QUANTITIES.items()}

    def resize(self, states: np.ndarray) -> np.ndarray:
        """``states`` of another motion model in this layout (ω̈ appended as 0 or dropped)."""
        m = states.shape[1]
        if m == self.size:
            return states
        if self.size > m:
            return np.hstack([states, np.zeros((states.shape[0], self.size - m))])
        return states[:, :self.size]
