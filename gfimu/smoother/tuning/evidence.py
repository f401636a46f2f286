"""Automatic choice of the smoother's process noise by the marginal likelihood of the data.

The smoother's model is Gaussian: a Gauss-Markov prior on the states
(white angular jerk of density q, or white snap) and Gaussian measurement
noise. With the measurement model linearised at an estimate ``x̄``, the
evidence of the data given the noise parameters θ is exact for the
linearised model (Laplace approximation of the nonlinear one):

    log p(y | θ) = -c*(θ) - ½ log det H(θ) - Σ_rows log σ_row(θ) - ½ (R - D) log 2π

where ``c*`` is the minimum of the quadratic model of the cost (half the
sum of squared whitened residuals; ``c* = c(x̄) - ½ gᵀ H⁻¹ g`` after one
Gauss-Newton step), ``H = JᵀJ`` the information matrix (its log-determinant
comes for free from the banded Cholesky factor), ``σ_row`` the standard
deviations of all factor rows (the normalising constants of the Gaussian
factors; the map from the states to the process residuals has unit
Jacobian determinant for the random-walk, trapezoid and white-snap steps),
R the number of rows and D the number of unknowns. One evaluation costs
one Gauss-Newton iteration, linear in the length.

:func:`tune` maximises it over the jerk (or snap) density on a log-spaced
grid refined by parabolic interpolation in ``log q``, re-linearising at the
smoother's solution with the selected density once (two rounds); optionally
also over a common scale of the accelerometer noise and over the motion
model ('jerk' against 'snap', compared by their maxima). Nothing here uses
the truth.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from ...log import Log
from ..solve.banded import (Factorisation, NormalEquations, add_normal_equations, band_structure_of, factorise, factorise_blocks,
                     normal_equations, solve, solve_step)
from ..model.problem import SmootherProblem, check_oscillators
from ..model.option_groups import ModelGroups, ModelOptions
from ..model.groups import Term
from ..solve.initialise import initial_estimate
from ..model.layout import OMEGA, OMEGA_DOT, StateLayout

InitialStates = Callable[[Log, ModelGroups], np.ndarray]
"""``(window log, option groups of the model) -> initial states (N, state size)``, e.g.
:func:`gfimu.smoother.solve.initialise.initial_estimate`."""

DENSITY_FIELD = {"jerk": "omega_dot_random_walk_radps2_per_sqrt_s", "snap": "omega_ddot_random_walk_radps3_per_sqrt_s"}
DENSITY_LIMITS = (1e-3, 1e8)
"""Search limits of the density [rad/s²/√s or rad/s³/√s]."""


@dataclass(frozen=True)
class Tuning:
    """Outcome of :func:`tune` for one solve window."""

    motion_model: str
    density: float
    """Selected jerk density [rad/s²/√s] ('jerk') or snap density [rad/s³/√s] ('snap')."""
    accel_noise_scale: float
    """Selected factor on the accelerometer noise std of every axis (1 when not tuned)."""
    log_evidence: float
    """Linearised log marginal likelihood at the selection [nats]."""
    evaluations: int
    """Number of settings whose evidence was computed."""
    axis_factors: tuple = (1.0, 1.0, 1.0)
    """Selected factor on the density per body axis."""
    specific_force_density: float = float("nan")
    """Selected specific-force random-walk density [m/s²/√s]."""
    axis_frequencies_hz: tuple = (0.0, 0.0, 0.0)
    """Selected natural frequency of the oscillator model per body axis [Hz] (0: white jerk)."""
    axis_frequency_std_hz: tuple = (0.0, 0.0, 0.0)
    """Std of that frequency from the curvature of the evidence [Hz]."""
    axis_amplitude_radps: tuple = (0.0, 0.0, 0.0)
    """Amplitude of the oscillation, √2 × RMS of the estimated ω about the axis [rad/s]."""

    def for_stream(self, model: ModelOptions, memory_s: float = 1.0) -> ModelOptions:
        """The ``model`` (carrying this selection) for a stream that goes on past the tuning data:
        on each oscillator axis the jerk density is raised, if needed, to ``√(2 τ) A Ω δΩ`` (τ =
        ``memory_s``, A the amplitude, δΩ the frequency's std), the density whose phase diffusion
        over τ covers the phase drift ``δΩ τ`` that the frequency's error causes. Without it the
        model, tuned stiff on a short stretch, drifts away from a long oscillation."""
        factors = np.array(model.process_axis_factors, dtype=float)
        q = model.omega_dot_random_walk_radps2_per_sqrt_s
        for a in range(3):
            f, sf, amp = self.axis_frequencies_hz[a], self.axis_frequency_std_hz[a], self.axis_amplitude_radps[a]
            if f > 0:
                floor = np.sqrt(2.0 * memory_s) * amp * (2 * np.pi * f) * (2 * np.pi * sf)
                factors[a] = max(factors[a], floor / q)
        return replace(model, process_axis_factors=tuple(float(v) for v in factors))

    def apply(self, groups: ModelGroups) -> ModelGroups:
        """The option ``groups`` with this selection in their model and batch model (the jerk density is the
        model's, the snap density the batch model's; the accelerometer noise scale is not an option, see
        :func:`make_problem`)."""
        model, batch_model = groups.model, groups.batch_model
        changes = {"process_axis_factors": tuple(self.axis_factors), "motion_model": self.motion_model}
        if self.motion_model == "jerk":
            changes[DENSITY_FIELD["jerk"]] = self.density
            changes["process_axis_frequencies_hz"] = tuple(float(v) for v in self.axis_frequencies_hz)
        else:
            batch_model = replace(batch_model, **{DENSITY_FIELD["snap"]: self.density})
        if np.isfinite(self.specific_force_density):
            changes["specific_force_random_walk_mps2_per_sqrt_s"] = self.specific_force_density
        return groups._replace(model=replace(model, **changes), batch_model=batch_model)

    def as_dict(self) -> dict:
        return {"motion_model": self.motion_model, "density": self.density, "axis_factors": list(self.axis_factors),
                "specific_force_density": self.specific_force_density, "accel_noise_scale": self.accel_noise_scale,
                "axis_frequencies_hz": list(self.axis_frequencies_hz), "axis_frequency_std_hz": list(self.axis_frequency_std_hz),
                "axis_amplitude_radps": list(self.axis_amplitude_radps), "log_evidence": self.log_evidence,
                "evaluations": self.evaluations}


def make_problem(log: Log, groups: ModelGroups, accel_noise_scale: float = 1.0,
                 omega_b_radps: np.ndarray | None = None) -> SmootherProblem:
    """:class:`SmootherProblem` of the option ``groups`` with every accelerometer noise std multiplied by
    ``accel_noise_scale`` and, when ``groups.batch_model.accel_noise_slope_mps2_per_radps`` is set, growing with
    |ω| of ``omega_b_radps``."""
    problem = SmootherProblem(log, groups)
    batch_model = groups.batch_model
    if accel_noise_scale != 1.0:
        problem = problem.with_noise(accel=problem.noise.accel.scaled(accel_noise_scale))  # the inversion's too ('quadratic')
    slope = batch_model.accel_noise_slope_mps2_per_radps
    if slope > 0 and omega_b_radps is not None and batch_model.measurement == "accelerometer":
        problem = problem.with_noise(accel=problem.noise.accel.motion_dependent(omega_b_radps, slope))
    return problem


def log_normaliser(problem: SmootherProblem) -> float:
    """``Σ log σ`` over all factor rows (½ log det of the covariance of the stacked factors), the sum of
    the model's groups' (:meth:`SmootherProblem.log_normaliser`)."""
    return problem.log_normaliser()


def linearised_log_evidence(problem: SmootherProblem, states: np.ndarray, params: np.ndarray | None = None,
                            measurement: NormalEquations | None = None, total: NormalEquations | None = None,
                            factorisation: Factorisation | None = None,
                            minimum: Callable[[np.ndarray, np.ndarray], float] | None = None) -> float:
    """Log marginal likelihood of the data under ``problem`` linearised at ``states`` [nats] (module docstring).

    ``measurement``: the normal equations of the measurement factors at ``states`` (see
    :func:`measurement_normal_equations`), reused while only the process noise changes; ``total``:
    those of all factors of ``problem`` at ``states`` when already known, and ``factorisation`` their
    factor when known too, with ``minimum(δx, δp)`` the linearised cost at the step (see
    :class:`ProcessBasis`).

    The minimum ``c*`` is the linearised cost at the Gauss-Newton step, ``½ Σ |r + J δ|²`` with the
    process rows evaluated row by row (:func:`linearised_half_cost`), not ``c(x̄) - ½ gᵀH⁻¹g``: a
    stiff setting makes the process cost at ``x̄`` many orders above ``c*`` (3.9·10¹³ against 4,830
    on a turntable log with an axis factor of 10⁻⁶) and the difference would lose tens of nats to
    rounding, enough to steer the search."""
    P = np.zeros(problem.n_global) if params is None else params
    if total is not None:
        ne = total
    elif measurement is None:
        ne = normal_equations(problem, states, P, problem.terms(states, P))
    else:
        ne = add_normal_equations(measurement, normal_equations(problem, states, P, problem.process_terms(states, P)))
    fac = factorise(ne, 0.0) if factorisation is None else factorisation
    dx, dp = solve_step(ne, fac)
    if minimum is not None:
        c_min = minimum(dx, dp)
    elif ne.terms is not None:
        c_min = linearised_half_cost(ne.terms, dx, dp)
    else:  # c + gᵀδ + ½ δᵀHδ with Hδ = -g (exact only when c is of the order of the minimum)
        c_min = ne.cost + 0.5 * (float(ne.grad.reshape(-1) @ dx.reshape(-1)) + float(ne.grad_global @ dp))
    logdet = 2.0 * float(np.sum(np.log(fac.cb[0]))) - 2.0 * float(np.sum(np.log(fac.scale)))
    if fac.schur is not None:
        logdet += float(np.linalg.slogdet(fac.schur)[1])
    unknowns = states.size + problem.n_global
    return -c_min - 0.5 * logdet - log_normaliser(problem) - 0.5 * (ne.rows - unknowns) * np.log(2 * np.pi)


def linearised_half_cost(terms: list, dx: np.ndarray, dp: np.ndarray) -> float:
    """``½ Σ |r + J δ|²`` over ``terms`` at the step (δx (N, m), δp (G,)): the cost of the linearised
    factors, a sum of squares that no rounding can turn negative."""
    total = 0.0
    for t in terms:
        if t.kind == "unary":
            k0 = t.first
            lin = t.residual + np.einsum("nrj,nj->nr", t.jac["x"], dx[k0:k0 + t.residual.shape[0]])
        elif t.kind == "binary":
            lin = t.residual + np.einsum("nrj,nj->nr", t.jac["x0"], dx[:-1]) + np.einsum("nrj,nj->nr", t.jac["x1"], dx[1:])
        else:
            lin = t.residual
        if t.jac_global is not None and dp.size:
            lin = lin + t.jac_global @ dp
        total += 0.5 * float(np.sum(lin * lin))
    return total


PROBE_FACTORS = (2.0, 3.0, 5.0, 7.0)
"""Factors on the noise std of the motion rows of body axes x, y, z and of the specific-force rows
with which :meth:`ProcessBasis.of` tells the rows apart."""


@dataclass
class _Part:
    """The nonzero entries of one part's normal equations (the same in every sample)."""

    diag: tuple  # (flat indices into m², values (N, k))
    lower: tuple
    grad: tuple
    cost: float

    @classmethod
    def of_terms(cls, terms: list, n: int, m: int, hessian: _Part | None = None) -> _Part | None:
        """The normal equations of ``terms`` in this form, each product taken over the columns where its
        Jacobian is nonzero (a row of the motion model touches two or four columns, not 2m);
        None for terms on the calibration variables. ``hessian``: a part whose terms had these Jacobians
        (the same numbers): its ``diag`` and ``lower`` are taken as they are, only the gradient and the
        cost are made from ``terms``."""
        stores = {"diag": {}, "lower": {}, "grad": {}}
        lengths = {"diag": n, "lower": n - 1, "grad": n}

        def put(target, flat, offset, values):  # values (samples, len(flat))
            store = stores[target]
            for j, f in enumerate(flat):
                if f not in store:
                    store[f] = np.zeros(lengths[target])
                store[f][offset:offset + len(values)] += values[:, j]

        def columns(J):
            c = np.flatnonzero(np.count_nonzero(J.reshape(-1, J.shape[-1]), axis=0))
            return c, J[:, :, c]

        def pairs(a, b):
            return (a[:, None] * m + b[None, :]).reshape(-1)

        cost = 0.0
        for t in terms:
            if t.kind not in ("unary", "binary") or t.jac_global is not None:
                return None
            r = t.residual
            cost += 0.5 * float(np.sum(r * r))
            blocks = [(t.jac["x"], t.first)] if t.kind == "unary" else [(t.jac["x0"], 0), (t.jac["x1"], 1)]
            cols = []
            for J, offset in blocks:
                c, Jc = columns(J)
                cols.append((c, Jc))
                if c.size:
                    if hessian is None:
                        JcT = np.ascontiguousarray(np.swapaxes(Jc, 1, 2))
                        put("diag", pairs(c, c), offset, (JcT @ Jc).reshape(len(Jc), -1))
                    put("grad", c, offset, np.einsum("nr,nrj->nj", r, Jc))
            if hessian is None and t.kind == "binary" and cols[0][0].size and cols[1][0].size:
                (c0, J0c), (c1, J1c) = cols
                put("lower", pairs(c1, c0), 0, (np.ascontiguousarray(np.swapaxes(J1c, 1, 2)) @ J0c).reshape(len(J0c), -1))

        def compact(store, length):
            idx = np.array(sorted(store), dtype=int)
            values = np.stack([store[f] for f in idx], axis=1) if idx.size else np.zeros((length, 0))
            return idx, values

        if hessian is not None:
            return cls(hessian.diag, hessian.lower, compact(stores["grad"], n), cost)
        return cls(*(compact(stores[k], lengths[k]) for k in ("diag", "lower", "grad")), cost)


@dataclass
class ProcessBasis:
    """The normal equations of a problem's non-measurement factors at fixed states, as a weighted sum
    over the noise parameters that the tuner searches: ``Σ_c w_c(θ) N_c`` with ``N_c`` those of the
    rows whose std scales with parameter c at unit settings, ``w = 1/(q f_a)²`` for the motion rows of
    body axis a (density q, axis factor f_a), ``1/q_f²`` for the specific force's, 1 for the rest
    (priors, gyroscope, ...). One evaluation of the evidence then needs no factor evaluation.

    :meth:`of` finds which rows scale with which parameter from the problem itself, at unit settings
    and at :data:`PROBE_FACTORS`, and gives None when some row scales otherwise (then the factors are
    evaluated for every setting, as before)."""

    parts: dict
    """'const', 0, 1, 2 (body axes), 'force' -> the normal equations of those rows at unit settings."""
    rows: int
    n_global: int
    terms: dict
    """The same keys -> those rows as terms (for the linearised cost, :meth:`BandedSum.half_cost`)."""

    labels: list = field(default_factory=list)
    """Per process term (in order): the (key, rows) it was split into."""
    unit_terms: list = field(default_factory=list)
    """The process terms at unit settings at the states this basis was made at."""

    @classmethod
    def of(cls, log: Log, groups: ModelGroups, field: str, states: np.ndarray,
           params: np.ndarray, omega_b_radps: np.ndarray | None = None,
           previous: ProcessBasis | None = None) -> ProcessBasis | None:
        """The basis at ``states`` (None where it does not apply, see the class). ``previous``: the basis
        of the same problem at other states; where the process factors' Jacobians there are the same
        numbers as here (factors linear in the states: the white jerk, the random walks, the priors), its
        split of the rows and its products ``JᵀJ`` are kept and only the gradients and costs are made
        here (:meth:`at`): the same numbers as made afresh."""
        model = groups.model
        if model.motion_model != "jerk" or any(f > 0 for f in model.process_axis_frequencies_hz):
            return None  # (the white-snap system is too stiff for sums that agree to many digits)
        unit = replace(model, **{field: 1.0}, process_axis_factors=(1.0, 1.0, 1.0),
                       specific_force_random_walk_mps2_per_sqrt_s=1.0)
        problem = make_problem(log, groups._replace(model=unit), 1.0, omega_b_radps)
        terms = problem.process_terms(states, params)
        if previous is not None and previous.same_jacobians(terms):
            return previous.at(terms, problem.n, problem.state_size)
        fx, fy, fz, ff = PROBE_FACTORS
        probe = replace(unit, process_axis_factors=(fx, fy, fz), specific_force_random_walk_mps2_per_sqrt_s=ff)
        probed = make_problem(log, groups._replace(model=probe), 1.0, omega_b_radps).process_terms(states, params)
        if len(terms) != len(probed):
            return None
        factors = {1.0: "const", fx: 0, fy: 1, fz: 2, ff: "force"}
        split: dict = {key: [] for key in factors.values()}
        labels = []
        for t, u in zip(terms, probed):
            if t.kind != u.kind or t.residual.shape != u.residual.shape:
                return None
            row_label = _row_labels(_row_entries(t), _row_entries(u), factors)
            if row_label is None:
                return None
            labels.append([])
            for key in factors.values():
                rows = [i for i, k in enumerate(row_label) if k == key]
                if rows:
                    split[key].append(_term_rows(t, rows))
                    labels[-1].append((key, rows))
        parts = {key: _Part.of_terms(ts, problem.n, problem.state_size) for key, ts in split.items() if ts}
        if any(part is None for part in parts.values()):
            return None  # calibration variables in the process factors: not written for here
        rows = sum(t.residual.size for ts in split.values() for t in ts)
        return cls(parts, rows, problem.n_global, {key: ts for key, ts in split.items() if ts}, labels, terms)

    def same_jacobians(self, terms: list) -> bool:
        """Whether ``terms`` (the process terms at unit settings) have this basis's Jacobians, bit for bit."""
        if len(terms) != len(self.unit_terms) or len(terms) != len(self.labels):
            return False
        for t, u in zip(terms, self.unit_terms):
            if (t.kind != u.kind or t.first != u.first or t.residual.shape != u.residual.shape
                    or t.jac_global is not None or u.jac_global is not None or sorted(t.jac) != sorted(u.jac)):
                return False
            if not all(np.array_equal(t.jac[k], u.jac[k]) for k in t.jac):
                return False
        return True

    def at(self, terms: list, n: int, m: int) -> ProcessBasis:
        """This basis with the residuals of ``terms`` (the same Jacobians, :meth:`same_jacobians`): the rows
        split as here, each part's ``JᵀJ`` kept, its gradient and cost from ``terms``."""
        split: dict = {}
        for t, labelled in zip(terms, self.labels):
            for key, rows in labelled:
                split.setdefault(key, []).append(_term_rows(t, rows))
        parts = {key: _Part.of_terms(ts, n, m, hessian=self.parts[key]) for key, ts in split.items()}
        return ProcessBasis(parts, self.rows, self.n_global, split, self.labels, terms)

    def banded(self, measurement: NormalEquations, previous: BandedSum | None = None) -> BandedSum:
        """The same weighted sum kept in the band order of the banded Cholesky factorisation, so that
        one setting costs a few vector additions and the factorisation (:class:`BandedSum`); ``previous``:
        one made before whose parts' band entries may be kept (:meth:`BandedSum.of`)."""
        return BandedSum.of(self, measurement, previous)


@dataclass
class BandedSum:
    """The measurement's normal equations plus the weighted sum of :class:`ProcessBasis`, factored
    (:func:`gfimu.smoother.solve.banded.factorise`), with the measurement's and each part's entries gathered
    into the band order once: a setting adds the parts' few nonzero band entries, weighted, to the
    measurement's and factors the result (the evidence of the factors evaluated per setting, to
    rounding: ``tests/test_banded_fast.py``)."""

    structure: object
    measurement: NormalEquations
    blocks: np.ndarray
    """(kd + 1, N, m) the measurement's band entries (:meth:`gfimu.smoother.solve.banded.BandStructure.blocks`)."""
    parts: dict
    """key -> (band rows, band columns, values (k, N), gradient columns, gradient values (N, j), cost)."""
    rows: int
    basis: ProcessBasis

    @classmethod
    def of(cls, basis: ProcessBasis, measurement: NormalEquations, previous: BandedSum | None = None) -> BandedSum:
        """``previous``: a sum made before; the band entries of each of its parts whose ``JᵀJ`` is the one
        of ``basis`` (the same arrays: :meth:`ProcessBasis.at` keeps them) are kept when the band is the
        same, only the gradients and costs are taken from ``basis``."""
        if measurement.terms is None:
            raise ValueError("BandedSum needs the measurement's normal equations with their terms "
                             "(measurement_normal_equations)")
        n, m = measurement.grad.shape
        pattern = np.count_nonzero(measurement.lower.reshape(-1, m * m), axis=0) > 0
        for part in basis.parts.values():
            idx, values = part.lower
            pattern[idx[np.any(values != 0, axis=0)]] = True
        structure = band_structure_of(pattern.reshape(m, m))
        blocks = structure.blocks(measurement.diag, measurement.lower)
        parts = {}
        for key, part in basis.parts.items():
            kept = None if previous is None or previous.structure is not structure else previous.parts.get(key)
            old = None if previous is None else previous.basis.parts.get(key)
            if kept is not None and old is not None and old.diag is part.diag and old.lower is part.lower:
                parts[key] = kept[:3] + (part.grad[0], part.grad[1], part.cost)
                continue
            flat = np.zeros((n, 2 * m * m + 1))
            flat[:, part.diag[0]] = part.diag[1]
            flat[: n - 1, m * m + part.lower[0]] = part.lower[1]
            band = np.take(flat, structure.index, axis=1)  # (N, kd + 1, m)
            d, p = np.nonzero(np.any(band != 0, axis=0))
            parts[key] = (d, p, np.ascontiguousarray(band[:, d, p].T), part.grad[0], part.grad[1], part.cost)
        return cls(structure, measurement, blocks, parts, basis.rows, basis)

    @staticmethod
    def weights(density: float, axis_factors, force_density: float) -> dict:
        """The factor on each part's normal equations at these settings (:class:`ProcessBasis`)."""
        weights = {"const": 1.0, "force": 1.0 / force_density**2}
        for a in range(3):
            weights[a] = 1.0 / (density * axis_factors[a]) ** 2
        return weights

    def half_cost(self, dx: np.ndarray, dp: np.ndarray, density: float, axis_factors, force_density: float) -> float:
        """The linearised cost at the step at these settings, the measurement's and each process part's
        rows taken one by one (:func:`linearised_log_evidence`)."""
        weights = self.weights(density, axis_factors, force_density)
        return linearised_half_cost(self.measurement.terms, dx, dp) + sum(
            weights[key] * linearised_half_cost(terms, dx, dp) for key, terms in self.basis.terms.items())

    def system(self, density: float, axis_factors, force_density: float) -> tuple[NormalEquations, Factorisation]:
        """Normal equations (gradient, cost, border; no blocks) and factor at these settings."""
        weights = self.weights(density, axis_factors, force_density)
        me = self.measurement
        blocks = self.blocks.copy()
        grad = me.grad.copy()
        cost = me.cost
        for key, (d, p, values, g_idx, g_values, part_cost) in self.parts.items():
            w = weights[key]
            blocks[d, :, p] += w * values
            grad[:, g_idx] += w * g_values
            cost += w * part_cost
        ne = NormalEquations(None, None, grad, me.coupling, me.border, me.grad_global, cost, (me.rows or 0) + self.rows)
        return ne, factorise_blocks(self.structure, blocks, blocks[0].copy(), ne)


def _row_labels(a: np.ndarray, b: np.ndarray, factors: dict) -> list | None:
    """The key of ``factors`` ({factor: key}) of each row of a term whose entries are ``a`` at unit settings
    and ``b`` probed ((samples, rows, entries), :func:`_row_entries`): the factor that every nonzero entry's
    ratio a/b equals to 1e-9 (relative; a row without a nonzero entry: factor 1); None where the two have
    other nonzero entries or a row's ratios match no factor. A ratio is within the tolerance of f for
    every entry of a row exactly when the row's smallest and largest ratios are."""
    if a.shape != b.shape:
        return None
    nz = a != 0
    if not np.array_equal(nz, b != 0):
        return None
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = a / np.where(nz, b, 1.0)
    lo = np.min(np.where(nz, ratio, np.inf), axis=(0, 2))
    hi = np.max(np.where(nz, ratio, -np.inf), axis=(0, 2))
    empty = ~np.any(nz, axis=(0, 2))
    out = []
    for i in range(a.shape[1]):
        ends = np.ones(1) if empty[i] else np.array([lo[i], hi[i]])
        for f, key in factors.items():
            if np.allclose(ends, f, rtol=1e-9, atol=0.0):
                out.append(key)
                break
        else:
            return None
    return out


def _row_entries(t: Term) -> np.ndarray:
    """(samples, rows, entries) of a term: residual and Jacobians side by side."""
    parts = [t.residual[:, :, None]] + [t.jac[k] for k in sorted(t.jac)]
    if t.jac_global is not None:
        parts.append(t.jac_global)
    return np.concatenate(parts, axis=2)


def _term_rows(t: Term, rows: list[int]) -> Term:
    """The term restricted to some of its rows."""
    return Term(t.kind, t.residual[:, rows], {k: v[:, rows] for k, v in t.jac.items()},
                None if t.jac_global is None else t.jac_global[:, rows], t.first)


def measurement_normal_equations(problem: SmootherProblem, states: np.ndarray, params: np.ndarray | None = None) -> NormalEquations:
    """Normal equations of the measurement factors alone (accelerometers or the inversion)."""
    P = np.zeros(problem.n_global) if params is None else params
    for group in problem.groups:  # the first group's first term (the process terms are not needed here)
        terms = group.terms(problem, states, P)
        if terms:
            return normal_equations(problem, states, P, terms[:1])
    return normal_equations(problem, states, P, [])


EXTEND_MIN_GAIN_NATS = 1.0
"""A 1-D search of the tuner follows the evidence past the edge of its grid, and takes an edge
point, only where that point beats its inner neighbour by more than this [nats] (odds of e to 1,
the usual bound below which a Bayes factor is not worth more than a bare mention). Along a flat
ridge (an axis already stiff enough that stiffer changes nothing the data can tell) the search
otherwise walks to the limit of its range, where the normal equations lose their precision."""


def _maximise_1d(f, x0: float, step: float, lo: float, hi: float, points: int = 1,
                 min_gain: float = EXTEND_MIN_GAIN_NATS) -> tuple[float, float, int]:
    """Maximise ``f`` over ``x`` (a log density) from a grid ``x0 + step·k``, |k| ≤ points,
    extended while the best point is at an edge and beats its inner neighbour by more than
    ``min_gain`` (:data:`EXTEND_MIN_GAIN_NATS`), then one parabolic refinement."""
    cache = {}

    def F(x):
        x = float(np.clip(x, lo, hi))
        key = round(x, 9)
        if key not in cache:
            cache[key] = f(x)
        return cache[key], x

    def best(vals):
        i = int(np.argmax(vals))
        if len(vals) > 1 and i == 0 and not vals[0] - vals[1] > min_gain:
            i = 1
        elif len(vals) > 1 and i == len(vals) - 1 and not vals[-1] - vals[-2] > min_gain:
            i = len(vals) - 2
        return i

    xs = [x0 + step * k for k in range(-points, points + 1)]
    vals = [F(x)[0] for x in xs]
    while True:
        i = best(vals)
        if i == 0 and xs[0] - step >= lo:
            xs.insert(0, xs[0] - step)
            vals.insert(0, F(xs[0])[0])
        elif i == len(xs) - 1 and xs[-1] + step <= hi:
            xs.append(xs[-1] + step)
            vals.append(F(xs[-1])[0])
        else:
            break
    i = best(vals)
    best_x, best_v = xs[i], vals[i]
    if 0 < i < len(xs) - 1:
        a, b, c = vals[i - 1], vals[i], vals[i + 1]
        denom = a - 2 * b + c
        if denom < 0 and np.isfinite(denom):
            xp = xs[i] + 0.5 * step * (a - c) / denom
            vp, xp = F(xp)
            if vp > best_v:
                best_x, best_v = xp, vp
    return best_x, best_v, len(cache)


def dominant_frequency_hz(signal: np.ndarray, rate_hz: float, min_hz: float, max_hz: float,
                          min_share: float = 0.0) -> float | None:
    """Frequency of the largest peak of the periodogram of ``signal`` (Hann window, zero-padded
    16 times, mean removed) within [min_hz, max_hz], refined by a parabola; None if there is none
    or if the peak (within ±max(5 %, 3/T)) holds less than ``min_share`` of the signal's power."""
    x = np.asarray(signal, dtype=float)
    n = x.size
    if n < 8 or not (max_hz > min_hz > 0):
        return None
    nfft = 16 * (1 << int(np.ceil(np.log2(n))))
    p = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(n), nfft)) ** 2
    f = np.fft.rfftfreq(nfft, 1.0 / rate_hz)
    band = np.flatnonzero((f >= min_hz) & (f <= max_hz))
    if band.size < 3 or not np.any(p[band] > 0):
        return None
    i = int(band[np.argmax(p[band])])
    if i in (band[0], band[-1]):
        return None  # no peak inside the band, only its edge
    if min_share > 0:
        half_width = max(0.05 * f[i], 3.0 * rate_hz / n)
        if np.sum(p[np.abs(f - f[i]) <= half_width]) < min_share * np.sum(p[1:]):
            return None
    a, b, c = np.log(p[i - 1: i + 2] + 1e-300)
    denom = a - 2 * b + c
    shift = 0.5 * (a - c) / denom if denom < 0 else 0.0
    return float(f[i] + shift * (f[1] - f[0]))


