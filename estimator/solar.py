"""Facade irradiance from weather-station data, computed with pvlib.

The building-hull heat-flux model (paper eq:q_bh) needs the solar irradiance on
the building's facades, ordered as the paper's disturbance vector
``v = [v_Ta, v_Ts, v_solE, v_solS, v_solW, v_solN]`` (paper eq:model_dt).
This module transposes weather-station irradiance (GHI, DNI, DHI) onto tilted
surfaces with :func:`pvlib.irradiance.get_total_irradiance`; no solar geometry
is written here.

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

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import pandas as pd
import pvlib

__all__ = [
    "FACADE_AZIMUTHS",
    "SKY_MODELS",
    "SolarInputError",
    "facade_irradiance",
    "plane_of_array_irradiance",
    "surface_irradiance",
]

#: Azimuths [deg, clockwise from north] of the paper's facade order E, S, W, N.
FACADE_AZIMUTHS: tuple[float, float, float, float] = (90.0, 180.0, 270.0, 0.0)

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


@dataclass(frozen=True)
class _Prepared:
    """Cleaned inputs and sun geometry shared by all planes of one call."""

    index: pd.DatetimeIndex
    ghi: np.ndarray
    dni: np.ndarray
    dhi: np.ndarray
    dni_extra: np.ndarray
    zenith: np.ndarray
    azimuth: np.ndarray
    sun_down: np.ndarray
    night: np.ndarray
    missing: np.ndarray
    albedo: float
    sky_model: str


def _prepare(times, ghi, dni, dhi, latitude, longitude, elevation, albedo, sky_model,
             interval, label) -> _Prepared:
    idx = _as_times(times)
    n = len(idx)
    ghi_a = _as_column("ghi", ghi, n)
    dni_a = _as_column("dni", dni, n)
    dhi_a = _as_column("dhi", dhi, n)
    if sky_model not in SKY_MODELS:
        raise SolarInputError(f"sky_model must be one of {SKY_MODELS}, got {sky_model!r}")
    if not 0.0 <= albedo <= 1.0:
        raise SolarInputError(f"albedo must be in [0, 1], got {albedo}")
    if not (-90.0 <= latitude <= 90.0 and -180.0 <= longitude <= 360.0):
        raise SolarInputError(
            f"latitude must be in [-90, 90] and longitude in [-180, 360] deg, "
            f"got ({latitude}, {longitude})"
        )
    step = pd.Timedelta(interval)
    if step <= pd.Timedelta(0):
        raise SolarInputError(f"interval must be positive, got {interval!r}")
    start, mid, end = _midpoints(idx, step, label)

    all_times = start.append(mid).append(end)
    sp = pvlib.solarposition.get_solarposition(
        all_times, latitude, longitude, altitude=elevation,
        pressure=pvlib.atmosphere.alt2pres(elevation),
    )
    zen_all = sp["apparent_zenith"].to_numpy()
    zen_start, zenith, zen_end = zen_all[:n], zen_all[n : 2 * n], zen_all[2 * n :]
    sun_down = zenith >= 90.0
    missing = np.isnan(ghi_a) | np.isnan(dni_a) | np.isnan(dhi_a)
    ghi_c, dni_c, dhi_c = (np.clip(np.nan_to_num(a), 0.0, None) for a in (ghi_a, dni_a, dhi_a))
    return _Prepared(
        index=idx,
        ghi=ghi_c,
        dni=np.where(sun_down, 0.0, dni_c),  # no beam from below the horizon
        dhi=dhi_c,
        dni_extra=np.asarray(pvlib.irradiance.get_extra_radiation(mid), dtype=float),
        zenith=zenith,
        azimuth=sp["azimuth"].to_numpy()[n : 2 * n],
        sun_down=sun_down,
        night=(zen_start >= 90.0) & sun_down & (zen_end >= 90.0),
        missing=missing,
        albedo=float(albedo),
        sky_model=sky_model,
    )


def _poa(prep: _Prepared, surface_tilt: float, surface_azimuth: float) -> pd.DataFrame:
    if not 0.0 <= surface_tilt <= 180.0:
        raise SolarInputError(f"surface_tilt must be in [0, 180] deg, got {surface_tilt}")

    def total(model: str) -> dict:
        return pvlib.irradiance.get_total_irradiance(
            surface_tilt, surface_azimuth, prep.zenith, prep.azimuth,
            prep.dni, prep.ghi, prep.dhi,
            dni_extra=prep.dni_extra, albedo=prep.albedo, model=model,
        )

    poa = total(prep.sky_model)
    sky = np.asarray(poa["poa_sky_diffuse"], dtype=float)
    if prep.sky_model != "isotropic" and prep.sun_down.any():
        iso = np.asarray(total("isotropic")["poa_sky_diffuse"], dtype=float)
        sky = np.where(prep.sun_down, iso, sky)
    # no diffuse light -> no sky diffuse on any plane (Perez divides 0 by 0 there)
    sky = np.where(prep.dhi <= 0.0, 0.0, sky)
    out = {}
    for name, comp in (("poa_direct", poa["poa_direct"]), ("poa_sky_diffuse", sky),
                       ("poa_ground_diffuse", poa["poa_ground_diffuse"])):
        comp = np.clip(np.asarray(comp, dtype=float), 0.0, None)
        comp = np.where(prep.night, 0.0, comp)
        out[name] = np.where(prep.missing, np.nan, comp)
    out["poa_global"] = out["poa_direct"] + out["poa_sky_diffuse"] + out["poa_ground_diffuse"]
    out["solar_zenith"] = prep.zenith
    out["solar_azimuth"] = prep.azimuth
    cols = ["poa_global", "poa_direct", "poa_sky_diffuse", "poa_ground_diffuse",
            "solar_zenith", "solar_azimuth"]
    return pd.DataFrame(out, index=prep.index)[cols]


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
    prep = _prepare(times, ghi, dni, dhi, latitude, longitude, elevation, albedo, sky_model,
                    interval, label)
    return _poa(prep, surface_tilt, surface_azimuth)


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
    prep = _prepare(times, ghi, dni, dhi, latitude, longitude, elevation, albedo, sky_model,
                    interval, label)
    return np.column_stack(
        [_poa(prep, tilt, az)["poa_global"].to_numpy() for tilt, az in surfaces]
    )


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
    numpy.ndarray, shape (N, 4)
        Global irradiance on vertical surfaces facing east, south, west and north
        (azimuth 90, 180, 270, 0 deg) [W/m²].
    """
    return surface_irradiance(
        times, ghi, dni, dhi, latitude, longitude, elevation,
        surfaces=[(90.0, az) for az in FACADE_AZIMUTHS],
        albedo=albedo, sky_model=sky_model, interval=interval, label=label,
    )
