"""Forecasts (paper 4-B, 5): week split, fixed profile, no look-ahead, interval coverage."""

import numpy as np
import pandas as pd
import pytest
from zonecast.estimator.dataset import ModelData
from zonecast.estimator.forecast import (
    Z90,
    WeekTrack,
    fill_profile,
    fixed_profile,
    issue_forecast,
    online_paper_predictions,
    week_split,
)
from zonecast.estimator.gains import WeeklyProfile, fit_weekly_profile
from zonecast.estimator.internal_gains import track_gains
from zonecast.estimator.rc.network import ModelOptions as _Options
from zonecast.estimator.telemetry import segments_of

#: the RC network alone (NREL's files' scheduled inputs, infiltration and ground, add to u)
# the paper's structure of the 5-zone: no infiltration, ground, shading or return air
NO_LEAK = _Options(infiltration="none", ground="adiabatic", shading="none", return_air="none")

ZONES = {"South": ["SPACE1-1"], "East": ["SPACE2-1"], "North": ["SPACE3-1"],
         "West": ["SPACE4-1"], "Core": ["SPACE5-1"]}
BOXES = [f"VAV-{i}" for i in range(1, 6)]
TZ = "America/Los_Angeles"
DAY = 96


@pytest.fixture(scope="module")
def model(five_zone):
    from zonecast.estimator.model import build_model
    return build_model(five_zone, ZONES, {f"VAV-{i}": f"SPACE{i}-1" for i in range(1, 6)},
                       options=NO_LEAK)


