"""Facade irradiance from weather-station data, computed with pvlib.

The building-hull heat-flux model (paper eq:q_bh) needs the solar irradiance on
the building's facades, ordered as the paper's disturbance vector
``v = [v_Ta, v_Ts, v_solE, v_solS, v_solW, v_solN]`` (paper eq:model_dt).
This module transposes weather-station irradiance (GHI, DNI, DHI) onto tilted
surfaces with :func:`pvlib.irradiance.get_total_irradiance`; no solar geometry
is written here. :func:`transpose` is the one implementation of the rules below, used by the
offline data path (:func:`facade_irradiance`) and the online runner's per-row conversion
(sun geometry cached a day at a time, :class:`SolarGeometryCache`).

Time convention
---------------
Telemetry rows mark the *start* of an interval and carry averages over
``[t, t + interval)``. The sun position used for a row is therefore computed
at the interval midpoint ``t + interval / 2`` (``label="start"``, the default).
Other labels are accepted for data sources that stamp the end or the centre of
the interval.

Night, negative and missing values
----------------------------------
* Negative station readings (thermopile offsets at night) are treated as 0.
* An interval during which the sun is below the horizon at its start, midpoint
  and end is *night*: the result is exactly 0 whatever the station reports.
* If the sun is below the horizon at the midpoint but not for the whole
  interval (sunrise/sunset), no beam reaches the facade and the sky diffuse
  part falls back to the isotropic model (the anisotropic models need the sun
  above the horizon).
* NaN in any of GHI, DNI, DHI gives NaN out for that row (also at night): gaps
  are never filled silently.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from typing import Literal

import numpy as np
import pandas as pd
import pvlib
from zonecast.estimator.shading import sun_vectors

__all__ = [
    "FACADE_AZIMUTHS",
    "SKY_DEPRESSION_ISO",
    "SKY_MODELS",
    "SolarGeometryCache",
    "SolarInputError",
    "clear_sky_temperature",
    "cloud_of_sky_temperature",
    "cloudy_sky_temperature",
    "facade_irradiance",
    "plane_of_array_irradiance",
    "sun_geometry",
    "surface_irradiance",
    "transpose",
]

#: Azimuths [deg, clockwise from north] of the paper's facade order E, S, W, N.
FACADE_AZIMUTHS: tuple[float, float, float, float] = (90.0, 180.0, 270.0, 0.0)

#: (tilt, azimuth) [deg] of the horizontal plane of the roofs' column ``solH``.
HORIZONTAL: tuple[float, float] = (0.0, 180.0)

#: Sky diffuse models accepted (pvlib names); see docs/numerics.md for the choice.
SKY_MODELS = ("perez", "haydavies", "isotropic", "klucher", "reindl")

Label = Literal["start", "center", "end"]


class SolarInputError(ValueError):
    """Invalid input to the facade-irradiance functions."""


class SolarTimeError(TypeError):
    """Times are not a tz-aware DatetimeIndex."""


def _as_times(times) -> pd.DatetimeIndex:
    idx = pd.DatetimeIndex(times) if not isinstance(times, pd.DatetimeIndex) else times
    if idx.tz is None:
        raise SolarTimeError(
            "times must be tz-aware (e.g. times.tz_localize('UTC') or pass ISO-8601 "
            "strings with an offset); naive times are ambiguous"
        )
    return idx


def _as_column(name: str, values, n: int) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise SolarInputError(
            f"{name} must be a 1-D array with one value per time ({n}), got shape {arr.shape}"
        )
    return arr


def _midpoints(idx: pd.DatetimeIndex, interval: pd.Timedelta, label: Label):
    """Return (start, midpoint, end) of each averaging interval."""
    if label == "start":
        start = idx
    elif label == "end":
        start = idx - interval
    elif label == "center":
        start = idx - interval / 2
    else:
        raise SolarInputError(f"label must be 'start', 'center' or 'end', got {label!r}")
    return start, start + interval / 2, start + interval


_DAY_NS = 86_400 * 10**9


def sun_geometry(starts: pd.DatetimeIndex, step: pd.Timedelta, latitude: float,
                 longitude: float, elevation: float = 0.0) -> np.ndarray:
    """Sun geometry of intervals ``[start, start + step)`` from pvlib.

    Parameters
    ----------
    starts : pandas.DatetimeIndex
        Interval starts (tz-aware).
    step : pandas.Timedelta
        Interval length.
    latitude, longitude, elevation : float
        Site location [deg north, deg east, m].

    Returns
    -------
    ndarray, shape (5, N)
        Apparent zenith at the start, midpoint and end [deg]; azimuth [deg] and
        extraterrestrial normal irradiance [W/m²] at the midpoint.
    """
    n = len(starts)
    mid = starts + step / 2
    end = starts + step
    sp = pvlib.solarposition.get_solarposition(
        starts.append(mid).append(end), latitude, longitude, altitude=elevation,
        pressure=pvlib.atmosphere.alt2pres(elevation))
    zen = sp["apparent_zenith"].to_numpy()
    out = np.empty((5, n))
    out[0], out[1], out[2] = zen[:n], zen[n:2 * n], zen[2 * n:]
    out[3] = sp["azimuth"].to_numpy()[n:2 * n]
    out[4] = np.asarray(pvlib.irradiance.get_extra_radiation(mid), dtype=float)
    return out


class SolarGeometryCache:
    """:func:`sun_geometry` of a site's grid intervals, computed a UTC day at a time.

    The online runner converts one row per step; pvlib's fixed cost per call (about
    10 ms with pandas) is paid once a day instead. Times off the grid are computed
    directly (not cached).

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
        return sun_geometry(starts, self.step, self.latitude, self.longitude, self.elevation)

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
        """(5, N) geometry (rows as :func:`sun_geometry`) of interval starts given as UTC
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


#: Average difference [K] between the outdoor air and the apparent sky temperature for
#: intermediate climates, ISO 13790:2008 sec. 11.4.6 (also ISO 52016-1): 11 K. The TMY3
#: files of the building family's five climates give 9.5-11.7 K (their horizontal
#: infrared, from which EnergyPlus takes its sky; docs/model.md "Sky").
SKY_DEPRESSION_ISO = 11.0


def _swinbank_emissivity(tk: np.ndarray) -> np.ndarray:
    """Swinbank's clear-sky emissivity 9.365e-6 T_a^2 [-] of air at ``tk`` [K]."""
    return 9.365e-6 * tk * tk


