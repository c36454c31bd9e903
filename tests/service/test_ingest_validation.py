"""Message validation (pure functions, no network)."""

from __future__ import annotations

import json
from datetime import UTC, datetime, timedelta

import pytest
from hypothesis import given
from hypothesis import strategies as st
from zonecast.service.ingest import (
    IngestLimits,
    MessageRejected,
    PointKind,
    PointSpec,
    Reading,
    Reason,
    accept,
    parse_time,
    parse_topic,
    validate_message,
)

NOW = datetime(2015, 4, 11, 17, 30, tzinfo=UTC)
CATALOGUES = {
    "office6": {
        "T_Room_NW_1": PointSpec(PointKind.TEMPERATURE),
        "VAV-NW-1 Flow": PointSpec("airflow", unit="kg/s", high=5.0),
        "GHI": PointSpec(PointKind.IRRADIANCE),
        "AHU1/SAT": PointSpec(PointKind.TEMPERATURE),
    }
}
TEL = "zonecast/office6/telemetry"


def check(payload, topic=TEL, **kw):
    body = payload if isinstance(payload, (bytes, str)) else json.dumps(payload)
    return validate_message(topic, body, CATALOGUES, now=NOW, **kw)


def rejected(payload, topic=TEL, **kw) -> MessageRejected:
    with pytest.raises(MessageRejected) as info:
        check(payload, topic, **kw)
    assert isinstance(info.value, ValueError)
    return info.value


def test_map_form_converts_to_utc():
    msg = check({"time": "2015-04-11T10:00:00-07:00",
                 "readings": {"T_Room_NW_1": 21.3, "VAV-NW-1 Flow": 0.31}})
    t = datetime(2015, 4, 11, 17, 0, tzinfo=UTC)
    assert msg.building == "office6" and msg.rejected == ()
    assert msg.readings == (Reading("T_Room_NW_1", t, 21.3), Reading("VAV-NW-1 Flow", t, 0.31))
    assert msg.readings[0].time.tzinfo is UTC


def test_batch_form_with_own_and_shared_times():
    msg = check({"time": "2015-04-11T17:00:00Z", "readings": [
        {"point": "T_Room_NW_1", "time": "2015-04-11T16:45:00Z", "value": 21},
        {"point": "GHI", "value": 350.5},
    ]})
    assert [(r.point, r.time.minute, r.value) for r in msg.readings] == [
        ("T_Room_NW_1", 45, 21.0), ("GHI", 0, 350.5)]
    assert isinstance(msg.readings[0].value, float)


def test_point_topic_object_and_bare_number():
    topic = "zonecast/office6/points/T_Room_NW_1"
    msg = check({"time": "2015-04-11T17:00:00Z", "value": 20.5}, topic=topic)
    assert msg.readings == (Reading("T_Room_NW_1", datetime(2015, 4, 11, 17, tzinfo=UTC), 20.5),)
    msg = check(b"20.5", topic=topic, properties={"time": "2015-04-11T17:00:00+00:00"})
    assert msg.readings[0].value == 20.5
    assert rejected(b"20.5", topic=topic).reason is Reason.MISSING_TIME
    # a point name may contain "/"
    msg = check({"time": "2015-04-11T17:00:00Z", "value": 14.0},
                topic="zonecast/office6/points/AHU1/SAT")
    assert msg.readings[0].point == "AHU1/SAT"


@pytest.mark.parametrize("payload, reason", [
    (b"{not json", Reason.MALFORMED_JSON),
    (b"\xff\xfe", Reason.MALFORMED_JSON),
    ([1, 2], Reason.NOT_AN_OBJECT),
    ({"time": "2015-04-11T17:00:00Z"}, Reason.NO_READINGS),
    ({"time": "2015-04-11T17:00:00Z", "readings": {}}, Reason.NO_READINGS),
    ({"time": "2015-04-11T17:00:00Z", "readings": 3}, Reason.NOT_AN_OBJECT),
    ({"readings": {"GHI": 1}}, Reason.MISSING_TIME),
    ({"time": "yesterday", "readings": {"GHI": 1}}, Reason.UNPARSABLE_TIME),
    ({"time": 1428771600, "readings": {"GHI": 1}}, Reason.UNPARSABLE_TIME),
    ({"time": "2015-04-11T17:00:00", "readings": {"GHI": 1}}, Reason.TIME_WITHOUT_OFFSET),
    ({"time": "2015-04-11T17:41:00Z", "readings": {"GHI": 1}}, Reason.FUTURE_TIME),
])
def test_whole_message_rejections(payload, reason):
    err = rejected(payload)
    assert err.reason is reason and err.building == "office6"
    assert str(err).startswith(reason.value + ": ")


