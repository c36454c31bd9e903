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


@pytest.mark.parametrize("disable, set_, message", [
    (["daylight"], None, r"--disable daylight: unknown effect"),
    (["gains.X"], None, r"unknown model zone 'X'"),
    (None, ["shgc"], r"write EFFECT=VALUE"),
    (None, ["shgc=high"], r"the value must be a number"),
    (None, ["colour=red"], r"--set colour: unknown setting"),
    (None, ["shgc=1.5"], r"less than 1"),
    (None, ["supply_offset=9"], r"less than or equal to 5"),
])
def test_bad_switches_say_what_to_fix(disable, set_, message):
    with pytest.raises(ValueError, match=message):
        parse_switches(disable, set_, ZONES)