def clear_sky_temperature(ta):
    """Clear-sky temperature [degC] for outdoor air at ``ta`` [degC]: Swinbank's sky
    emissivity eps = 9.365e-6 T_a^2 (T_a in K; Q. J. R. Meteorol. Soc. 89, 1963), the one
    clear-sky model that needs the air temperature alone, and T_sky = eps^(1/4) T_a (about
    20 K below the air at 10 degC, 11 K at 30 degC). Clouds, which warm the sky, are not
    seen by a station without long-wave or cloud readings.

    Parameters
    ----------
    ta : array_like
        Outdoor air temperature [degC]; NaN gives NaN.
    """
    tk = np.asarray(ta, dtype=float) + 273.15
    return np.sqrt(np.sqrt(_swinbank_emissivity(tk))) * tk - 273.15


def cloudy_sky_temperature(ta, cloud):
    """Sky temperature [degC] under a cloud cover: Crawford and Duchon's emissivity
    eps = c + (1 - c) eps_clear (J. Appl. Meteorol. 38, 1999: cloud radiates as a black
    body at the air temperature) with Swinbank's clear-sky eps_clear
    (:func:`clear_sky_temperature`), and T_sky = eps^(1/4) T_a. An overcast sky is at the
    air temperature; a clear one as :func:`clear_sky_temperature`.

    Parameters
    ----------
    ta : array_like
        Outdoor air temperature [degC]; NaN gives NaN.
    cloud : array_like
        Opaque cloud cover c [-], clipped to [0, 1]; NaN (no reading) is taken as a clear
        sky, the sky of :func:`clear_sky_temperature`.
    """
    tk = np.asarray(ta, dtype=float) + 273.15
    c = np.clip(np.nan_to_num(np.asarray(cloud, dtype=float), nan=0.0), 0.0, 1.0)
    eps = c + (1.0 - c) * _swinbank_emissivity(tk)
    return np.sqrt(np.sqrt(eps)) * tk - 273.15