def test_unknown_building_and_bad_topics():
    err = rejected({"time": "2015-04-11T17:00:00Z", "readings": {"GHI": 1}},
                   topic="zonecast/office7/telemetry")
    assert err.reason is Reason.UNKNOWN_BUILDING and err.building == "office7"
    for topic in ["zonecast/office6", "zonecast/office6/points", "other/office6/telemetry",
                  "zonecast//telemetry", "zonecast/office6/telemetry/x"]:
        assert rejected({}, topic=topic).reason is Reason.BAD_TOPIC


def test_size_and_count_limits():
    big = {"time": "2015-04-11T17:00:00Z", "readings": {"GHI": 1, "pad": "x" * 70_000}}
    assert rejected(big).reason is Reason.PAYLOAD_TOO_LARGE
    small = IngestLimits(max_payload_bytes=100)
    assert rejected({"time": "2015-04-11T17:00:00Z", "readings": {"GHI": 1}, "pad": "x" * 90},
                    limits=small).reason is Reason.PAYLOAD_TOO_LARGE
    many = {"time": "2015-04-11T17:00:00Z", "readings": [
        {"point": "GHI", "value": 1}] * 11}
    err = rejected(many, limits=IngestLimits(max_readings=10))
    assert err.reason is Reason.TOO_MANY_READINGS and "limit is 10" in err.detail


def test_future_limit_is_configurable():
    payload = {"time": "2015-04-11T18:15:00Z", "readings": {"GHI": 1}}
    assert rejected(payload).reason is Reason.FUTURE_TIME
    assert check(payload, limits=IngestLimits(max_future=timedelta(hours=1))).readings


def test_bad_readings_are_rejected_one_by_one_and_good_ones_kept():
    msg = check(b'{"time": "2015-04-11T17:00:00Z", "readings": {'
                b'"T_Room_NW_1": 21.0, "Nope": 1, "GHI": "350", "VAV-NW-1 Flow": true, '
                b'"AHU1/SAT": NaN}}')
    assert [r.point for r in msg.readings] == ["T_Room_NW_1"]
    assert {(r.point, r.reason) for r in msg.rejected} == {
        ("Nope", Reason.UNKNOWN_POINT), ("GHI", Reason.WRONG_TYPE),
        ("VAV-NW-1 Flow", Reason.WRONG_TYPE), ("AHU1/SAT", Reason.NOT_FINITE)}


@pytest.mark.parametrize("point, value, reason", [
    ("T_Room_NW_1", 85.0, Reason.ABSURD_VALUE),
    ("T_Room_NW_1", -51, Reason.ABSURD_VALUE),
    ("VAV-NW-1 Flow", 5.5, Reason.ABSURD_VALUE),  # custom high
    ("VAV-NW-1 Flow", -0.1, Reason.ABSURD_VALUE),
    ("GHI", "Infinity", Reason.NOT_FINITE),
    ("GHI", "1e999", Reason.NOT_FINITE),
    ("GHI", "null", Reason.WRONG_TYPE),
    ("GHI", "[1]", Reason.WRONG_TYPE),
])
def test_per_reading_value_rules(point, value, reason):
    raw = value if isinstance(value, str) else json.dumps(value)
    body = '{"time": "2015-04-11T17:00:00Z", "readings": {"' + point + '": ' + raw + "}}"
    msg = check(body)
    assert msg.readings == () and [r.reason for r in msg.rejected] == [reason]
    assert point in msg.rejected[0].detail


