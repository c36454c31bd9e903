"""Internal-gains profile and 24-hour zone-temperature forecasts, paper sections 4-B and 5.

Pure numerics (docs/forecasts.md has the method, the readings chosen and the numbers):

- :func:`week_split` — 8 training / 3 validation weeks, seeded;
- :func:`fixed_profile` — paper Eq:fixed_ig from per-week tracks (:func:`track_week`);
- :func:`issue_forecast` — one 24-h forecast issued at a row: Kalman state over the
  previous day (f_IG = 0 in the filter, air states following the measurements), internal
  gains from the fixed profile, the day-ahead blend (:class:`~.gains.DayAheadGains`) or
  persistence (paper eq:online_ig held over the horizon), the measured u and v over the
  horizon, and the filter covariance propagated through the model;
- :func:`online_paper_predictions` — paper section 5 as implemented here: one-step-ahead
  predictions with f_IG(k) = f_IG(k-1) and the state carried by the gains tracker;
- the paper's evaluation protocol on a campaign (Tables 2-3, figure data) is
  :func:`zonecast.estimator.study.forecast_study`.

Only rows up to the issue row of y are read by a forecast; u and v over the horizon are
the measured ones (as the paper's forecasts; no weather or HVAC forecast is modelled).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from zonecast.estimator.constants import (
    DAYAHEAD_TAU,
    DAYAHEAD_WINDOW,
    HORIZON,
    SIGMA_AIR_FORECAST,
    SIGMA_AIR_X0,
    SIGMA_MEAS,
    SIGMA_WALL_FORECAST,
    Z90,
)
from zonecast.estimator.dataset import ModelData
from zonecast.estimator.gains import (
    DayAheadGains,
    RankDeficientError,
    WeeklyProfile,
    estimate_gains_step,
    fit_weekly_profile,
)
from zonecast.estimator.identify import kalman_state
from zonecast.estimator.internal_gains import (
    GainsTrack,
    track_gains,
)
from zonecast.estimator.kalman import (
    ZoneStateFilter,
    air_wall_covariance,
    default_initial_covariance,
    initial_state_from_measurement,
)
from zonecast.estimator.model import BilinearModel

__all__ = [
    "FORECAST_METHODS",
    "FilterDay",
    "Forecast",
    "WeekTrack",
    "coverage",
    "coverage_halfwidth",
    "empirical_halfwidth",
    "fill_profile",
    "filter_day",
    "fixed_profile",
    "issue_forecast",
    "issue_rows",
    "online_paper_predictions",
    "propagate_std",
    "track_week",
    "week_split",
    "whole_weeks",
    "zone_floor_area",
]

#: forecast methods of :func:`issue_forecast`
FORECAST_METHODS = ("fixed", "dayahead", "persistence")


# --------------------------------------------------------------------------- split


def _rows_per_day(data: ModelData) -> int:
    step = data.times[1] - data.times[0]
    return int(pd.Timedelta("1D") / step)


def whole_weeks(data: ModelData) -> list[dict]:
    """Consecutive 7-day blocks of rows from the start of each contiguous segment:
    {index, segment, start (local date), rows [start, stop)} each."""
    per_week = 7 * _rows_per_day(data)
    local = data.local_times()
    weeks = []
    for seg, (a, b) in enumerate(data.segments):
        for s in range(a, b - per_week + 1, per_week):
            weeks.append({"index": len(weeks), "segment": seg, "start": str(local[s].date()),
                          "rows": [s, s + per_week]})
    return weeks


def week_split(data: ModelData, seed: int = 0, n_train: int = 8) -> dict:
    """Seeded split of the data's weeks into training and validation weeks.

    Weeks are consecutive 7-day blocks of rows from the start of each contiguous segment
    (the campaign has one segment per week). ``n_train`` of them are drawn at random with
    ``numpy.random.default_rng([seed, 21])``; the rest are validation weeks.

    Returns
    -------
    dict
        ``weeks``: list of {index, segment (index in ``data.segments``), start (local
        date), rows [start, stop)};
        ``train``, ``validation``: sorted week indices; ``train_starts``,
        ``validation_starts``: their local start dates; ``seed``.
    """
    weeks = whole_weeks(data)
    if len(weeks) <= n_train:
        raise ValueError(f"{len(weeks)} whole weeks in the data; need more than {n_train}")
    rng = np.random.default_rng([seed, 21])
    train = sorted(int(i) for i in rng.choice(len(weeks), n_train, replace=False))
    val = [w["index"] for w in weeks if w["index"] not in train]
    return {"weeks": weeks, "train": train, "validation": val,
            "train_starts": [weeks[i]["start"] for i in train],
            "validation_starts": [weeks[i]["start"] for i in val], "seed": int(seed)}


# --------------------------------------------------------------------------- profile


@dataclass
class WeekTrack:
    """Per-step gains of one week (paper Eq:ig(k-1)), tracked from x_KF after its first day.

    Attributes
    ----------
    start : int
        First tracked row (the week's first row + one day).
    track : GainsTrack
        ``track.f_ig[i]`` is f_IG at row ``start + i``.
    """

    start: int
    track: GainsTrack

    @property
    def rows(self) -> np.ndarray:
        return np.arange(self.start, self.start + len(self.track.f_ig))


def track_week(model: BilinearModel, data: ModelData, rows) -> WeekTrack:
    """Gains of a week: x(0) = :func:`~.identify.kalman_state` over the week's first day,
    then :func:`~.internal_gains.track_gains` to the week's last row."""
    a, b = rows
    day = _rows_per_day(data)
    x0 = kalman_state(model, data, a, a + day)
    return WeekTrack(a + day, track_gains(model, data, a + day, b - 1, x0))


#: how :meth:`Pipeline.weekly_profile <zonecast.estimator.pipeline.Pipeline.weekly_profile>`
#: fills an empty day of the profile (Monday, each tracked week's warm-up day):
#: ``"operating"`` from the days of its operating day's class (the site's working days or
#: the others; an operating day runs from the thermostat's occupied start to the next
#: one's, so a Monday's small hours follow a weekend day), ``"day"`` by the calendar
#: day's class, ``"all"`` from every day with data (before 2026-12-05).
#: ``--side monday-fill`` of benchmarks/bench_reheat_control.py compares them.
PROFILE_FILL = "operating"


def fill_profile(profile: WeeklyProfile, working_days: Sequence[int] | None = None,
                 day_start: float = 0.0) -> WeeklyProfile:
    """Bins without data take the mean of the same time of day over the days that have it.

    Weeks tracked from their second day leave the first day's bins (Monday's) empty; a
    forecast and the day-ahead offset need a value there. With ``working_days`` (local
    weekdays, 0 = Monday; the site's thermostat calendar) an empty bin takes the mean of
    the same time of day over the days of its own class, working or not, when any of them
    has data: a Monday filled from Tuesday to Sunday would carry two weekend days' gains
    into a working day (a third of its occupied gains missing). Without ``working_days``,
    or when no day of the class has data, every day with data counts.

    ``day_start`` [h, local] is where an operating day begins (the thermostat's occupied
    start): a bin before it belongs to the previous day's class. The small hours' f_IG
    after an occupied day carry the heat its rooms stored (positive), after a weekend day
    not: Monday 00:00-07:00 is filled from Sunday's small hours, not Tuesday's to
    Friday's (docs/forecasts.md "Monday's gains").
    """
    per_day = int(pd.Timedelta("1D") / profile.step)
    v = profile.values.reshape(7, per_day, -1)
    fill = np.broadcast_to(_nanmean0(v)[None], v.shape).copy()
    if working_days is not None:
        work = np.isin(np.arange(7), list(working_days))
        start = int(np.clip(round(day_start * per_day / 24), 0, per_day))
        # class of each (day, bin): the calendar day's, or the day before's before start
        cls = np.repeat(work[:, None], per_day, axis=1)
        cls[:, :start] = np.roll(work, 1)[:, None]
        for c in (True, False):
            sel = cls == c  # (7, per_day)
            vals = np.where(sel[:, :, None], v, np.nan)
            tod = _nanmean0(vals)  # (per_day, p)
            own = np.where(np.isnan(tod)[None], fill, tod[None])
            fill = np.where(sel[:, :, None], own, fill)
    filled = np.where(np.isnan(v), fill, v).reshape(profile.values.shape)
    return WeeklyProfile(np.nan_to_num(filled), profile.counts, profile.timezone, profile.step)


def fixed_profile(data: ModelData, tracks: list[WeekTrack],
                  working_days: Sequence[int] | None = None,
                  day_start: float = 0.0) -> WeeklyProfile:
    """Paper Eq:fixed_ig: the mean of the weeks' f_IG on the local time-of-week axis
    (empty bins filled by :func:`fill_profile`, by day class with ``working_days``)."""
    rows = np.concatenate([t.rows for t in tracks])
    f = np.concatenate([t.track.f_ig for t in tracks])
    step = data.times[1] - data.times[0]
    return fill_profile(fit_weekly_profile(data.times[rows], f, data.timezone, step=step),
                        working_days, day_start)


# --------------------------------------------------------------------------- filter


@dataclass
class FilterDay:
    """The filter over rows [start, issue]: state and covariance at ``issue`` and the
    per-step f_IG estimates (paper Eq:ig(k-1) from the filtered x(k-1)) of rows
    [start, issue)."""

    x: np.ndarray
    P: np.ndarray
    f_ig: np.ndarray


def filter_day(model: BilinearModel, data: ModelData, start: int, issue: int, *,
               prior: np.ndarray | None = None, sigma_air: float = SIGMA_AIR_X0,
               sigma_wall: float = SIGMA_WALL_FORECAST,
               sigma_meas: float = SIGMA_MEAS) -> FilterDay:
    """Kalman filter over rows [start, issue]; reads y only there.

    The filter's model uses the internal gains ``prior`` (rows [start, issue), W/m2;
    default 0, as :func:`~.identify.kalman_state`). The air states' process noise
    ``sigma_air`` (3 K) lets the filtered air follow the measurements; the innovations are
    then the residuals of paper Eq:xnoig_ynoig with the prior's gains, and Eq:ig(k-1) on
    them gives f_IG(k-1) - prior(k-1), returned added to the prior.
    """
    air = model.structure.air_states()
    y = data.y[start:issue + 1]
    y0 = y[0] if np.isfinite(y[0]).any() else np.nanmean(y, axis=0)
    x0 = initial_state_from_measurement(np.where(np.isfinite(y0), y0, np.nanmean(y0)),
                                        model.state_zones())
    Q = air_wall_covariance(model.n, air, sigma_air, sigma_wall)
    kf = ZoneStateFilter(x0, default_initial_covariance(model.n, air), model.C, Q,
                         np.full(model.n_zones, sigma_meas**2))
    kf.update(y[0])
    f = np.full((issue - start, model.n_zones), np.nan)
    c_ig = model.params.c_ig
    prior = np.zeros_like(f) if prior is None else np.asarray(prior, float)
    for i in range(issue - start):
        k = start + i
        phi, gv, gi = model.step_matrices(data.u[k], model.modes(data.u[k], data.reheat[k]))
        kf.predict(phi, gv @ data.v[k] + gi @ (c_ig + prior[i])
                   + model.reheat_step(data.u[k], data.reheat[k]))
        inn = kf.update(y[i + 1])
        if inn.dof:
            resid = np.full(model.n_zones, np.nan)
            resid[inn.observed] = inn.innovation
            try:
                f[i] = prior[i] + estimate_gains_step(model.C @ gi, resid,
                                                      np.zeros(model.n_zones)).f_ig
            except RankDeficientError:
                pass
    return FilterDay(kf.x, kf.P, f)


# --------------------------------------------------------------------------- forecast


@dataclass(frozen=True)
class Forecast:
    """A zone-temperature forecast: the one type issued offline (:func:`issue_forecast`),
    by the streaming estimator (:class:`~zonecast.estimator.streaming.OnlineEstimator`) and
    served by the service.

    Attributes
    ----------
    issued : pandas.Timestamp
        Issue time (UTC): the time of the last measurement used.
    times : pandas.DatetimeIndex
        Forecast times t + 15 min ... t + H steps (UTC).
    mean : ndarray, shape (H, n_zones)
        Predicted zone temperatures [degC].
    std : ndarray, shape (H, n_zones)
        Standard deviation of the prediction [K].
    f_ig : ndarray, shape (H, n_zones)
        Internal gains used per interval [W/m2].
    zones : list of str
    model_version : str
        Model file version (empty for a model that was not read from a file).
    issue_row : int or None
        Row of the data at the issue time, for forecasts issued on a data set (y is read
        up to this row only).
    halfwidth : ndarray (H, n_zones) or None
        Half-width of the 90 % interval [K] when it is calibrated on recent errors
        (:mod:`zonecast.estimator.calibration`); None: ``Z90 * std``.
    """

    issued: pd.Timestamp
    times: pd.DatetimeIndex
    mean: np.ndarray
    std: np.ndarray
    f_ig: np.ndarray
    zones: list[str]
    model_version: str = ""
    issue_row: int | None = None
    halfwidth: np.ndarray | None = None

    def interval(self, z: float = Z90) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) ends of the interval mean -+ z std [degC]; default 90 %."""
        half = z * self.std
        return self.mean - half, self.mean + half

    @property
    def lower(self) -> np.ndarray:
        """Lower end of the 90 % interval [degC] (calibrated when ``halfwidth`` is set)."""
        return self.mean - (Z90 * self.std if self.halfwidth is None else self.halfwidth)

    @property
    def upper(self) -> np.ndarray:
        """Upper end of the 90 % interval [degC] (calibrated when ``halfwidth`` is set)."""
        return self.mean + (Z90 * self.std if self.halfwidth is None else self.halfwidth)


def _gains(method: str, data: ModelData, issue: int, horizon: int, profile: WeeklyProfile,
           fd: FilterDay, dayahead: DayAheadGains) -> np.ndarray:
    times = pd.date_range(data.times[issue], periods=horizon, freq=profile.step)
    if method == "fixed":
        return np.nan_to_num(profile(times))
    hist = pd.DataFrame(fd.f_ig, index=data.times[issue - len(fd.f_ig):issue], columns=data.zones)
    if method == "dayahead":
        return dayahead.issue(data.times[issue], hist).to_numpy()[:horizon]
    if method == "persistence":  # paper eq:online_ig held over the horizon
        last = hist.ffill().iloc[-1].to_numpy() if len(hist) else np.zeros(len(data.zones))
        return np.tile(np.nan_to_num(last), (horizon, 1))
    raise ValueError(f"method must be one of {FORECAST_METHODS}, got {method!r}")


def propagate_std(model: BilinearModel, P: np.ndarray, u: np.ndarray, *,
                  sigma_air: float = SIGMA_AIR_FORECAST, sigma_wall: float = SIGMA_WALL_FORECAST,
                  sigma_meas: float = SIGMA_MEAS, reheat: np.ndarray | None = None) -> np.ndarray:
    """Std of C x(h) + e over the horizon: P <- Phi(u_h) P Phi(u_h)' + Q, var = C P C' + R
    (``reheat`` [K]: the discharge air's rise, for the films' regimes, :meth:`.modes`)."""
    modes = model.modes(u, reheat)
    air = model.structure.air_states()
    q = np.diag(air_wall_covariance(model.n, air, sigma_air, sigma_wall))
    out = np.empty((len(u), model.n_zones))
    for h in range(len(u)):
        phi = model.step_matrices(u[h], None if modes is None else modes[h])[0]
        P = phi @ P @ phi.T
        P[np.diag_indices_from(P)] += q
        out[h] = np.einsum("ij,jk,ik->i", model.C, P, model.C) + sigma_meas**2
    return np.sqrt(np.maximum(out, 0.0))


def issue_forecast(model: BilinearModel, data: ModelData, issue: int, profile: WeeklyProfile,
                   methods=("fixed",), *, horizon: int = HORIZON,
                   dayahead: DayAheadGains | None = None, intervals: bool = True,
                   filter_prior: str = "profile", sigma_air_filter: float = SIGMA_AIR_X0,
                   sigma_air_forecast: float = SIGMA_AIR_FORECAST,
                   sigma_wall: float = SIGMA_WALL_FORECAST,
                   sigma_meas: float = SIGMA_MEAS) -> dict[str, Forecast]:
    """Forecasts issued at row ``issue`` (one per method, sharing the filter and covariance).

    The state x(issue|issue) and its covariance come from :func:`filter_day` over the
    previous day (rows [issue - 1 day, issue]) with the profile's gains in the filter's
    model (``filter_prior="profile"``; ``"zero"``: f_IG = 0 as
    :func:`~.identify.kalman_state`); y after ``issue`` is never read. The model then runs
    ``horizon`` steps (cut at the end of the data segment) with the measured u and v of rows
    [issue, issue + horizon) and the method's internal gains:

    - ``fixed``: the weekly profile (paper Eq:fixed_ig);
    - ``dayahead``: profile + decaying offset learned from the previous day's per-step
      estimates (:class:`~.gains.DayAheadGains`, default :data:`DAYAHEAD_TAU`,
      :data:`DAYAHEAD_WINDOW`);
    - ``persistence``: the newest per-step estimate held (paper eq:online_ig over 24 h).

    Intervals: P(issue|issue) propagated exactly, P <- Phi P Phi' + Q with the forecast
    noise (``sigma_air_forecast``, ``sigma_wall``), std = sqrt(C P C' + sigma_meas^2).
    """
    day = _rows_per_day(data)
    start = max(issue - day, 0)
    seg_stop = next((b for a, b in data.segments if a <= issue < b), len(data))
    horizon = min(horizon, seg_stop - issue)  # inputs exist up to the segment's end
    if filter_prior not in ("profile", "zero"):
        raise ValueError(f"filter_prior must be 'profile' or 'zero', got {filter_prior!r}")
    prior = (np.nan_to_num(profile(data.times[start:issue])) if filter_prior == "profile"
             else None)
    fd = filter_day(model, data, start, issue, prior=prior, sigma_air=sigma_air_filter,
                    sigma_wall=sigma_wall, sigma_meas=sigma_meas)
    u, v = data.u[issue:issue + horizon], data.v[issue:issue + horizon]
    std = (propagate_std(model, fd.P, u, sigma_air=sigma_air_forecast, sigma_wall=sigma_wall,
                         sigma_meas=sigma_meas, reheat=data.reheat[issue:issue + horizon])
           if intervals
           else np.full((horizon, model.n_zones), np.nan))
    step = data.times[1] - data.times[0]
    times = pd.date_range(data.times[issue] + step, periods=horizon, freq=step)
    issuer = dayahead or DayAheadGains(profile, tau=DAYAHEAD_TAU, window=DAYAHEAD_WINDOW,
                                       horizon=HORIZON)
    out = {}
    for m in methods:
        f = _gains(m, data, issue, horizon, profile, fd, issuer)
        y = model.simulate(fd.x, u, v, f, reheat=data.reheat[issue:issue + horizon]).y[1:]
        out[m] = Forecast(data.times[issue], times, y, std, f, list(data.zones),
                          issue_row=issue)
    return out


def empirical_halfwidth(model: BilinearModel, data: ModelData, tracks: list[WeekTrack], *,
                        horizon: int = HORIZON, level: float = 0.9,
                        pool: int = 2) -> np.ndarray:
    """Half-widths [K] of ``level`` forecast intervals per lead and zone, from forecast
    errors on the given (training) weeks, shape (horizon, n_zones).

    Each week is forecast at its local midnights (:func:`issue_rows`) with the fixed
    profile of the *other* weeks (leave one week out, so the errors are out of sample);
    the state at an issue is the gains tracker's (its zone temperatures equal the measured
    ones; no filter is run, which keeps this cheap: one 96-step simulation per issue).
    The half-width at lead h is the ``level`` quantile of |error| over the issues and the
    leads h - pool ... h + pool. Gains errors are correlated over hours, which the
    covariance-propagated intervals do not represent (docs/forecasts.md).
    """
    if len(tracks) < 2:
        raise ValueError("empirical intervals need at least two tracked weeks")
    errors = []
    for i, wt in enumerate(tracks):
        profile = fixed_profile(data, tracks[:i] + tracks[i + 1:])
        rows = wt.rows
        seg_stop = rows[-1] + 1
        week_start = int(rows[0]) - _rows_per_day(data)   # tracks start a day into the week
        for r in issue_rows(data, (week_start, seg_stop)):
            h = min(horizon, seg_stop - r - 1)
            if h <= 0:
                continue
            x0 = wt.track.x[r - wt.start]
            f = np.nan_to_num(profile(data.times[r:r + h]))
            y = model.simulate(x0, data.u[r:r + h], data.v[r:r + h], f,
                               reheat=data.reheat[r:r + h]).y[1:]
            e = np.full((horizon, model.n_zones), np.nan)
            e[:h] = np.abs(y - data.y[r + 1:r + 1 + h])
            errors.append(e)
    if not errors:
        raise ValueError("no forecast issue time in the given weeks")
    err = np.array(errors)
    out = np.empty((horizon, model.n_zones))
    for h in range(horizon):
        block = err[:, max(h - pool, 0):h + pool + 1].reshape(-1, model.n_zones)
        out[h] = np.nanquantile(block, level, axis=0)
    return out


def coverage_halfwidth(pred: np.ndarray, half: np.ndarray, meas: np.ndarray, zones) -> dict:
    """Fraction of measured values within ``half`` (per lead and zone) of the forecast."""
    return coverage(pred, np.broadcast_to(half / Z90, pred.shape), meas, zones)


def issue_rows(data: ModelData, rows) -> list[int]:
    """Local-midnight rows of a week from its second day on (the forecast issue times)."""
    a, b = rows
    local = data.local_times()
    day = _rows_per_day(data)
    return [r for r in range(a + day, b) if local[r].hour == 0 and local[r].minute == 0]


def coverage(pred: np.ndarray, std: np.ndarray, meas: np.ndarray, zones) -> dict:
    """Fraction of measured values inside the 90 % interval, per zone and overall."""
    inside = np.abs(meas - pred) <= Z90 * std
    ok = np.isfinite(meas) & np.isfinite(pred) & np.isfinite(std)
    out = {z: float(inside[..., j][ok[..., j]].mean()) for j, z in enumerate(zones)}
    out["all"] = float(inside[ok].mean())
    return out


# --------------------------------------------------------------------------- online (paper)


def online_paper_predictions(model: BilinearModel, wt: WeekTrack) -> tuple[np.ndarray, np.ndarray]:
    """Paper section 5: y(k+1) predicted with f_IG(k) = f_IG(k-1) from the tracker's x(k).

    The tracker's x(k+1) = x~(k+1) + Gamma_IG f_IG(k), so the prediction with the online
    value f_IG(k-1) is C x(k+1) - C Gamma_IG (f_IG(k) - f_IG(k-1)).

    Returns
    -------
    rows : (N,) int, the rows k + 1 predicted (from the second tracked step on)
    pred : (N, n_zones) the one-step-ahead predictions [degC]
    """
    tr = wt.track
    df = tr.f_ig[1:] - tr.f_ig[:-1]
    pred = tr.x[2:] @ model.C.T - np.einsum("kij,kj->ki", tr.cb[1:], df)
    return wt.rows[1:] + 1, pred


# --------------------------------------------------------------------------- study


def zone_floor_area(model: BilinearModel) -> np.ndarray:
    """Floor area per zone [m2], recovered from B_IG (paper eq:q_ig: a_floor / capacity)."""
    return model.structure.capacity @ model.B_ig


def _nanmean0(a: np.ndarray) -> np.ndarray:
    """Mean over axis 0 skipping NaN; NaN (no warning) where a column has no value."""
    n = np.isfinite(a).sum(axis=0)
    return np.where(n > 0, np.nansum(a, axis=0) / np.maximum(n, 1), np.nan)
