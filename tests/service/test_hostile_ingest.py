"""Issue 14: ingest that cannot be poisoned, stalled or spoofed.

Poison messages (values and times that used to raise inside validation) are dead-lettered
and acknowledged, over MQTT and REST; the messages behind them are stored; the runner is
not wedged by one reading; late readings are reported; /forecast never answers nulls;
rejects are logged as structured lines.
"""

from __future__ import annotations

import io
import json
import uuid
from collections import Counter
from datetime import UTC, datetime, timedelta

import numpy as np
import pandas as pd
import pytest
from test_service_app import AUTH, FakeClock, body_of, make_settings, wait_until
from zonecast.service.ingest import (
    Catalogue,
    IngestLimits,
    PointSpec,
    Reason,
    accept,
    validate_message,
)

pytestmark = pytest.mark.timeout(300)

NOW = datetime(2015, 4, 11, 17, 30, tzinfo=UTC)
CATS = {"b1": {"T": PointSpec("temperature"), "G": PointSpec("irradiance")}}
TEL = "zonecast/b1/telemetry"
HUGE = "9" * 400


def poison_payloads(point: str, good_time: str) -> dict[str, bytes]:
    """The four poison kinds of the issue, each a payload that used to raise in validation,
    with the reason it must now be dead-lettered for."""
    return {
        "absurd_value": f'{{"time": "{good_time}", "readings": {{"{point}": {HUGE}}}}}'.encode(),
        "future_time": json.dumps({"time": "9999-12-31T23:59:59-14:00",
                                   "readings": {point: 20.0}}).encode(),
        "past_time": json.dumps({"time": "0001-01-01T00:00:00+01:00",
                                 "readings": {point: 20.0}}).encode(),
        "malformed_json": b"[" * 40_000,
    }


# --------------------------------------------------------------------------- validation
@pytest.mark.parametrize("reason, payload",
                         list(poison_payloads("T", "2015-04-11T17:00:00Z").items()))
def test_poison_values_and_times_are_reasons_not_exceptions(reason, payload):
    acc = accept(TEL, payload, NOW, CATS)
    assert [r.reason.value for r in acc.rejections] == [reason]
    assert acc.readings == () and len(acc.dead_letters) == 1
    detail = acc.rejections[0].detail
    assert len(detail) < 400  # a 400-digit number is not copied into the reason
    assert acc.dead_letters[0]["reason"].startswith(reason + ": ")


@pytest.mark.parametrize("time, reason", [
    ("1969-12-31T23:45:00Z", Reason.PAST_TIME),
    ("0001-01-01T00:00:00Z", Reason.PAST_TIME),
    ("9999-12-31T23:59:59Z", Reason.FUTURE_TIME),
    ("2015-04-11T17:07:00Z", Reason.OFF_GRID),
    ("2015-04-11T17:00:00.5Z", Reason.OFF_GRID),
    ("2015-04-11T10:00:01-07:00", Reason.OFF_GRID),
])
def test_time_window_and_grid(time, reason):
    acc = accept(TEL, json.dumps({"time": time, "readings": {"T": 20.0}}), NOW, CATS)
    assert acc.error is not None and acc.error.reason is reason, acc.rejections
    assert "earliest" in acc.error.detail or "grid" in acc.error.detail \
        or "range" in acc.error.detail or "ahead" in acc.error.detail


def test_earliest_time_from_the_catalogue_or_the_settings():
    cats = {"b1": Catalogue(CATS["b1"], earliest=datetime(2014, 4, 1, tzinfo=UTC),
                            step=timedelta(hours=1))}
    old = json.dumps({"time": "2014-03-31T23:00:00Z", "readings": {"T": 20.0}})
    ok = json.dumps({"time": "2014-04-01T00:00:00Z", "readings": {"T": 20.0}})
    quarter = json.dumps({"time": "2014-04-01T00:15:00Z", "readings": {"T": 20.0}})
    assert accept(TEL, old, NOW, cats).error.reason is Reason.PAST_TIME
    assert accept(TEL, ok, NOW, cats).readings
    assert accept(TEL, quarter, NOW, cats).error.reason is Reason.OFF_GRID  # the site's step
    # the settings' earliest time wins over the site's (here: later)
    limits = IngestLimits(earliest=datetime(2015, 1, 1, tzinfo=UTC))
    assert accept(TEL, ok, NOW, cats, limits=limits).error.reason is Reason.PAST_TIME
    with pytest.raises(ValueError, match="UTC offset"):
        Catalogue({}, earliest=datetime(2014, 1, 1))


