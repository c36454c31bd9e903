import numpy as np
import pandas as pd
import pytest
from zonecast.estimator.site import load_site
from zonecast.estimator.telemetry import TelemetryError, load_telemetry
from zonecast.estimator.units import STANDARD_AIR_DENSITY

from tests.conftest import telemetry_frame, write_site


@pytest.fixture
def site(tmp_path, site_dict):
    return load_site(write_site(tmp_path, site_dict))


def test_loads_and_converts_to_si(site, telemetry_csv):
    tel = load_telemetry(telemetry_csv(), site)
    f = tel.frame
    assert str(f.index.tz) == "UTC" and f.index[0] == pd.Timestamp("2015-04-18T15:00:00Z")
    np.testing.assert_allclose(f["TA2"], (70.0 + 0.18 * np.arange(8) - 32) * 5 / 9)
    np.testing.assert_allclose(f["A1 flow"], (100.0 + np.arange(8)) * 1e-3 * STANDARD_AIR_DENSITY)
    assert tel.segments == [(0, 8)]
    assert tel.airflow().shape == (8, 2)
    # zone A is the mean of its two sensors (21.0 degC and 70 degF = 21.11 degC at k=0)
    np.testing.assert_allclose(tel.zone_temperature()[0], [(21.0 + (70 - 32) * 5 / 9) / 2, 22.0])


def test_missing_cells_stay_nan_and_zone_mean_uses_what_reported(site, telemetry_csv):
    df = telemetry_frame()
    df = df.astype({"TA1": object, "TA2": object})
    df.loc[2, "TA1"] = ""
    df.loc[3, ["TA1", "TA2"]] = ["NaN", ""]
    tel = load_telemetry(telemetry_csv(df), site)
    assert np.isnan(tel.frame["TA1"].iloc[2])
    y = tel.zone_temperature()
    assert y[2, 0] == pytest.approx(tel.frame["TA2"].iloc[2])
    assert np.isnan(y[3, 0]) and np.isfinite(y[3, 1])


def test_gaps_make_segments_not_errors(site, telemetry_csv):
    df = pd.concat([telemetry_frame(4), telemetry_frame(4, "2015-04-25T08:00:00-07:00")])
    tel = load_telemetry(telemetry_csv(df), site)
    assert tel.segments == [(0, 4), (4, 8)]


def test_unmapped_columns_are_reported_not_dropped_silently(site, telemetry_csv):
    df = telemetry_frame()
    df["Chiller kW"] = 1.0
    assert load_telemetry(telemetry_csv(df), site).unused_columns == ["Chiller kW"]


def _drop(df, col):
    return df.drop(columns=[col])


@pytest.mark.parametrize("edit, message", [
    (lambda df: _drop(df, "TB"), r"missing columns for points the site maps: TB"),
    (lambda df: _drop(df, "time"), r"no 'time' column"),
    (lambda df: df.iloc[[0, 2, 1, 3]], r"times go backwards at line 4"),
    (lambda df: df.iloc[[0, 1, 1, 2]], r"duplicated time .* at lines 3 and 4"),
    (lambda df: df.assign(time=[t.replace(":00-07", ":07-07") if i == 5 else t
                                for i, t in enumerate(df.time)]),
     r"at line 7 is not on the 0:15:00 grid"),
    (lambda df: df.assign(OAT=["x" if i == 3 else v for i, v in enumerate(df.OAT)]),
     r"column 'OAT' has non-numeric values at lines 5 \(first: 'x'\)"),
    (lambda df: df.assign(time=[t[:19] for t in df.time]), r"need a UTC offset.*lines 2, 3"),
    (lambda df: df.assign(time=["yesterday"] + list(df.time[1:])), r"not ISO-8601 times at lines 2"),
])
def test_bad_files_are_rejected_with_row_and_column(site, telemetry_csv, edit, message):
    with pytest.raises(TelemetryError, match=message):
        load_telemetry(telemetry_csv(edit(telemetry_frame())), site)


def test_missing_file(site, tmp_path):
    with pytest.raises(TelemetryError, match="not found"):
        load_telemetry(tmp_path / "nope.csv", site)


def test_discharge_air_point_gives_the_rise_over_supply(tmp_path, site_dict, telemetry_csv):
    """A box's optional discharge-air point (any temperature unit) -> T_discharge - T_supply
    [K]; boxes without one have zero rise; a shut box's missing reading is no heat, an open
    box's missing reading stays missing."""
    from zonecast.estimator.dataset import model_data
    site_dict["boxes"]["VAV-B"]["discharge_temperature"] = {"point": "B DAT", "unit": "degF"}
    site = load_site(write_site(tmp_path, site_dict))
    assert site.point_units()["B DAT"] == "degF"
    df = telemetry_frame()
    df["B DAT"] = 95.0  # 35 degC: 22 K above the 13 degC supply
    df = df.astype({"B DAT": object})
    df.loc[2, "B DAT"] = ""
    df.loc[3, "B DAT"] = ""
    df.loc[3, "B flow"] = 0.0
    tel = load_telemetry(telemetry_csv(df), site)
    rise = tel.discharge_rise()
    assert rise.shape == (8, 2) and np.all(rise[:, 0] == 0.0)
    np.testing.assert_allclose(rise[[0, 1, 4], 1], 22.0)
    assert np.isnan(rise[2, 1]) and np.isnan(rise[3, 1])
    data = model_data(tel)
    assert np.isnan(data.reheat[2, 1]) and data.reheat[3, 1] == 0.0
    assert data.missing_inputs()[2] and not data.missing_inputs()[3]


