"""Weather forecasts as an input of the served zone-temperature forecast.

A :class:`WeatherForecast` is a 24-48 h forecast of outdoor temperature and station
irradiance (GHI, DNI, DHI) issued at some time; docs/data.md ("Weather forecasts") is the
contract. Each value is the quantity *at* its time stamp (temperature instantaneous,
irradiance the mean of an interval centred there); the estimator interpolates linearly
in time to the middle of each 15-min model interval and transposes the irradiance onto
the four facades with the same rules as the telemetry
(:func:`~zonecast.estimator.solar.transpose`).

When no forecast is fresh (none received, older than ``max_age``, or not covering a lead),
:class:`DiurnalWeather` supplies the fallback: *persistence with the diurnal shape of the
last days*. Per local time of day it keeps an exponentially weighted mean of the outdoor
temperature and of the four facade irradiances over the days seen (forgetting factor
``lam`` per day); the forecast is that shape, with the outdoor temperature shifted by the
current deviation from the shape, decaying as exp(-lead / tau). O(1) per step.

A received forecast is corrected by the newest measurement the same way
(:func:`observation_correction`): its outdoor temperature is shifted by the difference
between the measured value and the forecast's value for the current interval, decaying as
exp(-lead / obs_tau) (a forecast's error persists over hours; the measurement is the one
value of the next day that is known exactly). ``obs_tau`` is the fallback's ``tau``, not a
separate knob. The irradiance is not corrected (its error is cloud cover, which the current
value says little about a few hours ahead).

Optionally (``streaming.WEATHER_BLEND``, off by default: docs/forecasts.md "Forecast and
the recent days, combined") a received forecast F is then combined with the fallback D by
lead (:class:`~zonecast.estimator.calibration.WeatherBlend`):
served = D + a (F - D), with the weight a per lead bin and channel the least-squares
slope of the measured weather's departure from D on the forecast's, O - D ~ a (F - D),
learned online from the building's own pairs (exponential forgetting) and clipped to
[0, 1]; a = 1 (the forecast as received) until enough pairs are scored. This is the
combination of a forecast with climatology of forecast post-processing (model output
statistics): where a day-ahead forecast's error is as large as the weather's own
day-to-day change, the conditional mean of the weather given the forecast lies between the
forecast and the recent days' shape, and a shrinks towards it; where the forecast is sharp
a stays near 1.

:func:`from_open_meteo` reads Open-Meteo's JSON forecast format (``hourly`` arrays
``time``, ``temperature_2m``, ``shortwave_radiation``, ``direct_normal_irradiance``,
``diffuse_radiation``; the radiation values are means over the preceding hour, so they are
placed at the middle of that hour).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

__all__ = [
    "WEATHER_DEFAULTS",
    "DiurnalWeather",
    "WeatherForecast",
    "WeatherForecastError",
    "from_open_meteo",
    "observation_correction",
    "parse_weather_forecast",
]

#: fallback defaults, chosen on the training weeks (docs/forecasts.md "Served forecast")
WEATHER_DEFAULTS = {"lam": 0.5, "tau_h": 6.0, "max_age_h": 24.0, "obs_tau_h": 6.0}

#: plausible ranges of the values [degC], [W/m2]
TEMPERATURE_RANGE = (-60.0, 60.0)
IRRADIANCE_RANGE = (0.0, 1500.0)
MAX_POINTS = 1000
_ONE_DAY = pd.Timedelta(days=1)


class WeatherForecastError(ValueError):
    """A weather forecast that cannot be used; ``reason`` is a stable code."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason, self.detail = reason, detail


