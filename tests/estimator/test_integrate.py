"""The Chebyshev stepping kernel equals the dense zero-order-hold exponential."""

import numpy as np
import pytest
import scipy.linalg as sl
from hypothesis import given, settings
from hypothesis import strategies as st
from zonecast.estimator.integrate import (
    chebyshev_coefficients,
    simulate_exact,
    spectral_bound,
    tight_bound,
)


def random_network(rng, n, n_air):
    """A = -diag(1/cap) K with K a symmetric conductance Laplacian plus boundary links."""
    cap = rng.uniform(1e4, 1e6, n)
    K = np.zeros((n, n))
    for i in range(1, n):
        for j in rng.choice(i, size=min(i, 2), replace=False):
            g = rng.uniform(1.0, 500.0)
            K[i, j] = K[j, i] = -g
            K[i, i] += g
            K[j, j] += g
    K[np.diag_indices(n)] += rng.uniform(0.0, 50.0, n)  # links to fixed outside temperatures
    A = -K / cap[:, None]
    rooms = rng.choice(n_air, size=n_air + 2)           # some rooms with two boxes
    bxu = -1005.0 / cap[rooms]
    return A, cap, rooms, bxu


def dense_reference(A, rooms, bxu, x0, u, b, ts, h):
    n = len(x0)
    xs = [x0]
    x = x0
    for k in range(len(u)):
        dd = np.zeros(n)
        np.add.at(dd, rooms, bxu * u[k])
        M = np.zeros((n + 1, n + 1))
        M[:n, :n] = A + np.diag(dd)
        M[:n, n] = b[k] - dd * ts[k]
        x = (sl.expm(M * h) @ np.append(x, 1.0))[:n]
        xs.append(x)
    return np.array(xs)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(3, 25), steps=st.integers(1, 12))
def test_kernel_equals_dense_exponential(seed, n, steps):
    rng = np.random.default_rng(seed)
    n_air = max(1, n // 4)
    A, cap, rooms, bxu = random_network(rng, n, n_air)
    u = rng.uniform(0.0, 2.0, (steps, len(rooms))) * (rng.random((steps, len(rooms))) > 0.3)
    b = rng.normal(0.0, 1e-3, (steps, n))
    ts = rng.uniform(10.0, 40.0, steps)
    x0 = rng.uniform(10.0, 30.0, n)
    want = dense_reference(A, rooms, bxu, x0, u, b, ts, 900.0)
    for capacity in (None, cap):
        got = simulate_exact(A, rooms, bxu, x0, u, b, ts, 900.0, capacity=capacity)
        np.testing.assert_allclose(got, want, atol=1e-8, rtol=0)


def test_bounds_contain_the_spectrum():
    rng = np.random.default_rng(3)
    A, cap, rooms, bxu = random_network(rng, 30, 6)
    u = rng.uniform(0.0, 1.5, (40, len(rooms)))
    worst = 0.0
    for k in range(len(u)):
        dd = np.zeros(30)
        np.add.at(dd, rooms, bxu * u[k])
        worst = max(worst, -np.linalg.eigvals(A + np.diag(dd)).real.min())
    assert worst <= tight_bound(A, rooms, bxu, u, cap) <= spectral_bound(A, rooms, bxu, u) * 1.0001


def test_coefficients_sum_to_one_at_zero():
    # exp(0) = sum_k c_k T_k(1) = sum c_k
    c = chebyshev_coefficients(7.3)
    assert c.sum() == pytest.approx(1.0, abs=1e-12)


def test_negative_airflow_is_rejected():
    A = -np.eye(2) * 1e-3
    with pytest.raises(ValueError, match="airflows u must be >= 0"):
        simulate_exact(A, np.array([0]), np.array([-1e-3]), np.zeros(2), np.array([[-0.1]]),
                       np.zeros((1, 2)), np.array([13.0]), 900.0)


def test_results_are_bitwise_reproducible():
    rng = np.random.default_rng(11)
    A, cap, rooms, bxu = random_network(rng, 40, 8)
    u = rng.uniform(0.0, 1.0, (30, len(rooms)))
    b = rng.normal(0.0, 1e-3, (30, 40))
    ts = np.full(30, 13.0)
    runs = [simulate_exact(A, rooms, bxu, np.full(40, 20.0), u, b, ts, 900.0, capacity=cap)
            for _ in range(3)]
    assert all(np.array_equal(runs[0], r) for r in runs[1:])