def test_batch_items_rejected_one_by_one():
    msg = check({"readings": [
        {"point": "GHI", "time": "2015-04-11T17:00:00Z", "value": 10},
        {"point": "GHI", "value": 10},                       # no time anywhere
        {"point": "GHI", "time": "2015-04-11T17:00", "value": 10},
        {"point": "GHI", "time": "2015-04-12T17:00:00Z", "value": 10},
        "GHI=10",
        {"time": "2015-04-11T17:00:00Z", "value": 10},
    ]})
    assert len(msg.readings) == 1
    assert [r.reason for r in msg.rejected] == [
        Reason.MALFORMED_READING, Reason.MALFORMED_READING, Reason.MISSING_TIME,
        Reason.TIME_WITHOUT_OFFSET, Reason.FUTURE_TIME]


def test_parse_time_and_topic_helpers():
    assert parse_time("2015-04-11T10:00:00.5-07:00") == datetime(2015, 4, 11, 17, 0, 0, 500000,
                                                                 tzinfo=UTC)
    with pytest.raises(ValueError, match="time_without_offset"):
        parse_time("2015-04-11T10:00:00")
    assert parse_topic("zonecast/b1/telemetry") == ("b1", None)
    assert parse_topic("site/b1/points/x y", prefix="site") == ("b1", "x y")


def test_point_spec_defaults_and_errors():
    spec = PointSpec("temperature")
    assert (spec.kind, spec.unit, spec.low, spec.high) == (PointKind.TEMPERATURE, "degC", -50, 80)
    with pytest.raises(ValueError, match="use one of"):
        PointSpec("pressure")
    with pytest.raises(ValueError, match="low must be"):
        PointSpec("other", low=2, high=1)


@given(st.binary(max_size=300))
def test_arbitrary_bytes_never_crash(payload):
    try:
        msg = validate_message(TEL, payload, CATALOGUES, now=NOW)
    except MessageRejected as err:
        assert isinstance(err.reason, Reason)
    else:
        assert len(msg.readings) + len(msg.rejected) >= 1


@given(st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=5),
                    lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=8), c,
                                                                        max_size=3),
                    max_leaves=10))
def test_arbitrary_json_never_crashes(body):
    payload = json.dumps({"time": "2015-04-11T17:00:00Z", "readings": body})
    try:
        msg = validate_message(TEL, payload, CATALOGUES, now=NOW)
    except MessageRejected:
        return
    for r in msg.readings:
        assert isinstance(r.value, float) and r.time.tzinfo is UTC


def test_accept_says_what_to_store_and_why_for_both_transports():
    """``accept`` (the one path of MQTT and REST): readings, one dead letter per rejection
    with reason "<code>: <detail>", the counts by reason, and a whole-message rejection as
    ``error`` instead of an exception."""
    good = json.dumps({"time": "2015-04-11T17:00:00Z", "readings": {"T_Room_NW_1": 21.0}})
    acc = accept(TEL, good, NOW, CATALOGUES)
    assert acc.building == "office6" and acc.error is None
    assert [r.point for r in acc.readings] == ["T_Room_NW_1"]
    assert acc.rejections == () and acc.dead_letters == () and acc.reasons == {}

    partly = json.dumps({"time": "2015-04-11T17:00:00Z",
                         "readings": {"T_Room_NW_1": 21.0, "GHI": "sunny", "Nope": 1}})
    acc = accept(TEL, partly, NOW, CATALOGUES)
    assert acc.error is None and len(acc.readings) == 1
    assert acc.reasons == {"wrong_type": 1, "unknown_point": 1}
    assert [d["reason"] for d in acc.dead_letters] == [
        f"{r.reason.value}: {r.detail}" for r in acc.rejections]
    assert all(d["building"] == "office6" and d["topic"] == TEL and d["payload"] == partly
               and d["received_at"] == NOW for d in acc.dead_letters)

    acc = accept(TEL, b"{oops", NOW, CATALOGUES)
    assert acc.error is not None and acc.error.reason is Reason.MALFORMED_JSON
    assert acc.readings == () and acc.reasons == {"malformed_json": 1}
    assert [(d["reason"], d["building"]) for d in acc.dead_letters] == [
        (str(acc.error), "office6")]
    assert acc.rejections[0].point is None
    acc = accept("zonecast/elsewhere/telemetry", good, NOW, CATALOGUES)
    assert acc.reasons == {"unknown_building": 1} and acc.dead_letters[0]["building"] == "elsewhere"
