"""Accelerometer arrays: geometry, the linear model and its invertibility.

Pure maths, no I/O (reading and writing ``array.toml`` lives in
:mod:`gfimu.io`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from . import rigid_body
from .errors import InputError
from .rotations import matrix_from_rotation_vector

AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


class ArrayModelError(InputError):
    """The array cannot support the requested model (names the cause)."""


@dataclass(frozen=True)
class Accelerometer:
    """One accelerometer: 1, 2 or 3 axes, at ``position_m`` in B.

    ``rotation_body_sensor`` maps sensor-frame vectors into B:
    ``v_B = rotation_body_sensor @ v_sensor``. ``topic`` names the message
    topic (or stream) the sensor was recorded on, when known; the estimators
    do not use it.
    """

    name: str
    position_m: np.ndarray
    rotation_body_sensor: np.ndarray = field(default_factory=lambda: np.eye(3))
    axes: tuple[str, ...] = ("x", "y", "z")
    noise_std_mps2: float | None = None
    topic: str | None = None
    range_mps2: float | None = None
    """Largest magnitude each axis can read [m/s²] (the full scale, e.g. 16 g = 156.9 m/s²); None: not stated."""

    def __post_init__(self) -> None:
        pos = np.asarray(self.position_m, dtype=float).reshape(-1)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise ArrayModelError(f"accelerometer {self.name!r}: position_m must be 3 finite numbers, got {self.position_m!r}")
        rot = np.asarray(self.rotation_body_sensor, dtype=float)
        if rot.shape != (3, 3) or not np.all(np.isfinite(rot)):
            raise ArrayModelError(f"accelerometer {self.name!r}: rotation_body_sensor must be a 3x3 matrix")
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
            raise ArrayModelError(
                f"accelerometer {self.name!r}: rotation_body_sensor is not a rotation (orthonormal, det +1): {rot.tolist()}"
            )
        axes = tuple(self.axes)
        if not axes or len(set(axes)) != len(axes) or any(a not in AXIS_INDEX for a in axes):
            raise ArrayModelError(f"accelerometer {self.name!r}: axes must be distinct among x, y, z; got {list(axes)}")
        if self.noise_std_mps2 is not None and not (np.isfinite(self.noise_std_mps2) and self.noise_std_mps2 >= 0):
            raise ArrayModelError(f"accelerometer {self.name!r}: noise_std_mps2 must be >= 0")
        if self.topic is not None and (not isinstance(self.topic, str) or not self.topic.strip()):
            raise ArrayModelError(f"accelerometer {self.name!r}: topic must be a non-empty string, got {self.topic!r}")
        if self.range_mps2 is not None and not (np.isfinite(self.range_mps2) and self.range_mps2 > 0):
            raise ArrayModelError(f"accelerometer {self.name!r}: range_mps2 must be a finite number > 0, got {self.range_mps2!r}")
        pos.setflags(write=False)
        rot = rot.copy()
        rot.setflags(write=False)
        object.__setattr__(self, "position_m", pos)
        object.__setattr__(self, "rotation_body_sensor", rot)
        object.__setattr__(self, "axes", axes)

    @property
    def directions_b(self) -> np.ndarray:
        """Unit sensing directions of the listed axes in B, (n_axes, 3)."""
        return np.array([self.rotation_body_sensor[:, AXIS_INDEX[a]] for a in self.axes])

    @property
    def column_names(self) -> list[str]:
        return [f"{self.name}_{a}" for a in self.axes]


@dataclass(frozen=True)
class Gyroscope:
    """A triaxial gyroscope measuring ω in B (columns ``w_x, w_y, w_z``)."""

    noise_std_radps: float | None = None


@dataclass(frozen=True)
class Inclinometer:
    """A two-axis inclinometer giving tilt_x, tilt_y (log format, Lu, Tsai & Lin 2010)."""

    noise_std_rad: float | None = None


@dataclass(frozen=True)
class Body:
    """Principal moments of inertia about the axes of B (McGinnis, Perkins & King 2012)."""

    principal_inertia_kgm2: tuple[float, float, float]

    def __post_init__(self) -> None:
        i = np.asarray(self.principal_inertia_kgm2, dtype=float).reshape(-1)
        if i.shape != (3,) or not np.all(np.isfinite(i)) or np.any(i <= 0):
            raise ArrayModelError(f"body: principal_inertia_kgm2 must be 3 positive numbers, got {self.principal_inertia_kgm2!r}")
        a, b, c = np.sort(i)
        if a + b < c * (1 - 1e-9):
            raise ArrayModelError(f"body: principal_inertia_kgm2 {i.tolist()} violates the triangle inequality")
        object.__setattr__(self, "principal_inertia_kgm2", tuple(float(v) for v in i))


READINGS = ("specific_force", "linear_acceleration")
"""Values of ``array.toml``'s ``readings``: what the accelerometers report."""

