"""A site description drafted from an EnergyPlus input (`zonecast site draft`): the zones
and terminals traced, the thermostat read from its schedules, and clear errors."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
from zonecast.estimator.site import load_site
from zonecast.estimator.site_draft import (
    DraftError,
    draft_site,
    draft_thermostat,
    local_timezone,
    zone_terminals,
)

NREL = Path(__file__).resolve().parents[2] / "configs" / "sites" / "nrel"


def _compact(*fields):
    return {"data": [{"field": f} for f in fields]}


def _building() -> dict:
    """Three zones in epJSON form: A and B on a ZoneList thermostat, A with a reheat VAV box
    and a baseboard, B with a no-reheat box, C with a thermostat and no air terminal."""
    eq = lambda *items: {"equipment": [
        {"zone_equipment_object_type": t, "zone_equipment_name": n} for t, n in items]}
    return {
        "Site:Location": {"Here": {"latitude": 47.5, "longitude": 8.5, "time_zone": 1.0,
                                   "elevation": 400.0}},
        "Zone": {"A": {}, "B": {}, "C": {}},
        "ZoneList": {"Offices": {"zones": [{"zone_name": "a"}, {"zone_name": "B"}]}},
        "ZoneControl:Thermostat": {
            "T1": {"zone_or_zonelist_name": "Offices",
                   "control_1_object_type": "ThermostatSetpoint:DualSetpoint",
                   "control_1_name": "Dual"},
            "T2": {"zone_or_zonelist_name": "C",
                   "control_1_object_type": "ThermostatSetpoint:SingleHeating",
                   "control_1_name": "Heat only"}},
        "ThermostatSetpoint:DualSetpoint": {"Dual": {
            "heating_setpoint_temperature_schedule_name": "HTG",
            "cooling_setpoint_temperature_schedule_name": "CLG"}},
        "ThermostatSetpoint:SingleHeating": {"Heat only": {
            "setpoint_temperature_schedule_name": "HTG"}},
        "Schedule:Compact": {
            "HTG": _compact("Through: 12/31", "For: Weekdays", "Until: 07:00", 15.0,
                            "Until: 18:00", 21.0, "Until: 24:00", 15.0,
                            "For: AllOtherDays", "Until: 24:00", 15.0),
            "CLG": _compact("Through: 12/31", "For: Weekdays", "Until: 07:00", 28.0,
                            "Until: 18:00", 24.0, "Until: 24:00", 28.0,
                            "For: AllOtherDays", "Until: 24:00", 28.0)},
        "ZoneHVAC:EquipmentConnections": {
            "A c": {"zone_name": "A", "zone_conditioning_equipment_list_name": "A eq"},
            "B c": {"zone_name": "B", "zone_conditioning_equipment_list_name": "B eq"},
            "C c": {"zone_name": "C", "zone_conditioning_equipment_list_name": "C eq"}},
        "ZoneHVAC:EquipmentList": {
            "A eq": eq(("ZoneHVAC:AirDistributionUnit", "A adu"),
                       ("ZoneHVAC:Baseboard:Convective:Electric", "A bb")),
            "B eq": eq(("ZoneHVAC:AirDistributionUnit", "B adu")),
            "C eq": eq(("ZoneHVAC:Baseboard:Convective:Electric", "C bb"))},
        "ZoneHVAC:AirDistributionUnit": {
            "A adu": {"air_terminal_object_type": "AirTerminal:SingleDuct:VAV:Reheat",
                      "air_terminal_name": "A box"},
            "B adu": {"air_terminal_object_type": "AIRTERMINAL:SINGLEDUCT:VAV:NOREHEAT",
                      "air_terminal_name": "b BOX"}},
        "AirTerminal:SingleDuct:VAV:Reheat": {"A box": {"reheat_coil_name": "A coil"}},
        "AirTerminal:SingleDuct:VAV:NoReheat": {"B box": {}},
        "AirLoopHVAC": {"AHU": {}},
    }


def test_terminals_traced_through_zone_lists_and_equipment_lists():
    links, skipped = zone_terminals(_building())
    assert [(t.zone, t.kind, t.name, t.reheat_coil) for t in links] == [
        ("A", "AirTerminal:SingleDuct:VAV:Reheat", "A box", "A coil"),
        ("B", "AirTerminal:SingleDuct:VAV:NoReheat", "B box", None)]
    assert any("A bb" in s and "not an air terminal" in s for s in skipped)
    assert any(s.startswith("C: thermostat but no air terminal") for s in skipped)


def test_draft_is_a_valid_site_with_the_convention_and_the_thermostat(tmp_path):
    draft = draft_site(tmp_path / "b.idf", out=tmp_path / "site.yaml", timezone="Europe/Zurich",
                       data=_building())
    s = draft.site
    assert s.zones == {"A": ["A"], "B": ["B"]}
    assert s.boxes["A box"].discharge_temperature.point == "A_box_DAT"
    assert s.boxes["B box"].discharge_temperature is None        # no reheat coil
    assert s.boxes["B box"].airflow.point == "B_box_flow"
    assert s.points.zone_temperature["A"][0].point == "T_A"
    assert (s.location.latitude, s.location.longitude, s.location.elevation) == (47.5, 8.5, 400.0)
    t = s.thermostat
    assert (t.heating_occupied, t.heating_unoccupied) == (21.0, 15.0)
    assert (t.cooling_occupied, t.cooling_unoccupied) == (24.0, 28.0)
    assert t.occupied_hours == (7.0, 18.0) and t.working_days == [0, 1, 2, 3, 4]
    # the file written reads back as the same site, its idf relative to the site file
    path = tmp_path / "site.yaml"
    path.write_text(draft.to_yaml_text())
    back = load_site(path)
    assert back.idf == Path("b.idf") and back.thermostat == t and back.boxes == s.boxes
    assert "# note: C: thermostat but no air terminal" in path.read_text()


def test_draft_names_the_one_weather_file_beside_the_input(tmp_path):
    """An EPW beside the input becomes the site's weather_file (relative to the site file);
    with two, the notes ask which one; with none, no field."""
    (tmp_path / "sub").mkdir()
    out = tmp_path / "sub" / "site.yaml"
    none = draft_site(tmp_path / "b.idf", out=out, timezone="Europe/Zurich", data=_building())
    assert none.site.weather_file is None
    (tmp_path / "zurich.epw").write_text("LOCATION,Zurich\n")
    one = draft_site(tmp_path / "b.idf", out=out, timezone="Europe/Zurich", data=_building())
    assert one.site.weather_file == Path("../zurich.epw")
    assert one.site.weather_path.resolve() == (tmp_path / "zurich.epw").resolve()
    out.write_text(one.to_yaml_text())
    assert load_site(out).weather_path.resolve() == (tmp_path / "zurich.epw").resolve()
    (tmp_path / "other.epw").write_text("LOCATION,Other\n")
    two = draft_site(tmp_path / "b.idf", out=out, timezone="Europe/Zurich", data=_building())
    assert two.site.weather_file is None
    assert any("2 EPW files beside the input" in n for n in two.notes)


def test_thermostat_notes_what_it_approximates():
    data = _building()
    data["Schedule:Compact"]["HTG"] = _compact(
        "Through: 12/31", "For: Weekdays", "Until: 06:00", 15.0, "Until: 07:00", 18.0,
        "Until: 18:00", 21.0, "Until: 24:00", 15.0, "For: Saturday", "Until: 08:00", 15.0,
        "Until: 13:00", 21.0, "Until: 24:00", 15.0, "For: AllOtherDays", "Until: 24:00", 15.0)
    t, notes = draft_thermostat(data, ["A", "B"])
    assert t["working_days"] == [0, 1, 2, 3, 4, 5] and t["occupied_hours"] == [7.0, 18.0]
    assert any("3 set point levels" in n for n in notes)
    assert any("occupied hours differ" in n for n in notes)
    data["Schedule:Year"] = {"HTG2": {}}
    data["ThermostatSetpoint:DualSetpoint"]["Dual"]["heating_setpoint_temperature_schedule_name"] \
        = "HTG2"
    t, notes = draft_thermostat(data, ["A", "B"])
    assert t is None and any("HTG2 is not a Schedule:Compact" in n for n in notes)
    data["ThermostatSetpoint:DualSetpoint"]["Dual"]["heating_setpoint_temperature_schedule_name"] \
        = "K"
    data["Schedule:Constant"] = {"K": {"hourly_value": 20.0}}
    t, notes = draft_thermostat(data, ["A", "B"])
    assert t["heating_occupied"] == t["heating_unoccupied"] == 20.0
    assert t["occupied_hours"] == [7.0, 18.0]        # the cooling schedule's setback


def test_clear_errors_for_what_the_file_lacks(tmp_path):
    data = _building()
    no_loc = copy.deepcopy(data)
    del no_loc["Site:Location"]
    with pytest.raises(DraftError, match="no Site:Location"):
        draft_site(tmp_path / "b.idf", data=no_loc, timezone="UTC")
    no_box = copy.deepcopy(data)
    del no_box["ZoneHVAC:AirDistributionUnit"]
    with pytest.raises(DraftError, match="no thermostat-controlled zone is served by an air"):
        draft_site(tmp_path / "b.idf", data=no_box)
    dst = copy.deepcopy(data)
    dst["RunPeriodControl:DaylightSavingTime"] = {"x": {}}
    with pytest.raises(DraftError, match="daylight saving time at UTC\\+1: give the site's IANA"):
        draft_site(tmp_path / "b.idf", data=dst)
    assert local_timezone({}, 1.0) == "Etc/GMT-1"
    assert local_timezone({"RunPeriodControl:DaylightSavingTime": {"x": {}}}, -7.0) \
        == "America/Denver"
    with pytest.raises(DraftError, match="UTC offset 5.5 h"):
        local_timezone({}, 5.5)


@pytest.mark.energyplus
def test_nrel_five_zone_draft_matches_what_energyplus_ran(tmp_path):
    """The draft of NREL's 5ZoneAirCooled: its five conditioned zones and reheat boxes, the
    return plenum left out, and the thermostat EnergyPlus reported when it ran the file
    (docs/testbed.md: 22.2 / 16.7 and 23.9 / 29.4 degC, 06-20 h on weekdays)."""
    draft = draft_site(NREL / "5ZoneAirCooled.idf", out=tmp_path / "site.yaml")
    s = draft.site
    assert list(s.zones) == [f"SPACE{i}-1" for i in range(1, 6)]
    assert "PLENUM-1" not in s.zones
    assert all(b.discharge_temperature is not None for b in s.boxes.values())
    assert s.timezone == "Etc/GMT+6"      # no daylight saving object: standard time all year
    t = s.thermostat
    assert (t.heating_occupied, t.heating_unoccupied) == (22.2, 16.7)
    assert (t.cooling_occupied, t.cooling_unoccupied) == (23.9, 29.4)
    assert t.occupied_hours == (6.0, 20.0) and t.working_days == [0, 1, 2, 3, 4]


def test_thermostat_schedules_that_are_read_wrongly_or_not_at_all_say_so():
    """A warm-up boost is not the occupied level; a 99 degC cooling sentinel reads as
    cooling off; a -60 degC heating sentinel, or a schedule without a Sunday rule, leaves the
    thermostat out with a note instead of failing the draft."""
    data = _building()
    data["Schedule:Compact"]["HTG"] = _compact(
        "Through: 12/31", "For: Weekdays", "Until: 05:00", 15.0, "Until: 07:00", 23.0,
        "Until: 18:00", 21.0, "Until: 24:00", 15.0, "For: AllOtherDays", "Until: 24:00", 15.0)
    t, notes = draft_thermostat(data, ["A", "B"])
    assert (t["heating_occupied"], t["heating_unoccupied"]) == (21.0, 15.0)
    assert t["occupied_hours"] == [7.0, 18.0] and any("3 set point levels" in n for n in notes)
    data["Schedule:Compact"]["CLG"] = _compact(
        "Through: 12/31", "For: Weekdays", "Until: 07:00", 99.0, "Until: 18:00", 24.0,
        "Until: 24:00", 99.0, "For: AllOtherDays", "Until: 24:00", 99.0)
    t, notes = draft_thermostat(data, ["A", "B"])
    assert "cooling_occupied" not in t and t["heating_occupied"] == 21.0
    assert any(n.startswith("cooling set points left out") for n in notes)
    data["Schedule:Compact"]["HTG"] = _compact(
        "Through: 12/31", "For: Weekdays", "Until: 07:00", -60.0, "Until: 18:00", 21.0,
        "Until: 24:00", -60.0, "For: AllOtherDays", "Until: 24:00", -60.0)
    t, notes = draft_thermostat(data, ["A", "B"])
    assert t is None and any("out of range" in n for n in notes)
    data["Schedule:Compact"]["HTG"] = _compact(
        "Through: 12/31", "For: Weekdays", "Until: 24:00", 21.0,
        "For: Saturday", "Until: 24:00", 15.0)
    t, notes = draft_thermostat(data, ["A", "B"])
    assert t is None and any("no values for a sunday" in n for n in notes)


def test_point_names_stay_distinct_when_names_differ_only_in_spaces(tmp_path):
    data = _building()
    data["Zone"] = {"A 1": {}, "A_1": {}}
    data["ZoneList"]["Offices"]["zones"] = [{"zone_name": "A 1"}, {"zone_name": "A_1"}]
    data["ZoneHVAC:EquipmentConnections"]["A c"]["zone_name"] = "A 1"
    data["ZoneHVAC:EquipmentConnections"]["B c"]["zone_name"] = "A_1"
    s = draft_site(tmp_path / "b.idf", data=data, timezone="UTC").site
    assert [p[0].point for p in s.points.zone_temperature.values()] == ["T_A_1", "T_A_1_2"]
