"""The estimator's window shading against EnergyPlus's own sunlit fractions.

A free-floating box with three windows (south with an overhang and fins, east with an
overhang, west with a tilted overhang) and a detailed zone shading surface, rotated 20 deg,
run for two days in June and two in December; EnergyPlus reports each window's
"Surface Outside Face Sunlit Fraction" every 15 min, recomputed every day. The estimator
reads the same IDF (estimator/idf.py) and projects the same polygons
(estimator/shading.py) for the sun of each interval.
"""

from __future__ import annotations

import sqlite3

import numpy as np
import pandas as pd
import pytest
from zonecast.estimator.idf import read_building
from zonecast.estimator.shading import WindowShading, sun_vectors, sunlit_fraction
from zonecast.estimator.solar import sun_geometry
from zonecast.testbed.run import energyplus_dir, run_energyplus

pytestmark = pytest.mark.energyplus

LAT, LON, TZ, ELEV = 39.74, -105.18, -7.0, 1829.0  # Golden, CO
IDF = f"""
Version, 25.2;
SimulationControl, No, No, No, No, Yes, No, 1;
Building, Shadebox, 20, City, 0.04, 0.4, FullExterior, 25, 6;
Timestep, 4;
ShadowCalculation, PolygonClipping, Periodic, 1;
Site:Location, Golden, {LAT}, {LON}, {TZ}, {ELEV};
RunPeriod, June, 6, 20, 2015, 6, 21, 2015, , No, No, No, Yes, Yes, No, Hour24;
RunPeriod, December, 12, 20, 2015, 12, 21, 2015, , No, No, No, Yes, Yes, No, Hour24;
GlobalGeometryRules, UpperLeftCorner, Counterclockwise, Relative;
Material, Brick, Rough, 0.2, 0.9, 1900, 800;
WindowMaterial:SimpleGlazingSystem, Glass, 2.0, 0.4, 0.6;
Construction, Wall, Brick;
Construction, Win, Glass;
Zone, Box;
BuildingSurface:Detailed, S, Wall, Wall, Box, , Outdoors, , SunExposed, WindExposed, , 4,
    0, 0, 3, 0, 0, 0, 6, 0, 0, 6, 0, 3;
BuildingSurface:Detailed, E, Wall, Wall, Box, , Outdoors, , SunExposed, WindExposed, , 4,
    6, 0, 3, 6, 0, 0, 6, 5, 0, 6, 5, 3;
BuildingSurface:Detailed, N, Wall, Wall, Box, , Outdoors, , SunExposed, WindExposed, , 4,
    6, 5, 3, 6, 5, 0, 0, 5, 0, 0, 5, 3;
BuildingSurface:Detailed, W, Wall, Wall, Box, , Outdoors, , SunExposed, WindExposed, , 4,
    0, 5, 3, 0, 5, 0, 0, 0, 0, 0, 0, 3;
BuildingSurface:Detailed, F, Floor, Wall, Box, , Ground, , NoSun, NoWind, , 4,
    0, 0, 0, 0, 5, 0, 6, 5, 0, 6, 0, 0;
BuildingSurface:Detailed, R, Roof, Wall, Box, , Outdoors, , SunExposed, WindExposed, , 4,
    0, 5, 3, 0, 0, 3, 6, 0, 3, 6, 5, 3;
FenestrationSurface:Detailed, SWin, Window, Win, S, , autocalculate, , 1, 4,
    1, 0, 2.4, 1, 0, 0.9, 5, 0, 0.9, 5, 0, 2.4;
FenestrationSurface:Detailed, EWin, Window, Win, E, , autocalculate, , 1, 4,
    6, 1, 2.2, 6, 1, 1.0, 6, 4, 1.0, 6, 4, 2.2;
FenestrationSurface:Detailed, WWin, Window, Win, W, , autocalculate, , 1, 4,
    0, 4, 2.2, 0, 4, 1.0, 0, 1, 1.0, 0, 1, 2.2;
Shading:Overhang:Projection, SOver, SWin, 0.1, 90, 0.3, 0.3, 0.6;
Shading:Fin, SFins, SWin, 0.1, 0.2, 0.1, 90, 0.7, 0.1, 0.2, 0.1, 90, 0.5;
Shading:Overhang, EOver, EWin, 0.2, 90, 0.0, 0.5, 0.8;
Shading:Overhang, WOver, WWin, 0.0, 70, 0.2, 0.2, 1.0;
Shading:Zone:Detailed, Wing, W, , 4, 0, 0, 3, 0, 0, 0, -2, 0, 0, -2, 0, 3;
Output:SQLite, SimpleAndTabular;
Output:Variable, *, Surface Outside Face Sunlit Fraction, Timestep;
"""


@pytest.fixture(scope="module")
def energyplus_run(tmp_path_factory):
    work = tmp_path_factory.mktemp("shadebox")
    idf = work / "in.idf"
    idf.write_text(IDF)
    run_energyplus(idf, energyplus_dir() / "WeatherData" / "USA_CO_Golden-NREL.724666_TMY3.epw",
                   work)
    con = sqlite3.connect(work / "eplusout.sql")
    try:
        df = pd.read_sql_query(
            """select t.Month, t.Day, t.Hour, t.Minute, d.KeyValue, r.Value
               from ReportData r join Time t on r.TimeIndex = t.TimeIndex
               join ReportDataDictionary d
                 on d.ReportDataDictionaryIndex = r.ReportDataDictionaryIndex
               join EnvironmentPeriods e on e.EnvironmentPeriodIndex = t.EnvironmentPeriodIndex
               where e.EnvironmentType = 3 and (t.WarmupFlag = 0 or t.WarmupFlag is null)
                 and d.Name = 'Surface Outside Face Sunlit Fraction'""", con)
    finally:
        con.close()
    end = pd.to_datetime({"year": 2015, "month": df.Month, "day": df.Day}) \
        + pd.to_timedelta(df.Hour, unit="h") + pd.to_timedelta(df.Minute, unit="m")
    df["end"] = end
    wide = df.pivot_table(index="end", columns="KeyValue", values="Value")
    return idf, wide


def test_sunlit_fractions_match_energyplus(energyplus_run):
    idf, eplus = energyplus_run
    b = read_building(idf)
    assert {k.upper() for k in b.shading} == {"SWIN", "EWIN", "WWIN", "*"}
    # EnergyPlus shades a timestep with the sun of its reported instant (the interval's
    # end, standard time): compare there (geometry's midpoint = that instant)
    starts = (eplus.index - pd.Timedelta("7.5min")).tz_localize(f"Etc/GMT+{int(-TZ)}")
    geom = sun_geometry(starts.tz_convert("UTC"), pd.Timedelta("15min"), LAT, LON, ELEV)
    sun = sun_vectors(geom[1], geom[3])
    up = geom[1] < 88.0
    for name, w in b.windows.items():
        shades = b.shading.get(name, []) + b.shading.get("*", [])
        ws = WindowShading(name, 0, 1.0, w.vertices, shades)
        ours = sunlit_fraction(ws, sun)
        ref = eplus[name.upper()].to_numpy()
        lit = up & (sun @ ws._frame[3] > 0.05)  # the sun in front of the window
        assert lit.sum() > 20
        err = np.abs(ours[lit] - ref[lit])
        assert err.mean() < 0.003, (name, err.mean(), err.max())
        assert err.max() < 0.02, (name, err.max())
        assert np.ptp(ref[lit]) > 0.2  # the case shades for real
