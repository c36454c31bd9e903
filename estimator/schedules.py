"""EnergyPlus ``Schedule:Compact`` values at the site's local times.

A building's EnergyPlus file often drives a heat flow by a schedule that is not constant:
NREL's 5ZoneAirCooled leaks outdoor air from November to March only, the DOE reference
small office a quarter of it while the fans run. The model needs those values at every
telemetry row and over every forecast horizon, so :class:`CompactSchedule` reads the
object's fields once (epJSON form: ``{"data": [{"field": ...}, ...]}``) into a plain
description that survives JSON (it travels in the model's structure file) and evaluates
it on arrays of times.

What is read (EnergyPlus Input Output Reference, ``Schedule:Compact``): ``Through:
MM/DD`` periods, ``For:`` day lists (``AllDays``, ``Weekdays``, ``Weekends``,
``Holiday(s)``, ``AllOtherDays``, ``Monday`` ... ``Sunday``; design and custom days never
occur in measured data and match nothing), ``Until: HH:MM`` with the value after it.
``Interpolate:`` lines are read and the values stepped (no interpolation); the
description says so. A holiday is a date of the site's thermostat ``holidays``.

Written here because no maintained Python library evaluates EnergyPlus compact schedules
outside EnergyPlus (eppy and the epJSON schema read the fields only); docs/model.md
"Infiltration".
"""

from __future__ import annotations

import datetime as dt
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

__all__ = ["CompactSchedule", "ScheduleError", "local_day_minute"]

_HOUR_NS = 3_600 * 10**9
_DAY_MIN = 1_440
#: UTC offset [min] of each (time zone, UTC hour) met so far (a row at a time costs a dict
#: look-up instead of a pandas time-zone conversion)
_OFFSETS: dict[tuple[str, int], int] = {}


def local_day_minute(times, timezone: str) -> tuple[np.ndarray, np.ndarray]:
    """Local day (days since 1970-01-01) and minute of the day of tz-aware ``times`` in
    ``timezone``."""
    idx = pd.DatetimeIndex(times)
    if idx.tz is None:
        raise ScheduleError("schedule times must be time-zone aware")
    ns = idx.as_unit("ns").asi8
    hours = ns // _HOUR_NS
    keys = [(timezone, int(h)) for h in hours]
    missing = sorted({k[1] for k in keys if k not in _OFFSETS})
    if missing:
        if len(_OFFSETS) > 100_000:
            _OFFSETS.clear()
        probe = pd.DatetimeIndex(np.array(missing, dtype=np.int64) * _HOUR_NS, tz="UTC")
        local = probe.tz_convert(timezone)
        offs = (local.tz_localize(None).as_unit("ns").asi8 - probe.as_unit("ns").asi8) // (
            60 * 10**9)
        _OFFSETS.update({(timezone, h): int(o) for h, o in zip(missing, offs)})
    minutes = ns // (60 * 10**9) + np.array([_OFFSETS[k] for k in keys], dtype=np.int64)
    return minutes // _DAY_MIN, minutes % _DAY_MIN

_DAYS = ("monday", "tuesday", "wednesday", "thursday", "friday", "saturday", "sunday")


class ScheduleError(ValueError):
    """A Schedule:Compact object this reader cannot evaluate."""


def _day_keys(text: str) -> list[str]:
    out = []
    for word in re.split(r"[\s,]+", text.strip().lower()):
        if not word:
            continue
        if word == "holidays":
            word = "holiday"
        out.append(word)
    return out


