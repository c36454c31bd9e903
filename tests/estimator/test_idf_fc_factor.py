"""F-factor slabs and C-factor below-grade walls (ASHRAE 90.1's ratings, as the DOE prototype
buildings use them) read as the layered constructions EnergyPlus builds for them."""

from __future__ import annotations

import numpy as np
import pytest
from zonecast.estimator.idf import _eio_construction_layers, read_building
from zonecast.testbed.run import energyplus_dir, run_energyplus

pytestmark = pytest.mark.energyplus

IDF = """
Version, 25.2;
SimulationControl, No, No, No, No, Yes, No, 1;
RunPeriod, Jan, 1, 2, 2015, 1, 2, 2015, , No, No, No, Yes, Yes, No, Hour24;
Site:Location, Golden, 39.74, -105.18, -7.0, 1829.0;
Building, FC, 0, City, 0.04, 0.4, FullExterior, 25, 6;
GlobalGeometryRules, UpperLeftCorner, Counterclockwise, Relative;
Material, Brick, Rough, 0.2, 0.9, 1900, 800;
Construction, Wall, Brick;
Construction:FfactorGroundFloor, Slab F, {F}, 50, 30;
Construction:CfactorUndergroundWall, Bsmt C, 1.2, 3;
Site:GroundTemperature:FCfactorMethod, 1,2,3,4,5,6,7,8,9,10,11,12;
Zone, Z;
BuildingSurface:Detailed, S, Wall, Bsmt C, Z, , GroundFCfactorMethod, , NoSun, NoWind, , 4,
    0, 0, 3, 0, 0, 0, 10, 0, 0, 10, 0, 3;
BuildingSurface:Detailed, E, Wall, Wall, Z, , Outdoors, , SunExposed, WindExposed, , 4,
    10, 0, 3, 10, 0, 0, 10, 5, 0, 10, 5, 3;
BuildingSurface:Detailed, N, Wall, Wall, Z, , Outdoors, , SunExposed, WindExposed, , 4,
    10, 5, 3, 10, 5, 0, 0, 5, 0, 0, 5, 3;
BuildingSurface:Detailed, W, Wall, Wall, Z, , Outdoors, , SunExposed, WindExposed, , 4,
    0, 5, 3, 0, 5, 0, 0, 0, 0, 0, 0, 3;
BuildingSurface:Detailed, F, Floor, Slab F, Z, , GroundFCfactorMethod, , NoSun, NoWind, , 4,
    0, 0, 0, 0, 5, 0, 10, 5, 0, 10, 0, 0;
BuildingSurface:Detailed, R, Roof, Wall, Z, , Outdoors, , SunExposed, WindExposed, , 4,
    0, 5, 3, 0, 0, 3, 10, 0, 3, 10, 5, 3;
Output:Constructions, Constructions, Materials;
"""


def _resistance(building, name: str) -> float:
    return sum(layer.resistance for layer in building.constructions[name].layers)


@pytest.fixture(scope="module")
def slab(tmp_path_factory):
    """The building read at two F-factors, and EnergyPlus's own run of the first file."""
    out = {}
    for f in (0.73, 0.35):
        work = tmp_path_factory.mktemp(f"fc{f}")
        idf = work / "in.idf"
        idf.write_text(IDF.replace("{F}", str(f)))
        out[f] = read_building(idf)
        if f == 0.73:
            run_energyplus(idf, energyplus_dir() / "WeatherData"
                           / "USA_CO_Golden-NREL.724666_TMY3.epw", work)
            out["eio"] = _eio_construction_layers((work / "eplusout.eio").read_text())
    return out


