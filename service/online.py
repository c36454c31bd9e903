"""The online estimator of one building: Kalman filter, online f_IG and day-ahead forecast.

Pure numerics (no storage, network or clock): the runner (:mod:`.runner`) feeds it rows
read from storage, :func:`zonecast.service.offline.offline_forecasts` feeds it rows of a
telemetry file, and both get the same numbers.

A *row* is one time t on the 15-min grid with u(t), v(t) and y(t) (docs/data.md: row t
holds the zone temperatures at t and the inputs averaged over [t, t + 15 min)).
:meth:`OnlineEstimator.advance` processes rows in time order; rows with no data may be
left out (the estimator steps over them with held inputs and no measurement, up to
``max_gap``). One step t_prev -> t does, with the exact step matrices of the model for
u(t_prev) (paper eq:model_dt):

1. the prediction with zero time-varying gains, paper Eq:xnoig_ynoig:
   ``x~(t) = Phi x(t_prev) + Gamma_v v(t_prev) + Gamma_IG c_IG``;
2. the per-step least squares of paper Eq:ig(k-1), ``(C Gamma_IG) f_IG(t_prev) = y(t) - C x~(t)``
   (NaN when the observed zones do not determine all gains);
3. the Kalman predict with the online gains of paper eq:online_ig, f_IG(t_prev) taken as
   the newest estimate known before y(t) (that of the step before), then the update with
   the observed entries of y(t) (partial measurements allowed; NIS recorded);
4. the online value becomes the new estimate (eq:online_ig: f_IG(t) = f_IG(t_prev)).

A forecast issued at t starts from the filtered x(t|t), P(t|t) and runs the model 96
steps with the internal gains of :class:`~zonecast.estimator.gains.DayAheadGains` (weekly
profile plus the decaying recent offset) and *persistence inputs*: u and v of interval
t are the measured row t, those of t + h (h >= 1) are the values measured 24 h earlier
(no weather or HVAC forecast enters; see docs/service.md). The covariance is propagated
exactly, P <- Phi P Phi' + Q, and the 90 % interval of a zone is
``C x +- 1.645 sqrt(C P C')`` (state uncertainty; measurement noise not added).
"""

from __future__ import annotations

import io
import json
from collections import deque
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .modelfile import ModelBundle

__all__ = ["Forecast", "OnlineEstimator", "StepReport", "rows_from_frame"]

STEP = pd.Timedelta("15min")
Z90 = 1.6448536269514722  # standard normal 95 % quantile: two-sided 90 % interval
HORIZON = 96
MAX_GAP = pd.Timedelta("6h")


@dataclass(frozen=True)
class Forecast:
    """A day-ahead forecast.

    Attributes
    ----------
    issued : pandas.Timestamp
        Issue time (UTC): the time of the last measurement used.
    times : pandas.DatetimeIndex
        Forecast times t + 15 min ... t + 24 h (UTC).
    mean, std : ndarray, shape (96, n_zones)
        Zone temperature [degC] and its standard deviation [K].
    f_ig : ndarray, shape (96, n_zones)
        Internal gains used per interval [W/m2].
    zones : list of str
    model_version : str
    """

    issued: pd.Timestamp
    times: pd.DatetimeIndex
    mean: np.ndarray
    std: np.ndarray
    f_ig: np.ndarray
    zones: list[str]
    model_version: str

    @property
    def lower(self) -> np.ndarray:
        """Lower end of the 90 % interval [degC]."""
        return self.mean - Z90 * self.std

    @property
    def upper(self) -> np.ndarray:
        """Upper end of the 90 % interval [degC]."""
        return self.mean + Z90 * self.std


@dataclass(frozen=True)
class StepReport:
    """What one processed row did (for metrics and the state endpoint)."""

    time: pd.Timestamp
    nis: float
    dof: int
    reset: bool
    missing_zones: list[str]
    held_inputs: list[str]


