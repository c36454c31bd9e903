"""Time-varying internal gains f_IG: per-step least squares, weekly profile, online and day-ahead.

Paper sections "Identification of the Time-Varying Internal Gains" and "Online
Update of the Internal Gains Function". With the parameters identified, the
one-step prediction with ``f_IG(k-1) = 0`` (paper Eq:xnoig_ynoig) is

    x~(k) = F_{k-1} x(k-1) + c_{k-1}|_{f_IG = 0},     y~(k) = C x~(k),

and since ``x(k) = x~(k) + B_IG f_IG(k-1)`` the gains of the previous interval
solve the linear system (paper Eq:ig(k-1))

    (C B_IG) f_IG(k-1) = y_bar(k) - y~(k)

by ordinary least squares. ``f_IG`` is per unit floor area [W/m²] because
paper eq:q_ig multiplies it by the floor area inside ``B_IG``; ``B_IG`` here is
the *discrete-time* matrix of paper eq:model_dt.

Time stamps follow the telemetry convention: a row stamped t describes the
interval [t, t + step). ``f_IG(k)`` is stamped at t_k and needs the
measurement y_bar(k+1), so it becomes known at t_k + step.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

import numpy as np
import pandas as pd
from zonecast.estimator.constants import HORIZON, STEP

__all__ = [
    "REHEAT_LEAK_BOUNDS",
    "DayAheadGains",
    "GainsInputError",
    "GainsSeries",
    "GainsStep",
    "OnlineGains",
    "RankDeficientError",
    "ReheatLeak",
    "WeeklyProfile",
    "estimate_gains_series",
    "estimate_gains_step",
    "fit_reheat_leak",
    "fit_weekly_profile",
    "online_gains_series",
    "time_of_week_bin",
]

WEEK = pd.Timedelta("7D")


class GainsInputError(ValueError):
    """Inconsistent input to the internal-gains estimators."""


class GainsTimeError(TypeError):
    """Times are not tz-aware."""


class RankDeficientError(GainsInputError):
    """C B_IG restricted to the observed rows cannot determine every zone's gain."""


# --------------------------------------------------------------------------- per-step OLS


@dataclass(frozen=True)
class GainsStep:
    """One solution of paper Eq:ig(k-1).

    Attributes
    ----------
    f_ig : numpy.ndarray, shape (p,)
        Estimated internal gains f_IG(k-1) [W/m²].
    rank : int
        Numerical rank of C B_IG on the observed rows.
    rows_used : numpy.ndarray, shape (m,), bool
        Outputs that were observed (non-NaN) and used.
    min_norm : bool
        True if the system was rank deficient and the minimum-norm solution was
        returned (then only the component of f_IG in the row space is identified).
    """

    f_ig: np.ndarray
    rank: int
    rows_used: np.ndarray
    min_norm: bool


def _check_cb(CB_IG) -> np.ndarray:
    M = np.asarray(CB_IG, dtype=float)
    if M.ndim != 2 or not np.all(np.isfinite(M)):
        raise GainsInputError("CB_IG must be a finite 2-D array (outputs x zones), i.e. C @ B_IG")
    return M


def _solve(M: np.ndarray, r: np.ndarray, rank_deficient: str, rcond: float | None) -> GainsStep:
    p = M.shape[1]
    used = ~np.isnan(r)
    Mu, ru = M[used], r[used]
    if Mu.shape[0] == 0:
        rank = 0
        f = np.zeros(p)
    else:
        f, _, rank, _ = np.linalg.lstsq(Mu, ru, rcond=rcond)
    deficient = rank < p
    if deficient:
        if rank_deficient == "raise":
            raise RankDeficientError(
                f"C B_IG on the {int(used.sum())} observed outputs has rank {rank} < {p} zones, "
                "so f_IG is not identifiable; pass rank_deficient='min_norm' to accept the "
                "minimum-norm solution or 'nan' (series only) to skip such steps"
            )
        if rank_deficient == "nan":
            f = np.full(p, np.nan)
    return GainsStep(f_ig=f, rank=int(rank), rows_used=used, min_norm=bool(deficient and
                                                                         rank_deficient == "min_norm"))


