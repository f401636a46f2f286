"""The noise levels of one smoothing problem, as typed frozen values, and what a factor group reads.

Each built-in factor group computes its own levels from the options and the log
(:meth:`gfimu.smoother.model.groups.FactorGroup.noise`) as one of the frozen values below; the problem
gathers them into one :class:`NoiseLevels` when it is built (:meth:`NoiseLevels.gather`), each under its
named field:

- :attr:`NoiseLevels.accel`, an :class:`AccelNoise`: the accelerometers' std per axis (the option
  ``default_accel_noise_std_mps2`` where array.toml gives none, :func:`gfimu.noise.accel_noise_std`), and
  the per-sample std of the re-weightings; an :class:`InversionNoise` with ``measurement='quadratic'``;
- :attr:`NoiseLevels.first_state`, :attr:`NoiseLevels.force_walk`, :attr:`NoiseLevels.attitude`,
  :attr:`NoiseLevels.motion`, :attr:`NoiseLevels.gyro`, :attr:`NoiseLevels.tilt`, :attr:`NoiseLevels.free_flight`,
  :attr:`NoiseLevels.calibration`: the other groups';
- a group given in ``SmootherOptions.factor_groups`` keeps whatever its ``noise`` gives, read back with
  :meth:`NoiseLevels.of`.

Nothing changes them afterwards: the re-weightings (motion-dependent accelerometer noise, robust losses,
the local motion density, the tuner's accelerometer scale) make new values (:meth:`AccelNoise.scaled`,
:meth:`MotionNoise.scaled_steps`, ...) and a new problem around them
(:meth:`gfimu.smoother.model.problem.SmootherProblem.with_noise`). Their arrays are read-only.

:class:`ModelView` is what a factor group may read of the problem it is given: the batch smoother's
:class:`gfimu.smoother.model.problem.SmootherProblem` and the fixed-lag smoother's view of one or two
samples of a stream (:class:`gfimu.smoother.stream.array_model.StreamView`) both are one. The options it reads
are typed groups, ``model`` (:class:`gfimu.smoother.model.option_groups.ModelOptions`), ``batch_model``
(:class:`gfimu.smoother.model.option_groups.BatchModelOptions`), ``attitude`` and ``self_calibration``, each option
under its own name: ``-O
default_accel_noise_std_mps2=…`` is ``ModelOptions.default_accel_noise_std_mps2``, read by the accelerometer
groups' ``noise`` as ``problem.model.default_accel_noise_std_mps2`` into :attr:`AccelNoise.sigma`, which every
later use reads as ``problem.noise.accel``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from ...array import SensorArray
    from ...log import Log
    from .layout import StateLayout
    from .option_groups import AttitudeOptions, BatchModelOptions, ModelOptions, SelfCalibrationOptions


def _frozen(value):
    if isinstance(value, np.ndarray):
        value = value.view()
        value.flags.writeable = False
    return value


class _Levels:
    """Base of the built-in levels: frozen dataclasses whose array fields are made read-only."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            object.__setattr__(self, f.name, _frozen(getattr(self, f.name)))

    slot: ClassVar[str]
    """The field of :class:`NoiseLevels` these levels fill."""

    def into(self, levels: NoiseLevels) -> NoiseLevels:
        """``levels`` with these in their field :attr:`slot` (a field given twice is an error)."""
        if getattr(levels, self.slot) is not None:
            raise ValueError(f"two factor groups give the {self.slot} noise levels")
        return replace(levels, **{self.slot: self})


