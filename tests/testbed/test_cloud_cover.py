"""The virtual building's cloud-cover column from its weather file (docs/data.md, CLOUD)."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pandas as pd
import pytest
from zonecast.testbed.run import EnergyPlusError, epw_cloud_cover


def _epw(path, cover):
    """An EPW of 8760 rows whose opaque sky cover (field 24) is ``cover(hour_of_year)``."""
    lines = ["LOCATION,Test,,,,0,40.0,-105.0,-7.0,1800"] + ["X"] * 7
    t = dt.datetime(2015, 1, 1)
    for k in range(8760):
        end = t + dt.timedelta(hours=k + 1)
        m, d, h = end.month, end.day, end.hour
        if h == 0:  # EPW's hour 24 of the day before
            prev = end - dt.timedelta(hours=1)
            m, d, h = prev.month, prev.day, 24
        f = ["2015", str(m), str(d), str(h), "60"] + ["0"] * 30
        f[23] = str(cover(k + 1))
        lines.append(",".join(f))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_cover_is_interpolated_at_the_middle_of_each_row_in_percent(tmp_path):
    epw = _epw(tmp_path / "w.epw", lambda k: k % 11 if k % 11 <= 10 else 0)
    std = dt.timezone(dt.timedelta(hours=-7))
    # rows of 2015-03-10 from 00:00 standard time, 15 min apart (UTC index)
    index = pd.date_range("2015-03-10T07:00Z", periods=8, freq="15min")
    got = epw_cloud_cover(epw, index, std)
    start = (dt.date(2015, 3, 10) - dt.date(2015, 1, 1)).days * 24
    tau = start + (np.arange(8) * 15 + 7.5) / 60.0  # hours since 1 Jan, interval middles
    knots = np.arange(start - 2, start + 5)
    expect = 10.0 * np.interp(tau, knots, knots % 11)
    np.testing.assert_allclose(got, expect)
    assert got.min() >= 0.0 and got.max() <= 100.0


def test_february_29_takes_the_28th_and_missing_hours_are_skipped(tmp_path):
    epw = _epw(tmp_path / "w.epw", lambda k: 99 if k % 5 == 0 else 4)
    std = dt.timezone(dt.timedelta(hours=-7))
    leap = pd.date_range("2016-02-29T19:00Z", periods=4, freq="15min")
    feb28 = pd.date_range("2015-02-28T19:00Z", periods=4, freq="15min")
    np.testing.assert_allclose(epw_cloud_cover(epw, leap, std),
                               epw_cloud_cover(epw, feb28, std))
    np.testing.assert_allclose(epw_cloud_cover(epw, leap, std), 40.0)  # 99 = missing


def test_a_file_without_rows_is_refused(tmp_path):
    (tmp_path / "empty.epw").write_text("LOCATION,x\n")
    with pytest.raises(EnergyPlusError, match="no EPW data rows"):
        epw_cloud_cover(tmp_path / "empty.epw", pd.date_range("2015-01-01", periods=2,
                                                               freq="15min", tz="UTC"),
                        dt.UTC)
