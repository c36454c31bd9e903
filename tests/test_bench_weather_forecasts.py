"""benchmarks/bench_weather_forecasts.py's figures: what they measure on known rows, and
that the testbed's two irradiance-error forms land where docs/testbed.md says."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location(
        "bench_weather_forecasts", ROOT / "benchmarks" / "bench_weather_forecasts.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_statistics_of_known_rows(bench):
    """A forecast 100 W/m2 high on clear hours and right elsewhere; yesterday 200 W/m2 off:
    the RMSE, bias, skill and the clear/cloudy split say so; leads outside 12-36 h and
    night hours are left out."""
    clear = np.array([900.0, 900.0, 900.0, 900.0, 0.0, 900.0])
    t = np.array([850.0, 850.0, 200.0, 200.0, 0.0, 850.0])
    f = np.where(t / np.maximum(clear, 1) > 0.8, t + 100.0, t)
    d = pd.DataFrame({"lead": [12, 20, 24, 36, 20, 40], "f": f, "t": t, "dni_f": f,
                      "dni_t": t, "clear": clear, "yesterday": t + 200.0})
    s = bench.statistics(d)
    e = np.array([100.0, 100.0, 0.0, 0.0])
    assert s["RMSE"] == pytest.approx(np.sqrt(np.mean(e ** 2)))
    assert s["bias"] == pytest.approx(50.0)
    assert s["clear RMSE"] == pytest.approx(100.0) and s["clear bias"] == pytest.approx(100.0)
    assert s["cloudy-noon RMSE"] == pytest.approx(0.0)
    assert s["skill vs persistence"] == pytest.approx(1.0 - s["RMSE"] / 200.0)
    assert s["clear share"] == pytest.approx(0.5)
    assert s["rel. MAE"] == pytest.approx(50.0 / 525.0)


def test_the_cloud_form_is_small_on_clear_hours_and_beats_persistence(bench, vb):
    """On the three-week campaign: the ``cloud`` form's clear hours well under the
    ``factor`` form's, and its skill against persistence above it."""
    from zonecast.estimator.site import load_site
    from zonecast.estimator.telemetry import load_telemetry

    site = load_site(vb / "site.yaml")
    frame = load_telemetry(vb / "telemetry.csv", site).frame
    cloud = bench.statistics(bench.forecast_table(site, frame, "cloud"))
    factor = bench.statistics(bench.forecast_table(site, frame, "factor"))
    assert cloud["clear RMSE"] < 0.5 * factor["clear RMSE"]
    assert cloud["skill vs persistence"] > factor["skill vs persistence"]
    assert cloud["clear share"] == factor["clear share"]