@dataclass(frozen=True, eq=False)
class AccelNoise(_Levels):
    """The accelerometers' noise: ``sigma`` (axes,) [m/s²] from array.toml, or the option
    ``default_accel_noise_std_mps2`` for an axis without one (:func:`gfimu.noise.accel_noise_std`);
    ``per_sample`` (N, axes) when the std varies per sample (motion-dependent noise, robust re-weighting),
    ``base`` (N, axes) the per-sample std the robust re-weighting starts from (None: ``sigma``)."""

    slot: ClassVar[str] = "accel"

    sigma: np.ndarray
    per_sample: np.ndarray | None = None
    base: np.ndarray | None = None

    def stds(self) -> np.ndarray:
        """The std each residual is divided by: ``per_sample`` (N, axes), else ``sigma`` (axes,)."""
        return self.sigma if self.per_sample is None else self.per_sample

    def whitening(self, shape: tuple[int, int]) -> np.ndarray:
        """(N, axes) factor on the residuals: ``1 / per_sample``, else ``1 / sigma`` on every sample."""
        if self.per_sample is None:
            return np.broadcast_to(1.0 / self.sigma, shape)
        return 1.0 / self.per_sample

    def start(self, n: int) -> np.ndarray:
        """(n, axes) std the robust re-weighting starts from: ``base``, else ``sigma`` on every sample."""
        if self.base is None:
            return np.broadcast_to(self.sigma, (n, len(self.sigma)))
        return self.base

    def scaled(self, scale: float) -> AccelNoise:
        """Every axis's ``sigma`` times ``scale`` (the tuner's accelerometer noise scale)."""
        return replace(self, sigma=self.sigma * scale)

    def motion_dependent(self, omega_b_radps: np.ndarray, slope_mps2_per_radps: float) -> AccelNoise:
        """Std per sample ``sqrt(σ² + (slope |ω_k|)²)``, also the base of the robust re-weighting."""
        wn = np.linalg.norm(np.asarray(omega_b_radps, dtype=float), axis=1)
        sigma = np.sqrt(self.sigma[None, :] ** 2 + (slope_mps2_per_radps * wn[:, None]) ** 2)
        return replace(self, per_sample=sigma, base=sigma)

    def with_base(self, per_sample: np.ndarray) -> AccelNoise:
        """``per_sample`` (N, axes) as the current std and the re-weighting's base."""
        accel = np.array(per_sample, dtype=float)
        return replace(self, per_sample=accel, base=accel)

    def with_per_sample(self, per_sample: np.ndarray | None) -> AccelNoise:
        """``per_sample`` as the current std (the base kept)."""
        return replace(self, per_sample=per_sample)


@dataclass(frozen=True, eq=False, kw_only=True)
class InversionNoise(AccelNoise):
    """``measurement='quadratic'``: the accelerometers' noise and the per-sample inversion ``x_hat`` (N, 12)
    with its covariance ``x_cov`` and whitening ``x_whiten`` (``L⁻¹``, ``x_cov = L Lᵀ``)."""

    x_hat: np.ndarray
    x_cov: np.ndarray
    x_whiten: np.ndarray

    def scaled(self, scale: float) -> InversionNoise:
        """The accelerometers' std and the inversion's times ``scale``."""
        return replace(self, sigma=self.sigma * scale, x_cov=self.x_cov * scale**2, x_whiten=self.x_whiten / scale)


@dataclass(frozen=True, eq=False)
class FirstStateNoise(_Levels):
    """Stds (9,) or (12,) of the weak prior on the first sample's ``[ω, ω̇, f(, ω̈)]``."""

    slot: ClassVar[str] = "first_state"

    sigma: np.ndarray


@dataclass(frozen=True, eq=False)
class ForceWalkNoise(_Levels):
    """Std (N-1,) of each step of the specific force's random walk."""

    slot: ClassVar[str] = "force_walk"

    step_sigma: np.ndarray


@dataclass(frozen=True, eq=False)
class AttitudeNoise(_Levels):
    """With the attitude: the first attitude's prior (mean ``prior_wb``, stds ``prior_sigma``), the std of each
    kinematics step ``step_sigma`` and of each step of the gravity-free acceleration ``accel_step_sigma``."""

    slot: ClassVar[str] = "attitude"

    prior_wb: np.ndarray
    prior_sigma: np.ndarray
    step_sigma: np.ndarray
    accel_step_sigma: np.ndarray

    def with_prior(self, rotation_wb: np.ndarray) -> AttitudeNoise:
        """The first attitude's prior centred on ``rotation_wb``."""
        return replace(self, prior_wb=rotation_wb)


