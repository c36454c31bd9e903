"""The online service end to end: settings, model file, runner, REST API, replay over MQTT.

The virtual building (three EnergyPlus weeks, ~10 s) is simulated once per session. The
replay test sends the three weeks (2016 steps) through a real broker into the service,
with a service restart after the first week, and compares every forecast the service
issued with ``offline_forecasts`` on the same telemetry (1e-9).
"""

from __future__ import annotations

import json
from datetime import UTC, datetime

import numpy as np
import pandas as pd
import pytest

from tests.service.helpers import body_of, wait_until

TOKEN = "test-token-1"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
DAY = 96


def make_settings(tmp_path, vb, broker=None, **runner):
    from zonecast.service.settings import load_settings

    mqtt = {"mqtt_enabled": False}
    if broker is not None:
        mqtt = {"mqtt_enabled": True, "mqtt": {
            "host": broker.host, "port": broker.port, "username": broker.username,
            "protocol": "5" if broker.mqtt5 else "3.1.1",
            "client_id": f"zc-{tmp_path.name[-20:]}"}}
    return load_settings(storage_url=f"sqlite:///{tmp_path / 'zc.db'}", api_tokens=[TOKEN],
                         buildings={"office6": str(vb / "model.json")},
                         runner={"poll_interval": 0.05, "forecast_every": 1, "publish": False,
                                 **runner}, **mqtt)


def processed_through(app, t: str):
    """The runner has processed the row at ``t`` and finished its step (the row's forecast
    is set under the runner's lock, after the estimator's time moves on)."""
    target = pd.Timestamp(t).tz_convert("UTC")

    def done() -> bool:
        runner = app.state.zc.runners["office6"]
        with runner.lock:
            return (runner.est.time or pd.Timestamp(0, tz="UTC")) >= target
    return done


def assert_same_forecast(a, b, tol=1e-9):
    assert a.issued == b.issued
    assert (a.times == b.times).all()
    np.testing.assert_allclose(a.mean, b.mean, rtol=0, atol=tol)
    np.testing.assert_allclose(a.std, b.std, rtol=0, atol=tol)
    np.testing.assert_allclose(a.f_ig, b.f_ig, rtol=0, atol=tol)


# --------------------------------------------------------------------------- settings, files
def test_settings_yaml_then_environment_then_arguments(tmp_path, monkeypatch):
    from zonecast.service.settings import load_settings

    cfg = tmp_path / "service.yaml"
    cfg.write_text("storage_url: sqlite:///a.db\nmqtt: {host: broker, port: 1884}\n"
                   "api_tokens: [s3cr3t-xyz]\nbuildings: {office6: models/office6.json}\n"
                   "runner: {grace: 60}\n")
    monkeypatch.setenv("ZONECAST_MQTT__PORT", "1999")
    monkeypatch.setenv("ZONECAST_RUNNER__FORECAST_EVERY", "4")
    s = load_settings(cfg, storage_url="sqlite:///b.db")
    assert (s.mqtt.host, s.mqtt.port) == ("broker", 1999)
    assert s.runner.grace == 60 and s.runner.forecast_every == 4
    assert s.storage_url == "sqlite:///b.db"
    assert s.buildings["office6"] == tmp_path / "models" / "office6.json"
    assert [t.get_secret_value() for t in s.api_tokens] == ["s3cr3t-xyz"]
    assert s.api_tokens[next(iter(s.api_tokens))] == ("admin",) and "s3cr3t" not in repr(s)
    with pytest.raises(ValueError, match="not found"):
        load_settings(tmp_path / "missing.yaml")
    with pytest.raises(ValueError, match="letters, digits"):
        load_settings(buildings={"bad id": "x.json"})


def test_service_yaml_in_configs_is_valid(monkeypatch):
    from pathlib import Path

    from zonecast.service.settings import load_settings

    root = Path(__file__).resolve().parents[2]
    s = load_settings(root / "configs" / "service.yaml")
    assert "office6" in s.buildings
    for f in ("docker/compose.yaml", "configs/mosquitto.conf", "docker/Dockerfile"):
        assert (root / f).is_file(), f
    import yaml

    compose = yaml.safe_load((root / "docker" / "compose.yaml").read_text())
    assert {"zonecast", "mosquitto", "postgres"} <= set(compose["services"])


def test_catalogue_converts_plausible_ranges_to_the_wire_unit():
    from zonecast.service.context import catalogue_for_site

    class Site:  # catalogue_for_site only needs the point -> unit map
        def point_units(self):
            return {"T1": "degF", "T2": "degC", "F1": "L/s", "G": "kW/m2", "P": "kW", "PW": "W"}

    cat = catalogue_for_site(Site())
    assert cat["T1"].unit == "degF" and cat["T1"].kind.value == "temperature"
    assert (cat["T1"].low, cat["T1"].high) == (pytest.approx(-58), pytest.approx(176))
    assert (cat["T2"].low, cat["T2"].high) == (-50, 80)
    assert cat["F1"].high == pytest.approx(100 / 1.2e-3)
    assert cat["G"].high == pytest.approx(1.5)
    assert cat["P"].kind.value == "power" and (cat["P"].low, cat["P"].high) == (0, 1e5)
    assert cat["PW"].unit == "W" and cat["PW"].high == 1e8


