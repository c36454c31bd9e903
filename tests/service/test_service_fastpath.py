"""The runner's lean paths give the numbers of the general ones they replace: per-row
conversion (pvlib geometry cached a day at a time) vs ``rows_from_frame``, the day-ahead
gains on arrays vs ``DayAheadGains.issue``, and checkpoints of the earlier .npz format."""

from __future__ import annotations

import io
import json

import numpy as np
import pandas as pd
import pytest


def si_frame(bundle, telemetry) -> pd.DataFrame:
    frame = telemetry.set_index(pd.to_datetime(telemetry["time"], format="ISO8601", utc=True))
    return frame.drop(columns="time").astype(float)[list(bundle.site.point_units())]


def test_row_converter_equals_rows_from_frame_on_every_row(bundle, telemetry):
    from zonecast.estimator.streaming import RowConverter, rows_from_frame

    frame = si_frame(bundle, telemetry)
    site = bundle.site
    ghi, dni = site.points.solar.global_horizontal.point, site.points.solar.direct_normal.point
    zone_points = [s.point for s in site.points.zone_temperature[next(iter(site.zones))]]
    rng = np.random.default_rng(1)
    rows = rng.choice(len(frame), 60, replace=False)
    frame.iloc[rows[:20], frame.columns.get_loc(ghi)] = np.nan  # missing sun: NaN facades
    frame.iloc[rows[20:40], frame.columns.get_loc(dni)] = -3.0  # thermopile offset
    frame.iloc[rows[40:], [frame.columns.get_loc(p) for p in zone_points[:1]]] = np.nan
    _, u, v, y = rows_from_frame(bundle, frame)
    conv = RowConverter(bundle)
    ns = frame.index.as_unit("ns").asi8
    values = frame[conv.points].to_numpy()
    # all rows at once, and one row at a time as the runner converts them
    U, V, Y = conv.convert(ns, values)
    one = [conv.convert(ns[k:k + 1], values[k:k + 1]) for k in range(len(frame))]
    for got in ((U, V, Y), tuple(np.vstack(p) for p in zip(*one))):
        for a, b in zip((u, v, y), got):
            np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)
            assert np.array_equal(np.isnan(a), np.isnan(b))
    sol = V[:, 2:]
    assert np.isnan(sol[rows[:20]]).all() and (sol > 0).any() and (sol == 0).any()
    days = len(np.unique(ns // (86_400 * 10**9)))
    assert conv.solar.computed_days <= 2 * days  # a day of geometry per pvlib call, cached
    # a row off the step grid is computed directly (not cached)
    off = conv.convert(ns[40:41] + 60 * 10**9, values[40:41])[1]
    shifted = frame.iloc[40:41].copy()
    shifted.index = shifted.index + pd.Timedelta("1min")
    np.testing.assert_allclose(off, rows_from_frame(bundle, shifted)[2], rtol=0, atol=1e-12)
    # the boxes' discharge-air rise (the virtual building reports every box's discharge air)
    from zonecast.estimator.streaming import has_discharge, model_rows
    assert has_discharge(bundle)
    rise = model_rows(bundle, frame).reheat
    got = conv.convert_rows(ns, values)[3]
    np.testing.assert_allclose(got, rise, rtol=0, atol=1e-12)
    assert rise.max() > 5.0  # reheat coils ran


def test_dayahead_gains_on_arrays_equal_dayahead_issue(bundle, telemetry):
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tt, u, v, y = rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:3 * 96]))
    y = y.copy()
    y[100:110, 2] = np.nan  # the per-step gains become NaN for a while
    est = OnlineEstimator(bundle)
    checked = 0
    for k in range(len(tt)):
        if k in (150, 151):
            continue  # a gap: the gains history has a hole
        est.advance(tt[k], u[k], v[k], y[k])
        if not est.started:
            continue
        history = pd.DataFrame([f for _, f in est._gains], columns=bundle.zones,
                               index=pd.DatetimeIndex([s for s, _ in est._gains], tz="UTC"))
        ref = est._dayahead.issue(est.time, history).to_numpy()
        np.testing.assert_allclose(est.dayahead_gains(), ref, rtol=0, atol=1e-12)
        checked += 1
    assert checked > 250
    assert np.ptp(est.dayahead_gains(), axis=0).max() > 1.0  # the profile is not flat