def tune(log: Log, groups: ModelGroups, states: np.ndarray, params: np.ndarray | None = None,
         states_out: list | None = None, basis: bool = True) -> tuple[Tuning, ModelGroups]:
    """Select the process noise of the smoother's model and batch model (of the option ``groups``) maximising
    :func:`linearised_log_evidence` from a starting estimate ``states`` (e.g. the initialisation), as
    ``tuning = groups.tuning`` asks; returns the selection and the groups carrying it.

    Per motion model (both 'jerk' and 'snap' with ``tuning.tune_motion_model``, else the model's own):
    (1) the common jerk/snap density on a grid of factor 4, linearised at ``states``; the smoother is
    solved with it; (2) linearised at that solution, coordinate ascent over the factor of each body axis
    (``process_axis_factors``) and the specific-force density, and with ``tuning.tune_axis_frequencies``
    the oscillators; with ``tuning.tune_accel_noise`` the accelerometer noise scale is searched first in
    (1) and before and after the others in (2). Each 1-D search is a
    grid (factor 4 for the density, 10 for the others) extended while the best point is at an edge, refined by a parabola.
    The model with the larger evidence wins. ``states_out``, if given, receives the smoother's
    solution that the winner was linearised at (a better start than ``states`` for a stiff model).
    ``basis``: evaluate the process factors once per linearisation point and weight them per
    setting (:class:`ProcessBasis`; False: evaluate them for every setting, the same numbers slower)."""
    best = None
    tuning = groups.tuning
    for motion_model in ("jerk", "snap") if tuning.tune_motion_model else (groups.model.motion_model,):
        search = _NoiseSearch(log, groups, motion_model, states, params, basis)
        found = search.run(tuning.tune_accel_noise)
        if best is None or found.log_evidence > best[0].log_evidence:
            best = (found, search.settings(search.current), search.X)
    if states_out is not None:
        states_out.append(best[2])
    return best[:2]