_GEOMETRY_REASONS: dict = {}
"""Outcomes of :meth:`SensorArray.geometry_reason` per layout (the smoother asks once per problem)."""


@dataclass(frozen=True)
class SensorArray:
    """A rigid array of accelerometers, with optional gyro, inclinometer and body."""

    accelerometers: tuple[Accelerometer, ...]
    name: str = "array"
    gyroscope: Gyroscope | None = None
    inclinometer: Inclinometer | None = None
    body: Body | None = None
    readings: str = "specific_force"
    """What the accelerometers report (``array.toml``'s ``readings``): ``"specific_force"`` (f = a − g, the
    contract's readings) or ``"linear_acceleration"`` (a, gravity already removed by the recording device, as
    phone apps' "linear acceleration"; ω is unaffected, attitude and gravity-free outputs are refused)."""

    def __post_init__(self) -> None:
        if self.readings not in READINGS:
            raise ArrayModelError(f"readings must be one of {', '.join(map(repr, READINGS))}, got {self.readings!r}")
        accs = tuple(self.accelerometers)
        if not accs:
            raise ArrayModelError("array has no accelerometers")
        names = [a.name for a in accs]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ArrayModelError(f"accelerometer names must be unique; repeated: {dup}")
        object.__setattr__(self, "accelerometers", accs)

    # --- geometry -----------------------------------------------------------
    @cached_property
    def n_axes(self) -> int:
        """Accelerometer axes in all (the array is frozen: counted once, it is read per sample by the streams)."""
        return sum(len(a.axes) for a in self.accelerometers)

    @property
    def accel_columns(self) -> list[str]:
        """imu.csv column names of all accelerometer axes, in model-row order."""
        return [c for a in self.accelerometers for c in a.column_names]

    @property
    def axis_directions_b(self) -> np.ndarray:
        """(n_axes, 3) unit sensing directions in B, in model-row order."""
        return np.vstack([a.directions_b for a in self.accelerometers])

    @property
    def axis_positions_m(self) -> np.ndarray:
        """(n_axes, 3) lever arm of each axis, in model-row order."""
        return np.vstack([np.tile(a.position_m, (len(a.axes), 1)) for a in self.accelerometers])

    @property
    def axis_owner(self) -> np.ndarray:
        """(n_axes,) index of the accelerometer each model row belongs to."""
        return np.concatenate([np.full(len(a.axes), i) for i, a in enumerate(self.accelerometers)])

    @property
    def noise_std_per_axis_mps2(self) -> np.ndarray:
        """(n_axes,) noise std per axis; NaN where array.toml gives none."""
        return np.concatenate(
            [np.full(len(a.axes), np.nan if a.noise_std_mps2 is None else a.noise_std_mps2) for a in self.accelerometers]
        )

    @property
    def range_per_axis_mps2(self) -> np.ndarray:
        """(n_axes,) full scale per axis [m/s²]; NaN where array.toml gives none."""
        return np.concatenate(
            [np.full(len(a.axes), np.nan if a.range_mps2 is None else a.range_mps2) for a in self.accelerometers]
        )

    # --- linear model (Ho & Lin 2009, eqs. 6-7) -------------------------------
    def structure_matrix(self) -> np.ndarray:
        """(n_axes, 12) structure matrix S: readings = S @ [f, ω̇, q(ω)]. Computed once (the array is frozen)
        and read-only: the model checks and every choice a stream makes read it again."""
        return self._structure

    @cached_property
    def _structure(self) -> np.ndarray:
        S = rigid_body.structure_matrix(self.axis_directions_b, self.axis_positions_m)
        S.setflags(write=False)
        return S

    def rank(self, tol: float = 1e-9) -> int:
        s = np.linalg.svd(self.structure_matrix(), compute_uv=False)
        return int(np.sum(s > tol * s[0]))

    def condition_number(self) -> float:
        """2-norm condition number of S; ``inf`` when S has rank below 12."""
        s = np.linalg.svd(self.structure_matrix(), compute_uv=False)
        if s.size < rigid_body.N_UNKNOWNS or s[-1] <= 1e-12 * s[0]:
            return float("inf")
        return float(s[0] / s[-1])

    def check_invertible(self, max_condition: float = 1e8) -> None:
        """Raise :class:`ArrayModelError` naming why S cannot be inverted."""
        n = self.n_axes
        if n < rigid_body.N_UNKNOWNS:
            raise ArrayModelError(
                f"array {self.name!r} has {n} accelerometer axes; the 12-unknown inversion "
                f"[f, ω̇, q(ω)] needs at least 12 (use method 'ml' or add a gyroscope)"
            )
        S = self.structure_matrix()
        sv = np.linalg.svd(S, compute_uv=False)
        positions = np.array([a.position_m for a in self.accelerometers])
        if len(positions) >= 3:
            centred = positions - positions.mean(axis=0)
            spread = np.linalg.svd(centred, compute_uv=False)
            if spread.size < 3 or spread[-1] <= 1e-9 * max(spread[0], 1e-300):
                raise ArrayModelError(
                    f"array {self.name!r}: the accelerometer positions are coplanar, so S (rank "
                    f"{int(np.sum(sv > 1e-9 * sv[0]))} of 12) cannot be inverted; use method 'ml' or 'gyro-aided'"
                )
        if sv[-1] <= 1e-12 * sv[0]:
            raise ArrayModelError(
                f"array {self.name!r}: structure matrix has rank {int(np.sum(sv > 1e-9 * sv[0]))} of 12 "
                "(sensing directions do not span the model); use method 'ml'"
            )
        cond = sv[0] / sv[-1]
        if cond > max_condition:
            raise ArrayModelError(
                f"array {self.name!r}: structure matrix condition number {cond:.3g} exceeds {max_condition:.3g} "
                "(nearly degenerate layout)"
            )

    def linear_condition_number(self) -> float:
        """Condition number of the model's linear block [f, ω̇] with the lever arms taken from the positions'
        centroid and the ω̇ columns divided by the RMS lever arm (unit-free, independent of the body origin);
        ``inf`` when f and ω̇ are not determined (all accelerometers at one point, on one line, or sensing
        directions that do not span the motion)."""
        positions = self.axis_positions_m
        centred = positions - positions.mean(axis=0)
        size = float(np.sqrt(np.mean(np.sum(centred**2, axis=1))))
        if size <= 0:
            return float("inf")
        H = rigid_body.structure_matrix(self.axis_directions_b, centred)[:, :6] / np.array([1, 1, 1, size, size, size])
        sv = np.linalg.svd(H, compute_uv=False)
        if sv.size < 6 or sv[-1] <= 1e-12 * sv[0]:
            return float("inf")
        return float(sv[0] / sv[-1])

    def omega_equations(self) -> int:
        """Number of independent equations per sample left for ω once f and ω̇ are eliminated: the rank of
        ``P⊥ S_q`` (P⊥ the projection orthogonal to the linear block). Three or fewer with 12 or more axes
        (four coplanar triads) leave several exact ω per sample, not only ±ω (docs/geometry.md)."""
        S = self.structure_matrix()
        H, Sq = S[:, :6], S[:, 6:]
        u, sv, _ = np.linalg.svd(H, full_matrices=True)
        r = int(np.sum(sv > 1e-9 * max(sv[0], 1e-300))) if sv.size else 0
        A = u[:, r:].T @ Sq
        if A.size == 0:
            return 0
        sa = np.linalg.svd(A, compute_uv=False)
        return int(np.sum(sa > 1e-9 * max(np.abs(Sq).max(), 1e-300)))

    def omega_condition_number(self) -> float:
        """Condition number of the equations left for ω per sample once f and ω̇ are eliminated, ``P⊥ S_q``
        (6 columns, the quadratic terms; independent of the body origin and of the array's size); ``inf`` when
        fewer than 6 remain independent (coplanar triads: 3)."""
        S = self.structure_matrix()
        H, Sq = S[:, :6], S[:, 6:]
        u, sv, _ = np.linalg.svd(H, full_matrices=True)
        r = int(np.sum(sv > 1e-9 * max(sv[0], 1e-300))) if sv.size else 0
        A = u[:, r:].T @ Sq
        if A.shape[0] < 6:
            return float("inf")
        sa = np.linalg.svd(A, compute_uv=False)
        if sa[-1] <= 1e-12 * max(sa[0], 1e-300):
            return float("inf")
        return float(sa[0] / sa[-1])

    def geometry_reason(self, max_condition: float | None = None, several_solutions: bool = False) -> str | None:
        """``None`` when the accelerometers determine f, ω̇ and ω (see docs/geometry.md), else why not:
        all at one point, on one line, sensing directions that miss a component, or a layout so close to
        those that the linear block's condition number (:meth:`linear_condition_number`) exceeds
        ``max_condition`` (default :data:`MAX_LINEAR_CONDITION`). With ``several_solutions`` (the smoothers) also
        a layout of 12 or more axes whose equations for ω per sample are degenerate or nearly so
        (:meth:`omega_condition_number` over :data:`MAX_OMEGA_CONDITION`; coplanar triads: infinite), whose
        samples then have several exact or nearly exact solutions besides ±ω."""
        limit = MAX_LINEAR_CONDITION if max_condition is None else max_condition
        key = (self.name, limit, several_solutions,
               tuple((a.position_m.tobytes(), a.rotation_body_sensor.tobytes(), tuple(a.axes)) for a in self.accelerometers))
        if key not in _GEOMETRY_REASONS:
            if len(_GEOMETRY_REASONS) > 64:
                _GEOMETRY_REASONS.clear()
            _GEOMETRY_REASONS[key] = self._geometry_reason(limit, several_solutions)
        return _GEOMETRY_REASONS[key]

    def _geometry_reason(self, limit: float, several_solutions: bool) -> str | None:
        """:meth:`geometry_reason`, computed (it depends only on the names, positions and sensing axes)."""
        positions = np.array([a.position_m for a in self.accelerometers])
        centred = positions - positions.mean(axis=0)
        spread = np.linalg.svd(centred, compute_uv=False) if len(positions) > 1 else np.zeros(1)
        size = float(spread[0]) if spread.size else 0.0
        if len(positions) == 1:
            return (f"array {self.name!r} has a single accelerometer: one point does not sense the rotation (method "
                    "'free-flight' estimates it from the body's dynamics)")
        if size <= 1e-9:
            return (f"array {self.name!r}: all accelerometers sit at one point (positions within 1 nm): the rotation "
                    "is not sensed; check position_m (metres, body frame) or add accelerometers elsewhere")
        if spread.size < 2 or spread[1] <= 1e-9 * size:
            return (f"array {self.name!r}: all accelerometers lie on one line: rotation about that line and its ω̇ are "
                    "not sensed; add an accelerometer off the line")
        cond = self.linear_condition_number()
        if not np.isfinite(cond):
            return (f"array {self.name!r}: the sensing directions and lever arms do not determine f and ω̇ (the "
                    "linear block [f, ω̇] of the model is rank deficient); add axes in the missing directions")
        if cond > limit:
            return (f"array {self.name!r}: the layout is nearly degenerate (nearly on one line or one point): the "
                    f"condition number {cond:.3g} of the linear block [f, ω̇] exceeds {limit:.3g} (docs/geometry.md)")
        if several_solutions and self.n_axes >= 12:
            cond_w = self.omega_condition_number()
            if cond_w > MAX_OMEGA_CONDITION:
                what = (f"only {self.omega_equations()} independent equations remain for ω (coplanar triads)"
                        if not np.isfinite(cond_w) else
                        f"the equations left for ω have condition number {cond_w:.3g}, over {MAX_OMEGA_CONDITION:g} "
                        "(nearly coplanar triads)")
                return (f"array {self.name!r}: once f and ω̇ are eliminated {what}: each sample has several "
                        "(nearly) exact solutions besides ±ω and the smoother follows a wrong one (docs/geometry.md); "
                        "move a triad off the plane or use a gyroscope")
        return None

    def inversion_reason(self) -> str | None:
        """``None`` when the 12-unknown inversion works, else why it cannot (the geometry first,
        :meth:`geometry_reason`)."""
        reason = self.geometry_reason() if self.n_axes >= rigid_body.N_UNKNOWNS else None
        if reason:
            return reason
        try:
            self.check_invertible()
        except ArrayModelError as exc:
            return str(exc)
        return None

    def predict_readings(self, specific_force_b, omega_dot_b, omega_b) -> np.ndarray:
        """Noise-free readings (..., n_axes) in each sensor's own frame and axes."""
        f = np.asarray(specific_force_b, dtype=float)
        dw = np.asarray(omega_dot_b, dtype=float)
        w = np.asarray(omega_b, dtype=float)
        x = np.concatenate([f, dw, rigid_body.quadratic_terms(w)], axis=-1)
        return x @ self.structure_matrix().T

    def with_accelerometers(self, accelerometers) -> "SensorArray":
        return SensorArray(tuple(accelerometers), self.name, self.gyroscope, self.inclinometer, self.body,
                           self.readings)