def cloud_of_sky_temperature(ta, t_sky):
    """The cloud cover c [-] whose :func:`cloudy_sky_temperature` at air ``ta`` [degC] is
    ``t_sky`` [degC] (its inverse, clipped to [0, 1]; NaN where either is NaN)."""
    tk = np.asarray(ta, dtype=float) + 273.15
    clear = _swinbank_emissivity(tk)
    eps = ((np.asarray(t_sky, dtype=float) + 273.15) / tk) ** 4
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.clip((eps - clear) / (1.0 - clear), 0.0, 1.0)


def _check_options(albedo: float, sky_model: str) -> None:
    if sky_model not in SKY_MODELS:
        raise SolarInputError(f"sky_model must be one of {SKY_MODELS}, got {sky_model!r}")
    if not 0.0 <= albedo <= 1.0:
        raise SolarInputError(f"albedo must be in [0, 1], got {albedo}")


def transpose(geometry: np.ndarray, ghi, dni, dhi, surfaces, *, albedo: float = 0.2,
              sky_model: str = "perez", total: bool = False) -> dict[str, np.ndarray]:
    """Station irradiance onto planes, with the module's rules for night, negative and
    missing readings. The one implementation behind every function of this module and
    the online runner's per-row conversion.

    Parameters
    ----------
    geometry : ndarray, shape (5, N)
        From :func:`sun_geometry` (or :class:`SolarGeometryCache`).
    ghi, dni, dhi : ndarray, shape (N,)
        Station irradiance averaged over each interval [W/m²]; NaN = missing.
    surfaces : sequence of (tilt, azimuth), or ndarray (k, 2)
        Planes [deg; tilt from horizontal, azimuth clockwise from north].
    albedo : float
        Ground reflectance [-].
    sky_model : str
        One of :data:`SKY_MODELS`.
    total : bool
        Return only ``poa_global``, the sum of the three components (cheaper).

    Returns
    -------
    dict
        ``poa_direct``, ``poa_sky_diffuse``, ``poa_ground_diffuse`` (or only
        ``poa_global`` with ``total``) [W/m²], each of shape (N, len(surfaces)): >= 0,
        exactly 0 for a night interval, NaN where GHI, DNI or DHI is missing.
    """
    _check_options(albedo, sky_model)
    planes = np.asarray(surfaces, dtype=float).reshape(-1, 2)
    if np.any((planes[:, 0] < 0.0) | (planes[:, 0] > 180.0)):
        raise SolarInputError(f"surface_tilt must be in [0, 180] deg, got "
                              f"{planes[:, 0].tolist()}")
    zen_start, zenith, zen_end, azimuth, dni_extra = geometry
    ghi, dni, dhi = (np.asarray(a, dtype=float) for a in (ghi, dni, dhi))
    n, k = len(ghi), len(planes)
    missing = ~(np.isfinite(ghi) & np.isfinite(dni) & np.isfinite(dhi))
    sun_down = zenith >= 90.0
    day = ~((zen_start >= 90.0) & sun_down & (zen_end >= 90.0)) & ~missing
    names = ("poa_global",) if total else ("poa_direct", "poa_sky_diffuse",
                                           "poa_ground_diffuse")
    out = {c: np.zeros((n, k)) for c in names}  # a night interval is exactly 0
    if day.any():
        m = int(day.sum())

        def rep(a):  # one entry per (row, plane), planes fastest
            return np.repeat(a[day], k)

        down = rep(sun_down)
        g, b, d = (rep(np.maximum(a, 0.0)) for a in (ghi, dni, dhi))  # negative readings: 0
        args = (np.tile(planes[:, 0], m), np.tile(planes[:, 1], m), rep(zenith), rep(azimuth),
                np.where(down, 0.0, b), g, d)  # no beam from below the horizon

        def poa(model):
            return pvlib.irradiance.get_total_irradiance(
                *args, dni_extra=rep(dni_extra), albedo=albedo, model=model)

        res = poa(sky_model)
        sky = np.asarray(res["poa_sky_diffuse"], dtype=float)
        if sky_model != "isotropic" and down.any():
            sky = np.where(down, np.asarray(poa("isotropic")["poa_sky_diffuse"], dtype=float),
                           sky)
        # no diffuse light -> no sky diffuse on any plane (Perez divides 0 by 0 there)
        parts = {"poa_direct": np.clip(np.asarray(res["poa_direct"], dtype=float), 0.0, None),
                 "poa_sky_diffuse": np.clip(np.where(d <= 0.0, 0.0, sky), 0.0, None),
                 "poa_ground_diffuse": np.clip(np.asarray(res["poa_ground_diffuse"],
                                                          dtype=float), 0.0, None)}
        if total:
            parts = {"poa_global": parts["poa_direct"] + parts["poa_sky_diffuse"]
                     + parts["poa_ground_diffuse"]}
        for name, comp in parts.items():
            out[name][day] = comp.reshape(m, k)
    if missing.any():
        for comp in out.values():
            comp[missing] = np.nan
    return out