def test_settings_earliest_time_reaches_the_limits():
    from zonecast.service.settings import MqttSettings

    s = MqttSettings(earliest_time="2014-01-01T00:00:00Z")
    assert s.limits.earliest == datetime(2014, 1, 1, tzinfo=UTC)
    with pytest.raises(ValueError):
        MqttSettings(earliest_time="2014-01-01T00:00:00")  # no offset


def test_catalogue_for_the_site_has_its_step_and_earliest_time(bundle):
    from zonecast.estimator.site import Experiment
    from zonecast.service.context import catalogue_for_site

    cat = catalogue_for_site(bundle.site)  # the virtual weeks list no experiment
    assert cat.step == timedelta(minutes=15) and cat.earliest is None
    start = datetime(2015, 4, 18, 8, tzinfo=UTC)
    site = bundle.site.model_copy(update={"experiments": [
        Experiment(start=start + timedelta(days=7), end=start + timedelta(days=8)),
        Experiment(start=start, end=start + timedelta(hours=10))]})
    cat = catalogue_for_site(site)
    assert cat.earliest == start - timedelta(days=365)
    late = json.dumps({"time": "2014-04-18T07:45:00Z", "readings": {"OAT": 5.0}})
    acc = accept("zonecast/office6/telemetry", late, NOW, {"office6": cat})
    assert acc.error.reason is Reason.PAST_TIME


def test_batch_top_level_time_only_rejects_items_without_their_own():
    msg = validate_message(TEL, json.dumps({"time": "2015-04-11T17:07:00Z", "readings": [
        {"point": "T", "time": "2015-04-11T17:00:00Z", "value": 20.0},
        {"point": "G", "value": 100.0}]}), CATS, now=NOW)
    assert [r.point for r in msg.readings] == ["T"]
    assert [(r.point, r.reason) for r in msg.rejected] == [("G", Reason.OFF_GRID)]


def test_an_unexpected_exception_in_validation_is_a_dead_letter(monkeypatch):
    from zonecast.service import ingest

    def broken(*args, **kwargs):
        raise KeyError("surprise")

    monkeypatch.setattr(ingest, "validate_message", broken)
    acc = accept(TEL, b'{"time": "2015-04-11T17:00:00Z", "readings": {"T": 1}}', NOW, CATS)
    assert acc.error.reason is Reason.INTERNAL_ERROR and acc.building == "b1"
    assert "KeyError" in acc.error.detail and "surprise" in acc.error.detail
    assert acc.dead_letters[0]["reason"].startswith("internal_error: ")