@dataclass(frozen=True)
class WeatherForecast:
    """A weather forecast.

    Attributes
    ----------
    issued : pandas.Timestamp
        When the forecast was made (UTC); it is used for model forecasts issued at or
        after this time.
    times : pandas.DatetimeIndex
        Value times (UTC, strictly increasing).
    temperature : ndarray
        Outdoor air temperature [degC].
    ghi, dni, dhi : ndarray
        Global horizontal, direct normal and diffuse horizontal irradiance [W/m2].
    source : str
        Where it came from (free text, e.g. ``open-meteo``, ``testbed``).
    """

    issued: pd.Timestamp
    times: pd.DatetimeIndex
    temperature: np.ndarray
    ghi: np.ndarray
    dni: np.ndarray
    dhi: np.ndarray
    source: str = ""

    def __post_init__(self):
        # nanosecond resolution: the estimator's grid arithmetic is in ns
        object.__setattr__(self, "issued", pd.Timestamp(self.issued).tz_convert("UTC").as_unit("ns"))
        object.__setattr__(self, "times", pd.DatetimeIndex(self.times).tz_convert("UTC").as_unit("ns"))

    def values_at(self, times_ns: np.ndarray) -> np.ndarray:
        """Linear interpolation to UTC times (ns): (N, 4) temperature, GHI, DNI, DHI;
        NaN outside the forecast's span."""
        t = np.asarray(times_ns, dtype=np.int64)
        src = self.times.asi8
        out = np.full((len(t), 4), np.nan)
        inside = (t >= src[0]) & (t <= src[-1])
        if inside.any():
            x = (t[inside] - src[0]).astype(float)
            xp = (src - src[0]).astype(float)
            for j, col in enumerate((self.temperature, self.ghi, self.dni, self.dhi)):
                out[inside, j] = np.interp(x, xp, col)
        return out

    def to_json(self) -> dict:
        """The REST/MQTT body of this forecast (docs/data.md)."""
        return {"issued": self.issued.isoformat(), "source": self.source,
                "times": [t.isoformat() for t in self.times],
                "temperature": self.temperature.tolist(), "ghi": self.ghi.tolist(),
                "dni": self.dni.tolist(), "dhi": self.dhi.tolist()}


def observation_correction(forecast_now: float, measured_now: float, lead_h: np.ndarray,
                           tau_h: float = WEATHER_DEFAULTS["obs_tau_h"]) -> np.ndarray:
    """Additive correction of a forecast's outdoor temperature [K] at leads ``lead_h`` [h]:
    (measured - forecast) at lead 0, decaying as exp(-lead / tau_h). Zero where either
    value is missing or ``tau_h`` <= 0 (no correction)."""
    lead_h = np.asarray(lead_h, float)
    d = float(measured_now) - float(forecast_now)
    if tau_h <= 0 or not math.isfinite(d):
        return np.zeros_like(lead_h)
    return d * np.exp(-lead_h / tau_h)


def _time(value, what: str) -> pd.Timestamp:
    try:
        t = pd.Timestamp(value)
    except (ValueError, TypeError) as exc:
        raise WeatherForecastError("unparsable_time", f"{what} {value!r}: {exc}") from None
    if t.tzinfo is None:
        raise WeatherForecastError("time_without_offset",
                                   f"{what} {value!r} needs a UTC offset, e.g. 2015-05-13T00:00:00Z")
    return t.tz_convert("UTC")


