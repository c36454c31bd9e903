"""EnergyPlus Schedule:Compact values (estimator/schedules.py)."""

from __future__ import annotations

import datetime as dt
import json

import numpy as np
import pandas as pd
import pytest
from zonecast.estimator.schedules import CompactSchedule, ScheduleError


def _fields(*items):
    return {"data": [{"field": f} for f in items]}


#: DOE reference small office's infiltration: a quarter while the fans run
QUARTER = _fields("Through: 12/31", "For: Weekdays SummerDesignDay", "Until: 06:00", 1.0,
                  "Until: 22:00", 0.25, "Until: 24:00", 1.0,
                  "For: Saturday WinterDesignDay", "Until: 06:00", 1.0, "Until: 18:00", 0.25,
                  "Until: 24:00", 1.0, "For: Sunday Holidays AllOtherDays", "Until: 24:00", 1.0)
#: NREL 5ZoneAirCooled's infiltration: November to March only
SEASONAL = _fields("Through: 3/31", "For: AllDays", "Until: 24:00", 1.0,
                   "Through: 10/31", "For: AllDays", "Until: 24:00", 0.0,
                   "Through: 12/31", "For: AllDays", "Until: 24:00", 1.0)


def _at(text, tz="America/Chicago", periods=1, freq="15min"):
    return pd.date_range(text, periods=periods, freq=freq, tz=tz)


def test_daily_values_by_day_type_and_holiday():
    s = CompactSchedule.from_epjson("Q", QUARTER)
    # Friday 2015-06-26: 1 until 06:00, 0.25 from the 06:00 interval to 22:00
    fri = s.values(_at("2015-06-26 05:30", periods=4), "America/Chicago")
    np.testing.assert_array_equal(fri, [1.0, 1.0, 0.25, 0.25])
    fri_eve = s.values(_at("2015-06-26 21:45", periods=2), "America/Chicago")
    np.testing.assert_array_equal(fri_eve, [0.25, 1.0])
    # Saturday: the fans stop at 18:00
    sat = s.values(_at("2015-06-27 17:45", periods=2), "America/Chicago")
    np.testing.assert_array_equal(sat, [0.25, 1.0])
    # Sunday, and a weekday that is a holiday: AllOtherDays / Holidays
    assert s.values(_at("2015-06-28 12:00"), "America/Chicago")[0] == 1.0
    hol = s.values(_at("2015-07-03 12:00"), "America/Chicago", holidays=[dt.date(2015, 7, 3)])
    assert hol[0] == 1.0
    assert s.values(_at("2015-07-03 12:00"), "America/Chicago")[0] == 0.25


def test_local_time_of_utc_times_and_through_periods():
    s = CompactSchedule.from_epjson("S", SEASONAL)
    # 31 March 23:45 local is in the first period, 1 April 00:00 in the second
    t = pd.DatetimeIndex(["2015-04-01 04:45", "2015-04-01 05:00"], tz="UTC")   # UTC-5 (CDT)
    np.testing.assert_array_equal(s.values(t, "America/Chicago"), [1.0, 0.0])
    np.testing.assert_array_equal(s.values(_at("2014-10-31 23:45", periods=2), "America/Chicago"),
                                  [0.0, 1.0])
    assert s.values(_at("2014-12-31 23:45"), "America/Chicago")[0] == 1.0
    with pytest.raises(ScheduleError, match="time-zone aware"):
        s.values(pd.date_range("2015-01-01", periods=2, freq="15min"), "America/Chicago")


def test_idf_style_values_and_json_round_trip():
    """An 'Until: HH:MM,value' field (IDF text) reads like the epJSON pair; the JSON form
    evaluates the same."""
    a = CompactSchedule.from_epjson("A", _fields("Through: 12/31", "For: AllDays",
                                                 "Until: 08:00,0.5", "Until: 24:00,2"))
    b = CompactSchedule.from_epjson("A", _fields("Through: 12/31", "For: AllDays",
                                                 "Until: 08:00", 0.5, "Until: 24:00", 2))
    assert a == b
    c = CompactSchedule.from_dict(json.loads(json.dumps(a.to_dict())))
    t = _at("2015-01-05", tz="UTC", periods=96)
    np.testing.assert_array_equal(c.values(t, "UTC"), a.values(t, "UTC"))
    assert a.values(t, "UTC").tolist() == [0.5] * 32 + [2.0] * 64


@pytest.mark.parametrize("fields, match", [
    (_fields("For: AllDays", "Until: 24:00", 1), "before any 'Through:'"),
    (_fields("Through: 12/31", "Until: 24:00", 1), "before any 'For:'"),
    (_fields("Through: 6/30", "For: AllDays", "Until: 24:00", 1), "must end on 12/31"),
    (_fields("Through: 12/31", "For: AllDays", "Until: 24:00", "x"), "not a number"),
    (_fields("Through: 12/31", "For: AllDays", "Until: noon", 1), "Until: HH:MM"),
    (_fields("Through: 12/31", "For: AllDays", "Until: 24:00"), "has no value"),
])
def test_unreadable_schedules_say_what_is_wrong(fields, match):
    with pytest.raises(ScheduleError, match=match):
        CompactSchedule.from_epjson("Bad", fields)


def test_a_day_without_a_rule_is_an_error_naming_the_fix():
    s = CompactSchedule.from_epjson("W", _fields("Through: 12/31", "For: Weekdays",
                                                 "Until: 24:00", 1))
    with pytest.raises(ScheduleError, match="AllOtherDays"):
        s.values(_at("2015-06-27 12:00"), "America/Chicago")   # a Saturday


def test_local_day_and_minute_match_pandas_across_daylight_saving():
    from zonecast.estimator.schedules import local_day_minute

    rng = np.random.default_rng(4)
    start = pd.Timestamp("2014-01-01", tz="UTC").value
    ns = np.sort(start + rng.integers(0, 2 * 365 * 96, 3000) * 900 * 10**9)
    ns = np.r_[ns, pd.Timestamp("2015-03-08 07:45", tz="UTC").value,   # 01:45 CST
               pd.Timestamp("2015-03-08 08:00", tz="UTC").value]       # 03:00 CDT
    t = pd.DatetimeIndex(ns, tz="UTC")
    for tz in ("America/Chicago", "Etc/GMT+6", "Asia/Kolkata"):
        days, minutes = local_day_minute(t, tz)
        local = t.tz_convert(tz)
        want_days = (local.tz_localize(None).normalize() - pd.Timestamp("1970-01-01")).days
        np.testing.assert_array_equal(days, want_days.to_numpy())
        np.testing.assert_array_equal(minutes, (local.hour * 60 + local.minute).to_numpy())
    _, m = local_day_minute(t[-2:], "America/Chicago")
    assert m.tolist() == [105, 180]