def estimate_gains_step(
    CB_IG,
    y_meas,
    y_pred,
    *,
    rank_deficient: Literal["raise", "min_norm"] = "raise",
    rcond: float | None = None,
) -> GainsStep:
    """Solve paper Eq:ig(k-1) for one step by ordinary least squares.

    Parameters
    ----------
    CB_IG : array_like, shape (m, p)
        Product of the output matrix C and the discrete internal-gains input
        matrix B_IG [K/(W/m²)].
    y_meas : array_like, shape (m,)
        Measured zone temperatures y_bar(k) [°C]; NaN rows are dropped.
    y_pred : array_like, shape (m,)
        One-step prediction y~(k) with f_IG(k-1) = 0 (paper Eq:xnoig_ynoig) [°C].
    rank_deficient : {"raise", "min_norm"}, default "raise"
        What to do when the observed rows do not determine all p gains.
    rcond : float, optional
        Cut-off ratio for small singular values (numpy.linalg.lstsq).

    Returns
    -------
    GainsStep
    """
    M = _check_cb(CB_IG)
    m = M.shape[0]
    y_meas = np.asarray(y_meas, dtype=float)
    y_pred = np.asarray(y_pred, dtype=float)
    if y_meas.shape != (m,) or y_pred.shape != (m,):
        raise GainsInputError(
            f"y_meas and y_pred must have shape ({m},) to match CB_IG, got "
            f"{y_meas.shape} and {y_pred.shape}"
        )
    if rank_deficient not in ("raise", "min_norm"):
        raise GainsInputError(f"rank_deficient must be 'raise' or 'min_norm', got {rank_deficient!r}")
    return _solve(M, y_meas - y_pred, rank_deficient, rcond)


@dataclass(frozen=True)
class GainsSeries:
    """Per-step estimates over a series (see :func:`estimate_gains_series`).

    Attributes
    ----------
    f_ig : numpy.ndarray, shape (N, p)
        ``f_ig[k]`` = f_IG(k) [W/m²], estimated from ``residuals[k + 1]``; the
        last row and rows without a usable estimate are NaN.
    rank : numpy.ndarray, shape (N,), int
        Rank used for each row (0 where nothing was observed).
    min_norm : numpy.ndarray, shape (N,), bool
        Rows returned as minimum-norm solutions.
    """

    f_ig: np.ndarray
    rank: np.ndarray
    min_norm: np.ndarray


def estimate_gains_series(
    CB_IG,
    residuals,
    *,
    rank_deficient: Literal["raise", "min_norm", "nan"] = "nan",
    rcond: float | None = None,
) -> GainsSeries:
    """Solve paper Eq:ig(k-1) at every step of a series.

    Parameters
    ----------
    CB_IG : array_like, shape (m, p) or (N, m, p)
        C B_IG, constant or per step (row k used for f_IG(k)) [K/(W/m²)].
    residuals : array_like, shape (N, m)
        ``residuals[k] = y_bar(k) - y~(k)`` [K], the measurement minus the
        one-step prediction with zero time-varying gains. The innovations of
        :func:`zonecast.estimator.kalman.run_filter` run with f_IG = 0 in c_k are
        exactly this. ``residuals[0]`` is not used.
    rank_deficient : {"nan", "min_norm", "raise"}, default "nan"
        Rows where the observed outputs do not determine all p gains become NaN,
        a minimum-norm solution (flagged), or an error. A row with no observed
        output is always NaN.
    rcond : float, optional
        Cut-off ratio for small singular values.

    Returns
    -------
    GainsSeries
        Aligned with the interval-start convention: ``f_ig[k]`` belongs to [t_k, t_{k+1}).
    """
    R = np.asarray(residuals, dtype=float)
    if R.ndim != 2:
        raise GainsInputError(f"residuals must have shape (N, m), got {R.shape}")
    N, m = R.shape
    M = np.asarray(CB_IG, dtype=float)
    per_step = M.ndim == 3
    if per_step:
        if M.shape[:2] != (N, m) or not np.all(np.isfinite(M)):
            raise GainsInputError(f"CB_IG per step must have shape ({N}, {m}, p) and be finite")
    else:
        M = _check_cb(M)
        if M.shape[0] != m:
            raise GainsInputError(f"CB_IG must have {m} rows to match residuals, got {M.shape[0]}")
    if rank_deficient not in ("raise", "min_norm", "nan"):
        raise GainsInputError(
            f"rank_deficient must be 'nan', 'min_norm' or 'raise', got {rank_deficient!r}"
        )
    p = M.shape[-1]
    f = np.full((N, p), np.nan)
    rank = np.zeros(N, dtype=int)
    flag = np.zeros(N, dtype=bool)
    for k in range(N - 1):
        r = R[k + 1]
        if np.isnan(r).all():
            continue
        sol = _solve(M[k] if per_step else M, r, rank_deficient, rcond)
        f[k], rank[k], flag[k] = sol.f_ig, sol.rank, sol.min_norm
    return GainsSeries(f, rank, flag)


