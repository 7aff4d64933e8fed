"""Least squares and orthonormal bases of tall matrices through the Gram matrix, and NumPy's own
solvers where the columns are too nearly dependent for it."""

from __future__ import annotations

import numpy as np
import pytest

from deepmorph_detect.tall_solves import least_squares, orthonormal_columns


def _tall(k: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.standard_normal((9216, k)) * rng.uniform(0.1, 10.0, k)  # columns of unequal scale


@pytest.mark.parametrize("k", [1, 2, 6, 8])
def test_least_squares_is_numpys_on_well_apart_columns(k: int) -> None:
    a = _tall(k, k)
    b = a @ np.arange(1.0, k + 1) + np.random.default_rng(9).standard_normal(len(a))
    np.testing.assert_allclose(least_squares(a, b), np.linalg.lstsq(a, b, rcond=None)[0], rtol=1e-10, atol=1e-12)


def test_least_squares_of_dependent_columns_is_the_minimum_norm_one() -> None:
    # two inks of one colour: the normal equations have no unique solution, lstsq's is kept
    a = _tall(3)
    a[:, 2] = 2.0 * a[:, 0]
    b = a[:, 0] + a[:, 1]
    x = least_squares(a, b)
    np.testing.assert_allclose(x, np.linalg.lstsq(a, b, rcond=None)[0], atol=1e-10)
    np.testing.assert_allclose(a @ x, b, atol=1e-8)
    nearly = a.copy()
    nearly[:, 2] += 1e-9 * _tall(1, 5)[:, 0]  # dependent to rounding: still NumPy's answer
    np.testing.assert_allclose(least_squares(nearly, b), np.linalg.lstsq(nearly, b, rcond=None)[0], atol=1e-6)


@pytest.mark.parametrize("dependent", [False, True])
def test_orthonormal_columns_span_what_qr_spans(dependent: bool) -> None:
    a = _tall(8, 3)
    if dependent:
        a[:, 7] = a[:, 0] - a[:, 3]
    q = orthonormal_columns(a)
    reference = np.linalg.qr(a)[0]
    assert q.shape == a.shape
    np.testing.assert_allclose(q.T @ q, np.eye(8), atol=1e-10)
    probe = np.random.default_rng(4).standard_normal(len(a))
    np.testing.assert_allclose(q @ (q.T @ probe), reference @ (reference.T @ probe), atol=1e-8)