# --------------------------------------------------------------------------- runner semantics
class FakeClock:
    def __init__(self, t):
        self.t = pd.Timestamp(t).to_pydatetime()

    def __call__(self):
        return self.t


def test_runner_waits_for_late_points_then_closes_by_watermark_or_idle(bundle, telemetry,
                                                                         tmp_path):
    from zonecast.service.context import catalogue_for_site
    from zonecast.service.ingest import validate_message
    from zonecast.service.runner import Runner
    from zonecast.service.settings import RunnerSettings
    from zonecast.service.storage import open_storage

    store = open_storage(f"sqlite:///{tmp_path / 'r.db'}")
    cats = {bundle.building: catalogue_for_site(bundle.site)}

    def put(row, drop=()):
        body = body_of(row)
        for p in drop:
            body["readings"].pop(p)
        msg = validate_message(f"zonecast/{bundle.building}/telemetry", json.dumps(body), cats)
        store.put_readings(bundle.building, msg.readings)

    rows = telemetry.iloc[:6]
    late = bundle.site.points.outdoor_air_temperature.point
    clock = FakeClock("2015-04-13T08:00:00Z")
    runner = Runner(bundle, store, RunnerSettings(grace=300, idle_timeout=1800,
                                                  forecast_every=4), clock=clock)
    meters = bundle.site.meter_points()
    assert meters
    put(rows.iloc[0], drop=meters)  # the meters are no part of a complete row
    put(rows.iloc[1], drop=[late])  # row 1 incomplete: its OAT comes late
    assert runner.poll() == 1  # row 0 complete; row 1 waits
    put(rows.iloc[2])  # watermark = row 2 < row 1 + 15 min + 5 min: still waiting
    assert runner.poll() == 0 and runner.est.time == pd.Timestamp(rows.iloc[0]["time"])
    put(rows.iloc[1])  # the late reading arrives (out of order): row 1 complete, then row 2
    assert runner.poll() == 2
    assert runner.last_report.held_inputs == []
    put(rows.iloc[3], drop=[late])
    put(rows.iloc[4])
    assert runner.poll() == 0  # row 3 incomplete, watermark row 4 is within its grace
    put(rows.iloc[5])  # watermark row 5 >= row 3 + 20 min: row 3 closes without OAT
    assert runner.poll() == 3
    assert runner.last_report.time == pd.Timestamp(rows.iloc[5]["time"])
    # idle: the last row, incomplete, is closed once nothing arrived for idle_timeout
    put(telemetry.iloc[6], drop=[late])
    assert runner.poll() == 0
    clock.t = pd.Timestamp("2030-01-01T00:00:00Z").to_pydatetime()
    assert runner.poll() == 1
    assert "v:Ta" in runner.last_report.held_inputs
    # the same rows offline (row 1 complete, rows 3 and 6 without OAT) give the same numbers
    from zonecast.estimator.streaming import offline_forecasts

    t4 = pd.Timestamp(telemetry.iloc[4]["time"]).tz_convert("UTC")
    got = [f for f in runner.history if f.issued == t4]
    assert len(got) == 1
    off = offline_forecasts(bundle, telemetry_si(bundle, telemetry.iloc[:7], drop_oat=[3, 6]),
                            [t4])
    assert_same_forecast(got[0], off[t4])
    store.close()


def test_a_backlog_is_checkpointed_per_chunk_and_resumes_to_the_same_state(bundle, telemetry,
                                                                           tmp_path):
    """130 stored rows are closed in two chunks (a day, then the rest), each followed by one
    checkpoint (not one per row); a runner resumed from the first chunk's checkpoint, as
    after a crash inside the second chunk, recomputes the second chunk from the stored
    readings to the same state and forecast, bit for bit, with the runner's settings (the
    thermostat model off) kept. Live, one row: one checkpoint."""
    from zonecast.service.context import catalogue_for_site
    from zonecast.service.ingest import validate_message
    from zonecast.service.runner import Runner, read_checkpoint
    from zonecast.service.settings import RunnerSettings
    from zonecast.service.storage import open_storage

    store = open_storage(f"sqlite:///{tmp_path / 'r.db'}")
    cats = {bundle.building: catalogue_for_site(bundle.site)}

    def put(row):
        msg = validate_message(f"zonecast/{bundle.building}/telemetry",
                               json.dumps(body_of(row)), cats)
        store.put_readings(bundle.building, msg.readings)

    saved = []
    save = store.save_checkpoint

    def counting_save(building, time, state, sync=True):
        saved.append((time, state))
        return save(building, time, state, sync=sync)

    store.save_checkpoint = counting_save
    for i in range(130):
        put(telemetry.iloc[i])
    # the thermostat model off: about checkpoints, and a third of the CPU
    settings = RunnerSettings(grace=300, idle_timeout=1800, forecast_every=4,
                              thermostat_forecast=False)
    clock = FakeClock("2015-04-20T00:00:00Z")
    first = Runner(bundle, store, settings, clock=clock)
    assert first.poll() == 130
    t = [pd.Timestamp(x).tz_convert("UTC") for x in telemetry["time"].iloc[:131]]
    assert [pd.Timestamp(c[0]) for c in saved] == [t[95], t[129]]
    assert read_checkpoint(saved[0][1])[0]["next_time"] == t[96].isoformat()
    # a crash inside the second chunk: the store still holds the first chunk's checkpoint
    save(bundle.building, saved[0][0], saved[0][1], sync=True)
    again = Runner(bundle, store, settings, clock=clock)
    assert again.next_time == t[96]
    assert again.poll() == 34
    assert np.array_equal(again.est.x, first.est.x)
    # the runner's setting survives the checkpoint's load (it was reset to the default)
    assert again.est.reheat_control is False
    assert_same_forecast(again.est.forecast(), first.est.forecast(), tol=0)
    saved.clear()
    put(telemetry.iloc[130])  # live: one row, one checkpoint
    assert again.poll() == 1 and [pd.Timestamp(c[0]) for c in saved] == [t[130]]


