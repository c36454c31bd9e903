import numpy as np
import pytest
from zonecast.estimator.dataset import DISTURBANCES, model_data, zone_weights
from zonecast.estimator.site import load_site
from zonecast.estimator.telemetry import load_telemetry

from tests.conftest import telemetry_frame, write_site


@pytest.fixture
def tel(tmp_path, site_dict, telemetry_csv):
    site_dict["points"]["zone_temperature"]["A"] = [{"point": "TA1", "room": "Room_A1"},
                                                    {"point": "TA2", "unit": "degF", "room": "Room_A2"}]
    site_dict["experiments"] = [{"start": "2015-04-18T08:30:00-07:00",
                                 "end": "2015-04-18T09:00:00-07:00"}]
    site = load_site(write_site(tmp_path, site_dict))
    return load_telemetry(telemetry_csv(telemetry_frame(8)), site)


def test_arrays_follow_the_paper_order(tel):
    d = model_data(tel)
    assert DISTURBANCES == ("Ta", "Ts", "solE", "solS", "solW", "solN", "solH")
    assert d.u.shape == (8, 2) and d.v.shape == (8, 7) and d.y.shape == (8, 2)
    np.testing.assert_allclose(d.v[:, 0], tel.frame["OAT"])
    np.testing.assert_allclose(d.v[:, 1], tel.frame["SAT"])
    assert np.all(d.v[:, 2:] >= 0) and np.all(np.isfinite(d.v))
    # morning (08:00-10:00 local): the east facade gets more than the west one
    assert np.all(d.v[:, 2] > d.v[:, 4])
    # the roofs' column: a horizontal plane gets more than the north facade
    assert np.all(d.v[:, 6] > d.v[:, 5])
    assert d.excitation.tolist() == [False, False, True, True, False, False, False, False]


def test_volume_weights_match_the_model_output(tel):
    w = zone_weights(tel.site, {"room_a1": 30.0, "ROOM_A2": 90.0})
    np.testing.assert_allclose(w["A"], [30.0, 90.0])
    d = model_data(tel, {"Room_A1": 30.0, "Room_A2": 90.0, "Room_B": 10.0})
    f = tel.frame
    np.testing.assert_allclose(d.y[:, 0], (30 * f["TA1"] + 90 * f["TA2"]) / 120)


def test_missing_weather_stays_missing(tmp_path, site_dict, telemetry_csv):
    site = load_site(write_site(tmp_path, site_dict))
    df = telemetry_frame(8).astype({"DNI": object})
    df.loc[3, "DNI"] = ""
    d = model_data(load_telemetry(telemetry_csv(df), site))
    assert np.isnan(d.v[3, 2:]).all() and np.isfinite(np.delete(d.v, 3, axis=0)).all()
    assert d.missing_inputs().tolist() == [False, False, False, True, False, False, False, False]
