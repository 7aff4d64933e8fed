"""Least squares and orthonormal bases for tall, thin matrices: a picture's pixels by a few
columns (the per-bit check's light fields, inks and motion images, ``(9216, 2-8)``).

NumPy's ``lstsq`` (an SVD) and ``qr`` (Householder) take 0.3-0.7 ms on such a matrix, most of
it outside the arithmetic. Both are solved here through the columns' ``(k, k)`` Gram matrix and
its Cholesky factor, in a fifth to a third of the time, where that is as exact: the factor's
diagonal (each column's distance from the ones before it) spreads less than
:data:`WELL_CONDITIONED_SPREAD`, which keeps the squared condition number's rounding near
1e-10. Elsewhere (nearly collinear columns: a colour word's inks, a blank render) NumPy's own
solvers decide, as before.
"""

from __future__ import annotations

import numpy as np

# the most the Cholesky factor's diagonal may spread for the Gram route: above it, NumPy's solvers
WELL_CONDITIONED_SPREAD = 1e3


def _gram_factor(a: np.ndarray) -> np.ndarray | None:
    """The lower Cholesky factor of ``a``'s Gram matrix ``a^T a``, or ``None`` where the
    columns are too nearly dependent for it (:data:`WELL_CONDITIONED_SPREAD`)."""
    try:
        factor = np.linalg.cholesky(a.T @ a)
    except np.linalg.LinAlgError:
        return None
    diagonal = np.abs(np.diag(factor))
    if not np.all(np.isfinite(diagonal)) or diagonal.min() * WELL_CONDITIONED_SPREAD < diagonal.max():
        return None
    return factor


def orthonormal_columns(a: np.ndarray) -> np.ndarray:
    """``(n, k)`` an orthonormal basis of the columns of ``a`` (``(n, k)``, ``n >= k``): the
    span of a QR factorisation's ``Q``, as ``a L^-T``."""
    factor = _gram_factor(a)
    if factor is None:
        return np.linalg.qr(a)[0]
    return a @ np.linalg.inv(factor).T


def least_squares(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(k,)`` the ``x`` minimising ``|a x - b|`` for ``a`` ``(n, k)`` and ``b`` ``(n,)``: by
    the normal equations where the columns are well apart, else ``lstsq``'s minimum-norm one."""
    factor = _gram_factor(a)
    if factor is None:
        return np.linalg.lstsq(a, b, rcond=None)[0]
    y = np.linalg.solve(factor, a.T @ b)
    return np.linalg.solve(factor.T, y)


__all__ = ["WELL_CONDITIONED_SPREAD", "least_squares", "orthonormal_columns"]
