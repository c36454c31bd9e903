"""Validate telemetry messages from a building management system (BMS).

Pure functions: no network, no database, no clock except the ``now`` a caller
passes (it defaults to the current UTC time). Both ingest paths, the MQTT ingester
(:mod:`zonecast.service.mqtt`) and the REST route (``POST .../telemetry``), call
:func:`accept` for every message they receive and store what it returns: the
accepted readings and the dead letters, in one transaction. :func:`validate_message`
is the validation itself. ``docs/service.md`` is the user-facing description of the
topic scheme, payload forms and rejection reasons.

Topic scheme (``prefix`` defaults to ``zonecast``)::

    <prefix>/<building>/telemetry        one or many points in one JSON object
    <prefix>/<building>/points/<point>   one reading of one point

Rejections come in two sizes. A *message* is rejected as a whole
(:class:`MessageRejected`) when nothing in it can be trusted: the payload is too
large or not JSON, the topic or building is unknown, the message-level time is
bad, or it holds no readings or too many. Otherwise each reading is judged on its
own: good readings are kept and every bad one is returned in
:attr:`ValidatedMessage.rejected` with its reason, so one broken sensor does not
discard a whole floor's readings and nothing is dropped silently.

Nothing a publisher sends makes :func:`accept` raise: an exception inside validation that
no rule anticipated becomes a whole-message rejection ``internal_error`` carrying the
exception's text, so the message is dead-lettered and acknowledged like any other bad one
instead of stalling the stream behind it.

Time rules (docs/service.md, "Validation"): a time must lie in the plausibility window
[earliest, received + ``max_future``] and on the building's step grid (a multiple of the
step since the Unix epoch, docs/data.md); ``past_time``, ``future_time`` and ``off_grid``
otherwise.
"""

from __future__ import annotations

import json
import logging
import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from enum import Enum
from typing import Any, NamedTuple

from zonecast.service.settings import DEFAULT_PREFIX, IngestLimits

__all__ = [
    "DEFAULT_PREFIX",
    "EPOCH",
    "Accepted",
    "Catalogue",
    "CheckedReadings",
    "IngestLimits",
    "MessageRejected",
    "PointCatalogue",
    "PointKind",
    "PointSpec",
    "Reading",
    "Reason",
    "RejectedReading",
    "ValidatedMessage",
    "accept",
    "dead_letters",
    "log_rejections",
    "parse_time",
    "parse_topic",
    "refuse",
    "validate_message",
]

_DEFAULT_LIMITS = IngestLimits()
#: earliest plausible time when neither the settings nor the building's catalogue say more
EPOCH = datetime(1970, 1, 1, tzinfo=UTC)

log = logging.getLogger(__name__)


class Reason(str, Enum):
    """Why a message or a reading was rejected (the value is the stable code)."""

    BAD_TOPIC = "bad_topic"
    PAYLOAD_TOO_LARGE = "payload_too_large"
    MALFORMED_JSON = "malformed_json"
    NOT_AN_OBJECT = "not_an_object"
    UNKNOWN_BUILDING = "unknown_building"
    NO_READINGS = "no_readings"
    TOO_MANY_READINGS = "too_many_readings"
    MALFORMED_READING = "malformed_reading"
    UNKNOWN_POINT = "unknown_point"
    WRONG_TYPE = "wrong_type"
    NOT_FINITE = "not_finite"
    ABSURD_VALUE = "absurd_value"
    MISSING_TIME = "missing_time"
    UNPARSABLE_TIME = "unparsable_time"
    TIME_WITHOUT_OFFSET = "time_without_offset"
    FUTURE_TIME = "future_time"
    #: before the earliest plausible time (settings, the site, or 1970)
    PAST_TIME = "past_time"
    #: not a multiple of the building's step since the Unix epoch (docs/data.md)
    OFF_GRID = "off_grid"
    #: validation raised an exception no rule anticipated (the text says which): a bug,
    #: but the message is dead-lettered and acknowledged instead of stalling ingest
    INTERNAL_ERROR = "internal_error"
    #: Passed validation but storage refused it (a bug: please report it).
    STORAGE_REJECTED = "storage_rejected"
    #: a weather forecast (``<prefix>/<building>/weather_forecast``) failed its rules; the
    #: detail starts with the rule's code (zonecast.service.weather)
    BAD_WEATHER_FORECAST = "bad_weather_forecast"

    def __str__(self) -> str:  # "unknown_point", not "Reason.UNKNOWN_POINT"
        return self.value


