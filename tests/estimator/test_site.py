import datetime as dt

import pytest
from zonecast.estimator.site import SiteError, load_site

from tests.conftest import write_site


def test_valid_site_loads_with_units_and_shorthands(tmp_path, site_dict):
    site = load_site(write_site(tmp_path, site_dict))
    assert site.step == dt.timedelta(minutes=15)
    assert site.point_units() == {"TA1": "degC", "TA2": "degF", "TB": "degC", "SAT": "degC",
                                  "OAT": "degC", "GHI": "W/m2", "DNI": "W/m2", "DHI": "W/m2",
                                  "A1 flow": "L/s", "B flow": "kg/s"}
    assert site.idf_path == tmp_path.resolve() / "building.idf"


def test_round_trip_through_yaml(tmp_path, site_dict):
    site = load_site(write_site(tmp_path, site_dict))
    site.to_yaml(tmp_path / "again.yaml")
    again = load_site(tmp_path / "again.yaml")
    assert again.model_dump(exclude={"base_dir"}) == site.model_dump(exclude={"base_dir"})


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["boxes"]["VAV-B"]["airflow"].__class__ is str and
     d["boxes"]["VAV-B"].update(airflow={"point": "B flow", "unit": "gallons"}),
     r"unit 'gallons' is not a airflow unit"),
    (lambda d: d["points"].update(outdoor_air_temperature={"point": "OAT", "unit": "kg/s"}),
     r"outdoor_air_temperature.*not a temperature unit"),
    (lambda d: d["zones"].update(B=["Room_B", "Room_A1"]), r"Room_A1 is in model zones A and B"),
    (lambda d: d["boxes"]["VAV-B"].update(room="Attic"), r"boxes\[VAV-B\]\.room 'Attic'"),
    (lambda d: d["points"]["zone_temperature"].pop("B"), r"must name exactly the model zones"),
    (lambda d: d.update(timezone="Pacific/Berkeley"), r"not an IANA time zone"),
    (lambda d: d.update(step="7min"), r"must divide a day"),
    (lambda d: d.update(step="quarter"), r"write e.g. '15min'"),
    (lambda d: d["points"].update(outdoor_air_temperature="SAT"), r"more than one role"),
    (lambda d: d.pop("idf"), r"idf: Field required"),
    (lambda d: d["points"]["zone_temperature"].update(
        B=[{"point": "TB", "room": "Room_A1"}]), r"sensor TB sits in room Room_A1"),
    (lambda d: d.update(thermostat={"heating_occupied": 21, "heating_unoccupied": 17,
                                    "occupied_hours": [19, 7]}),
     r"occupied_hours.*need 0 <= start < end <= 24"),
    (lambda d: d.update(thermostat={"heating_occupied": 21, "heating_unoccupied": 17,
                                    "working_days": [1, 7]}), r"working_days \[7\]"),
])
def test_invalid_sites_name_the_field(tmp_path, site_dict, mutate, message):
    mutate(site_dict)
    with pytest.raises(SiteError, match=message):
        load_site(write_site(tmp_path, site_dict))


def test_site_error_is_a_value_error(tmp_path):
    (tmp_path / "site.yaml").write_text("- just a list\n")
    with pytest.raises(ValueError, match="must hold a mapping"):
        load_site(tmp_path / "site.yaml")
    with pytest.raises(SiteError, match="not found"):
        load_site(tmp_path / "missing.yaml")


def test_thermostat_schedule_follows_local_time_and_experiments(tmp_path, site_dict):
    import numpy as np
    import pandas as pd
    site_dict["thermostat"] = {"heating_occupied": 21, "heating_unoccupied": 17,
                               "occupied_hours": [7, 19], "experiment_heating": 10}
    site = load_site(write_site(tmp_path, site_dict))
    site.to_yaml(tmp_path / "again.yaml")
    assert load_site(tmp_path / "again.yaml").thermostat == site.thermostat
    tz = site.timezone
    # Friday 06:45, 07:00, 18:45, 19:00 local, then Saturday 10:00 local
    local = pd.DatetimeIndex(["2015-01-16 06:45", "2015-01-16 07:00", "2015-01-16 18:45",
                              "2015-01-16 19:00", "2015-01-17 10:00"]).tz_localize(tz)
    sp = site.thermostat.heating_setpoint(local.tz_convert("UTC"), tz)
    assert sp.tolist() == [17, 21, 21, 17, 17]
    exp = np.array([False, True, False, False, False])
    assert site.thermostat.heating_setpoint(local, tz, exp).tolist() == [17, 10, 21, 17, 17]


def test_weather_file_relative_to_the_site(tmp_path, site_dict):
    (tmp_path / "w").mkdir()
    (tmp_path / "w" / "x.epw").write_text("LOCATION,X\n")
    site_dict["weather_file"] = "w/x.epw"
    site = load_site(write_site(tmp_path, site_dict))
    assert site.weather_path == tmp_path.resolve() / "w" / "x.epw"
    # a missing file is an error only where it is read (F/C-factor faces: read_building),
    # not when a served model's site is loaded
    site_dict["weather_file"] = "w/gone.epw"
    assert load_site(write_site(tmp_path, site_dict)).weather_path.name == "gone.epw"

