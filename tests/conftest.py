"""Shared fixtures: a small valid site and telemetry written by hand (no testbed)."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

SITE = {
    "building": "tiny",
    "idf": "building.idf",
    "timezone": "America/Los_Angeles",
    "location": {"latitude": 37.87, "longitude": -122.26},
    "step": "15min",
    "zones": {"A": ["Room_A1", "Room_A2"], "B": ["Room_B"]},
    "boxes": {"VAV-A1": {"room": "Room_A1", "airflow": {"point": "A1 flow", "unit": "L/s"}},
              "VAV-B": {"room": "Room_B", "airflow": "B flow"}},
    "points": {"zone_temperature": {"A": ["TA1", {"point": "TA2", "unit": "degF", "room": "Room_A2"}],
                                    "B": "TB"},
               "supply_air_temperature": {"point": "SAT", "unit": "degC"},
               "outdoor_air_temperature": "OAT",
               "solar": {"global_horizontal": "GHI", "direct_normal": "DNI",
                         "diffuse_horizontal": "DHI"}},
}


@pytest.fixture
def site_dict():
    return copy.deepcopy(SITE)


def write_site(tmp_path, data) -> Path:
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def telemetry_frame(n: int = 8, start: str = "2015-04-18T08:00:00-07:00") -> pd.DataFrame:
    t = pd.date_range(pd.Timestamp(start), periods=n, freq="15min")
    k = np.arange(n, dtype=float)
    return pd.DataFrame({
        "time": [x.isoformat() for x in t],
        "TA1": 21.0 + 0.1 * k, "TA2": 70.0 + 0.18 * k, "TB": 22.0 - 0.1 * k,
        "A1 flow": 100.0 + k, "B flow": 0.2 + 0.01 * k, "SAT": 13.0 + 0 * k, "OAT": 15.0 + k,
        "GHI": 300.0 + k, "DNI": 500.0 + k, "DHI": 100.0 + k})


@pytest.fixture
def telemetry_csv(tmp_path):
    def write(df: pd.DataFrame | None = None, name: str = "telemetry.csv"):
        df = telemetry_frame() if df is None else df
        path = tmp_path / name
        df.to_csv(path, index=False)
        return path
    return write