class PointKind(str, Enum):
    """What a point measures; selects the default plausible range."""

    TEMPERATURE = "temperature"
    AIRFLOW = "airflow"
    IRRADIANCE = "irradiance"
    POWER = "power"
    CLOUD_COVER = "cloud_cover"
    OTHER = "other"


#: Default plausible range per kind, in the kind's SI unit (degC, kg/s, W/m2, W; a meter
#: of a floor's lights and plug loads reads well below 100 MW).
DEFAULT_RANGES: dict[PointKind, tuple[float, float]] = {
    PointKind.TEMPERATURE: (-50.0, 80.0),
    PointKind.AIRFLOW: (0.0, 100.0),
    PointKind.IRRADIANCE: (0.0, 1500.0),
    PointKind.POWER: (0.0, 1e8),
    PointKind.CLOUD_COVER: (0.0, 1.0),
    PointKind.OTHER: (-1e12, 1e12),
}
_DEFAULT_UNITS = {
    PointKind.TEMPERATURE: "degC",
    PointKind.AIRFLOW: "kg/s",
    PointKind.IRRADIANCE: "W/m2",
    PointKind.POWER: "W",
    PointKind.CLOUD_COVER: "1",
    PointKind.OTHER: "",
}


@dataclass(frozen=True)
class PointSpec:
    """What one telemetry point is and which values are plausible.

    Parameters
    ----------
    kind : PointKind or str
        ``temperature``, ``airflow``, ``irradiance``, ``power``, ``cloud_cover`` or
        ``other``.
    unit : str, optional
        Unit of the values on the wire (documentation only; no conversion
        happens at ingest). Defaults to the kind's SI unit.
    low, high : float, optional
        Plausible range [unit], inclusive. Values outside are rejected as
        ``absurd_value``. Default: the kind's range in :data:`DEFAULT_RANGES`
        (temperature -50...80 degC).
    """

    kind: PointKind = PointKind.OTHER
    unit: str | None = None
    low: float | None = None
    high: float | None = None

    def __post_init__(self) -> None:
        try:
            kind = PointKind(self.kind)
        except ValueError:
            choices = ", ".join(k.value for k in PointKind)
            raise ValueError(f"unknown point kind {self.kind!r}: use one of {choices}") from None
        low, high = DEFAULT_RANGES[kind]
        object.__setattr__(self, "kind", kind)
        object.__setattr__(self, "unit", _DEFAULT_UNITS[kind] if self.unit is None else self.unit)
        object.__setattr__(self, "low", low if self.low is None else float(self.low))
        object.__setattr__(self, "high", high if self.high is None else float(self.high))
        if not self.low <= self.high:
            raise ValueError(f"plausible range [{self.low}, {self.high}] is empty: low must be <= high")


#: A building's points: BMS point name -> its spec.
PointCatalogue = Mapping[str, PointSpec]


class Catalogue(dict[str, PointSpec]):
    """A building's point catalogue with the building's own time rules.

    A plain ``{point: PointSpec}`` dict works everywhere a catalogue is expected; this
    subclass adds what depends on the site (``zonecast.service.context.catalogue_for_site``
    builds one per building).

    Parameters
    ----------
    points : mapping of str to PointSpec
    earliest : datetime, optional
        Earliest plausible reading time of this building (tz-aware); used unless the
        settings fix one for all buildings (``IngestLimits.earliest``). Default: 1970.
    step : timedelta, optional
        The building's step grid; default ``IngestLimits.grid``.
    """

    def __init__(self, points: Mapping[str, PointSpec] = (), *,
                 earliest: datetime | None = None, step: timedelta | None = None):
        super().__init__(points)
        if earliest is not None and (earliest.tzinfo is None or earliest.utcoffset() is None):
            raise ValueError(f"earliest {earliest.isoformat()} must carry a UTC offset")
        if step is not None and step <= timedelta(0):
            raise ValueError(f"step {step} must be positive")
        self.earliest = earliest
        self.step = step


def _time_rules(catalogue: PointCatalogue, limits: IngestLimits
                ) -> tuple[datetime, timedelta | None]:
    """(earliest plausible time, step grid or None) for a building."""
    earliest = limits.earliest
    if earliest is None:
        earliest = getattr(catalogue, "earliest", None) or EPOCH
    return earliest, getattr(catalogue, "step", None) or limits.grid


