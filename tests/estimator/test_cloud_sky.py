"""The sky under a measured cloud cover (``ModelOptions.sky="cloud"``, docs/model.md "Sky"):
the emissivity, the site's point and its units, the scheduled sky inputs offline and
online, and the forecast's held cover."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from zonecast.estimator.dataset import scheduled_rise
from zonecast.estimator.solar import (
    clear_sky_temperature,
    cloud_of_sky_temperature,
    cloudy_sky_temperature,
)
from zonecast.estimator.units import check_unit, to_si

SKY = {"s": {"flow": 1.0, "supply": "sky", "sky": "cloud"}}


def test_overcast_sky_is_at_the_air_and_a_clear_one_is_swinbanks():
    ta = np.array([-10.0, 5.0, 20.0, 35.0])
    np.testing.assert_allclose(cloudy_sky_temperature(ta, 1.0), ta, atol=1e-9)
    np.testing.assert_allclose(cloudy_sky_temperature(ta, 0.0), clear_sky_temperature(ta))
    # no reading (NaN) is a clear sky; covers outside [0, 1] are clipped
    np.testing.assert_allclose(cloudy_sky_temperature(ta, np.nan), clear_sky_temperature(ta))
    np.testing.assert_allclose(cloudy_sky_temperature(ta, 1.7), ta, atol=1e-9)
    # half cover at 10 degC: eps = 0.5 + 0.5 * 9.365e-6 * 283.15^2 (Crawford and Duchon)
    eps = 0.5 + 0.5 * 9.365e-6 * 283.15 ** 2
    assert float(cloudy_sky_temperature(10.0, 0.5)) == pytest.approx(
        eps ** 0.25 * 283.15 - 273.15, abs=1e-9)
    assert np.isnan(cloudy_sky_temperature(np.nan, 0.5))


@settings(max_examples=60, deadline=None)
@given(st.floats(-30.0, 40.0), st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_more_cloud_a_warmer_sky_never_above_the_air_and_the_inverse_recovers_it(ta, a, b):
    lo, hi = sorted((a, b))
    t_lo, t_hi = cloudy_sky_temperature(ta, lo), cloudy_sky_temperature(ta, hi)
    assert t_lo <= t_hi + 1e-12
    assert t_hi <= ta + 1e-9
    assert float(cloud_of_sky_temperature(ta, t_lo)) == pytest.approx(lo, abs=1e-9)


def test_cloud_cover_units_convert_to_a_fraction_and_others_are_refused():
    np.testing.assert_allclose(to_si([0.0, 50.0, 100.0], "%"), [0.0, 0.5, 1.0])
    np.testing.assert_allclose(to_si([4.0, 8.0], "okta"), [0.5, 1.0])
    np.testing.assert_allclose(to_si([3.0], "tenths"), [0.3])
    assert check_unit("1", "cloud_cover") == "1"
    with pytest.raises(ValueError, match=r"not a cloud_cover unit; use one of \['1', '%'"):
        check_unit("W/m2", "cloud_cover")


def test_scheduled_sky_rise_follows_the_rows_cover():
    ta, ts = np.array([10.0, 10.0, 10.0]), np.array([13.0, 13.0, 13.0])
    cloud = np.array([0.0, 1.0, np.nan])
    rise = scheduled_rise(SKY, None, None, ta, ts, cloud)[:, 0]
    np.testing.assert_allclose(rise + ts, [clear_sky_temperature(10.0), 10.0,
                                           clear_sky_temperature(10.0)], atol=1e-9)
    # without a cover column the cloudy option is the clear sky
    np.testing.assert_allclose(scheduled_rise(SKY, None, None, ta, ts)[:, 0],
                               clear_sky_temperature(ta) - ts)


def test_site_maps_a_cloud_cover_point(site_dict):
    from zonecast.estimator.site import Site

    SITE_DICT = site_dict
    site = Site.model_validate({**SITE_DICT, "points": {**SITE_DICT["points"],
                                                        "cloud_cover": {"point": "CLOUD",
                                                                        "unit": "okta"}}})
    assert site.point_units()["CLOUD"] == "okta"
    short = Site.model_validate({**SITE_DICT, "points": {**SITE_DICT["points"],
                                                         "cloud_cover": "CLOUD"}})
    assert short.point_units()["CLOUD"] == "1"
    with pytest.raises(ValueError, match="not a cloud_cover unit"):
        Site.model_validate({**SITE_DICT, "points": {**SITE_DICT["points"], "cloud_cover": {
            "point": "CLOUD", "unit": "degC"}}})
    assert "CLOUD" not in Site.model_validate(SITE_DICT).point_units()


def test_cloud_option_without_the_sites_point_says_what_to_add(vb):
    from zonecast.estimator.pipeline import Pipeline
    from zonecast.estimator.rc.network import ModelDefinitionError, ModelOptions
    from zonecast.estimator.site import load_site

    site = load_site(vb / "site.yaml")
    bare = site.model_copy(update={"points": site.points.model_copy(
        update={"cloud_cover": None})})
    with pytest.raises(ModelDefinitionError, match="add the point .* or choose sky"):
        Pipeline.from_site(bare, options=ModelOptions(sky="cloud")).structure()


def test_online_rows_equal_offline_and_the_forecast_holds_the_current_cover(tmp_path, vb,
                                                                          telemetry):
    """A model with sky="cloud" on the virtual building (its site maps the weather
    file's opaque sky cover in %): the runner's row conversion, in one batch and one row
    at a time, gives the offline sky inputs, which follow the cover; the served forecast's
    sky inputs keep the current row's cover over the horizon."""
    import pandas as pd
    from zonecast.estimator.artifact import load_model_file, write_model_file
    from zonecast.estimator.pipeline import Pipeline
    from zonecast.estimator.rc.network import ModelOptions
    from zonecast.estimator.streaming import OnlineEstimator, RowConverter, model_rows
    from zonecast.estimator.telemetry import load_telemetry

    pipe = Pipeline.from_site(vb / "site.yaml", options=ModelOptions(sky="cloud"))
    st_ = pipe.structure()
    sky = [j for j, spec in enumerate(st_.scheduled.values()) if spec["supply"] == "sky"]
    assert sky and all(spec["sky"] == "cloud" for spec in st_.scheduled.values()
                       if spec["supply"] == "sky")
    path = write_model_file(tmp_path / "model.json", vb / "site.yaml", structure=st_,
                            room_volume=pipe.room_volume, parameters={"gamma_IW": 9.0})
    bundle = load_model_file(path)
    tel = load_telemetry(vb / "telemetry.csv", pipe.site)
    cover = tel.weather().cloud.to_numpy()
    assert 0.0 <= np.nanmin(cover) < 0.2 and 0.8 < np.nanmax(cover) <= 1.0  # % -> fraction
    data = model_rows(bundle, tel.frame)
    nb = len(bundle.site.boxes)
    k = len(st_.scheduled)
    cols = [data.reheat.shape[1] - k + j for j in sky]
    t_sky = data.reheat[:, cols[0]] + data.v[:, 1]
    np.testing.assert_allclose(t_sky, cloudy_sky_temperature(data.v[:, 0], cover), atol=1e-9)
    conv = RowConverter(bundle)
    ns = tel.frame.index.as_unit("ns").asi8
    raw = pd.read_csv(vb / "telemetry.csv")[conv.points].to_numpy()  # wire units (%)
    batch = conv.convert_rows(ns, raw)[3]
    np.testing.assert_allclose(batch, data.reheat, rtol=0, atol=1e-9, equal_nan=True)
    some = range(0, len(ns), 97)
    rows = np.vstack([conv.convert_rows(ns[i:i + 1], raw[i:i + 1])[3] for i in some])
    np.testing.assert_allclose(rows, data.reheat[list(some)], rtol=0, atol=1e-9,
                               equal_nan=True)
    # the forecast's sky inputs: the current cover held, at the forecast's outdoor air
    est = OnlineEstimator(bundle)
    u, v, y, rh = conv.convert_rows(ns[:200], raw[:200])
    for i in range(200):
        est.advance(pd.Timestamp(ns[i], tz="UTC"), u[i], v[i], y[i], rh[i])
    ins = est.forecast_inputs()
    n_in = ins.shape[1]
    nbm = bundle.model.n_boxes  # the site's boxes and the scheduled inputs
    assert nbm == nb + k
    t_sky_f = ins[:, n_in - k + sky[0]] + ins[:, nbm + 1]
    held = cover[199] if np.isfinite(cover[199]) else 0.0
    np.testing.assert_allclose(t_sky_f, cloudy_sky_temperature(ins[:, nbm], held), atol=1e-6)