MAX_LINEAR_CONDITION = 40.0
"""Largest condition number of the unit-free linear block [f, ω̇] of an array the methods accept
(:meth:`SensorArray.geometry_reason`). From the study of docs/geometry.md: triads closing in on a line keep the
smoother's accuracy up to 24 and lose it at 71; 40 is about the geometric mean."""
MAX_OMEGA_CONDITION = 450.0
"""Largest condition number of the equations left for ω (:meth:`SensorArray.omega_condition_number`) of an array
the smoothers accept without a gyroscope. From the same study: flattened triads keep the smoother's accuracy up to
141 and lose it at 1414; 450 is about the geometric mean."""


# --- built-in layouts --------------------------------------------------------

def cube_array(half_edge_m: float = 0.05, noise_std_mps2: float | None = 0.07, name: str | None = None) -> SensorArray:
    """Four triads on alternate corners of a cube (Ho & Lin 2009, Fig. 2)."""
    corners = half_edge_m * np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)
    accs = tuple(Accelerometer(f"a{i + 1}", p, noise_std_mps2=noise_std_mps2) for i, p in enumerate(corners))
    return SensorArray(accs, name or f"cube-12 (half edge {half_edge_m:g} m)")


def single_triad(position_m=(0.0, 0.0, 0.0), noise_std_mps2: float | None = 0.07, body: Body | None = None) -> SensorArray:
    """One triaxial accelerometer (McGinnis, Perkins & King 2012's free-flight sensor)."""
    return SensorArray((Accelerometer("a1", np.asarray(position_m, float), noise_std_mps2=noise_std_mps2),), "single-triad", body=body)


