"""Rectangular ("simple geometry") and typed detailed surfaces read as EnergyPlus reads them.

The reference is EnergyPlus itself: it turns every rectangular surface into vertices when it
reads its input and writes them to ``eplusout.eio`` (``Output:Surfaces:List,
DetailsWithVertices``). Two zones, one rotated and moved, exercise every simple base surface
type, windows and doors on simple and detailed walls, a tilted wall, a zone boundary (the far
side EnergyPlus creates) and the typed detailed objects.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from zonecast.estimator.idf import BuildingDescriptionError, building_from_epjson, read_building
from zonecast.estimator.rectangles import in_plane_axes, rectangle, subsurface

from tests.estimator.idf_text import BOX, HEADER

EIO_IDF = HEADER + """
Building, Probe, 30, City, 0.04, 0.4, FullExterior, 25, 6;
GlobalGeometryRules, UpperLeftCorner, Counterclockwise, Relative, Relative, Relative;
WindowMaterial:SimpleGlazingSystem, Glass, 2.0, 0.4, 0.6;
Construction, Win, Glass;
Zone, A, 15, 2, 3, 1;
Zone, B, 0, 0, 0, 0, 1, 1, 3, 90;
Wall:Exterior, AS, Wall, A, , 180, 90, 0, 0, 3, 6, 3;
Wall:Exterior, AE, Wall, A, , 90, 90, 6, 0, 3, 5, 3;
Wall:Underground, AN, Wall, A, , 0, 90, 6, 5, 3, 6, 3;
Wall:Interzone, AW, Wall, A, , B, 270, 90, 0, 5, 3, 5, 3;
Roof, AR, Wall, A, , 180, 0, 0, 0, 6, 6, 5;
Floor:GroundContact, AF, Wall, A, , 0, 180, 0, 0, 3, 6, 5;
Window, AS_W, Win, AS, , 1, 1, 0.9, 4, 1.5;
Door, AE_D, Wall, AE, 1, 1, 0, 1, 2;
GlazedDoor, AE_G, Win, AE, , 1, 2.5, 0, 1, 2.2;
Wall:Detailed, BD, Wall, B, , Outdoors, , SunExposed, WindExposed, , 4,
    0, 0, 3, 0, 0, 0, 6, 0, 0, 6, 0, 3;
Window, BD_W, Win, BD, , 1, 2, 0.5, 3, 2;
Wall:Exterior, BT, Wall, B, , 200, 60, 1, 2, 3, 4, 2;
Window, BT_W, Win, BT, , 1, 0.5, 0.5, 2, 1;
RoofCeiling:Detailed, BR, Wall, B, , Outdoors, , SunExposed, WindExposed, , 4,
    0, 5, 3, 0, 0, 3, 6, 0, 3, 6, 5, 3;
Floor:Adiabatic, BF, Wall, B, , 90, 180, 0, 0, 0, 5, 6;
Ceiling:Adiabatic, BC, Wall, B, , 30, 0, 0, 0, 3, 4, 5;
Wall:Adiabatic, BA, Wall, B, , 300, 90, 0, 0, 0, 2, 3;
Shading:Site, Bushes, 180, 90, 1, -4, 0, 20, 1;
Shading:Building, Hedge, 90, 90, 12, -3, 0, 10, 2;
Floor:Detailed, BFD, Wall, B, , Adiabatic, , NoSun, NoWind, , 4,
    0, 0, 0, 0, 5, 0, -2, 5, 0, -2, 0, 0;