def test_meter_readings_ahead_of_the_temperatures_do_not_close_rows(bundle, telemetry,
                                                                     tmp_path):
    """The lights and plug-load meters may come from another system, ahead of the BMS's
    points: their readings are no watermark, so a row waiting for a straggler still waits
    (before, meters two hours ahead closed it without its outdoor air temperature)."""
    from zonecast.service.context import catalogue_for_site
    from zonecast.service.ingest import validate_message
    from zonecast.service.runner import Runner
    from zonecast.service.settings import RunnerSettings
    from zonecast.service.storage import open_storage

    store = open_storage(f"sqlite:///{tmp_path / 'r.db'}")
    cats = {bundle.building: catalogue_for_site(bundle.site)}
    meters = bundle.site.meter_points()
    assert len(meters) >= 2

    def put(row, keep=None, drop=()):
        body = body_of(row)
        body["readings"] = {p: v for p, v in body["readings"].items()
                            if (keep is None or p in keep) and p not in drop}
        msg = validate_message(f"zonecast/{bundle.building}/telemetry", json.dumps(body), cats)
        store.put_readings(bundle.building, msg.readings)

    late = bundle.site.points.outdoor_air_temperature.point
    runner = Runner(bundle, store, RunnerSettings(grace=300, idle_timeout=1800),
                    clock=FakeClock("2015-04-13T08:00:00Z"))
    put(telemetry.iloc[0])
    put(telemetry.iloc[1], drop=[late])
    for i in range(2, 10):  # the meters run two hours ahead
        put(telemetry.iloc[i], keep=meters)
    assert runner.poll() == 1 and runner.next_time == pd.Timestamp(telemetry.iloc[1]["time"])
    put(telemetry.iloc[1])  # the straggler arrives: row 1 is complete
    put(telemetry.iloc[2])
    assert runner.poll() == 2
    assert runner.last_report.held_inputs == [] and runner.late_readings == 0
    store.close()


def telemetry_si(bundle, rows: pd.DataFrame, drop_oat=()):
    """Rows of the CSV as an SI frame (the virtual building's units are SI)."""
    frame = rows.set_index(pd.to_datetime(rows["time"], format="ISO8601", utc=True))
    frame = frame.drop(columns="time").astype(float)
    oat = bundle.site.points.outdoor_air_temperature.point
    for i in drop_oat:
        frame.iloc[i, frame.columns.get_loc(oat)] = np.nan
    return frame


def test_checkpoint_round_trip_is_exact(bundle, telemetry):
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tt, u, v, y = rows_from_frame(bundle, telemetry_si(bundle, telemetry.iloc[:12]))
    a = OnlineEstimator(bundle)
    for k in range(8):
        a.advance(tt[k], u[k], v[k], y[k])
    b = OnlineEstimator(bundle)
    b.load_bytes(a.to_bytes())
    y2 = y.copy()
    y2[9, 1:] = np.nan  # a partial measurement
    for k in range(8, 12):
        a.advance(tt[k], u[k], v[k], y2[k])
        b.advance(tt[k], u[k], v[k], y2[k])
    assert np.array_equal(a.x, b.x)
    assert all(np.array_equal(p, q) for p, q in zip(a.zone_estimate(), b.zone_estimate()))
    assert_same_forecast(a.forecast(), b.forecast(), tol=0)
    with pytest.raises(ValueError, match="not after"):
        a.advance(tt[3], u[3], v[3], y[3])


def test_loading_a_checkpoint_keeps_the_owners_settings(bundle, telemetry):
    """The forecasting settings an owner sets (the runner's thermostat_forecast, ...) are
    not state: loading a checkpoint keeps them (it reset them to the defaults)."""
    from zonecast.estimator.streaming import (
        _SETTINGS_KEPT_ON_LOAD,
        OnlineEstimator,
        rows_from_frame,
    )

    tt, u, v, y = rows_from_frame(bundle, telemetry_si(bundle, telemetry.iloc[:4]))
    a = OnlineEstimator(bundle)
    for k in range(4):
        a.advance(tt[k], u[k], v[k], y[k])
    b = OnlineEstimator(bundle)
    mine = {}
    for name in _SETTINGS_KEPT_ON_LOAD:
        value = getattr(b, name)
        mine[name] = (not value if isinstance(value, bool)
                      else value * 2 if value else pd.Timedelta(hours=1))
        setattr(b, name, mine[name])
    b.load_bytes(a.to_bytes())
    assert {name: getattr(b, name) for name in mine} == mine
    assert np.array_equal(b.x, a.x)