# --------------------------------------------------------------------------- MQTT
def test_poison_then_good_through_a_real_broker_all_good_stored(broker, tmp_path, vb, bundle,
                                                                telemetry):
    """100 poison messages, then 20 good ones, through Mosquitto into the service: every
    good reading stored, every poison message dead-lettered with its reason and
    acknowledged (nothing left for the broker to redeliver), /metrics counts by reason."""
    from fastapi.testclient import TestClient
    from test_mqtt_ingester import Publisher
    from zonecast.service.app import create_app

    settings = make_settings(tmp_path, vb, broker)
    prefix = f"zc{uuid.uuid4().hex[:8]}"
    settings = settings.model_copy(update={"mqtt": settings.mqtt.model_copy(
        update={"topic_prefix": prefix, "client_id": f"zc-poison-{uuid.uuid4().hex[:6]}"})})
    topic = f"{prefix}/office6/telemetry"
    kinds = poison_payloads("OAT", telemetry["time"].iloc[0])
    publisher = Publisher(broker)
    app = create_app(settings)
    try:
        with TestClient(app) as client:
            ingester = app.state.zc.ingester
            assert ingester.wait_ready(15)
            for i in range(100):
                publisher.send(topic, list(kinds.values())[i % 4])
            for i in range(20):
                publisher.send(topic, body_of(telemetry.iloc[i]))
            wait_until(lambda: ingester.counters()["messages_stored"] == 120, 60,
                       "every message acknowledged")
            metrics = client.get("/metrics", headers=AUTH).text
            ready = client.get("/readyz").json()
            counters = ingester.counters()
            assert ingester.unacknowledged_for() == 0.0
            store = app.state.zc.storage
            stored = store.readings("office6", telemetry["time"].iloc[0],
                                    pd.Timestamp(telemetry["time"].iloc[19]) + pd.Timedelta(
                                        "15min"))
            letters = store.dead_letters(limit=500, building="office6")
    finally:
        publisher.close()
    n_points = len(bundle.site.point_units())
    assert stored.shape == (20, n_points) and stored.notna().all().all()
    assert counters["readings_stored"] == 20 * n_points
    assert counters["rejected"] == {reason: 25 for reason in kinds}
    assert Counter(d.reason.split(":")[0] for d in letters) == {r: 25 for r in kinds}
    for reason in kinds:
        assert f'zonecast_rejected_total{{reason="{reason}",transport="mqtt"}} 25.0' in metrics
    assert 'zonecast_ingest_errors_total{kind="worker"} 0.0' in metrics
    assert ready["ready"] is True, ready


def test_known_bad_kinds_and_poison_keep_ingest_flowing(broker, tmp_path):
    """The malformed kinds of test_mqtt_ingester plus the poison kinds, each between two
    good messages, on the ingester alone: each dead-lettered with its reason."""
    from test_mqtt_ingester import (
        BAD,
        DeadLetterWatcher,
        Publisher,
        catalogue,
        count,
        interleave_bad_messages,
    )
    from zonecast.service.mqtt import Ingester
    from zonecast.service.settings import MqttSettings
    from zonecast.service.storage import open_storage

    building = f"bld{uuid.uuid4().hex[:8]}"
    settings = MqttSettings(host=broker.host, port=broker.port, username=broker.username,
                            client_id=f"zonecast-test-{uuid.uuid4().hex[:8]}",
                            protocol="5" if broker.mqtt5 else "3.1.1",
                            max_payload_bytes=48 * 1024, max_readings=50)
    poison = [("telemetry", payload, reason)
              for reason, payload in poison_payloads("T_Room_0", "2015-04-11T17:00:00Z").items()]
    poison.append(("telemetry", {"time": "2015-04-11T17:05:00Z", "readings": {"T_Room_0": 1}},
                   "off_grid"))
    cases = [c for c in BAD if c[2] != "payload_too_large"] + poison
    store = open_storage(f"sqlite:///{tmp_path}/z.db")
    watcher = DeadLetterWatcher(broker)
    publisher = Publisher(broker)
    try:
        with Ingester(settings, store, {building: catalogue()}) as ingester:
            counters = interleave_bad_messages(ingester, watcher, publisher, building, cases)
    finally:
        watcher.close()
        publisher.close()
    expected = [reason for _, _, reason in cases]
    assert [n["rejections"][0]["reason"] for n in watcher.notices] == expected
    assert counters["rejected"] == Counter(expected)
    assert count(store, building) == 10 * (len(cases) + 1)
    store.close()


class RefusingStorage:
    """Wraps a storage; refuses (as data, like PostgreSQL's SQLSTATE 22) every write that
    holds readings of ``point``."""

    class DataError(Exception):
        sqlstate = "22008"  # datetime_field_overflow

    def __init__(self, inner, point):
        self.inner, self.point = inner, point

    def put_many(self, batches, dead_letters=(), **kw):
        if any(r[0] == self.point for _, rows in batches for r in rows):
            raise self.DataError("date/time field value out of range (simulated)")
        return self.inner.put_many(batches, dead_letters, **kw)