def paper001_array(
    m_m: float = 0.5, n_m: float = 0.25, noise_std_mps2: float | None = 0.07, lever_arm_m: float | None = None
) -> SensorArray:
    """Best layout of Lu, Tsai & Lin 2010: three 2-axis accelerometers, gyro, inclinometer.

    ``m_m`` and ``n_m`` are the entries m and n of the paper's gain matrix
    (eq. 9). Inverting that matrix gives the layout (derivation in
    :func:`gfimu.estimators.gyro_aided.paper001_gain_matrix`): chips on three
    alternate corners of a cube of half edge L, ``acc1`` at L(-1, -1, -1)
    sensing x, y (the paper's a1, a2), ``acc2`` at L(-1, 1, 1) sensing z, x
    (a3, a4) and ``acc3`` at L(1, -1, 1) sensing y, z (a5, a6). m must be 0.5;
    ``L = 1 / (4 n)`` metres (the paper's unit-free L = 1 for n = 0.25) unless
    ``lever_arm_m`` is given.
    """
    if not np.isclose(m_m, 0.5):
        raise ArrayModelError(f"paper001 layout: m is the average of two opposite sensors and must be 0.5, got {m_m!r}")
    if lever_arm_m is None:
        if not (np.isfinite(n_m) and n_m > 0):
            raise ArrayModelError(f"paper001 layout: n must be positive, got {n_m!r}")
        lever_arm_m = 1.0 / (4.0 * n_m)
    if not (np.isfinite(lever_arm_m) and lever_arm_m > 0):
        raise ArrayModelError(f"paper001 layout: lever_arm_m must be positive, got {lever_arm_m!r}")
    L = float(lever_arm_m)
    accs = (
        Accelerometer("acc1", [-L, -L, -L], axes=("x", "y"), noise_std_mps2=noise_std_mps2),
        Accelerometer("acc2", [-L, L, L], axes=("z", "x"), noise_std_mps2=noise_std_mps2),
        Accelerometer("acc3", [L, -L, L], axes=("y", "z"), noise_std_mps2=noise_std_mps2),
    )
    return SensorArray(accs, "paper001-9axis", gyroscope=Gyroscope(0.01), inclinometer=Inclinometer(0.002))


