"""Small numerical helpers shared by the models (float64, NumPy only)."""

from __future__ import annotations

import numpy as np


def nnls(A: np.ndarray, b: np.ndarray, max_iter: int | None = None, tol: float | None = None):
    """Non-negative least squares: argmin ||A x - b||_2 subject to x >= 0.

    Lawson & Hanson 1974 (Solving Least Squares Problems, ch. 23), the
    active-set algorithm SciPy's ``nnls`` also implements. Returns (x, residual norm).
    """
    A = np.asarray(A, np.float64)
    b = np.asarray(b, np.float64)
    m, n = A.shape
    x = np.zeros(n)
    passive = np.zeros(n, bool)
    tol = tol if tol is not None else 10.0 * np.finfo(float).eps * np.linalg.norm(A, 1) * max(m, n)
    max_iter = max_iter or 3 * n
    w = A.T @ (b - A @ x)
    it = 0
    while (~passive).any() and (w[~passive] > tol).any() and it < max_iter:
        it += 1
        j = np.argmax(np.where(passive, -np.inf, w))
        passive[j] = True
        while True:
            z = np.zeros(n)
            z[passive] = np.linalg.lstsq(A[:, passive], b, rcond=None)[0]
            if (z[passive] > 0).all():
                x = z
                break
            neg = passive & (z <= 0)
            alpha = np.min(x[neg] / (x[neg] - z[neg]))
            x = x + alpha * (z - x)
            passive &= x > tol
            x[~passive] = 0.0
        w = A.T @ (b - A @ x)
    return x, float(np.linalg.norm(A @ x - b))