def test_storage_refusing_data_is_a_dead_letter_not_a_stall(broker, tmp_path):
    from test_mqtt_ingester import Publisher, catalogue, count, telemetry
    from zonecast.service.mqtt import Ingester
    from zonecast.service.settings import MqttSettings
    from zonecast.service.storage import open_storage

    building = f"bld{uuid.uuid4().hex[:8]}"
    settings = MqttSettings(host=broker.host, port=broker.port, username=broker.username,
                            client_id=f"zonecast-test-{uuid.uuid4().hex[:8]}",
                            protocol="5" if broker.mqtt5 else "3.1.1")
    store = open_storage(f"sqlite:///{tmp_path}/z.db")
    publisher = Publisher(broker)
    try:
        with Ingester(settings, RefusingStorage(store, "Flow"),
                      {building: catalogue()}) as ingester:
            assert ingester.wait_ready(15)
            publisher.send(f"zonecast/{building}/telemetry", telemetry(0))
            publisher.send(f"zonecast/{building}/telemetry", {
                "time": "2015-04-11T17:15:00Z", "readings": {"Flow": 0.3}})
            publisher.send(f"zonecast/{building}/telemetry", telemetry(2))
            wait_until(lambda: ingester.counters()["messages_stored"] == 3, what="3 acks")
            counters = ingester.counters()
    finally:
        publisher.close()
    assert count(store, building) == 20
    assert counters["rejected"] == {"storage_rejected": 1} and counters["storage_errors"] == 0
    (letter,) = store.dead_letters()
    assert letter.reason.startswith("storage_rejected: DataError: date/time")
    store.close()


# --------------------------------------------------------------------------- REST
def test_rest_answers_4xx_with_the_reason_for_every_poison_kind(tmp_path, vb, telemetry):
    from fastapi.testclient import TestClient
    from zonecast.service.app import create_app

    app = create_app(make_settings(tmp_path, vb))
    url = "/api/v1/buildings/office6/telemetry"
    kinds = poison_payloads("OAT", telemetry["time"].iloc[0])
    kinds["off_grid"] = json.dumps({"time": "2015-04-13T00:07:00-07:00",
                                    "readings": {"OAT": 10.0}}).encode()
    with TestClient(app, raise_server_exceptions=False) as client:
        for reason, payload in kinds.items():
            r = client.post(url, content=payload, headers=AUTH)
            assert r.status_code == 422, (reason, r.status_code, r.text[:300])
            assert reason in r.json()["detail"]
            assert [x["reason"] for x in r.json()["rejected"]] == [reason]
        letters = app.state.zc.storage.dead_letters(building="office6")
        metrics = client.get("/metrics", headers=AUTH).text
    assert sorted(d.reason.split(":")[0] for d in letters) == sorted(kinds)
    assert 'zonecast_rejected_total{reason="past_time",transport="rest"} 1.0' in metrics


# --------------------------------------------------------------------------- runner
def _runner(bundle, store, clock, **kw):
    from zonecast.service.runner import Runner
    from zonecast.service.settings import RunnerSettings

    return Runner(bundle, store, RunnerSettings(grace=300, idle_timeout=1800,
                                                forecast_every=4, **kw), clock=clock)


def _put(store, bundle, row, drop=()):
    from zonecast.service.context import catalogue_for_site

    body = body_of(row)
    for p in drop:
        body["readings"].pop(p)
    msg = validate_message(f"zonecast/{bundle.building}/telemetry", json.dumps(body),
                           {bundle.building: catalogue_for_site(bundle.site)})
    assert not msg.rejected
    store.put_readings(bundle.building, msg.readings)


def test_a_reading_of_year_1_stored_before_the_start_does_not_wedge_the_runner(
        bundle, telemetry, tmp_path):
    from zonecast.service.storage import open_storage

    store = open_storage(f"sqlite:///{tmp_path / 'r.db'}")
    # stored behind ingest's back (as before the time window existed)
    store.put_readings(bundle.building, [("OAT", datetime(1, 1, 1, tzinfo=UTC), 5.0),
                                         ("OAT", datetime(9999, 12, 31, tzinfo=UTC), 5.0)])
    clock = FakeClock("2015-04-13T12:00:00Z")
    runner = _runner(bundle, store, clock)
    for i in range(4):
        _put(store, bundle, telemetry.iloc[i])
    assert runner.poll() == 4
    assert runner.est.time == pd.Timestamp(telemetry["time"].iloc[3]).tz_convert("UTC")
    store.close()