def test_layers_as_energyplus_runs_the_file(slab):
    """The constructions equal the ones EnergyPlus builds when it runs the file itself."""
    b = slab[0.73]
    for name in ("Slab F", "Bsmt C"):
        ref = slab["eio"][name.upper()]
        ours = b.constructions[name].layers
        assert len(ours) == len(ref) == 2, name
        for layer, (_, d, k, rho, cp, r) in zip(ours, ref):
            assert layer.resistance == pytest.approx(r, rel=1e-3), name
            assert layer.thickness == pytest.approx(d), name
            if d > 0:
                assert (layer.conductivity, layer.density, layer.specific_heat) == \
                    pytest.approx((k, rho, cp)), name
    assert not [u for u in b.unsupported if u.object_type.startswith("Construction:")]


def test_f_factor_semantics(slab):
    """R_eff = A / (P F): the fictitious layer moves by A/P (1/F2 - 1/F1), nothing else."""
    a_over_p = 50 / 30
    d_r = _resistance(slab[0.35], "Slab F") - _resistance(slab[0.73], "Slab F")
    assert d_r == pytest.approx(a_over_p * (1 / 0.35 - 1 / 0.73), rel=1e-3)
    assert _resistance(slab[0.35], "Bsmt C") == pytest.approx(_resistance(slab[0.73], "Bsmt C"))


def test_ground_boundary_and_temperatures(slab):
    b = slab[0.73]
    assert (b.surfaces["F"].boundary, b.surfaces["S"].boundary) == ("Ground", "Ground")
    for name in ("F", "S"):
        assert b.ground_temperature_at(name) == tuple(float(m) for m in range(1, 13))
    assert any("FCfactorMethod" in n for n in b.notes)


GOLDEN = "USA_CO_Golden-NREL.724666_TMY3.epw"
#: the file without its FC-method ground temperatures, with building-surface ones near room
#: temperature (as the DOE prototypes have) and one plain ground-contact floor
NO_FC = (IDF.replace("{F}", "0.73")
         .replace("Site:GroundTemperature:FCfactorMethod, 1,2,3,4,5,6,7,8,9,10,11,12;",
                  "Site:GroundTemperature:BuildingSurface, 20,20,20,20,20,20,21,21,21,21,21,21;")
         + "BuildingSurface:Detailed, G, Floor, Wall, Z, , Ground, , NoSun, NoWind, , 4,\n"
           "    0, 0, 0.5, 0, 5, 0.5, 10, 5, 0.5, 10, 0, 0.5;\n")


def _eio_fc_ground(text: str) -> tuple[float, ...]:
    line = next(ln for ln in text.splitlines()
                if ln.strip().startswith("Site:GroundTemperature:FCfactorMethod,"))
    return tuple(float(x) for x in line.split(",")[1:13])


@pytest.fixture(scope="module")
def no_fc(tmp_path_factory):
    """The file without Site:GroundTemperature:FCfactorMethod, run by EnergyPlus with
    Golden's weather file, and read with and without that file."""
    work = tmp_path_factory.mktemp("nofc")
    idf = work / "in.idf"
    idf.write_text(NO_FC)
    epw = energyplus_dir() / "WeatherData" / GOLDEN
    run_energyplus(idf, epw, work)
    return {"eio": _eio_fc_ground((work / "eplusout.eio").read_text()),
            "site": read_building(idf, weather_file=epw), "near": read_building(idf)}


def test_fc_ground_is_the_weather_files_as_energyplus_takes_it(no_fc):
    """Without Site:GroundTemperature:FCfactorMethod EnergyPlus holds F/C-factor faces at the
    weather file's 0.5 m ground temperatures (its eio says so), not at the building-surface
    temperatures; a plain ground-contact floor keeps those."""
    b = no_fc["site"]
    assert b.ground_temperature_at("F") == pytest.approx(no_fc["eio"], abs=0.006)
    assert b.ground_temperature_at("S") == pytest.approx(no_fc["eio"], abs=0.006)
    assert b.ground_temperature_at("G") == (20.0,) * 6 + (21.0,) * 6
    assert max(no_fc["eio"]) - min(no_fc["eio"]) > 5  # a real annual swing, not 20-21 degC
    assert any("0.5 m temperatures of the site's weather file" in n for n in b.notes)


