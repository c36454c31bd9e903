"""Facade irradiance: physical sanity checks and the pvlib call itself."""

import numpy as np
import pandas as pd
import pvlib
import pytest
from zonecast.estimator import solar

LAT, LON, ELEV = 37.62, -122.40, 5.0
TZ = "America/Los_Angeles"
STEP = pd.Timedelta("15min")


def clear_day(day: str):
    """One day of 15-min interval-start stamps and clear-sky averages (midpoint)."""
    times = pd.date_range(day, periods=96, freq=STEP, tz=TZ)
    loc = pvlib.location.Location(LAT, LON, tz=TZ, altitude=ELEV)
    cs = loc.get_clearsky(times + STEP / 2, model="simplified_solis")
    return times, cs["ghi"].to_numpy(), cs["dni"].to_numpy(), cs["dhi"].to_numpy()


def solar_noon_row(times) -> int:
    transit = pvlib.solarposition.sun_rise_set_transit_spa(times[:1], LAT, LON)["transit"].iloc[0]
    mids = times + STEP / 2
    return int(np.argmin(np.abs((mids - transit).total_seconds())))


def test_output_shape_order_and_range():
    times, ghi, dni, dhi = clear_day("2024-06-21")
    out = solar.facade_irradiance(times, ghi, dni, dhi, LAT, LON, ELEV)
    assert out.shape == (96, 4)
    assert np.all(np.isfinite(out))
    assert np.all(out >= 0.0)
    # column order E, S, W, N equals the general function with those azimuths
    general = solar.surface_irradiance(
        times, ghi, dni, dhi, LAT, LON, ELEV, surfaces=[(90, 90), (90, 180), (90, 270), (90, 0)]
    )
    np.testing.assert_array_equal(out, general)


def test_south_facade_gets_more_beam_at_winter_noon_than_summer_noon():
    beams = {}
    for day in ("2024-12-21", "2024-06-21"):
        times, ghi, dni, dhi = clear_day(day)
        poa = solar.plane_of_array_irradiance(
            times, ghi, dni, dhi, LAT, LON, ELEV, surface_tilt=90, surface_azimuth=180
        )
        beams[day] = poa["poa_direct"].iloc[solar_noon_row(times)]
    assert beams["2024-12-21"] > 1.5 * beams["2024-06-21"] > 0


@pytest.mark.parametrize("day", ["2024-03-20", "2024-06-21", "2024-12-21"])
def test_east_peaks_in_the_morning_and_west_in_the_afternoon(day):
    times, ghi, dni, dhi = clear_day(day)
    out = solar.facade_irradiance(times, ghi, dni, dhi, LAT, LON, ELEV)
    noon = solar_noon_row(times)
    assert np.argmax(out[:, 0]) < noon < np.argmax(out[:, 2])


def test_night_is_exactly_zero_even_with_sensor_offsets():
    times = pd.date_range("2024-06-21 00:00", periods=12, freq=STEP, tz=TZ)  # local midnight
    ghi = np.full(12, -2.0)
    dhi = np.full(12, 1.5)  # a thermopile offset, not light
    dni = np.zeros(12)
    out = solar.facade_irradiance(times, ghi, dni, dhi, LAT, LON, ELEV)
    assert np.all(out == 0.0)


def test_negative_inputs_never_give_negative_output():
    times, ghi, dni, dhi = clear_day("2024-09-01")
    rng = np.random.default_rng(0)
    noisy = [a + rng.normal(0, 30, a.shape) for a in (ghi, dni, dhi)]
    out = solar.facade_irradiance(times, *noisy, LAT, LON, ELEV)
    assert np.all(out >= 0.0)


def test_nan_in_gives_nan_out_without_touching_other_rows():
    times, ghi, dni, dhi = clear_day("2024-06-21")
    ref = solar.facade_irradiance(times, ghi, dni, dhi, LAT, LON, ELEV)
    dni2 = dni.copy()
    dni2[[3, 50]] = np.nan  # one night row, one day row
    out = solar.facade_irradiance(times, ghi, dni2, dhi, LAT, LON, ELEV)
    assert np.isnan(out[[3, 50]]).all()
    keep = np.setdiff1d(np.arange(96), [3, 50])
    np.testing.assert_array_equal(out[keep], ref[keep])


