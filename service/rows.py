"""Per-row telemetry conversion for the online runner, without pandas.

:func:`zonecast.service.online.rows_from_frame` builds the model's arrays through the
estimator's :class:`~zonecast.estimator.telemetry.Telemetry` and
:func:`~zonecast.estimator.dataset.model_data`: right for a file, but about 10 ms of
pandas and pvlib fixed costs for the one row a runner step needs. :class:`RowConverter`
gives the same numbers (tested against ``rows_from_frame`` on every row of three
virtual-building weeks) from a plain array of readings in their wire units:

- unit conversion with :func:`~zonecast.estimator.units.to_si`, per group of points of
  one unit;
- zone temperatures as the same weighted mean over the sensors that reported
  (:func:`~zonecast.estimator.dataset.zone_weights`);
- facade irradiance: the sun's position is still computed by pvlib
  (:func:`pvlib.solarposition.get_solarposition` at the start, midpoint and end of each
  interval, :func:`pvlib.irradiance.get_extra_radiation` at the midpoint), but for a
  whole day of grid times at once and cached (:class:`SolarGeometryCache`); the
  transposition onto the four facades is one :func:`pvlib.irradiance.get_total_irradiance`
  call for all four planes, with the rules of :mod:`zonecast.estimator.solar` (negative
  readings as 0, no beam from below the horizon, isotropic sky diffuse when the sun is
  below the horizon at the midpoint, no sky diffuse without diffuse light, exactly 0 for
  a night interval, NaN where GHI, DNI or DHI is missing).
"""

from __future__ import annotations

from collections import OrderedDict
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pvlib

from zonecast.service.modelfile import ModelBundle

__all__ = ["RowConverter", "SolarGeometryCache"]

_DAY_NS = 86_400 * 10**9


