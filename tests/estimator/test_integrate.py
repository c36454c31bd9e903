"""The Chebyshev stepping kernel equals the dense zero-order-hold exponential."""

import numpy as np
import pytest
import scipy.linalg as sl
from hypothesis import given, settings
from hypothesis import strategies as st
from zonecast.estimator.integrate import (
    ExactStepper,
    StepperLadder,
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


def test_stepper_run_and_columns_equal_single_steps_and_the_dense_reference():
    rng = np.random.default_rng(5)
    A, cap, rooms, bxu = random_network(rng, 20, 4)
    u = rng.uniform(0.0, 1.0, (15, len(rooms)))
    b = rng.normal(0.0, 1e-3, (15, 20))
    ts = rng.uniform(10.0, 30.0, 15)
    x0 = rng.uniform(15.0, 25.0, 20)
    st_ = ExactStepper(A, rooms, bxu, 900.0, u.max(axis=0), capacity=cap)
    xs = st_.run(x0, u, b, ts)
    x = x0
    for k in range(15):  # one compiled run = the same arithmetic as 15 single steps
        x = st_.step(x, u[k], b[k], ts[k])
        assert np.array_equal(xs[k + 1], x)
    np.testing.assert_allclose(xs, dense_reference(A, rooms, bxu, x0, u, b, ts, 900.0),
                               atol=1e-8, rtol=0)
    B = rng.normal(0.0, 1e-4, (20, 3))
    G = st_.columns(u[0], B)
    for j in range(3):
        assert np.array_equal(G[:, j], st_.step(np.zeros(20), u[0], B[:, j], 0.0))
    # Gamma B against the augmented dense exponential: int_0^h exp(A(u) s) ds B
    dd = np.zeros(20)
    np.add.at(dd, rooms, bxu * u[0])
    M = np.zeros((23, 23))
    M[:20, :20], M[:20, 20:] = A + np.diag(dd), B
    np.testing.assert_allclose(G, sl.expm(M * 900.0)[:20, 20:], atol=1e-9, rtol=1e-7)
    with pytest.raises(ValueError, match="above the stepper's u_max"):
        st_.columns(u.max(axis=0) * 1.5, B)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(2, 30))