def test_step_report_innovation_is_the_one_the_filter_scored(bundle, telemetry):
    """The innovation a step reports (the /health RMS) is the filter's: its NIS with the
    innovation covariance of the filter that scored it is the step's NIS (the young
    filter's S_j while every zone is measured since the start, then the steady-state
    filter's H P H' + R of the observed zones), and it is NaN exactly for the zones
    without a measurement."""
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    frame = telemetry_si(bundle, telemetry.iloc[:40])
    times, u, v, y = rows_from_frame(bundle, frame)
    y = y.copy()
    y[20:25, 1] = np.nan  # zone 1 unobserved for five rows
    est = OnlineEstimator(bundle)
    filt = est._steady.filt
    first = est.advance(times[0], u[0], v[0], y[0])
    assert np.isnan(first.innovation).all()  # the row that starts the filter
    for k in range(1, len(times)):
        rep = est.advance(times[k], u[k], v[k], y[k])
        obs = np.isfinite(y[k])
        assert (np.isfinite(rep.innovation) == obs).all()
        nu = rep.innovation[obs]
        if k < 20:  # the young filter's step k (its gains computed at the start)
            S = est._yf.S[k - 1]
        else:  # zone 1 missing at row 20 handed over to the steady-state filter
            S = filt.H[obs] @ filt.P @ filt.H[obs].T + filt.R[np.ix_(obs, obs)]
        assert nu @ np.linalg.solve(S, nu) == pytest.approx(rep.nis, rel=1e-9)
    assert est._yf.steps >= 20 and est._young is None


def test_state_std_without_measurements_follows_the_forecast_std(bundle, telemetry):
    """Steps without any measurement are predictions: the state's standard deviation
    after k of them is the forecast's at horizon k, and grows."""
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tt, u, v, y = rows_from_frame(bundle, telemetry_si(bundle, telemetry.iloc[:14]))
    est = OnlineEstimator(bundle)
    est.young_filter = False  # the steady-state filter's (the young one's: the next test)
    for k in range(10):
        est.advance(tt[k], u[k], v[k], y[k])
    fc = est.forecast()
    std0 = est.zone_estimate()[1]
    for k in range(10, 13):
        est.advance(tt[k], u[k], v[k], np.full_like(y[k], np.nan))
        np.testing.assert_array_equal(est.zone_estimate()[1], fc.std[k - 10])
    assert (est.zone_estimate()[1] > std0).all()
    partial = y[13].copy()
    partial[0] = np.nan
    est.advance(tt[13], u[13], v[13], partial)
    std = est.zone_estimate()[1]
    # the unobserved zone is less certain; the others lose a little of the cross-information
    assert std[0] > std0[0] and std[0] > std[1:].max() and (std[1:] >= std0[1:] - 1e-12).all()


def test_young_filter_after_a_start_then_the_steady_one(bundle, telemetry):
    """After a start the filter takes the young gains (the time-varying filter from the
    initial covariance, all zones measured): its state differs from the steady filter's,
    its zone std shrinks towards the steady filter's and stays above it; with
    ``young_std`` its forecast std is at least the steady one (without it, the steady one,
    the state's std unchanged); steps without a measurement follow the young forecast's
    std; a missing zone hands over to the steady filter; a checkpoint in the middle of
    the young steps continues bitwise."""
    from zonecast.estimator.streaming import OnlineEstimator, rows_from_frame

    tt, u, v, y = rows_from_frame(bundle, telemetry_si(bundle, telemetry.iloc[:40]))
    est = OnlineEstimator(bundle)
    est.young_std = True  # the young filter's forecast std too (not the default)
    steady = OnlineEstimator(bundle)
    steady.young_filter = False
    est.advance(tt[0], u[0], v[0], y[0])
    steady.advance(tt[0], u[0], v[0], y[0])
    yf = est._yf
    assert yf is not None and yf.steps > 12
    ss_zone = np.sqrt(np.diag(est._steady.filt.output_covariance()))
    ss_fc = np.sqrt(est._steady.horizon_var)
    stds = []
    for k in range(1, 10):
        est.advance(tt[k], u[k], v[k], y[k])
        steady.advance(tt[k], u[k], v[k], y[k])
        assert est._young == k
        stds.append(est.zone_estimate()[1])
        assert (stds[-1] >= ss_zone - 1e-9).all()
        assert not np.array_equal(est.x, steady.x)  # the gains differ
    assert (stds[-1] < stds[0]).all()  # converging towards the steady filter's
    mid = OnlineEstimator(bundle)
    mid.load_bytes(est.to_bytes())
    fc = est.forecast()
    assert (fc.std >= ss_fc - 1e-9).all() and (fc.std > ss_fc + 1e-6).any()
    mid.young_std = False  # the steady filter's forecast std with the young gains
    assert np.array_equal(mid.forecast().std, ss_fc) and np.array_equal(mid.x, est.x)
    # the state's std is the young filter's either way
    np.testing.assert_array_equal(mid.zone_estimate()[1], stds[-1])
    mid.young_std = True
    for k in range(10, 13):  # no measurement: predictions from the young update
        est.advance(tt[k], u[k], v[k], np.full_like(y[k], np.nan))
        np.testing.assert_array_equal(est.zone_estimate()[1], fc.std[k - 10])
    partial = y[13].copy()
    partial[0] = np.nan
    est.advance(tt[13], u[13], v[13], partial)
    assert est._young is None and est._young_seen is None  # steady from here on
    # the checkpoint taken at step 9 continues exactly as the original did
    for k in range(10, 14):
        mid.advance(tt[k], u[k], v[k], y[k] if k < 10 else (
            np.full_like(y[k], np.nan) if k < 13 else partial))
    assert np.array_equal(mid.x, est.x)