def test_gains_level_is_the_weighted_mean_of_the_residuals_and_issue_agrees(
        bundle, telemetry, monkeypatch):
    """With GAINS_LEVEL_TAU the served gains are the profile plus a slow level L (the
    exponentially weighted mean of f_IG - profile over the per-step estimates) plus the
    short offset decaying to L: the same numbers as ``DayAheadGains.issue(level=L)``; a
    checkpoint keeps L; a restart forgets it."""
    from zonecast.estimator import streaming
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tau = pd.Timedelta("6h")
    monkeypatch.setattr(streaming, "GAINS_LEVEL_TAU", tau)
    tt, u, v, y = rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:3 * 96]))
    y = y.copy()
    y[100:110, 2] = np.nan  # the per-step gains become NaN for a while
    est, plain = OnlineEstimator(bundle), None
    alpha = 1.0 - np.exp(-(pd.Timedelta(bundle.profile.step) / tau))
    ref, seen, checked = np.zeros(len(bundle.zones)), 0, 0
    for k in range(len(tt)):
        est.advance(tt[k], u[k], v[k], y[k])
        if not est.started:
            continue
        if len(est._gains) and est._gains[-1][0] != seen:
            stamp, f = est._gains[-1]
            seen = stamp
            prof = np.nan_to_num(bundle.profile(pd.DatetimeIndex([stamp])))[0]
            ok = np.isfinite(f)
            ref[ok] += alpha * (f[ok] - prof[ok] - ref[ok])
        np.testing.assert_allclose(est._level, ref, rtol=0, atol=1e-9)
        history = pd.DataFrame([f for _, f in est._gains], columns=bundle.zones,
                               index=pd.DatetimeIndex([s for s, _ in est._gains], tz="UTC"))
        issued = est._dayahead.issue(est.time, history, level=est._level).to_numpy()
        np.testing.assert_allclose(est.dayahead_gains(), issued, rtol=0, atol=1e-12)
        checked += 1
    assert checked > 250 and np.abs(ref).max() > 0.1
    # far ahead the served gains are the profile plus the level
    base = np.nan_to_num(bundle.profile(pd.date_range(est.time, periods=96, freq="15min")))
    np.testing.assert_allclose(est.dayahead_gains()[-1], base[-1] + est._level, atol=1e-3)
    # a checkpoint keeps the level; without the option the gains are the profile's
    copy = OnlineEstimator(bundle)
    copy.load_bytes(est.to_bytes())
    assert np.array_equal(copy._level, est._level)
    assert np.array_equal(copy.dayahead_gains(), est.dayahead_gains())
    monkeypatch.setattr(streaming, "GAINS_LEVEL_TAU", None)
    plain = OnlineEstimator(bundle)
    plain.load_bytes(est.to_bytes())
    assert np.abs(plain.dayahead_gains()[-1] - base[-1]).max() < 1e-2
    est.reset()
    assert not est._level.any()


def test_served_forecast_at_a_due_step_is_the_calibration_forecast(bundle, telemetry):
    """At a step where a calibration forecast is kept, the served forecast reuses it (no
    model run) and equals, bit for bit, the one computed afresh; a new weather forecast,
    another control or the next step computes afresh."""
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tt, u, v, y = rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:2 * 96]))
    est = OnlineEstimator(bundle)
    runs = []
    real = est._run_forecast
    est._run_forecast = lambda *a, **k: runs.append(1) or real(*a, **k)
    due = 0
    for k in range(len(tt)):
        est.advance(tt[k], u[k], v[k], y[k])
        if est._due is None or est._due[0][0] != est.time:
            continue
        due += 1
        runs.clear()
        cached = est.forecast()
        assert not runs  # no model run
        est._due = None
        fresh = est.forecast()
        assert runs
        for name in ("mean", "std", "f_ig", "lower", "upper"):
            assert np.array_equal(getattr(cached, name), getattr(fresh, name)), name
    assert due >= 4
    # another control than the calibration's, or a new weather forecast: afresh
    est.advance(tt[-1] + pd.Timedelta("15min"), u[-1], v[-1], y[-1])
    while est._due is None or est._due[0][0] != est.time:
        est.advance(est.time + pd.Timedelta("15min"), u[-1], v[-1], y[-1])
    runs.clear()
    est.forecast(thermostat_reheat=not est.reheat_control)
    assert runs
    est.set_weather_forecast(None)
    assert est._due is None


