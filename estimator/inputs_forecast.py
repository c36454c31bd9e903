"""Forecasts of a building's HVAC inputs (box airflows, supply-air temperature) learned
online from its own history.

The served 24-h forecast needs u (box airflows) and T_s (supply-air temperature) over the
horizon; nobody publishes a forecast of them. :class:`HvacInputForecaster` learns them per
*slot* = (day class, time of day): day class 0 is a working day, 1 a weekend day or
holiday (the site's thermostat ``working_days`` and ``holidays``; Monday to Friday without
a thermostat), time of day the local 15-min interval. In each slot and for each channel it
keeps an exponentially weighted linear regression on the outdoor temperature T_a of the
same interval, with the slope shrunk towards zero (ridge):

    y = m_y + b (T_a - m_x),   b = S_xy / (S_xx + w sigma0^2)

(w the slot's weight sum, m_x, m_y the weighted means, S_xx, S_xy the weighted co-moments;
sigma0 [K] the shrinkage: a slope needs a spread of outdoor temperature of about sigma0
within the slot before it counts). This captures a supply-air reset on outdoor temperature
and the reheat airflow of cold mornings, and falls back to the slot mean where the slot
has seen one outdoor temperature only. Each processed row updates one slot: recursive
(weighted Welford), O(1) work and O(slots x channels) state, with forgetting factor
``lam`` per update of a slot (an effective memory of 1 / (1 - lam) days of that slot).

A forecast from issue time t adds to the slot prediction the current deviation
(measured row t minus its slot prediction) decaying as exp(-lead / tau): the first hours
follow today's operation, later ones the learned pattern.

Rows inside the site's experiments (excitation) are not learned: the airflows there are
the experiment's, not the building's operation.

Pure numerics; the state serialises bit for bit (:meth:`state_arrays`,
:meth:`load_state_arrays`) into the streaming estimator's checkpoint.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterable, Mapping

import numpy as np
import pandas as pd

__all__ = ["INPUT_FORECAST_DEFAULTS", "AirflowFloor", "DayCalendar", "HvacInputForecaster"]

_DAY_NS = 86_400 * 10**9

#: the defaults of :class:`HvacInputForecaster`, chosen on the training weeks of the
#: office6 campaign (docs/forecasts.md "Served forecast")
INPUT_FORECAST_DEFAULTS = {"lam": 0.9, "sigma0": 1.0, "sigma0_solar": 30.0, "tau_h": 2.0}


class DayCalendar:
    """Local day class and time-of-day slot of UTC grid times.

    Parameters
    ----------
    timezone : str
        IANA time zone of the site.
    step : timedelta
        Grid step (divides a day) [s].
    working_days : iterable of int
        Working weekdays (0 = Monday).
    holidays : iterable of date
        Local dates that are not working days.
    """

    n_classes = 2

    def __init__(self, timezone: str, step, working_days: Iterable[int] = (0, 1, 2, 3, 4),
                 holidays: Iterable[dt.date] = ()):
        self.timezone = timezone
        self.step_ns = pd.Timedelta(step).value
        if self.step_ns <= 0 or _DAY_NS % self.step_ns:
            raise ValueError(f"step {step} must divide a day")
        self.per_day = _DAY_NS // self.step_ns
        self.working_days = sorted({int(d) for d in working_days})
        self.holidays = sorted({pd.Timestamp(d).date() for d in holidays})
        self._hol = np.array([np.datetime64(d, "D") for d in self.holidays], dtype="datetime64[D]")
        self._days: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    @property
    def n_slots(self) -> int:
        return self.n_classes * self.per_day

    @classmethod
    def for_site(cls, site) -> DayCalendar:
        """The calendar of a :class:`~zonecast.estimator.site.Site` (its thermostat's
        working days and holidays when it has a thermostat)."""
        th = site.thermostat
        if th is None:
            return cls(site.timezone, site.step)
        return cls(site.timezone, site.step, th.working_days, th.holidays)

    def _off(self, dow: np.ndarray, dates: np.ndarray) -> np.ndarray:
        """Whether local dates (their weekdays ``dow``, 0 = Monday) are not working days."""
        off = ~np.isin(dow, self.working_days)
        if len(self._hol):
            off |= np.isin(dates, self._hol)
        return off

    def _compute(self, times: pd.DatetimeIndex) -> tuple[np.ndarray, np.ndarray]:
        """Slots of ``times`` and whether each lies on a working day that follows a day
        off (the previous local date not a working day)."""
        local = times.tz_convert(self.timezone)
        sec = ((np.asarray(local.hour, dtype=np.int64) * 60 + np.asarray(local.minute, np.int64))
               * 60 + np.asarray(local.second, np.int64))
        tod = np.minimum(sec * 10**9 // self.step_ns, self.per_day - 1)
        dates = np.asarray(local.tz_localize(None).normalize(), dtype="datetime64[D]")
        dow = np.asarray(local.day_of_week)
        off = self._off(dow, dates)
        after_off = ~off & self._off((dow - 1) % 7, dates - np.timedelta64(1, "D"))
        return off.astype(np.int64) * self.per_day + tod, after_off

    def _lookup(self, times_ns) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_compute` of UTC times given as ns since the epoch; grid times are cached
        a UTC day at a time."""
        t = np.asarray(times_ns, dtype=np.int64).reshape(-1)
        if np.any(t % self.step_ns):
            return self._compute(pd.DatetimeIndex(t, tz="UTC"))
        days = t // _DAY_NS
        out = np.empty(len(t), dtype=np.int64)
        after = np.empty(len(t), dtype=bool)
        for day in np.unique(days):
            hit = self._days.get(int(day))
            if hit is None:
                if len(self._days) >= 8:
                    self._days.pop(next(iter(self._days)))
                grid = pd.DatetimeIndex(int(day) * _DAY_NS + self.step_ns * np.arange(self.per_day),
                                        tz="UTC")
                hit = self._days[int(day)] = self._compute(grid)
            sel = days == day
            i = (t[sel] - day * _DAY_NS) // self.step_ns
            out[sel], after[sel] = hit[0][i], hit[1][i]
        return out, after

    def slots(self, times_ns) -> np.ndarray:
        """Slot (day class x per_day + local interval of the day) of UTC times given as
        ns since the epoch."""
        return self._lookup(times_ns)[0]

    #: classes of :meth:`interval_classes`
    n_interval_classes = 3

    def interval_classes(self, times_ns) -> np.ndarray:
        """Day class of UTC times (ns since the epoch) for the interval calibration: 0 a
        working day, 1 a weekend day or holiday, 2 a working day after a day off (the
        first day the HVAC runs its occupied schedule after floating: docs/forecasts.md
        "The day after a day off")."""
        slot, after = self._lookup(times_ns)
        return np.where(after, 2, slot // self.per_day)


class HvacInputForecaster:
    """Online per-slot ridge regression of HVAC inputs on weather (module docstring).

    Parameters
    ----------
    calendar : DayCalendar
    n_channels : int
        Channels forecast (box airflows [kg/s] then the supply-air temperature [degC]).
    n_regressors : int
        Regressors x (the served forecast uses outdoor temperature [degC] and the
        irradiance of each of the building's four facades [W/m2]: five).
    shrink : array (n_regressors,)
        Ridge prior scale sigma0 of each regressor, in its unit ([K], [W/m2]): a slope
        counts once the regressor spreads by about this much within the slot.
    nonnegative : array of bool (n_channels,)
        Channels clipped at zero in forecasts (airflows).
    lam : float
        Forgetting factor per update of a slot [-] (0 < lam <= 1).
    tau_h : float
        Decay time of the current deviation over the horizon [h].
    """

    def __init__(self, calendar: DayCalendar, n_channels: int, *, n_regressors: int = 2,
                 shrink=None, nonnegative=None,
                 lam: float = INPUT_FORECAST_DEFAULTS["lam"],
                 tau_h: float = INPUT_FORECAST_DEFAULTS["tau_h"]):
        if not 0.0 < lam <= 1.0:
            raise ValueError(f"lam must lie in (0, 1], got {lam}")
        if tau_h < 0:
            raise ValueError("tau_h must be >= 0")
        self.calendar = calendar
        self.n_channels, self.p = int(n_channels), int(n_regressors)
        self.shrink = (np.full(self.p, INPUT_FORECAST_DEFAULTS["sigma0"]) if shrink is None
                       else np.asarray(shrink, float).reshape(self.p))
        if np.any(self.shrink <= 0):
            raise ValueError("shrink must be > 0")
        self.nonneg = (np.zeros(self.n_channels, bool) if nonnegative is None
                       else np.asarray(nonnegative, bool))
        self.lam, self.tau_h = float(lam), float(tau_h)
        ns = calendar.n_slots
        self.w = np.zeros(ns)                          # weight sum per slot
        self.mx = np.zeros((ns, self.p))               # regressor means
        self.sxx = np.zeros((ns, self.p, self.p))      # regressor co-moments
        self.my = np.zeros((ns, self.n_channels))      # channel means
        self.sxy = np.zeros((ns, self.p, self.n_channels))  # cross co-moments
        self.updates = 0

    # --- learning ------------------------------------------------------------------
    def update(self, t_ns: int, x: np.ndarray, y: np.ndarray) -> bool:
        """Learn the row at ``t_ns`` (UTC ns): regressors ``x`` (n_regressors,) and
        channels ``y`` (n_channels,). Rows with any value missing are skipped (returns
        False). O(n_regressors x n_channels)."""
        x = np.asarray(x, dtype=float).reshape(self.p)
        y = np.asarray(y, dtype=float)
        if not (np.isfinite(x).all() and np.isfinite(y).all()):
            return False
        s = int(self.calendar.slots([t_ns])[0])
        lam = self.lam
        w = lam * self.w[s] + 1.0
        dx = x - self.mx[s]
        mx = self.mx[s] + dx / w
        my = self.my[s] + (y - self.my[s]) / w
        self.sxx[s] = lam * self.sxx[s] + np.outer(dx, x - mx)
        self.sxy[s] = lam * self.sxy[s] + np.outer(dx, y - my)
        self.mx[s], self.my[s], self.w[s] = mx, my, w
        self.updates += 1
        return True

    # --- forecasting -------------------------------------------------------------------
    def slot_prediction(self, slots: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Regression prediction (len(slots), n_channels) at regressors ``x``
        (len(slots), n_regressors; NaN: that regressor at its slot mean), and a mask of
        the slots that have been learned."""
        slots = np.asarray(slots, dtype=np.int64)
        w = self.w[slots]
        seen = w > 0
        a = self.sxx[slots] + (np.maximum(w, 1e-12)[:, None, None]
                               * np.diag(self.shrink ** 2)[None, :, :])
        b = np.linalg.solve(a, self.sxy[slots])  # (n, p, n_channels)
        dx = np.asarray(x, float).reshape(len(slots), self.p) - self.mx[slots]
        dx = np.where(np.isfinite(dx), dx, 0.0)
        pred = self.my[slots] + np.einsum("np,npc->nc", dx, b)
        pred = np.where(self.nonneg[None, :], np.maximum(pred, 0.0), pred)
        return pred, seen

    def forecast(self, times_ns, x, current: np.ndarray, fallback: np.ndarray) -> np.ndarray:
        """Channels over the intervals starting at ``times_ns`` (the first is the issue
        row, measured: ``current``).

        Parameters
        ----------
        times_ns : array (H,) of int
            Interval starts, UTC ns; times_ns[0] is the issue row.
        x : array (H, n_regressors)
            Forecast regressors (the served forecast: outdoor temperature [degC], then the
            irradiance of each facade [W/m2]); NaN: the slot mean.
        current : array (n_channels,)
            Measured channels of the issue row.
        fallback : array (H, n_channels)
            Used in slots never learned (e.g. persistence of yesterday's values).

        Returns
        -------
        ndarray (H, n_channels)
        """
        t = np.asarray(times_ns, dtype=np.int64)
        pred, seen = self.slot_prediction(self.calendar.slots(t), x)
        out = np.where(seen[:, None], pred, fallback)
        cur = np.asarray(current, float)
        d = np.where(seen[0] & np.isfinite(cur), cur - out[0], 0.0)
        lead_h = (t - t[0]) / 3.6e12
        decay = np.exp(-lead_h / self.tau_h) if self.tau_h > 0 else (lead_h == 0).astype(float)
        out = out + decay[:, None] * d[None, :]
        out = np.where(self.nonneg[None, :], np.maximum(out, 0.0), out)
        out[0] = np.where(np.isfinite(cur), cur, out[0])
        return out

    # --- state ------------------------------------------------------------------------
    _KEYS = ("w", "mx", "sxx", "my", "sxy")

    def state_arrays(self, prefix: str = "ifc_") -> dict[str, np.ndarray]:
        """The learned state as named arrays (bitwise round trip with
        :meth:`load_state_arrays`)."""
        out = {f"{prefix}{k}": getattr(self, k) for k in self._KEYS}
        out[f"{prefix}updates"] = np.array([self.updates], dtype=np.int64)
        return out

    def load_state_arrays(self, arrays: Mapping[str, np.ndarray], prefix: str = "ifc_") -> bool:
        """Restore :meth:`state_arrays`; returns False (state untouched) when ``arrays``
        holds none, or ones of another shape (a checkpoint of another model)."""
        if not all(f"{prefix}{k}" in arrays for k in self._KEYS):
            return False
        new = {k: np.array(arrays[f"{prefix}{k}"], dtype=float) for k in self._KEYS}
        if any(new[k].shape != getattr(self, k).shape for k in self._KEYS):
            return False
        for k in self._KEYS:
            setattr(self, k, new[k])
        self.updates = int(np.asarray(arrays.get(f"{prefix}updates", [0]))[0])
        return True


class AirflowFloor:
    """Each VAV box's minimum airflow while its air handler runs, learned from its own
    readings: the lowest of the daily minima over the last ``days`` days of the rows
    :meth:`update` is given (the served forecast gives the working days' occupied rows).

    A box's minimum is a setting of its controller (its minimum-flow fraction), which no
    site description states; a box in the thermostat's dead band sits at it. A day's
    minimum is above it when the room needed cooling all day (a hot day, a core room), so
    the floor is the lowest daily minimum of the window, not their mean; a day without
    a row of a box leaves that box's minimum unknown (NaN) for the day. Rows where a box
    reads no airflow (its air handler off) or NaN teach nothing.

    Parameters
    ----------
    n_boxes : int
    days : int
        Days kept [d].
    """

    def __init__(self, n_boxes: int, days: int = 14):
        if days < 1:
            raise ValueError(f"days {days}: keep at least one day")
        self.n_boxes, self.days = int(n_boxes), int(days)
        self.ring = np.full((self.days, self.n_boxes), np.nan)  # daily minima, oldest first
        self.today = np.full(self.n_boxes, np.nan)               # running minimum of the day
        self.day = np.array([-1], dtype=np.int64)               # the local day of ``today``

    def update(self, day: int, u: np.ndarray) -> None:
        """Learn one row of local day ``day`` (any increasing day number) with airflows
        ``u`` (n_boxes,) [kg/s]; a new day closes the running one into the window."""
        day = int(day)
        if day != self.day[0]:
            if self.day[0] >= 0:  # days without rows between stay unknown
                gap = day - int(self.day[0]) if day > self.day[0] else 1
                self.ring = np.roll(self.ring, -gap, axis=0)
                self.ring[max(self.days - gap, 0):] = np.nan
                if gap <= self.days:  # the closed day is still inside the window
                    self.ring[self.days - gap] = self.today
            self.today = np.full(self.n_boxes, np.nan)
            self.day[0] = day
        u = np.asarray(u, dtype=float)
        ok = np.isfinite(u) & (u > 0)
        self.today = np.where(ok, np.fmin(self.today, u), self.today)

    def floor(self) -> np.ndarray:
        """(n_boxes,) [kg/s]: the lowest closed daily minimum of the window; NaN for a
        box without a closed day in it (the running day counts once it is closed)."""
        seen = np.isfinite(self.ring).any(axis=0)
        out = np.full(self.n_boxes, np.nan)
        out[seen] = np.nanmin(self.ring[:, seen], axis=0)
        return out

    # --- state ------------------------------------------------------------------------
    def state_arrays(self, prefix: str = "afl_") -> dict[str, np.ndarray]:
        """The learned state as named arrays (bitwise round trip with
        :meth:`load_state_arrays`)."""
        return {f"{prefix}ring": self.ring, f"{prefix}today": self.today,
                f"{prefix}day": self.day}

    def load_state_arrays(self, arrays: Mapping[str, np.ndarray], prefix: str = "afl_") -> bool:
        """Restore :meth:`state_arrays`; returns False (state untouched) when ``arrays``
        holds none, or ones of another shape (a checkpoint of another model)."""
        keys = [f"{prefix}{k}" for k in ("ring", "today", "day")]
        if not all(k in arrays for k in keys):
            return False
        ring, today = (np.array(arrays[k], dtype=float) for k in keys[:2])
        if ring.shape != self.ring.shape or today.shape != self.today.shape:
            return False
        self.ring, self.today = ring, today
        self.day = np.array(arrays[keys[2]], dtype=np.int64).reshape(1)
        return True