def _weekly(n, seed=1):
    """Inputs and gains that repeat every week (so identical weeks give identical f_IG)."""
    rng = np.random.default_rng(seed)
    k = np.arange(n) % (7 * DAY)
    day = k / DAY
    u_week = np.repeat(rng.uniform(0.05, 0.5, (7 * DAY // 4, 5)), 4, axis=0)
    u = u_week[k]
    v = np.column_stack([14 + 4 * np.sin(2 * np.pi * day), np.full(n, 13.0),
                         np.zeros((n, 5)) + 100 * (np.sin(2 * np.pi * day) > 0)[:, None]])
    scale = rng.uniform(0.5, 1.5, 5)
    f = np.clip(20 * np.sin(2 * np.pi * (day - 0.3)), 0, None)[:, None] * scale
    f[(day >= 5)] *= 0.3  # quieter weekends
    return u, v, f


def _data(times, u, v, y):
    return ModelData(times, u, v, y, list(ZONES), BOXES, segments_of(times, pd.Timedelta("15min")),
                     np.zeros(len(times), bool), TZ)


def _times(n):
    return pd.date_range(pd.Timestamp("2015-04-13", tz=TZ), periods=n, freq="15min").tz_convert("UTC")


def test_week_split_is_seeded_and_disjoint():
    n = 11 * 7 * DAY
    times = pd.DatetimeIndex(np.concatenate([_times(7 * DAY) + pd.Timedelta(weeks=3 * w)
                                             for w in range(11)]))
    d = _data(times, np.zeros((n, 5)), np.zeros((n, 7)), np.zeros((n, 5)))
    a, b, c = week_split(d, 0), week_split(d, 0), week_split(d, 1)
    assert a == b
    assert len(a["weeks"]) == 11 and len(a["train"]) == 8 and len(a["validation"]) == 3
    assert set(a["train"]).isdisjoint(a["validation"])
    assert sorted(a["train"] + a["validation"]) == list(range(11))
    assert a["train"] != c["train"]
    assert [w["segment"] for w in a["weeks"]] == list(range(11))
    assert a["train_starts"][0] == str(d.local_times()[a["weeks"][a["train"][0]]["rows"][0]].date())


def test_fixed_profile_of_identical_weeks_is_the_injected_gains(model):
    n = 2 * 7 * DAY
    u, v, f = _weekly(n)
    sim = model.simulate(model.steady_state(u[0], v[0]), u, v, f)
    d = _data(_times(n), u, v, sim.y[:-1])
    tracks = [WeekTrack(s, track_gains(model, d, s, e, sim.x[s]))
              for s, e in ((DAY, 7 * DAY - 1), (8 * DAY, n - 1))]
    prof = fixed_profile(d, tracks)
    rows = np.arange(8 * DAY, n - 1)  # Tuesday ... Sunday of the second week
    np.testing.assert_allclose(prof(d.times[rows]), f[rows], atol=1e-6)
    # both weeks alike, and the online (paper) one-step predictions reproduce y exactly
    np.testing.assert_allclose(tracks[0].track.f_ig, tracks[1].track.f_ig, atol=1e-6)
    rows1, pred = online_paper_predictions(model, tracks[0])
    err = pred - d.y[rows1]
    assert np.abs(err).max() < 0.2  # only the 15-min change of f_IG is missed


def test_an_empty_day_is_filled_from_its_own_day_class():
    """Monday (each tracked week's warm-up day) has no data: with the working days it takes
    the other working days' mean by time of day, not a mean that counts the weekend."""
    per_day = 96
    tod = np.sin(np.linspace(0, np.pi, per_day))  # a day's shape
    level = np.array([np.nan, 10, 12, 14, 16, 1, 3])  # Monday empty, weekend low
    values = (level[:, None] * tod[None]).reshape(-1, 1)
    counts = np.isfinite(values).astype(int)
    prof = WeeklyProfile(values, counts, TZ)
    by_class = fill_profile(prof, working_days=[0, 1, 2, 3, 4]).values.reshape(7, per_day)
    np.testing.assert_allclose(by_class[0], 13 * tod)  # Tue-Fri mean
    np.testing.assert_allclose(by_class[1:], (level[1:, None] * tod[None]))  # data kept
    pooled = fill_profile(prof).values.reshape(7, per_day)
    np.testing.assert_allclose(pooled[0], 56 / 6 * tod)  # every day with data
    # an empty weekend day takes the other weekend day's; a class without any data the
    # every-day mean
    level2 = np.array([10, 10, 12, 14, 16, 1, np.nan])
    v2 = (level2[:, None] * tod[None]).reshape(-1, 1)
    filled = fill_profile(WeeklyProfile(v2, np.isfinite(v2).astype(int), TZ),
                          working_days=range(5)).values.reshape(7, per_day)
    np.testing.assert_allclose(filled[6], 1 * tod)
    only_work = np.where(np.arange(7)[:, None] < 5, 5.0, np.nan) * np.ones((7, per_day))
    filled = fill_profile(WeeklyProfile(only_work.reshape(-1, 1), np.ones((672, 1), int), TZ),
                          working_days=range(5)).values.reshape(7, per_day)
    np.testing.assert_allclose(filled[5:], 5.0)


def test_an_empty_mondays_small_hours_follow_the_weekend():
    """With the operating day starting at 07:00, Monday's bins before 07:00 belong to
    Sunday's operating day: filled from Sunday's small hours (the only other day after a
    non-working day), Monday's later bins from Tuesday to Friday."""
    per_day, start = 96, 28  # 07:00
    level = np.array([np.nan, 10, 12, 14, 16, 1, 3.0])
    values = np.repeat(level[:, None], per_day, axis=1)
    before = np.nan_to_num(np.roll(level, 1), nan=11.0)  # Monday's level had it been seen
    values[1:, :start] += 100 * before[1:, None]  # small hours: the day before's
    prof = WeeklyProfile(values.reshape(-1, 1), np.ones((672, 1), int), TZ)
    out = fill_profile(prof, working_days=range(5), day_start=7.0).values.reshape(7, per_day)
    np.testing.assert_allclose(out[0, :start], values[6, :start])  # Sunday's small hours
    np.testing.assert_allclose(out[0, start:], 13.0)  # Tuesday to Friday
    np.testing.assert_allclose(out[1:], values[1:])
    # day_start 0: the calendar day's class for every bin (Tuesday to Friday all day)
    by_day = fill_profile(prof, working_days=range(5)).values.reshape(7, per_day)
    np.testing.assert_allclose(by_day[0], values[1:5].mean(axis=0))


@pytest.mark.parametrize("corrupt", [1e6, np.nan])
def test_forecast_never_reads_y_after_the_issue_time(model, corrupt):
    n = 3 * DAY
    u, v, f = _weekly(n, seed=3)
    sim = model.simulate(model.steady_state(u[0], v[0]), u, v, f)
    times = _times(n)
    prof = fit_weekly_profile(times, 0.8 * f, TZ)
    d = _data(times, u, v, sim.y[:-1].copy())
    issue = 2 * DAY - 8
    methods = ("fixed", "dayahead", "persistence")
    ref = issue_forecast(model, d, issue, prof, methods)
    d.y[issue + 1:] = corrupt
    new = issue_forecast(model, d, issue, prof, methods)
    for m in methods:
        np.testing.assert_array_equal(ref[m].mean, new[m].mean)
        np.testing.assert_array_equal(ref[m].std, new[m].std)
        assert np.isfinite(ref[m].mean).all() and len(ref[m].mean) == DAY
    d.y[issue] += 1.0  # the newest measurement does matter
    assert not np.allclose(issue_forecast(model, d, issue, prof, methods)["dayahead"].mean,
                           ref["dayahead"].mean)


def test_interval_coverage_is_near_nominal_on_model_data(model):
    """Model-simulated data with known process and measurement noise; the filter and the
    forecast use the same noise, the gains are known: 90 % intervals hold ~90 %."""
    sa, sw, sm = 0.1, 0.01, 0.1
    rng = np.random.default_rng(7)
    n = 8 * DAY
    u, v, f = _weekly(n, seed=5)
    air = model.structure.air_states()
    q = np.full(model.n, sw)
    q[air] = sa
    x = model.steady_state(u[0], v[0], f[0])
    ys = np.empty((n, model.n_zones))
    for k in range(n):
        ys[k] = model.C @ x + sm * rng.standard_normal(model.n_zones)
        phi, gv, gi = model.step_matrices(u[k])
        x = phi @ x + gv @ v[k] + gi @ (model.params.c_ig + f[k]) + q * rng.standard_normal(model.n)
    times = _times(n)
    prof = fit_weekly_profile(times, f, TZ)
    d = _data(times, u, v, ys)
    inside, total = 0, 0
    for issue in range(DAY, n - DAY, DAY // 2):
        fc = issue_forecast(model, d, issue, prof, ("fixed",), sigma_air_filter=sa,
                            sigma_air_forecast=sa, sigma_wall=sw, sigma_meas=sm)["fixed"]
        meas = d.y[issue + 1:issue + 1 + len(fc.mean)]
        lo, hi = fc.interval()
        np.testing.assert_allclose(hi - fc.mean, Z90 * fc.std)
        inside += int(((meas >= lo) & (meas <= hi)).sum())
        total += meas.size
    assert 0.84 <= inside / total <= 0.96, inside / total


def test_empirical_halfwidth_is_zero_on_exact_weeks_and_grows_with_gains_noise(model):
    """Weeks that repeat exactly are forecast without error by the other weeks' profile;
    day-to-day gains noise widens the intervals, and they cover it out of sample."""
    from zonecast.estimator.forecast import coverage_halfwidth, empirical_halfwidth
    n = 3 * 7 * DAY
    u, v, f = _weekly(n)
    d0 = None

    def tracks_for(f_true):
        nonlocal d0
        sim = model.simulate(model.steady_state(u[0], v[0]), u, v, f_true)
        d0 = _data(_times(n), u, v, sim.y[:-1])
        return [WeekTrack(w * 7 * DAY + DAY,
                          track_gains(model, d0, w * 7 * DAY + DAY, (w + 1) * 7 * DAY - 1,
                                      sim.x[w * 7 * DAY + DAY]))
                for w in range(3)]

    exact_tracks = tracks_for(f)
    exact = empirical_halfwidth(model, d0, exact_tracks)
    assert exact.shape == (DAY, 5)
    assert np.nanmax(exact) < 1e-6
    rng = np.random.default_rng(3)
    noisy_f = f * rng.uniform(0.4, 1.6, (n // DAY, 1, 5)).repeat(DAY, axis=0).reshape(n, 5)
    tracks = tracks_for(noisy_f)
    wide = empirical_halfwidth(model, d0, tracks)
    assert np.nanmin(wide.max(axis=0)) > 0.05  # every zone gets a real width
    # the widths of weeks 1-2 cover week 3's fixed-profile forecasts near 90 %
    half = empirical_halfwidth(model, d0, tracks[:2], pool=4)
    prof = fixed_profile(d0, tracks[:2])
    preds, meas = [], []
    for r in range(15 * DAY, n - DAY, DAY):
        x0 = tracks[2].track.x[r - tracks[2].start]
        preds.append(model.simulate(x0, u[r:r + DAY], v[r:r + DAY],
                                    prof(d0.times[r:r + DAY])).y[1:])
        meas.append(d0.y[r + 1:r + 1 + DAY])
    cov = coverage_halfwidth(np.array(preds), half, np.array(meas), list(ZONES))
    assert 0.8 < cov["all"] < 0.99
    with pytest.raises(ValueError, match="at least two tracked weeks"):
        empirical_halfwidth(model, d0, tracks[:1])