class SolarGeometryCache:
    """Sun geometry of the site's intervals, computed by pvlib a UTC day at a time.

    For interval start t (on the site's step grid, ``label="start"`` as the estimator's
    :func:`~zonecast.estimator.solar.facade_irradiance` uses it): apparent zenith at t,
    at t + step/2 and at t + step, azimuth and extraterrestrial normal irradiance at
    t + step/2. Times off the grid are computed directly (not cached).

    Parameters
    ----------
    latitude, longitude, elevation : float
        Site location [deg north, deg east, m].
    step : timedelta
        Interval length (divides a day).
    max_days : int
        Days kept in the cache (oldest dropped first).
    """

    def __init__(self, latitude: float, longitude: float, elevation: float, step,
                 max_days: int = 4):
        self.latitude, self.longitude, self.elevation = latitude, longitude, elevation
        self.step = pd.Timedelta(step)
        self._step_ns = self.step.value
        if self._step_ns <= 0 or _DAY_NS % self._step_ns:
            raise ValueError(f"step {step} must divide a day")
        self._per_day = _DAY_NS // self._step_ns
        self.max_days = max_days
        self._days: OrderedDict[int, np.ndarray] = OrderedDict()
        self.computed_days = 0

    def _compute(self, starts: pd.DatetimeIndex) -> np.ndarray:
        """(5, N): zenith at start, midpoint, end; azimuth and dni_extra at the midpoint."""
        n = len(starts)
        mid = starts + self.step / 2
        end = starts + self.step
        sp = pvlib.solarposition.get_solarposition(
            starts.append(mid).append(end), self.latitude, self.longitude,
            altitude=self.elevation, pressure=pvlib.atmosphere.alt2pres(self.elevation))
        zen = sp["apparent_zenith"].to_numpy()
        out = np.empty((5, n))
        out[0], out[1], out[2] = zen[:n], zen[n:2 * n], zen[2 * n:]
        out[3] = sp["azimuth"].to_numpy()[n:2 * n]
        out[4] = np.asarray(pvlib.irradiance.get_extra_radiation(mid), dtype=float)
        return out

    def _day(self, day: int) -> np.ndarray:
        hit = self._days.get(day)
        if hit is None:
            starts = pd.DatetimeIndex(day * _DAY_NS + self._step_ns * np.arange(self._per_day),
                                      tz="UTC")
            hit = self._compute(starts)
            self.computed_days += 1
            self._days[day] = hit
            while len(self._days) > self.max_days:
                self._days.popitem(last=False)
        else:
            self._days.move_to_end(day)
        return hit

    def geometry(self, times_ns: np.ndarray) -> np.ndarray:
        """(5, N) geometry (rows as :meth:`_compute`) of interval starts given as UTC
        nanoseconds since the epoch."""
        times_ns = np.asarray(times_ns, dtype=np.int64)
        if np.any(times_ns % self._step_ns):
            return self._compute(pd.DatetimeIndex(times_ns, tz="UTC"))
        if len(times_ns) == 1:  # the runner's case
            day, off = divmod(int(times_ns[0]), _DAY_NS)
            return self._day(day)[:, off // self._step_ns:off // self._step_ns + 1]
        out = np.empty((5, len(times_ns)))
        days = times_ns // _DAY_NS
        for day in np.unique(days):
            sel = days == day
            out[:, sel] = self._day(int(day))[:, (times_ns[sel] - day * _DAY_NS) // self._step_ns]
        return out


class RowConverter:
    """Readings of a site's points in their wire units -> the model's u, v, y.

    Parameters
    ----------
    bundle : ModelBundle
    albedo, sky_model : as :func:`zonecast.estimator.dataset.model_data` (its defaults).
    """

    def __init__(self, bundle: ModelBundle, *, albedo: float = 0.2, sky_model: str = "perez"):
        from zonecast.estimator.dataset import zone_weights
        from zonecast.estimator.solar import FACADE_AZIMUTHS, SKY_MODELS

        if sky_model not in SKY_MODELS:
            raise ValueError(f"sky_model must be one of {SKY_MODELS}, got {sky_model!r}")
        site = bundle.site
        self.units = site.point_units()
        self.points = list(self.units)
        col = {p: i for i, p in enumerate(self.points)}
        by_unit: dict[str, list[int]] = {}
        for p, unit in self.units.items():
            by_unit.setdefault(unit, []).append(col[p])
        self._groups = [(unit, np.array(idx)) for unit, idx in by_unit.items()]
        self._box = np.array([col[b.airflow.point] for b in site.boxes.values()], dtype=int)
        pts = site.points
        self._ta = col[pts.outdoor_air_temperature.point]
        self._ts = col[pts.supply_air_temperature.point]
        self._sun = np.array([col[pts.solar.global_horizontal.point],
                              col[pts.solar.direct_normal.point],
                              col[pts.solar.diffuse_horizontal.point]])
        weights = zone_weights(SimpleNamespace(site=site), bundle.room_volume)
        self._zones = []
        for zone in site.zones:
            idx = np.array([col[s.point] for s in pts.zone_temperature[zone]], dtype=int)
            w = (np.ones(len(idx)) if weights is None or zone not in weights
                 else np.asarray(weights[zone], float))
            self._zones.append((idx, w))
        loc = site.location
        self.solar = SolarGeometryCache(loc.latitude, loc.longitude, loc.elevation, site.step)
        self._azimuths = np.asarray(FACADE_AZIMUTHS, dtype=float)
        self.albedo, self.sky_model = float(albedo), sky_model

    def convert(self, times_ns, values) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rows of readings -> (u, v, y).

        Parameters
        ----------
        times_ns : array (N,) of int
            Row times as UTC nanoseconds since the epoch (interval starts).
        values : array (N, n_points)
            Readings in the units of the site's point map, columns in the order of
            :attr:`points`; NaN = missing.

        Returns
        -------
        u (N, n_boxes) [kg/s], v (N, 6) [degC, degC, W/m2 x 4], y (N, n_zones) [degC]
        """
        from zonecast.estimator.units import to_si

        raw = np.asarray(values, dtype=float)
        if raw.ndim != 2 or raw.shape[1] != len(self.points):
            raise ValueError(f"values must have shape (N, {len(self.points)})")
        si = np.empty_like(raw)
        for unit, idx in self._groups:
            si[:, idx] = to_si(raw[:, idx], unit)
        n = len(si)
        sol = np.full((n, 4), np.nan)
        sun = si[:, self._sun]
        ok = np.isfinite(sun).all(axis=1)
        if ok.any():
            sol[ok] = self._facades(np.asarray(times_ns, dtype=np.int64)[ok], sun[ok])
        v = np.column_stack([si[:, self._ta], si[:, self._ts], sol])
        y = np.full((n, len(self._zones)), np.nan)
        for j, (idx, w) in enumerate(self._zones):
            vals = si[:, idx]
            good = np.isfinite(vals)
            wsum = (good * w).sum(axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                y[:, j] = np.where(wsum > 0, np.nansum(vals * w, axis=1) / wsum, np.nan)
        return si[:, self._box], v, y

    def _facades(self, times_ns: np.ndarray, sun: np.ndarray) -> np.ndarray:
        """Facade irradiance (N, 4) [W/m2] of rows with finite GHI, DNI, DHI."""
        zen_start, zenith, zen_end, azimuth, dni_extra = self.solar.geometry(times_ns)
        clean = np.clip(sun, 0.0, None)
        ghi, dni, dhi = clean[:, 0], clean[:, 1], clean[:, 2]
        sun_down = zenith >= 90.0
        night = (zen_start >= 90.0) & sun_down & (zen_end >= 90.0)
        out = np.zeros((len(times_ns), 4))  # a night interval is exactly 0
        day = ~night
        if not day.any():
            return out
        k = len(self._azimuths)

        def rep(a):  # one entry per (row, facade), facades fastest
            return np.repeat(a[day], k)

        az = np.tile(self._azimuths, int(day.sum()))
        down = rep(sun_down)
        args = (90.0, az, rep(zenith), rep(azimuth), np.where(down, 0.0, rep(dni)), rep(ghi),
                rep(dhi))

        def total(model):
            return pvlib.irradiance.get_total_irradiance(
                *args, dni_extra=rep(dni_extra), albedo=self.albedo, model=model)

        poa = total(self.sky_model)
        sky = np.asarray(poa["poa_sky_diffuse"], dtype=float)
        if self.sky_model != "isotropic" and down.any():
            iso = np.asarray(total("isotropic")["poa_sky_diffuse"], dtype=float)
            sky = np.where(down, iso, sky)
        sky = np.where(rep(dhi) <= 0.0, 0.0, sky)
        direct = np.clip(np.asarray(poa["poa_direct"], dtype=float), 0.0, None)
        sky = np.clip(sky, 0.0, None)
        ground = np.clip(np.asarray(poa["poa_ground_diffuse"], dtype=float), 0.0, None)
        out[day] = (direct + sky + ground).reshape(-1, k)
        return out
