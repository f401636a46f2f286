"""Dense reference for the smoother's linearised log evidence (shared by the tuning tests)."""

import numpy as np

from gfimu.smoother.tuning.evidence import log_normaliser


def dense_log_evidence(problem, x: np.ndarray) -> float:
    """log ∫ N(y; h(x̄) + J (x - x̄), R) p(x | q) dx for ``problem`` linearised at ``x`` (x̄),
    from the dense stacked Jacobian of all its factors."""
    J, r = dense_system(problem, x)
    H, g = J.T @ J, J.T @ r
    c_min = 0.5 * r @ r - 0.5 * g @ np.linalg.solve(H, g)
    R, D = J.shape
    return float(-c_min - 0.5 * np.linalg.slogdet(H)[1] - log_normaliser(problem) - 0.5 * (R - D) * np.log(2 * np.pi))


def dense_minimum(problem, x: np.ndarray) -> float:
    """Half the squared residual of the linearised factors at their minimum, ``½ |(I - Q Qᵀ) r|²``
    from a QR factorisation of the dense stacked Jacobian (no normal equations, no subtraction)."""
    J, r = dense_system(problem, x)
    Q, _ = np.linalg.qr(J)
    lin = r - Q @ (Q.T @ r)
    return 0.5 * float(lin @ lin)


def dense_system(problem, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The dense stacked Jacobian (rows, N m) and residual of all factors of ``problem`` at ``x``."""
    n, m = x.shape
    rows, res = [], []
    for t in problem.terms(x, np.zeros(0)):
        if t.kind == "unary":
            J = np.zeros((t.residual.shape[0], t.residual.shape[1], n, m))
            for i in range(t.residual.shape[0]):
                J[i, :, t.first + i, :] = t.jac["x"][i]
        else:
            J = np.zeros((n - 1, t.residual.shape[1], n, m))
            for i in range(n - 1):
                J[i, :, i, :] = t.jac["x0"][i]
                J[i, :, i + 1, :] = t.jac["x1"][i]
        rows.append(J.reshape(-1, n * m))
        res.append(t.residual.reshape(-1))
    return np.vstack(rows), np.concatenate(res)