def _perez_shares(geometry: np.ndarray, dni: np.ndarray, dhi: np.ndarray,
                  planes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Circumsolar and horizon shares [-] of Perez's sky diffuse on each plane, shape
    (N, k); 0 where the sky is dark or the sun is down (isotropic there, as in
    :func:`transpose`)."""
    _, zenith, _, azimuth, dni_extra = geometry
    n, k = len(dni), len(planes)
    circ, hor = np.zeros((n, k)), np.zeros((n, k))
    ok = (zenith < 90.0) & np.isfinite(dni) & np.isfinite(dhi) & (dhi > 0.0)
    if not ok.any():
        return circ, hor
    m = int(ok.sum())

    def rep(a):
        return np.repeat(a[ok], k)

    zen = rep(zenith)
    parts = pvlib.irradiance.perez(
        np.tile(planes[:, 0], m), np.tile(planes[:, 1], m), rep(np.maximum(dhi, 0.0)),
        rep(np.maximum(dni, 0.0)), rep(dni_extra), zen, rep(azimuth),
        pvlib.atmosphere.get_relative_airmass(zen), return_components=True)
    total = np.asarray(parts["poa_sky_diffuse"], dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        for out, key in ((circ, "poa_circumsolar"), (hor, "poa_horizon")):
            share = np.where(total > 0.0, np.asarray(parts[key], dtype=float) / total, 0.0)
            out[ok] = np.nan_to_num(share).reshape(m, k)
    return circ, hor


def window_transmission(aoi, panes: int) -> np.ndarray:
    """Transmission of ``panes`` clear glass panes at angle of incidence ``aoi`` [deg],
    relative to normal incidence [-].

    Each pane is two air-glass interfaces (Fresnel reflection) with absorption in the glass:
    pvlib's ``iam.physical`` (one interface and the absorption of a cover glass) squared per
    pane. For one clear pane this gives 0.90 at 60 deg, 0.74 at 70 deg and 0.40 at 80 deg,
    ASHRAE's angular data for 3 mm clear glass 0.90, 0.74 and 0.45 (Handbook of
    Fundamentals, ch. 15); 0 at grazing incidence.
    """
    return np.asarray(pvlib.iam.physical(np.asarray(aoi, dtype=float)), dtype=float) \
        ** (2 * int(panes))


def _diffuse_transmission(panes: int) -> dict[str, float]:
    """Hemispherical averages of :func:`window_transmission` on a vertical window for the
    isotropic sky, the horizon band and the ground (Marion's integration, pvlib's
    ``iam.marion_integrate``); cached per number of panes."""
    if panes not in _DIFFUSE_TRANSMISSION:
        _DIFFUSE_TRANSMISSION[panes] = {
            region: float(np.asarray(pvlib.iam.marion_integrate(
                lambda aoi: window_transmission(aoi, panes), 90.0, region)))
            for region in ("sky", "horizon", "ground")}
    return _DIFFUSE_TRANSMISSION[panes]


_DIFFUSE_TRANSMISSION: dict[int, dict[str, float]] = {}


def facade_columns(geometry: np.ndarray, ghi, dni, dhi, azimuths: Sequence[float], *,
                   shading=None, albedo: float = 0.2, sky_model: str = "perez",
                   sunlit: np.ndarray | None = None, panes: int = 0) -> np.ndarray:
    """The model's five solar columns (:data:`~.rc.network.SOLAR_COLUMNS`): global
    irradiance on vertical facades facing ``azimuths``, shaded where a facade's windows are,
    then on a horizontal plane (roofs; never shaded).

    Parameters
    ----------
    geometry, ghi, dni, dhi, albedo, sky_model
        As in :func:`transpose`.
    azimuths : four azimuths [deg]
        The facades (:attr:`~.rc.network.RCStructure.facade_azimuths`).
    shading : :class:`~zonecast.estimator.shading.FacadeShading` or None
        The building's shaded windows (:attr:`~.rc.network.RCStructure.facade_shading`):
        each column loses what the shading takes off its windows
        (:meth:`~zonecast.estimator.shading.FacadeShading.loss`; beam and circumsolar by
        the sunlit fraction, isotropic and horizon sky by the diffuse ratios). None: the
        unshaded facades, exactly :func:`transpose` with ``total=True``.
    sunlit : ndarray (N, windows), optional
        The shaded windows' sunlit fractions when already known
        (:meth:`~zonecast.estimator.shading.FacadeShading.sunlit`).
    panes : int
        0 (default): the global irradiance. Otherwise the facade columns weigh each part by
        what ``panes`` glass panes let through at its angle, relative to normal incidence
        (:func:`window_transmission`; beam and circumsolar at the sun's angle of incidence,
        sky, horizon and ground by :func:`_diffuse_transmission`):
        ``ModelOptions.window_angle``. The horizontal column (roofs) is never weighed.

    Returns
    -------
    ndarray, shape (N, 5) [W/m²]; NaN where an input is missing.
    """
    planes = np.array([(90.0, float(a)) for a in azimuths] + [HORIZONTAL])
    if not shading and not panes:
        return transpose(geometry, ghi, dni, dhi, planes, albedo=albedo, sky_model=sky_model,
                         total=True)["poa_global"]
    comp = transpose(geometry, ghi, dni, dhi, planes, albedo=albedo, sky_model=sky_model)
    sky = comp["poa_sky_diffuse"]
    if sky_model == "perez":
        circ_share, hor_share = _perez_shares(geometry, np.asarray(dni, dtype=float),
                                              np.asarray(dhi, dtype=float), planes)
    else:
        circ_share = hor_share = np.zeros_like(sky)
    circ, hor = sky * circ_share, sky * hor_share
    iso = sky - circ - hor
    direct = comp["poa_direct"]
    total = comp["poa_direct"] + comp["poa_sky_diffuse"] + comp["poa_ground_diffuse"]
    if panes:
        aoi = pvlib.irradiance.aoi(planes[None, :, 0], planes[None, :, 1],
                                   geometry[1][:, None], geometry[3][:, None])
        tau = np.where(aoi < 90.0, window_transmission(np.minimum(aoi, 90.0), panes), 0.0)
        dif = _diffuse_transmission(panes)
        glass = np.ones(len(planes), dtype=bool)
        glass[-1] = False  # the roofs' horizontal column: opaque, not weighed
        direct = np.where(glass, direct * tau, direct)
        circ = np.where(glass, circ * tau, circ)
        iso = np.where(glass, iso * dif["sky"], iso)
        hor = np.where(glass, hor * dif["horizon"], hor)
        ground = np.where(glass, comp["poa_ground_diffuse"] * dif["ground"],
                          comp["poa_ground_diffuse"])
        total = np.where(glass, direct + iso + circ + hor + ground, total)
    if not shading:
        return np.clip(total, 0.0, None)
    loss = shading.loss(sun_vectors(geometry[1], geometry[3]), np.nan_to_num(direct),
                        np.nan_to_num(iso), np.nan_to_num(circ), np.nan_to_num(hor),
                        sunlit=sunlit)
    return np.clip(total - loss, 0.0, None)


def _inputs(times, ghi, dni, dhi, latitude, longitude, elevation, interval, label):
    """Validated columns and the sun geometry of each row's interval."""
    idx = _as_times(times)
    n = len(idx)
    cols = [_as_column(name, a, n) for name, a in (("ghi", ghi), ("dni", dni), ("dhi", dhi))]
    if not (-90.0 <= latitude <= 90.0 and -180.0 <= longitude <= 360.0):
        raise SolarInputError(
            f"latitude must be in [-90, 90] and longitude in [-180, 360] deg, "
            f"got ({latitude}, {longitude})"
        )
    step = pd.Timedelta(interval)
    if step <= pd.Timedelta(0):
        raise SolarInputError(f"interval must be positive, got {interval!r}")
    start, _, _ = _midpoints(idx, step, label)
    return idx, cols, sun_geometry(start, step, latitude, longitude, elevation)