def test_npz_checkpoint_of_the_earlier_format_still_loads(bundle, telemetry):
    """Checkpoints stored before the raw format (an .npz with ISO time lists) resume. Their
    estimator had no young filter after a start (the format has no key for it), so they
    resume with the steady-state filter, as the estimator that wrote them ran."""
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tt, u, v, y = rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:20]))
    a = OnlineEstimator(bundle)
    a.young_filter = False  # as the estimators that wrote this format
    for k in range(12):
        a.advance(tt[k], u[k], v[k], y[k])
    meta = {"time": a.time.isoformat(), "started": True, "steps": a.steps,
            "resets": a.resets, "nis_sum": a.nis_sum, "dof_sum": a.dof_sum,
            "gain_times": [s.isoformat() for s, _ in a._gains],
            "input_times": [s.isoformat() for s, _ in a._inputs],
            "version": bundle.version, "since": a._since}
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(meta)), pending=a._pending, held=a._held,
             online=a._online, last_y=a.last_y, last_f=a.last_f, observed=a._observed,
             gains=np.array([f for _, f in a._gains]), inputs=np.array([r for _, r in a._inputs]),
             x=a._x)
    b, c = OnlineEstimator(bundle), OnlineEstimator(bundle)
    b.load_bytes(buf.getvalue())
    c.load_bytes(a.to_bytes())
    assert a.to_bytes()[:4] == b"ZCE2"
    for k in range(12, 20):
        for e in (a, b, c):
            e.advance(tt[k], u[k], v[k], y[k])
    for e in (b, c):
        assert np.array_equal(e.x, a.x) and e.steps == a.steps
        fa, fe = a.forecast(), e.forecast()
        assert np.array_equal(fa.mean, fe.mean) and np.array_equal(fa.f_ig, fe.f_ig)


def test_checkpoint_rows_of_another_width_are_refused(bundle, telemetry):
    """A checkpoint written before v gained the roofs' solH column holds one input fewer per
    row: it is refused with a message (the runner then starts the filter afresh), never
    loaded into the wrong columns."""
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tt, u, v, y = rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:8]))
    a = OnlineEstimator(bundle)
    for k in range(8):
        a.advance(tt[k], u[k], v[k], y[k])
    nb = bundle.model.n_boxes
    drop = nb + 6  # the seventh disturbance, solH
    meta = {"time": a.time.isoformat(), "started": True, "steps": a.steps,
            "resets": a.resets, "nis_sum": a.nis_sum, "dof_sum": a.dof_sum,
            "gain_times": [s.isoformat() for s, _ in a._gains],
            "input_times": [s.isoformat() for s, _ in a._inputs],
            "version": bundle.version, "since": a._since}
    inputs = np.array([r for _, r in a._inputs])
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(meta)), pending=np.delete(a._pending, drop),
             held=np.delete(a._held, drop), online=a._online, last_y=a.last_y,
             last_f=a.last_f, observed=a._observed, gains=np.array([f for _, f in a._gains]),
             inputs=np.delete(inputs, drop, axis=1), x=a._x)
    b = OnlineEstimator(bundle)
    with pytest.raises(ValueError, match="start the filter afresh"):
        b.load_bytes(buf.getvalue())
    assert b.time is None and not b.started  # untouched


def test_discharge_air_enters_the_online_step_and_a_silent_point_means_no_rise(bundle, telemetry):
    """The runner's estimator uses each box's discharge-air rise; a discharge point that
    never reported is reported as held and stepped as no rise (the supply-air term), which
    is what an estimator without the point computes."""
    from zonecast.estimator.streaming import OnlineEstimator, model_rows

    d = model_rows(bundle, si_frame(bundle, telemetry.iloc[:2 * 96]))
    assert np.abs(d.reheat).max() > 5.0
    with_rh, silent, zero = (OnlineEstimator(bundle) for _ in range(3))
    for k in range(len(d)):
        with_rh.advance(d.times[k], d.u[k], d.v[k], d.y[k], d.reheat[k])
        rep = silent.advance(d.times[k], d.u[k], d.v[k], d.y[k])
        zero.advance(d.times[k], d.u[k], d.v[k], d.y[k], np.zeros(len(d.boxes)))
    assert any(name.startswith("r:") for name in rep.held_inputs)
    assert np.array_equal(silent.x, zero.x)
    # with the same horizon inputs (the learned input forecasts differ: one learner saw no
    # discharge-air channel at all)
    ins = zero.persistence_inputs()
    assert np.array_equal(silent.persistence_inputs(), ins)
    assert np.array_equal(silent.forecast(ins).mean, zero.forecast(ins).mean)
    assert np.abs(with_rh.forecast(with_rh.persistence_inputs()).mean
                  - zero.forecast(ins).mean).max() > 0.05