def test_forecast_with_supplied_inputs(bundle, telemetry, tmp_path):
    """Supplied horizon inputs replace the served input forecasts; the default forecast
    is that of :meth:`forecast_inputs` bitwise, the persistence reference that of the
    measured rows 24 h earlier; bad shapes are refused."""
    from zonecast.estimator.streaming import OnlineEstimator, model_rows, offline_forecasts

    frame = telemetry_si(bundle, telemetry.iloc[:2 * DAY + 10])
    d = model_rows(bundle, frame)
    tt, u, v, y, rh = d.times, d.u, d.v, d.y, d.reheat
    est = OnlineEstimator(bundle)
    for k in range(len(tt)):
        est.advance(tt[k], u[k], v[k], y[k], rh[k])
    k = len(tt) - 1
    # inputs: u, v, then the boxes' discharge-air rise (the virtual building reports it)
    persistence = np.vstack([np.hstack([u[k], v[k], rh[k]])]
                            + [np.hstack([u[k - DAY + h], v[k - DAY + h], rh[k - DAY + h]])
                               for h in range(1, DAY)])
    assert np.array_equal(est.persistence_inputs(), persistence)
    served = est.forecast()
    # (the served forecast's reheat is its thermostat model's when reheat_control is on)
    again = est.forecast(est.forecast_inputs(), thermostat_reheat=est.reheat_control)
    assert np.array_equal(served.mean, again.mean) and np.array_equal(served.std, again.std)
    a, b = est.forecast(est.persistence_inputs()), est.forecast(persistence)
    assert np.array_equal(a.mean, b.mean) and np.array_equal(a.std, b.std)
    warmer = persistence.copy()
    warmer[:, bundle.model.n_boxes] += 5.0  # outdoor air 5 K warmer all day
    c = est.forecast(warmer)
    assert (c.mean[-1] > a.mean[-1]).all()
    with pytest.raises(ValueError, match="inputs must be finite with shape"):
        est.forecast(persistence[:10])
    off = offline_forecasts(bundle, frame, [tt[k]], inputs={tt[k]: warmer})[tt[k]]
    assert np.array_equal(off.mean, c.mean)


# --------------------------------------------------------------------------- REST
def test_every_endpoint_but_health_needs_a_valid_token(tmp_path, vb):
    from fastapi.testclient import TestClient
    from zonecast.service.app import create_app

    app = create_app(make_settings(tmp_path, vb))
    paths = ["/api/v1/buildings", "/api/v1/buildings/office6", "/api/v1/buildings/office6/state",
             "/api/v1/buildings/office6/internal-gains", "/api/v1/buildings/office6/forecast",
             "/api/v1/buildings/office6/history", "/api/v1/buildings/office6/health",
             "/api/v1/buildings/office6/diagnosis", "/api/v1/buildings/office6/gaps", "/metrics"]
    with TestClient(app) as client:
        for p in paths:
            for headers in ({}, {"Authorization": "Bearer wrong"}, {"Authorization": "Basic x"}):
                r = client.get(p, headers=headers)
                assert r.status_code == 401, (p, headers, r.text)
                assert r.headers["www-authenticate"] == "Bearer"
                assert "token" in r.json()["detail"]
        r = client.post("/api/v1/buildings/office6/telemetry", json={"readings": {}})
        assert r.status_code == 401
        r = client.post("/api/v1/buildings/office6/weather_forecast", json={})
        assert r.status_code == 401
        assert client.get("/healthz").json() == {"status": "ok"}
        assert client.get("/readyz").json()["ready"] is True
        spec = client.get("/openapi.json").json()
    ops = {(path, m): op for path, item in spec["paths"].items() for m, op in item.items()}
    assert len(ops) == 15  # /ui and its files are not in the spec
    for (path, method), op in ops.items():
        assert bool(op.get("security")) == (path not in ("/healthz", "/readyz")), path


