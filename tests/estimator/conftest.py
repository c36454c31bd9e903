"""Shared fixtures for the estimator tests."""

from __future__ import annotations

import json
import sqlite3
import subprocess
from pathlib import Path

import pytest

#: NREL's example inputs, vendored with provenance in configs/sites/nrel
DATA = Path(__file__).resolve().parents[2] / "configs" / "sites" / "nrel"
FIVE_ZONE = DATA / "5ZoneAirCooled.idf"
SMALL_OFFICE = DATA / "RefBldgSmallOfficeNew2004_Chicago.idf"


def _need(path: Path) -> Path:
    if not path.is_file():
        raise FileNotFoundError(f"test building {path} is missing from the repository")
    return path


@pytest.fixture(scope="session")
def five_zone_path() -> Path:
    return _need(FIVE_ZONE)


@pytest.fixture(scope="session")
def small_office_path() -> Path:
    return _need(SMALL_OFFICE)


@pytest.fixture(scope="session")
def five_zone(five_zone_path):
    from zonecast.estimator.idf import read_building

    return read_building(five_zone_path)


@pytest.fixture(scope="session")
def small_office(small_office_path):
    from zonecast.estimator.idf import read_building

    return read_building(small_office_path)


def _energyplus_geometry(idf: Path, out: Path) -> dict:
    """Run EnergyPlus (design days only) with Output:SQLite; return its zone and surface tables."""
    from zonecast.estimator.idf import find_energyplus, load_epjson

    install = find_energyplus()
    data, _ = load_epjson(idf)
    data["Output:SQLite"] = {"Output:SQLite 1": {"option_type": "SimpleAndTabular"}}
    out.mkdir(parents=True, exist_ok=True)
    model = out / "in.epJSON"
    model.write_text(json.dumps(data))
    proc = subprocess.run(
        [str(install.binary), "-D", "-d", str(out), str(model)],
        capture_output=True, text=True, timeout=900, check=False,
    )
    sql = out / "eplusout.sql"
    assert sql.is_file(), proc.stdout[-3000:]
    con = sqlite3.connect(sql)
    zones = {
        r[0].upper(): {"volume": r[1], "floor_area": r[2]}
        for r in con.execute("SELECT ZoneName, Volume, FloorArea FROM Zones")
    }
    surfaces = {
        r[0].upper(): {"area": r[1], "gross_area": r[2], "azimuth": r[3], "tilt": r[4]}
        for r in con.execute("SELECT SurfaceName, Area, GrossArea, Azimuth, Tilt FROM Surfaces")
    }
    con.close()
    return {"zones": zones, "surfaces": surfaces}


@pytest.fixture(scope="session")
def energyplus_geometry():
    """Function running EnergyPlus on a file and returning its zone/surface geometry tables."""
    return _energyplus_geometry