# --------------------------------------------------------------------------- time of week


def _as_times(times, name: str = "times") -> pd.DatetimeIndex:
    idx = times if isinstance(times, pd.DatetimeIndex) else pd.DatetimeIndex(times)
    if idx.tz is None:
        raise GainsTimeError(f"{name} must be tz-aware (localize to the building's time zone or UTC)")
    return idx


def _check_tz(timezone: str) -> str:
    try:
        ZoneInfo(timezone)
    except (ZoneInfoNotFoundError, ValueError, TypeError, OSError) as exc:
        raise GainsInputError(
            f"timezone must be an IANA name such as 'America/Los_Angeles', got {timezone!r}"
        ) from exc
    return timezone


def _step_minutes(step) -> int:
    td = pd.Timedelta(step)
    minutes = td / pd.Timedelta("1min")
    if minutes <= 0 or minutes != int(minutes) or (7 * 24 * 60) % int(minutes):
        raise GainsInputError(f"step must be a whole number of minutes dividing one week, got {step!r}")
    return int(minutes)


def _local_week_and_bin(times, timezone: str, step) -> tuple[np.ndarray, np.ndarray]:
    idx = _as_times(times)
    minutes = _step_minutes(step)
    local = idx.tz_convert(_check_tz(timezone)).tz_localize(None)  # local wall-clock time
    # integer arithmetic on the wall-clock minutes since 1970-01-01 (a Thursday, hence
    # the 3 days that make the week start on Monday); pandas' field accessors cost ~1 ms
    minute = local.as_unit("ns").asi8 // 60_000_000_000
    days = minute // 1440
    weeks = (days + 3) // 7
    bins = ((minute + 3 * 1440) % (7 * 1440)) // minutes
    return np.asarray(weeks, dtype=np.int64), np.asarray(bins, dtype=int)


def time_of_week_bin(times, timezone: str, step: str | pd.Timedelta = "15min") -> np.ndarray:
    """Time-of-week bin of each time, in local wall-clock time.

    Parameters
    ----------
    times : pandas.DatetimeIndex or sequence of tz-aware timestamps
        Interval-start stamps (any tz; converted to ``timezone``).
    timezone : str
        The building's IANA time zone; DST is followed.
    step : str or pandas.Timedelta, default "15min"
        Bin width; 15 min gives 672 bins.

    Returns
    -------
    numpy.ndarray of int, shape (N,)
        ``(local weekday * 1440 + local minute of day) // step``; bin 0 starts
        Monday 00:00 local. Times not on the grid fall into the bin that contains them.
    """
    return _local_week_and_bin(times, timezone, step)[1]


