"""The blind-diagnosis scenarios of a family member (testbed/scenarios.py): built from the
member's own zones, deterministic in the scenario seeds, every effect kind with controls."""

import pytest
from zonecast.testbed.effects import parse_switches
from zonecast.testbed.family import draw_member
from zonecast.testbed.scenarios import KINDS, member_scenarios, pick_zone

ZONED = {"sensor_bias": "bias", "occupancy_gains": "gains", "thermal_mass": "mass",
         "interzone_air": "mixing"}


def _zone_of(s):
    key = s.switches[1].split("=", 1)[0]
    return key.split(".", 1)[1]


@pytest.mark.parametrize("zones", [["N", "E", "S", "W", "C"], ["Nord", "Sud", "Kern"]])
def test_scenarios_use_the_buildings_own_zones_and_every_effect(zones):
    scen = member_scenarios(zones, 0.4, 0.8)
    assert scen == member_scenarios(list(zones), 0.4, 0.8)  # deterministic
    names = [s.name for s in scen]
    assert len(set(names)) == len(names)
    assert sum(s.truth is None for s in scen) >= 3
    assert {s.truth for s in scen if s.truth} == set(KINDS)
    for s in scen:
        if s.truth in ZONED:
            z = _zone_of(s)
            assert z in zones and z in s.name
            assert s.switches[1].startswith(ZONED[s.truth] + ".")
            assert z == pick_zone(zones, s.seed, s.truth)
        # the testbed accepts every switch for these zones
        if s.switches and s.switches[0] == "--set":
            parse_switches(None, [s.switches[1]], zones)


def test_zone_draw_depends_on_seed_and_kind_only():
    zones = [f"Z{i}" for i in range(12)]
    draws = {(seed, k): pick_zone(zones, seed, k) for seed in range(6) for k in KINDS}
    assert draws == {(seed, k): pick_zone(list(zones), seed, k) for seed in range(6)
                     for k in KINDS}
    assert len(set(draws.values())) > 4  # not one fixed zone


def test_magnitudes_follow_the_building_and_mass_needs_furniture():
    scen = member_scenarios(["A", "B"], 0.5, 0.0)
    assert not [s for s in scen if s.truth == "thermal_mass"]  # nothing to scale
    shgc = sorted(float(s.switches[1].split("=")[1]) for s in scen if s.truth == "window_solar")
    assert shgc == [0.2, 0.85]  # 0.4 x and 1.75 x the building's 0.5, capped at 0.85
    with pytest.raises(ValueError):
        member_scenarios(["A"], 1.2, 0.5)


def test_a_drawn_family_member_gets_its_own_scenarios():
    m = draw_member(0, 3)
    zones = list(m.config.zones)
    scen = member_scenarios(zones, m.config.glazing.shgc, m.config.furniture_area_per_floor_area)
    assert all(_zone_of(s) in zones for s in scen if s.truth in ZONED)
