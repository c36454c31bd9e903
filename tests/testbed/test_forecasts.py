"""The testbed's synthetic weather forecasts: the weather plus seeded error growing with lead
time, each part's size settable (zero gives the weather itself)."""

import json

import numpy as np
import pandas as pd
from zonecast.estimator.site import load_site
from zonecast.estimator.telemetry import load_telemetry
from zonecast.testbed.forecasts import ERROR_MODEL, weather_forecasts, write_weather_forecasts


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