@dataclass(frozen=True)
class CompactSchedule:
    """A parsed ``Schedule:Compact``.

    Attributes
    ----------
    name : str
    periods : list
        ``[[month, day], [[day keys...], [[minute, value], ...]], ...]`` per ``Through``:
        the period ends on month/day (inclusive); each rule lists its day keys and its
        ``Until`` times as minutes after midnight with the value up to that minute.
    notes : list of str
        What was read approximately (interpolation).
    """

    name: str
    periods: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    #: (until minutes, values) of each local date already evaluated (per holiday flag)
    _days: dict = field(default_factory=dict, compare=False, repr=False)

    # --- reading --------------------------------------------------------------------
    @classmethod
    def from_epjson(cls, name: str, fields: Mapping) -> CompactSchedule:
        """Parse the epJSON fields of a Schedule:Compact object named ``name``."""
        items = [f.get("field") if isinstance(f, Mapping) else f
                 for f in fields.get("data", [])]
        periods: list = []
        notes: list = []
        rule = None
        i = 0
        while i < len(items):
            item = items[i]
            text = str(item).strip()
            low = text.lower()
            if low.startswith("through:"):
                m = re.match(r"through:\s*(\d{1,2})\s*/\s*(\d{1,2})", low)
                if not m:
                    raise ScheduleError(f"schedule {name}: cannot read {text!r} (Through: MM/DD)")
                periods.append([[int(m.group(1)), int(m.group(2))], []])
                rule = None
            elif low.startswith("for:"):
                if not periods:
                    raise ScheduleError(f"schedule {name}: 'For:' before any 'Through:'")
                rule = [_day_keys(text[4:]), []]
                periods[-1][1].append(rule)
            elif low.startswith("interpolate:"):
                if low.split(":", 1)[1].strip() not in ("no", ""):
                    notes.append(f"schedule {name}: interpolation read as steps")
            elif low.startswith("until:"):
                if rule is None:
                    raise ScheduleError(f"schedule {name}: 'Until:' before any 'For:'")
                m = re.match(r"until:\s*(\d{1,2})\s*:\s*(\d{2})\s*(?:,\s*(.+))?$", low)
                if not m:
                    raise ScheduleError(f"schedule {name}: cannot read {text!r} (Until: HH:MM)")
                minute = int(m.group(1)) * 60 + int(m.group(2))
                if m.group(3) is not None:          # IDF style: "Until: 24:00,1.0"
                    value = m.group(3)
                else:                               # epJSON: the value is the next field
                    i += 1
                    if i >= len(items):
                        raise ScheduleError(f"schedule {name}: {text!r} has no value")
                    value = items[i]
                try:
                    rule[1].append([minute, float(value)])
                except (TypeError, ValueError):
                    raise ScheduleError(f"schedule {name}: value {value!r} after {text!r} is "
                                        "not a number") from None
            else:
                raise ScheduleError(f"schedule {name}: cannot read field {text!r}")
            i += 1
        if not periods:
            raise ScheduleError(f"schedule {name}: no 'Through:' period")
        for (month, day), rules in periods:
            if not rules or any(not r[1] for r in rules):
                raise ScheduleError(f"schedule {name}: period through {month}/{day} has a "
                                    "day list without values")
        if periods[-1][0] != [12, 31]:
            raise ScheduleError(f"schedule {name}: the last period must end on 12/31")
        return cls(name, periods, notes)

    # --- JSON ------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {"name": self.name, "periods": self.periods, "notes": list(self.notes)}

    @classmethod
    def from_dict(cls, d: Mapping) -> CompactSchedule:
        return cls(str(d["name"]), [[list(p[0]), [[list(r[0]), [list(u) for u in r[1]]]
                                                   for r in p[1]]] for p in d["periods"]],
                   list(d.get("notes", [])))

    # --- values ----------------------------------------------------------------------
    def day_values(self, date: dt.date, holiday: bool = False) -> list[list]:
        """The ``[[minute, value], ...]`` of ``date`` (a holiday when ``holiday``)."""
        key = (date.month, date.day)
        for (month, day), rules in self.periods:
            if key <= (month, day):
                break
        kind = "holiday" if holiday else _DAYS[date.weekday()]
        weekend = kind in ("saturday", "sunday")
        for keys, until in rules:
            if (kind in keys or "alldays" in keys
                    or ("weekdays" in keys and not holiday and not weekend)
                    or ("weekends" in keys and weekend and not holiday)):
                return until
        for keys, until in rules:
            if "allotherdays" in keys:
                return until
        raise ScheduleError(f"schedule {self.name}: no values for a {kind} "
                            f"({date.isoformat()}); add a 'For: AllOtherDays' rule")

    def values(self, times: pd.DatetimeIndex | Sequence, timezone: str,
               holidays: Iterable[dt.date] = ()) -> np.ndarray:
        """Schedule value of each interval starting at ``times`` (UTC or tz-aware) in the
        site's local time ``timezone``: the value of the first ``Until`` after the
        interval's start, as EnergyPlus gives it for a time step ending at or before it."""
        days, minutes = local_day_minute(times, timezone)
        hol = set(holidays)
        out = np.empty(len(days))
        cache = self._days
        if len(cache) > 4096:       # a long replay: keep the memory bounded
            cache.clear()
        epoch = dt.date(1970, 1, 1)
        for k, (day, minute) in enumerate(zip(days.tolist(), minutes.tolist())):
            holiday = bool(hol) and (epoch + dt.timedelta(days=day)) in hol
            key = (day, holiday)
            hit = cache.get(key)
            if hit is None:
                until = self.day_values(epoch + dt.timedelta(days=day), holiday)
                hit = cache[key] = (np.array([u[0] for u in until]),
                                    np.array([u[1] for u in until], dtype=float))
            ends, vals = hit
            j = int(np.searchsorted(ends, minute, side="right"))
            out[k] = vals[min(j, len(vals) - 1)]
        return out