class Reading(NamedTuple):
    """One accepted reading: ``(point, time, value)``; ``time`` is tz-aware UTC."""

    point: str
    time: datetime
    value: float


_new_reading = tuple.__new__  # Reading without its Python-level __new__ (the hot path)


class CheckedReadings(tuple):
    """Readings of one message as :func:`validate_message` returns them when their keys
    ``(point, time)`` are distinct (the map and point forms): every item a :class:`Reading`
    of a catalogue point, a UTC ``datetime`` and a finite ``float``. Storage then skips
    checking them again (``zonecast.service.storage``); any other sequence is checked."""

    __slots__ = ()


@dataclass(frozen=True)
class RejectedReading:
    """One reading that failed validation inside an otherwise accepted message."""

    point: str | None
    reason: Reason
    detail: str


@dataclass(frozen=True)
class ValidatedMessage:
    """Result of validating one message whose envelope was accepted."""

    building: str
    readings: tuple[Reading, ...]
    rejected: tuple[RejectedReading, ...] = field(default=())


class MessageRejected(ValueError):
    """A whole message was rejected.

    Attributes
    ----------
    reason : Reason
        Stable code, e.g. ``malformed_json``.
    detail : str
        What was wrong and what to fix.
    building : str or None
        The building named by the topic, when the topic could be read.
    """

    def __init__(self, reason: Reason, detail: str, building: str | None = None):
        super().__init__(f"{reason.value}: {detail}")
        self.reason = reason
        self.detail = detail
        self.building = building


class _Bad(Exception):
    """Internal: one reading failed (carries reason and detail)."""

    def __init__(self, reason: Reason, detail: str):
        super().__init__(detail)
        self.reason = reason
        self.detail = detail


def parse_topic(topic: str, prefix: str = DEFAULT_PREFIX) -> tuple[str, str | None]:
    """Split a telemetry topic into building and point.

    Parameters
    ----------
    topic : str
        ``<prefix>/<building>/telemetry`` or ``<prefix>/<building>/points/<point>``.
        A point name may itself contain ``/`` (everything after ``points/``).
    prefix : str
        First topic level.

    Returns
    -------
    (building, point)
        ``point`` is None for the ``telemetry`` form.

    Raises
    ------
    MessageRejected
        ``bad_topic`` when the topic follows neither form.
    """
    parts = topic.split("/")
    if len(parts) >= 3 and parts[0] == prefix and parts[1]:
        building = parts[1]
        if len(parts) == 3 and parts[2] == "telemetry":
            return building, None
        point = "/".join(parts[3:])
        if parts[2] == "points" and point:
            return building, point
    raise MessageRejected(
        Reason.BAD_TOPIC,
        f"topic {topic!r} is not {prefix}/<building>/telemetry or "
        f"{prefix}/<building>/points/<point>",
        building=parts[1] if len(parts) >= 2 and parts[0] == prefix and parts[1] else None,
    )


def parse_time(value: Any, *, now: datetime | None = None,
               max_future: timedelta | None = None, earliest: datetime | None = None,
               grid: timedelta | None = None) -> datetime:
    """Parse an ISO-8601 timestamp that carries a UTC offset, to UTC.

    Parameters
    ----------
    value : str or datetime
        e.g. ``"2015-04-11T10:00:00-07:00"`` or ``"2015-04-11T17:00:00Z"``.
    now : datetime, optional
        Reference time for the future check (tz-aware).
    max_future : timedelta, optional
        With ``now``: the latest accepted time is ``now + max_future``.
    earliest : datetime, optional
        The earliest accepted time (tz-aware).
    grid : timedelta, optional
        The time must be a multiple of ``grid`` since the Unix epoch.

    Returns
    -------
    datetime
        tz-aware, in UTC.

    Raises
    ------
    ValueError
        With ``reason`` attribute ``missing_time``, ``unparsable_time``,
        ``time_without_offset``, ``future_time``, ``past_time`` or ``off_grid``. A time
        that cannot be converted to UTC at all (year 1 or 9999 with an offset) is
        ``past_time`` or ``future_time``, never an ``OverflowError``.
    """
    try:
        return _parse_time(value, now, max_future, earliest, _micros(grid))
    except _Bad as bad:
        err = ValueError(f"{bad.reason.value}: {bad.detail}")
        err.reason = bad.reason  # type: ignore[attr-defined]
        raise err from None


