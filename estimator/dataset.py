"""Telemetry -> the paper's arrays: u(k), v(k), measured ȳ(k), on the model step.

``v = [Ta, Ts, solE, solS, solW, solN, solH]`` (paper section "Building Model", plus the
roofs' horizontal column): outdoor and supply air temperature [degC] and irradiance on
vertical facades facing east, south, west and north and on a horizontal plane [W/m2],
computed with pvlib from the weather station's GHI, DNI and DHI
(:func:`zonecast.estimator.solar.facade_columns`). Row k holds y(k), u(k), v(k)
(docs/data.md), so x(k+1) = f(x(k), u(k), v(k)) maps row k to row k+1.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from zonecast.estimator.constants import STEP
from zonecast.estimator.rc.network import DISTURBANCES, SOLAR_COLUMNS
from zonecast.estimator.schedules import CompactSchedule, local_day_minute
from zonecast.estimator.site import Site
from zonecast.estimator.solar import (
    FACADE_AZIMUTHS,
    SKY_DEPRESSION_ISO,
    clear_sky_temperature,
    cloudy_sky_temperature,
    facade_columns,
    sun_geometry,
)
from zonecast.estimator.telemetry import Telemetry, segments_of

__all__ = ["DISTURBANCES", "ModelData", "model_data", "scheduled_inputs", "scheduled_rise",
           "with_scheduled", "zone_weights"]



@dataclass
class ModelData:
    """Arrays of a telemetry span in the model's terms.

    Attributes
    ----------
    times : DatetimeIndex (UTC), the start of each step
    u : (N, n_boxes) box airflows [kg/s], site box order
    v : (N, 7) disturbances [degC, degC, W/m2 x 5] (:data:`DISTURBANCES`)
    y : (N, n_zones) measured zone temperatures [degC], NaN where no sensor reported
    zones, boxes : names in column order
    segments : contiguous row ranges [start, stop)
    excitation : (N,) True inside an experiment period of the site
    timezone : IANA name for local time
    reheat : (N, n_boxes) discharge-air temperature above the supply air [K], the rise
        reheat coils add (:meth:`~.telemetry.Telemetry.discharge_rise`); zero for boxes
        without a discharge-air point and where a box is shut. Default: zeros.
    power : (N, n_zones) metered electric power of each zone's lights and plug loads [W]
        (:meth:`~.telemetry.Telemetry.power`), NaN where not metered; None when the site
        has no meter.
    """

    times: pd.DatetimeIndex
    u: np.ndarray
    v: np.ndarray
    y: np.ndarray
    zones: list[str]
    boxes: list[str]
    segments: list[tuple[int, int]]
    excitation: np.ndarray
    timezone: str
    reheat: np.ndarray | None = None
    power: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.reheat is None:
            self.reheat = np.zeros_like(self.u, dtype=float)
        elif self.reheat.shape != self.u.shape:
            raise ValueError(f"reheat has shape {self.reheat.shape}; expected {self.u.shape} "
                             "(one discharge-air rise per box and step)")
        if self.power is not None and self.power.shape != self.y.shape:
            raise ValueError(f"power has shape {self.power.shape}; expected {self.y.shape} "
                             "(one metered power per zone and step)")

    def __len__(self) -> int:
        return len(self.times)

    def rows(self, sel) -> ModelData:
        """A sub-span by boolean mask or slice; segments are recomputed."""
        idx = np.arange(len(self))[sel]
        times = self.times[idx]
        step = (self.times[1] - self.times[0]) if len(self.times) > 1 else STEP
        return ModelData(times, self.u[idx], self.v[idx], self.y[idx], self.zones, self.boxes,
                         segments_of(times, step.to_pytimedelta()), self.excitation[idx],
                         self.timezone, self.reheat[idx],
                         None if self.power is None else self.power[idx])

    def local_times(self) -> pd.DatetimeIndex:
        return self.times.tz_convert(self.timezone)

    def missing_inputs(self) -> np.ndarray:
        """Rows whose u, v or discharge-air rise has a NaN: the model cannot be stepped
        over them."""
        return ~(np.isfinite(self.u).all(axis=1) & np.isfinite(self.v).all(axis=1)
                 & np.isfinite(self.reheat).all(axis=1))


def zone_weights(site: Site, room_volume: Mapping[str, float] | None) -> dict[str, np.ndarray] | None:
    """Weights of each zone's sensors: the air volume of the room a sensor sits in when the
    site names it and ``room_volume`` is given (matching C, which averages rooms by air
    volume), else equal weights."""
    if room_volume is None:
        return None
    vol = {k.upper(): float(v) for k, v in room_volume.items()}
    out = {}
    for zone, sensors in site.points.zone_temperature.items():
        if all(s.room is not None and s.room.upper() in vol for s in sensors):
            out[zone] = np.array([vol[s.room.upper()] for s in sensors])
    return out


def scheduled_inputs(scheduled: Mapping[str, Mapping], times, site: Site) -> np.ndarray:
    """(N, len(scheduled)) airflows [kg/s] of the model's scheduled inputs
    (:attr:`~.rc.network.RCStructure.scheduled`) over the intervals starting at ``times``:
    each one's flow, times its schedule's value in the site's local time where it has one
    (the thermostat's holidays as EnergyPlus ``Holiday`` days,
    :mod:`~zonecast.estimator.schedules`)."""
    idx = pd.DatetimeIndex(times)
    th = site.thermostat
    holidays = list(th.holidays) if th is not None else []
    out = np.empty((len(idx), len(scheduled)))
    cache: dict[str, np.ndarray] = {}
    for j, spec in enumerate(scheduled.values()):
        sched = spec.get("schedule")
        if sched is None:
            out[:, j] = float(spec["flow"])
            continue
        key = sched["name"]
        if key not in cache:
            cache[key] = _parsed(sched).values(idx, site.timezone, holidays)
        out[:, j] = float(spec["flow"]) * cache[key]
    return out


#: parsed schedules by the identity of their spec (a model's structure keeps its specs for
#: its life, so the runner's row-at-a-time conversion parses each once)
_PARSED: dict[int, tuple[Mapping, CompactSchedule]] = {}


def _parsed(sched: Mapping) -> CompactSchedule:
    hit = _PARSED.get(id(sched))
    if hit is None or hit[0] is not sched:
        if len(_PARSED) > 256:
            _PARSED.clear()
        hit = _PARSED[id(sched)] = (sched, CompactSchedule.from_dict(sched))
    return hit[1]


def scheduled_rise(scheduled: Mapping[str, Mapping], times, site: Site, ta: np.ndarray,
                   ts: np.ndarray, cloud: np.ndarray | None = None) -> np.ndarray:
    """(N, len(scheduled)) supply temperature of each scheduled input over the supply air
    T_s [K] (the discharge-air rise the model adds to T_s): the outdoor air T_a for an
    infiltration (``"supply": "Ta"``), the month's ground temperature in the site's local
    time for a ground contact (``"supply": "ground"``), the clear-sky temperature of the
    outdoor air for a face's long-wave exchange with the sky (``"supply": "sky"``,
    :func:`~zonecast.estimator.solar.clear_sky_temperature`), the sky's temperature under
    the measured ``cloud`` cover [-] (``"sky": "cloud"``,
    :func:`~zonecast.estimator.solar.cloudy_sky_temperature`; a row without a reading is
    taken as clear), or the outdoor air less
    :data:`~zonecast.estimator.solar.SKY_DEPRESSION_ISO` (``"sky": "iso"``)."""
    ta, ts = np.asarray(ta, float), np.asarray(ts, float)
    out = np.empty((len(ts), len(scheduled)))
    month = None
    for j, spec in enumerate(scheduled.values()):
        if spec["supply"] == "Ta":
            out[:, j] = ta - ts
        elif spec["supply"] == "ground":
            if month is None:
                days = local_day_minute(times, site.timezone)[0]
                month = (np.datetime64("1970-01-01", "D") + days).astype("datetime64[M]")
                month = month.astype(np.int64) % 12
            out[:, j] = np.asarray(spec["monthly"], float)[month] - ts
        elif spec["supply"] == "sky" and spec.get("sky", "clear") == "iso":
            out[:, j] = ta - SKY_DEPRESSION_ISO - ts
        elif spec["supply"] == "sky" and spec.get("sky") == "cloud":
            c = np.full(len(ts), np.nan) if cloud is None else np.asarray(cloud, float)
            out[:, j] = cloudy_sky_temperature(ta, c) - ts
        elif spec["supply"] == "sky":
            out[:, j] = clear_sky_temperature(ta) - ts
        else:
            raise ValueError(f"scheduled input supply {spec['supply']!r}: expected 'Ta', "
                             "'ground' or 'sky'")
    return out


def with_scheduled(scheduled: Mapping[str, Mapping], times, site: Site, u: np.ndarray,
                   v: np.ndarray, rise: np.ndarray, cloud: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """u and the discharge-air rise with the scheduled inputs' columns appended: their
    airflows (:func:`scheduled_inputs`) and their supply over the supply air
    (:func:`scheduled_rise`; ``cloud`` the cloud cover [-] of the rows, None: none)."""
    if not scheduled:
        return u, rise
    flows = scheduled_inputs(scheduled, times, site)
    sup = scheduled_rise(scheduled, times, site, v[:, 0], v[:, 1], cloud)
    return np.hstack([u, flows]), np.hstack([rise, sup])


def model_data(tel: Telemetry, room_volume: Mapping[str, float] | None = None, *,
               sky_model: str = "perez", albedo: float = 0.2,
               facade_azimuths: Sequence[float] = FACADE_AZIMUTHS,
               scheduled: Mapping[str, Mapping] | None = None,
               shading=None, panes: int = 0) -> ModelData:
    """Build :class:`ModelData` from validated telemetry.

    Parameters
    ----------
    tel : validated telemetry
    room_volume : room (EnergyPlus zone) -> air volume [m3], to weight several sensors of a
        zone like the model's output matrix C; default equal weights.
    sky_model, albedo : passed to the facade irradiance model.
    facade_azimuths : the four facades [deg] of v's solar columns (the model's
        :attr:`~.rc.network.RCStructure.facade_azimuths`; default E, S, W, N).
    scheduled : the model's scheduled inputs (:attr:`~.rc.network.RCStructure.scheduled`),
        appended after the site's boxes to u and the rise (:func:`with_scheduled`).
    shading : the model's shaded windows (:attr:`~.rc.network.RCStructure.facade_shading`),
        applied to the solar columns (:func:`~zonecast.estimator.solar.facade_columns`).
    panes : the windows' panes whose angular transmission weighs the facade columns
        (:attr:`~.rc.network.RCStructure.window_panes`; 0: none).
    """
    site = tel.site
    w = tel.weather()
    sol = np.full((len(w), len(SOLAR_COLUMNS)), np.nan)
    ok = w[["ghi", "dni", "dhi"]].notna().all(axis=1).to_numpy()
    if ok.any():
        loc = site.location
        geom = sun_geometry(w.index[ok], pd.Timedelta(site.step), loc.latitude, loc.longitude,
                            loc.elevation)
        sol[ok] = facade_columns(geom, w.ghi.to_numpy()[ok], w.dni.to_numpy()[ok],
                                 w.dhi.to_numpy()[ok], facade_azimuths, shading=shading,
                                 albedo=albedo, sky_model=sky_model, panes=panes)
    v = np.column_stack([w.Ta.to_numpy(), w.Ts.to_numpy(), sol])
    exc = np.zeros(len(w), dtype=bool)
    for e in site.experiments:
        exc |= (w.index >= e.start) & (w.index < e.end)
    u = tel.airflow()
    rise = tel.discharge_rise()
    rise[(u == 0) & ~np.isfinite(rise)] = 0.0  # a shut box delivers no heat
    scheduled = scheduled or {}
    u, rise = with_scheduled(scheduled, tel.times, site, u, v, rise, w.cloud.to_numpy())
    return ModelData(tel.times, u, v, tel.zone_temperature(zone_weights(site, room_volume)),
                     list(site.zones), list(site.boxes) + list(scheduled), list(tel.segments),
                     exc, site.timezone, rise, tel.power())