def test_hvac_inputs_regress_on_each_facade_irradiance(bundle, telemetry):
    """The HVAC-input learner's regressors are the outdoor temperature and the irradiance
    of each of the building's four facades (not their sum): a slot learned once holds
    exactly that row's five values as its regressor means."""
    from zonecast.estimator.streaming import OnlineEstimator, model_rows

    d = model_rows(bundle, si_frame(bundle, telemetry.iloc[40:44]))
    tt, v = d.times, d.v
    a = OnlineEstimator(bundle)
    for k in range(4):
        a.advance(tt[k], d.u[k], v[k], d.y[k], d.reheat[k])
    assert a.inputs_fc.p == 5
    for k in range(4):
        slot = int(a.calendar.slots([tt[k].value])[0])
        assert a.inputs_fc.w[slot] == 1.0
        np.testing.assert_array_equal(a.inputs_fc.mx[slot], v[k][[0, 2, 3, 4, 5]])


def test_forecast_is_held_in_the_thermostat_band_after_the_recovery_time(bundle, telemetry):
    """The served forecast is the free model forecast clipped to the site's set-point band
    (Thermostat.band), the band opened for HOLD_RECOVERY_H after each set-point step and
    inside experiments; without a thermostat, or with hold_setpoints off, it is the free
    forecast."""
    import dataclasses

    from zonecast.estimator import streaming
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    site = bundle.site
    assert site.thermostat is not None
    tt, u, v, y = rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:2 * 96 + 30]))
    est = OnlineEstimator(bundle)
    for k in range(len(tt)):
        est.advance(tt[k], u[k], v[k], y[k])
    ins = est.persistence_inputs()
    held = est.forecast(ins).mean
    est.hold_setpoints = False
    free = est.forecast(ins).mean
    est.hold_setpoints = True
    times = est.time + streaming.STEP * np.arange(1, streaming.HORIZON + 1)
    exp = np.array([any(pd.Timestamp(e.start) <= t < pd.Timestamp(e.end)
                        for e in site.experiments) for t in times])
    heat, cool = site.thermostat.band(times, site.timezone, exp)
    h0, c0 = site.thermostat.band(times - pd.Timedelta(hours=streaming.HOLD_RECOVERY_H),
                                  site.timezone, exp)
    lo, hi = np.minimum(heat, h0), np.maximum(cool, c0)
    np.testing.assert_array_equal(held, np.clip(free, lo[:, None], hi[:, None]))
    assert (held != free).any()  # the band acts on this day (a working day's morning)
    # the set point steps up at the start of occupancy: held at the old value for the
    # recovery time, then at the new one
    step_up = np.flatnonzero(np.diff(heat) > 0)
    assert len(step_up) and lo[step_up[0] + 1] < heat[step_up[0] + 1]
    no_tstat = dataclasses.replace(bundle, site=site.model_copy(update={"thermostat": None}))
    bare = OnlineEstimator(no_tstat)
    for k in range(len(tt)):
        bare.advance(tt[k], u[k], v[k], y[k])
    np.testing.assert_array_equal(bare.forecast(ins).mean, free)


def test_thermostat_band_is_open_where_nothing_is_declared():
    from zonecast.estimator.site import Thermostat

    times = pd.date_range("2015-04-20T00:00-07:00", periods=6, freq="4h")  # a Monday
    t = Thermostat(heating_occupied=21, heating_unoccupied=17, occupied_hours=(8, 18))
    heat, cool = t.band(times, "America/Los_Angeles")
    np.testing.assert_array_equal(heat, [17, 17, 21, 21, 21, 17])
    assert np.isinf(cool).all() and (cool > 0).all()  # no cooling set point declared
    t2 = t.model_copy(update={"cooling_occupied": 24.0, "cooling_unoccupied": 28.0,
                              "holidays": [pd.Timestamp("2015-04-20").date()]})
    exp = np.array([False, True, False, False, False, False])
    heat, cool = t2.band(times, "America/Los_Angeles", exp)
    np.testing.assert_array_equal(heat, [17, -np.inf, 17, 17, 17, 17])  # a holiday
    np.testing.assert_array_equal(cool, [28, np.inf, 28, 28, 28, 28])


def test_the_row_converter_and_runner_do_not_wait_for_the_meters(bundle):
    """The lights and plug-load meters (points.power) are ingested (the catalogue has them)
    and tracked for gaps, but the estimator's rows are made of its own points: a row never
    waits for a meter, and a row of meter readings alone is not processed (the runner's
    own behaviour: tests/service/test_service_app.py)."""
    from zonecast.estimator.streaming import RowConverter
    from zonecast.service.context import catalogue_for_site

    meters = bundle.site.meter_points()
    assert meters and set(meters) <= set(catalogue_for_site(bundle.site))
    conv = RowConverter(bundle)
    assert not set(meters) & set(conv.points)
    assert set(conv.points) | set(meters) == set(bundle.site.point_units())