@dataclass(frozen=True)
class WeeklyProfile:
    """Fixed internal-gains function on a local time-of-week axis (paper Eq:fixed_ig).

    Attributes
    ----------
    values : numpy.ndarray, shape (n_bins, p)
        Mean f_IG per bin [W/m²]; NaN where no week had data.
    counts : numpy.ndarray, shape (n_bins, p), int
        Number of weeks that contributed to each bin and zone.
    timezone : str
        IANA time zone of the time-of-week axis.
    step : pandas.Timedelta
        Bin width.
    """

    values: np.ndarray
    counts: np.ndarray
    timezone: str
    step: pd.Timedelta = field(default=STEP)

    @property
    def n_bins(self) -> int:
        """Number of bins (672 for 15 min)."""
        return self.values.shape[0]

    def __call__(self, times) -> np.ndarray:
        """Profile at arbitrary tz-aware times [W/m²], shape (N, p)."""
        return self.values[time_of_week_bin(times, self.timezone, self.step)]

    def updated(self, times, f_ig, forgetting: float) -> WeeklyProfile:
        """Exponential-forgetting update with new estimates.

        Each finite new value ``f`` in bin b moves the bin towards it:
        ``v_b <- (1 - forgetting) v_b + forgetting f`` (an empty bin takes ``f``).

        Parameters
        ----------
        times : pandas.DatetimeIndex
            Stamps of the new estimates (tz-aware).
        f_ig : array_like, shape (N, p)
            New per-step estimates [W/m²]; NaN entries are ignored.
        forgetting : float
            Weight of a new value, in (0, 1] [-]; 1/W approximates a W-week memory.

        Returns
        -------
        WeeklyProfile
            A new profile; ``counts`` is incremented where a bin received data.
        """
        if not 0.0 < forgetting <= 1.0:
            raise GainsInputError(f"forgetting must be in (0, 1], got {forgetting}")
        F = np.asarray(f_ig, dtype=float)
        bins = time_of_week_bin(times, self.timezone, self.step)
        if F.shape != (len(bins), self.values.shape[1]):
            raise GainsInputError(
                f"f_ig must have shape ({len(bins)}, {self.values.shape[1]}), got {F.shape}"
            )
        v = self.values.copy()
        touched = np.zeros_like(self.counts, dtype=bool)
        for b, row in zip(bins, F):
            ok = np.isfinite(row)
            empty = ok & np.isnan(v[b])
            v[b, empty] = row[empty]
            upd = ok & ~empty
            v[b, upd] = (1.0 - forgetting) * v[b, upd] + forgetting * row[upd]
            touched[b] |= ok
        return replace(self, values=v, counts=self.counts + touched)


def fit_weekly_profile(
    times, f_ig, timezone: str, *, step: str | pd.Timedelta = "15min"
) -> WeeklyProfile:
    """Average per-week internal-gains estimates on a local time-of-week axis.

    Implements paper Eq:fixed_ig, ``f_hat(b) = (1/W) sum_w f_w(b)``, with weeks
    running Monday 00:00 to Monday 00:00 in local time. Within one week the
    samples of a bin are averaged first (the repeated hour when DST ends puts two
    samples in a bin; the skipped hour when DST starts leaves its bins empty for
    that week); then the weeks are averaged, each week with data in the bin
    counting once. NaN estimates are skipped.

    Parameters
    ----------
    times : pandas.DatetimeIndex or sequence of tz-aware timestamps
        Stamps of the estimates (interval start), shape (N,).
    f_ig : array_like, shape (N, p)
        Per-step estimates f_IG [W/m²], e.g. :attr:`GainsSeries.f_ig`.
    timezone : str
        The building's IANA time zone.
    step : str or pandas.Timedelta, default "15min"
        Bin width.

    Returns
    -------
    WeeklyProfile
    """
    weeks, bins = _local_week_and_bin(times, timezone, step)
    F = np.asarray(f_ig, dtype=float)
    if F.ndim == 1:
        F = F[:, None]
    if F.shape[0] != len(bins):
        raise GainsInputError(f"f_ig must have one row per time ({len(bins)}), got {F.shape[0]}")
    n_bins = (7 * 24 * 60) // _step_minutes(step)
    p = F.shape[1]
    frame = pd.DataFrame(F)
    frame["week"], frame["bin"] = weeks, bins
    per_week = frame.groupby(["week", "bin"]).mean()  # skips NaN
    grouped = per_week.groupby(level="bin")
    mean, count = grouped.mean(), grouped.count()
    values = np.full((n_bins, p), np.nan)
    counts = np.zeros((n_bins, p), dtype=int)
    values[mean.index.to_numpy()] = mean.to_numpy()
    counts[count.index.to_numpy()] = count.to_numpy()
    return WeeklyProfile(values=values, counts=counts, timezone=timezone, step=pd.Timedelta(step))