def parse_weather_forecast(body: Mapping, *, now: pd.Timestamp | None = None,
                           min_hours: float = 24.0, max_hours: float = 48.0,
                           max_future: pd.Timedelta = _ONE_DAY) -> WeatherForecast:
    """Validate a weather-forecast body (docs/data.md) into a :class:`WeatherForecast`.

    Parameters
    ----------
    body : mapping
        ``issued``, ``times`` (ISO 8601 with offset), ``temperature`` [degC], ``ghi``,
        ``dni``, ``dhi`` [W/m2] (equal lengths), optional ``source``.
    now : Timestamp, optional
        Receive time (UTC); ``issued`` may not lie more than ``max_future`` after it.
    min_hours, max_hours : float
        The forecast must reach at least ``min_hours`` beyond ``issued`` and span at most
        ``max_hours`` [h] (plus one hour of slack each way).

    Raises
    ------
    WeatherForecastError
        With a stable ``reason``: ``not_an_object``, ``missing_field``, ``wrong_type``,
        ``length_mismatch``, ``too_many_points``, ``unparsable_time``,
        ``time_without_offset``, ``future_time``, ``not_increasing``, ``not_finite``,
        ``absurd_value``, ``too_short``, ``too_long``.
    """
    if not isinstance(body, Mapping):
        raise WeatherForecastError("not_an_object", "the body must be a JSON object")
    fields = ("issued", "times", "temperature", "ghi", "dni", "dhi")
    missing = [f for f in fields if f not in body]
    if missing:
        raise WeatherForecastError("missing_field", f"missing {missing}; need {list(fields)}")
    issued = _time(body["issued"], "issued")
    if now is not None and issued > pd.Timestamp(now).tz_convert("UTC") + max_future:
        raise WeatherForecastError("future_time", f"issued {issued.isoformat()} lies more than "
                                   f"{max_future} after the receive time")
    arrays = {}
    for f in fields[1:]:
        v = body[f]
        if not isinstance(v, list | tuple):
            raise WeatherForecastError("wrong_type", f"{f} must be a list")
        arrays[f] = v
    n = len(arrays["times"])
    if n < 2:
        raise WeatherForecastError("too_short", "need at least two times")
    if n > MAX_POINTS:
        raise WeatherForecastError("too_many_points", f"{n} times, at most {MAX_POINTS}")
    bad_len = [f for f in fields[2:] if len(arrays[f]) != n]
    if bad_len:
        raise WeatherForecastError("length_mismatch", f"{bad_len} do not have {n} values "
                                   "like times")
    times = pd.DatetimeIndex([_time(x, f"times[{i}]") for i, x in enumerate(arrays["times"])])
    if not (np.diff(times.asi8) > 0).all():
        raise WeatherForecastError("not_increasing", "times must be strictly increasing")
    vals = {}
    for f in fields[2:]:
        for i, x in enumerate(arrays[f]):
            if isinstance(x, bool) or not isinstance(x, int | float):
                raise WeatherForecastError("wrong_type", f"{f}[{i}] = {x!r} is not a number")
            if not math.isfinite(x):
                raise WeatherForecastError("not_finite", f"{f}[{i}] = {x!r}")
        a = np.asarray(arrays[f], dtype=float)
        lo, hi = TEMPERATURE_RANGE if f == "temperature" else IRRADIANCE_RANGE
        out = (a < lo) | (a > hi)
        if out.any():
            i = int(np.argmax(out))
            raise WeatherForecastError("absurd_value", f"{f}[{i}] = {a[i]} outside "
                                       f"[{lo}, {hi}]")
        vals[f] = a
    reach = (times[-1] - issued) / pd.Timedelta(hours=1)
    span = (times[-1] - times[0]) / pd.Timedelta(hours=1)
    if reach < min_hours - 1:
        raise WeatherForecastError("too_short", f"reaches {reach:.1f} h beyond issued, need "
                                   f"{min_hours:g} h")
    if span > max_hours + 1:
        raise WeatherForecastError("too_long", f"spans {span:.1f} h, at most {max_hours:g} h")
    return WeatherForecast(issued, times, vals["temperature"], vals["ghi"], vals["dni"],
                           vals["dhi"], str(body.get("source", ""))[:64])


def from_open_meteo(doc: Mapping, issued=None) -> dict:
    """An Open-Meteo forecast response (JSON, ``hourly`` with ``time``, ``temperature_2m``
    [°C], ``shortwave_radiation``, ``direct_normal_irradiance``, ``diffuse_radiation``
    [W/m²]) -> the body of :func:`parse_weather_forecast`.

    Time stamps are local times without offset plus ``utc_offset_seconds`` (or Unix
    seconds with ``timeformat=unixtime``). Radiation is the mean over the preceding hour,
    so it is stamped at the middle of that hour (30 min earlier); temperature is
    instantaneous. ``issued`` defaults to the first time stamp. Rows with a missing
    value (null) are left out.

    Raises
    ------
    WeatherForecastError
        Not an Open-Meteo response with these variables, or units other than °C and W/m².
    """
    hourly = doc.get("hourly") if isinstance(doc, Mapping) else None
    need = ("time", "temperature_2m", "shortwave_radiation", "direct_normal_irradiance",
            "diffuse_radiation")
    if not isinstance(hourly, Mapping) or any(k not in hourly for k in need):
        raise WeatherForecastError("missing_field", f"an Open-Meteo response with hourly {need}")
    units = doc.get("hourly_units", {}) or {}
    if units.get("temperature_2m", "°C") != "°C":
        raise WeatherForecastError("wrong_unit", "temperature_2m must be in °C "
                                   "(request temperature_unit=celsius)")
    for k in need[2:]:
        if units.get(k, "W/m²") not in ("W/m²", "W/m2"):
            raise WeatherForecastError("wrong_unit", f"{k} must be in W/m²")
    raw = hourly["time"]
    if raw and isinstance(raw[0], int | float):
        t = pd.DatetimeIndex(pd.to_datetime(np.asarray(raw, dtype=np.int64), unit="s", utc=True))
    else:
        offset = pd.Timedelta(seconds=int(doc.get("utc_offset_seconds", 0)))
        t = pd.DatetimeIndex(pd.to_datetime(list(raw))).tz_localize("UTC") - offset
    temp = np.array([np.nan if x is None else x for x in hourly["temperature_2m"]], float)
    rad = [np.array([np.nan if x is None else x for x in hourly[k]], float) for k in need[2:]]
    # radiation: preceding-hour mean -> the hour's middle; temperature stays where it is
    half = pd.Timedelta(minutes=30)
    t_rad = t - half
    ok_t = np.isfinite(temp)
    ok_r = np.isfinite(rad[0]) & np.isfinite(rad[1]) & np.isfinite(rad[2])
    # one time axis: the radiation times; temperature interpolated onto them
    tt = t_rad[ok_r]
    if ok_t.sum() < 2 or len(tt) < 2:
        raise WeatherForecastError("too_short", "fewer than two complete hours")
    temp_at = np.interp(tt.asi8.astype(float), t[ok_t].asi8.astype(float), temp[ok_t])
    first = pd.Timestamp(t[0]) if issued is None else pd.Timestamp(issued).tz_convert("UTC")
    return {"issued": first.isoformat(), "source": "open-meteo",
            "times": [x.isoformat() for x in tt], "temperature": temp_at.tolist(),
            "ghi": rad[0][ok_r].tolist(), "dni": rad[1][ok_r].tolist(),
            "dhi": rad[2][ok_r].tolist()}


