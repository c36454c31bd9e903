"""Exterior shading of windows (estimator/shading.py) and its path into the solar columns."""

import math

import numpy as np
import pandas as pd
import pvlib
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from zonecast.estimator import shading as sh
from zonecast.estimator import solar as sol
from zonecast.estimator.artifact import load_structure, save_structure
from zonecast.estimator.idf import building_from_epjson
from zonecast.estimator.rc.network import ModelOptions, build_structure
from zonecast.estimator.solar import facade_columns, sun_geometry, transpose

# a south-facing window 2 m wide, 1.5 m high, counter-clockwise seen from outside
WIN = np.array([[0.0, 0.0, 2.5], [0.0, 0.0, 1.0], [2.0, 0.0, 1.0], [2.0, 0.0, 2.5]])


def _south_sun(altitude):
    return sh.sun_vectors(np.atleast_1d(90.0 - np.asarray(altitude, float)),
                          np.full(np.size(altitude), 180.0))


def test_window_frame_axes():
    o, e1, e2, n = sh.window_frame(WIN)
    assert np.allclose(n, [0, -1, 0]) and np.allclose(e1, [1, 0, 0])
    assert np.allclose(e2, [0, 0, 1]) and np.allclose(o, WIN[0])
    with pytest.raises(sh.ShadingError, match="no area"):
        sh.window_frame(np.zeros((4, 3)))


@settings(max_examples=40, deadline=None)
@given(depth=st.floats(0.1, 2.0), altitude=st.floats(2.0, 85.0), offset=st.floats(0.0, 0.5))
def test_overhang_shadow_matches_the_profile_angle(depth, altitude, offset):
    """Sun square to a window under a full-width overhang: the shadow reaches
    depth tan(altitude) - offset below the window's top (the profile-angle formula)."""
    ws = sh.WindowShading("w", 1, 1.0, WIN, [sh.overhang_polygon(WIN, offset, 90, 0, 0, depth)])
    shadow = np.clip(depth * math.tan(math.radians(altitude)) - offset, 0.0, 1.5)
    assert sh.sunlit_fraction(ws, _south_sun([altitude]))[0] == pytest.approx(
        1.0 - shadow / 1.5, abs=1e-4)


def test_fins_shade_the_side_the_sun_comes_from():
    # a fin reaching far above and below: its shadow is a vertical band on the window
    left = sh.fin_polygons(WIN, [{"side": "left", "extension": 0, "above": 5, "below": 5,
                                  "tilt": 90, "depth": 1.0}])
    ws = sh.WindowShading("w", 1, 1.0, WIN, left)
    # seen from outside a south window its left side is west: sun from south-west shades
    east, west = sh.sun_vectors([80.0, 80.0], [160.0, 200.0])
    assert sh.sunlit_fraction(ws, np.array([east]))[0] == pytest.approx(1.0)
    # band width = depth tan(20 deg) for a sun 20 deg off the window's normal
    expect = 1.0 - 1.0 * math.tan(math.radians(20.0)) / 2.0
    assert sh.sunlit_fraction(ws, np.array([west]))[0] == pytest.approx(expect, abs=1e-4)


def test_no_shadow_without_sun_in_front():
    ws = sh.WindowShading("w", 1, 1.0, WIN, [sh.overhang_polygon(WIN, 0, 90, 0, 0, 1.0)])
    north_sun = sh.sun_vectors([40.0], [0.0])
    assert sh.sunlit_fraction(ws, north_sun)[0] == 1.0


