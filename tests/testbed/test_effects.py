import pytest
from zonecast.testbed.effects import parse_switches

ZONES = ["NW", "NE", "W", "E", "S", "C"]


def test_switches_parse():
    e = parse_switches(["reheat", "gains.S", "sensor_noise"],
                       ["infiltration=2", "shgc=0.25", "bias.NW=0.5"], ZONES)
    assert not e.reheat and e.gains == {"S": 0.0} and e.infiltration == 2.0
    assert e.shgc == 0.25 and e.sensor_bias == {"NW": 0.5}
    assert e.sensor_noise == 0.0 and e.sensor_resolution == 0.0
    assert parse_switches(["gains"], None, ZONES).gains == {z: 0.0 for z in ZONES}
    assert parse_switches(None, ["supply_offset=-1.5"], ZONES).supply_offset == -1.5
    assert parse_switches(["supply_offset"], None, ZONES).supply_offset == 0.0
    e = parse_switches(None, ["mass.S=3"], ZONES)
    assert e.mass == {"S": 3.0} and e.mass_scale("S") == 3.0 and e.mass_scale("NW") == 1.0


@pytest.mark.parametrize("disable, set_, message", [
    (["daylight"], None, r"--disable daylight: unknown effect"),
    (["gains.X"], None, r"unknown model zone 'X'"),
    (None, ["shgc"], r"write EFFECT=VALUE"),
    (None, ["shgc=high"], r"the value must be a number"),
    (None, ["colour=red"], r"--set colour: unknown setting"),
    (None, ["shgc=1.5"], r"less than 1"),
    (None, ["supply_offset=9"], r"less than or equal to 5"),
    (None, ["mass.S=0"], r"furniture area scale must be > 0"),
    (None, ["mixing.S=-1"], r"mixing flow must be >= 0"),
    (None, ["sky=clear"], r"--set sky=clear: choose 'weather'"),
])
def test_bad_switches_say_what_to_fix(disable, set_, message):
    with pytest.raises(ValueError, match=message):
        parse_switches(disable, set_, ZONES)


def test_mass_switch_scales_the_furniture_of_its_zone_only():
    import datetime as dt
    import re

    from zonecast.testbed.config import load_config
    from zonecast.testbed.effects import Effects
    from zonecast.testbed.idfgen import build_idf

    cfg = load_config()
    period = [(dt.date(2015, 4, 13), dt.date(2015, 4, 19))]

    def furniture(effects):
        text = build_idf(cfg, period, effects, ["htg", "clg"])
        found = re.findall(r"InternalMass,\s*(\S+) Furniture,[^;]*?,\s*([\d.eE+-]+);", text)
        return {room: float(a) for room, a in found}

    base = furniture(Effects())
    more = furniture(Effects(mass={"S": 3.0}))
    assert base and set(base) == set(more)
    for room, area in base.items():
        assert more[room] == pytest.approx(area * (3.0 if cfg.rooms[room].zone == "S" else 1.0))


def test_mixing_switch_joins_its_zone_to_neighbours_of_other_zones_once():
    import datetime as dt
    import re

    from zonecast.testbed.config import load_config
    from zonecast.testbed.effects import Effects
    from zonecast.testbed.geometry import plan_walls
    from zonecast.testbed.idfgen import build_idf

    cfg = load_config()
    period = [(dt.date(2015, 4, 13), dt.date(2015, 4, 19))]
    assert "ZoneCrossMixing" not in build_idf(cfg, period, Effects(), ["htg", "clg"])
    text = build_idf(cfg, period, Effects(mixing={"S": 0.05}), ["htg", "clg"])
    found = re.findall(r"ZoneCrossMixing,\s*[^,]+,\s*([^,]+),\s*AlwaysOn,\s*Flow/Zone,"
                       r"\s*([\d.]+),[^;]*?,\s*([A-Za-z0-9_]+),\s*0(?:\.0)?;", text)
    pairs = {tuple(sorted((a, b))) for a, _, b in found}
    assert len(pairs) == len(found) > 0 and all(float(q) == 0.05 for _, q, _ in found)
    walls = plan_walls({n: r.rect for n, r in cfg.rooms.items()})
    expected = {tuple(sorted((r, w.neighbour))) for r, room in cfg.rooms.items()
                if room.zone == "S" for w in walls[r].walls
                if w.neighbour is not None and cfg.rooms[w.neighbour].zone != "S"}
    assert pairs == expected


def test_sky_switch_puts_the_sky_at_the_dry_bulb_in_the_idf():
    import datetime as dt

    from zonecast.testbed.config import load_config
    from zonecast.testbed.effects import Effects
    from zonecast.testbed.idfgen import build_idf

    cfg = load_config("office6")
    week = [(dt.date(2015, 4, 12), dt.date(2015, 4, 19))]
    e = parse_switches(None, ["sky=dry_bulb"], ZONES)
    assert e.sky == "dry_bulb" and parse_switches(None, None, ZONES).sky == "weather"
    idf = build_idf(cfg, week, e, [])
    assert ("WeatherProperty:SkyTemperature,\n    ,\n    DifferenceScheduleDryBulbValue,\n"
            "    Sky Below Dry Bulb,\n    No;") in idf
    assert "Schedule:Constant,\n    Sky Below Dry Bulb,\n    Any Number,\n    0;" in idf
    assert "WeatherProperty:SkyTemperature" not in build_idf(cfg, week, Effects(), [])


def test_inside_convection_switch_writes_energyplus_constant_films_only_when_asked():
    import datetime as dt

    from zonecast.testbed.config import load_config
    from zonecast.testbed.effects import Effects
    from zonecast.testbed.idfgen import build_idf

    cfg = load_config("office6")
    week = [(dt.date(2015, 4, 12), dt.date(2015, 4, 19))]
    e = parse_switches(None, ["inside_convection=simple"], ZONES)
    assert e.inside_convection == "simple"
    assert parse_switches(None, None, ZONES).inside_convection == "tarp"
    assert "SurfaceConvectionAlgorithm:Inside,\n    Simple;" in build_idf(cfg, week, e, [])
    assert "SurfaceConvectionAlgorithm:Inside" not in build_idf(cfg, week, Effects(), [])
    with pytest.raises(ValueError, match="inside_convection=adaptive: choose 'tarp'"):
        parse_switches(None, ["inside_convection=adaptive"], ZONES)