! BFD faces up: EnergyPlus reverses it (upside-down floor, automatic fix)
Output:Surfaces:List, DetailsWithVertices;
"""


#: World rectangular coordinates, stacked zones coupled through Ceiling:Interzone /
#: Floor:Interzone and an interzone wall with a Window:Interzone pair, site and building
#: shading rectangles (the conventions of EnergyPlus's 4ZoneWithShading_Simple example)
WORLD_IDF = HEADER + """
Building, Stack, 15, City, 0.04, 0.4, FullExterior, 25, 6;
GlobalGeometryRules, UpperLeftCorner, CounterClockWise, World, , World;
WindowMaterial:SimpleGlazingSystem, Glass, 2.0, 0.4, 0.6;
Construction, Win, Glass;
Zone, L, 0, 6, 6, 0;
Zone, U, 0, 6, 6, 10;
Zone, U2, 0, 26, 6, 10;
Wall:Exterior, L1, Wall, L, , 180, 90, 6, 6, 0, 20, 10;
Window, L1W, Win, L1, , 1, 4, 3, 3, 5;
Wall:Exterior, L2, Wall, L, , 0, 90, 26, 26, 0, 20, 10;
Wall:Exterior, L3, Wall, L, , 270, 90, 6, 26, 0, 20, 10;
Wall:Adiabatic, L4, Wall, L, , 90, 90, 26, 6, 0, 20, 10;
Floor:Adiabatic, LF, Wall, L, , 90, 180, 6, 6, 0, 20, 20;
Ceiling:Interzone, LC, Wall, L, , UF, 180, 0, 6, 6, 10, 20, 20;
Wall:Exterior, U1, Wall, U, , 180, 90, 6, 6, 10, 20, 10;
Wall:Exterior, U2w, Wall, U, , 0, 90, 26, 26, 10, 20, 10;
Wall:Exterior, U3, Wall, U, , 270, 90, 6, 26, 10, 20, 10;
Wall:Interzone, U4, Wall, U, , V4, 90, 90, 26, 6, 10, 20, 10;
Window:Interzone, U4W, Win, U4, V4W, 1, 4, 3, 3, 5;
Floor:Interzone, UF, Wall, U, , LC, 90, 180, 6, 6, 10, 20, 20;
Roof, UR, Wall, U, , 180, 0, 6, 6, 20, 20, 20;
Wall:Exterior, V1, Wall, U2, , 180, 90, 26, 6, 10, 20, 10;
Wall:Exterior, V2, Wall, U2, , 90, 90, 46, 6, 10, 20, 10;
Wall:Exterior, V3, Wall, U2, , 0, 90, 46, 26, 10, 20, 10;
Wall:Interzone, V4, Wall, U2, , U4, 270, 90, 26, 26, 10, 20, 10;
Window:Interzone, V4W, Win, V4, U4W, 1, 13, 3, 3, 5;
Floor:Adiabatic, VF, Wall, U2, , 90, 180, 26, 6, 10, 20, 20;
Roof, VR, Wall, U2, , 180, 0, 26, 6, 20, 20, 20;
Shading:Site, Bushes, 180, 90, 1, 0, 0, 50, 1;
Shading:Building, Hedge, 90, 90, 51, 0, 0, 50, 1;
Output:Surfaces:List, DetailsWithVertices;
"""


def _eio_shading(path) -> list[np.ndarray]:
    """Vertices of the detached shading surfaces EnergyPlus reports (not their mirrors)."""
    out = []
    for line in path.read_text().splitlines():
        f = [x.strip() for x in line.split(",")]
        if f[0] == "Shading Surface" and not f[1].upper().startswith("MIR-"):
            n = int(f[26])
            out.append(np.array([float(x) for x in f[27:27 + 3 * n]]).reshape(n, 3))
    return out


def _eio_surfaces(path) -> dict[str, dict]:
    """Heat-transfer surfaces EnergyPlus reports: class, area, azimuth, tilt, vertices."""
    out = {}
    for line in path.read_text().splitlines():
        if not line.startswith("HeatTransfer Surface,"):
            continue
        f = [x.strip() for x in line.split(",")]
        n = int(f[26])
        verts = np.array([float(x) for x in f[27:27 + 3 * n]]).reshape(n, 3)
        out[f[1].upper()] = {"class": f[2], "base": f[3].upper(), "area": float(f[9]),
                             "azimuth": float(f[12]), "tilt": float(f[13]), "vertices": verts}
    return out


def _run_probe(work, text: str):
    from zonecast.testbed.run import energyplus_dir, run_energyplus

    idf = work / "in.idf"
    idf.write_text(text)
    run_energyplus(idf, energyplus_dir() / "WeatherData" / "USA_CO_Golden-NREL.724666_TMY3.epw",
                   work)
    building = read_building(idf)
    building.eio_shading = _eio_shading(work / "eplusout.eio")  # the reference, for the test
    return building, _eio_surfaces(work / "eplusout.eio")


@pytest.fixture(scope="module")
def probe(tmp_path_factory):
    return _run_probe(tmp_path_factory.mktemp("rectangles"), EIO_IDF)


@pytest.fixture(scope="module")
def world_probe(tmp_path_factory):
    return _run_probe(tmp_path_factory.mktemp("world"), WORLD_IDF)


@pytest.mark.energyplus
@pytest.mark.parametrize("which", ["probe", "world_probe"])
def test_vertices_equal_energyplus(which, request):
    building, eio = request.getfixturevalue(which)
    ours = {**{n.upper(): s for n, s in building.surfaces.items()},
            **{n.upper(): w for n, w in building.windows.items()}}
    # every surface EnergyPlus has (the zone boundary's far side included), and no other
    assert set(ours) == set(eio)
    for name, ref in eio.items():
        # same corners in the same order (counter-clockwise from the upper left), to the
        # 0.01 m EnergyPlus prints
        np.testing.assert_allclose(ours[name].vertices, ref["vertices"], atol=0.006,
                                   err_msg=name)
        assert ours[name].area == pytest.approx(ref["area"], abs=0.006), name


@pytest.mark.energyplus
@pytest.mark.parametrize("which", ["probe", "world_probe"])
def test_rectangular_shading_equals_energyplus(which, request):
    """Shading:Site and Shading:Building rectangles where EnergyPlus puts them (the
    building's turned by its north axis with relative coordinates, neither with World)."""
    building, _ = request.getfixturevalue(which)
    ours = building.shading["*"]
    assert len(ours) == len(building.eio_shading) == 2
    for ref in building.eio_shading:
        assert any(np.allclose(p, ref, atol=0.006) for p in ours), ref


@pytest.mark.energyplus
def test_world_interzone_pairs(world_probe):
    """World rectangles: the named interzone pairs couple both ways, interzone windows are
    windows on a Surface wall."""
    b, _ = world_probe
    s = b.surfaces
    assert (s["LC"].boundary, s["LC"].boundary_object, s["UF"].boundary_object) == \
        ("Surface", "UF", "LC")
    assert (s["U4"].boundary_object, s["V4"].boundary_object) == ("V4", "U4")
    assert b.windows["U4W"].surface == "U4" and b.windows["V4W"].surface == "V4"
    assert s["U4"].area == pytest.approx(200 - 15)


@pytest.mark.energyplus
def test_types_boundaries_and_net_areas(probe):
    building, eio = probe
    s = building.surfaces
    assert (s["AS"].boundary, s["AN"].boundary, s["AF"].boundary, s["BA"].boundary) == \
        ("Outdoors", "Ground", "Ground", "Adiabatic")
    assert (s["AR"].surface_type, s["BR"].surface_type, s["BC"].surface_type,
            s["BFD"].surface_type) == ("Roof", "Roof", "Ceiling", "Floor")
    # the interzone wall faces zone B: EnergyPlus's far side iz-AW, paired both ways
    assert (s["AW"].boundary, s["AW"].boundary_object) == ("Surface", "iz-AW")
    assert (s["iz-AW"].zone, s["iz-AW"].boundary_object) == ("B", "AW")
    assert s["iz-AW"].azimuth == pytest.approx(eio["IZ-AW"]["azimuth"], abs=0.01)
    # net areas: windows and doors taken off their walls, doors are opaque surfaces
    assert s["AS"].area == pytest.approx(18.0 - 6.0)
    assert s["AE"].area == pytest.approx(15.0 - 2.0 - 2.2)
    assert s["AE_D"].area == pytest.approx(2.0) and "AE_G" in building.windows
    assert building.windows["AE_G"].kind == "GlassDoor"
    assert building.windows["BT_W"].u_value == 2.0
    assert not [u for u in building.unsupported if u.object_type in (
        "Wall:Exterior", "Window", "Door", "GlazedDoor", "Wall:Detailed", "Roof")]


def _detailed_twin(data: dict, eio: dict[str, dict]) -> dict:
    """The same building with every rectangular and typed surface replaced by
    BuildingSurface:Detailed / FenestrationSurface:Detailed at EnergyPlus's own vertices
    (world coordinates)."""
    twin = {k: v for k, v in data.items() if k not in {
        "Wall:Exterior", "Wall:Underground", "Wall:Interzone", "Wall:Adiabatic", "Roof",
        "Floor:GroundContact", "Floor:Adiabatic", "Ceiling:Adiabatic", "Window", "Door",
        "GlazedDoor", "Wall:Detailed", "RoofCeiling:Detailed", "Floor:Detailed"}}
    twin["GlobalGeometryRules"] = {"GlobalGeometryRules 1": {
        "starting_vertex_position": "UpperLeftCorner", "vertex_entry_direction":
        "Counterclockwise", "coordinate_system": "World"}}
    kinds = {"Wall": "Wall", "Roof": "Roof", "Floor": "Floor", "Window": "Window",
             "Door": "Door", "GlassDoor": "GlassDoor"}
    names = {n.upper(): n for typ in data for n in data[typ]}
    zone_of = {n: f["zone_name"] for typ in data for n, f in data[typ].items()
               if isinstance(f, dict) and "zone_name" in f}
    bsd, fsd = {}, {}
    boundary = {"AS": "Outdoors", "AE": "Outdoors", "AN": "Ground", "AR": "Outdoors",
                "AF": "Ground", "BD": "Outdoors", "BT": "Outdoors", "BR": "Outdoors",
                "BF": "Adiabatic", "BC": "Adiabatic", "BA": "Adiabatic", "BFD": "Adiabatic"}
    for key, ref in eio.items():
        name = names.get(key, "iz-AW" if key == "IZ-AW" else key)
        verts = [{"vertex_x_coordinate": x, "vertex_y_coordinate": y, "vertex_z_coordinate": z}
                 for x, y, z in ref["vertices"]]
        if ref["base"]:
            fsd[name] = {"surface_type": kinds[ref["class"]],
                         "construction_name": "Wall" if ref["class"] == "Door" else "Win",
                         "building_surface_name": names[ref["base"]], **{
                f"vertex_{i + 1}_{c}_coordinate": float(v)
                for i, p in enumerate(ref["vertices"]) for c, v in zip("xyz", p)}}
            continue
        zone = zone_of.get(name, "B")  # iz-AW: the far side, in zone B
        if name in ("AW", "iz-AW"):
            fields = {"outside_boundary_condition": "Surface",
                      "outside_boundary_condition_object": "iz-AW" if name == "AW" else "AW"}
        else:
            fields = {"outside_boundary_condition": boundary[name]}
        stype = {"BC": "Ceiling"}.get(name, kinds[ref["class"]])
        bsd[name] = {"surface_type": stype, "construction_name": "Wall", "zone_name": zone,
                     **fields, "vertices": verts}
    twin["BuildingSurface:Detailed"] = bsd
    twin["FenestrationSurface:Detailed"] = fsd
    return twin


@pytest.mark.energyplus
def test_same_building_as_detailed_twin(probe, tmp_path):
    """The rectangular description and a detailed one at EnergyPlus's vertices read alike."""
    from zonecast.estimator.idf import load_epjson

    building, eio = probe
    idf = tmp_path / "in.idf"
    idf.write_text(EIO_IDF)
    data, _ = load_epjson(idf)
    twin = building_from_epjson(json.loads(json.dumps(_detailed_twin(data, eio))))
    assert set(twin.surfaces) == set(building.surfaces)
    for name, s in building.surfaces.items():
        t = twin.surfaces[name]
        assert (t.zone, t.surface_type, t.boundary, t.construction) == \
            (s.zone, s.surface_type, s.boundary, s.construction), name
        # the twin's vertices are EnergyPlus's, printed to 0.01 m: areas within 1 %
        assert t.area == pytest.approx(s.area, rel=0.01), name
        assert t.tilt == pytest.approx(s.tilt, abs=0.2), name
    for name, z in building.zones.items():
        assert twin.zones[name].floor_area == pytest.approx(z.floor_area, rel=0.01), name


def _minimal(**objects) -> dict:
    data = {
        "Version": {"Version 1": {"version_identifier": "25.2"}},
        "GlobalGeometryRules": {"GlobalGeometryRules 1": {
            "starting_vertex_position": "UpperLeftCorner",
            "vertex_entry_direction": "Counterclockwise", "coordinate_system": "Relative"}},
        "Material": {"Brick": {"roughness": "Rough", "thickness": 0.2, "conductivity": 0.9,
                               "density": 1900, "specific_heat": 800}},
        "Construction": {"Wall": {"outside_layer": "Brick"}},
        "Zone": {"Z": {}},
    }
    data.update(objects)
    return data


def test_zero_length_rectangle_refused():
    data = _minimal(**{"Wall:Exterior": {"W": {
        "construction_name": "Wall", "zone_name": "Z", "azimuth_angle": 180,
        "starting_x_coordinate": 0, "starting_y_coordinate": 0, "starting_z_coordinate": 0,
        "length": 0, "height": 3}}})
    with pytest.raises(BuildingDescriptionError, match="W.*positive length and height"):
        building_from_epjson(data)


def test_window_on_unknown_surface_refused():
    data = _minimal(Window={"W1": {
        "construction_name": "Wall", "building_surface_name": "Nowhere",
        "starting_x_coordinate": 0, "starting_z_coordinate": 0, "length": 1, "height": 1}})
    with pytest.raises(BuildingDescriptionError, match="Window 'W1' sits on surface 'Nowhere'"):
        building_from_epjson(data)


def test_rectangle_in_building_without_rotation():
    """World rectangular coordinates: corners taken as they are, zone origin ignored."""
    data = _minimal(**{"Wall:Exterior": {"W": {
        "construction_name": "Wall", "zone_name": "Z", "azimuth_angle": 90,
        "starting_x_coordinate": 4, "starting_y_coordinate": 0, "starting_z_coordinate": 0,
        "length": 5, "height": 3}}})
    data["Zone"]["Z"] = {"x_origin": 100, "direction_of_relative_north": 45}
    data["GlobalGeometryRules"]["GlobalGeometryRules 1"][
        "rectangular_surface_coordinate_system"] = "World"
    w = building_from_epjson(data).surfaces["W"]
    assert w.azimuth == pytest.approx(90.0) and w.area == pytest.approx(15.0)
    np.testing.assert_allclose(w.vertices[1], [4, 0, 0])
    np.testing.assert_allclose(w.vertices[2], [4, 5, 0])


angles = st.floats(0, 359.9)


@settings(max_examples=60, deadline=None)
@given(az=angles, tilt=st.floats(1, 179), length=st.floats(0.1, 20),
       height=st.floats(0.1, 20), x=st.floats(0, 0.5), z=st.floats(0, 0.5))
def test_rectangle_geometry(az, tilt, length, height, x, z):
    """A rectangle's outward normal is its azimuth and tilt, its area length x height; a
    subsurface lies in its base's plane, inside it, with the same normal."""
    r = rectangle([1.0, 2.0, 3.0], az, tilt, length, height)
    n = 0.5 * np.cross(r, np.roll(r, -1, axis=0)).sum(axis=0)
    area = np.linalg.norm(n)
    assert area == pytest.approx(length * height, rel=1e-9)
    a, t = math.radians(az), math.radians(tilt)
    np.testing.assert_allclose(n / area, [math.sin(t) * math.sin(a), math.sin(t) * math.cos(a),
                                          math.cos(t)], atol=1e-9)
    w = subsurface(r, x * length, z * height, 0.5 * length, 0.5 * height)
    along, up = in_plane_axes(az, tilt)
    rel = w - r[1]
    np.testing.assert_allclose(rel @ (n / area), 0.0, atol=1e-9)
    assert (rel @ along).min() >= -1e-9 and (rel @ along).max() <= length + 1e-9
    assert (rel @ up).min() >= -1e-9 and (rel @ up).max() <= height + 1e-9
    nw = 0.5 * np.cross(w, np.roll(w, -1, axis=0)).sum(axis=0)
    np.testing.assert_allclose(nw / np.linalg.norm(nw), n / area, atol=1e-9)


def _two_rooms(**objects) -> dict:
    walls = {f"{z} {k}": {"construction_name": "Wall", "zone_name": z, "azimuth_angle": az,
                          "starting_x_coordinate": x, "starting_y_coordinate": y,
                          "starting_z_coordinate": 0, "length": 4, "height": 3}
             for z, dx in (("A", 0), ("B", 10))
             for k, az, x, y in (("S", 180, dx, 0), ("E", 90, dx + 4, 0),
                                 ("N", 0, dx + 4, 4), ("W", 270, dx, 4))}
    floors = {f"{z} F": {"construction_name": "Wall", "zone_name": z, "azimuth_angle": 180,
                         "starting_x_coordinate": dx + 4, "starting_y_coordinate": 0,
                         "starting_z_coordinate": 0, "length": 4, "width": 4}
              for z, dx in (("A", 0), ("B", 10))}
    data = _minimal(**{"Wall:Exterior": walls, "Floor:Adiabatic": floors}, **objects)
    data["Zone"] = {"A": {}, "B": {}}
    data["ZoneList"] = {"Offices": {"zones": [{"zone_name": "A"}, {"zone_name": "B"}]}}
    data["Space"] = {"A open": {"zone_name": "A"}}
    return data


def test_lists_and_spaces_expanded_to_their_zones():
    """An InternalMass or infiltration object on a ZoneList applies to every zone of it, one
    on a Space to the space's zone, as EnergyPlus does."""
    b = building_from_epjson(_two_rooms(
        InternalMass={"Furniture": {"construction_name": "Wall",
                                    "zone_or_zonelist_name": "Offices", "surface_area": 20},
                      "Desk": {"construction_name": "Wall", "space_or_spacelist_name": "A open",
                               "surface_area": 5}},
        **{"ZoneInfiltration:DesignFlowRate": {"Leak": {
            "zone_or_zonelist_or_space_or_spacelist_name": "Offices",
            "design_flow_rate_calculation_method": "AirChanges/Hour",
            "air_changes_per_hour": 0.5}}}))
    assert {(m.name, m.zone, m.area) for m in b.internal_masses.values()} == {
        ("A Furniture", "A", 20.0), ("B Furniture", "B", 20.0), ("Desk", "A", 5.0)}
    assert {i.zone for i in b.infiltration.values()} == {"A", "B"}
    for inf in b.infiltration.values():
        assert inf.flow == pytest.approx(0.5 * b.zones[inf.zone].volume / 3600.0)
    assert not [u for u in b.unsupported if u.object_type in ("InternalMass", "ZoneList")]


AIR_BOUNDARY_IDF = HEADER + """
Building, AB, 0, City, 0.04, 0.4, FullExterior, 25, 6;
GlobalGeometryRules, UpperLeftCorner, Counterclockwise, Relative, Relative, Relative;
Construction:AirBoundary, Open, SimpleMixing, 0.5;
Zone, A;
Zone, B;
Wall:Exterior, AS, Wall, A, , 180, 90, 0, 0, 0, 4, 3;
Wall:Exterior, AN, Wall, A, , 0, 90, 4, 5, 0, 4, 3;
Wall:Exterior, AW, Wall, A, , 270, 90, 0, 5, 0, 5, 3;
Wall:Interzone, AE, Open, A, , BW, 90, 90, 4, 0, 0, 5, 3;
Floor:Adiabatic, AF, Wall, A, , 0, 180, 4, 0, 0, 4, 5;
Roof, AR, Wall, A, , 180, 0, 0, 0, 3, 4, 5;
Wall:Exterior, BS, Wall, B, , 180, 90, 4, 0, 0, 8, 3;
Wall:Exterior, BN, Wall, B, , 0, 90, 12, 5, 0, 8, 3;
Wall:Exterior, BE, Wall, B, , 90, 90, 12, 0, 0, 5, 3;
Wall:Interzone, BW, Open, B, , AE, 270, 90, 4, 5, 0, 5, 3;
Floor:Adiabatic, BF, Wall, B, , 0, 180, 12, 0, 0, 8, 5;
Roof, BR, Wall, B, , 180, 0, 4, 0, 3, 8, 5;
"""


@pytest.mark.energyplus
def test_air_boundary_is_energyplus_cross_mixing(tmp_path):
    """An air wall (Construction:AirBoundary, simple mixing) is no wall: the two rooms'
    air exchange the flow EnergyPlus's cross mixing has (its eio), fixed, both ways."""
    from zonecast.estimator.rc.network import ModelOptions, build_structure
    from zonecast.testbed.run import energyplus_dir, run_energyplus

    idf = tmp_path / "in.idf"
    idf.write_text(AIR_BOUNDARY_IDF)
    run_energyplus(idf, energyplus_dir() / "WeatherData" / "USA_CO_Golden-NREL.724666_TMY3.epw",
                   tmp_path)
    ref = [ln.split(",") for ln in (tmp_path / "eplusout.eio").read_text().splitlines()
           if ln.startswith(" CrossMixing Airflow Stats Nominal,")]
    assert len(ref) == 1
    flow = float(ref[0][7])
    b = read_building(idf)
    assert "AE" not in b.surfaces and "BW" not in b.surfaces
    assert len(b.air_boundaries) == 1
    za, zb, q = b.air_boundaries[0]
    assert {za, zb} == {"A", "B"} and q == pytest.approx(flow, rel=1e-3)
    assert b.zones["A"].volume == pytest.approx(60.0) and b.zones["B"].volume == pytest.approx(120.0)
    st = build_structure(b, {"A": ["A"], "B": ["B"]}, {})
    ia = next(i for i, lab in enumerate(st.labels) if lab.kind == "room_air" and lab.room == "A")
    ib = next(i for i, lab in enumerate(st.labels) if lab.kind == "room_air" and lab.room == "B")
    g = ModelOptions().rho_air * ModelOptions().cp_air * q
    a0 = st.A0.toarray()
    assert a0[ia, ib] * st.capacity[ia] == pytest.approx(g, rel=1e-9)
    assert a0[ib, ia] * st.capacity[ib] == pytest.approx(g, rel=1e-9)
    assert not [u for u in b.unsupported if u.object_type == "Construction:AirBoundary"]


def test_air_boundary_without_neighbour_refused():
    data = _minimal(**{"Construction:AirBoundary": {"Open": {"air_exchange_method": "None"}},
                       "Wall:Adiabatic": {"W": {
                           "construction_name": "Open", "zone_name": "Z", "azimuth_angle": 90,
                           "starting_x_coordinate": 0, "starting_y_coordinate": 0,
                           "starting_z_coordinate": 0, "length": 3, "height": 3}}})
    with pytest.raises(BuildingDescriptionError, match="air-boundary surface 'W' must face"):
        building_from_epjson(data)


@pytest.mark.energyplus
def test_window_multiplier_as_energyplus(tmp_path):
    """A window with multiplier 4 (4 x 3 m2 on an 18 m2 wall): EnergyPlus takes one window
    off the wall (net 15 m2, its eio) and counts the window's heat four times; before, the
    reader took all four off and would refuse a multiplied area larger than the wall."""
    from zonecast.testbed.run import energyplus_dir, run_energyplus

    idf = tmp_path / "in.idf"
    idf.write_text(HEADER + """
Building, M, 0, City, 0.04, 0.4, FullExterior, 25, 6;
GlobalGeometryRules, UpperLeftCorner, Counterclockwise, Relative, Relative, Relative;
WindowMaterial:SimpleGlazingSystem, Glass, 2.0, 0.4, 0.6;
Construction, Win, Glass;
""" + BOX + """Window, SW, Win, S, , 4, 1, 1, 2, 1.5;
Output:Surfaces:List, Details;
""")
    run_energyplus(idf, energyplus_dir() / "WeatherData" / "USA_CO_Golden-NREL.724666_TMY3.epw",
                   tmp_path)
    eio = {}
    for line in (tmp_path / "eplusout.eio").read_text().splitlines():
        f = [x.strip() for x in line.split(",")]
        if f[0] == "HeatTransfer Surface":
            eio[f[1]] = float(f[9])
    b = read_building(idf)
    assert b.surfaces["S"].area == pytest.approx(eio["S"]) == pytest.approx(15.0)
    assert b.windows["SW"].area == pytest.approx(4 * eio["SW"]) == pytest.approx(12.0)


@pytest.mark.energyplus
def test_interzone_window_pair_couples_once(world_probe):
    """A Window:Interzone pair (listed on both walls, as EnergyPlus requires) couples the two
    rooms' air once, by one window's area times U_win (before: twice)."""
    from zonecast.estimator.rc.network import UWIN, ModelOptions, build_structure

    b, _ = world_probe
    st = build_structure(b, {"L": ["L"], "U": ["U"], "U2": ["U2"]}, {},
                         ModelOptions(ground="adiabatic"))
    room = {lab.room: i for i, lab in enumerate(st.labels) if lab.kind == "room_air"}
    a = st.A_p[UWIN].toarray()
    assert a[room["U"], room["U2"]] * st.capacity[room["U"]] == pytest.approx(15.0)
    assert a[room["U2"], room["U"]] * st.capacity[room["U2"]] == pytest.approx(15.0)


def test_solar_enclosures_are_the_groups_joined_by_air_boundaries():
    from zonecast.estimator.rc.network import solar_enclosures

    groups = solar_enclosures([("A", "B", 0.1), ("C", "D", 0.1), ("B", "E", 0.2)])
    assert groups == {r: ["A", "B", "E"] for r in "ABE"} | {r: ["C", "D"] for r in "CD"}
    assert solar_enclosures([]) == {}


def test_window_sun_lands_on_the_faces_of_the_whole_enclosure(tmp_path):
    """EnergyPlus makes rooms joined by an air boundary one solar enclosure: the sun through
    A's window lands on the faces of A and B, by area (as on one room's faces); with
    solar_enclosure="room" (model files before the option) on A's alone. Same total."""
    from zonecast.estimator.rc.network import DISTURBANCES, WINSOL, ModelOptions, build_structure

    idf = tmp_path / "in.idf"
    idf.write_text(AIR_BOUNDARY_IDF + "WindowMaterial:SimpleGlazingSystem, Glass, 2.0, 0.4;\n"
                   "Construction, Win, Glass;\nWindow, AS_W, Win, AS, , 1, 1, 0.5, 2, 1.5;\n")
    b = read_building(idf)
    zones = {"A": ["A"], "B": ["B"]}
    col = DISTURBANCES.index("solS")
    per_room = {}
    for opt in ("air_boundaries", "room"):
        st = build_structure(b, zones, {}, ModelOptions(solar_enclosure=opt))
        bv = st.Bv_p[WINSOL].toarray()[:, col]
        rooms = {}
        for i in np.flatnonzero(bv):
            rooms[st.labels[i].room] = rooms.get(st.labels[i].room, 0.0) + bv[i] * st.capacity[i]
        per_room[opt] = rooms
        assert sum(rooms.values()) == pytest.approx(2.0 * 1.5)  # the window's area, all of it
        assert any("solar enclosure" in n for n in st.notes) == (opt == "air_boundaries")
    assert set(per_room["room"]) == {"A"}
    assert set(per_room["air_boundaries"]) == {"A", "B"}
    # B's faces (its floor twice A's) take more than A's
    assert per_room["air_boundaries"]["B"] > per_room["air_boundaries"]["A"]


def test_radiant_gains_reach_the_whole_enclosure(tmp_path):
    """With internal_gains="idf" the radiant share of A's lights lands on the faces of A's
    enclosure (A and B), the convective share on A's air; "room" keeps it in A."""
    from zonecast.estimator.rc.network import ModelOptions, build_structure

    idf = tmp_path / "in.idf"
    idf.write_text(AIR_BOUNDARY_IDF + "Schedule:Constant, On, , 1;\n"
                   "Lights, L, A, On, LightingLevel, 200, , , 0, 0.6, 0.2;\n")
    b = read_building(idf)
    zones = {"A": ["A"], "B": ["B"]}
    heat = {}
    for opt in ("air_boundaries", "room"):
        st = build_structure(b, zones, {}, ModelOptions(internal_gains="idf",
                                                        solar_enclosure=opt))
        col = np.asarray(st.B_ig)[:, 0] * st.capacity  # zone A's gains [W per W/m2]
        rooms = {}
        for i in np.flatnonzero(col):
            key = (st.labels[i].room, st.labels[i].kind == "room_air")
            rooms[key] = rooms.get(key, 0.0) + col[i]
        heat[opt] = rooms
        assert sum(rooms.values()) == pytest.approx(b.zones["A"].floor_area)
    assert {r for r, _ in heat["room"]} == {"A"}
    assert ("B", False) in heat["air_boundaries"] and ("B", True) not in heat["air_boundaries"]
    assert heat["air_boundaries"][("A", True)] == pytest.approx(heat["room"][("A", True)])


def test_air_paths_the_model_lacks_are_listed_as_not_modelled():
    """Ventilation, other infiltration objects, an airflow network and Kiva foundations
    change EnergyPlus's heat balance: the reader says they are not modelled."""
    wall = {"construction_name": "Wall", "zone_name": "Z", "azimuth_angle": 180,
            "starting_x_coordinate": 0, "starting_y_coordinate": 0, "starting_z_coordinate": 0,
            "length": 4, "height": 3}
    data = _minimal(**{"Wall:Exterior": {"W": wall},
                       "ZoneVentilation:DesignFlowRate": {"Vent": {"zone_or_zonelist_name": "Z"}},
                       "ZoneInfiltration:EffectiveLeakageArea": {"ELA": {"zone_name": "Z"}},
                       "AirflowNetwork:SimulationControl": {"AFN": {}},
                       "Foundation:Kiva": {"Slab": {}}})
    b = building_from_epjson(data)
    listed = {(u.object_type, u.name): u.reason for u in b.unsupported}
    assert "only ZoneInfiltration:DesignFlowRate" in listed[("ZoneVentilation:DesignFlowRate",
                                                             "Vent")]
    assert "leakage area" in listed[("ZoneInfiltration:EffectiveLeakageArea", "ELA")]
    assert ("AirflowNetwork:SimulationControl", "AFN") in listed
    assert "adiabatic" in listed[("Foundation:Kiva", "Slab")]