@dataclass(frozen=True)
class ReheatLeak:
    """The share of the measured reheat heat that the per-step gains estimate carries
    (:func:`fit_reheat_leak`).

    Attributes
    ----------
    k : numpy.ndarray, shape (p,)
        Heat of the estimate per heat of the zone's reheat [W/W] as used (0 where the
        fitted value was not significant); the model's reheat heat is scaled by 1 + k.
    fitted : numpy.ndarray, shape (p,)
        The least-squares value before the test and the bounds [W/W].
    stderr : numpy.ndarray, shape (p,)
        Its standard error [W/W] (white residuals assumed: a lower bound).
    rows : int
        Rows with a finite estimate that entered the fit.
    """

    k: np.ndarray
    fitted: np.ndarray
    stderr: np.ndarray
    rows: int


#: bounds of :func:`fit_reheat_leak`'s k [W/W]: at -0.5 the air takes half the measured
#: reheat heat, at 1 twice it
REHEAT_LEAK_BOUNDS = (-0.5, 1.0)


def fit_reheat_leak(times, f_ig, q_reheat, timezone: str, *,
                    step: str | pd.Timedelta = "15min", min_t: float = 3.0,
                    bounds: tuple[float, float] = REHEAT_LEAK_BOUNDS) -> ReheatLeak:
    """How much of each zone's measured reheat heat its gains estimate carries.

    The model of the estimate is the fixed weekly profile of paper Eq:fixed_ig plus a
    term in the zone's reheat heat, ``f(t) = profile(bin(t)) + k q(t) + e(t)``: within a
    time-of-week bin the occupants' heat repeats from week to week while the reheat
    follows the weather, so the within-bin least squares (the bins as fixed effects)
    separates the two without knowing the true gains. A perfect model has k = 0; a
    model whose air answers the boxes' heat too weakly (films too strong in operation,
    docs/identification.md "The reheat leak is EnergyPlus's inside convection") has k > 0.
    Days of more occupants need less reheat, so k is biased towards zero, not away.

    Parameters
    ----------
    times : tz-aware timestamps, shape (N,)
    f_ig : array_like, shape (N, p)
        Per-step gains estimates [W/m²] (NaN skipped).
    q_reheat : array_like, shape (N, p)
        Each zone's reheat heat, c_p sum_j u_j r_j per zone floor area [W/m²].
    timezone : str
        The building's IANA time zone (the profile's time-of-week axis).
    step : bin width of the time-of-week axis.
    min_t : float
        A zone's k is used only when |k| / stderr reaches this [-].
    bounds : (float, float)
        k is clipped to these [W/W].

    Returns
    -------
    ReheatLeak
    """
    F = np.asarray(f_ig, dtype=float)
    Q = np.asarray(q_reheat, dtype=float)
    if F.ndim != 2 or Q.shape != F.shape:
        raise GainsInputError(f"f_ig and q_reheat must both have shape (N, p); got {F.shape} "
                              f"and {Q.shape}")
    bins = time_of_week_bin(times, timezone, step)
    if len(bins) != len(F):
        raise GainsInputError(f"one time per row: {len(bins)} times for {len(F)} rows")
    p = F.shape[1]
    k, fitted, se = np.zeros(p), np.zeros(p), np.full(p, np.inf)
    ok_all = np.isfinite(F) & np.isfinite(Q)
    for j in range(p):
        ok = ok_all[:, j]
        if ok.sum() < 3:
            continue
        frame = pd.DataFrame({"f": F[ok, j], "q": Q[ok, j], "b": bins[ok]})
        means = frame.groupby("b")[["f", "q"]].transform("mean")
        ft, qt = (frame["f"] - means["f"]).to_numpy(), (frame["q"] - means["q"]).to_numpy()
        sq = float(qt @ qt)
        dof = len(qt) - frame["b"].nunique() - 1
        if sq <= 1e-12 * float(frame["q"] @ frame["q"]) or dof < 1:
            continue  # the reheat repeats every week: the profile holds all of it
        fitted[j] = float(ft @ qt) / sq
        resid = ft - fitted[j] * qt
        se[j] = float(np.sqrt(resid @ resid / dof / sq))
        if abs(fitted[j]) >= min_t * se[j]:
            k[j] = float(np.clip(fitted[j], *bounds))
    return ReheatLeak(k, fitted, se, int(ok_all.all(axis=1).sum()))