def _parse_time(value: Any, now: datetime | None, max_future: timedelta | None,
                earliest: datetime | None = None, grid_us: int | None = None) -> datetime:
    if value is None:
        raise _Bad(Reason.MISSING_TIME, 'no "time": add an ISO-8601 time with UTC offset')
    if isinstance(value, datetime):
        parsed = value
    elif isinstance(value, str):
        try:
            parsed = datetime.fromisoformat(value.strip())
        except ValueError:
            raise _Bad(Reason.UNPARSABLE_TIME,
                       f"time {value!r} is not ISO-8601, e.g. 2015-04-11T10:00:00-07:00") from None
    else:
        raise _Bad(Reason.UNPARSABLE_TIME,
                   f"time must be an ISO-8601 string, got {type(value).__name__}")
    if parsed.tzinfo is None or parsed.utcoffset() is None:
        raise _Bad(Reason.TIME_WITHOUT_OFFSET,
                   f"time {str(value)!r} has no UTC offset: append Z or +HH:MM")
    try:
        parsed = parsed.astimezone(UTC)
    except OverflowError:  # year 1 or 9999 shifted by its offset leaves datetime's range
        late = parsed.year > 1
        raise _Bad(Reason.FUTURE_TIME if late else Reason.PAST_TIME,
                   f"time {str(value)!r} is outside the representable range; send a "
                   "plausible measurement time") from None
    if now is not None and max_future is not None and parsed > now + max_future:
        raise _Bad(Reason.FUTURE_TIME,
                   f"time {parsed.isoformat()} is more than {max_future} ahead of "
                   f"{now.astimezone(UTC).isoformat()}: check the publisher's clock")
    if earliest is not None and parsed < earliest:
        raise _Bad(Reason.PAST_TIME,
                   f"time {parsed.isoformat()} is before {earliest.astimezone(UTC).isoformat()}, "
                   "the earliest plausible time of this building: check the publisher's clock "
                   "(or the setting mqtt.earliest_time)")
    if grid_us is not None and _off_grid(parsed, grid_us):
        raise _Bad(Reason.OFF_GRID,
                   f"time {parsed.isoformat()} is not on the {_span(grid_us)} grid: stamp "
                   f"readings with the start of their {_span(grid_us)} interval (docs/data.md)")
    return parsed


_DAY_US = 86_400_000_000