def test_young_checkpoints_past_the_filters_end_and_a_zero_length_young_filter(
        bundle, telemetry, monkeypatch):
    """A checkpoint whose young-filter step lies at or past this estimator's young filter
    resumes with the steady filter; YOUNG_STEPS = 0 means no young filter at all."""
    import zonecast.estimator.streaming as S

    tt, u, v, y = S.rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:6]))
    a = S.OnlineEstimator(bundle)
    for k in range(4):
        a.advance(tt[k], u[k], v[k], y[k])
    assert a._young == 3 and a._young_seen == 3
    monkeypatch.setattr(S, "YOUNG_STEPS", 3)
    b = S.OnlineEstimator(bundle)
    b.load_bytes(a.to_bytes())
    assert b._yf.steps == 3 and b._young is None and b._young_seen == 3
    b.advance(tt[4], u[4], v[4], y[4])  # the steady filter, no IndexError
    assert b._young is None and b._young_seen is None
    monkeypatch.setattr(S, "YOUNG_STEPS", 0)
    c = S.OnlineEstimator(bundle)
    for k in range(3):
        c.advance(tt[k], u[k], v[k], y[k])
    assert c._young is None and c._young_seen is None


def test_estimator_calibrates_by_the_sites_day_class_and_resumes_a_pooled_checkpoint(
        bundle, telemetry, monkeypatch):
    """The estimator's interval calibration is split by the site calendar's day class
    (working day / weekend or holiday) of the target; a checkpoint written by an estimator
    calibrating all days pooled resumes with both classes seeded from its scores."""
    from zonecast.estimator import streaming
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tt, u, v, y = rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:400]))
    monkeypatch.setattr(streaming, "DAY_CLASS_INTERVALS", True)
    monkeypatch.setattr(streaming, "AFTER_OFF_INTERVALS", False)  # two classes
    est = OnlineEstimator(bundle)
    cal = est.calibrator
    assert cal.n_classes == 2
    saturday = pd.Timestamp("2015-05-16 12:00", tz=bundle.site.timezone)
    monday = pd.Timestamp("2015-05-18 12:00", tz=bundle.site.timezone)
    step = streaming.STEP.value
    assert cal.class_of(saturday.value // step) == 1 and cal.class_of(monday.value // step) == 0
    monkeypatch.setattr(streaming, "DAY_CLASS_INTERVALS", False)
    old = OnlineEstimator(bundle)
    assert old.calibrator.n_classes == 1
    for k in range(len(tt)):
        old.advance(tt[k], u[k], v[k], y[k])
    assert old.calibrator.hist.sum() > 0
    monkeypatch.setattr(streaming, "DAY_CLASS_INTERVALS", True)
    new = OnlineEstimator(bundle)
    new.load_bytes(old.to_bytes())
    n = new.calibrator.n_class_bins
    for c in range(2):
        assert np.array_equal(new.calibrator.hist[c * n:(c + 1) * n], old.calibrator.hist)
    assert np.array_equal(new.calibrator.levels, np.tile(old.calibrator.levels, (2, 1)))
    f = new.forecast()
    assert np.all(np.isfinite(f.lower)) and np.all(f.upper > f.lower)
    # and back: a day-class checkpoint resumes pooled (the classes' scores summed)
    for k in range(len(tt) // 2):
        new.advance(tt[-1] + (k + 1) * pd.Timedelta("15min"), u[k], v[k], y[k])
    monkeypatch.setattr(streaming, "DAY_CLASS_INTERVALS", False)
    back = OnlineEstimator(bundle)
    back.load_bytes(new.to_bytes())
    assert back.calibrator.n_classes == 1
    np.testing.assert_allclose(back.calibrator.hist,
                               new.calibrator.hist[:n] + new.calibrator.hist[n:])
    np.testing.assert_allclose(back.calibrator.levels[0], new.calibrator.levels.mean(axis=0))
    f = back.forecast()
    assert np.all(np.isfinite(f.lower)) and np.all(f.upper > f.lower)


def test_estimator_calibrates_the_day_after_a_day_off_apart_when_asked(bundle, telemetry,
                                                                       monkeypatch):
    """With AFTER_OFF_INTERVALS the calibration has a third class for the working days after a
    day off (the site calendar's), the estimator scores into it on Mondays, and a two-class
    checkpoint resumes with its classes kept."""
    from zonecast.estimator import streaming
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tt, u, v, y = rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:200]))
    monkeypatch.setattr(streaming, "DAY_CLASS_INTERVALS", True)
    monkeypatch.setattr(streaming, "AFTER_OFF_INTERVALS", False)
    old = OnlineEstimator(bundle)
    for k in range(40):  # a two-class checkpoint with working-day scores
        old.advance(tt[k], u[k], v[k], y[k])
    monkeypatch.setattr(streaming, "AFTER_OFF_INTERVALS", True)
    est = OnlineEstimator(bundle)
    cal = est.calibrator
    assert cal.n_classes == 3
    step = streaming.STEP.value
    tz = bundle.site.timezone
    for day, c in (("2015-05-16", 1), ("2015-05-18", 2), ("2015-05-19", 0)):
        assert cal.class_of(pd.Timestamp(f"{day} 12:00", tz=tz).value // step) == c
    for k in range(len(tt)):
        est.advance(tt[k], u[k], v[k], y[k])
    n = cal.n_class_bins
    local = pd.DatetimeIndex(tt).tz_convert(tz)
    assert (local.day_of_week == 0).any() and cal.hist[2 * n:].sum() > 0
    resumed = OnlineEstimator(bundle)
    resumed.load_bytes(old.to_bytes())
    assert old.calibrator.hist[:n].sum() > 0
    assert np.array_equal(resumed.calibrator.hist[:2 * n], old.calibrator.hist)
    assert np.array_equal(resumed.calibrator.hist[2 * n:], old.calibrator.hist[:n])
    f = resumed.forecast()
    assert np.all(np.isfinite(f.lower)) and np.all(f.upper > f.lower)


def test_served_interval_widens_by_the_forecasts_change_under_the_weathers_error(
        bundle, telemetry):
    """The served forecast's interval scales sqrt(std^2 + change^2), the change being the
    forecast run again with its weather inputs perturbed by the learned spread; the
    spread is learned from the served weather's own errors and survives a checkpoint."""
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tt, u, v, y = rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:700]))
    est = OnlineEstimator(bundle)
    for k in range(len(tt)):
        est.advance(tt[k], u[k], v[k], y[k])
    ws = est.weather_spread
    assert ws is not None and ws.weight.max() >= ws.min_weight
    ins = est.forecast_inputs()
    f_ig = est.dayahead_gains()
    control = est.reheat_control
    mean = est._run_forecast(ins, f_ig, control=control)
    d = ws.spread(ins[:, est._w_cols])
    assert d[1:, 0].min() > 0  # the outdoor temperature's error, every lead
    pert = ins.copy()
    pert[:, est._w_cols] += d
    change = est._run_forecast(pert, f_ig, control=control) - mean
    want = np.sqrt(est._forecast_std() ** 2 + change ** 2)
    np.testing.assert_allclose(est._served_std(ins, f_ig, control, mean), want)
    fc = est.forecast()
    k = est.time.value // 900_000_000_000
    np.testing.assert_allclose(fc.upper - fc.mean, est.calibrator.halfwidth(k, want))
    assert np.abs(change).max() > 0.01  # the weather moves the forecast
    other = OnlineEstimator(bundle)
    other.load_bytes(est.to_bytes())
    assert np.array_equal(other.weather_spread.spread(ins[:, est._w_cols]), d)
    assert np.array_equal(other.forecast().upper, fc.upper)


