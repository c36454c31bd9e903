"""Kalman filter: covariance invariants, open loop, consistency (NIS), partial measurements."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from zonecast.estimator import kalman as K


def random_system(rng, n, m, stable=True):
    F = rng.normal(0, 0.3, (n, n))
    if stable:
        F = 0.9 * F / max(1.0, np.abs(np.linalg.eigvals(F)).max())
    H = rng.normal(0, 1, (m, n))
    Lq = rng.normal(0, 0.1, (n, n))
    Lr = rng.normal(0, 0.2, (m, m))
    Q = Lq @ Lq.T + 1e-3 * np.eye(n)
    R = Lr @ Lr.T + 1e-2 * np.eye(m)
    return F, H, Q, R


def textbook_filter(x0, P0, F, c, Y, H, Q, R):
    """Reference: standard KF, reduced H per step, covariance (I - K H) P."""
    x, P = x0.copy(), P0.copy()
    out = []
    for k, y in enumerate(Y):
        if k > 0:
            x = F @ x + c
            P = F @ P @ F.T + Q
        obs = ~np.isnan(y)
        if obs.any():
            Hk, Rk = H[obs], R[np.ix_(obs, obs)]
            S = Hk @ P @ Hk.T + Rk
            Kg = P @ Hk.T @ np.linalg.inv(S)
            x = x + Kg @ (y[obs] - Hk @ x)
            P = (np.eye(len(x)) - Kg @ Hk) @ P
        out.append(x)
    return np.array(out)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 6),
    m=st.integers(1, 4),
    N=st.integers(1, 40),
    p_missing=st.floats(0.0, 1.0),
    scale=st.floats(1e-3, 1e2),
)
def test_covariance_stays_symmetric_psd(seed, n, m, N, p_missing, scale):
    rng = np.random.default_rng(seed)
    F, H, Q, R = random_system(rng, n, m, stable=False)
    Y = rng.normal(0, scale, (N, m))
    Y[rng.random((N, m)) < p_missing] = np.nan
    f = K.ZoneStateFilter(np.zeros(n), np.eye(n) * scale, H, Q * scale, R * scale)
    for k in range(N):
        if k:
            f.predict(F, rng.normal(0, 1, n))
        f.update(Y[k])
        P = f.P
        assert np.array_equal(P, P.T)
        w = np.linalg.eigvalsh(P)
        assert w.min() >= -1e-9 * max(1.0, w.max())


def test_no_measurements_is_open_loop_propagation_exactly():
    rng = np.random.default_rng(1)
    n, m, N = 5, 2, 50
    F, H, Q, R = random_system(rng, n, m)
    c = rng.normal(0, 1, (N - 1, n))
    x0 = rng.normal(20, 1, n)
    P0 = np.eye(n)
    res = K.run_filter(x0, P0, (F, c), np.full((N, m), np.nan), H, Q, R, store_covariance="full")
    x, P = x0.copy(), P0.copy()
    for k in range(1, N):
        x = F @ x + c[k - 1]
        P = F @ P @ F.T + Q
        P = 0.5 * (P + P.T)
        assert np.array_equal(res.x[k], x)
        assert np.array_equal(res.P[k], P)
    assert np.isnan(res.nis).all() and np.isnan(res.innovation).all()
    assert (res.dof == 0).all()


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("p_missing", [0.0, 0.3])
def test_nis_mean_matches_measurement_dimension(seed, p_missing):
    """A correctly tuned filter on its own model has NIS ~ chi²(dof) at every step.

    The innovations of an optimal filter are white, so the sum of NIS over N steps
    is chi² with sum(dof) degrees of freedom: mean sum(dof), variance 2 sum(dof).
    The ratio sum(NIS)/sum(dof) therefore has standard deviation sqrt(2/sum(dof));
    we accept 4 standard deviations (two-sided false-alarm rate ~6e-5).
    """
    rng = np.random.default_rng(100 + seed)
    n, m, N = 4, 3, 3000
    F, H, Q, R = random_system(rng, n, m)
    c = rng.normal(0, 0.5, n)
    x0, P0 = np.full(n, 20.0), np.eye(n) * 0.5
    x = rng.multivariate_normal(x0, P0)
    Y = np.empty((N, m))
    for k in range(N):
        if k:
            x = F @ x + c + rng.multivariate_normal(np.zeros(n), Q)
        Y[k] = H @ x + rng.multivariate_normal(np.zeros(m), R)
    Y[rng.random((N, m)) < p_missing] = np.nan
    res = K.run_filter(x0, P0, (F, c), Y, H, Q, R)
    used = res.dof > 0
    ratio = np.nansum(res.nis[used]) / res.dof.sum()
    assert abs(ratio - 1.0) < 4.0 * np.sqrt(2.0 / res.dof.sum())
    # and a mistuned filter (R 10x too small) is detected by the same statistic
    bad = K.run_filter(x0, P0, (F, c), Y, H, Q, R / 10)
    assert np.nansum(bad.nis) / bad.dof.sum() > 1.5


def test_missing_column_equals_filtering_with_reduced_H():
    rng = np.random.default_rng(3)
    n, m, N = 6, 4, 60
    F, H, Q, R = random_system(rng, n, m)
    c = rng.normal(0, 1, n)
    Y = rng.normal(0, 1, (N, m))
    Ynan = Y.copy()
    Ynan[:, 2] = np.nan
    keep = [0, 1, 3]
    a = K.run_filter(np.zeros(n), np.eye(n), (F, c), Ynan, H, Q, R, store_covariance="full")
    b = K.run_filter(np.zeros(n), np.eye(n), (F, c), Y[:, keep], H[keep], Q,
                     R[np.ix_(keep, keep)], store_covariance="full")
    np.testing.assert_allclose(a.x, b.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(a.P, b.P, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(a.innovation[:, keep], b.innovation, rtol=1e-12, atol=1e-12)
    assert np.isnan(a.innovation[:, 2]).all()
    np.testing.assert_allclose(a.nis, b.nis, rtol=1e-10)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), p_missing=st.floats(0.0, 1.0))
def test_random_missing_rows_equal_textbook_filter_with_reduced_rows(seed, p_missing):
    rng = np.random.default_rng(seed)
    n, m, N = 4, 3, 30
    F, H, Q, R = random_system(rng, n, m)
    c = rng.normal(0, 1, n)
    Y = rng.normal(0, 1, (N, m))
    Y[rng.random((N, m)) < p_missing] = np.nan
    x0, P0 = rng.normal(0, 1, n), np.eye(n)
    res = K.run_filter(x0, P0, lambda k: (F, c), Y, H, Q, R)
    ref = textbook_filter(x0, P0, F, c, Y, H, Q, R)
    np.testing.assert_allclose(res.x, ref, rtol=1e-8, atol=1e-8)


def test_update_returns_innovation_statistics():
    H = np.array([[1.0, 0.0], [0.0, 1.0]])
    f = K.ZoneStateFilter([20.0, 21.0], [1.0, 4.0], H, [0.0, 0.0], [0.25, 0.25])
    inn = f.update([21.0, np.nan])
    assert inn.observed.tolist() == [True, False]
    assert inn.dof == 1
    np.testing.assert_allclose(inn.innovation, [1.0])
    np.testing.assert_allclose(inn.S, [[1.25]])
    assert inn.nis == pytest.approx(1.0 / 1.25)
    # the unobserved state is untouched (no correlation), the observed one moves
    assert f.x[1] == 21.0 and 20.0 < f.x[0] < 21.0
    none = f.update([np.nan, np.nan])
    assert np.isnan(none.nis) and none.dof == 0


def test_step_callable_and_arrays_agree():
    rng = np.random.default_rng(4)
    n, m, N = 3, 2, 20
    Fs = np.stack([random_system(rng, n, m)[0] for _ in range(N - 1)])
    _, H, Q, R = random_system(rng, n, m)
    cs = rng.normal(0, 1, (N - 1, n))
    Y = rng.normal(0, 1, (N, m))
    a = K.run_filter(np.zeros(n), np.eye(n), (Fs, cs), Y, H, Q, R)
    b = K.run_filter(np.zeros(n), np.eye(n), lambda k: (Fs[k], cs[k]), Y, H, Q, R)
    np.testing.assert_array_equal(a.x, b.x)
    c0 = K.run_filter(np.zeros(n), np.eye(n), (Fs[0], None), Y, H, Q, R, store_covariance="none")
    assert c0.P is None


def test_initial_state_from_measurement():
    y0 = np.array([21.0, np.nan, 23.0])
    zones = np.array([0, 0, 1, 2, 2, -1])
    x0 = K.initial_state_from_measurement(y0, zones)
    np.testing.assert_allclose(x0, [21, 21, 22, 23, 23, 22])
    with pytest.raises(ValueError, match="no measured zone"):
        K.initial_state_from_measurement([np.nan, np.nan], [0, 1])
    with pytest.raises(ValueError, match="entries must be in -1..1"):
        K.initial_state_from_measurement([20.0, 21.0], [0, 2])


def test_default_noise_separates_air_and_walls():
    Q = K.default_process_noise(5, [0, 3])
    np.testing.assert_allclose(np.diag(Q), [0.01, 1e-4, 1e-4, 0.01, 1e-4])
    P0 = K.default_initial_covariance(5, np.array([True, False, False, True, False]))
    np.testing.assert_allclose(np.diag(P0), [0.09, 4, 4, 0.09, 4])
    np.testing.assert_allclose(K.default_measurement_noise(2), 0.04 * np.eye(2))


def test_errors_say_what_to_fix():
    H = np.eye(2)
    with pytest.raises(ValueError, match=r"H must have shape \(m, 3\)"):
        K.ZoneStateFilter(np.zeros(3), np.eye(3), H, np.eye(3), np.eye(2))
    with pytest.raises(ValueError, match="R must be symmetric"):
        K.ZoneStateFilter(np.zeros(2), np.eye(2), H, np.eye(2), [[1, 0.5], [0, 1]])
    f = K.ZoneStateFilter(np.zeros(2), np.eye(2), H, np.eye(2), np.eye(2))
    with pytest.raises(ValueError, match=r"F must have shape \(2, 2\)"):
        f.predict(np.eye(3))
    with pytest.raises(ValueError, match=r"y must have shape \(2,\)"):
        f.update([1.0])
    with pytest.raises(ValueError, match="steps must be a callable"):
        K.run_filter(np.zeros(2), np.eye(2), "F", np.zeros((3, 2)), H, np.eye(2), np.eye(2))
    with pytest.raises(ValueError, match="store_covariance must be"):
        K.run_filter(np.zeros(2), np.eye(2), (np.eye(2), None), np.zeros((3, 2)), H,
                     np.eye(2), np.eye(2), store_covariance="all")
    with pytest.raises(ValueError, match="sigma must be > 0"):
        K.default_measurement_noise(2, sigma=0)


# --------------------------------------------------------------------------- steady state
def test_steady_state_covariance_is_the_limit_of_the_filter():
    rng = np.random.default_rng(21)
    n, m = 6, 3
    F, H, Q, R = random_system(rng, n, m)
    P = K.steady_state_covariance(F, H, Q, R)
    f = K.ZoneStateFilter(np.zeros(n), np.eye(n), H, Q, R)
    for _ in range(400):
        f.predict(F)
        prior = f.P
        f.update(np.zeros(m))
    np.testing.assert_allclose(prior, P, atol=1e-10, rtol=1e-8)
    assert np.allclose(P, P.T) and np.linalg.eigvalsh(P).min() > 0
    with pytest.raises(K.KalmanInputError, match="H must have shape"):
        K.steady_state_covariance(F, H[:, :2], Q, R)


@pytest.mark.parametrize("observed", [[True, True, True], [True, False, True], [False, True, False]])
def test_steady_filter_update_equals_the_textbook_update_from_its_prior(observed):
    rng = np.random.default_rng(4)
    n, m = 5, 3
    F, H, Q, R = random_system(rng, n, m)
    P = K.steady_state_covariance(F, H, Q, R)
    sf = K.SteadyStateFilter(P, H, R)
    obs = np.array(observed)
    x = rng.normal(size=n)
    y = rng.normal(size=m)
    y[~obs] = np.nan
    post, inn = sf.update(x, y)
    Hs, Rs = H[obs], R[np.ix_(obs, obs)]
    S = Hs @ P @ Hs.T + Rs
    Kg = P @ Hs.T @ np.linalg.inv(S)
    np.testing.assert_allclose(post, x + Kg @ (y[obs] - Hs @ x), atol=1e-12)
    nu = y[obs] - Hs @ x
    assert inn.dof == obs.sum() and inn.nis == pytest.approx(nu @ np.linalg.solve(S, nu))
    Ppost = P - Kg @ Hs @ P
    np.testing.assert_allclose(sf.output_covariance(obs), H @ Ppost @ H.T, atol=1e-12)
    if obs.all():
        np.testing.assert_allclose(sf.posterior(), Ppost, atol=1e-12)
    same, none = sf.update(x, np.full(m, np.nan))
    assert np.array_equal(same, x) and none.dof == 0 and np.isnan(none.nis)


def test_horizon_output_variances_equal_explicit_propagation():
    rng = np.random.default_rng(9)
    n, m = 7, 2
    F, H, Q, _ = random_system(rng, n, m)
    P0 = np.diag(rng.uniform(0.1, 1.0, n))
    got = K.horizon_output_variances(F, P0, Q, H, 12)
    P = P0
    for h in range(12):
        P = F @ P @ F.T + Q
        np.testing.assert_allclose(got[h], np.diag(H @ P @ H.T), rtol=1e-12, atol=1e-14)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 12), m=st.integers(1, 5),
       p_missing=st.floats(0.0, 0.9))
def test_update_equals_filterpys_joseph_update(seed, n, m, p_missing):
    """The rank-m evaluation of the Joseph form gives filterpy's update (state, covariance,
    innovation and its covariance) to rounding."""
    from filterpy.kalman import KalmanFilter

    rng = np.random.default_rng(seed)
    _F, H, Q, R = random_system(rng, n, m, stable=False)
    A = rng.normal(0, 1, (n, n))
    P0 = A @ A.T + 0.1 * np.eye(n)
    x0 = rng.normal(20, 2, n)
    y = rng.normal(20, 2, m)
    y[rng.random(m) < p_missing] = np.nan
    obs = ~np.isnan(y)
    f = K.ZoneStateFilter(x0, P0, H, Q, R)
    inn = f.update(y)
    ref = KalmanFilter(dim_x=n, dim_z=int(obs.sum()) or 1)
    ref.x, ref.P = x0.copy(), P0.copy()
    if obs.any():
        ref.update(y[obs], R=R[np.ix_(obs, obs)], H=H[obs])
        np.testing.assert_allclose(inn.innovation, ref.y, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(inn.S, ref.S, rtol=1e-9, atol=1e-9)
    scale = max(1.0, np.abs(P0).max())
    np.testing.assert_allclose(f.x, ref.x, rtol=1e-9, atol=1e-9 * scale)
    np.testing.assert_allclose(f.P, 0.5 * (ref.P + ref.P.T), rtol=1e-8, atol=1e-9 * scale)


def test_young_filter_is_the_time_varying_filter_from_its_start():
    """The young filter's gains, innovation covariances and output variances are those of
    the time-varying filter started from P0 with every output measured; they end once
    the gain is within rtol of the steady-state gain; its forecast variances are those
    propagated from the posterior of the latest evaluated step (never narrower)."""
    rng = np.random.default_rng(33)
    n, m = 6, 2
    F, H, Q, R = random_system(rng, n, m)
    P0 = np.diag(rng.uniform(1.0, 4.0, n))
    yf = K.young_filter(F, H, Q, R, P0, steps=300, horizon=5, rtol=1e-6)
    f = K.ZoneStateFilter(np.zeros(n), P0, H, Q, R)
    f.update(np.zeros(m))
    np.testing.assert_allclose(yf.output_var[0], np.diag(H @ f.P @ H.T), rtol=1e-10)
    posts = [f.P]
    for j in range(yf.steps):
        f.predict(F)
        prior = f.P
        inn = f.update(np.zeros(m))
        S = H @ prior @ H.T + R
        np.testing.assert_allclose(yf.S[j], S, rtol=1e-9)
        np.testing.assert_allclose(yf.gains[j], prior @ H.T @ np.linalg.inv(S), rtol=1e-8,
                                   atol=1e-12)
        np.testing.assert_allclose(yf.S_inv[j] @ yf.S[j], np.eye(m), atol=1e-9)
        np.testing.assert_allclose(yf.output_var[j + 1], np.diag(H @ f.P @ H.T), rtol=1e-8)
        assert inn.dof == m
        posts.append(f.P)
    # ended early, at the steady gain
    assert 1 < yf.steps < 300
    P_ss = K.steady_state_covariance(F, H, Q, R)
    K_ss = P_ss @ H.T @ np.linalg.inv(H @ P_ss @ H.T + R)
    assert np.abs(yf.gains[-1] - K_ss).max() <= 1e-6 * np.abs(K_ss).max()
    assert np.abs(yf.gains[0] - K_ss).max() > 1e-3 * np.abs(K_ss).max()
    # forecast variances: from the latest power-of-two step at or before j
    assert list(yf.horizon_at[:4]) == [0, 1, 2, 4]
    for j in (0, 3, 5):
        at = max(a for a in yf.horizon_at if a <= j)
        np.testing.assert_allclose(yf.horizon_variance(j),
                                   K.horizon_output_variances(F, posts[at], Q, H, 5),
                                   rtol=1e-10)
    # the steady-state filter at hand gives the same gains without solving the DARE again
    ss = K.SteadyStateFilter(P_ss, H, R)
    again = K.young_filter(F, H, Q, R, P0, steps=300, horizon=5, rtol=1e-6, steady=ss)
    assert again.steps == yf.steps
    np.testing.assert_allclose(again.gains, yf.gains, rtol=1e-9, atol=1e-12)
    # a cap shorter than the convergence keeps exactly that many steps
    assert K.young_filter(F, H, Q, R, P0, steps=3, horizon=5).steps == 3