class DiurnalWeather:
    """Fallback weather: the diurnal shape of the last days (module docstring).

    Parameters
    ----------
    per_day : int
        Intervals per day (96 for 15 min).
    lam : float
        Forgetting factor per day of each time-of-day bin [-].
    tau_h : float
        Decay time of the current outdoor-temperature deviation [h].
    """

    def __init__(self, per_day: int, *, lam: float = WEATHER_DEFAULTS["lam"],
                 tau_h: float = WEATHER_DEFAULTS["tau_h"]):
        if not 0.0 < lam <= 1.0:
            raise ValueError(f"lam must lie in (0, 1], got {lam}")
        self.per_day, self.lam, self.tau_h = int(per_day), float(lam), float(tau_h)
        self.w = np.zeros(self.per_day)
        # Ta [degC], solE, solS, solW, solN, solH [W/m2] (a checkpoint of another shape is
        # not loaded: load_state_arrays)
        self.mean = np.zeros((self.per_day, 6))

    def update(self, tod: int, ta: float, sol: np.ndarray) -> bool:
        """Learn one row (local time-of-day bin ``tod``); skipped when anything is missing."""
        row = np.concatenate([[ta], np.asarray(sol, float)])
        if not np.isfinite(row).all():
            return False
        w = self.lam * self.w[tod] + 1.0
        self.mean[tod] = self.mean[tod] + (row - self.mean[tod]) / w
        self.w[tod] = w
        return True

    def forecast(self, tods: np.ndarray, lead_h: np.ndarray, current: np.ndarray) -> np.ndarray:
        """(H, 6) Ta, solE..solH at the bins ``tods`` and leads ``lead_h`` [h]; ``current``
        the measured (Ta, sol x 5) of the issue row (NaN where none; bins never seen are
        NaN)."""
        tods = np.asarray(tods, dtype=np.int64)
        seen = self.w[tods] > 0
        out = np.where(seen[:, None], self.mean[tods], np.nan)
        cur = np.asarray(current, float)
        if seen[0] and np.isfinite(cur[0]):
            d = cur[0] - out[0, 0]
            out[:, 0] = out[:, 0] + d * np.exp(-np.asarray(lead_h, float) / self.tau_h)
        return out

    def state_arrays(self, prefix: str = "wfb_") -> dict[str, np.ndarray]:
        return {f"{prefix}w": self.w, f"{prefix}mean": self.mean}

    def load_state_arrays(self, arrays: Mapping[str, np.ndarray], prefix: str = "wfb_") -> bool:
        if f"{prefix}w" not in arrays or np.shape(arrays[f"{prefix}mean"]) != self.mean.shape:
            return False
        self.w = np.array(arrays[f"{prefix}w"], float)
        self.mean = np.array(arrays[f"{prefix}mean"], float)
        return True