def test_rest_ingest_state_gains_forecast(tmp_path, vb, bundle, telemetry):
    import gc

    from fastapi.testclient import TestClient
    from zonecast.estimator.streaming import offline_forecasts
    from zonecast.service.app import create_app

    app = create_app(make_settings(tmp_path, vb, forecast_every=4))
    n = 9
    with TestClient(app) as client:
        assert gc.get_freeze_count() > 0  # start-up objects are out of the collector's way
        for i in range(n):
            r = client.post("/api/v1/buildings/office6/telemetry", json=body_of(telemetry.iloc[i]),
                            headers=AUTH)
            assert r.status_code == 200, r.text
            assert r.json()["stored"] == len(telemetry.columns) - 1
        again = client.post("/api/v1/buildings/office6/telemetry",
                            json=body_of(telemetry.iloc[0]), headers=AUTH).json()
        assert again["stored"] == 0 and again["duplicates"] == len(telemetry.columns) - 1
        wait_until(processed_through(app, telemetry.iloc[n - 1]["time"]), what="runner")
        st = client.get("/api/v1/buildings/office6/state", headers=AUTH).json()
        assert st["last_update"] == pd.Timestamp(telemetry.iloc[n - 1]["time"]).tz_convert(
            "UTC").isoformat().replace("+00:00", "Z")
        assert [z["zone"] for z in st["zones"]] == bundle.zones
        assert all(0 < z["std"] < 1 and abs(z["temperature"] - z["measured"]) < 1
                   for z in st["zones"])
        assert "stale" in st["quality"] and st["steps"] == n - 1
        g = client.get("/api/v1/buildings/office6/internal-gains", headers=AUTH).json()
        assert len(g["zones"][0]["profile"]) == 672
        assert g["zones"][0]["profile"][0] == 0.5
        f = client.get("/api/v1/buildings/office6/forecast", params={"horizon": "6h"},
                       headers=AUTH).json()
        assert len(f["times"]) == 24 and len(f["zones"][0]["mean"]) == 24
        z = f["zones"][0]
        assert all(lo < m < hi for lo, m, hi in zip(z["lower"], z["mean"], z["upper"]))
        assert f["model_version"] == bundle.version
        for bad, msg in [("25h", "up to 24h"), ("7min", "multiple of 15 min"),
                         ("soon", "not a duration")]:
            r = client.get("/api/v1/buildings/office6/forecast", params={"horizon": bad},
                           headers=AUTH)
            assert r.status_code == 422 and msg in r.json()["detail"]
        # rejections: whole message and per reading, with reasons
        r = client.post("/api/v1/buildings/office6/telemetry", content=b"{oops", headers=AUTH)
        assert r.status_code == 422 and r.json()["detail"].startswith("malformed_json")
        # nothing accepted: 422 with every reading's reason; something accepted: 200
        r = client.post("/api/v1/buildings/office6/telemetry", headers=AUTH, json={
            "time": "2015-04-13T03:00:00-07:00", "readings": {"OAT": "warm", "nope": 1}})
        assert r.status_code == 422
        assert sorted(x["reason"] for x in r.json()["rejected"]) == ["unknown_point", "wrong_type"]
        assert r.json()["detail"].startswith("no reading accepted: ")
        r = client.post("/api/v1/buildings/office6/telemetry", headers=AUTH, json={
            "time": "2015-04-13T03:00:00-07:00", "readings": {"OAT": 11.5, "nope": 1}})
        assert r.status_code == 200 and r.json()["stored"] == 1
        assert [x["reason"] for x in r.json()["rejected"]] == ["unknown_point"]
        r = client.post("/api/v1/buildings/office6/telemetry", headers=AUTH,
                        content=b"x" * (2 * 1024 * 1024))
        assert r.status_code == 413
        assert client.get("/api/v1/buildings/elsewhere", headers=AUTH).status_code == 404
        issued = f["issued"]
        metrics = client.get("/metrics", headers=AUTH).text
        assert 'zonecast_rejected_total{reason="unknown_point",transport="rest"} 2.0' in metrics
        assert "zonecast_step_latency_seconds_count" in metrics
        assert "zonecast_nis_per_dof" in metrics
    assert gc.get_freeze_count() == 0  # released at shutdown
    off = offline_forecasts(bundle, telemetry_si(bundle, telemetry.iloc[:n]), [issued])
    got = app.state.zc.runners["office6"].forecast
    assert_same_forecast(got, off[pd.Timestamp(issued)])


