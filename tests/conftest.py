"""Shared fixtures: a small valid site and telemetry written by hand (no testbed), and three
weeks of the virtual building with a model file (testbed, real EnergyPlus) for the tests that
need real data."""

from __future__ import annotations

import copy
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from threadpoolctl import threadpool_limits

# One BLAS thread per test process unless OPENBLAS_NUM_THREADS says otherwise, as every
# `zonecast` command does (zonecast/cli.py): `make test` runs a worker per core, and each
# worker's OpenBLAS threads then only contend with the other worker's (docs/benchmarks.md,
# "The test suite's time")
if "OPENBLAS_NUM_THREADS" not in os.environ:
    threadpool_limits(1, user_api="blas")


def pytest_collection_modifyitems(session, config, items):
    """Start the service-only environment of tests/test_serve_without_energyplus.py in the
    background as soon as its test is selected."""
    if any(item.module.__name__.endswith("test_serve_without_energyplus") for item in items
           if getattr(item, "module", None) is not None):
        from tests.serve_only_env import start_background_build
        start_background_build(config)


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


# --------------------------------------------------------------------------- virtual building
@pytest.fixture(scope="session")
def vb(tmp_path_factory):
    """Three consecutive virtual-building weeks (real EnergyPlus, ~10 s) and a model file
    (with its structure .npz) with gamma_IW = 9 and a weekly internal-gains profile
    (6 W/m2 on weekdays 8-18 h, else 0.5 W/m2)."""
    import datetime as dt

    import numpy as np
    from zonecast.estimator.artifact import write_model_file
    from zonecast.estimator.pipeline import Pipeline
    from zonecast.testbed.run import run_weeks

    out = tmp_path_factory.mktemp("vb")
    run_weeks([dt.date(2015, 4, 13), dt.date(2015, 4, 20), dt.date(2015, 4, 27)], out, seed=3)
    pipe = Pipeline.from_site(out / "site.yaml")
    zones = list(pipe.site.zones)
    bins = np.arange(672)
    office = ((bins % 96) >= 32) & ((bins % 96) < 72) & (bins < 480)
    values = np.where(office[:, None], 6.0, 0.5) * np.ones((1, len(zones)))
    write_model_file(out / "model.json", out / "site.yaml", parameters={"gamma_IW": 9.0},
                     weekly_profile={"zones": zones, "values": values.tolist()},
                     structure=pipe.structure(), room_volume=pipe.room_volume)
    return out


@pytest.fixture(scope="session")
def bundle(vb):
    from zonecast.estimator.artifact import load_model_file

    return load_model_file(vb / "model.json")


@pytest.fixture(scope="session")
def telemetry(vb):
    import pandas as pd

    return pd.read_csv(vb / "telemetry.csv", dtype={"time": str})


@pytest.fixture(scope="session")
def paper_campaign(tmp_path_factory, worker_id):
    """The default campaign (``run_campaign(seed=0)``: office6, 11 weeks, real EnergyPlus,
    ~25 s) made once for every pytest-xdist worker of the run (a file lock in the run's
    shared temporary folder); read-only for the tests that use it."""
    import fcntl

    from zonecast.testbed.run import run_campaign

    root = tmp_path_factory.getbasetemp()
    if worker_id != "master":  # the workers' folders share the run's folder
        root = root.parent
    out = root / "paper-campaign-seed0"
    with open(root / "paper-campaign-seed0.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # the other workers wait for the first
        if not (out / ".complete").is_file():
            run_campaign(out, seed=0)
            (out / ".complete").touch()
    return out