@dataclass(frozen=True, eq=False)
class MotionNoise(_Levels):
    """The motion model's noise: white jerk's trapezoid and ω̇-step stds (N-1,) per body axis times
    ``axis_factors``; the driven oscillator's unit covariance and whitening per step when ``oscillator``
    (natural frequencies ``natural_frequency_radps``); white snap's ``snap_cov``, ``snap_whiten``; ``base``:
    the (trapezoid, ω̇-step, snap whitening) the robust re-weighting starts from (None: the current)."""

    slot: ClassVar[str] = "motion"

    trapezoid_sigma: np.ndarray
    omega_dot_step_sigma: np.ndarray
    axis_factors: np.ndarray
    natural_frequency_radps: np.ndarray
    oscillator: bool = False
    oscillator_unit_cov: np.ndarray | None = None
    oscillator_unit_whiten: np.ndarray | None = None
    oscillator_unit_sigma: np.ndarray | None = None
    snap_cov: np.ndarray | None = None
    snap_whiten: np.ndarray | None = None
    base: tuple | None = None

    def oscillator_weight(self) -> np.ndarray:
        """(N-1,) factor on the oscillator steps' std: 1, or the re-weighting's (which scales
        ``omega_dot_step_sigma``)."""
        return self.omega_dot_step_sigma / self.oscillator_unit_sigma

    def oscillator_whiten(self) -> np.ndarray:
        """(N-1, 6, 6) whitening of the oscillator steps (inverse Cholesky factor of their covariance)."""
        return self.oscillator_unit_whiten / self.oscillator_weight()[:, None, None]

    def oscillator_covariance(self) -> np.ndarray:
        """(N-1, 6, 6) covariance of the oscillator steps."""
        return self.oscillator_unit_cov * (self.oscillator_weight() ** 2)[:, None, None]

    def start(self) -> tuple:
        """The (trapezoid, ω̇-step, snap whitening) the robust re-weighting starts from."""
        return (self.trapezoid_sigma, self.omega_dot_step_sigma, self.snap_whiten) if self.base is None else self.base

    def scaled_steps(self, factors: np.ndarray) -> MotionNoise:
        """The white-jerk steps' stds times ``factors`` (N-1,)."""
        return replace(self, trapezoid_sigma=self.trapezoid_sigma * factors,
                       omega_dot_step_sigma=self.omega_dot_step_sigma * factors)

    def with_steps(self, trapezoid_sigma: np.ndarray, omega_dot_step_sigma: np.ndarray) -> MotionNoise:
        """These white-jerk step stds as the current ones and the re-weighting's start."""
        return replace(self, trapezoid_sigma=np.array(trapezoid_sigma, dtype=float),
                       omega_dot_step_sigma=np.array(omega_dot_step_sigma, dtype=float), base=None)

    def from_start(self, snap: bool) -> MotionNoise:
        """The noise the re-weighting starts from (:meth:`start`) as the current one, kept as the start."""
        base = self.start()
        if snap:
            return replace(self, trapezoid_sigma=base[0], omega_dot_step_sigma=base[1], base=base,
                           snap_whiten=base[2], snap_cov=None)
        return replace(self, trapezoid_sigma=base[0], omega_dot_step_sigma=base[1], base=base)

    def weighted(self, weights: np.ndarray, snap: bool) -> MotionNoise:
        """The start's stds divided by ``sqrt(weights)`` (N-1,) (the re-weighting's IRLS weights)."""
        base = self.start()
        root = np.sqrt(weights)
        out = replace(self, trapezoid_sigma=base[0] / root, omega_dot_step_sigma=base[1] / root)
        if snap:
            whiten = base[2] * root[:, None, None]
            out = replace(out, snap_whiten=whiten, snap_cov=np.linalg.inv(np.swapaxes(whiten, 1, 2) @ whiten))
        return out


@dataclass(frozen=True, eq=False)
class GyroNoise(_Levels):
    """The gyroscope's white-noise std [rad/s] (array.toml, :func:`gfimu.noise.gyro_noise_std`)."""

    slot: ClassVar[str] = "gyro"

    sigma: float


@dataclass(frozen=True, eq=False)
class TiltNoise(_Levels):
    """The inclinometer's tilt-angle std [rad] (array.toml, :func:`gfimu.noise.tilt_noise_std`)."""

    slot: ClassVar[str] = "tilt"

    sigma: float