def rows_from_frame(bundle: ModelBundle, frame: pd.DataFrame):
    """Telemetry in SI units (UTC index on the step grid, one column per point) -> the
    model's arrays: times, u (N, boxes) [kg/s], v (N, 6), y (N, zones) [degC].

    Missing points are NaN columns. The same function serves the runner (a few rows
    from storage) and the offline path (a whole file).
    """
    from zonecast.estimator.dataset import model_data
    from zonecast.estimator.telemetry import Telemetry, segments_of

    site = bundle.site
    cols = list(site.point_units())
    frame = frame.reindex(columns=cols).astype(float)
    tel = Telemetry(frame, site, segments_of(frame.index, site.step))
    data = model_data(tel, bundle.room_volume)
    return data.times, data.u, data.v, data.y


def _input_names(bundle: ModelBundle) -> list[str]:
    from zonecast.estimator.dataset import DISTURBANCES

    return [f"u:{b}" for b in bundle.site.boxes] + [f"v:{d}" for d in DISTURBANCES]


class OnlineEstimator:
    """Streaming state, internal gains and forecasts of one building.

    Parameters
    ----------
    bundle : ModelBundle
        Model, profile and noise (:func:`~zonecast.service.modelfile.load_model_file`).
    max_gap : pandas.Timedelta
        Longest stretch without any data that is bridged by prediction; after a longer
        gap the filter restarts from the next measurement.
    """

    def __init__(self, bundle: ModelBundle, *, max_gap: pd.Timedelta = MAX_GAP):
        from zonecast.estimator.gains import DayAheadGains

        self.bundle = bundle
        self.max_gap = pd.Timedelta(max_gap)
        m = bundle.model
        self._n, self._nz = m.n, m.n_zones
        self._nin = m.n_boxes + 6
        air = np.flatnonzero([lbl.kind == "room_air" for lbl in m.structure.labels])
        from zonecast.estimator.kalman import (
            air_wall_covariance,
            default_measurement_noise,
        )

        ns = bundle.noise
        self._Q = air_wall_covariance(m.n, air, ns.sigma_air, ns.sigma_wall)
        self._R = default_measurement_noise(m.n_zones, sigma=ns.sigma_meas)
        self._P0 = air_wall_covariance(m.n, air, ns.p0_sigma_air, ns.p0_sigma_wall)
        self._dayahead = DayAheadGains(bundle.profile, horizon=HORIZON)
        self._names = _input_names(bundle)
        self.reset()
        self.steps = 0
        self.resets = 0
        self.nis_sum = 0.0
        self.dof_sum = 0

    # --- state ---------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the state (the next row with a measurement starts the filter)."""
        self._filter = None
        self.time: pd.Timestamp | None = None
        self._pending = np.full(self._nin, np.nan)  # inputs of the row at self.time
        self._held = np.full(self._nin, np.nan)  # last finite value of each input
        self._online = np.zeros(self._nz)  # f_IG used for the next prediction [W/m2]
        self._gains: deque[tuple[pd.Timestamp, np.ndarray]] = deque(maxlen=8)
        self._inputs: deque[tuple[pd.Timestamp, np.ndarray]] = deque(maxlen=HORIZON)
        self.last_y = np.full(self._nz, np.nan)
        self.last_f = np.full(self._nz, np.nan)

    @property
    def started(self) -> bool:
        return self._filter is not None

    @property
    def x(self) -> np.ndarray:
        return self._filter.x

    @property
    def P(self) -> np.ndarray:
        return self._filter.P

    @property
    def online_gains(self) -> np.ndarray:
        """Current online f_IG per zone [W/m2] (paper eq:online_ig)."""
        return self._online.copy()

    def zone_estimate(self) -> tuple[np.ndarray, np.ndarray]:
        """Filtered zone temperatures C x [degC] and their standard deviations [K]."""
        C = self.bundle.model.C
        return C @ self.x, np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", C, self.P, C), 0.0))

    def _start(self, t: pd.Timestamp, y: np.ndarray) -> None:
        from zonecast.estimator.kalman import ZoneStateFilter, initial_state_from_measurement

        x0 = initial_state_from_measurement(y, self.bundle.state_zone)
        self._filter = ZoneStateFilter(x0, self._P0, self.bundle.model.C, self._Q, self._R)
        self.time = t
        self._online = np.zeros(self._nz)

    # --- one row ---------------------------------------------------------------------
    def advance(self, t, u, v, y) -> StepReport | None:
        """Process the row at ``t`` (after every earlier row).

        Parameters
        ----------
        t : timestamp
            Row time (tz-aware, on the 15-min grid), later than the last processed row.
        u : array (n_boxes,)
            Box airflows averaged over [t, t + 15 min) [kg/s]; NaN = missing.
        v : array (6,)
            Ta, Ts [degC], solE, solS, solW, solN [W/m2] over the same interval.
        y : array (n_zones,)
            Zone temperatures at t [degC]; NaN = missing.

        Returns
        -------
        StepReport or None
            None while the filter has not started (no measurement yet).
        """
        t = pd.Timestamp(t).tz_convert("UTC")
        if self.time is not None and t <= self.time:
            raise ValueError(f"row {t.isoformat()} is not after the last processed row "
                             f"{self.time.isoformat()}")
        inputs = np.concatenate([np.asarray(u, float), np.asarray(v, float)])
        y = np.asarray(y, dtype=float)
        reset = False
        if self.started and t - self.time > self.max_gap:
            self.reset()
            self.resets += 1
            reset = True
        nis, dof = float("nan"), 0
        if not self.started:
            if not np.isfinite(y).any():
                return None
            self._start(t, y)
        else:
            nis, dof = self._bridge_and_step(t, y)
        ok = np.isfinite(inputs)
        self._held[ok] = inputs[ok]
        self._pending = self._held.copy()
        self._inputs.append((t, self._pending.copy()))
        self.last_y = y.copy()
        held = [n for n, good in zip(self._names, ok) if not good]
        missing = [z for z, val in zip(self.bundle.zones, y) if not np.isfinite(val)]
        return StepReport(t, nis, dof, reset, missing, held)

    def _bridge_and_step(self, t: pd.Timestamp, y: np.ndarray) -> tuple[float, int]:
        empty = np.full(self._nz, np.nan)
        while self.started and self.time + STEP < t:  # steps without any data: predict only
            self._step(self.time + STEP, empty)
        if not self.started:
            if np.isfinite(y).any():
                self._start(t, y)
            return float("nan"), 0
        return self._step(t, y)

    def _step(self, t: pd.Timestamp, y: np.ndarray) -> tuple[float, int]:
        from zonecast.estimator.gains import RankDeficientError, estimate_gains_step

        m = self.bundle.model
        if not np.isfinite(self._pending).all():
            # an input never seen since the start: the model cannot be stepped; the
            # filter restarts at the next measurement
            self.reset()
            self.resets += 1
            return float("nan"), 0
        u, v = self._pending[:m.n_boxes], self._pending[m.n_boxes:]
        phi, gv, gig = m.step_matrices(u)
        c0 = gv @ v + gig @ m.params.c_ig  # Eq:xnoig_ynoig (f_IG = 0)
        x_prev = self._filter.x
        y_tilde = m.C @ (phi @ x_prev + c0)
        try:
            f = estimate_gains_step(m.C @ gig, y, y_tilde).f_ig  # Eq:ig(k-1)
        except RankDeficientError:
            f = np.full(self._nz, np.nan)
        self._filter.predict(phi, c0 + gig @ self._online)  # eq:online_ig
        inn = self._filter.update(y)
        self._gains.append((self.time, f))
        ok = np.isfinite(f)
        self._online[ok] = f[ok]
        self.last_f = f
        self.time = t
        self.steps += 1
        if inn.dof:
            self.nis_sum += inn.nis
            self.dof_sum += inn.dof
        return inn.nis, inn.dof

    # --- forecast ---------------------------------------------------------------------
    def forecast(self) -> Forecast:
        """Day-ahead forecast from the current state (see the module docstring)."""
        if not self.started:
            raise ValueError("no forecast yet: the filter has not received a measurement")
        m = self.bundle.model
        t = self.time
        history = pd.DataFrame([f for _, f in self._gains], columns=self.bundle.zones,
                               index=pd.DatetimeIndex([s for s, _ in self._gains], tz="UTC"))
        f_ig = self._dayahead.issue(t, history).to_numpy()
        past = {s: row for s, row in self._inputs}
        current = past[t]
        ins = np.empty((HORIZON, self._nin))
        for h in range(HORIZON):
            ins[h] = current if h == 0 else past.get(t + h * STEP - pd.Timedelta("1D"), current)
        u, v = ins[:, :m.n_boxes], ins[:, m.n_boxes:]
        sim = m.simulate(self._filter.x, u, v, f_ig)
        P = self._filter.P
        var = np.empty((HORIZON, self._nz))
        for h in range(HORIZON):
            phi = m.step_matrices(u[h])[0]
            P = phi @ P @ phi.T + self._Q
            var[h] = np.einsum("ij,jk,ik->i", m.C, P, m.C)
        times = pd.date_range(t + STEP, periods=HORIZON, freq=STEP)
        return Forecast(t, times, sim.y[1:], np.sqrt(np.maximum(var, 0.0)), f_ig,
                        self.bundle.zones, self.bundle.version)

    # --- checkpoint --------------------------------------------------------------------
    def to_bytes(self) -> bytes:
        """Exact (bitwise) serialisation of the state: an .npz without pickles."""
        meta = {"time": None if self.time is None else self.time.isoformat(),
                "started": self.started, "steps": self.steps, "resets": self.resets,
                "nis_sum": self.nis_sum, "dof_sum": self.dof_sum,
                "gain_times": [s.isoformat() for s, _ in self._gains],
                "input_times": [s.isoformat() for s, _ in self._inputs],
                "version": self.bundle.version}
        arrays = {"pending": self._pending, "held": self._held, "online": self._online,
                  "last_y": self.last_y, "last_f": self.last_f,
                  "gains": np.array([f for _, f in self._gains]).reshape(-1, self._nz),
                  "inputs": np.array([r for _, r in self._inputs]).reshape(-1, self._nin)}
        if self.started:
            arrays["x"], arrays["P"] = self._filter.x, self._filter.P
        buf = io.BytesIO()
        np.savez(buf, meta=np.array(json.dumps(meta)), **arrays)
        return buf.getvalue()

    def load_bytes(self, data: bytes) -> None:
        """Restore a state written by :meth:`to_bytes` for the same model."""
        from zonecast.estimator.kalman import ZoneStateFilter

        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            arr = {k: z[k] for k in z.files if k != "meta"}
        self.reset()
        self.time = None if meta["time"] is None else pd.Timestamp(meta["time"])
        self.steps, self.resets = meta["steps"], meta["resets"]
        self.nis_sum, self.dof_sum = meta["nis_sum"], meta["dof_sum"]
        self._pending, self._held, self._online = arr["pending"], arr["held"], arr["online"]
        self.last_y, self.last_f = arr["last_y"], arr["last_f"]
        self._gains.extend((pd.Timestamp(s), f) for s, f in zip(meta["gain_times"], arr["gains"]))
        self._inputs.extend((pd.Timestamp(s), r)
                            for s, r in zip(meta["input_times"], arr["inputs"]))
        if meta["started"]:
            self._filter = ZoneStateFilter(arr["x"], arr["P"], self.bundle.model.C, self._Q,
                                           self._R)