def test_weather_spread_both_ways_is_two_sigma_points(bundle, telemetry):
    """With spread_two_sided the std is sqrt(std^2 + (change+^2 + change-^2) / 2), the
    weather perturbed up and down by its learned error (irradiance clipped at zero); a
    forecast linear in the weather (no thermostat, no set-point band) gets what the
    one-way spread gives."""
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tt, u, v, y = rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:700]))
    est = OnlineEstimator(bundle)
    for k in range(len(tt)):
        est.advance(tt[k], u[k], v[k], y[k])
    ins, f_ig, control = est.forecast_inputs(), est.dayahead_gains(), est.reheat_control
    w = est._w_cols
    d = est.weather_spread.spread(ins[:, w])
    est.spread_two_sided = True
    mean = est._run_forecast(ins, f_ig, control=control)
    up, down = ins.copy(), ins.copy()
    up[:, w] += d
    down[:, w] -= d
    down[:, w[1:]] = np.maximum(down[:, w[1:]], 0.0)
    cu = est._run_forecast(up, f_ig, control=control) - mean
    cd = est._run_forecast(down, f_ig, control=control) - mean
    want = np.sqrt(est._forecast_std() ** 2 + 0.5 * (cu ** 2 + cd ** 2))
    np.testing.assert_allclose(est._served_std(ins, f_ig, control, mean), want)
    assert np.abs(cd).max() > 0.01
    # linear in the weather: both ways = one way
    est.hold_setpoints = False
    free = est._run_forecast(ins, f_ig, control=False)
    two = est._served_std(ins, f_ig, False, free)
    est.spread_two_sided = False
    one = est._served_std(ins, f_ig, False, free)
    assert (down[:, w[1:]] == ins[:, w[1:]] - d[:, 1:]).all()  # nothing clipped here
    np.testing.assert_allclose(two, one, rtol=1e-9, atol=1e-12)