# --------------------------------------------------------------------------- online


def online_gains_series(f_est, *, initial: float = 0.0) -> np.ndarray:
    """Online internal gains along a series, paper eq:online_ig.

    ``f_online[k] = f_IG(k-1)``: the newest estimate known at time k (f_IG(k-1)
    needs y_bar(k)). Where an estimate is NaN the last finite one is held, per
    zone; before the first estimate ``initial`` is used.

    Parameters
    ----------
    f_est : array_like, shape (N, p)
        Per-step estimates f_IG(k) [W/m²] (:attr:`GainsSeries.f_ig`).
    initial : float, default 0.0
        Value before any estimate is known [W/m²] (0 is the paper's
        parameter-identification assumption).

    Returns
    -------
    numpy.ndarray, shape (N, p)
        f_IG(k) to use in paper eq:model_dt when predicting x(k+1) [W/m²].
    """
    F = np.asarray(f_est, dtype=float)
    if F.ndim != 2:
        raise GainsInputError(f"f_est must have shape (N, p), got {F.shape}")
    shifted = np.vstack([np.full((1, F.shape[1]), np.nan), F[:-1]])
    return pd.DataFrame(shifted).ffill().fillna(initial).to_numpy()


class OnlineGains:
    """Streaming form of paper eq:online_ig: f_IG(k) = f_IG(k-1).

    Parameters
    ----------
    n_zones : int
        Number of zones p.
    initial : float, default 0.0
        Value before the first estimate [W/m²].
    """

    def __init__(self, n_zones: int, *, initial: float = 0.0):
        if n_zones < 1:
            raise GainsInputError("n_zones must be >= 1")
        self._value = np.full(n_zones, float(initial))

    @property
    def value(self) -> np.ndarray:
        """Current f_IG [W/m²], shape (p,)."""
        return self._value.copy()

    def observe(self, f_prev) -> None:
        """Take the newest estimate f_IG(k-1) [W/m²]; NaN entries keep the old value."""
        f = np.asarray(f_prev, dtype=float)
        if f.shape != self._value.shape:
            raise GainsInputError(f"f_prev must have shape {self._value.shape}, got {f.shape}")
        ok = np.isfinite(f)
        self._value[ok] = f[ok]

    def predict(self, steps: int = 1) -> np.ndarray:
        """f_IG for the next ``steps`` intervals [W/m²], shape (steps, p): all equal."""
        return np.tile(self._value, (steps, 1))


# --------------------------------------------------------------------------- day ahead