@pytest.mark.parametrize("model", solar.SKY_MODELS)
@pytest.mark.parametrize("day", ["2024-03-20", "2024-06-21", "2024-12-21"])
def test_without_beam_facades_get_only_diffuse(model, day):
    # overcast sky: DNI = 0, so closure gives GHI = DHI
    times, ghi, _, _ = clear_day(day)
    dhi = 0.7 * ghi
    dni0 = np.zeros_like(ghi)
    # diffuse-only value: a vertical plane sees half the sky dome and half the ground
    iso = 0.5 * dhi + 0.5 * 0.2 * dhi
    for az in solar.FACADE_AZIMUTHS:
        poa = solar.plane_of_array_irradiance(
            times, dhi, dni0, dhi, LAT, LON, ELEV, surface_azimuth=az, sky_model=model
        )
        assert np.all(poa["poa_direct"] == 0.0)
        diffuse = poa["poa_sky_diffuse"] + poa["poa_ground_diffuse"]
        np.testing.assert_allclose(poa["poa_global"], diffuse, rtol=0, atol=1e-12)
        np.testing.assert_allclose(poa["poa_ground_diffuse"], 0.1 * dhi, rtol=1e-12)
        if model == "perez":
            # Perez keeps circumsolar/horizon brightening in its overcast bin (sky
            # brightness eps = 1), so it may exceed the isotropic value; bound it loosely.
            assert np.all(poa["poa_global"] <= 2.5 * iso + 1e-9)
        else:
            # no beam -> these models have no anisotropic part: exactly isotropic
            np.testing.assert_allclose(poa["poa_global"], iso, rtol=1e-9, atol=1e-9)


def test_matches_pvlib_get_total_irradiance_at_the_interval_midpoint():
    t = pd.Timestamp("2024-04-10 10:00", tz=TZ)
    ghi, dni, dhi = 700.0, 650.0, 150.0
    out = solar.facade_irradiance(pd.DatetimeIndex([t]), [ghi], [dni], [dhi], LAT, LON, ELEV,
                                  albedo=0.3)
    mid = pd.DatetimeIndex([t + STEP / 2])
    sp = pvlib.solarposition.get_solarposition(
        mid, LAT, LON, altitude=ELEV, pressure=pvlib.atmosphere.alt2pres(ELEV)
    )
    for col, az in enumerate(solar.FACADE_AZIMUTHS):
        ref = pvlib.irradiance.get_total_irradiance(
            90, az, sp["apparent_zenith"], sp["azimuth"], dni, ghi, dhi,
            dni_extra=pvlib.irradiance.get_extra_radiation(mid), albedo=0.3, model="perez",
        )
        assert out[0, col] == pytest.approx(float(ref["poa_global"].iloc[0]), rel=1e-12)
    # energy sanity: no vertical facade receives more than beam-normal plus all diffuse
    assert np.all(out <= dni + dhi + 0.3 * ghi)


def test_end_label_is_start_label_shifted_by_one_interval():
    times, ghi, dni, dhi = clear_day("2024-06-21")
    a = solar.facade_irradiance(times, ghi, dni, dhi, LAT, LON, ELEV, label="start")
    b = solar.facade_irradiance(times + STEP, ghi, dni, dhi, LAT, LON, ELEV, label="end")
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-9)


def test_midpoint_is_used_not_the_stamp():
    times, ghi, dni, dhi = clear_day("2024-06-21")
    poa = solar.plane_of_array_irradiance(times, ghi, dni, dhi, LAT, LON, ELEV)
    sp = pvlib.solarposition.get_solarposition(times + STEP / 2, LAT, LON, altitude=ELEV,
                                               pressure=pvlib.atmosphere.alt2pres(ELEV))
    np.testing.assert_allclose(poa["solar_zenith"], sp["apparent_zenith"], rtol=1e-12)


def test_errors_say_what_to_fix():
    times, ghi, dni, dhi = clear_day("2024-06-21")
    with pytest.raises(TypeError, match="tz-aware"):
        solar.facade_irradiance(times.tz_localize(None), ghi, dni, dhi, LAT, LON)
    with pytest.raises(ValueError, match="one value per time"):
        solar.facade_irradiance(times, ghi[:-1], dni, dhi, LAT, LON)
    with pytest.raises(ValueError, match="albedo must be in"):
        solar.facade_irradiance(times, ghi, dni, dhi, LAT, LON, albedo=1.5)
    with pytest.raises(ValueError, match="sky_model must be one of"):
        solar.facade_irradiance(times, ghi, dni, dhi, LAT, LON, sky_model="hay")
    with pytest.raises(ValueError, match="label must be"):
        solar.facade_irradiance(times, ghi, dni, dhi, LAT, LON, label="middle")
    with pytest.raises(ValueError, match="surfaces must list"):
        solar.surface_irradiance(times, ghi, dni, dhi, LAT, LON, surfaces=[])
    with pytest.raises(ValueError, match="latitude must be in"):
        solar.facade_irradiance(times, ghi, dni, dhi, 137.0, LON)


def test_zero_diffuse_near_the_horizon_gives_zero_not_nan():
    """Regression: at sunset the station reports 0 W/m2 while the sun is still just above
    the horizon at the interval midpoint; Perez's clearness index is 0/0 there."""
    import pandas as pd
    from zonecast.estimator.solar import facade_irradiance

    t = pd.DatetimeIndex([pd.Timestamp("2014-09-09 02:15:00+00:00")])  # zenith 89.3 deg
    out = facade_irradiance(t, [0.0], [0.0], [0.0], 37.62, -122.4, 2.0)
    assert np.all(out == 0.0)