def plane_of_array_irradiance(
    times,
    ghi,
    dni,
    dhi,
    latitude: float,
    longitude: float,
    elevation: float = 0.0,
    *,
    surface_tilt: float = 90.0,
    surface_azimuth: float = 180.0,
    albedo: float = 0.2,
    sky_model: str = "perez",
    interval: str | pd.Timedelta = "15min",
    label: Label = "start",
) -> pd.DataFrame:
    """Irradiance components on one plane, per telemetry interval.

    Parameters
    ----------
    times : pandas.DatetimeIndex or sequence of tz-aware timestamps
        Interval labels (tz-aware). With ``label="start"`` each stamp marks the
        start of an averaging interval of length ``interval``.
    ghi, dni, dhi : array_like, shape (N,)
        Global horizontal, direct normal and diffuse horizontal irradiance
        averaged over the interval [W/m²].
    latitude, longitude : float
        Site location [deg]; north and east positive.
    elevation : float, default 0
        Site elevation above sea level [m] (sets the pressure for refraction).
    surface_tilt : float, default 90
        Tilt from horizontal [deg]; 90 is a vertical facade.
    surface_azimuth : float, default 180
        Direction the surface faces [deg, clockwise from north]: E=90, S=180.
    albedo : float, default 0.2
        Ground reflectance [-], in [0, 1].
    sky_model : str, default "perez"
        Sky diffuse model, one of :data:`SKY_MODELS`.
    interval : str or pandas.Timedelta, default "15min"
        Length of the averaging interval [s as a Timedelta].
    label : {"start", "center", "end"}, default "start"
        Which point of the interval the stamps mark.

    Returns
    -------
    pandas.DataFrame
        Indexed by ``times``, columns ``poa_global``, ``poa_direct``,
        ``poa_sky_diffuse``, ``poa_ground_diffuse`` [W/m²], all ≥ 0 or NaN, and
        ``solar_zenith``, ``solar_azimuth`` [deg] (apparent zenith and azimuth
        at the interval midpoint).

    Raises
    ------
    SolarInputError
        Bad shapes, albedo, tilt, sky model or interval.
    SolarTimeError
        ``times`` is not tz-aware.
    """
    _check_options(albedo, sky_model)
    idx, cols, geom = _inputs(times, ghi, dni, dhi, latitude, longitude, elevation, interval,
                              label)
    comp = transpose(geom, *cols, [(surface_tilt, surface_azimuth)], albedo=albedo,
                     sky_model=sky_model)
    out = {name: a[:, 0] for name, a in comp.items()}
    out["poa_global"] = out["poa_direct"] + out["poa_sky_diffuse"] + out["poa_ground_diffuse"]
    out["solar_zenith"], out["solar_azimuth"] = geom[1], geom[3]
    cols_out = ["poa_global", "poa_direct", "poa_sky_diffuse", "poa_ground_diffuse",
                "solar_zenith", "solar_azimuth"]
    return pd.DataFrame(out, index=idx)[cols_out]


