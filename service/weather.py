"""Weather forecasts received over MQTT (``<prefix>/<building>/weather_forecast``) and REST
(``POST /api/v1/buildings/{id}/weather_forecast``): one acceptance path for both.

:func:`accept_weather` validates a message (size, JSON, topic, building, then the body rules
of :func:`zonecast.estimator.weather_forecast.parse_weather_forecast`: plausible values,
equal lengths, increasing times with offsets, 24-48 h reach) and says what to do: hand the
forecast to the building's runner, or store a dead letter whose reason is
``bad_weather_forecast: <code>: <detail>`` (the code from the estimator's
:class:`~zonecast.estimator.weather_forecast.WeatherForecastError`). It never raises.
docs/data.md ("Weather forecasts") is the body's contract.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Collection
from dataclasses import dataclass
from datetime import datetime

import pandas as pd
from zonecast.estimator.weather_forecast import (
    WeatherForecast,
    WeatherForecastError,
    parse_weather_forecast,
)

__all__ = ["WEATHER_SUFFIX", "WeatherAccepted", "accept_weather", "is_weather_topic"]

WEATHER_SUFFIX = "weather_forecast"
log = logging.getLogger(__name__)


def is_weather_topic(topic: str, prefix: str) -> bool:
    """``<prefix>/<building>/weather_forecast``?"""
    parts = topic.split("/")
    return len(parts) == 3 and parts[0] == prefix and bool(parts[1]) \
        and parts[2] == WEATHER_SUFFIX


@dataclass(frozen=True)
class WeatherAccepted:
    """The outcome of one weather-forecast message.

    Attributes
    ----------
    building : str or None
    forecast : WeatherForecast or None
        The validated forecast (None when rejected).
    reason, detail : str or None
        Why it was rejected (stable code, text).
    dead_letters : tuple of dict
        Keyword arguments of ``Storage.put_dead_letter`` (``Storage.put_many``).
    """

    building: str | None
    forecast: WeatherForecast | None
    reason: str | None = None
    detail: str | None = None
    dead_letters: tuple[dict, ...] = ()


def accept_weather(topic: str, payload: bytes | str, received: datetime,
                   buildings: Collection[str], *, prefix: str,
                   max_bytes: int = 1024 * 1024) -> WeatherAccepted:
    """Validate one weather-forecast message received at ``received`` (UTC)."""
    parts = topic.split("/")
    building = parts[1] if len(parts) >= 2 and parts[0] == prefix and parts[1] else None

    def reject(reason: str, detail: str) -> WeatherAccepted:
        letter = {"topic": topic, "payload": payload, "building": building,
                  "reason": f"bad_weather_forecast: {reason}: {detail}", "received_at": received}
        log.warning("weather forecast rejected (%s) on %s: %s", reason, topic, detail,
                    extra={"building": building, "reason": reason, "topic": topic})
        return WeatherAccepted(building, None, reason, detail, (letter,))

    try:
        if not is_weather_topic(topic, prefix):
            return reject("bad_topic", f"topic {topic!r} is not {prefix}/<building>/"
                          f"{WEATHER_SUFFIX}")
        if building not in buildings:
            return reject("unknown_building", f"building {building!r} is not served")
        if len(payload) > max_bytes:
            return reject("payload_too_large", f"{len(payload)} bytes, at most {max_bytes}")
        try:
            body = json.loads(payload)
        except (ValueError, UnicodeDecodeError) as exc:
            return reject("malformed_json", str(exc)[:200])
        wf = parse_weather_forecast(body, now=pd.Timestamp(received))
    except WeatherForecastError as exc:
        return reject(exc.reason, exc.detail)
    except Exception as exc:  # noqa: BLE001 - one bad message must not stop ingest
        return reject("internal_error", f"{type(exc).__name__}: {str(exc)[:300]}")
    return WeatherAccepted(building, wf)
