"""The testbed's synthetic weather forecasts: the weather plus seeded error growing with lead
time, each part's size settable (zero gives the weather itself)."""

import json

import numpy as np
import pandas as pd
import pytest
from zonecast.estimator.site import load_site
from zonecast.estimator.telemetry import load_telemetry
from zonecast.testbed.forecasts import (
    ERROR_MODEL,
    error_model,
    weather_forecasts,
    write_weather_forecasts,
)


def _frame(vb):
    site = load_site(vb / "site.yaml")
    return site, load_telemetry(vb / "telemetry.csv", site).frame


def _arrays(bodies, key):
    n = min(len(b[key]) for b in bodies)
    return np.array([b[key][:n] for b in bodies], dtype=float)


def test_error_parts_switch_off_alone_and_grow_with_lead(vb):
    site, frame = _frame(vb)
    full = weather_forecasts(site, frame, seed=4)
    none = weather_forecasts(site, frame, seed=4, temperature_sigma=(0, 0),
                             irradiance_sigma=(0, 0))
    t_only = weather_forecasts(site, frame, seed=4, irradiance_sigma=(0, 0))
    i_only = weather_forecasts(site, frame, seed=4, temperature_sigma=(0, 0))
    assert [b["issued"] for b in full] == [b["issued"] for b in none] and len(full) > 4
    # without error a forecast is the weather: the outdoor temperature at each hour
    oat = frame[site.points.outdoor_air_temperature.point]
    b = none[0]
    times = [pd.Timestamp(t) for t in b["times"]]
    assert all(t in oat.index for t in times) and len(times) >= 25
    np.testing.assert_allclose(b["temperature"], [oat.loc[t] for t in times], atol=1e-3)
    # each part switched off alone keeps the other part's draws
    np.testing.assert_array_equal(_arrays(t_only, "ghi"), _arrays(none, "ghi"))
    np.testing.assert_array_equal(_arrays(t_only, "temperature"), _arrays(full, "temperature"))
    np.testing.assert_array_equal(_arrays(i_only, "temperature"), _arrays(none, "temperature"))
    np.testing.assert_array_equal(_arrays(i_only, "ghi"), _arrays(full, "ghi"))
    # temperature error: about 0.3 K at issue, larger a day ahead
    err = _arrays(full, "temperature") - _arrays(none, "temperature")
    assert np.std(err[:, 0]) < 0.8 < np.std(err[:, 24])


def test_written_file_records_the_error_model_used(vb, tmp_path):
    path = write_weather_forecasts(vb, seed=1, out=tmp_path / "wf.json",
                                   irradiance_sigma=(0.0, 0.0))
    doc = json.loads(path.read_text())
    assert doc["error_model"]["irradiance_sigma"] == [0.0, 0.0]
    assert doc["error_model"]["temperature_sigma_k"] == ERROR_MODEL["temperature_sigma_k"]
    default = json.loads(write_weather_forecasts(vb, seed=1, out=tmp_path / "d.json").read_text())
    assert default["error_model"] == ERROR_MODEL and len(default["forecasts"]) == \
        len(doc["forecasts"])


def _clear_sky(site, bodies):
    import pvlib

    loc = pvlib.location.Location(site.location.latitude, site.location.longitude,
                                  altitude=site.location.elevation)
    n = min(len(b["times"]) for b in bodies)
    return np.array([loc.get_clearsky(pd.DatetimeIndex(b["times"][:n]))["ghi"].to_numpy()
                     for b in bodies])


def test_cloud_error_is_small_on_clear_hours_and_large_on_cloudy_ones(vb):
    """The default ``cloud`` form: zero sigmas give the weather itself; the error in the
    clear-sky index is smaller on clear hours than on cloudy ones (Mathiesen & Kleissl
    2011's picture), a forecast is never clearer than a clear sky, and DNI moves with GHI
    (Erbs' split)."""
    site, frame = _frame(vb)
    assert ERROR_MODEL["irradiance_error"] == "cloud"
    full = weather_forecasts(site, frame, seed=4)
    none = weather_forecasts(site, frame, seed=4, temperature_sigma=(0, 0),
                             irradiance_sigma=(0, 0), clear_sigma=(0, 0))
    truth = weather_forecasts(site, frame, seed=4, temperature_sigma=(0, 0),
                              irradiance_sigma=(0, 0), irradiance_error="factor")
    for key in ("ghi", "dni", "dhi", "temperature"):
        np.testing.assert_array_equal(_arrays(none, key), _arrays(truth, key))
    # the temperature error is the factor form's, draw for draw
    factor = weather_forecasts(site, frame, seed=4, irradiance_error="factor")
    np.testing.assert_array_equal(_arrays(full, "temperature"), _arrays(factor, "temperature"))
    cs = _clear_sky(site, full)
    g_f, g_t = _arrays(full, "ghi"), _arrays(none, "ghi")
    day = cs > 200.0
    k_t, k_f = g_t[day] / cs[day], g_f[day] / cs[day]
    late = np.broadcast_to(np.arange(cs.shape[1]) >= 12, cs.shape)[day]
    clear, cloudy = late & (k_t >= 0.9), late & (k_t <= 0.4)
    assert clear.sum() > 30 and cloudy.sum() > 10, (clear.sum(), cloudy.sum())
    sd_clear, sd_cloudy = np.std(k_f[clear] - k_t[clear]), np.std(k_f[cloudy] - k_t[cloudy])
    assert sd_clear < 0.1 < sd_cloudy, (sd_clear, sd_cloudy)
    assert (g_f <= np.maximum(np.minimum(cs, 1300.0), g_t) + 0.006).all()  # rounded to 0.01
    d_ghi = g_f - g_t
    d_dni = _arrays(full, "dni") - _arrays(none, "dni")
    assert (d_ghi * d_dni >= -1e-9).all()
    assert (np.abs(d_dni[np.abs(d_ghi) > 50]) > 0).mean() > 0.9


def test_the_factor_form_is_kept_and_a_wrong_form_says_which_exist(vb):
    site, frame = _frame(vb)
    with pytest.raises(ValueError, match="irradiance_error must be one of .*'factor'"):
        weather_forecasts(site, frame, irradiance_error="clouds")
    model = error_model(irradiance_error="factor")
    assert model["irradiance_error"] == "factor" and "clear_sigma" not in model
    assert error_model() == ERROR_MODEL and ERROR_MODEL["clear_sigma"] == [0.03, 0.07]
    factor = weather_forecasts(site, frame, seed=4, irradiance_error="factor")
    none = weather_forecasts(site, frame, seed=4, irradiance_sigma=(0, 0),
                             irradiance_error="factor")
    ratio = _arrays(factor, "ghi") / np.where(_arrays(none, "ghi") > 0, _arrays(none, "ghi"), 1)
    dni = _arrays(factor, "dni") / np.where(_arrays(none, "dni") > 0, _arrays(none, "dni"), 1)
    sunny = (_arrays(none, "ghi") > 100) & (_arrays(none, "dni") > 100) & \
        (_arrays(factor, "ghi") < 1300) & (_arrays(factor, "dni") < 1100)
    np.testing.assert_allclose(ratio[sunny], dni[sunny], rtol=1e-3)  # one factor on both
