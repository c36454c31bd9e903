"""F-factor slabs and C-factor below-grade walls (ASHRAE 90.1's ratings, as the DOE prototype
buildings use them) read as the layered constructions EnergyPlus builds for them."""

from __future__ import annotations

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
    assert b.ground_temperature == tuple(float(m) for m in range(1, 13))
    assert any("FCfactorMethod" in n for n in b.notes)