def test_a_lone_reading_far_ahead_neither_closes_rows_nor_makes_the_runner_jump(
        bundle, telemetry, tmp_path):
    """A stray reading stamped a week ahead (a publisher with a wrong clock) amid a stream:
    incomplete rows still wait for their stragglers, the rows arriving after it are all
    processed, and only once the feed is idle does the runner move on to it; a reading
    arriving after that for an earlier row is reported as late, not silently ignored."""
    from zonecast.service.storage import open_storage

    store = open_storage(f"sqlite:///{tmp_path / 'r.db'}")
    t = [pd.Timestamp(x).tz_convert("UTC") for x in telemetry["time"]]
    clock = FakeClock(t[0] + pd.Timedelta(days=8))
    runner = _runner(bundle, store, clock)
    stray = t[0] + pd.Timedelta(days=7)
    store.put_readings(bundle.building, [("OAT", stray, 12.0)])
    assert runner.poll() == 0 and runner.next_time is None  # a lone reading starts nothing
    late = bundle.site.points.outdoor_air_temperature.point
    _put(store, bundle, telemetry.iloc[0])
    _put(store, bundle, telemetry.iloc[1], drop=[late])
    assert runner.poll() == 1  # row 1 waits for its OAT: the stray is no watermark
    for i in range(2, 12):
        _put(store, bundle, telemetry.iloc[i])
    _put(store, bundle, telemetry.iloc[1])  # the straggler
    assert runner.poll() == 11
    assert runner.est.time == t[11] and runner.last_report.held_inputs == []
    assert runner.late_readings == 0
    for i in range(12, 2 * 96 + 4):  # two more days, in order: no jump to the stray
        _put(store, bundle, telemetry.iloc[i])
        runner.poll()
    assert runner.est.time == t[2 * 96 + 3] and runner.est.steps == 2 * 96 + 3
    # the feed stops: after idle_timeout (arrival times are the real clock's) the runner
    # moves on, up to the stray (alone, 4 days after the last row: the filter restarts)
    clock.t = datetime.now(UTC) + timedelta(hours=1)
    runner.poll()
    assert runner.next_time == stray + pd.Timedelta("15min")
    # data for rows behind the runner now: stored, counted, logged, on /state
    _put(store, bundle, telemetry.iloc[2 * 96 + 4])
    runner.poll()
    assert runner.late_readings == len(bundle.site.point_units())
    assert runner.last_late == (t[2 * 96 + 4], t[2 * 96 + 4])
    store.close()


def test_late_readings_after_a_restart_are_counted_from_the_checkpoint(bundle, telemetry,
                                                                       tmp_path):
    from zonecast.service.storage import open_storage

    store = open_storage(f"sqlite:///{tmp_path / 'r.db'}")
    clock = FakeClock("2015-04-13T12:00:00Z")
    runner = _runner(bundle, store, clock)
    for i in range(6):
        _put(store, bundle, telemetry.iloc[i], drop=["OAT"] if i == 2 else ())
    assert runner.poll() == 6  # row 2 closed by the watermark without its OAT
    again = _runner(bundle, store, clock)  # restart from the checkpoint
    _put(store, bundle, telemetry.iloc[2])  # OAT of row 2, processed before the restart
    again.poll()
    assert again.late_readings == 1
    store.close()