# --------------------------------------------------------------------------- replay
@pytest.mark.slow
def test_replay_three_weeks_through_broker_with_restart_equals_offline(tmp_path, vb, bundle,
                                                                       telemetry, broker):
    """Week 1 is replayed into a running service; the service stops; weeks 2-3 are
    replayed while it is down (the broker queues them on the persistent session) and with
    the CLI; a new service resumes from the checkpoint. Every reading is stored exactly
    once and every forecast equals the offline one within 1e-9."""
    from fastapi.testclient import TestClient
    from typer.testing import CliRunner
    from zonecast.estimator.streaming import offline_forecasts
    from zonecast.service.app import create_app
    from zonecast.service.replay import replay
    from zonecast.service.settings import MqttSettings

    from zonecast.cli import app as cli

    settings = make_settings(tmp_path, vb, broker, forecast_every=8)
    pub = MqttSettings(host=broker.host, port=broker.port, username=broker.username,
                       protocol="5" if broker.mqtt5 else "3.1.1")
    t = [pd.Timestamp(x) for x in telemetry["time"]]
    first, total = 7 * DAY, 21 * DAY
    assert len(t) >= total, "the vb fixture must hold three weeks"
    split, end = t[first], t[total - 1] + pd.Timedelta("15min")
    issued = []
    app = create_app(settings)
    with TestClient(app):
        res = replay(vb, pub, "office6", end=split, client_id="zc-replay-1")
        assert res["messages"] == first
        wait_until(processed_through(app, telemetry.iloc[first - 1]["time"]), 300, "week 1")
        issued += list(app.state.zc.runners["office6"].history)
    # service down: weeks 2-3 are published meanwhile, with the CLI
    out = CliRunner().invoke(cli, ["replay", "--data", str(vb), "--building", "office6",
                                   "--broker", f"mqtt://{broker.host}:{broker.port}",
                                   "--start", split.isoformat(), "--end", end.isoformat(),
                                   "--username", broker.username,
                                   "--protocol", pub.protocol])
    assert out.exit_code == 0, out.output
    assert f"published {total - first} messages" in out.output
    app2 = create_app(settings)
    with TestClient(app2) as client:
        runner = app2.state.zc.runners["office6"]
        # resumed from the checkpoint (the queued weeks may already be flowing in, so the
        # filter's time at this line can be past it)
        assert runner.resumed_from == t[first - 1].tz_convert("UTC")
        wait_until(processed_through(app2, telemetry.iloc[total - 1]["time"]), 600, "weeks 2-3")
        issued += list(runner.history)
        stored = app2.state.zc.storage.readings("office6", t[0], end)
        st = client.get("/api/v1/buildings/office6/state", headers=AUTH).json()
    n_points = len(bundle.site.point_units())
    assert stored.shape == (total, n_points) and stored.notna().all().all()
    expect = telemetry_si(bundle, telemetry.iloc[:total])[stored.columns]
    np.testing.assert_array_equal(stored.to_numpy(), expect.to_numpy())
    assert st["steps"] == total - 1  # every step once: nothing lost, nothing repeated
    assert len(issued) == total // 8
    assert len({f.issued for f in issued}) == len(issued)
    # every issued forecast (incl. the last before and the first after the restart)
    # against the offline pipeline
    offline = offline_forecasts(bundle, telemetry_si(bundle, telemetry.iloc[:total]),
                                [f.issued for f in issued])
    for f in issued:
        assert_same_forecast(f, offline[f.issued])


