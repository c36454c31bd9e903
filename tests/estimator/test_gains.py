"""Internal gains: per-step OLS, weekly profile (DST), online and day-ahead estimators."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from zonecast.estimator import gains as G
from zonecast.estimator import kalman as K

TZ = "America/Los_Angeles"
STEP = pd.Timedelta("15min")


def cb_matrix(rng, m=6, p=6):
    # discrete C B_IG: nearly diagonal (each zone's gains heat its own air), small coupling
    return np.diag(rng.uniform(0.01, 0.05, p))[:m] + rng.uniform(0, 0.002, (m, p))


# ------------------------------------------------------------------------- OLS


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(6, 9))
def test_ols_recovers_injected_gains_exactly_without_noise(seed, m):
    rng = np.random.default_rng(seed)
    M = cb_matrix(rng, m, 6) if m == 6 else rng.normal(0, 0.03, (m, 6))
    f_true = rng.uniform(-5, 30, 6)
    y_pred = rng.normal(21, 1, m)
    sol = G.estimate_gains_step(M, y_pred + M @ f_true, y_pred)
    np.testing.assert_allclose(sol.f_ig, f_true, rtol=1e-8, atol=1e-8)
    assert sol.rank == 6 and not sol.min_norm and sol.rows_used.all()


def test_ols_with_noise_is_close_and_unbiased():
    rng = np.random.default_rng(5)
    M = rng.normal(0, 0.03, (12, 6)) + np.vstack([np.eye(6) * 0.05] * 2)
    f_true = np.array([2.0, 8.0, 15.0, 5.0, 0.0, 10.0])
    est = []
    for _ in range(400):
        y_pred = rng.normal(21, 1, 12)
        y = y_pred + M @ f_true + rng.normal(0, 0.02, 12)
        est.append(G.estimate_gains_step(M, y, y_pred).f_ig)
    est = np.array(est)
    # OLS covariance sigma^2 (M'M)^-1: the mean of 400 estimates is within 4 standard errors
    se = np.sqrt(np.diag(0.02**2 * np.linalg.inv(M.T @ M)) / 400)
    assert np.all(np.abs(est.mean(0) - f_true) < 4 * se)
    assert np.all(np.abs(est[0] - f_true) < 2.0)


def test_nan_rows_are_dropped():
    rng = np.random.default_rng(6)
    M = rng.normal(0, 0.03, (8, 6))
    f_true = rng.uniform(0, 20, 6)
    y = M @ f_true
    y[[1, 5]] = np.nan
    sol = G.estimate_gains_step(M, y, np.zeros(8))
    np.testing.assert_allclose(sol.f_ig, f_true, rtol=1e-8)
    assert sol.rows_used.tolist() == [True, False, True, True, True, False, True, True]


def test_rank_deficiency_raises_or_returns_flagged_min_norm():
    rng = np.random.default_rng(7)
    M = cb_matrix(rng)
    y = M @ np.ones(6)
    y[2] = np.nan  # zone 2 unmeasured -> 5 equations for 6 unknowns
    with pytest.raises(ValueError, match="rank 5 < 6 zones.*rank_deficient='min_norm'"):
        G.estimate_gains_step(M, y, np.zeros(6))
    sol = G.estimate_gains_step(M, y, np.zeros(6), rank_deficient="min_norm")
    assert sol.min_norm and sol.rank == 5
    used = sol.rows_used
    np.testing.assert_allclose(M[used] @ sol.f_ig, y[used], atol=1e-10)  # consistent
    assert np.linalg.norm(sol.f_ig) <= np.linalg.norm(np.ones(6)) + 1e-9  # minimum norm


def test_series_alignment_and_innovations_of_a_zero_gain_filter():
    """f_ig[k] is f_IG(k) for [t_k, t_k+1), estimated from the residual at k+1."""
    rng = np.random.default_rng(8)
    n, m, N = 8, 2, 40
    A = 0.9 * np.eye(n) + 0.01 * rng.random((n, n))
    C = np.zeros((m, n))
    C[0, 0] = C[1, 1] = 1.0
    B_ig = np.zeros((n, m))
    B_ig[0, 0], B_ig[1, 1] = 0.04, 0.03
    f_true = rng.uniform(0, 20, (N, m))
    c0 = np.full(n, 2.0)  # everything but f_IG
    X, Y = np.empty((N, n)), np.empty((N, m))
    x = np.full(n, 20.0)
    for k in range(N):
        X[k], Y[k] = x, C @ x
        x = A @ x + c0 + B_ig @ f_true[k]
    # paper Eq:xnoig_ynoig with the true state x(k-1)
    y_tilde = np.vstack([np.full((1, m), np.nan), (C @ (A @ X[:-1].T + c0[:, None])).T])
    est = G.estimate_gains_series(C @ B_ig, Y - y_tilde)
    np.testing.assert_allclose(est.f_ig[:-1], f_true[:-1], rtol=1e-9)
    assert np.isnan(est.f_ig[-1]).all()
    # a filter run with f_IG = 0 in c_k: its innovations are y_bar(k) - y~(k) with
    # x(k-1) the filtered state, i.e. the right-hand side of Eq:ig(k-1)
    Q, R = K.default_process_noise(n, [0, 1]), K.default_measurement_noise(m)
    res = K.run_filter(np.full(n, 20.0), np.eye(n), (A, c0), Y, C, Q, R)
    y_tilde_kf = (C @ (A @ res.x[:-1].T + c0[:, None])).T
    np.testing.assert_allclose(res.innovation[1:], Y[1:] - y_tilde_kf, rtol=1e-10, atol=1e-10)


def test_series_rank_policies():
    rng = np.random.default_rng(9)
    M = cb_matrix(rng)
    R = rng.normal(0, 0.1, (5, 6))
    R[2, 0] = np.nan  # f_IG(1) rank deficient
    R[3] = np.nan  # f_IG(2) nothing observed
    s = G.estimate_gains_series(M, R)
    assert np.isnan(s.f_ig[1]).all() and np.isnan(s.f_ig[2]).all() and np.isfinite(s.f_ig[0]).all()
    s2 = G.estimate_gains_series(M, R, rank_deficient="min_norm")
    assert s2.min_norm.tolist() == [False, True, False, False, False]
    assert np.isfinite(s2.f_ig[1]).all() and np.isnan(s2.f_ig[2]).all()
    with pytest.raises(ValueError, match="not identifiable"):
        G.estimate_gains_series(M, R, rank_deficient="raise")


# ------------------------------------------------------------------------- weekly profile


def week_pattern(bins, p=3):
    return np.stack([np.sin(2 * np.pi * bins / 672 * (z + 1)) * 10 + z for z in range(p)], 1)


def test_time_of_week_bins():
    t = pd.DatetimeIndex(
        ["2024-01-01 00:00", "2024-01-01 00:14", "2024-01-03 12:15", "2024-01-07 23:45"], tz=TZ
    )
    assert G.time_of_week_bin(t, TZ).tolist() == [0, 0, 2 * 96 + 49, 671]
    # the same instants given in UTC map to the same local bins
    assert G.time_of_week_bin(t.tz_convert("UTC"), TZ).tolist() == [0, 0, 2 * 96 + 49, 671]


def test_profile_of_identical_weeks_is_that_week():
    times = pd.date_range("2024-01-08", periods=672 * 4, freq=STEP, tz=TZ)  # 4 Mon-start weeks
    f = week_pattern(G.time_of_week_bin(times, TZ))
    prof = G.fit_weekly_profile(times, f, TZ)
    assert prof.n_bins == 672
    np.testing.assert_allclose(prof.values, week_pattern(np.arange(672)), rtol=1e-12)
    assert (prof.counts == 4).all()
    # evaluation at arbitrary (off-grid, other-tz) times
    q = pd.DatetimeIndex(["2025-06-04 17:05"], tz="UTC")
    b = G.time_of_week_bin(q, TZ)[0]
    np.testing.assert_allclose(prof(q)[0], week_pattern(np.arange(672))[b])


def test_profile_is_the_mean_of_weekly_estimates():
    times = pd.date_range("2024-01-08", periods=672 * 3, freq=STEP, tz=TZ)
    rng = np.random.default_rng(10)
    weeks = rng.normal(5, 3, (3, 672, 2))
    prof = G.fit_weekly_profile(times, weeks.reshape(-1, 2), TZ)
    np.testing.assert_allclose(prof.values, weeks.mean(0), rtol=1e-12)


@pytest.mark.parametrize("start", ["2024-03-04", "2024-10-28"])  # weeks with spring / fall DST
def test_dst_weeks_map_to_local_bins(start):
    # UTC 15-min grid over the DST week and one week either side
    times = pd.date_range(pd.Timestamp(start, tz=TZ), periods=672 * 3 + 8, freq=STEP).tz_convert(
        "UTC"
    )
    local = times.tz_convert(TZ)
    expect = ((local.day_of_week * 24 + local.hour) * 60 + local.minute) // 15
    bins = G.time_of_week_bin(times, TZ)
    assert bins.tolist() == list(expect)
    # 10:00 local is bin 40 of the day before and after the transition (Sunday)
    for day in ("2024-03-09", "2024-03-10", "2024-11-02", "2024-11-03"):
        t = pd.DatetimeIndex([pd.Timestamp(f"{day} 10:00", tz=TZ)]).tz_convert("UTC")
        dow = pd.Timestamp(day).day_of_week
        assert G.time_of_week_bin(t, TZ)[0] == dow * 96 + 40
    # a pattern that is a function of local time of week is recovered exactly
    f = week_pattern(bins)
    prof = G.fit_weekly_profile(times, f, TZ)
    ok = ~np.isnan(prof.values[:, 0])
    np.testing.assert_allclose(prof.values[ok], week_pattern(np.arange(672))[ok], rtol=1e-12)
    assert ok.all()  # the neighbouring weeks fill the skipped spring hour


def test_spring_forward_hour_gets_no_sample_and_fall_back_hour_gets_two():
    spring = pd.date_range(pd.Timestamp("2024-03-10 00:00", tz=TZ), periods=96 - 4, freq=STEP)
    bins = G.time_of_week_bin(spring, TZ)
    sunday = 6 * 96
    assert not set(range(sunday + 8, sunday + 12)) & set(bins.tolist())  # 02:00-02:59 skipped
    fall = pd.date_range(pd.Timestamp("2024-11-03 00:00", tz=TZ), periods=96 + 4, freq=STEP)
    bins = G.time_of_week_bin(fall, TZ)
    assert np.bincount(bins - sunday)[4:8].tolist() == [2, 2, 2, 2]  # 01:00-01:59 twice
    # the two samples of the repeated hour are averaged within the week (count 1)
    f = np.arange(len(fall), dtype=float)[:, None]
    prof = G.fit_weekly_profile(fall, f, TZ)
    assert prof.counts[sunday + 4, 0] == 1
    assert prof.values[sunday + 4, 0] == pytest.approx((4 + 8) / 2)


def test_profile_forgetting_update():
    times = pd.date_range("2024-01-08", periods=672, freq=STEP, tz=TZ)
    prof = G.fit_weekly_profile(times, np.ones((672, 1)), TZ)
    new = prof.updated(times[:2], np.array([[3.0], [np.nan]]), forgetting=0.25)
    assert new.values[0, 0] == pytest.approx(1.5) and new.values[1, 0] == 1.0
    assert new.counts[0, 0] == 2 and new.counts[1, 0] == 1
    assert prof.values[0, 0] == 1.0  # original untouched


# ------------------------------------------------------------------------- online


def test_online_series_is_previous_estimate_with_hold():
    f = np.array([[1.0, 10.0], [2.0, np.nan], [np.nan, 30.0], [4.0, 40.0]])
    out = G.online_gains_series(f)
    np.testing.assert_array_equal(out, [[0, 0], [1, 10], [2, 10], [2, 30]])
    og = G.OnlineGains(2)
    rows = []
    for k in range(4):
        rows.append(og.predict(1)[0])
        og.observe(f[k])
    np.testing.assert_array_equal(rows, out)
    assert og.predict(3).shape == (3, 2)


# ------------------------------------------------------------------------- day ahead


def make_history(rng, start="2024-05-06", weeks=2, p=3):
    times = pd.date_range(start, periods=672 * weeks, freq=STEP, tz=TZ)
    f = week_pattern(G.time_of_week_bin(times, TZ), p) + rng.normal(0, 1, (len(times), p))
    return pd.DataFrame(f, index=times, columns=["W", "S", "E"][:p])


def test_day_ahead_never_reads_the_future():
    rng = np.random.default_rng(11)
    hist = make_history(rng)
    prof = G.fit_weekly_profile(hist.index[:672], hist.to_numpy()[:672], TZ)
    da = G.DayAheadGains(prof)
    now = pd.Timestamp("2024-05-15 08:00", tz=TZ)
    ref = da.issue(now, hist)
    assert ref.shape == (96, 3) and ref.index[0] == now and ref.index[1] - ref.index[0] == STEP
    corrupt = hist.copy()
    unknown = corrupt.index > now - STEP  # f_IG(t) needs y(t + step): unknown at now
    corrupt.loc[unknown] = 1e6
    pd.testing.assert_frame_equal(da.issue(now, corrupt), ref)
    corrupt.loc[unknown] = np.nan
    pd.testing.assert_frame_equal(da.issue(now, corrupt), ref)
    pd.testing.assert_frame_equal(da.issue(now, hist.loc[~unknown]), ref)
    # ...while the newest known estimate is used
    known = hist.copy()
    known.loc[now - STEP] = 1e6
    assert not np.allclose(da.issue(now, known).to_numpy(), ref.to_numpy())


def test_day_ahead_limits():
    rng = np.random.default_rng(12)
    hist = make_history(rng)
    prof = G.fit_weekly_profile(hist.index, hist.to_numpy(), TZ)
    now = pd.Timestamp("2024-05-15 08:00", tz=TZ)
    starts = pd.date_range(now, periods=96, freq=STEP)
    # offset decays: far horizon tends to the profile
    out = G.DayAheadGains(prof, tau="1h").issue(now, hist).to_numpy()
    d, newest = G.DayAheadGains(prof, tau="1h").offset(now, hist)
    assert newest == now - STEP
    np.testing.assert_allclose(out[0], prof(starts[:1])[0] + d)
    np.testing.assert_allclose(out[-1], prof(starts[-1:])[0], atol=np.abs(d).max() * 1e-9 + 1e-12)
    # zero profile, one-step window, no decay -> paper eq:online_ig persistence
    zero = G.WeeklyProfile(np.zeros((672, 3)), np.ones((672, 3), int), TZ)
    pers = G.DayAheadGains(zero, tau=pd.Timedelta(days=10**5), window=STEP).issue(now, hist)
    np.testing.assert_allclose(pers.to_numpy(), np.tile(hist.loc[now - STEP].to_numpy(), (96, 1)),
                               rtol=1e-4)
    # no history known -> the profile
    empty = G.DayAheadGains(prof).issue(now, hist.loc[hist.index > now])
    np.testing.assert_allclose(empty.to_numpy(), prof(starts))


def test_day_ahead_level():
    """With a level L the offset decays to L, not to the profile; no history: profile + L;
    a zone whose recent estimates are all NaN starts at L; L = 0 is the plain issue."""
    rng = np.random.default_rng(14)
    hist = make_history(rng)
    prof = G.fit_weekly_profile(hist.index, hist.to_numpy(), TZ)
    now = pd.Timestamp("2024-05-15 08:00", tz=TZ)
    starts = pd.date_range(now, periods=96, freq=STEP)
    da = G.DayAheadGains(prof, tau="1h")
    L = np.array([2.0, -1.0, 0.5])
    d, _ = da.offset(now, hist)
    out = da.issue(now, hist, level=L).to_numpy()
    np.testing.assert_allclose(out[0], prof(starts[:1])[0] + d)
    np.testing.assert_allclose(out[-1], prof(starts[-1:])[0] + L, atol=1e-9)
    np.testing.assert_allclose(da.issue(now, hist, level=np.zeros(3)).to_numpy(),
                               da.issue(now, hist).to_numpy())
    empty = da.issue(now, hist.loc[hist.index > now], level=L)
    np.testing.assert_allclose(empty.to_numpy(), prof(starts) + L)
    holed = hist.copy()
    holed.loc[holed.index > now - pd.Timedelta("3h"), "S"] = np.nan
    got = da.issue(now, holed, level=L).to_numpy()
    np.testing.assert_allclose(got[:, 1], prof(starts)[:, 1] + L[1])
    with pytest.raises(ValueError, match=r"level must have shape \(3,\)"):
        da.issue(now, hist, level=np.zeros(2))


def test_errors_say_what_to_fix():
    rng = np.random.default_rng(13)
    M = cb_matrix(rng)
    with pytest.raises(ValueError, match=r"shape \(6,\) to match CB_IG"):
        G.estimate_gains_step(M, np.zeros(5), np.zeros(6))
    with pytest.raises(ValueError, match="CB_IG must be a finite 2-D array"):
        G.estimate_gains_step(np.zeros(6), np.zeros(6), np.zeros(6))
    with pytest.raises(TypeError, match="tz-aware"):
        G.time_of_week_bin(pd.date_range("2024-01-01", periods=3, freq=STEP), TZ)
    with pytest.raises(ValueError, match="IANA name"):
        G.time_of_week_bin(pd.date_range("2024-01-01", periods=3, freq=STEP, tz=TZ), "Pacific")
    with pytest.raises(ValueError, match="dividing one week"):
        G.time_of_week_bin(pd.date_range("2024-01-01", periods=3, freq=STEP, tz=TZ), TZ, "11min")
    prof = G.WeeklyProfile(np.zeros((672, 1)), np.zeros((672, 1), int), TZ)
    with pytest.raises(ValueError, match="tau must be positive"):
        G.DayAheadGains(prof, tau="0s")
    with pytest.raises(TypeError, match="now must be a tz-aware"):
        G.DayAheadGains(prof).issue(pd.Timestamp("2024-01-01"), pd.DataFrame({"a": []}))
    with pytest.raises(ValueError, match="forgetting must be in"):
        prof.updated(pd.DatetimeIndex([], tz=TZ), np.zeros((0, 1)), forgetting=0)


def two_zone_building(seed=0, days=14):
    """A 2-zone air+wall RC building, 15-min ZOH discretisation, office-hours gains."""
    from scipy.linalg import expm

    rng = np.random.default_rng(seed)
    Ca, Cw, haw, hao, hwo, hzz, floor = 2e6, 2e7, 500.0, 50.0, 30.0, 20.0, 100.0
    n, m = 4, 2
    Ac, Bc, Bg = np.zeros((n, n)), np.zeros((n, 1)), np.zeros((n, m))
    for z in range(2):
        a, w = 2 * z, 2 * z + 1
        Ac[a, [a, w]] = -(haw + hao + hzz) / Ca, haw / Ca
        Ac[w, [w, a]] = -(haw + hwo) / Cw, haw / Cw
        Bc[[a, w], 0] = hao / Ca, hwo / Cw
        Bg[a, z] = floor / Ca
    Ac[0, 2] = Ac[2, 0] = hzz / Ca
    Md = expm(np.block([[Ac, np.hstack([Bc, Bg])], [np.zeros((3, n + 3))]]) * 900.0)
    A, Bv, Big = Md[:n, :n], Md[:n, n], Md[:n, n + 1:]
    C = np.zeros((m, n))
    C[0, 0] = C[1, 2] = 1.0
    N = 96 * days
    t = np.arange(N)
    c = np.outer(10 + 5 * np.sin(2 * np.pi * t / 96), Bv)
    occ = ((t % 96 >= 32) & (t % 96 < 72)).astype(float)
    f_true = np.stack([15 * occ, 8 * occ], 1) + rng.normal(0, 1, (N, m))
    x = np.array([20.0, 19.0, 20.0, 19.0])
    Y = np.empty((N, m))
    for k in range(N):
        Y[k] = C @ x + rng.normal(0, 0.1, m)
        x = A @ x + c[k] + Big @ f_true[k] + rng.normal(0, [0.02, 0.005, 0.02, 0.005])
    return A, c[:-1], C, Big, Y, f_true


@pytest.mark.parametrize("sigma_air, slope_range", [(1.0, (0.9, 1.15)), (0.01, (1.3, 5.0))])
def test_filter_innovations_feed_eq_ig_unbiased_only_if_the_filter_tracks_the_air(
    sigma_air, slope_range
):
    """With x(k-1) from a filter run with f_IG = 0, a stiff filter (small Q on air) carries
    its own state error into y_bar(k) - y~(k) and overestimates f_IG; a filter that follows
    the measured air temperature gives an unbiased Eq:ig(k-1). See docs/numerics.md."""
    A, c, C, Big, Y, f_true = two_zone_building()
    Q = K.default_process_noise(4, [0, 2], sigma_air=sigma_air)
    res = K.run_filter([20, 19, 20, 19], np.eye(4) * 0.1, (A, c), Y, C, Q,
                       K.default_measurement_noise(2, sigma=0.1))
    est = G.estimate_gains_series(C @ Big, res.innovation).f_ig
    ok = np.isfinite(est[:, 0])
    for z in range(2):
        slope = np.polyfit(f_true[ok, z], est[ok, z], 1)[0]
        assert slope_range[0] < slope < slope_range[1]


def _leak_data(k: float, weeks: int = 6, seed: int = 0, repeat_q: bool = False):
    """Weeks of 15-min rows: f = a weekly profile + k q + noise, q a reheat heat that follows
    a slow random 'weather' (or repeats every week with ``repeat_q``)."""
    rng = np.random.default_rng(seed)
    times = pd.date_range("2015-01-05", periods=weeks * 672, freq="15min", tz="America/Chicago")
    b = np.arange(len(times)) % 672
    profile = np.where(((b % 96) >= 32) & ((b % 96) < 72) & (b < 480), 6.0, 0.5)
    if repeat_q:
        q = 2.0 + np.sin(2 * np.pi * b / 96)
    else:
        weather = np.convolve(rng.normal(size=len(times)), np.ones(48) / 48, mode="same")
        q = np.clip(3.0 + 8.0 * weather - 1.5 * profile / 6.0, 0.0, None)
    f = profile + k * q + rng.normal(0.0, 0.3, len(times))
    return times, f, q


def test_fit_reheat_leak_separates_the_reheat_from_the_weekly_profile():
    """Within time-of-week bins the profile cancels: k is recovered where the reheat
    varies from week to week, 0 (and said so by its standard error) where it does not
    leak, where it repeats every week (no within-bin variation) and outside the bounds."""
    t, f1, q1 = _leak_data(0.25, seed=1)
    _, f0, q0 = _leak_data(0.0, seed=2)
    leak = G.fit_reheat_leak(t, np.c_[f1, f0], np.c_[q1, q0], "America/Chicago")
    assert leak.k[0] == pytest.approx(0.25, abs=0.02)
    assert abs(leak.fitted[0] - 0.25) < 4 * leak.stderr[0]
    assert leak.k[1] == 0.0 and abs(leak.fitted[1]) < 3 * leak.stderr[1]
    assert leak.rows == len(t)
    # the same reheat every week: the profile explains it, nothing is fitted
    _, fr, qr = _leak_data(0.25, seed=3, repeat_q=True)
    rep = G.fit_reheat_leak(t, fr[:, None], qr[:, None], "America/Chicago")
    assert rep.k[0] == 0.0 and not np.isfinite(rep.stderr[0])
    # clipped to the bounds; NaN rows skipped
    f_big = f1 + 2.0 * q1
    f_big[:100] = np.nan
    big = G.fit_reheat_leak(t, f_big[:, None], q1[:, None], "America/Chicago", bounds=(-0.5, 1.0))
    assert big.fitted[0] == pytest.approx(2.25, abs=0.05) and big.k[0] == 1.0
    assert big.rows == len(t) - 100


def test_fit_reheat_leak_errors_say_what_to_fix():
    t, f, q = _leak_data(0.1, weeks=2)
    with pytest.raises(G.GainsInputError, match=r"must both have shape \(N, p\)"):
        G.fit_reheat_leak(t, f[:, None], np.c_[q, q], "America/Chicago")
    with pytest.raises(G.GainsInputError, match="one time per row"):
        G.fit_reheat_leak(t[:-1], f[:, None], q[:, None], "America/Chicago")