def test_closed_loop_factor_is_the_share_of_a_heat_probe_the_thermostats_let_through(
        bundle, telemetry):
    """The closed-loop factor is the rms change of the controlled forecast under the gains
    raised and lowered by the probe over the uncontrolled model's response to it: 1 for a
    forecast linear in the gains (no thermostat, no band), below 1 where the thermostats
    hold a room, in [0, 1] everywhere; the served std is then
    sqrt(rho^2 std^2 + (1 - rho^2) sigma_meas^2) before the weather's spread."""
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tt, u, v, y = rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:700]))
    est = OnlineEstimator(bundle)
    for k in range(len(tt)):
        est.advance(tt[k], u[k], v[k], y[k])
    assert est._probe > 0
    ins, f_ig = est.forecast_inputs(), est.dayahead_gains()
    # linear: no set-point band, no thermostat
    est.hold_setpoints = False
    free = est._run_forecast(ins, f_ig, control=False)
    rho = est._closed_loop_factor(ins, f_ig, free)
    assert rho.shape == free.shape
    np.testing.assert_allclose(rho, 1.0, atol=1e-6)
    # with the thermostats: some room-steps held, all within [0, 1]
    est.hold_setpoints = True
    control = est.reheat_control
    mean = est._run_forecast(ins, f_ig, control=control)
    rho = est._closed_loop_factor(ins, f_ig, mean)
    assert (rho >= 0).all() and (rho <= 1).all()
    assert rho.min() < 0.5 and rho.max() > 0.9
    # the served std uses it (weather's spread off to see the model's part alone)
    est.weather_spread, est.closed_loop_std = None, True
    meas = np.diag(est._steady.R)
    std = est._forecast_std()
    want = np.sqrt(rho ** 2 * std ** 2 + (1 - rho ** 2) * meas[None, :])
    np.testing.assert_allclose(est._served_std(ins, f_ig, control, mean), want)
    est.closed_loop_std = False
    np.testing.assert_allclose(est._served_std(ins, f_ig, control, mean), std)


def test_forecast_variants_of_one_replay_equal_separate_replays(bundle, telemetry):
    """offline_forecast_variants gives, variant for variant, bit for bit what a replay per
    variant (offline_forecasts) gives: the served forecast, persistence, and given inputs
    where the mapping has them (served elsewhere)."""
    from zonecast.estimator.streaming import (
        OnlineEstimator,
        offline_forecast_variants,
        offline_forecasts,
    )

    frame = si_frame(bundle, telemetry.iloc[:500])
    times = list(frame.index[[300, 420, 499]])
    persisted = offline_forecasts(bundle, frame, times, persistence=True)
    nin = OnlineEstimator(bundle)._nin  # u, v and any per-box discharge-air rise
    rng = np.random.default_rng(0)
    base = np.column_stack([np.full((96, bundle.model.n_boxes), 0.2), np.full((96, 1), 10.0),
                            np.full((96, 1), 14.0), rng.uniform(0, 300, (96, 5))])
    given = {times[1]: np.hstack([base, np.zeros((96, nin - base.shape[1]))])}
    separate = {"served": offline_forecasts(bundle, frame, times),
                "persistence": persisted,
                "given": offline_forecasts(bundle, frame, times, inputs=given)}
    together = offline_forecast_variants(bundle, frame, times, {
        "served": None, "persistence": "persistence", "given": given})
    for name, fcs in separate.items():
        for t in times:
            a, b = fcs[t], together[name][t]
            assert np.array_equal(a.mean, b.mean) and np.array_equal(a.upper, b.upper), name
    assert not np.array_equal(together["given"][times[1]].mean, together["served"][times[1]].mean)
    assert np.array_equal(together["given"][times[0]].mean, together["served"][times[0]].mean)
    with pytest.raises(ValueError, match="None, 'persistence' or a mapping"):
        offline_forecast_variants(bundle, frame, times, {"x": "yesterday"})


