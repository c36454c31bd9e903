"""The served forecast's reheat as the thermostat's answer (OnlineEstimator.reheat_control):
the boxes with a discharge-air point reheat just enough to hold their room at the heating
set point, none above it; inputs given by the caller (known-input evaluations) keep their
measured rise."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest


@pytest.fixture(scope="module")
def est(bundle, telemetry):
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    frame = telemetry.set_index(pd.to_datetime(telemetry["time"], format="ISO8601", utc=True))
    frame = frame.drop(columns="time").astype(float)[list(bundle.site.point_units())]
    tt, u, v, y = rows_from_frame(bundle, frame.iloc[:2 * 96 + 30])
    e = OnlineEstimator(bundle)
    for k in range(len(tt)):
        e.advance(tt[k], u[k], v[k], y[k])
    return e


def _parts(est):
    from zonecast.estimator.streaming import NV

    m = est.bundle.model
    nb = m.n_boxes
    ins = est.persistence_inputs()
    f_ig = est.dayahead_gains()
    u, v = ins[:, :nb], ins[:, nb:nb + NV]
    forcing = v @ m.Bv.T + (f_ig + m.params.c_ig) @ m.B_ig.T
    return m, nb, ins, u, v, forcing, est._ladder.for_airflows(u)


def test_controlled_run_holds_the_heating_setpoint_with_the_least_reheat(est):
    m, nb, ins, u, v, forcing, stepper = _parts(est)
    assert est._coil.all()  # the virtual building reports every box's discharge air
    rise = ins[:, -nb:]
    # no set point anywhere: the coil boxes' rise is dropped, nothing else changes
    off = np.full(len(u), -np.inf)
    free = stepper.run(est._x, u, forcing + m.reheat_forcing(u, np.zeros_like(rise)), v[:, 1])
    np.testing.assert_array_equal(est._controlled_run(stepper, u, forcing, v[:, 1], rise, off),
                                  free)
    # a set point above the free forecast in some rooms and steps
    rooms = est._coil_rooms
    assert len(rooms) >= m.n_zones  # the virtual building: one or more rooms per zone
    T_free = free[1:, rooms]
    sp = np.full(len(u), float(np.percentile(T_free, 60)))
    xs = est._controlled_run(stepper, u, forcing, v[:, 1], rise, sp)
    T = xs[1:, rooms]
    can = (u * est._coil) @ est._coil_room_box > 0  # (H, rooms) a coil box runs
    assert can.any()
    assert (T[can] >= sp[0] - 1e-6).all()  # every room's air held wherever it can be
    heated = can & (T_free < sp[0] - 0.05)
    assert heated.sum() > 10
    # the least reheat: a heated room ends the step at the set point (not above), unless
    # a neighbour's heat carried it there
    assert np.isclose(T[heated], sp[0], atol=1e-6).mean() > 0.9
    # heat only raises temperatures: never below the forecast without reheat
    assert (xs >= free - 1e-9).all()


def test_served_forecast_uses_the_controller_and_known_inputs_do_not(est):
    from zonecast.estimator import streaming

    assert est.reheat_control == streaming.REHEAT_CONTROL
    before = est.reheat_control
    try:
        est.reheat_control = False
        served_off = est.forecast().mean
        ins = est.forecast_inputs()
        known_off = est.forecast(ins).mean
        est.reheat_control = True
        served_on = est.forecast().mean
        known_on = est.forecast(ins).mean
        asked = est.forecast(ins, thermostat_reheat=True).mean
    finally:
        est.reheat_control = before
    np.testing.assert_array_equal(known_on, known_off)  # given inputs keep their rise
    # ... unless asked: the same controlled forecast as served from the same inputs
    np.testing.assert_array_equal(asked, served_on)
    np.testing.assert_array_equal(est.forecast(thermostat_reheat=False).mean, served_off)
    # the served forecast is the controlled run, clipped to the band
    m, nb, nv = est.bundle.model, est.bundle.model.n_boxes, streaming.NV
    u = ins[:, :nb]
    forcing = ins[:, nb:nb + nv] @ m.Bv.T + (est.dayahead_gains() + m.params.c_ig) @ m.B_ig.T
    lo, hi = est._setpoint_band()
    heat, cool = est._setpoint_band(steps=True)  # the controller's: in effect per step
    xs = est._controlled_run(est._ladder.for_airflows(u), u, forcing, ins[:, nb + 1],
                             ins[:, -nb:], heat, cool,
                             est.airflow_floor.floor() if est.deadband_control else None)
    np.testing.assert_allclose(served_on, np.clip(xs[1:] @ m.C.T, lo[:, None], hi[:, None]),
                               rtol=0, atol=1e-12)
    assert not np.array_equal(served_on, served_off)


def test_controlled_run_equals_exact_responses_and_depends_on_its_inputs_only(est):
    """The Newton solve with the run's earlier responses gives the reheat of the exact
    one-step responses at every step (to REHEAT_TOL), and the run is a function of the
    state and inputs: a second run after another one is the same to the bit."""
    m, nb, ins, u, v, forcing, stepper = _parts(est)
    rise = ins[:, -nb:]
    rooms, rb, coil = est._coil_rooms, est._coil_room_box, est._coil
    free = stepper.run(est._x, u, forcing + m.reheat_forcing(u, np.zeros_like(rise)), v[:, 1])
    sp = np.full(len(u), float(np.percentile(free[1:, rooms], 70)))
    # reference: the exact responses at each step's airflows, solved directly
    f = forcing + m.reheat_forcing(u, np.where(coil[None, :], 0.0, rise))
    ref = np.empty_like(free)
    ref[0] = x = est._x
    heated = 0
    for h in range(len(u)):
        x = stepper.step(x, u[h], f[h], v[h, 1])
        need = sp[h] - x[rooms]
        sel = np.flatnonzero((need > 1e-6) & ((u[h] * coil) @ rb > 0))
        if len(sel):
            R = m.reheat_forcing(np.broadcast_to(u[h], (len(sel), nb)), rb[:, sel].T)
            resp = stepper.columns(u[h], R.T)
            x = x + resp @ np.maximum(np.linalg.solve(resp[rooms[sel]], need[sel]), 0.0)
            heated += 1
        ref[h + 1] = x
    assert heated > 20
    xs = est._controlled_run(stepper, u, forcing, v[:, 1], rise, sp)
    np.testing.assert_allclose(xs, ref, rtol=0, atol=1e-7)
    est._controlled_run(stepper, u, forcing, v[:, 1], rise, sp - 0.5)  # another run between
    np.testing.assert_array_equal(est._controlled_run(stepper, u, forcing, v[:, 1], rise, sp), xs)


def test_older_responses_are_kept_while_they_converge_and_every_policy_agrees(est, monkeypatch):
    """However long the Newton solve keeps the older responses (REHEAT_ITER, REHEAT_RATE),
    the controlled run is the same to the solver's tolerance; the default keeps them while
    each iteration cuts the shortfall twentyfold, so it recomputes fewer responses than
    three iterations would, and recomputing at once (REHEAT_RATE 0) at every heated step
    recomputes the most."""
    import zonecast.estimator.streaming as S

    m, nb, ins, u, v, forcing, stepper = _parts(est)
    rise = ins[:, -nb:]
    rooms = est._coil_rooms
    free = stepper.run(est._x, u, forcing + m.reheat_forcing(u, np.zeros_like(rise)), v[:, 1])
    sp = np.full(len(u), float(np.percentile(free[1:, rooms], 70)))
    counted = {"n": 0}
    inner = est._air_responses

    def counting(stepper_, u_, rows):
        counted["n"] += len(rows)
        return inner(stepper_, u_, rows)

    monkeypatch.setattr(est, "_air_responses", counting)
    runs, columns = {}, {}
    for policy in [(S.REHEAT_ITER, S.REHEAT_RATE), (3, 1.0), (1, 0.0)]:
        monkeypatch.setattr(S, "REHEAT_ITER", policy[0])
        monkeypatch.setattr(S, "REHEAT_RATE", policy[1])
        counted["n"] = 0
        runs[policy] = est._controlled_run(stepper, u, forcing, v[:, 1], rise, sp)
        columns[policy] = counted["n"]
    default, three, always = list(runs)  # the three policies, in the order run
    for policy in (three, always):
        np.testing.assert_allclose(runs[policy], runs[default], rtol=0, atol=1e-7)
    assert columns[default] < columns[three] <= columns[always]


def test_cooling_holds_the_cooling_setpoint_and_heat_and_cool_solve_together(est):
    """With a cooling set point the rooms with a running box end every step at or below
    it, at it where they would be above (the least cooling), never colder than without
    cooling; without one (None) the run is the reheat-only run."""
    m, nb, ins, u, v, forcing, stepper = _parts(est)
    rise = ins[:, -nb:]
    rooms = est._ctl[1]["rooms"]
    heat = np.full(len(u), -np.inf)
    free = est._controlled_run(stepper, u, forcing, v[:, 1], rise, heat)
    np.testing.assert_array_equal(
        est._controlled_run(stepper, u, forcing, v[:, 1], rise, heat, None), free)
    T_free = free[1:, rooms]
    cool = np.full(len(u), float(np.percentile(T_free, 40)))
    xs = est._controlled_run(stepper, u, forcing, v[:, 1], rise, heat, cool)
    T = xs[1:, rooms]
    can = (u * est._cool) @ est._ctl[1]["rb"] > 0
    assert can.any()
    assert (T[can] <= cool[0] + 1e-6).all()
    # the least cooling: a room that a step without control would leave above the set
    # point ends it at the set point (unless a neighbour's cooling carried it below)
    f = forcing + m.reheat_forcing(u, np.where(est._coil[None, :], 0.0, rise))
    one = np.array([stepper.step(xs[j], u[j], f[j], v[j, 1])[rooms] for j in range(len(u))])
    cooled = can & (one > cool[0] + 1e-6)
    assert cooled.sum() > 10
    assert np.isclose(T[cooled], cool[0], atol=1e-6).mean() > 0.9
    assert (xs <= free + 1e-9).all()  # cooling only lowers temperatures
    # both set points at once: a narrow band around the free forecast's middle
    mid = float(np.median(T_free))
    both = est._controlled_run(stepper, u, forcing, v[:, 1], rise,
                               np.full(len(u), mid - 0.1), np.full(len(u), mid + 0.1))
    Tb = both[1:, rooms]
    ch = (u * est._coil) @ est._ctl[0]["rb"] > 0
    assert (Tb[can] <= mid + 0.1 + 1e-6).all() and (Tb[ch] >= mid - 0.1 - 1e-6).all()


def test_served_forecast_cools_only_when_asked(est):
    before = est.cooling_control, est.deadband_control
    try:
        est.deadband_control = False  # the cooling alone (the dead band only warms)
        est.cooling_control = False
        plain = est.forecast().mean
        est.cooling_control = True
        cooled = est.forecast().mean
        known = est.forecast(est.forecast_inputs()).mean  # given inputs: no controller
    finally:
        est.cooling_control, est.deadband_control = before
    assert (cooled <= plain + 1e-9).all()
    np.testing.assert_array_equal(est.forecast(est.forecast_inputs()).mean, known)


def test_dead_band_throttles_cooling_boxes_down_to_their_floor(est):
    """With airflow floors a room below the cooling set point whose boxes run above their
    floors is warmed towards the set point by at most the cooling of the airflow above the
    floors; without a known floor, or without slack, the run is the cooling run."""
    m, nb, ins, u, v, forcing, stepper = _parts(est)
    rise = ins[:, -nb:]
    rooms = est._ctl[1]["rooms"]
    heat = np.full(len(u), -np.inf)
    T0 = est._controlled_run(stepper, u, forcing, v[:, 1], rise, heat)[1:, rooms]
    cool = np.full(len(u), float(np.percentile(T0, 60)))
    base = est._controlled_run(stepper, u, forcing, v[:, 1], rise, heat, cool)
    for floor in (np.full(nb, np.nan), u.max(axis=0) + 1.0):  # unknown; no slack anywhere
        np.testing.assert_array_equal(
            est._controlled_run(stepper, u, forcing, v[:, 1], rise, heat, cool, floor), base)
    floor = 0.5 * u.min(axis=0)
    xs = est._controlled_run(stepper, u, forcing, v[:, 1], rise, heat, cool, floor)
    T, Tb = xs[1:, rooms], base[1:, rooms]
    # throttling only warms (to the one re-step after a clipped r: a neighbour's r
    # is not solved again, which leaves it within a mK, _control_step)
    assert (xs >= base - 2e-3).all()
    assert (T <= cool[0] + 1e-6).all()           # never above the cooling set point
    assert (T > Tb + 0.05).sum() > 10            # and it warms rooms below it
    # the most a room is warmed in one step: the heat of its airflow above the floors
    w = -est._bxu * est._cool
    rb = est._ctl[1]["rb"]
    f = forcing + m.reheat_forcing(u, np.where(est._coil[None, :], 0.0, rise))
    for j in range(len(u)):
        free = stepper.step(xs[j], u[j], f[j], v[j, 1])
        slack = (np.maximum(u[j] - floor, 0.0) * w) @ rb
        rmax = slack * np.maximum(free[rooms] - v[j, 1], 0.0) / ((u[j] * w) @ rb)
        g = (u[j] * w) @ rb
        E = np.zeros((m.n, len(rooms)))
        E[rooms, np.arange(len(rooms))] = g * rmax
        cap = stepper.step(xs[j], u[j], f[j] + E.sum(axis=1), v[j, 1])
        assert (xs[j + 1, rooms] <= np.maximum(cap[rooms], cool[0]) + 1e-6).all()


def test_served_forecast_throttles_with_the_learned_floors(est):
    """The served forecast's dead band uses the floors the estimator learned from its own
    working-day rows; off, or with given inputs, nothing is throttled."""
    from zonecast.estimator import streaming

    assert est.deadband_control == streaming.DEADBAND_CONTROL
    floor = est.airflow_floor.floor()
    assert np.isfinite(floor[est._cool]).all()  # a working day seen: every box's floor
    before = est.deadband_control
    try:
        est.deadband_control = False
        plain = est.forecast().mean
        known = est.forecast(est.forecast_inputs()).mean
        est.deadband_control = True
        eased = est.forecast().mean
        np.testing.assert_array_equal(est.forecast(est.forecast_inputs()).mean, known)
    finally:
        est.deadband_control = before
    # it only warms, to the one re-step after a clipped r (_control_step: a neighbour's
    # r is not solved again; mK per clipped step, 3.8 mK after 24 steps here)
    assert (eased >= plain - 0.01).all()
    assert (eased - plain).max() > 0.05


def test_controller_set_points_are_those_in_effect_during_each_step():
    """The forecast's output band keeps the previous set point for HOLD_RECOVERY_H after a
    set-point step; the controller's set points are the schedule at each interval's start,
    so the interval that ends at the evening set-back (19:00) is still held at the occupied
    set points, and the one that ends at 07:00 is not yet."""
    from zonecast.estimator import streaming
    from zonecast.estimator.site import Thermostat

    th = Thermostat(heating_occupied=21, heating_unoccupied=17, cooling_occupied=24,
                    cooling_unoccupied=27, occupied_hours=(7, 19))
    tz = "America/Chicago"
    issued = pd.Timestamp("2015-01-12T00:00", tz=tz).tz_convert("UTC").value  # a Monday
    ends = pd.DatetimeIndex(issued + streaming.STEP.value
                            * np.arange(1, streaming.HORIZON + 1), tz="UTC").tz_convert(tz)
    at = {t.strftime("%H:%M"): h for h, t in enumerate(ends)}
    heat, cool = streaming.forecast_setpoints(th, issued, tz, steps=True)
    lo, hi = streaming.forecast_setpoints(th, issued, tz, recovery_h=0.25)
    # the interval 18:45-19:00 is occupied: the controller holds 21 / 24; the band opens
    assert (heat[at["19:00"]], cool[at["19:00"]]) == (21, 24)
    assert (lo[at["19:00"]], hi[at["19:00"]]) == (17, 27)
    assert (heat[at["19:15"]], cool[at["19:15"]]) == (17, 27)
    # 06:45-07:00 is not: both keep the unoccupied set points; from 07:00 on both step
    assert (heat[at["07:00"]], lo[at["07:00"]]) == (17, 17)
    assert (heat[at["07:15"]], lo[at["07:15"]], cool[at["07:15"]]) == (21, 21, 24)
    # the controller's set points are the schedule one interval earlier
    np.testing.assert_array_equal(heat, th.band(ends - streaming.STEP, tz)[0])
    # an experiment opens the controller's band on the intervals that start inside it
    a = pd.Timestamp("2015-01-12T18:00", tz=tz).value
    b = pd.Timestamp("2015-01-12T20:00", tz=tz).value
    heat_x, cool_x = streaming.forecast_setpoints(th, issued, tz, [(a, b)], steps=True)
    open_ = np.isneginf(heat_x)
    assert open_.sum() == 8 and np.isposinf(cool_x[open_]).all()
    assert open_[at["18:15"]] and not open_[at["18:00"]] and open_[at["20:00"]]
    assert not open_[at["20:15"]]


def test_served_forecast_reheats_through_the_step_that_ends_at_the_set_back(est):
    """With a heating set point that falls after step k, the controller holds every room
    with a running coil box at the higher set point through step k (the step's set point),
    while a controller given the output band (one step earlier) lets it fall at step k."""
    m, nb, ins, u, v, forcing, stepper = _parts(est)
    rise = ins[:, -nb:]
    rooms = est._coil_rooms
    free = stepper.run(est._x, u, forcing + m.reheat_forcing(u, np.zeros_like(rise)), v[:, 1])
    can = (u * est._coil) @ est._coil_room_box > 0
    high = float(np.percentile(free[1:, rooms], 80))
    # a step k where some running room would end below the high set point without reheat
    k = next(h for h in range(40, len(u)) if (can[h] & (free[h + 1, rooms] < high - 0.2)).any())
    step_sp = np.where(np.arange(len(u)) <= k, high, -np.inf)   # in effect during each step
    band_sp = np.where(np.arange(len(u)) < k, high, -np.inf)    # the band: one step earlier
    xs = est._controlled_run(stepper, u, forcing, v[:, 1], rise, step_sp)
    xb = est._controlled_run(stepper, u, forcing, v[:, 1], rise, band_sp)
    held = can[k]
    assert (xs[k + 1, rooms][held] >= high - 1e-6).all()
    assert (xb[k + 1, rooms][held] < high - 0.1).any()
    np.testing.assert_array_equal(xs[:k + 1], xb[:k + 1])  # same run up to that step