def test_forecast_answers_409_naming_what_is_missing(tmp_path, vb, bundle, telemetry):
    """A building whose supply air temperature never arrives: /state flags it and
    /forecast answers 409 naming the point, never 200 with null means; before any data,
    409 says the filter has not started."""
    from fastapi.testclient import TestClient
    from zonecast.service.app import create_app

    sat = bundle.site.points.supply_air_temperature.point
    app = create_app(make_settings(tmp_path, vb, forecast_every=1))
    url = "/api/v1/buildings/office6"
    with TestClient(app) as client:
        r = client.get(f"{url}/forecast", headers=AUTH)
        assert r.status_code == 409 and "has not started" in r.json()["detail"]
        for i in range(6):
            body = body_of(telemetry.iloc[i])
            body["readings"].pop(sat)
            assert client.post(f"{url}/telemetry", json=body, headers=AUTH).status_code == 200
        runner = app.state.zc.runners["office6"]
        # incomplete rows: rows 0-3 close by the watermark (row 5); the estimator cannot
        # step without a supply air temperature and restarts at every measurement
        t4 = pd.Timestamp(telemetry["time"].iloc[4])
        wait_until(lambda: runner.next_time == t4, what="runner")
        assert runner.forecast is not None  # issued at a restart, undefined
        r = client.get(f"{url}/forecast", headers=AUTH)
        assert r.status_code == 409, r.text[:300]
        assert sat in r.json()["detail"] and "undefined" in r.json()["detail"]
        state = client.get(f"{url}/state", headers=AUTH).json()
        assert f"never_received:{sat}" in state["quality"]
        assert "filter_restarted" in state["quality"]
        # the missing point arrives: the forecast is served once the rows without it are
        # more than a day old (the persistence inputs of the horizon are the last 24 h)
        for i in range(6, 8):
            client.post(f"{url}/telemetry", json=body_of(telemetry.iloc[i]), headers=AUTH)
        wait_until(lambda: runner.est.time == pd.Timestamp(telemetry["time"].iloc[7]),
                   what="row 7")
        r = client.get(f"{url}/forecast", headers=AUTH)
        assert r.status_code == 409 and sat not in r.json()["detail"]
        last = 5 + 96 + 1
        for i in range(8, last + 1):
            client.post(f"{url}/telemetry", json=body_of(telemetry.iloc[i]), headers=AUTH)
        wait_until(lambda: runner.est.time == pd.Timestamp(telemetry["time"].iloc[last]),
                   what="a day later")
        r = client.get(f"{url}/forecast", headers=AUTH)
        assert r.status_code == 200, r.text[:300]
        assert all(np.isfinite(z["mean"]).all() for z in r.json()["zones"])
        assert client.get(f"{url}/state", headers=AUTH).json()["late_readings"] == 0


# --------------------------------------------------------------------------- logs
def test_a_reject_is_one_json_line_with_level_time_building_reason(tmp_path, vb):
    import logging

    from fastapi.testclient import TestClient
    from zonecast.service.app import create_app
    from zonecast.service.logs import JsonFormatter, TextFormatter

    out, text = io.StringIO(), io.StringIO()
    handlers = [logging.StreamHandler(out), logging.StreamHandler(text)]
    handlers[0].setFormatter(JsonFormatter())
    handlers[1].setFormatter(TextFormatter())
    logger = logging.getLogger("zonecast")
    for h in handlers:
        logger.addHandler(h)
    level = logger.level
    logger.setLevel(logging.INFO)
    try:
        with TestClient(create_app(make_settings(tmp_path, vb))) as client:
            r = client.post("/api/v1/buildings/office6/telemetry", headers=AUTH, json={
                "time": "2015-04-13T00:05:00-07:00", "readings": {"OAT": 10.0}})
            assert r.status_code == 422
    finally:
        for h in handlers:
            logger.removeHandler(h)
        logger.setLevel(level)
    lines = [json.loads(line) for line in out.getvalue().splitlines()]  # every line is JSON
    (reject,) = [x for x in lines if x.get("reason") == "off_grid"]
    assert reject["level"] == "WARNING" and reject["building"] == "office6"
    assert reject["transport"] == "rest" and reject["logger"] == "zonecast.service.ingest"
    assert datetime.fromisoformat(reject["time"]).tzinfo is not None
    assert any(x.get("building") == "office6" and "loaded" in x["message"] for x in lines)
    line = next(x for x in text.getvalue().splitlines() if "off_grid" in x)
    assert " WARNING zonecast.service.ingest " in line and "building=office6" in line
    assert "reason=off_grid" in line