def random_array(n_triads: int = 5, half_extent_m: float = 0.03, noise_std_mps2: float | None = 0.07, seed: int = 7,
                 name: str | None = None) -> SensorArray:
    """``n_triads`` triads at uniform random positions within ±``half_extent_m`` per axis, each
    rotated at random (rotation vector drawn from a standard normal); reproducible by ``seed``."""

    rng = np.random.default_rng(seed)
    accs = tuple(
        Accelerometer(f"s{i}", rng.uniform(-half_extent_m, half_extent_m, 3), matrix_from_rotation_vector(rng.normal(size=3)),
                      noise_std_mps2=noise_std_mps2)
        for i in range(n_triads)
    )
    return SensorArray(accs, name or f"random-{n_triads} (±{half_extent_m * 100:g} cm)")


MIMU4444_POSITIONS_M = np.array(
    [
        [-0.00945, 0.00945, 0.001],
        [-0.00945, 0.00945, -0.001],
        [-0.00945, -0.00945, 0.001],
        [-0.00945, -0.00945, -0.001],
        [0.00945, 0.00945, 0.001],
        [0.00945, 0.00945, -0.001],
        [0.00945, -0.00945, 0.001],
        [0.00945, -0.00945, -0.001],
    ]
)


MIMU4444_RANGE_MPS2 = 16 * 9.80665
"""Full scale of the board's accelerometers, ±16 g [m/s²]."""


def mimu4444_array(noise_std_mps2: float | None = 0.05, with_gyroscope: bool = False,
                   range_mps2: float | None = MIMU4444_RANGE_MPS2) -> SensorArray:
    """The eight corner IMUs of the MIMU4444 board (nominal positions, board frame).

    The readings are expressed in the board frame after conversion, so every
    sensor has identity rotation here.
    """
    accs = tuple(Accelerometer(f"imu{i + 1}", p, noise_std_mps2=noise_std_mps2, range_mps2=range_mps2)
                 for i, p in enumerate(MIMU4444_POSITIONS_M))
    return SensorArray(accs, "mimu4444", gyroscope=Gyroscope(0.01) if with_gyroscope else None)


LAYOUTS = {
    "cube": cube_array,
    "paper001": paper001_array,
    "single-triad": single_triad,
    "mimu4444": mimu4444_array,
}