def test_settled_calibration_skips_the_young_filters_forecasts_after_each_start(
        bundle, telemetry, monkeypatch):
    """With ``calibrate_young`` off the interval calibration keeps no forecast issued in the
    first YOUNG_STEPS steps after a start, the first one and the one after a gap longer
    than ``max_gap``; the filter's age survives a checkpoint, and a checkpoint written
    before the age was kept resumes as a settled filter."""
    import zonecast.estimator.streaming as S

    monkeypatch.setattr(S, "YOUNG_STEPS", 16)
    tt, u, v, y = S.rows_from_frame(bundle, si_frame(bundle, telemetry.iloc[:80]))
    gap = 40  # rows 40..43 missing: a gap of 75 min restarts the filter at row 44
    keep = [k for k in range(len(tt)) if not gap <= k < gap + 4]

    def kept_steps(calibrate_young: bool) -> list[int]:
        est = S.OnlineEstimator(bundle, max_gap=pd.Timedelta("30min"))
        est.calibrate_young = calibrate_young
        seen: list[int] = []
        add = est.calibrator.add_forecast

        def record(step_index, mean, std=None):
            seen.append(int(step_index))
            return add(step_index, mean, std)

        est.calibrator.add_forecast = record
        for k in keep:
            est.advance(tt[k], u[k], v[k], y[k])
        assert est.resets == 1
        step = tt[0].value // S.STEP.value
        return [s - step for s in seen]  # rows of the kept forecasts

    young = kept_steps(True)
    settled = kept_steps(False)
    due = [k for k in keep if (tt[k].value // S.STEP.value) % 8 == 0]
    assert young == due
    # the first start at row 0, the restart at row 44: 16 steps each before any is kept
    assert settled == [k for k in due if 16 <= k < gap or k >= gap + 4 + 16]
    assert settled and len(settled) < len(young)
    # the age in a checkpoint; an older checkpoint without it is a settled filter
    a = S.OnlineEstimator(bundle)
    for k in range(5):
        a.advance(tt[k], u[k], v[k], y[k])
    assert a._age == 4
    b = S.OnlineEstimator(bundle)
    b.load_bytes(a.to_bytes())
    assert b._age == 4
    raw = a.to_bytes()
    n = int.from_bytes(raw[4:8], "big")
    meta = json.loads(raw[8:8 + n])
    assert meta.pop("age") == 4
    head = json.dumps(meta).encode()  # the same state as written before the age was kept
    c = S.OnlineEstimator(bundle)
    c.load_bytes(raw[:4] + len(head).to_bytes(4, "big") + head + raw[8 + n:])
    assert c._age == S.YOUNG_STEPS


def test_served_weather_is_the_forecast_combined_with_the_fallback_by_learned_weights(
        bundle, telemetry, monkeypatch):
    """With weather forecasts in use, the served weather inputs are D + a (F - D) on the
    forecast's intervals, F the forecast as received (its temperature corrected by the
    measurement), D the diurnal fallback and a the weights learned from the building's
    own forecasts and measured weather; the weights survive a checkpoint; without the
    option (the default) the forecast is served as received."""
    from zonecast.estimator import streaming
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame
    from zonecast.estimator.weather_forecast import parse_weather_forecast
    from zonecast.testbed.forecasts import weather_forecasts

    monkeypatch.setattr(streaming, "WEATHER_BLEND", True)
    frame = si_frame(bundle, telemetry.iloc[:1000])
    wfs = [parse_weather_forecast(b) for b in weather_forecasts(bundle.site, frame, seed=2)]
    tt, u, v, y = rows_from_frame(bundle, frame.iloc[:800])  # the forecasts reach beyond
    est = OnlineEstimator(bundle)
    j = 0
    for k in range(len(tt)):
        while j < len(wfs) and wfs[j].issued <= tt[k]:
            est.set_weather_forecast(wfs[j])
            j += 1
        est.advance(tt[k], u[k], v[k], y[k])
    wb = est.weather_blend
    assert wb is not None and wb.weight.max() >= wb.min_weight
    a = wb.weights()
    assert (a < 1.0).any() and (a >= 0).all()
    raw, fb, from_wf = est._weather_parts()
    assert from_wf[1:].all()
    served, mask = est.weather_inputs()
    assert np.array_equal(mask, from_wf)
    lb = np.arange(len(raw) - 1) // wb.lead_bin
    np.testing.assert_allclose(served[1:], fb[1:] + a[lb] * (raw[1:] - fb[1:]), atol=1e-9)
    assert np.array_equal(served[0], raw[0])
    assert not np.allclose(served[1:], raw[1:])
    other = OnlineEstimator(bundle)
    other.load_bytes(est.to_bytes())
    assert np.array_equal(other.weather_inputs()[0], served)
    monkeypatch.setattr(streaming, "WEATHER_BLEND", False)
    plain = OnlineEstimator(bundle)
    plain.load_bytes(est.to_bytes())
    assert plain.weather_blend is None
    assert np.array_equal(plain.weather_inputs()[0], raw)