def test_configure_logging_and_the_serve_option(capsys):
    import logging

    from typer.testing import CliRunner
    from zonecast.service.logs import configure_logging

    from zonecast.cli import app as cli

    root = logging.getLogger()
    saved = root.handlers[:], root.level
    stream = io.StringIO()
    try:
        configure_logging("json", "warning", stream=stream)
        logging.getLogger("zonecast.test").info("not shown")
        logging.getLogger("zonecast.test").warning("shown %d", 1, extra={"building": "b"})
        with pytest.raises(ValueError, match="log format"):
            configure_logging("xml")
        with pytest.raises(ValueError, match="log level"):
            configure_logging("text", "loud")
    finally:
        root.handlers[:], _ = saved
        root.setLevel(saved[1])
    (line,) = stream.getvalue().splitlines()
    assert json.loads(line) | {"time": None} == {"time": None, "level": "WARNING",
                                                 "logger": "zonecast.test",
                                                 "message": "shown 1", "building": "b"}
    out = CliRunner().invoke(cli, ["serve", "--help"], terminal_width=200)
    assert "--log-format" in out.output


# --------------------------------------------------------------------------- replay
def test_replay_client_ids_are_unique_and_two_replays_run_side_by_side(broker, vb, telemetry):
    import threading

    from zonecast.service.replay import replay, unique_client_id
    from zonecast.service.settings import MqttSettings

    a, b = unique_client_id("replay"), unique_client_id("replay")
    assert a != b and a.startswith("zonecast-replay-") and len(a) <= 64
    pub = MqttSettings(host=broker.host, port=broker.port, username=broker.username,
                       protocol="5" if broker.mqtt5 else "3.1.1",
                       topic_prefix=f"zc{uuid.uuid4().hex[:8]}")
    end = telemetry["time"].iloc[40]
    results: list = []

    def run():
        results.append(replay(vb, pub, "office6", end=end))

    threads = [threading.Thread(target=run) for _ in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(60)
    assert [r["messages"] for r in results] == [40, 40]


def test_replay_exits_non_zero_when_the_broker_refuses_a_message(vb, monkeypatch):
    from typer.testing import CliRunner
    from zonecast.service import replay as replay_module

    from zonecast.cli import app as cli

    class Refused:
        is_failure = True

        def __str__(self):
            return "Not authorized"

    class Info:
        def __init__(self, mid):
            self.mid = mid

        def wait_for_publish(self, timeout):
            pass

        def is_published(self):
            return True

    class FakeClient:  # acknowledges the first two messages, refuses the third
        on_publish = None
        mids = 0

        def publish(self, topic, payload, qos):
            self.mids += 1
            ok = self.mids < 3
            self.on_publish(self, None, self.mids, Refused() if not ok else None, None)
            return Info(self.mids)

        def disconnect(self):
            pass

        def loop_stop(self):
            pass

    monkeypatch.setattr(replay_module, "connect_publisher", lambda *a, **k: FakeClient())
    out = CliRunner().invoke(cli, ["replay", "--data", str(vb), "--building", "office6",
                                   "--broker", "mqtt://127.0.0.1:1"])
    assert out.exit_code == 2
    assert "refused by the broker: Not authorized" in out.output
    assert "2 messages were acknowledged" in out.output


def test_a_cloud_cover_outside_its_range_in_the_points_unit_is_absurd(bundle):
    """The virtual building maps its cloud cover in %: the catalogue's plausible range is
    0-100 %, and a reading of 130 is refused as absurd while 80 is stored."""
    from zonecast.service.context import catalogue_for_site

    cat = catalogue_for_site(bundle.site)
    spec = cat["CLOUD"]
    assert spec.kind.value == "cloud_cover" and spec.unit == "%"
    assert (spec.low, spec.high) == pytest.approx((0.0, 100.0))
    msg = validate_message("zonecast/office6/telemetry", json.dumps({
        "time": "2015-04-11T17:00:00Z", "readings": {"CLOUD": 130.0, "OAT": 12.0}}),
        {"office6": cat}, now=NOW)
    assert [r.point for r in msg.readings] == ["OAT"]
    assert [(r.point, r.reason) for r in msg.rejected] == [("CLOUD", Reason.ABSURD_VALUE)]