@dataclass(frozen=True, eq=False)
class FreeFlightNoise(_Levels):
    """Free flight's stds: the unmodelled torque in Euler's equation ``torque_sigma`` [N m]
    (``torque_noise_std_nm``) and the specific force at the centre of mass ``fall_sigma`` [m/s²]
    (``free_fall_std_mps2``)."""

    slot: ClassVar[str] = "free_flight"

    torque_sigma: float
    fall_sigma: float


@dataclass(frozen=True, eq=False)
class CalibrationNoise(_Levels):
    """The prior std of every calibration variable (G,), in the order of the problem's calibration vector: each
    accelerometer bias ``bias_prior_std_mps2``, scale-factor error ``scale_prior_std``, the gyroscope bias
    ``gyro_bias_prior_std_radps``."""

    slot: ClassVar[str] = "calibration"

    prior_sigma: np.ndarray


@dataclass(frozen=True, eq=False)
class NoiseLevels:
    """The noise levels of a problem's groups, each under its own typed field (None where no group gives
    it), and those of the groups given in the options (:meth:`of`). Immutable: :meth:`replace`."""

    accel: AccelNoise | None = None
    first_state: FirstStateNoise | None = None
    force_walk: ForceWalkNoise | None = None
    attitude: AttitudeNoise | None = None
    motion: MotionNoise | None = None
    gyro: GyroNoise | None = None
    tilt: TiltNoise | None = None
    free_flight: FreeFlightNoise | None = None
    calibration: CalibrationNoise | None = None
    own: tuple[tuple[Any, Any], ...] = ()
    """(group, what its ``noise`` gave) of every group whose levels are not a built-in kind."""

    @classmethod
    def gather(cls, groups, problem: ModelView) -> NoiseLevels:
        """The levels of ``groups`` on ``problem``: each group's ``noise(problem)``, a built-in kind in its field,
        anything else (not None) kept for the group (:meth:`of`)."""
        levels = cls()
        own = []
        for group in groups:
            if callable(getattr(group, "setup", None)):
                from ...errors import InputError

                raise InputError(f"factor group {group.name!r}: give its noise levels with noise(problem), "
                                 "not setup(problem) (a problem is frozen once built)")
            value = group.noise(problem)
            if isinstance(value, _Levels):
                levels = value.into(levels)
            elif value is not None:
                own.append((group, value))
        return replace(levels, own=tuple(own)) if own else levels

    def of(self, group) -> Any:
        """What ``group`` (one given in the options) gave as its noise levels (KeyError if none)."""
        for owner, value in self.own:
            if owner is group:
                return value
        raise KeyError(f"factor group {getattr(group, 'name', group)!r} gave no noise levels")

    def replace(self, **changes) -> NoiseLevels:
        """A new value with these fields changed."""
        return replace(self, **changes)

    @property
    def inversion(self) -> InversionNoise:
        """The per-sample inversion's levels (``measurement='quadratic'``)."""
        if not isinstance(self.accel, InversionNoise):
            raise AttributeError("the problem's measurement is not the per-sample inversion")
        return self.accel


@runtime_checkable
class ModelView(Protocol):
    """What a factor group reads of the problem it is given (:class:`gfimu.smoother.model.problem.SmootherProblem`,
    :class:`gfimu.smoother.stream.array_model.StreamView`): the array and the samples, the model's option groups
    (``model``, ``batch_model``, ``attitude``, ``self_calibration``), the state layout and the noise levels; the
    calibration variables (none in a stream).

    The state's columns are read in one place, :attr:`layout` (a :class:`gfimu.smoother.model.layout.StateLayout`):
    its ``size``, whether it carries the snap (``snap``) and the attitude (``attitude``, its ``rotation``
    columns); a group reads no other name for them."""

    array: SensorArray
    log: Log
    model: ModelOptions
    batch_model: BatchModelOptions
    attitude: AttitudeOptions
    self_calibration: SelfCalibrationOptions
    n: int
    dt_s: np.ndarray
    layout: StateLayout
    use_gyro: bool
    use_inclinometer: bool
    n_global: int
    global_blocks: dict
    noise: NoiseLevels

    def global_part(self, params: np.ndarray, name: str) -> np.ndarray | None: ...