def _off_grid(t: datetime, grid_us: int) -> bool:
    """``t`` (UTC) is not a multiple of ``grid_us`` microseconds since the epoch; for a grid
    that divides a day (every site step does) by the time of day alone."""
    if _DAY_US % grid_us:
        return bool((t - EPOCH) // timedelta(microseconds=1) % grid_us)
    return bool(((t.hour * 3600 + t.minute * 60 + t.second) * 1_000_000 + t.microsecond)
                % grid_us)


def _micros(grid: timedelta | None) -> int | None:
    return None if grid is None else grid // timedelta(microseconds=1)


def _span(grid_us: int) -> str:
    seconds = grid_us / 1e6
    return f"{int(seconds) // 60}-min" if seconds % 60 == 0 else f"{seconds:g}-s"


def _check_value(point: str, value: Any, spec: PointSpec) -> float:
    # bool is an int subclass in Python but never a measurement.
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _Bad(Reason.WRONG_TYPE,
                   f"point {point!r}: value {_short(value)} is a {type(value).__name__}, "
                   "expected a number")
    if isinstance(value, int) and not spec.low <= value <= spec.high:
        # exact comparison: a 400-digit integer is absurd, and float() of it would raise
        raise _Bad(Reason.ABSURD_VALUE,
                   f"point {point!r}: {_short(value)} {spec.unit} is outside the plausible "
                   f"range [{spec.low:g}, {spec.high:g}] for a {spec.kind.value} point")
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    if not math.isfinite(number):
        raise _Bad(Reason.NOT_FINITE, f"point {point!r}: value {_short(value)} is not finite; "
                   "omit the reading when there is no measurement")
    if not spec.low <= number <= spec.high:
        raise _Bad(Reason.ABSURD_VALUE,
                   f"point {point!r}: {number:g} {spec.unit} is outside the plausible range "
                   f"[{spec.low:g}, {spec.high:g}] for a {spec.kind.value} point")
    return number


def _short(value: Any, limit: int = 40) -> str:
    """``repr`` of a value, cut to ``limit`` characters (a dead letter's detail stays short)."""
    text = repr(value) if not isinstance(value, int) or value.bit_length() < 128 \
        else f"<integer of {len(str(abs(value)))} digits>"
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _loads(payload: bytes | str, building: str) -> Any:
    # NaN/Infinity/-Infinity literals (not strict JSON, but Python and some
    # gateways emit them) parse to floats so they are rejected as not_finite.
    try:
        text = payload.decode("utf-8") if isinstance(payload, bytes) else payload
        return json.loads(text, parse_constant=float)
    except ValueError as exc:  # UnicodeDecodeError and JSONDecodeError
        raise MessageRejected(Reason.MALFORMED_JSON,
                              f"payload is not valid UTF-8 JSON ({exc})", building) from None
    except RecursionError:  # e.g. 40 kB of "[": deeper than the parser's stack
        raise MessageRejected(Reason.MALFORMED_JSON,
                              "payload is nested too deeply to parse: send the map or batch "
                              "form", building) from None


def validate_message(
    topic: str,
    payload: bytes | str,
    catalogues: Mapping[str, PointCatalogue],
    *,
    now: datetime | None = None,
    limits: IngestLimits = _DEFAULT_LIMITS,
    prefix: str = DEFAULT_PREFIX,
    properties: Mapping[str, str] | None = None,
) -> ValidatedMessage:
    """Validate one telemetry message.

    Parameters
    ----------
    topic : str
        MQTT topic (see :func:`parse_topic`).
    payload : bytes or str
        Message body. Accepted forms:

        - telemetry, map form: ``{"time": T, "readings": {point: value, ...}}``
        - telemetry, batch form: ``{"readings": [{"point": P, "time": T, "value": V}, ...]}``
          (an item without ``time`` takes the top-level ``time`` if any)
        - point topic, object form: ``{"time": T, "value": V}``
        - point topic, bare form: a JSON number ``V``; its time comes from the
          MQTT v5 user property ``time`` (``properties["time"]``).

        ``T`` is ISO-8601 with a UTC offset; ``V`` is a JSON number.
    catalogues : Mapping[str, PointCatalogue]
        Known buildings -> their point catalogues.
    now : datetime, optional
        Reference time for the future check; default: current UTC time.
    limits : IngestLimits
        Size, count and clock-skew limits.
    prefix : str
        First topic level.
    properties : Mapping[str, str], optional
        MQTT v5 user properties of the message.

    Returns
    -------
    ValidatedMessage
        Accepted readings (UTC) and the readings rejected one by one.

    Raises
    ------
    MessageRejected
        When the message as a whole is unusable; see :class:`Reason`.
    """
    size = len(payload.encode() if isinstance(payload, str) else payload)
    building: str | None = None
    try:
        building, topic_point = parse_topic(topic, prefix)
    except MessageRejected as rej:
        building = rej.building
        if size <= limits.max_payload_bytes:
            raise
    if size > limits.max_payload_bytes:
        raise MessageRejected(Reason.PAYLOAD_TOO_LARGE,
                              f"payload is {size} bytes, the limit is {limits.max_payload_bytes}: "
                              "split it into several messages", building)
    catalogue = catalogues.get(building)
    if catalogue is None:
        raise MessageRejected(Reason.UNKNOWN_BUILDING,
                              f"building {building!r} has no point catalogue: register the "
                              "building or fix the topic", building)
    now = datetime.now(UTC) if now is None else now
    body = _loads(payload, building)

    def reject(reason: Reason, detail: str) -> MessageRejected:
        return MessageRejected(reason, detail, building)

    earliest, grid = _time_rules(catalogue, limits)
    grid_us = _micros(grid)

    parsed: dict[str, datetime] = {}  # batch items mostly share a few time strings

    def parse(raw: Any) -> datetime:
        if isinstance(raw, str):
            hit = parsed.get(raw)
            if hit is None:
                hit = parsed[raw] = _parse_time(raw, now, limits.max_future, earliest, grid_us)
            return hit
        return _parse_time(raw, now, limits.max_future, earliest, grid_us)

    def message_time(raw: Any) -> datetime:
        try:
            return parse(raw)
        except _Bad as bad:
            raise reject(bad.reason, bad.detail) from None

    # Normalise every form to a list of (point, raw time, raw value) triples;
    # a per-item structural problem becomes a RejectedReading.
    items: list[tuple[str, Any, Any]] = []
    accepted: list[Reading] = []
    rejected: list[RejectedReading] = []
    if topic_point is not None:
        if isinstance(body, dict):
            if "value" not in body:
                raise reject(Reason.NO_READINGS, 'point payload has no "value"')
            items.append((topic_point, message_time(body.get("time")), body["value"]))
        elif isinstance(body, (int, float)) and not isinstance(body, bool):
            when = (properties or {}).get("time")
            items.append((topic_point, message_time(when), body))
        else:
            raise reject(Reason.NOT_AN_OBJECT,
                         'point payload must be {"time": ..., "value": ...} or a bare number '
                         f"with an MQTT v5 user property 'time', got {type(body).__name__}")
    else:
        if not isinstance(body, dict):
            raise reject(Reason.NOT_AN_OBJECT,
                         f"telemetry payload must be a JSON object, got {type(body).__name__}")
        raw = body.get("readings")
        if not raw:
            raise reject(Reason.NO_READINGS,
                         'no "readings": send {"time": ..., "readings": {point: value}} or '
                         '{"readings": [{"point": ..., "time": ..., "value": ...}]}')
        if not isinstance(raw, (dict, list)):
            raise reject(Reason.NOT_AN_OBJECT,
                         f'"readings" must be an object or a list, got {type(raw).__name__}')
        if len(raw) > limits.max_readings:
            raise reject(Reason.TOO_MANY_READINGS,
                         f"{len(raw)} readings in one message, the limit is "
                         f"{limits.max_readings}: split it")
        if isinstance(raw, dict):
            when = message_time(body.get("time"))
            # the common case here: a float inside its point's range (JSON keys are str;
            # NaN and infinities fail the comparison); the rest goes through the checks below
            get = catalogue.get
            for point, value in raw.items():
                spec = get(point)
                if spec is not None and type(value) is float and \
                        spec.low <= value <= spec.high:
                    accepted.append(_new_reading(Reading, (point, when, value)))
                else:
                    items.append((point, when, value))
        else:
            # the top-level time only concerns the items without their own: a bad one
            # rejects those items, not the items that carry a good time
            shared: datetime | _Bad | None = None
            if body.get("time") is not None:
                try:
                    shared = parse(body["time"])
                except _Bad as bad:
                    shared = bad
            for i, item in enumerate(raw):
                if not isinstance(item, dict) or not isinstance(item.get("point"), str) \
                        or "value" not in item:
                    rejected.append(RejectedReading(
                        item.get("point") if isinstance(item, dict) else None,
                        Reason.MALFORMED_READING,
                        f'readings[{i}] must be {{"point": str, "time": str, "value": number}}'))
                    continue
                items.append((item["point"], item.get("time", shared), item["value"]))

    for point, when, value in items:
        spec = catalogue.get(point)
        # the common case first: a float inside the point's range with a parsed time; the
        # same outcome as the checks below (NaN and infinities fail the comparison)
        if spec is not None and type(value) is float and spec.low <= value <= spec.high \
                and type(when) is datetime:
            accepted.append(Reading(point, when, value))
            continue
        try:
            if spec is None:
                raise _Bad(Reason.UNKNOWN_POINT,
                           f"point {point!r} is not in the catalogue of building {building!r}: "
                           "add it or fix the point name")
            number = _check_value(point, value, spec)
            if isinstance(when, _Bad):
                raise when
            if not isinstance(when, datetime):
                when = parse(when)
            accepted.append(Reading(point, when, number))
        except _Bad as bad:
            rejected.append(RejectedReading(point, bad.reason, bad.detail))
    # distinct keys: one reading (point topic), or one time and a JSON object's keys
    checked = CheckedReadings if topic_point is not None or isinstance(raw, dict) else tuple
    return ValidatedMessage(building, checked(accepted), tuple(rejected))


@dataclass(frozen=True, slots=True)
class Accepted:
    """What one message leaves to store and to count (:func:`accept`, :func:`refuse`).

    Attributes
    ----------
    building : str or None
        The building the topic names (None when it names none).
    readings : tuple of Reading
        Readings to store for ``building`` (none when the whole message was rejected).
    rejections : tuple of RejectedReading
        The readings rejected one by one, or the whole message as one rejection with
        ``point`` None.
    dead_letters : tuple of dict
        One per rejection: keyword arguments of ``Storage.put_dead_letter``, as
        ``Storage.put_many`` takes them.
    error : MessageRejected or None
        Set when the message was rejected as a whole.
    """

    building: str | None
    readings: tuple[Reading, ...] = ()
    rejections: tuple[RejectedReading, ...] = ()
    dead_letters: tuple[dict[str, Any], ...] = ()
    error: MessageRejected | None = None

    @property
    def reasons(self) -> Counter[str]:
        """Rejections by reason code (``rejected`` of the counters and metrics)."""
        return Counter(r.reason.value for r in self.rejections)


def dead_letters(topic: str, payload: bytes | str, received: datetime, building: str | None,
                 rejections: tuple[RejectedReading, ...]) -> tuple[dict[str, Any], ...]:
    """One dead letter per rejection, reason ``"<code>: <detail>"`` (keyword arguments of
    ``Storage.put_dead_letter``)."""
    return tuple({"topic": topic, "payload": payload, "building": building,
                  "reason": f"{r.reason.value}: {r.detail}", "received_at": received}
                 for r in rejections)


def refuse(topic: str, payload: bytes | str, received: datetime,
           error: MessageRejected) -> Accepted:
    """A message rejected as a whole: no readings, one dead letter with ``error``'s reason."""
    rejections = (RejectedReading(None, error.reason, error.detail),)
    return Accepted(error.building, (), rejections,
                    dead_letters(topic, payload, received, error.building, rejections), error)


def accept(
    topic: str,
    payload: bytes | str,
    received: datetime,
    catalogues: Mapping[str, PointCatalogue],
    *,
    limits: IngestLimits = _DEFAULT_LIMITS,
    prefix: str = DEFAULT_PREFIX,
    properties: Mapping[str, str] | None = None,
) -> Accepted:
    """Validate one message received at ``received`` (also the reference time of the
    future check) and say what to store: readings and dead letters.

    The one ingest path of MQTT and REST. Parameters as :func:`validate_message`; a message
    rejected as a whole does not raise but comes back with :attr:`Accepted.error` set
    (:func:`refuse`).
    """
    try:
        result = validate_message(topic, payload, catalogues, now=received, limits=limits,
                                  prefix=prefix, properties=properties)
    except MessageRejected as rej:
        return refuse(topic, payload, received, rej)
    except Exception as exc:  # a bug must cost one message, never the stream
        try:
            building = parse_topic(topic, prefix)[0]
        except MessageRejected as rej:
            building = rej.building
        text = str(exc)[:300] or "no message"
        log.error("validation raised %s on %s: %s", type(exc).__name__, topic, text,
                  exc_info=exc, extra={"building": building, "reason": "internal_error"})
        return refuse(topic, payload, received, MessageRejected(
            Reason.INTERNAL_ERROR, f"validation raised {type(exc).__name__}: {text} (a bug; "
            "please report it with this payload)", building))
    if not result.rejected:
        return Accepted(result.building, result.readings)
    return Accepted(result.building, result.readings, result.rejected,
                    dead_letters(topic, payload, received, result.building, result.rejected))


def log_rejections(acc: Accepted, topic: str, transport: str) -> None:
    """Log the rejections of one message: one WARNING line per reason, with the fields
    ``building``, ``reason``, ``transport``, ``topic``, ``count``, ``points`` (up to 10) and
    ``detail`` (the first rejection's) for structured logs (``zonecast.service.logs``)."""
    if not acc.rejections:
        return
    groups: dict[str, list[RejectedReading]] = {}
    for r in acc.rejections:
        groups.setdefault(r.reason.value, []).append(r)
    what = "message" if acc.error is not None else "readings"
    for reason, rejections in groups.items():
        points = [r.point for r in rejections if r.point is not None][:10]
        log.warning("%s rejected (%s, %d) on %s: %s", what, reason, len(rejections), topic,
                    rejections[0].detail,
                    extra={"building": acc.building, "reason": reason, "transport": transport,
                           "topic": topic, "count": len(rejections), "points": points,
                           "detail": rejections[0].detail})