def test_clip_front():
    o, n = np.zeros(3), np.array([0.0, -1.0, 0.0])
    behind = np.array([[0, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
    assert sh.clip_front(behind, o, n) is None
    across = np.array([[0, -1, 0], [1, -1, 0], [1, 1, 0], [0, 1, 0]], float)
    part = sh.clip_front(across, o, n)
    assert part is not None and np.all((part - o) @ n >= 0)
    assert np.ptp(part[:, 1]) == pytest.approx(1.0, abs=1e-5)


def test_diffuse_ratios_fall_with_depth():
    ratios = [sh.WindowShading("w", 1, 1.0, WIN,
                               [sh.overhang_polygon(WIN, 0, 90, 1, 1, d)]).sky
              for d in (0.2, 0.6, 1.2)]
    assert 1.0 > ratios[0] > ratios[1] > ratios[2] > 0.3
    bare = sh.WindowShading("w", 1, 1.0, WIN, [])
    assert (bare.sky, bare.horizon) == (1.0, 1.0)


def test_window_shading_round_trip():
    ws = sh.WindowShading("w", 1, 0.5, WIN, [sh.overhang_polygon(WIN, 0.1, 90, 0, 0, 0.8)])
    back = sh.WindowShading.from_dict(ws.to_dict())
    sun = _south_sun(np.linspace(5, 80, 7))
    assert np.array_equal(sh.sunlit_fraction(ws, sun), sh.sunlit_fraction(back, sun))
    assert (back.sky, back.horizon, back.share) == (ws.sky, ws.horizon, 0.5)


def _day(lat=40.0, lon=-105.0):
    times = pd.date_range("2024-06-21 00:00", periods=96, freq="15min", tz="UTC")
    geom = sun_geometry(times, pd.Timedelta("15min"), lat, lon, 1600.0)
    cosz = np.clip(np.cos(np.radians(geom[1])), 0, None)
    dni = 800.0 * (cosz > 0.05)
    dhi = 100.0 * (cosz > 0)
    ghi = dni * cosz + dhi
    return geom, ghi, dni, dhi


def test_facade_columns_without_shading_are_transpose_exactly():
    geom, ghi, dni, dhi = _day()
    planes = np.array([(90.0, a) for a in (90, 180, 270, 0)] + [(0.0, 180.0)])
    ref = transpose(geom, ghi, dni, dhi, planes, total=True)["poa_global"]
    got = facade_columns(geom, ghi, dni, dhi, (90, 180, 270, 0))
    assert np.array_equal(got, ref)
    empty = sh.FacadeShading([])
    assert np.array_equal(facade_columns(geom, ghi, dni, dhi, (90, 180, 270, 0),
                                         shading=empty), ref)


def test_horizontal_column_is_the_global_horizontal_irradiance():
    """The roofs' column: on a horizontal plane beam and sky diffuse add up to the
    station's GHI when its three readings close (Perez's circumsolar and horizon terms
    vanish on a horizontal plane; no ground in its view)."""
    geom, ghi, dni, dhi = _day()
    got = facade_columns(geom, ghi, dni, dhi, (90, 180, 270, 0))[:, 4]
    up = geom[1] < 85.0  # sun above 5 deg: Perez's circumsolar ratio is exact there
    np.testing.assert_allclose(got[up], ghi[up], rtol=1e-9, atol=1e-9)
    assert np.all(got[~up] <= ghi[~up] + 1e-9) and np.all(got >= 0)


def test_facade_columns_shade_only_their_facade():
    geom, ghi, dni, dhi = _day()
    ws = sh.WindowShading("w", 1, 1.0, WIN, [sh.overhang_polygon(WIN, 0, 90, 1, 1, 1.0)])
    fs = sh.FacadeShading([ws])
    plain = facade_columns(geom, ghi, dni, dhi, (90, 180, 270, 0))
    shaded = facade_columns(geom, ghi, dni, dhi, (90, 180, 270, 0), shading=fs)
    assert shaded.shape == plain.shape == (len(ghi), 5)
    assert np.array_equal(shaded[:, [0, 2, 3, 4]], plain[:, [0, 2, 3, 4]])
    noon = np.argmax(plain[:, 1])
    assert shaded[noon, 1] < 0.6 * plain[noon, 1]  # a high June sun under a 1 m overhang
    assert np.all(shaded[:, 1] <= plain[:, 1] + 1e-9) and np.all(shaded >= 0)
    # ground-reflected light is never shaded: the column keeps at least it
    comp = transpose(geom, ghi, dni, dhi, np.array([(90.0, 180.0)]))
    assert np.all(shaded[:, 1] >= comp["poa_ground_diffuse"][:, 0] - 1e-9)


def _box_with_window(shading_objects):
    data = {
        "Version": {"V": {"version_identifier": "25.2"}},
        "Building": {"B": {"north_axis": 0.0}},
        "GlobalGeometryRules": {"G": {"coordinate_system": "Relative",
                                      "starting_vertex_position": "UpperLeftCorner",
                                      "vertex_entry_direction": "Counterclockwise"}},
        "Zone": {"Box": {}},
        "Material": {"M": {"thickness": 0.2, "conductivity": 1.0, "density": 2000,
                           "specific_heat": 900, "roughness": "Rough"}},
        "WindowMaterial:SimpleGlazingSystem": {"G": {"u_factor": 2.0,
                                                     "solar_heat_gain_coefficient": 0.4}},
        "Construction": {"C": {"outside_layer": "M"}, "Win": {"outside_layer": "G"}},
    }
    x, y, h = 4.0, 5.0, 3.0
    quads = {"South": [(0, 0, h), (0, 0, 0), (x, 0, 0), (x, 0, h)],
             "East": [(x, 0, h), (x, 0, 0), (x, y, 0), (x, y, h)],
             "North": [(x, y, h), (x, y, 0), (0, y, 0), (0, y, h)],
             "West": [(0, y, h), (0, y, 0), (0, 0, 0), (0, 0, h)],
             "Floor": [(0, 0, 0), (0, y, 0), (x, y, 0), (x, 0, 0)],
             "Roof": [(0, y, h), (0, 0, h), (x, 0, h), (x, y, h)]}

    def verts(q):
        return [dict(zip(("vertex_x_coordinate", "vertex_y_coordinate",
                          "vertex_z_coordinate"), p)) for p in q]

    data["BuildingSurface:Detailed"] = {
        n: {"surface_type": {"Floor": "Floor", "Roof": "Roof"}.get(n, "Wall"),
            "construction_name": "C", "zone_name": "Box",
            "outside_boundary_condition": "Outdoors", "vertices": verts(q)}
        for n, q in quads.items()}
    data["FenestrationSurface:Detailed"] = {"SWin": {
        "surface_type": "Window", "construction_name": "Win", "building_surface_name": "South",
        "vertices": verts([(1, 0, 2.5), (1, 0, 1.0), (3, 0, 1.0), (3, 0, 2.5)])}}
    data.update(shading_objects)
    return data


def test_idf_overhang_projection_and_zone_shading_surface():
    b = building_from_epjson(_box_with_window({
        "Shading:Overhang:Projection": {"OH": {
            "window_or_door_name": "SWin", "height_above_window_or_door": 0.1,
            "tilt_angle_from_window_door": 90, "left_extension_from_window_door_width": 0.2,
            "right_extension_from_window_door_width": 0.3,
            "depth_as_fraction_of_window_door_height": 0.5}},
        "Schedule:Compact": {"Opaque": {"data": [{"field": "Through: 12/31"},
                                                 {"field": "For: AllDays"},
                                                 {"field": "Until: 24:00"}, {"field": 0.0}]}},
        "Shading:Zone:Detailed": {"Wing": {
            "base_surface_name": "South", "transmittance_schedule_name": "Opaque",
            "vertices": [{"vertex_x_coordinate": a, "vertex_y_coordinate": b_,
                          "vertex_z_coordinate": c}
                         for a, b_, c in [(4, 0, 3), (4, 0, 0), (4, -2, 0), (4, -2, 3)]]}}}))
    (oh,) = b.shading["SWin"]
    # 0.1 m above the 2.5 m top, from x = 1 - 0.2 to 3 + 0.3, 0.75 m out (south: -y)
    assert np.allclose(sorted(oh[:, 0]), [0.8, 0.8, 3.3, 3.3])
    assert np.allclose(oh[:, 2], 2.6) and np.allclose(sorted(oh[:, 1]), [-0.75, -0.75, 0, 0])
    assert len(b.shading["*"]) == 1
    assert not any("transmittance" in n for n in b.notes)  # a constant 0 is opaque
    s = build_structure(b, {"Z": ["Box"]}, {}, options=ModelOptions(ground="adiabatic"))
    (entry,) = s.shading
    assert entry["facade"] == 1 and entry["share"] == pytest.approx(1.0)
    assert len(entry["shades"]) == 2 and 0 < entry["sky"] < 1
    none = build_structure(b, {"Z": ["Box"]}, {}, options=ModelOptions(ground="adiabatic",
                                                                        shading="none"))
    assert none.shading == [] and none.facade_shading is None


def test_structure_file_keeps_the_shading(tmp_path):
    b = building_from_epjson(_box_with_window({"Shading:Fin": {"F": {
        "window_or_door_name": "SWin", "left_extension_from_window_door": 0.1,
        "left_distance_above_top_of_window": 0.2, "left_distance_below_bottom_of_window": 0.2,
        "left_tilt_angle_from_window_door": 90, "left_depth": 0.5,
        "right_extension_from_window_door": 0.1, "right_distance_above_top_of_window": 0.2,
        "right_distance_below_bottom_of_window": 0.2, "right_tilt_angle_from_window_door": 90,
        "right_depth": 0.0}}}))
    assert len(b.shading["SWin"]) == 1  # the right fin has no depth
    s = build_structure(b, {"Z": ["Box"]}, {}, options=ModelOptions(ground="adiabatic"))
    path = save_structure(tmp_path / "s.npz", s, {"Box": 60.0})
    back, _ = load_structure(path)
    assert back.shading == s.shading and back.options.shading == "idf"
    sun = sh.sun_vectors([70.0, 60.0], [200.0, 230.0])
    a = s.facade_shading.windows[0]
    assert np.array_equal(sh.sunlit_fraction(a, sun),
                          sh.sunlit_fraction(back.facade_shading.windows[0], sun))


def test_unknown_window_is_noted():
    b = building_from_epjson(_box_with_window({"Shading:Overhang": {"OH": {
        "window_or_door_name": "Nope", "height_above_window_or_door": 0.0, "depth": 1.0}}}))
    assert b.shading == {}
    assert any("'Nope'" in n and "left out" in n for n in b.notes)


def test_window_transmission_matches_ashrae_clear_glass():
    """One clear pane relative to normal incidence (ASHRAE Fundamentals ch. 15, 3 mm clear:
    0.90 at 60 deg, 0.74 at 70, 0.45 at 80); two panes lose more; 1 at normal incidence,
    0 at grazing."""
    from zonecast.estimator.solar import window_transmission

    one = window_transmission([0.0, 60.0, 70.0, 80.0, 90.0], 1)
    np.testing.assert_allclose(one[:4], [1.0, 0.90, 0.74, 0.45], atol=0.051)
    assert one[4] == pytest.approx(0.0, abs=1e-9)
    two = window_transmission([0.0, 60.0, 70.0, 80.0], 2)
    np.testing.assert_allclose(two, one[:4] ** 2)


def test_facade_columns_weighed_by_the_windows_angle():
    """With panes, each facade column is its beam and circumsolar times the transmission at
    the sun's angle, its sky, horizon and ground parts times their hemispherical averages;
    the roofs' column is not weighed; with shading the loss is taken from the weighed parts."""
    from zonecast.estimator.solar import _diffuse_transmission, window_transmission

    geom, ghi, dni, dhi = _day()
    az = (90, 180, 270, 0)
    planes = np.array([(90.0, a) for a in az] + [(0.0, 180.0)])
    comp = transpose(geom, ghi, dni, dhi, planes)
    circ_share, hor_share = sol._perez_shares(geom, dni, dhi, planes)
    sky = comp["poa_sky_diffuse"]
    circ, hor = sky * circ_share, sky * hor_share
    aoi = pvlib.irradiance.aoi(planes[:, 0], planes[:, 1], geom[1][:, None], geom[3][:, None])
    tau = np.where(aoi < 90, window_transmission(np.minimum(aoi, 90), 2), 0.0)
    d = _diffuse_transmission(2)
    want = ((comp["poa_direct"] + circ) * tau + (sky - circ - hor) * d["sky"]
            + hor * d["horizon"] + comp["poa_ground_diffuse"] * d["ground"])
    got = facade_columns(geom, ghi, dni, dhi, az, panes=2)
    plain = facade_columns(geom, ghi, dni, dhi, az)
    np.testing.assert_allclose(got[:, :4], want[:, :4], rtol=1e-9, atol=1e-9)
    assert np.array_equal(got[:, 4], plain[:, 4])
    noon = np.argmax(plain[:, 1])  # a high June sun on the south facade: far off normal
    assert got[noon, 1] < 0.8 * plain[noon, 1] and np.all(got <= plain + 1e-9)
    ws = sh.WindowShading("w", 1, 1.0, WIN, [sh.overhang_polygon(WIN, 0, 90, 1, 1, 1.0)])
    shaded = facade_columns(geom, ghi, dni, dhi, az, shading=sh.FacadeShading([ws]), panes=2)
    assert np.all(shaded[:, 1] <= got[:, 1] + 1e-9) and np.all(shaded >= 0)
    assert np.array_equal(shaded[:, [0, 2, 3]], got[:, [0, 2, 3]])


@pytest.mark.parametrize(("u", "panes"), [(5.9, 1), (2.0, 2)])
def test_window_angle_panes_from_the_rated_u(tmp_path, u, panes):
    """window_angle="glass": one pane for single glazing's rated U, two otherwise; the
    structure file keeps it; model data built from it weigh the columns (Pipeline.data and
    the other callers pass the structure's panes to facade_columns)."""
    data = _box_with_window({})
    data["WindowMaterial:SimpleGlazingSystem"]["G"]["u_factor"] = u
    b = building_from_epjson(data)
    s = build_structure(b, {"Z": ["Box"]}, {}, options=ModelOptions(ground="adiabatic",
                                                                    window_angle="glass"))
    assert s.window_panes == panes
    back, _ = load_structure(save_structure(tmp_path / "s.npz", s, {"Box": 60.0}))
    assert back.window_panes == panes and back.options.window_angle == "glass"
    plain = build_structure(b, {"Z": ["Box"]}, {}, options=ModelOptions(ground="adiabatic"))
    assert plain.window_panes == 0
    back0, _ = load_structure(save_structure(tmp_path / "p.npz", plain, {"Box": 60.0}))
    assert back0.window_panes == 0


def test_window_angle_refused_when_unknown():
    with pytest.raises(ValueError, match="window_angle must be 'none' or 'glass'"):
        ModelOptions(window_angle="tinted")