def test_discharge_air_point_is_a_temperature(tmp_path, site_dict):
    from zonecast.estimator.site import SiteError
    site_dict["boxes"]["VAV-B"]["discharge_temperature"] = {"point": "B DAT", "unit": "kg/s"}
    with pytest.raises(SiteError, match="discharge_temperature"):
        load_site(write_site(tmp_path, site_dict))
    site_dict["boxes"]["VAV-B"]["discharge_temperature"] = "SAT"
    with pytest.raises(SiteError, match="more than one role"):
        load_site(write_site(tmp_path, site_dict))


def test_power_meters_sum_per_zone_in_watts(tmp_path, site_dict, telemetry_csv):
    """points.power: a zone's meters (W or kW, short form W) are summed; a meter's short
    gap inside the data is filled linearly, a longer one or one at the end is NaN, and so
    is a zone without meters; ModelData carries them; no meter -> None."""
    from zonecast.estimator.dataset import model_data
    assert load_telemetry(telemetry_csv(), load_site(write_site(tmp_path, site_dict))).power() \
        is None
    site_dict["points"]["power"] = {"A": ["PA lights", {"point": "PA plugs", "unit": "kW"}]}
    site = load_site(write_site(tmp_path, site_dict))
    assert site.point_units()["PA lights"] == "W" and site.point_units()["PA plugs"] == "kW"
    df = telemetry_frame()
    df["PA lights"] = 800.0
    df["PA plugs"] = 1.0 + 0.2 * np.arange(len(df))
    df = df.astype({"PA plugs": object})
    df.loc[2, "PA plugs"] = ""  # one row: filled
    df.loc[7, "PA plugs"] = ""  # at the end: not filled
    tel = load_telemetry(telemetry_csv(df), site)
    p = tel.power()
    assert p.shape == (8, 2) and np.isnan(p[:, 1]).all()
    np.testing.assert_allclose(p[:7, 0], 800.0 + 1000.0 + 200.0 * np.arange(7))
    assert np.isnan(p[7, 0])
    assert np.isnan(tel.power(max_fill=0)[2, 0])
    data = model_data(tel)
    np.testing.assert_array_equal(data.power, p)
    np.testing.assert_array_equal(data.rows(slice(1, 4)).power, p[1:4])


def test_power_meters_name_model_zones_and_measure_power(tmp_path, site_dict):
    from zonecast.estimator.site import SiteError
    site_dict["points"]["power"] = {"Z": "PZ"}
    with pytest.raises(SiteError, match=r"points.power names \['Z'\], which are not model zones"):
        load_site(write_site(tmp_path, site_dict))
    site_dict["points"]["power"] = {"A": {"point": "PA", "unit": "degC"}}
    with pytest.raises(SiteError, match="not a power unit"):
        load_site(write_site(tmp_path, site_dict))
    site_dict["points"]["power"] = {"A": "OAT"}
    with pytest.raises(SiteError, match="more than one role"):
        load_site(write_site(tmp_path, site_dict))
    site_dict["points"]["power"] = {"A": []}
    with pytest.raises(SiteError, match=r"power\[A\] lists no meter"):
        load_site(write_site(tmp_path, site_dict))


def test_fill_short_gaps_fills_inner_runs_up_to_the_limit_within_segments():
    from zonecast.estimator.telemetry import fill_short_gaps
    nan = np.nan
    x = np.array([0.0, nan, 2.0, nan, nan, nan, 6.0, nan, 8.0, 9.0, nan, 11.0, nan])
    # segments [0, 9) and [9, 13): row 8 -> 9 is a jump in time, never bridged
    got = fill_short_gaps(x, [(0, 9), (9, 13)], 2)
    np.testing.assert_array_equal(got, [0, 1, 2, nan, nan, nan, 6, 7, 8, 9, 10, 11, nan])
    np.testing.assert_array_equal(fill_short_gaps(x, [(0, 13)], 3)[3:6], [3, 4, 5])
    y = np.array([1.0, nan, nan, 4.0])
    np.testing.assert_array_equal(fill_short_gaps(y, [(0, 2), (2, 4)], 5), y)  # ends of both
    np.testing.assert_array_equal(fill_short_gaps(x, [(0, 13)], 0), x)
    assert np.isnan(x[1])  # the input is not changed