def _copy_settings(c: dict) -> dict:
    return {k: (np.array(v, copy=True) if isinstance(v, np.ndarray) else v) for k, v in c.items()}


class _NoiseSearch:
    """The search of one motion model's process noise for :func:`tune`: the settings in log space
    (``current``: density, per-axis factors, specific-force density, accelerometer noise scale, and the
    per-axis oscillators' frequency, its std and amplitude), the linearisation point ``X`` (``version``
    0: the starting estimate, 1: the smoother's solution with the density found), and the evidence of
    each setting tried there (``known``), with the normal equations and process bases it reuses."""

    def __init__(self, log: Log, groups: ModelGroups, motion_model: str, states: np.ndarray,
                 params: np.ndarray | None, basis: bool):
        self.log, self.groups, self.motion_model = log, groups, motion_model
        model, batch_model = groups.model, groups.batch_model
        self.basis = basis
        self.frequencies = groups.tuning.tune_axis_frequencies
        """Whether the oscillators are tried (``tune_axis_frequencies``)."""
        self.field = DENSITY_FIELD[motion_model]
        self.p0 = params
        density = getattr(model if motion_model == "jerk" else batch_model, self.field)
        self.current = {"density": np.log(density),
                        "axis": np.log(np.asarray(model.process_axis_factors, float)),
                        "force": np.log(model.specific_force_random_walk_mps2_per_sqrt_s), "scale": 0.0,
                        "freq": np.array(model.process_axis_frequencies_hz if motion_model == "jerk"
                                         else (0.0, 0.0, 0.0), dtype=float),
                        "freq_std": np.zeros(3), "amp": np.zeros(3)}
        # the state layout of this motion model with the model given (the oscillators need 'jerk')
        given = replace(model, motion_model=motion_model)
        check_oscillators(given)
        self.X = StateLayout.of(given, groups.attitude).resize(states)
        self.cache: dict = {}
        self.bases: dict = {}
        self.summed: dict = {}
        self.known: dict = {}  # evidence per setting at this linearisation: a search starts where the last one ended
        self.version = 0

    def settings(self, c: dict) -> ModelGroups:
        """The option groups with the model and batch model of setting ``c`` (the jerk density is the model's,
        the snap density the batch model's)."""
        density = {self.field: float(np.exp(c["density"]))}
        model = replace(self.groups.model, motion_model=self.motion_model, **(density if self.motion_model == "jerk" else {}),
                        process_axis_factors=tuple(float(v) for v in np.exp(c["axis"])),
                        process_axis_frequencies_hz=tuple(float(v) for v in c["freq"]),
                        specific_force_random_walk_mps2_per_sqrt_s=float(np.exp(c["force"])))
        batch_model = self.groups.batch_model
        return self.groups._replace(model=model, batch_model=(batch_model if self.motion_model == "jerk"
                                                              else replace(batch_model, **density)))

    def run(self, accel_noise: bool) -> Tuning:
        """(1) the density linearised at the start, the smoother solved with it; (2) linearised at that
        solution, each axis factor, the specific-force density, the oscillators; the noise scale around
        them with ``accel_noise``. The :class:`Tuning` found."""
        log, current = self.log, self.current
        if accel_noise:
            self.search("scale", 1e-2, 1e3)
        value = self.search("density", *DENSITY_LIMITS, step=np.log(4.0))
        problem = make_problem(log, self.settings(current), float(np.exp(current["scale"])), self.X[:, OMEGA])
        self.X, self.version = solve(problem, self.X, self.p0).states, 1
        if accel_noise:
            self.search("scale", 1e-2, 1e3, step=np.log(2.0))
        for a in range(3):
            value = self.search("axis", 1e-5, 1e2, axis=a)
        value = self.search("force", 1e-3, 1e4)
        if self.motion_model == "jerk" and self.frequencies:
            value = self.search_frequencies(value)
        if accel_noise:
            value = self.search("scale", 1e-2, 1e3, step=np.log(1.5))
        return Tuning(self.motion_model, float(np.exp(current["density"])), float(np.exp(current["scale"])), float(value),
                      len(self.known), tuple(float(v) for v in np.exp(current["axis"])), float(np.exp(current["force"])),
                      tuple(float(v) for v in current["freq"]), tuple(float(v) for v in current["freq_std"]),
                      tuple(float(v) for v in current["amp"]))

    def evidence(self, c: dict) -> float:
        """The linearised log-evidence of setting ``c`` at ``X`` (each setting computed once)."""
        key = (self.version, float(c["scale"]), float(c["density"]), tuple(np.asarray(c["axis"], float).tolist()),
               float(c["force"]), tuple(np.asarray(c["freq"], float).tolist()))
        if key not in self.known:
            self.known[key] = self._evidence_at(c)
        return self.known[key]

    def _evidence_at(self, c: dict) -> float:
        log, X, p0, version = self.log, self.X, self.p0, self.version
        cache, bases, summed = self.cache, self.bases, self.summed
        try:
            problem = make_problem(log, self.settings(c), float(np.exp(c["scale"])), X[:, OMEGA])
            key = (version, float(c["scale"]))
            if key not in cache:
                cache.clear()
                cache[key] = measurement_normal_equations(problem, X, p0)
            if self.basis and not np.any(c["freq"] > 0):
                if version not in bases:  # at a new linearisation point: the last one's split and JᵀJ where they hold
                    before = next(iter(bases.values()), None)
                    bases.clear()
                    bases[version] = ProcessBasis.of(log, self.settings(c), self.field, X,
                                                     np.zeros(problem.n_global) if p0 is None else p0, X[:, OMEGA],
                                                     previous=before)
                if bases[version] is not None:
                    if key not in summed:
                        before = next(iter(summed.values()), None)
                        summed.clear()
                        summed[key] = bases[version].banded(cache[key], previous=before)
                    setting = (float(np.exp(c["density"])), np.exp(c["axis"]), float(np.exp(c["force"])))
                    total, fac = summed[key].system(*setting)
                    return linearised_log_evidence(problem, X, p0, total=total, factorisation=fac,
                                                   minimum=lambda dx, dp: summed[key].half_cost(dx, dp, *setting))
            return linearised_log_evidence(problem, X, p0, cache[key])
        except np.linalg.LinAlgError:
            return -np.inf

    def search(self, name: str, lo: float, hi: float, axis: int | None = None, step: float = np.log(10.0)) -> float:
        """One setting (``axis``: one component of it) to its evidence's maximum in [lo, hi], kept in
        ``current``; the evidence there."""
        current = self.current

        def f(v):
            c = _copy_settings(current)
            if axis is None:
                c[name] = v
            else:
                c[name][axis] = v
            return self.evidence(c)

        start = current[name] if axis is None else current[name][axis]
        v, value, _ = _maximise_1d(f, float(start), step, np.log(lo), np.log(hi))
        if axis is None:
            current[name] = v
        else:
            current[name][axis] = v
        return value

    def _frequency_evidence(self, a: int, log_f: float) -> float:
        c = _copy_settings(self.current)
        c["freq"][a] = float(np.exp(log_f))
        return self.evidence(c)

    def search_frequencies(self, value: float) -> float:
        """Per body axis whose solved ω has one dominant spectral line (80 % of its power): the
        oscillator at that frequency, refined with the axis density by coordinate ascent; kept where
        the evidence rises by more than 10 nats."""
        log, X, current = self.log, self.X, self.current
        rate = float(log.rate_hz)
        t = log.times_s
        span_s = float(t[-1] - t[0])
        uniform_t = t[0] + np.arange(int(span_s * rate) + 1) / rate  # the periodogram over gaps too
        for a in range(3):
            if current["freq"][a] > 0:
                continue
            f0 = dominant_frequency_hz(np.interp(uniform_t, t, X[:, a]), rate, 1.5 / max(span_s, 1e-9),
                                       min(0.05 * rate, 50.0), min_share=0.8)
            if f0 is None:
                continue
            saved = _copy_settings(current)
            current["freq"][a] = f0
            trial = value
            for step, reach in ((np.log(1.02), np.log(1.3)), (np.log(1.002), np.log(1.03))):
                start = np.log(current["freq"][a])
                v, trial, _ = _maximise_1d(lambda v: self._frequency_evidence(a, v), start, step,
                                           start - reach, start + reach)
                current["freq"][a] = float(np.exp(v))
                trial = self.search("axis", 1e-6, 1e2, axis=a)
            if trial > value + 10.0:
                value = trial
                # frequency std from the evidence's curvature in log f; amplitude of the oscillation
                step = np.log(1.002)
                v = np.log(current["freq"][a])
                up, down = self._frequency_evidence(a, v + step), self._frequency_evidence(a, v - step)
                curv = (up - 2.0 * trial + down) / step**2
                current["freq_std"][a] = current["freq"][a] / np.sqrt(-curv) if curv < 0 else current["freq"][a] * 0.01
                current["amp"][a] = np.sqrt(2.0) * float(np.std(X[:, a]))
            else:
                current.clear()
                current.update(saved)
        return value


