"""The weekly profile's empty bins (the tracked weeks' warm-up day, filled by
forecast.fill_profile) learned from the building's own per-step f_IG as it operates
(OnlineEstimator.profile_learn, streaming.PROFILE_LEARN_EMPTY)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest


@pytest.fixture(scope="module")
def monday_empty(bundle):
    """The virtual building's model with its profile's Monday marked as filled."""
    from zonecast.estimator.gains import WeeklyProfile

    p = bundle.profile
    counts = np.full(p.values.shape, 3)
    counts[:96] = 0
    return dataclasses.replace(bundle, profile=WeeklyProfile(p.values, counts, p.timezone,
                                                             p.step))


def _rows(bundle, telemetry, n):
    from zonecast.estimator.streaming import rows_from_frame

    frame = telemetry.set_index(pd.to_datetime(telemetry["time"], format="ISO8601", utc=True))
    frame = frame.drop(columns="time").astype(float)[list(bundle.site.point_units())]
    return rows_from_frame(bundle, frame.iloc[:n])


def test_empty_bins_learn_the_mean_of_their_estimates_and_the_fill(monday_empty, telemetry):
    from zonecast.estimator import streaming
    from zonecast.estimator.streaming import OnlineEstimator

    tt, u, v, y = _rows(monday_empty, telemetry, 96 + 40)
    assert tt[0].tz_convert(monday_empty.site.timezone).day_of_week == 0  # a Monday
    on, off = OnlineEstimator(monday_empty), OnlineEstimator(monday_empty)
    on.profile_learn, off.profile_learn = True, False
    seen: dict[int, list] = {}
    for k in range(len(tt)):
        for e in (on, off):
            e.advance(tt[k], u[k], v[k], y[k])
        if k == 90:  # Monday evening: the day-ahead offset is taken against Monday's bins
            gains = on.dayahead_gains(), off.dayahead_gains()
        if on._gains:
            t, f = on._gains[-1]
            seen.setdefault(int(on._bins(np.array([t.value]))[0]), []).append(f)
    fill = np.nan_to_num(monday_empty.profile.values)
    np.testing.assert_array_equal(off._profile, fill)  # off: the file's profile
    w = streaming.PROFILE_FILL_WEIGHT
    learned = 0
    for b, fs in seen.items():
        fs = np.array(fs)
        if b < 96:  # Monday's bins: the fill and the estimates, averaged
            ok = np.isfinite(fs)
            want = (w * fill[b] + np.where(ok, fs, 0).sum(axis=0)) / (w + ok.sum(axis=0))
            np.testing.assert_allclose(on._profile[b], want, rtol=1e-12)
            learned += int(ok.any())
        else:  # bins with weeks behind them are the file's
            np.testing.assert_array_equal(on._profile[b], fill[b])
    assert learned > 80
    assert not np.array_equal(on._profile, fill)
    # the served gains follow the learned profile
    assert not np.array_equal(*gains)


def test_learned_profile_survives_a_checkpoint_and_experiments_teach_nothing(
        monday_empty, telemetry):
    from zonecast.estimator.streaming import OnlineEstimator

    tt, u, v, y = _rows(monday_empty, telemetry, 60)
    a = OnlineEstimator(monday_empty)
    a.profile_learn = True
    for k in range(40):
        a.advance(tt[k], u[k], v[k], y[k])
    b = OnlineEstimator(monday_empty)
    b.load_bytes(a.to_bytes())
    b.profile_learn = True  # (a restore takes the library's default, as every switch)
    np.testing.assert_array_equal(b._profile, a._profile)
    for k in range(40, 60):
        for e in (a, b):
            e.advance(tt[k], u[k], v[k], y[k])
    np.testing.assert_array_equal(b._profile, a._profile)
    # inside an experiment nothing is learned
    c = OnlineEstimator(monday_empty)
    c.profile_learn = True
    c._experiments = [(tt[0].value, tt[-1].value + 1)]
    for k in range(40):
        c.advance(tt[k], u[k], v[k], y[k])
    assert not c._pf_n.any()
    np.testing.assert_array_equal(c._profile, np.nan_to_num(monday_empty.profile.values))