def surface_irradiance(
    times,
    ghi,
    dni,
    dhi,
    latitude: float,
    longitude: float,
    elevation: float = 0.0,
    *,
    surfaces: Sequence[tuple[float, float]],
    albedo: float = 0.2,
    sky_model: str = "perez",
    interval: str | pd.Timedelta = "15min",
    label: Label = "start",
) -> np.ndarray:
    """Total irradiance on any set of planes.

    Parameters
    ----------
    times, ghi, dni, dhi, latitude, longitude, elevation, albedo, sky_model, interval, label
        As in :func:`plane_of_array_irradiance`.
    surfaces : sequence of (tilt, azimuth)
        One ``(surface_tilt [deg], surface_azimuth [deg, clockwise from north])``
        pair per output column.

    Returns
    -------
    numpy.ndarray, shape (N, len(surfaces))
        Plane-of-array global irradiance [W/m²]; ≥ 0, NaN where an input is NaN.
    """
    if len(surfaces) == 0:
        raise SolarInputError("surfaces must list at least one (tilt, azimuth) pair")
    _check_options(albedo, sky_model)
    _, cols, geom = _inputs(times, ghi, dni, dhi, latitude, longitude, elevation, interval, label)
    return transpose(geom, *cols, surfaces, albedo=albedo, sky_model=sky_model,
                     total=True)["poa_global"]