def test_fc_layers_built_without_the_fc_ground_object(no_fc, slab):
    """EnergyPlus stops building F/C-factor layers on a design day without FC-method ground
    temperatures; the layers must not depend on them (the DOE prototypes have none)."""
    b = no_fc["site"]
    assert not [u for u in b.unsupported if u.object_type.startswith("Construction:")]
    for name in ("Slab F", "Bsmt C"):
        assert _resistance(b, name) == pytest.approx(_resistance(slab[0.73], name))


def test_fc_ground_from_the_nearest_shipped_weather_file(no_fc):
    """Without a site weather file: the EPW shipped with EnergyPlus nearest to the input's
    Site:Location (Golden's here), and the notes name it."""
    b = no_fc["near"]
    assert b.ground_temperature_at("F") == no_fc["site"].ground_temperature_at("F")
    assert any(GOLDEN in n and "nearest" in n for n in b.notes)


def test_epw_ground_temperatures_header(tmp_path):
    from zonecast.estimator.idf import epw_ground_temperatures
    epw = tmp_path / "x.epw"
    epw.write_text("LOCATION,X,,,,,40,-100,-6,200\n"
                   "GROUND TEMPERATURES,2,.5,,,," + ",".join(str(m) for m in range(12))
                   + ",2,1.1,1200,800," + ",".join(str(10 + m) for m in range(12)) + "\n")
    got = epw_ground_temperatures(epw)
    assert got == {0.5: tuple(float(m) for m in range(12)),
                   2.0: tuple(float(10 + m) for m in range(12))}
    epw.write_text("LOCATION,X,,,,,40,-100,-6,200\nGROUND TEMPERATURES,2,.5,,,,1,2\n")
    with pytest.raises(ValueError, match="GROUND TEMPERATURES header is malformed"):
        epw_ground_temperatures(epw)


def test_model_holds_each_ground_face_at_its_own_temperature(no_fc):
    """The model's ground inputs: the F/C-factor faces at the FC-method temperatures, the
    plain ground-contact floor at the building-surface ones."""
    from zonecast.estimator.rc.network import build_structure

    st = build_structure(no_fc["site"], {"Z": ["Z"]}, {})
    monthly = {b: spec["monthly"] for b, spec in st.scheduled.items()
               if spec.get("supply") == "ground"}
    assert monthly["ground:F"] == pytest.approx(list(no_fc["eio"]), abs=0.006)
    assert monthly["ground:S"] == monthly["ground:F"]
    assert monthly["ground:G"] == [20.0] * 6 + [21.0] * 6


def test_a_missing_site_weather_file_is_a_clear_error(tmp_path):
    idf = tmp_path / "in.idf"
    idf.write_text(NO_FC)
    with pytest.raises(FileNotFoundError, match="the site's weather_file.*does not exist"):
        read_building(idf, weather_file=tmp_path / "nowhere.epw")



def test_fc_faces_are_regular_states(no_fc):
    """EnergyPlus puts the fictitious insulation outside the concrete: the outer face node
    lies between massless layers and still gets a capacity (a massless face's), so the
    model is finite and stable (it was 1/0 before)."""
    from zonecast.estimator.rc.elements import MASSLESS_FACE_CAPACITY, discretise_layers
    from zonecast.estimator.rc.network import build_structure

    layout = discretise_layers(no_fc["site"].constructions["Slab F"].layers)
    assert (layout.capacities > 0).all() and layout.capacities[0] == MASSLESS_FACE_CAPACITY
    from zonecast.estimator.model import build_model

    st = build_structure(no_fc["site"], {"Z": ["Z"]}, {})
    assert np.isfinite(st.A0.toarray()).all()
    model = build_model(no_fc["site"], {"Z": ["Z"]}, {})
    a = model.structure.A(model.params.physical)
    a = a.toarray() if hasattr(a, "toarray") else np.asarray(a)
    assert np.isfinite(a).all() and np.linalg.eigvals(a).real.max() < 0