@dataclass(frozen=True)
class DayAheadGains:
    """Day-ahead internal gains: weekly profile plus a decaying recent offset.

    For a forecast issued at ``now`` the gains of interval h (starting at
    ``s_h = now + h step``, h = 0..horizon-1) are

        f(s_h) = f_hat(s_h) + d * exp(-(s_h - now) / tau),

    where f_hat is the weekly profile (paper Eq:fixed_ig) and ``d`` the mean of
    ``f_IG(t) - f_hat(t)`` over the estimates known at ``now`` (stamp
    ``t <= now - step``, because f_IG(t) needs the measurement at ``t + step``)
    within ``window`` before the newest known stamp. With ``tau -> inf``, a zero
    profile and a one-step window this is paper eq:online_ig; with ``tau -> 0`` it
    is the fixed profile. Nothing measured after ``now`` is read.

    Parameters
    ----------
    profile : WeeklyProfile
        Fixed weekly profile; bins without data count as 0.
    tau : pandas.Timedelta, default 3 h
        Decay time constant of the offset [s as a Timedelta]; > 0.
    window : pandas.Timedelta, default 1 h
        Span of recent estimates averaged for the offset.
    horizon : int, default 96
        Number of steps issued (96 x 15 min = 24 h).
    """

    profile: WeeklyProfile
    tau: pd.Timedelta = field(default=pd.Timedelta("3h"))
    window: pd.Timedelta = field(default=pd.Timedelta("1h"))
    horizon: int = HORIZON

    def __post_init__(self):
        object.__setattr__(self, "tau", pd.Timedelta(self.tau))
        object.__setattr__(self, "window", pd.Timedelta(self.window))
        if self.tau <= pd.Timedelta(0):
            raise GainsInputError("tau must be positive (use a very large tau for pure persistence)")
        if self.window < self.profile.step:
            raise GainsInputError(f"window must be at least one step ({self.profile.step})")
        if self.horizon < 1:
            raise GainsInputError("horizon must be >= 1 step")

    def offset(self, now, history: pd.DataFrame, fallback=None
               ) -> tuple[np.ndarray, pd.Timestamp | None]:
        """Recent offset d [W/m²] per zone and the newest stamp used (None if no data);
        ``fallback`` (per zone, default 0) is d of a zone without a finite recent
        estimate."""
        now = pd.Timestamp(now)
        if now.tzinfo is None:
            raise GainsTimeError("now must be a tz-aware timestamp")
        if not isinstance(history, pd.DataFrame):
            raise GainsInputError("history must be a pandas DataFrame indexed by tz-aware time")
        p = self.profile.values.shape[1]
        if history.shape[1] != p:
            raise GainsInputError(f"history must have {p} columns (one per zone), got {history.shape[1]}")
        idx = _as_times(history.index, "history.index")
        step = self.profile.step
        known = np.asarray(idx <= now - step)
        empty = np.zeros(p) if fallback is None else np.asarray(fallback, dtype=float)
        if not known.any():
            return empty.copy(), None
        past = history.loc[known]
        newest = idx[known].max()
        recent = past.loc[np.asarray(past.index > newest - self.window)]
        resid = recent.to_numpy(dtype=float) - np.nan_to_num(self.profile(recent.index))
        with np.errstate(invalid="ignore"):
            n_ok = np.isfinite(resid).sum(axis=0)
            d = np.where(n_ok > 0, np.nansum(resid, axis=0) / np.maximum(n_ok, 1), empty)
        return d, newest

    def issue(self, now, history: pd.DataFrame, level=None) -> pd.DataFrame:
        """Issue f_IG for the next ``horizon`` intervals.

        Parameters
        ----------
        now : pandas.Timestamp
            Issue time (tz-aware); the first issued interval starts here.
        history : pandas.DataFrame
            Past per-step estimates f_IG [W/m²], indexed by interval-start stamps
            (tz-aware), one column per zone. Rows the issuer could not know at
            ``now`` are ignored.
        level : array_like, shape (p,), optional
            A slow level L [W/m²] of ``f_IG - f_hat`` (the streaming estimator's
            exponentially weighted mean, :data:`~zonecast.estimator.streaming.GAINS_LEVEL_TAU`):
            ``f(s_h) = f_hat(s_h) + L + (d - L) exp(-(s_h - now) / tau)``, the offset
            decaying to the level instead of to the profile; ``d`` is L in a zone
            without recent estimates. None: no level (the formula above).

        Returns
        -------
        pandas.DataFrame
            Shape (horizon, p), indexed by the interval starts (tz of ``now``),
            same columns as ``history`` [W/m²].
        """
        L = None if level is None else np.asarray(level, dtype=float)
        p = self.profile.values.shape[1]
        if L is not None and L.shape != (p,):
            raise GainsInputError(f"level must have shape {(p,)} (one per zone), got {L.shape}")
        d, _ = self.offset(now, history, fallback=L)  # a zone without estimates: d = L
        now = pd.Timestamp(now)
        starts = pd.date_range(now, periods=self.horizon, freq=self.profile.step)
        lead = (starts - now) / self.tau
        base = np.nan_to_num(self.profile(starts))
        decay = np.exp(-np.asarray(lead, dtype=float))[:, None]
        if L is None:
            f = base + decay * d[None, :]
        else:
            f = base + L[None, :] + decay * (d - L)[None, :]
        return pd.DataFrame(f, index=starts, columns=history.columns)