def facade_irradiance(
    times,
    ghi,
    dni,
    dhi,
    latitude: float,
    longitude: float,
    elevation: float = 0.0,
    *,
    albedo: float = 0.2,
    sky_model: str = "perez",
    interval: str | pd.Timedelta = "15min",
    label: Label = "start",
    azimuths: Sequence[float] = FACADE_AZIMUTHS,
) -> np.ndarray:
    """Irradiance on vertical facades in the paper's order [solE, solS, solW, solN].

    These are the last four entries of the disturbance vector ``v`` of paper
    eq:model_dt, used by the building-hull model paper eq:q_bh.

    Parameters
    ----------
    times, ghi, dni, dhi, latitude, longitude, elevation, albedo, sky_model, interval, label
        As in :func:`plane_of_array_irradiance`.

    Returns
    -------
    azimuths : four azimuths [deg]
        The facades' directions, default east, south, west and north (90, 180, 270, 0);
        a rotated building's own (:attr:`~.rc.network.RCStructure.facade_azimuths`).

    Returns
    -------
    numpy.ndarray, shape (N, 4)
        Global irradiance on vertical surfaces facing ``azimuths`` [W/m²].
    """
    return surface_irradiance(
        times, ghi, dni, dhi, latitude, longitude, elevation,
        surfaces=[(90.0, float(az)) for az in azimuths],
        albedo=albedo, sky_model=sky_model, interval=interval, label=label,
    )