def test_state_and_forecast_are_published_retained_over_mqtt(tmp_path, vb, bundle, telemetry,
                                                              broker):
    """With ``runner.publish`` the retained forecast on MQTT is the REST forecast body, and
    the retained state is the latest step's."""
    import threading
    import uuid

    import paho.mqtt.client as mqtt
    from fastapi.testclient import TestClient
    from paho.mqtt.enums import CallbackAPIVersion
    from zonecast.estimator.streaming import offline_forecasts
    from zonecast.service.app import create_app

    settings = make_settings(tmp_path, vb, broker, forecast_every=4, publish=True)
    prefix = f"zc{uuid.uuid4().hex[:8]}"
    settings = settings.model_copy(update={"mqtt": settings.mqtt.model_copy(
        update={"topic_prefix": prefix})})
    n = 9
    app = create_app(settings)
    with TestClient(app) as client:
        for i in range(n):
            r = client.post("/api/v1/buildings/office6/telemetry", json=body_of(telemetry.iloc[i]),
                            headers=AUTH)
            assert r.status_code == 200, r.text
        wait_until(processed_through(app, telemetry.iloc[n - 1]["time"]), what="runner")
        rest = client.get("/api/v1/buildings/office6/forecast", headers=AUTH).json()
        got: dict[str, dict] = {}
        both = threading.Event()
        last = pd.Timestamp(telemetry.iloc[n - 1]["time"]).tz_convert("UTC")

        def on_message(c, u, msg):
            # the last step's state may still be on its way when we subscribe: the retained
            # message is then the step before, and the last one follows as a live message
            got[msg.topic.rsplit("/", 1)[-1]] = json.loads(msg.payload)
            state = got.get("state", {}).get("last_update")
            fc = got.get("forecast", {}).get("issued")  # likewise the last forecast
            if fc == rest["issued"] and state is not None and pd.Timestamp(state) == last:
                both.set()

        sub = mqtt.Client(callback_api_version=CallbackAPIVersion.VERSION2,
                          client_id=f"sub-{uuid.uuid4().hex[:8]}",
                          protocol=mqtt.MQTTv5 if broker.mqtt5 else mqtt.MQTTv311)
        sub.username_pw_set(broker.username, "secret")
        sub.on_message = on_message
        sub.connect(broker.host, broker.port)
        sub.loop_start()
        try:
            sub.subscribe([(f"{prefix}/office6/state", 1), (f"{prefix}/office6/forecast", 1)])
            assert both.wait(20), f"retained messages not received: {sorted(got)}"
        finally:
            sub.disconnect()
            sub.loop_stop()
    assert got["forecast"] == rest and len(rest["times"]) == 96
    assert pd.Timestamp(got["state"]["last_update"]) == last and got["state"]["steps"] == n - 1
    issued = pd.Timestamp(rest["issued"])
    off = offline_forecasts(bundle, telemetry_si(bundle, telemetry.iloc[:n]), [issued])[issued]
    np.testing.assert_allclose(np.array([z["mean"] for z in rest["zones"]]).T, off.mean,
                               rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- weather forecasts
def _body(issued: str, hours: int = 36, warm: float = 0.0) -> dict:
    t = pd.date_range(pd.Timestamp(issued), periods=hours + 1, freq="1h")
    hod = np.asarray(t.hour, float)
    sun = np.clip(np.sin((hod - 14) / 24 * 2 * np.pi + np.pi / 2), 0, None)  # UTC noon ~ 20h
    return {"issued": pd.Timestamp(issued).isoformat(), "source": "test",
            "times": [x.isoformat() for x in t],
            "temperature": (14.0 + warm + 3 * sun).tolist(), "ghi": (700 * sun).tolist(),
            "dni": (600 * sun).tolist(), "dhi": (100 * sun).tolist()}


def test_accept_weather_gives_reasons_and_dead_letters():
    from zonecast.service.weather import accept_weather, is_weather_topic

    now = datetime(2015, 4, 14, tzinfo=UTC)
    ok = accept_weather("zc/office6/weather_forecast", json.dumps(_body("2015-04-14T06:00Z")),
                        now, {"office6"}, prefix="zc")
    assert ok.forecast is not None and ok.reason is None and not ok.dead_letters
    assert is_weather_topic("zc/office6/weather_forecast", "zc")
    assert not is_weather_topic("zc/office6/telemetry", "zc")
    cases = {"unknown_building": ("zc/other/weather_forecast", json.dumps(_body("2015-04-14T06:00Z"))),
             "bad_topic": ("zc/office6/weather", "{}"),
             "malformed_json": ("zc/office6/weather_forecast", "{nope"),
             "absurd_value": ("zc/office6/weather_forecast",
                              json.dumps({**_body("2015-04-14T06:00Z"),
                                          "temperature": [99.0] * 37})),
             "future_time": ("zc/office6/weather_forecast", json.dumps(_body("2015-04-20T06:00Z")))}
    for reason, (topic, payload) in cases.items():
        acc = accept_weather(topic, payload, now, {"office6"}, prefix="zc")
        assert acc.forecast is None and acc.reason == reason, (reason, acc)
        assert len(acc.dead_letters) == 1
        assert acc.dead_letters[0]["reason"].startswith(f"bad_weather_forecast: {reason}")


def test_rest_weather_forecast_is_used_and_survives_a_restart(tmp_path, vb, bundle, telemetry):
    """POST a forecast: 200, GET shows it, the served forecast differs from the fallback
    one; a warmer forecast gives a warmer zone forecast; it survives a restart
    (checkpoint); a bad one is 422 and dead-lettered."""
    from fastapi.testclient import TestClient
    from zonecast.estimator.weather_forecast import WEATHER_DEFAULTS
    from zonecast.service.app import create_app

    n = 9
    t_last = pd.Timestamp(telemetry.iloc[n - 1]["time"]).tz_convert("UTC")
    issued = t_last.floor("6h")
    settings = make_settings(tmp_path, vb, forecast_every=1)
    app = create_app(settings)
    with TestClient(app) as client:
        for i in range(n):
            r = client.post("/api/v1/buildings/office6/telemetry",
                            json=body_of(telemetry.iloc[i]), headers=AUTH)
            assert r.status_code == 200
        wait_until(processed_through(app, telemetry.iloc[n - 1]["time"]), what="runner")
        assert client.get("/api/v1/buildings/office6/weather_forecast",
                          headers=AUTH).status_code == 404
        runner = app.state.zc.runners["office6"]
        with runner.lock:
            fallback = runner.est.forecast()
        r = client.post("/api/v1/buildings/office6/weather_forecast",
                        json=_body(issued.isoformat()), headers=AUTH)
        assert r.status_code == 200, r.text
        assert r.json()["in_use"] is True and r.json()["points"] == 37
        got = client.get("/api/v1/buildings/office6/weather_forecast", headers=AUTH).json()
        assert got["issued"] == issued.isoformat() and got["source"] == "test"
        with runner.lock:
            ins, from_wf = runner.est.weather_inputs()
            cool = runner.est.forecast()
        assert from_wf[1:].all() and not np.array_equal(cool.mean, fallback.mean)
        r = client.post("/api/v1/buildings/office6/weather_forecast",
                        json=_body(issued.isoformat(), warm=8.0), headers=AUTH)
        assert r.status_code == 200
        with runner.lock:
            warm_ins, _ = runner.est.weather_inputs()
            warm = runner.est.forecast()
        # 8 K warmer, less the part the measured temperature corrects (it decays with lead)
        lead_h = np.arange(1, len(ins)) * 0.25
        np.testing.assert_allclose(warm_ins[1:, 0] - ins[1:, 0],
                                   8.0 * (1.0 - np.exp(-lead_h / WEATHER_DEFAULTS["obs_tau_h"])),
                                   atol=1e-9)
        assert warm_ins[-1, 0] - ins[-1, 0] > 7.8  # a day ahead: nearly the forecast alone
        assert warm.mean[-1].mean() > cool.mean[-1].mean()  # the HVAC forecast reacts too
        bad = client.post("/api/v1/buildings/office6/weather_forecast",
                          json={**_body(issued.isoformat()), "ghi": [1.0]}, headers=AUTH)
        assert bad.status_code == 422 and "length_mismatch" in bad.json()["detail"]
        letters = app.state.zc.storage.dead_letters(building="office6")
        assert any("bad_weather_forecast: length_mismatch" in d.reason for d in letters)
    app = create_app(settings)
    with TestClient(app) as client:
        runner = app.state.zc.runners["office6"]
        assert runner.est.weather is not None and runner.est.weather.issued == issued
        with runner.lock:
            again = runner.est.forecast()
        np.testing.assert_array_equal(again.mean, warm.mean)