def test_propagator_equals_the_dense_exponential(seed, n):
    """ExactStepper.propagator (the step's series applied to the identity) is exp(A(u) h)
    and maps a state as a step of it does without forcing."""
    rng = np.random.default_rng(seed)
    A, cap, rooms, bxu = random_network(rng, n, max(1, n // 3))
    u = rng.uniform(0.0, 1.0, (2, len(rooms)))
    st_ = ExactStepper(A, rooms, bxu, 900.0, u.max(axis=0), capacity=cap)
    dd = np.zeros(n)
    np.add.at(dd, rooms, bxu * u[0])
    P = st_.propagator(u[0])
    np.testing.assert_allclose(P, sl.expm((A + np.diag(dd)) * 900.0), atol=1e-10, rtol=0)
    x = rng.uniform(15.0, 25.0, n)
    np.testing.assert_allclose(P @ x, st_.step(x, u[0], np.zeros(n), 0.0), atol=1e-9, rtol=0)
    with pytest.raises(ValueError, match="above the stepper's u_max"):
        st_.propagator(u.max(axis=0) * 1.5)


def test_run_columns_equals_one_run_per_column_bit_for_bit():
    """Several simulations that share the airflows (block kernel) give each column exactly
    what its own run gives."""
    rng = np.random.default_rng(11)
    A, cap, rooms, bxu = random_network(rng, 18, 4)
    u = rng.uniform(0.0, 1.0, (12, len(rooms)))
    ts = rng.uniform(10.0, 30.0, 12)
    st_ = ExactStepper(A, rooms, bxu, 900.0, u.max(axis=0), capacity=cap)
    X0 = rng.uniform(15.0, 25.0, (18, 3))
    bcols = rng.normal(0.0, 1e-4, (18, 3))
    s = rng.uniform(0.0, 5.0, (12, 3))
    xs = st_.run_columns(X0, u, bcols, s, ts)
    assert xs.shape == (13, 18, 3)
    for c in range(3):
        one = st_.run(X0[:, c], u, s[:, c, None] * bcols[None, :, c], ts)
        assert np.array_equal(xs[:, :, c], one)


def test_ladder_level_depends_on_the_airflows_only():
    rng = np.random.default_rng(8)
    A, cap, rooms, bxu = random_network(rng, 12, 3)
    lad = StepperLadder(A, rooms, bxu, 900.0, cap, u_base=0.5)
    assert [lad.level(np.array([a])) for a in (0.0, 0.5, 0.51, 1.0, 1.01, 7.9)] == [0, 0, 1, 1, 2, 4]
    x0 = rng.uniform(15.0, 25.0, 12)
    b = rng.normal(0.0, 1e-3, 12)
    low = rng.uniform(0.0, 0.5, len(rooms))
    a = lad.for_airflows(low).step(x0, low, b, 14.0)
    # a second ladder built in another order returns the same stepper for the same u
    other = StepperLadder(A, rooms, bxu, 900.0, cap, u_base=0.5)
    other.for_airflows(np.full(len(rooms), 3.0))
    assert np.array_equal(other.for_airflows(low).step(x0, low, b, 14.0), a)
    # a higher level steps the same airflows to round-off
    high = lad.for_airflows(np.full(len(rooms), 3.0)).step(x0, low, b, 14.0)
    np.testing.assert_allclose(high, a, atol=1e-9, rtol=0)
    with pytest.raises(ValueError, match="u_base must be > 0"):
        StepperLadder(A, rooms, bxu, 900.0, cap, u_base=0.0)
    with pytest.raises(ValueError, match="finite and >= 0"):
        lad.level(np.array([-0.1]))


def test_ladder_keeps_a_scheduled_input_on_its_own_bound():
    """A box with a fixed bound (a ground contact's constant G A / c_p of tens of kg/s)
    neither raises the level nor the other boxes' bounds; it steps as the general ladder
    does to round-off, and an airflow above its bound is covered by the level."""
    rng = np.random.default_rng(9)
    A, cap, rooms, bxu = random_network(rng, 12, 3)
    fixed = np.zeros(len(rooms))
    fixed[-1] = 40.0
    lad = StepperLadder(A, rooms, bxu, 900.0, cap, u_base=0.5, fixed=fixed)
    plain = StepperLadder(A, rooms, bxu, 900.0, cap, u_base=0.5)
    u = np.r_[rng.uniform(0.1, 0.5, len(rooms) - 1), 40.0]
    assert lad.level(u) == 0 and plain.level(u) == 7
    x0 = rng.uniform(15.0, 25.0, 12)
    b = rng.normal(0.0, 1e-3, 12)
    np.testing.assert_allclose(lad.for_airflows(u).step(x0, u, b, 14.0),
                               plain.for_airflows(u).step(x0, u, b, 14.0), atol=1e-9, rtol=0)
    assert lad.level(np.r_[u[:-1], 50.0]) == plain.level(np.array([50.0]))
    with pytest.raises(ValueError, match="one bound >= 0"):
        StepperLadder(A, rooms, bxu, 900.0, cap, u_base=0.5, fixed=np.zeros(2))


def test_compile_kernels_compiles_every_kernel_with_the_estimators_types():
    """``make venv`` compiles the kernels once (numba's cache): after compile_kernels every
    kernel called from Python has exactly the one signature the estimator's calls give it
    (``_return_terms`` is called only from inside the others: loaded from the cache, its
    own dispatcher never compiles)."""
    from zonecast.estimator import integrate

    assert integrate.compile_kernels() == 6
    for name in integrate._KERNELS[1:]:
        kernel = getattr(integrate, name)
        if hasattr(kernel, "signatures"):  # numba present (the pure-Python fallback has none)
            assert len(kernel.signatures) == 1, name