def most_moving_span(omega_dot: np.ndarray, width: int) -> tuple[int, int]:
    """(start, stop) of the ``width`` samples of ``omega_dot`` (N, 3) whose steps have the largest
    sum of squares, among starts half a width apart (the middle one where that ties)."""
    n = len(omega_dot)
    if width >= n:
        return 0, n
    power = np.concatenate([[0.0], np.cumsum(np.sum(np.diff(omega_dot, axis=0) ** 2, axis=1))])
    middle = (n - width) // 2
    starts = np.unique(np.concatenate([np.arange(0, n - width + 1, max(width // 2, 1)), [n - width, middle]]))
    score = power[np.minimum(starts + width - 1, n - 1)] - power[starts]
    best = starts[score >= score.max() * (1.0 - 1e-9)]
    start = int(best[np.argmin(np.abs(best - middle))])
    return start, start + width


def tuned_problem(part: Log, groups: ModelGroups, tunings: list | None = None, initial: InitialStates | None = None,
                  span_s: float | None = None) -> tuple[SmootherProblem, np.ndarray]:
    """Problem and initial states of one solve window of the option ``groups``, with the process noise
    chosen from the data (:func:`tune`) when ``groups.tuning.tune_process_noise``; the choice is appended to
    ``tunings`` and the problem carries the tuned model and batch model (``problem.model``, ``problem.batch_model``).

    ``initial``: how the initial states are made (default :func:`gfimu.smoother.solve.initialise.initial_estimate`);
    ``span_s``: choose on at most this much of the window [s] (None: the whole window): the stretch
    where the initial estimate's ω̇ moves most (the middle one among equals), so that a window that
    rests in its middle is not tuned on its rest alone."""
    initial = initial or initial_estimate
    x0 = initial(part, groups)
    if not groups.tuning.tune_process_noise:
        return make_problem(part, groups, 1.0, x0[:, OMEGA]), x0
    solved: list = []
    span = slice(0, len(part))
    if span_s is not None and part.times_s[-1] - part.times_s[0] > span_s:
        width = max(int(round(span_s * part.rate_hz)), 4)
        span = slice(*most_moving_span(x0[:, OMEGA_DOT], width))
    chosen, tuned = tune(part.select(span), groups, x0[span], states_out=solved)
    if tunings is not None:
        tunings.append(chosen)
    if tuned.model.motion_model != groups.model.motion_model:
        x0 = initial(part, tuned)
    elif any(f > 0 for f in chosen.axis_frequencies_hz):
        if span == slice(0, len(part)):
            x0 = solved[0]  # the stiff oscillator model starts from the tuner's solution
        else:  # ... or from the white-jerk solution of the whole window with the chosen densities
            plain = tuned._replace(model=replace(tuned.model, process_axis_frequencies_hz=(0.0, 0.0, 0.0)))
            x0 = solve(make_problem(part, plain, chosen.accel_noise_scale, x0[:, OMEGA]), x0).states
    return make_problem(part, tuned, chosen.accel_noise_scale, x0[:, OMEGA]), x0
