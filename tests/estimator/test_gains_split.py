"""Internal gains split as the IDF's People, Lights and equipment objects split their heat
(``ModelOptions.internal_gains="idf"``; NREL's 5-zone: lights return 20 % into PLENUM-1)."""

import dataclasses

import numpy as np
import pytest
from zonecast.estimator.idf import PERSON_SENSIBLE, InternalGain, building_from_epjson
from zonecast.estimator.model import BilinearModel
from zonecast.estimator.rc.network import ModelDefinitionError, ModelOptions, build_structure
from zonecast.estimator.rc.parameters import ParameterSet

ZONES = {"South": ["SPACE1-1"], "East": ["SPACE2-1"], "North": ["SPACE3-1"],
         "West": ["SPACE4-1"], "Core": ["SPACE5-1"]}
BOXES = {f"VAV{i}": f"SPACE{i}-1" for i in range(1, 6)}
#: the combined-film structure (with the star, the default since 2026-12-05, the windows'
#: radiant share goes to their glass nodes instead of the air)
BASE = {"infiltration": "none", "ground": "adiabatic", "shading": "none",
        "interior_radiation": "none"}


@pytest.fixture(scope="module")
def pair(five_zone):
    return (build_structure(five_zone, ZONES, BOXES, ModelOptions(**BASE)),
            build_structure(five_zone, ZONES, BOXES, ModelOptions(**BASE, internal_gains="idf")))


def test_gain_objects_are_read_with_their_design_heat_and_shares(five_zone):
    g = {k: v for k, v in five_zone.internal_gains.items() if v.zone == "SPACE1-1"}
    assert sorted(x.kind for x in g.values()) == ["ElectricEquipment", "Lights", "People"]
    people = g["SPACE1-1 People 1"]
    # 11 people x ActSchd's constant 117.24 W x the autocalculated sensible share
    assert people.power == pytest.approx(11 * 117.239997864 * PERSON_SENSIBLE)
    assert people.radiant == pytest.approx(0.3) and people.return_air == 0
    lights = g["SPACE1-1 Lights 1"]
    assert lights.power == pytest.approx(1584.0)
    assert lights.radiant == pytest.approx(0.59 + 0.2) and lights.return_air == pytest.approx(0.2)
    equip = g["SPACE1-1 ElecEq 1"]
    assert (equip.power, equip.radiant) == (pytest.approx(1056.0), pytest.approx(0.3))
    conv, rad, ret = five_zone.gain_split("SPACE1-1")
    total = people.power + lights.power + equip.power
    assert ret == pytest.approx(0.2 * 1584 / total)
    assert rad == pytest.approx((0.3 * people.power + 0.79 * 1584 + 0.3 * 1056) / total)
    assert conv + rad + ret == pytest.approx(1.0)
    assert five_zone.gain_split("PLENUM-1") == (1.0, 0.0, 0.0)  # no objects: all on the air


def test_split_keeps_the_heat_and_puts_each_share_where_the_idf_says(five_zone, pair):
    air, split = pair
    assert (split.B_ig >= 0).all()
    # the same heat enters: capacity-weighted columns are each zone's floor area
    np.testing.assert_allclose(split.capacity @ split.B_ig, air.capacity @ air.B_ig, rtol=1e-12)
    np.testing.assert_allclose(air.capacity @ air.B_ig,
                               [five_zone.zones[r[0]].floor_area for r in ZONES.values()])
    heat = split.B_ig * split.capacity[:, None]
    plenum = split.rooms.index("PLENUM-1")
    for zi, (zone, (room,)) in enumerate(ZONES.items()):
        conv, rad, ret = five_zone.gain_split(room)
        a = five_zone.zones[room].floor_area
        i = split.rooms.index(room)
        # on the room's air: the convective share and the windows' part of the radiant one
        glass = sum(w.area for w in five_zone.windows.values() if w.zone == room)
        assert heat[plenum, zi] == pytest.approx(ret * a)
        others = np.delete(heat[:, zi], [i, plenum])
        assert others.sum() == pytest.approx(rad * a * (1 - glass / _enclosure(five_zone, room)),
                                             rel=1e-9)
        assert heat[i, zi] == pytest.approx(a * (conv + rad * glass / _enclosure(five_zone, room)))


def _enclosure(building, room):
    """What a room's radiant share is spread over [m2]: the inside faces of its elements
    (both faces of internal mass, the mirrored face of another zone's surface facing it)
    and its windows."""
    faces = sum(s.area for s in building.surfaces.values() if s.zone == room)
    faces += sum(s.area for s in building.surfaces.values()
                 if s.boundary == "Zone" and str(s.boundary_object).lower() == room.lower())
    masses = sum(2 * m.area for m in building.internal_masses.values() if m.zone == room)
    glass = sum(w.area for w in building.windows.values() if w.zone == room)
    return faces + masses + glass


def test_split_model_is_metzler_stable_and_conserves_heat_at_steady_state(five_zone, pair):
    _, split = pair
    m = BilinearModel(split, ParameterSet(list(ZONES)))
    u = np.full(len(BOXES), 0.3)
    A = m.system_matrix(u)
    assert (A - np.diag(np.diag(A)) >= -1e-15).all()
    assert np.linalg.eigvals(A).real.max() < 0


def test_a_building_without_gain_objects_puts_everything_on_the_air(five_zone, pair):
    air, _ = pair
    bare = dataclasses.replace(five_zone, internal_gains={})
    st = build_structure(bare, ZONES, BOXES, ModelOptions(**BASE, internal_gains="idf"))
    np.testing.assert_array_equal(st.B_ig, air.B_ig)


def test_zone_lists_are_expanded_and_unknown_options_rejected():
    data = {
        "Zone": {"A": {}, "B": {}},
        "ZoneList": {"Offices": {"zones": [{"zone_name": "A"}, {"zone_name": "B"}]}},
        "ElectricEquipment": {"Eq": {"zone_or_zonelist_or_space_or_spacelist_name": "Offices",
                                     "schedule_name": "x",
                                     "design_level_calculation_method": "Watts/Area",
                                     "watts_per_floor_area": 10.0, "fraction_latent": 0.1,
                                     "fraction_radiant": 0.45, "fraction_lost": 0.0}},
    }
    b = building_from_epjson(data)
    eq = sorted(b.internal_gains)
    assert eq == ["Eq:A", "Eq:B"]
    assert all(isinstance(b.internal_gains[k], InternalGain) for k in eq)
    assert b.internal_gains["Eq:A"].radiant == pytest.approx(0.45 / 0.9)
    with pytest.raises(ModelDefinitionError, match="internal_gains must be 'air' or 'idf'"):
        ModelOptions(internal_gains="walls")
