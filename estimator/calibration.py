"""90 % forecast intervals calibrated on a building's own recent forecast errors.

The model's forecast standard deviation (steady-state filter, nominal model: state noise
only) does not know the errors of the input forecasts and of the internal-gains profile;
its 90 % intervals cover far less than 90 % (docs/forecasts.md). :class:`IntervalCalibrator`
rescales it by lead time from the errors the building's own served forecasts made:

- every ``cadence`` steps the streaming estimator issues a calibration forecast (the
  same served forecast) and keeps its mean until its horizon has passed;
- each new measurement y(t) gives, for every kept forecast and zone, the score
  s = |y - mean| / std at that forecast's lead; the score goes into a histogram per
  (bin, zone) with log-spaced score bins. A bin is a lead class (``lead_edges``: up to
  2 h, 2-8 h, 8-24 h) times the UTC time of day of the *target* in ``tod_bins`` bins:
  the errors depend on both (small at night, largest at noon of a working day), and a
  forecast issued at any time of day must get intervals that fit it;
- with a ``day_class`` (the site's working days against weekends and holidays,
  :class:`~zonecast.estimator.inputs_forecast.DayCalendar`) the bins are split by the
  target's day class too: a building's errors on a day its HVAC runs its occupied
  schedule are not those of a day it floats, and pooled scores over-cover the one and
  under-cover the other (docs/forecasts.md "Intervals by day class"); a class's bin
  without enough scores of its own uses the classes' pooled scores;
- the histograms decay by ``lam`` per step (an effective window of 1 / (1 - lam) steps of
  data, ~``window_days``), so the calibration follows the recent days, O(1) per step; with
  day classes only the target's class decays at a step (a window of ``window_days`` days
  of that class);
  scores inside the site's experiments are not kept (the streaming estimator skips them);
- the served half-width is q(bin, zone) x std(h) (times the tracked factor, below):
  split-conformal scaling of the model std with the empirical quantile of recent scores;
- the quantile's level per zone follows adaptive conformal inference (Gibbs and Candès
  2021): after each scored error, level += gamma (miss - (1 - target)), with miss = 1 when
  the error lay outside the interval then served (per day class and zone). A window of
  harder (or easier) days than the present would otherwise widen (narrow) the intervals
  for as long as it lasts. "Then served" is the interval of the forecast's issue
  (``feedback="served"``: each kept forecast keeps the score quantiles it was issued
  with). Until 2026-12-05 a miss was judged against the quantiles at the time of the
  measurement (``feedback="current"``), which by a 24-h lead have already widened on the
  same forecast's earlier errors: the calibration counted about 0.90 of its errors inside
  while the intervals as served covered 0.86 (docs/forecasts.md "The adaptive level's
  feedback");
- ``adapt="scale"`` keeps the level at the target and tracks a factor on the served
  half-width instead: log factor += eta (miss - (1 - target)) per scored error, per day
  class and zone, the miss judged against the served interval (quantile tracking in log
  space, Angelopoulos, Candès and Tibshirani 2023, "Conformal PID control"). Unlike a
  level, which stops at 0.995 (a level of 1 would be an interval as wide as the largest
  score), the factor has no bound short of its numerical guard, so a run of days worse
  than the window's scores is paid back and the served intervals cover the target over
  time; with the level adapted and its misses judged as served the level sat at 0.995 a
  tenth of the time on a training member and the intervals covered 0.877
  (docs/forecasts.md "The adaptive level's feedback").

Until a bin has ``min_weight`` scores the model's own z_0.9 = 1.645 is used.

:class:`WeatherSpread` learns the errors of the weather the served forecasts used, by lead;
the streaming estimator widens the std the calibration scales by the forecast's change
under that error (docs/forecasts.md "Intervals that know the weather's error").
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping

import numpy as np

__all__ = ["CALIBRATION_DEFAULTS", "IntervalCalibrator", "WeatherBlend", "WeatherSpread"]

#: window chosen on office6's training weeks; gamma re-chosen on the validation weeks of the
#: family's training buildings (docs/forecasts.md "Served forecast"); since 2026-12-05 the
#: misses move a factor (adapt "scale", eta 3.5 x gamma), judged by the served interval,
#: adopted on the 12 training members' streams (docs/forecasts.md "The adaptive level's
#: feedback"); gamma is the level's step of adapt "level"
CALIBRATION_DEFAULTS = {"window_days": 7.0, "cadence": 8, "tod_bins": 12, "level": 0.9,
                        "min_weight": 30.0, "gamma": 0.001, "feedback": "served",
                        "adapt": "scale", "eta": 0.0035}
#: guard on the log factor of ``adapt="scale"`` (a factor of 1 / 148 .. 148), against a
#: runaway on broken data; far from reached on a training member's 42-week stream (|log
#: factor| at most 0.6 at its end, docs/forecasts.md "The adaptive level's feedback")
_LOG_SCALE_GUARD = 5.0

_EDGES = np.geomspace(1e-2, 1e2, 51)  # score bins; below/above go to the first/last
_DAY_NS = 86_400 * 10**9


def _hist_quantile(hist: np.ndarray, level: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quantile at ``level`` (bins, zones) of score histograms (bins, zones, score bins)
    with linear interpolation in log score within a score bin; and the histograms'
    weights."""
    c = np.cumsum(hist, axis=2)
    total = c[:, :, -1]
    target = level * total
    k = np.minimum((c < target[:, :, None]).sum(axis=2), len(_EDGES))
    prev = np.take_along_axis(c, np.maximum(k - 1, 0)[:, :, None], axis=2)[:, :, 0]
    prev = np.where(k == 0, 0.0, prev)
    here = np.take_along_axis(hist, k[:, :, None], axis=2)[:, :, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.clip(np.where(here > 0, (target - prev) / here, 0.5), 0.0, 1.0)
    lo_e = np.log(np.concatenate([[_EDGES[0] / 1.1], _EDGES]))
    hi_e = np.log(np.concatenate([_EDGES, [_EDGES[-1] * 1.1]]))
    return np.exp(lo_e[k] + frac * (hi_e[k] - lo_e[k])), total


class IntervalCalibrator:
    """Empirical quantiles of standardised forecast errors per lead bin and zone.

    Parameters
    ----------
    n_zones, horizon : int
        Zones and forecast steps.
    steps_per_day : int
        Steps per day (for ``window_days``).
    window_days : float
        Effective memory [days of data].
    cadence : int
        A calibration forecast every ``cadence`` steps.
    tod_bins : int
        Bins of the target's UTC time of day.
    level : float
        Interval coverage aimed at [-].
    gamma : float
        Step of the adaptive level per scored error [-] (0: fixed level).
    lead_edges : sequence of int
        Lead classes in steps: [e0, e1), [e1, e2), ... (e0 = 0, last = horizon).
    min_weight : float
        Scores a bin needs before its quantile replaces z_0.9.
    z_default : float
        Multiplier of std without enough scores.
    day_class : callable, optional
        UTC grid times [ns since the epoch] (int64 array) -> day class of each (int array
        in ``0 .. n_classes - 1``), e.g. ``DayCalendar.slots(t) // DayCalendar.per_day``.
        None: one class (the calibration before 2026-12-04).
    n_classes : int
        Day classes ``day_class`` returns.
    feedback : {"served", "current"}
        Which interval the adaptive level's miss is judged against: the one the forecast
        was issued with ("served", adaptive conformal inference as published), or the
        one the quantiles give when the measurement arrives ("current", before
        2026-12-05).
    adapt : {"level", "scale"}
        What the misses move: the quantile's level (``gamma``; adaptive conformal
        inference) or a factor on the half-width (``eta``; quantile tracking in log
        space, the level fixed at ``level``; needs ``feedback="served"``).
    eta : float
        Step of the log factor per scored error [-] (``adapt="scale"``).
    """

    def __init__(self, n_zones: int, horizon: int, steps_per_day: int, *,
                 window_days: float = CALIBRATION_DEFAULTS["window_days"],
                 cadence: int = CALIBRATION_DEFAULTS["cadence"],
                 tod_bins: int = CALIBRATION_DEFAULTS["tod_bins"],
                 level: float = CALIBRATION_DEFAULTS["level"],
                 min_weight: float = CALIBRATION_DEFAULTS["min_weight"],
                 gamma: float = CALIBRATION_DEFAULTS["gamma"],
                 lead_edges=(0, 8, 32), step_ns: int = 900 * 10**9,
                 z_default: float = 1.6448536269514722,
                 day_class: Callable[[np.ndarray], np.ndarray] | None = None,
                 n_classes: int = 1, feedback: str = CALIBRATION_DEFAULTS["feedback"],
                 adapt: str = CALIBRATION_DEFAULTS["adapt"],
                 eta: float = CALIBRATION_DEFAULTS["eta"]):
        if not 0 < level < 1:
            raise ValueError("level must lie in (0, 1)")
        if feedback not in ("served", "current"):
            raise ValueError(f"feedback must be 'served' or 'current', got {feedback!r}")
        if adapt not in ("level", "scale"):
            raise ValueError(f"adapt must be 'level' or 'scale', got {adapt!r}")
        if adapt == "scale" and feedback != "served":
            raise ValueError("adapt='scale' judges each miss by the served interval: give "
                             "feedback='served'")
        self.feedback, self.adapt, self.eta = feedback, adapt, float(eta)
        if n_classes < 1 or (day_class is None) != (n_classes == 1):
            raise ValueError("give day_class with n_classes > 1, or neither")
        self.nz, self.horizon, self.cadence = int(n_zones), int(horizon), int(cadence)
        self.tod_bins, self.target, self.gamma = int(tod_bins), float(level), float(gamma)
        self.step_ns = int(step_ns)
        self.lam = 1.0 - 1.0 / (window_days * steps_per_day)
        self.min_weight, self.z_default = float(min_weight), float(z_default)
        lead_class = np.searchsorted(np.asarray(lead_edges[1:]), np.arange(1, horizon + 1),
                                     side="right")
        self._lead_class = lead_class  # lead h (1..horizon) at index h - 1
        self.day_class, self.n_classes = day_class, int(n_classes)
        #: bins of one day class (lead class x time of day)
        self.n_class_bins = (int(lead_class.max()) + 1) * self.tod_bins
        self.n_bins = self.n_classes * self.n_class_bins
        self.hist = np.zeros((self.n_bins, self.nz, len(_EDGES) + 1))
        #: adaptive level per day class and zone
        self.levels = np.full((self.n_classes, self.nz), self.target)
        #: log factor on the served half-width per day class and zone (adapt="scale")
        self.log_scale = np.zeros((self.n_classes, self.nz))
        # (issue step, mean, std or None: the std given to resolve, the score quantiles
        # (horizon, n_zones) it was issued with or None: the quantiles when scored)
        self.pending: deque[tuple[int, np.ndarray, np.ndarray | None, np.ndarray | None]] = \
            deque(maxlen=horizon // cadence + 1)
        self._q: np.ndarray | None = None

    def bins(self, step_index: int, leads: np.ndarray) -> np.ndarray:
        """Bin of the targets at leads ``leads`` (1..horizon) of a forecast issued at grid
        step ``step_index``."""
        leads = np.asarray(leads, dtype=np.int64)
        t = (int(step_index) + leads) * self.step_ns
        b = self._class_bins(t, leads)
        if self.day_class is not None:
            b = b + np.asarray(self.day_class(t), dtype=np.int64) * self.n_class_bins
        return b

    def _class_bins(self, t: np.ndarray, leads: np.ndarray) -> np.ndarray:
        """Bin within a day class of targets at UTC grid times ``t`` [ns] and leads."""
        tod = (t % _DAY_NS) * self.tod_bins // _DAY_NS
        return self._lead_class[leads - 1] * self.tod_bins + tod

    def class_of(self, step_index: int) -> int:
        """Day class of grid step ``step_index`` (0 without day classes)."""
        if self.day_class is None:
            return 0
        t = np.array([int(step_index) * self.step_ns], dtype=np.int64)
        return int(np.asarray(self.day_class(t))[0])

    @property
    def level(self) -> np.ndarray:
        """Adaptive level per zone (n_zones,) of the first day class (all of them
        without day classes)."""
        return self.levels[0]

    def due(self, step_index: int) -> bool:
        """Whether a calibration forecast is due at grid step number ``step_index``."""
        return step_index % self.cadence == 0

    def add_forecast(self, step_index: int, mean: np.ndarray,
                     std: np.ndarray | None = None) -> None:
        """Keep a forecast issued at step ``step_index`` (mean (horizon, n_zones) [degC]);
        ``std`` (horizon, n_zones) [K] the model std it was issued with (default: the std
        :meth:`resolve` is given). With ``feedback="served"`` it keeps the score quantiles
        of its interval too (those :meth:`halfwidth` gives at this step)."""
        issued = None
        if self.feedback == "served":
            issued = self.quantiles()[self.bins(step_index, np.arange(1, self.horizon + 1))]
        self.pending.append((int(step_index), np.array(mean, dtype=float),
                             None if std is None else np.array(std, dtype=float), issued))

    def resolve(self, step_index: int, y: np.ndarray, std: np.ndarray) -> int:
        """Score the kept forecasts against y at step ``step_index`` (decays the histograms
        once); ``std`` (horizon, n_zones) the model std [K] of forecasts kept without
        their own. Returns the scores added."""
        y = np.asarray(y, float)
        ok = np.isfinite(y)
        added = 0
        c = self.class_of(step_index)
        if ok.any():
            zones = np.flatnonzero(ok)
            q = self.quantiles()
            for k0, mean, own, issued in self.pending:
                h = step_index - k0
                if 1 <= h <= self.horizon:
                    sd = std if own is None else own
                    s = np.abs(y[zones] - mean[h - 1, zones]) / np.maximum(sd[h - 1, zones], 1e-9)
                    b = int(self._class_bins(np.array([step_index * self.step_ns]),
                                             np.array([h]))[0]) + c * self.n_class_bins
                    self.hist[b, zones, np.searchsorted(_EDGES, s)] += 1.0
                    step = self.eta if self.adapt == "scale" else self.gamma
                    if step > 0:
                        served = q[b, zones] if issued is None else issued[h - 1, zones]
                        miss = (s > served).astype(float)
                        if self.adapt == "scale":
                            self.log_scale[c, zones] = np.clip(
                                self.log_scale[c, zones] + step * (miss - (1.0 - self.target)),
                                -_LOG_SCALE_GUARD, _LOG_SCALE_GUARD)
                        else:
                            self.levels[c, zones] = np.clip(
                                self.levels[c, zones] + step * (miss - (1.0 - self.target)),
                                0.5, 0.995)
                    added += len(zones)
        # the target's day class forgets (all of them without classes)
        self.hist[c * self.n_class_bins:(c + 1) * self.n_class_bins] *= self.lam
        while self.pending and step_index - self.pending[0][0] >= self.horizon:
            self.pending.popleft()
        self._q = None
        return added

    def quantiles(self) -> np.ndarray:
        """(n_bins, n_zones) score quantile at each zone's current level (z_default where
        a bin has too few scores). Linear interpolation in log score within a histogram
        bin."""
        if self._q is not None:
            return self._q
        level = np.repeat(self.levels, self.n_class_bins, axis=0)  # (n_bins, nz)
        q, total = _hist_quantile(self.hist, level)
        if self.n_classes > 1:
            # a class's bin short of scores takes the classes' pooled ones at its level
            pooled = self.hist.reshape(self.n_classes, self.n_class_bins, self.nz, -1).sum(axis=0)
            qp, tp = _hist_quantile(np.tile(pooled, (self.n_classes, 1, 1)), level)
            q = np.where(total >= self.min_weight, q, qp)
            total = np.where(total >= self.min_weight, total, tp)
        self._q = np.where(total >= self.min_weight, q, self.z_default)
        if self.adapt == "scale":
            self._q = self._q * np.exp(np.repeat(self.log_scale, self.n_class_bins, axis=0))
        return self._q

    def halfwidth(self, step_index: int, std: np.ndarray) -> np.ndarray:
        """Calibrated 90 % half-widths (horizon, n_zones) [K] of a forecast issued at grid
        step ``step_index`` with model std ``std`` [K]."""
        b = self.bins(step_index, np.arange(1, self.horizon + 1))
        return self.quantiles()[b] * np.asarray(std, float)

    # --- state ------------------------------------------------------------------------
    def state_arrays(self, prefix: str = "cal_") -> dict[str, np.ndarray]:
        steps = np.array([k for k, *_ in self.pending], dtype=np.int64)
        means = np.array([m for _, m, *_ in self.pending]).reshape(-1, self.horizon, self.nz)
        nan = np.full((self.horizon, self.nz), np.nan)
        stds = np.array([nan if s is None else s for _, _, s, _ in self.pending]).reshape(
            -1, self.horizon, self.nz)
        issued = np.array([nan if q is None else q for *_, q in self.pending]).reshape(
            -1, self.horizon, self.nz)
        return {f"{prefix}hist": self.hist, f"{prefix}level": self.levels,
                f"{prefix}steps": steps, f"{prefix}means": means, f"{prefix}stds": stds,
                f"{prefix}issued_q": issued, f"{prefix}log_scale": self.log_scale}

    def load_state_arrays(self, arrays: Mapping[str, np.ndarray], prefix: str = "cal_") -> bool:
        if f"{prefix}hist" not in arrays:
            return False
        hist = np.array(arrays[f"{prefix}hist"], float)
        level = np.array(arrays.get(f"{prefix}level", self.levels[0]), float)
        if hist.shape == self.hist.shape:
            self.hist = hist
            self.levels = level.reshape(self.levels.shape) if level.size == self.levels.size \
                else np.tile(level.reshape(1, -1)[-1:], (self.n_classes, 1))
        elif hist.shape == (self.n_class_bins,) + self.hist.shape[1:]:
            # a checkpoint of the calibration without day classes: each class starts from
            # the pooled scores and level
            self.hist = np.tile(hist, (self.n_classes, 1, 1))
            self.levels = np.tile(level.reshape(1, -1)[-1:], (self.n_classes, 1))
        elif (1 < self.n_classes and hist.ndim == self.hist.ndim
              and hist.shape[1:] == self.hist.shape[1:]
              and hist.shape[0] % self.n_class_bins == 0
              and hist.shape[0] // self.n_class_bins > 1):
            # a checkpoint with another number of day classes (the day after a day off
            # with its own or not): the classes both have kept; a new class starts from
            # the first class's (working days') scores and level, a class no longer kept
            # gives its scores to the first class
            k = hist.shape[0] // self.n_class_bins
            hist = hist.reshape((k, self.n_class_bins) + hist.shape[1:])
            lv = (level.reshape(k, -1) if level.size == k * self.nz
                  else np.tile(level.reshape(1, -1)[-1:], (k, 1)))
            if k < self.n_classes:
                hist = np.concatenate([hist] + [hist[:1]] * (self.n_classes - k))
            else:
                extra = hist[self.n_classes:].sum(axis=0)
                hist = hist[:self.n_classes].copy()
                hist[0] += extra
            self.hist = hist.reshape(self.hist.shape)
            self.levels = _class_rows(lv, self.n_classes, self.nz)
        elif (self.n_classes == 1 and hist.ndim == self.hist.ndim
              and hist.shape[1:] == self.hist.shape[1:]
              and hist.shape[0] % self.n_class_bins == 0):
            # a checkpoint of the calibration by day class: the classes' weighted scores
            # pooled, the adaptive level their mean
            k = hist.shape[0] // self.n_class_bins
            self.hist = hist.reshape((k, self.n_class_bins) + hist.shape[1:]).sum(axis=0)
            self.levels = _class_rows(level.reshape(k, -1), 1, self.nz)
        else:
            return False
        # the half-width's factor, carried over the day classes as the level is (a new class
        # starts from the working days' factor, pooled classes take their mean); absent in
        # checkpoints before it, or for other zones: it starts again from 1
        self.log_scale = _class_rows(arrays.get(f"{prefix}log_scale"), self.n_classes, self.nz)
        if self.adapt == "scale":  # the level is fixed (a level-adapting checkpoint's is not)
            self.levels = np.full_like(self.levels, self.target)
        self.pending.clear()
        stds = arrays.get(f"{prefix}stds")  # absent in checkpoints before it
        # absent before 2026-12-05 (or kept with feedback "current"): judged by the
        # quantiles when scored
        issued = arrays.get(f"{prefix}issued_q") if self.feedback == "served" else None
        for i, (k, m) in enumerate(zip(arrays[f"{prefix}steps"], arrays[f"{prefix}means"])):
            sd = None if stds is None or np.isnan(stds[i]).all() else np.array(stds[i], float)
            q = (None if issued is None or np.isnan(issued[i]).all()
                 else np.array(issued[i], float))
            self.pending.append((int(k), np.array(m, float), sd, q))
        self._q = None
        return True


def _class_rows(rows, n_classes: int, nz: int) -> np.ndarray:
    """(n_classes, nz) from a checkpoint's (k, nz) per-class array ``rows``: the same, the
    first rows of more, the mean of several into one, or one or fewer rows extended by
    copies of the first (the working days'); zeros when absent or of other zones."""
    if rows is None or np.ndim(rows) != 2 or np.shape(rows)[1] != nz or len(rows) == 0:
        return np.zeros((n_classes, nz))
    rows = np.array(rows, float)
    if n_classes == 1 and len(rows) > 1:
        return rows.mean(axis=0, keepdims=True)
    if len(rows) >= n_classes:
        return rows[:n_classes].copy()
    return np.concatenate([rows] + [rows[:1]] * (n_classes - len(rows)))


class _LeadScores:
    """What :class:`WeatherSpread` and :class:`WeatherBlend` share: forecasts kept by the
    grid step they were issued at until their horizon has passed, scored by lead in bins of
    ``lead_bin`` steps, with sums that decay by ``lam`` per step (an effective memory of
    ``window_days`` days of data)."""

    #: the subclass's decaying (lead bins, channels) sums, the arrays each kept forecast
    #: holds after its step, and the checkpoint keys' prefix
    _SUMS: tuple[str, ...] = ()
    _KEPT: tuple[str, ...] = ()
    _PREFIX = ""

    def __init__(self, n_channels: int, horizon: int, steps_per_day: int,
                 window_days: float, lead_bin: int):
        if window_days <= 0 or lead_bin < 1:
            raise ValueError(f"window_days must be > 0 and lead_bin >= 1, got {window_days}, "
                             f"{lead_bin}")
        self.nc, self.horizon, self.lead_bin = int(n_channels), int(horizon), int(lead_bin)
        self.lam = 1.0 - 1.0 / (window_days * steps_per_day)
        self.n_bins = -(-self.horizon // self.lead_bin)
        self._lead_bin_of = np.arange(self.horizon) // self.lead_bin  # lead h at h - 1
        self.pending: deque = deque(maxlen=horizon + 1)

    def _due(self, step_index: int):
        """(lead bin, lead h, kept entry) of every kept forecast that step ``step_index``
        scores (1 <= h < horizon)."""
        for entry in self.pending:
            h = step_index - entry[0]
            if 1 <= h < self.horizon:
                yield self._lead_bin_of[h - 1], h, entry

    def _drop_past(self, step_index: int) -> None:
        while self.pending and step_index - self.pending[0][0] >= self.horizon:
            self.pending.popleft()

    def state_arrays(self, prefix: str | None = None) -> dict[str, np.ndarray]:
        """The sums and the kept forecasts as named arrays (a checkpoint's)."""
        p = self._PREFIX if prefix is None else prefix
        out = {f"{p}{name}": getattr(self, name) for name in self._SUMS}
        out[f"{p}steps"] = np.array([e[0] for e in self.pending], dtype=np.int64)
        for i, name in enumerate(self._KEPT, start=1):
            out[f"{p}{name}"] = np.array([e[i] for e in self.pending]).reshape(
                -1, self.horizon, self.nc)
        return out

    def load_state_arrays(self, arrays: Mapping[str, np.ndarray],
                          prefix: str | None = None) -> bool:
        """Restore :meth:`state_arrays`; False (and nothing changed) when absent or of
        another shape."""
        p = self._PREFIX if prefix is None else prefix
        first = f"{p}{self._SUMS[0]}"
        if first not in arrays or np.shape(arrays[first]) != getattr(self, self._SUMS[0]).shape:
            return False
        for name in self._SUMS:
            setattr(self, name, np.array(arrays[f"{p}{name}"], float))
        self.pending.clear()
        for k, *kept in zip(arrays[f"{p}steps"], *(arrays[f"{p}{n}"] for n in self._KEPT)):
            self.pending.append((int(k), *(np.array(v, float) for v in kept)))
        return True


class WeatherSpread(_LeadScores):
    """Errors of the weather inputs the served forecasts used, by lead, learned online.

    Each calibration forecast's weather inputs (H, channels) are kept until the horizon
    has passed; each new row's measured weather scores them by lead (bins of
    ``lead_bin`` steps): the exponentially weighted mean square error per (lead bin,
    channel), and for ``relative`` channels (irradiance: zero at night, an error that
    scales with the sun) the mean square of the values used too. :meth:`spread` turns a
    forecast's weather inputs into a one-sided perturbation of each: the RMS error of
    an absolute channel, the relative RMS error times the value of a relative one. The
    estimator runs its forecast again with the perturbed weather, and the zone
    temperatures' change is the forecast's sensitivity to the weather forecast's error:
    large when the rooms float with the sun and the outdoor air, small where the
    thermostats hold them (docs/forecasts.md "Intervals that know the weather's error").

    Parameters
    ----------
    n_channels, horizon : int
        Weather channels and forecast steps.
    steps_per_day : int
        Steps per day (for ``window_days``).
    relative : sequence of bool
        Per channel: error relative to the value (True) or absolute (False).
    window_days : float
        Effective memory [days of data].
    lead_bin : int
        Steps per lead bin.
    min_weight : float
        Scores a (lead bin, channel) needs before it perturbs (none before).
    """

    _SUMS, _KEPT, _PREFIX = ("sq_err", "sq_val", "weight"), ("values",), "wsp_"

    def __init__(self, n_channels: int, horizon: int, steps_per_day: int, relative, *,
                 window_days: float = 7.0, lead_bin: int = 4, min_weight: float = 30.0):
        super().__init__(n_channels, horizon, steps_per_day, window_days, lead_bin)
        self.relative = np.asarray(relative, dtype=bool)
        if self.relative.shape != (self.nc,):
            raise ValueError(f"relative needs one flag per channel ({self.nc})")
        self.min_weight = float(min_weight)
        self.sq_err = np.zeros((self.n_bins, self.nc))
        self.sq_val = np.zeros((self.n_bins, self.nc))
        self.weight = np.zeros((self.n_bins, self.nc))

    def add(self, step_index: int, values: np.ndarray) -> None:
        """Keep the weather inputs (horizon, channels) of a forecast issued at grid step
        ``step_index`` (row 0 the issue interval, row h lead h)."""
        self.pending.append((int(step_index), np.array(values, dtype=float)))

    def resolve(self, step_index: int, measured: np.ndarray) -> None:
        """Score the kept inputs against the weather ``measured`` (channels,) at grid step
        ``step_index``; decays once."""
        obs = np.asarray(measured, float)
        for lb, h, (_, vals) in self._due(step_index):
            v = vals[h]
            ok = np.isfinite(obs) & np.isfinite(v)
            self.sq_err[lb, ok] += (v[ok] - obs[ok]) ** 2
            self.sq_val[lb, ok] += v[ok] ** 2
            self.weight[lb, ok] += 1.0
        for a in (self.sq_err, self.sq_val, self.weight):
            a *= self.lam
        self._drop_past(step_index)

    def spread(self, values: np.ndarray) -> np.ndarray:
        """One-sided perturbation (horizon, channels) of weather inputs ``values``: 0 at
        row 0 (measured) and wherever too few scores are learned."""
        values = np.asarray(values, float)
        ok = self.weight >= self.min_weight
        with np.errstate(invalid="ignore", divide="ignore"):
            absolute = np.where(ok, np.sqrt(self.sq_err / np.maximum(self.weight, 1e-300)), 0.0)
            ratio = np.where(ok & (self.sq_val > 0),
                             np.sqrt(self.sq_err / np.where(self.sq_val > 0, self.sq_val, 1.0)),
                             0.0)
        out = np.zeros_like(values)
        lb = self._lead_bin_of[:len(values) - 1]
        out[1:] = np.where(self.relative[None, :], ratio[lb] * np.abs(values[1:]), absolute[lb])
        return np.nan_to_num(out)


class WeatherBlend(_LeadScores):
    """Combination weights of a weather forecast with the diurnal fallback, by lead,
    learned online (:mod:`zonecast.estimator.weather_forecast`'s docstring; an option of
    the streaming estimator, ``streaming.WEATHER_BLEND``).

    For each (lead bin, channel) it keeps exponentially weighted sums of (F - D)^2 and
    (O - D)(F - D) over the scored pairs, F the forecast's value, D the fallback's and O
    the measured weather at the forecast interval; the weight is their ratio clipped to
    [0, 1], or 1 while the bin's effective number of scored pairs is below
    ``min_weight``. Only intervals that the forecast supplied are kept and scored.

    Parameters
    ----------
    n_channels, horizon : int
        Weather channels and forecast steps.
    steps_per_day : int
        Steps per day (for ``window_days``).
    window_days : float
        Effective memory [days of data].
    lead_bin : int
        Steps per lead bin.
    min_weight : float
        Effective number of scored pairs a (lead bin, channel) needs before its weight is
        used.
    """

    _SUMS, _KEPT, _PREFIX = ("s_ff", "s_of", "weight"), ("forecast", "fallback"), "wbl_"

    def __init__(self, n_channels: int, horizon: int, steps_per_day: int, *,
                 window_days: float = 14.0, lead_bin: int = 4, min_weight: float = 30.0):
        super().__init__(n_channels, horizon, steps_per_day, window_days, lead_bin)
        self.min_weight = float(min_weight)
        self.s_ff = np.zeros((self.n_bins, self.nc))
        self.s_of = np.zeros((self.n_bins, self.nc))
        self.weight = np.zeros((self.n_bins, self.nc))

    def add(self, step_index: int, forecast: np.ndarray, fallback: np.ndarray) -> None:
        """Keep the forecast's and the fallback's values (horizon, channels) of a forecast
        issued at grid step ``step_index`` (row h lead h; NaN where the forecast did not
        supply the interval)."""
        self.pending.append((int(step_index), np.array(forecast, dtype=float),
                             np.array(fallback, dtype=float)))

    def resolve(self, step_index: int, measured: np.ndarray) -> None:
        """Score the kept pairs against the weather ``measured`` (channels,) at grid step
        ``step_index``; decays once."""
        obs = np.asarray(measured, float)
        for a in (self.s_ff, self.s_of, self.weight):
            a *= self.lam
        for lb, h, (_, f, d) in self._due(step_index):
            ok = np.isfinite(obs) & np.isfinite(f[h]) & np.isfinite(d[h])
            dev = f[h, ok] - d[h, ok]
            self.s_ff[lb, ok] += dev ** 2
            self.s_of[lb, ok] += (obs[ok] - d[h, ok]) * dev
            self.weight[lb, ok] += 1.0
        self._drop_past(step_index)

    def weights(self) -> np.ndarray:
        """(lead bins, channels) weights a in [0, 1]; 1 where too few pairs are scored or
        the forecast never departed from the fallback."""
        ok = (self.weight >= self.min_weight) & (self.s_ff > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            a = np.where(ok, self.s_of / np.where(self.s_ff > 0, self.s_ff, 1.0), 1.0)
        return np.clip(a, 0.0, 1.0)

    def blend(self, forecast: np.ndarray, fallback: np.ndarray) -> np.ndarray:
        """(horizon, channels) D + a (F - D) at rows 1 .. horizon - 1 where both are
        finite; the forecast elsewhere (row 0 is the measured interval)."""
        f = np.array(forecast, dtype=float)
        d = np.asarray(fallback, float)
        a = self.weights()[self._lead_bin_of[:len(f) - 1]]
        both = np.isfinite(f[1:]) & np.isfinite(d[1:])
        f[1:] = np.where(both, d[1:] + a * (f[1:] - d[1:]), f[1:])
        return f

