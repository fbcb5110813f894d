"""The compiled loops of the forms (:mod:`bayesprog.forms.compiled`) compute what the numpy
expressions they stand for compute, to the bit (the gmm over a grid against scipy's densities:
tests/test_forms.py)."""

from __future__ import annotations

import numpy as np
import pytest

from bayesprog.forms.compiled import floored, gaussian_exponents


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))


@pytest.mark.parametrize("seed", range(4))
def test_gaussian_exponents_are_numpy_s(seed):
    rng = np.random.default_rng(seed)
    rows, k, n = rng.integers(1, 7), rng.integers(1, 9), rng.integers(1, 40)
    x = np.sort(rng.uniform(-0.3, 0.3, n))
    means = rng.normal(0, 0.2, (rows, k))
    means[0, 0] = x[0]  # a mean on a coordinate: an exponent of -0.0
    sigma = rng.uniform(1e-3, 0.05, rows)
    out = np.empty((rows, k, n))
    gaussian_exponents(x, means, sigma, out)
    expected = -0.5 * ((x - means[..., None]) / sigma[:, None, None]) ** 2
    assert _same(out, expected)


@pytest.mark.parametrize("seed", range(4))
def test_a_floored_mixture_is_numpy_s(seed):
    rng = np.random.default_rng(seed)
    rows, cells = rng.integers(1, 7), rng.integers(1, 300)
    mix = rng.exponential(1.0, (rows, cells)) * np.where(rng.random((rows, cells)) < 0.2, 0, 1)
    mix[0, 0] = 1e-310  # a subnormal
    divisor, keep = rng.uniform(0.01, 10, rows), rng.uniform(0.0, 1.0, rows)
    floor = rng.uniform(0.0, 3000, rows)
    out = np.empty((rows, cells))
    floored(mix, divisor, keep, floor, out)
    expected = keep[:, None] * ((0.0 + mix) / divisor[:, None]) + floor[:, None]
    assert _same(out, expected)
